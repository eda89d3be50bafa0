//! Scene — the clear sky and the sun. In: an apparent elevation (and, for the sun, the final
//! direction of a sky-bound ray). Out: linear RGB radiance.
//!
//! **Unit of radiance** (everywhere in the film): 1.0 = the radiance of the white horizon sky at
//! `brightness = 1` — the limit of an optically infinite path of uniformly lit air.
//!
//! **Sky model** (single scattering, uniform source, no sun position dependence): along a viewing
//! path of optical depth τ·m the scattered light builds up as `1 − exp(−τ·m)`, so
//!
//! ```text
//! L_c(e) = brightness · (1 − exp(−τ_c · m(e)))
//! τ_c    = τ_R · (550 nm / λ_c)⁴  +  τ_A · (550 nm / λ_c)^1.3
//! ```
//!
//! with the Rayleigh optical depth τ_R at 550 nm (0.0975 for a sea-level column), an aerosol
//! optical depth τ_A with Ångström exponent 1.3, λ_c = 612, 549 and 465 nm for the R, G and B
//! channels (roughly the dominant wavelengths of the Rec.709 primaries), and the Kasten–Young
//! (1989) relative air mass `m(e) = 1 / (sin e + 0.50572 (e° + 6.07995)^−1.6364)` (m(90°) = 1,
//! m(0) ≈ 37.9). The zenith is blue (τ_B ≈ 2.4 τ_G), the horizon white (every channel saturates).
//! Elevations below 0 use m(0): the lowest sky is the horizon sky.
//!
//! **Sun**: a limb-darkened disc, `I(μ) = 1 − u (1 − μ)` (linear law, μ = cos of the angle from
//! disc centre to the line of sight at the solar surface), times `intensity`, attenuated by
//! `exp(−τ_c)` with τ_c integrated along the ray's own curved path from the camera to the top
//! ([`Sky::sun_extinction`] gives the extinction profile; the renderer traces each ray that may
//! show the sun): this reddens and dims the low sun, and a Novaya Zemlya ray that skims hundreds
//! of kilometres of near-surface air far more than an air-mass formula would. Where no traced
//! path is at hand (a ray model that cannot integrate one) the air mass stands in:
//! `exp(−τ_c · m(e))` with e the ray's APPARENT elevation at the camera (clamped at 0). Where the
//! disc is seen is decided by the ray's FINAL direction, so a sun below the astronomical horizon
//! can be seen through rays that come up (Novaya Zemlya).
//!
//! **Aerial perspective** (only with `visibility_km`, [`AerialPerspective`]): the air between the
//! camera and a card or the sea both dims it and adds scattered light. Extinction per channel at
//! height h is `β_c(h) = β_R,c e^(−h/8 km) + β_A,c e^(−h/H_A)`, with the Rayleigh part at sea
//! level from the sky's own column, `β_R,c = τ_R (550/λ_c)⁴ / 8 km`, and the aerosol part from the
//! Koschmieder visibility V (meteorological optical range: the TOTAL extinction at 550 nm at the
//! surface is 3.912 / V), `β_A,c = (3.912/V − τ_R/8 km) (550/λ_c)^1.3`. An object of radiance L
//! seen through optical depth τ_c appears as `L e^(−τ_c) + L_path,c (1 − e^(−τ_c))` with the path
//! radiance L_path = the horizon sky `radiance(0)` (the same uniform-source limit the sky model
//! uses), so an object far beyond the visibility fades exactly into the horizon sky.

use serde::Serialize;

/// Wavelengths standing in for the R, G, B channels (nm).
pub const CHANNEL_WAVELENGTHS_NM: [f64; 3] = [612.0, 549.0, 465.0];

/// Ångström exponent of the aerosol optical depth.
pub const AEROSOL_ANGSTROM_EXPONENT: f64 = 1.3;

/// Kasten–Young (1989) relative air mass for apparent elevation `elevation_rad` (clamped to ≥ 0).
#[inline]
pub fn relative_air_mass(elevation_rad: f64) -> f64 {
    let e = elevation_rad.clamp(0.0, std::f64::consts::FRAC_PI_2);
    1.0 / (e.sin() + 0.50572 * (e.to_degrees() + 6.07995).powf(-1.6364))
}

/// Clear-sky parameters (see the module documentation for the model).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sky {
    /// Radiance of the white horizon sky (the unit of the film at 1.0).
    pub brightness: f64,
    /// Rayleigh optical depth of the air column at 550 nm (0.0975 at sea level).
    pub rayleigh_optical_depth: f64,
    /// Aerosol optical depth at 550 nm (0: pure Rayleigh sky).
    pub aerosol_optical_depth: f64,
    /// Aerial perspective between the camera and cards or the sea; `None`: objects are seen
    /// without extinction (and the scene hash is unchanged from before the setting existed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub aerial: Option<AerialPerspective>,
    /// The wavelengths (nm) the R, G, B channels stand for: [`CHANNEL_WAVELENGTHS_NM`], except
    /// in one band of a spectral render, where all three are the band's wavelength (not part of
    /// the scene file, so not of its hash).
    #[serde(skip)]
    pub channel_wavelengths_nm: [f64; 3],
}

/// Rayleigh scale height (m) of the extinction profile used by the aerial perspective.
pub const RAYLEIGH_SCALE_HEIGHT_M: f64 = 8_000.0;

/// Koschmieder's constant: −ln 0.02, the contrast threshold that defines the visibility.
pub const KOSCHMIEDER_CONSTANT: f64 = 3.912;

/// Default aerosol scale height (m) of the aerial perspective.
pub const DEFAULT_AEROSOL_SCALE_HEIGHT_M: f64 = 1_000.0;

/// The scene's haze: visibility and the aerosol scale height (module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AerialPerspective {
    /// Koschmieder visibility at the surface (m): total extinction at 550 nm is 3.912 / this.
    pub visibility_m: f64,
    /// Scale height of the aerosol extinction (m).
    pub aerosol_scale_height_m: f64,
}

/// Visibility (m) of an aerosol-free sky with Rayleigh optical depth `rayleigh_optical_depth`:
/// the largest `visibility_m` the aerial perspective accepts (∞ without Rayleigh extinction).
pub fn rayleigh_visibility_m(rayleigh_optical_depth: f64) -> f64 {
    KOSCHMIEDER_CONSTANT * RAYLEIGH_SCALE_HEIGHT_M / rayleigh_optical_depth
}

/// Gauss–Legendre nodes on [0, 1] and weights (summing to 1) of order `n` (Newton on P_n).
fn gauss_legendre_unit(n: usize) -> Vec<(f64, f64)> {
    (1..=n)
        .map(|i| {
            let mut x = (std::f64::consts::PI * (i as f64 - 0.25) / (n as f64 + 0.5)).cos();
            let mut dp = 1.0;
            for _ in 0..100 {
                let (mut p0, mut p1) = (1.0, x);
                for k in 2..=n {
                    let p2 = ((2 * k - 1) as f64 * x * p1 - (k - 1) as f64 * p0) / k as f64;
                    (p0, p1) = (p1, p2);
                }
                dp = n as f64 * (x * p1 - p0) / (x * x - 1.0);
                let dx = p1 / dp;
                x -= dx;
                if dx.abs() < 1e-15 {
                    break;
                }
            }
            let w = 2.0 / ((1.0 - x * x) * dp * dp);
            (0.5 * (1.0 + x), 0.5 * w)
        })
        .collect()
}

/// Order of the Gauss–Legendre rule along a chord.
const CHORD_NODES: usize = 16;

/// Extinction coefficients and path radiance of a sky with aerial perspective, resolved once.
#[derive(Debug, Clone, PartialEq)]
pub struct Extinction {
    /// Rayleigh extinction per channel at sea level (1/m).
    pub rayleigh_per_m: [f64; 3],
    /// Aerosol extinction per channel at sea level (1/m).
    pub aerosol_per_m: [f64; 3],
    /// Aerosol scale height (m).
    pub aerosol_scale_height_m: f64,
    /// Radiance the air adds in the optically thick limit: the horizon sky.
    pub path_radiance: [f64; 3],
    nodes: Vec<(f64, f64)>,
}

impl Extinction {
    /// Scale heights (m) of the two parts of the profile: Rayleigh, then aerosol.
    pub fn scale_heights_m(&self) -> [f64; 2] {
        [RAYLEIGH_SCALE_HEIGHT_M, self.aerosol_scale_height_m]
    }

    /// Optical depth per channel along a path whose density-weighted lengths are
    /// `density_paths_m`: ∫ exp(−h/H) ds (m) for each of [`Self::scale_heights_m`].
    pub fn path_optical_depth(&self, density_paths_m: [f64; 2]) -> [f64; 3] {
        let [rayleigh_m, aerosol_m] = density_paths_m;
        [0, 1, 2].map(|c| self.rayleigh_per_m[c] * rayleigh_m + self.aerosol_per_m[c] * aerosol_m)
    }

    /// Extinction coefficient per channel at `height_m` (1/m).
    pub fn coefficient_per_m(&self, height_m: f64) -> [f64; 3] {
        let r = (-height_m / RAYLEIGH_SCALE_HEIGHT_M).exp();
        let a = (-height_m / self.aerosol_scale_height_m).exp();
        [0, 1, 2].map(|c| self.rayleigh_per_m[c] * r + self.aerosol_per_m[c] * a)
    }

    /// Optical depth per channel along the straight chord from height `from_m` (ground distance
    /// 0) to height `to_m` at ground distance `ground_distance_m`, over a sphere of
    /// `earth_radius_m`: Gauss–Legendre quadrature in the chord's exact line–sphere geometry (a
    /// curved ray differs from its chord by its sag, κL²/8; see `docs/scene.md`).
    pub fn chord_optical_depth(
        &self,
        earth_radius_m: f64,
        from_m: f64,
        to_m: f64,
        ground_distance_m: f64,
    ) -> [f64; 3] {
        let (r0, r1) = (earth_radius_m + from_m, earth_radius_m + to_m);
        let theta = ground_distance_m / earth_radius_m;
        // Camera at (0, r0), end point at (r1 sin θ, r1 cos θ).
        let (bx, by) = (r1 * theta.sin(), r1 * theta.cos() - r0);
        let length_m = bx.hypot(by);
        let mut tau = [0.0; 3];
        for &(t, w) in &self.nodes {
            let h = (t * bx).hypot(r0 + t * by) - earth_radius_m;
            let beta = self.coefficient_per_m(h);
            for c in 0..3 {
                tau[c] += w * beta[c];
            }
        }
        tau.map(|t| t * length_m)
    }

    /// What an object of premultiplied radiance `radiance` and coverage `alpha` looks like
    /// through optical depth `tau`: `L e^(−τ) + α L_path (1 − e^(−τ))`. A non-finite τ (a ray
    /// with an unknown end) is taken as optically thick.
    #[inline]
    pub fn attenuate(&self, radiance: [f64; 3], alpha: f64, tau: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|c| {
            let t = if tau[c].is_finite() {
                (-tau[c]).exp()
            } else {
                0.0
            };
            radiance[c] * t + alpha * self.path_radiance[c] * (1.0 - t)
        })
    }
}

impl Default for Sky {
    fn default() -> Self {
        Self {
            brightness: 1.0,
            rayleigh_optical_depth: 0.0975,
            aerosol_optical_depth: 0.02,
            aerial: None,
            channel_wavelengths_nm: CHANNEL_WAVELENGTHS_NM,
        }
    }
}

impl Sky {
    /// Optical depth τ_c of each channel (zenith path).
    pub fn optical_depths(&self) -> [f64; 3] {
        self.channel_wavelengths_nm.map(|l| {
            let r = 550.0 / l;
            self.rayleigh_optical_depth * r.powi(4)
                + self.aerosol_optical_depth * r.powf(AEROSOL_ANGSTROM_EXPONENT)
        })
    }

    /// Sky radiance (linear RGB) looking at apparent elevation `elevation_rad`.
    pub fn radiance(&self, elevation_rad: f64) -> [f64; 3] {
        self.radiance_with_depths(elevation_rad, self.optical_depths())
    }

    /// [`Sky::radiance`] with the channels' optical depths `depths` (from
    /// [`Sky::optical_depths`]) computed once by the caller: the same result, six `powf`/`powi`
    /// cheaper per call (the renderer tabulates thousands of elevations per frame).
    #[inline]
    pub fn radiance_with_depths(&self, elevation_rad: f64, depths: [f64; 3]) -> [f64; 3] {
        let m = relative_air_mass(elevation_rad);
        depths.map(|tau| self.brightness * (1.0 - (-tau * m).exp()))
    }

    /// The aerial perspective's extinction, if the sky has one (module documentation).
    pub fn extinction(&self) -> Option<Extinction> {
        let aerial = self.aerial?;
        let rayleigh_550 = self.rayleigh_optical_depth / RAYLEIGH_SCALE_HEIGHT_M;
        let aerosol_550 = (KOSCHMIEDER_CONSTANT / aerial.visibility_m - rayleigh_550).max(0.0);
        let ratios = self.channel_wavelengths_nm.map(|l| 550.0 / l);
        Some(Extinction {
            rayleigh_per_m: ratios.map(|r| rayleigh_550 * r.powi(4)),
            aerosol_per_m: ratios.map(|r| aerosol_550 * r.powf(AEROSOL_ANGSTROM_EXPONENT)),
            aerosol_scale_height_m: aerial.aerosol_scale_height_m,
            path_radiance: self.radiance(0.0),
            nodes: gauss_legendre_unit(CHORD_NODES),
        })
    }

    /// The extinction along the sun's own ray: the aerial perspective's (module documentation)
    /// with `visibility_km`; otherwise the sky's own columns spread over their scale heights,
    /// β_R,c = τ_R,c / 8 km and β_A,c = τ_A,c / 1 km, so a vertical path through the whole
    /// atmosphere has the sky's optical depths (less the 0.7 % of the Rayleigh column above a
    /// 40 km top).
    pub fn sun_extinction(&self) -> Extinction {
        if let Some(extinction) = self.extinction() {
            return extinction;
        }
        let ratios = self.channel_wavelengths_nm.map(|l| 550.0 / l);
        let rayleigh_550 = self.rayleigh_optical_depth / RAYLEIGH_SCALE_HEIGHT_M;
        let aerosol_550 = self.aerosol_optical_depth / DEFAULT_AEROSOL_SCALE_HEIGHT_M;
        Extinction {
            rayleigh_per_m: ratios.map(|r| rayleigh_550 * r.powi(4)),
            aerosol_per_m: ratios.map(|r| aerosol_550 * r.powf(AEROSOL_ANGSTROM_EXPONENT)),
            aerosol_scale_height_m: DEFAULT_AEROSOL_SCALE_HEIGHT_M,
            path_radiance: self.radiance(0.0),
            nodes: gauss_legendre_unit(CHORD_NODES),
        }
    }

    /// Transmittance exp(−τ_c·m(e)) of each channel along apparent elevation `elevation_rad`.
    pub fn transmittance(&self, elevation_rad: f64) -> [f64; 3] {
        let m = relative_air_mass(elevation_rad);
        self.optical_depths().map(|tau| (-tau * m).exp())
    }
}

/// Angular diameter of the sun (rad) from its diameter (1 392 000 km) and distance (149.6e6 km):
/// 0.533°.
pub fn sun_angular_diameter_rad() -> f64 {
    2.0 * (0.5 * crate::units::SUN_DIAMETER_M / crate::units::SUN_DISTANCE_M).atan()
}

/// The sun: position (true, i.e. geometric, direction seen from the observer), size and brightness.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sun {
    /// True elevation of the sun's centre (rad; may be below 0).
    pub elevation_rad: f64,
    /// Azimuth of the sun's centre (rad, clockwise from north).
    pub azimuth_rad: f64,
    /// Angular diameter (rad); 0.533° by default.
    pub angular_diameter_rad: f64,
    /// Linear limb-darkening coefficient u: I(μ) = 1 − u(1 − μ); 0.6 in the visible.
    pub limb_darkening: f64,
    /// Radiance of the disc centre outside the atmosphere, in film units (1 = horizon sky).
    pub intensity: f64,
}

impl Sun {
    /// Limb-darkened radiance factor (intensity × I(μ), before atmospheric attenuation) seen in
    /// direction (`azimuth_rad`, `elevation_rad`); 0 outside the disc.
    #[inline]
    pub fn disc(&self, azimuth_rad: f64, elevation_rad: f64) -> f64 {
        SunDisc::new(self).radiance(azimuth_rad, elevation_rad)
    }
}

/// A [`Sun`]'s disc with the per-frame constants of [`Sun::disc`] computed once (the renderer
/// asks for every sample whose ray leaves in the sun's band of elevations).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SunDisc {
    elevation_rad: f64,
    azimuth_rad: f64,
    cos_elevation: f64,
    sin_elevation: f64,
    radius_rad: f64,
    /// sin²(radius / 2): the haversine of the disc's edge.
    edge_haversine: f64,
    intensity: f64,
    limb_darkening: f64,
}

impl SunDisc {
    /// The disc of `sun`.
    pub fn new(sun: &Sun) -> Self {
        let radius_rad = 0.5 * sun.angular_diameter_rad;
        SunDisc {
            elevation_rad: sun.elevation_rad,
            azimuth_rad: sun.azimuth_rad,
            cos_elevation: sun.elevation_rad.cos(),
            sin_elevation: sun.elevation_rad.sin(),
            radius_rad,
            edge_haversine: (0.5 * radius_rad).sin().powi(2),
            intensity: sun.intensity,
            limb_darkening: sun.limb_darkening,
        }
    }

    /// The disc centre's azimuth (rad, clockwise from north).
    pub fn azimuth_rad(&self) -> f64 {
        self.azimuth_rad
    }

    /// Whether a direction at `elevation_rad` is within the disc's band of elevations.
    #[inline]
    pub fn may_meet(&self, elevation_rad: f64) -> bool {
        (elevation_rad - self.elevation_rad).abs() <= self.radius_rad
    }

    /// Whether some elevation in [`lo_rad`, `hi_rad`] may be within the disc's band: when this
    /// is false, [`Self::may_meet`] is false for every elevation of the range (the band is
    /// widened by far more than any rounding). NaN bounds are ignored (a NaN elevation never
    /// meets the disc).
    pub fn may_meet_range(&self, lo_rad: f64, hi_rad: f64) -> bool {
        let pad = self.radius_rad + 1e-12;
        hi_rad >= self.elevation_rad - pad && lo_rad <= self.elevation_rad + pad
    }

    /// [`Sun::disc`]: the haversine of the angular distance from the centre against that of the
    /// edge, so a direction outside costs no arcsine ([`Self::along`] then
    /// [`DiscChord::radiance`]).
    #[inline]
    pub fn radiance(&self, azimuth_rad: f64, elevation_rad: f64) -> f64 {
        self.along(elevation_rad)
            .map_or(0.0, |chord| chord.radiance(azimuth_rad))
    }

    /// The disc along elevation `elevation_rad`, its terms that depend on the elevation alone
    /// worked out once: `None` where [`Self::radiance`] is 0 at every azimuth because of the
    /// elevation (not finite, or outside the disc's band).
    #[inline]
    pub fn along(&self, elevation_rad: f64) -> Option<DiscChord> {
        if !elevation_rad.is_finite() {
            return None;
        }
        // Quick reject on elevation (cheap), then the haversine distance on the sphere.
        let rise = elevation_rad - self.elevation_rad;
        if rise.abs() > self.radius_rad {
            return None;
        }
        let half_rise_sin = (0.5 * rise).sin();
        // cos(e) = cos(e☉ + rise), from the half-angle's sine and cosine.
        let half_rise_cos = (1.0 - half_rise_sin * half_rise_sin).sqrt();
        let (rise_sin, rise_cos) = (
            2.0 * half_rise_sin * half_rise_cos,
            1.0 - 2.0 * half_rise_sin * half_rise_sin,
        );
        let cos_elevation = self.cos_elevation * rise_cos - self.sin_elevation * rise_sin;
        Some(DiscChord {
            azimuth_rad: self.azimuth_rad,
            rise_haversine: half_rise_sin * half_rise_sin,
            longitude_weight: cos_elevation * self.cos_elevation,
            edge_haversine: self.edge_haversine,
            radius_rad: self.radius_rad,
            intensity: self.intensity,
            limb_darkening: self.limb_darkening,
        })
    }
}

/// Below this |x| [`small_sin`] sums a series.
const SMALL_SIN_MAX: f64 = 0.01;

/// sin x: for |x| ≤ [`SMALL_SIN_MAX`] from its Maclaurin series to the x⁷ term (the first
/// omitted term is below 3e-22 of the value, far under an ulp), otherwise the library's.
/// Written by hand because the disc's azimuths are tiny angles and the renderer takes one per
/// lit column; the series agrees with the library to rounding (a unit test checks).
#[inline]
fn small_sin(x: f64) -> f64 {
    if x.abs() > SMALL_SIN_MAX {
        return x.sin();
    }
    sin_series(x)
}

/// [`small_sin`]'s series, at any x.
#[inline]
fn sin_series(x: f64) -> f64 {
    const C: [f64; 3] = [-1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0];
    let z = x * x;
    x + x * z * (C[0] + z * (C[1] + z * C[2]))
}

/// Below this haversine [`distance_squared`] sums a series.
const SMALL_HAVERSINE_MAX: f64 = 1e-4;

/// The squared angular distance d² (rad²) whose haversine sin²(d/2) is `haversine` (in
/// [0, 1]): d = 2 asin √h. For h ≤ [`SMALL_HAVERSINE_MAX`] (d up to 1.15°, the sun's disc
/// many times over) from the series asin²(√h) = h (1 + h/3 + 8h²/45 + 4h³/35 + 128h⁴/1575 + …)
/// to the h³ term (the first omitted term is below 1e-17 of the value), otherwise by the
/// arcsine. Written by hand for the reason of [`small_sin`].
#[inline]
fn distance_squared(haversine: f64) -> f64 {
    let h = haversine;
    if h > SMALL_HAVERSINE_MAX {
        let d = 2.0 * h.sqrt().min(1.0).asin();
        return d * d;
    }
    distance_squared_series(h)
}

/// [`distance_squared`]'s series, at any haversine.
#[inline]
fn distance_squared_series(h: f64) -> f64 {
    4.0 * h * (1.0 + h * (1.0 / 3.0 + h * (8.0 / 45.0 + h * (4.0 / 35.0))))
}

/// A [`SunDisc`] along one elevation ([`SunDisc::along`]): its radiance as a function of the
/// azimuth alone, the same values as [`SunDisc::radiance`] at that elevation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscChord {
    /// The disc centre's azimuth (rad).
    azimuth_rad: f64,
    /// sin²(rise / 2), the rise the elevation's above the centre's: the haversine's elevation
    /// term.
    rise_haversine: f64,
    /// cos e · cos e☉: the weight of the haversine's longitude term.
    longitude_weight: f64,
    edge_haversine: f64,
    radius_rad: f64,
    intensity: f64,
    limb_darkening: f64,
}

impl DiscChord {
    /// The disc's radiance towards azimuth `azimuth_rad` (rad, clockwise from north) along this
    /// elevation; 0 outside the disc.
    #[inline]
    pub fn radiance(&self, azimuth_rad: f64) -> f64 {
        if !azimuth_rad.is_finite() {
            return 0.0;
        }
        let half_lon_sin = small_sin(0.5 * (azimuth_rad - self.azimuth_rad));
        let haversine = self.haversine(half_lon_sin);
        if haversine >= self.edge_haversine {
            return 0.0;
        }
        self.limb_darkened(distance_squared(haversine))
    }

    /// [`Self::radiance`] towards `heading_rad + offset` for each offset of `offsets_rad`
    /// (rad), into `out` (as long): the same values, bit for bit. For a disc whose edge is
    /// within both series' ranges and azimuths whose half-difference from the centre's is
    /// within 0.01 rad, the sine series' range (the columns of a chord), one loop without
    /// branches over the columns, which the compiler vectorises (each column evaluates both
    /// series and keeps 0 beyond the edge: within the edge the series are what
    /// [`Self::radiance`] takes); a run that leaves those ranges anywhere is done again column
    /// by column.
    pub fn radiance_along(&self, heading_rad: f64, offsets_rad: &[f64], out: &mut [f64]) {
        let out = &mut out[..offsets_rad.len()];
        let mut series = self.edge_haversine <= SMALL_HAVERSINE_MAX;
        if series {
            for (v, &offset) in out.iter_mut().zip(offsets_rad) {
                // A non-finite azimuth gives a NaN or infinite x, and the run is redone.
                let x = 0.5 * ((heading_rad + offset) - self.azimuth_rad);
                series &= x.abs() <= SMALL_SIN_MAX;
                let haversine = self.haversine(sin_series(x));
                let inside = self.limb_darkened(distance_squared_series(haversine));
                // Within the edge (or NaN, which the series also takes) the radiance is
                // `inside`, else 0.
                *v = if haversine >= self.edge_haversine {
                    0.0
                } else {
                    inside
                };
            }
        }
        if !series {
            for (v, &offset) in out.iter_mut().zip(offsets_rad) {
                *v = self.radiance(heading_rad + offset);
            }
        }
    }

    /// The haversine of the angle from the disc centre to the direction along this elevation
    /// whose azimuth differs from the centre's by Δ, from sin(Δ/2).
    #[inline]
    fn haversine(&self, half_lon_sin: f64) -> f64 {
        self.rise_haversine + self.longitude_weight * half_lon_sin * half_lon_sin
    }

    /// The limb-darkened radiance at squared angular distance `d_squared` (rad²) from the
    /// centre, within the disc.
    #[inline]
    fn limb_darkened(&self, d_squared: f64) -> f64 {
        let s_squared = (d_squared / (self.radius_rad * self.radius_rad)).min(1.0);
        let mu = (1.0 - s_squared).sqrt();
        self.intensity * (1.0 - self.limb_darkening * (1.0 - mu))
    }

    /// The disc centre's azimuth (rad, clockwise from north).
    pub fn azimuth_rad(&self) -> f64 {
        self.azimuth_rad
    }

    /// A half-width w (rad) of the chord in azimuth, below π/3 when finite: [`Self::radiance`]
    /// is 0 towards every azimuth whose difference from the centre's is, modulo 2π, within
    /// [w, 2π − w] (padded far beyond any rounding of the azimuth). Infinite where it bounds
    /// nothing (no positive longitude weight, or a chord this wide).
    pub fn half_width_rad(&self) -> f64 {
        let weight = self.longitude_weight;
        if !(weight > 0.0 && weight.is_finite()) {
            return f64::INFINITY;
        }
        // |sin(Δ/2)| below this is needed for a haversine below the edge's.
        let half_sin = ((self.edge_haversine - self.rise_haversine).max(0.0) / weight).sqrt();
        if half_sin.is_nan() || half_sin >= 0.5 {
            return f64::INFINITY;
        }
        2.0 * half_sin.asin() * (1.0 + 1e-6) + 1e-9
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_series_agree_with_the_library_to_rounding() {
        // Both sides of each switch, and tiny arguments.
        let ulps = |a: f64, b: f64| (a - b).abs() / (f64::EPSILON * b.abs().max(f64::MIN_POSITIVE));
        for i in -2000..=2000 {
            let x = SMALL_SIN_MAX * 1.2 * f64::from(i) / 2000.0;
            assert!(ulps(small_sin(x), x.sin()) <= 2.0, "sin {x}");
        }
        for i in 0..=3000 {
            let h = SMALL_HAVERSINE_MAX * 1.5 * (f64::from(i) / 3000.0).powi(3);
            let d = 2.0 * h.sqrt().asin();
            assert!(ulps(distance_squared(h), d * d) <= 4.0, "haversine {h}");
        }
        assert_eq!(distance_squared(1.0), std::f64::consts::PI.powi(2));
    }

    #[test]
    fn a_run_of_columns_gets_each_columns_own_radiance_bit_for_bit() {
        // The sun's disc low and near the zenith (chords many times wider in azimuth), and one
        // 40 times as wide (its edge beyond the haversine series); chords across their bands,
        // runs of offsets across the chord and beyond it (wide enough to leave the sine
        // series), and runs with a non-finite offset.
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for (diameter_deg, elevation) in [(0.533, 0.01), (0.533, 1.55), (21.0, 0.01)] {
            let disc = SunDisc::new(&Sun {
                elevation_rad: elevation,
                azimuth_rad: 2.5,
                angular_diameter_rad: f64::to_radians(diameter_deg),
                limb_darkening: 0.6,
                intensity: 3.0,
            });
            let r = disc.radius_rad;
            for i in -9..=9 {
                let chord = disc.along(elevation + r * f64::from(i) / 10.0).unwrap();
                let w = chord.half_width_rad();
                let runs = [(2.5, 1.2 * w), (2.4, 0.5 * w), (2.5, 0.05), (2.47, 0.015)];
                for (heading, span) in runs {
                    // Offsets about the disc centre's.
                    let n = 301;
                    let mut offsets: Vec<f64> = (0..n)
                        .map(|k| {
                            (2.5 - heading) + span * (2.0 * f64::from(k) / f64::from(n - 1) - 1.0)
                        })
                        .collect();
                    let mut out = vec![f64::NAN; n as usize];
                    let want = |offsets: &[f64]| {
                        offsets
                            .iter()
                            .map(|o| chord.radiance(heading + o))
                            .collect::<Vec<_>>()
                    };
                    chord.radiance_along(heading, &offsets, &mut out);
                    assert_eq!(
                        bits(&out),
                        bits(&want(&offsets)),
                        "{diameter_deg} {i} {span}"
                    );
                    assert!(out.iter().any(|&v| v > 0.0));
                    offsets[150] = f64::NAN;
                    offsets[151] = f64::INFINITY;
                    chord.radiance_along(heading, &offsets, &mut out);
                    assert_eq!(bits(&out), bits(&want(&offsets)), "{diameter_deg} {i} NaN");
                }
            }
        }
    }

    #[test]
    fn the_chord_half_width_bounds_the_disc_tightly() {
        // Suns low and high, elevations across the disc's band (its edges included): towards
        // every azimuth at least the half-width from the centre's (modulo 2π, on either side,
        // many turns away) the disc is dark; just inside it, where the chord is not a point, it
        // is lit.
        let tau = std::f64::consts::TAU;
        for sun_elevation in [-0.03, 0.0, 0.4, 1.2] {
            let disc = SunDisc::new(&Sun {
                elevation_rad: sun_elevation,
                azimuth_rad: 2.5,
                angular_diameter_rad: 0.533f64.to_radians(),
                limb_darkening: 0.6,
                intensity: 1.0,
            });
            let r = disc.radius_rad;
            for i in -100i32..=100 {
                let e = sun_elevation + r * f64::from(i) / 100.0;
                // The band's very edges may round outside it.
                let Some(chord) = disc.along(e) else {
                    assert_eq!(i.abs(), 100, "{e}");
                    continue;
                };
                let w = chord.half_width_rad();
                assert!(w.is_finite() && w < std::f64::consts::FRAC_PI_3, "{e}: {w}");
                for turns in [-3.0, 0.0, 1.0, 40.0] {
                    for k in 0..=200 {
                        let delta = w + (tau - 2.0 * w) * f64::from(k) / 200.0;
                        for d in [delta, -delta] {
                            let azimuth = 2.5 + d + tau * turns;
                            assert_eq!(chord.radiance(azimuth), 0.0, "{e} {d} {turns}");
                            assert_eq!(disc.radiance(azimuth, e), 0.0, "{e} {d} {turns}");
                        }
                    }
                }
                if i.abs() <= 99 {
                    for d in [0.9999 * w, -0.9999 * w] {
                        assert!(chord.radiance(2.5 + d) > 0.0, "{e} {d}: {w}");
                    }
                }
                assert_eq!(
                    chord.radiance(2.5 + 0.3 * w),
                    disc.radiance(2.5 + 0.3 * w, e)
                );
            }
            assert!(disc.along(sun_elevation + 1.0001 * r).is_none());
            assert!(disc.along(f64::NAN).is_none());
        }
    }

    #[test]
    fn the_disc_range_test_holds_wherever_an_elevation_in_the_range_meets_the_band() {
        let disc = SunDisc::new(&Sun {
            elevation_rad: -0.02,
            azimuth_rad: 0.0,
            angular_diameter_rad: 0.533f64.to_radians(),
            limb_darkening: 0.6,
            intensity: 1.0,
        });
        for i in -200..200 {
            let lo = f64::from(i) * 2e-4;
            for width in [0.0, 1e-5, 3e-3] {
                let hi = lo + width;
                let any = (0..=20).any(|k| disc.may_meet(lo + width * f64::from(k) / 20.0));
                assert!(!any || disc.may_meet_range(lo, hi), "{lo} {hi}");
            }
        }
        assert!(disc.may_meet_range(-0.03, 0.0) && !disc.may_meet_range(0.0, 0.1));
    }

    #[test]
    fn air_mass_matches_kasten_young() {
        // Kasten & Young (1989): m(90°) = 1 and m(0°) = 37.92 (their formula and table).
        assert!((relative_air_mass(std::f64::consts::FRAC_PI_2) - 1.0).abs() < 1e-3);
        let m0 = relative_air_mass(0.0);
        assert!((m0 - 37.92).abs() < 0.05, "{m0}");
        // Plane-parallel limit at 30°: 1/sin 30° = 2 (Kasten–Young 1.9995).
        assert!((relative_air_mass(30f64.to_radians()) - 2.0).abs() < 0.01);
    }

    #[test]
    fn sky_is_blue_at_zenith_and_white_at_horizon() {
        let sky = Sky::default();
        let z = sky.radiance(std::f64::consts::FRAC_PI_2);
        let h = sky.radiance(0.0);
        assert!(z[2] > 1.5 * z[1] && z[1] > z[0], "{z:?}");
        assert!(h.iter().all(|&c| c > 0.9 && c <= 1.0), "{h:?}");
        // Monotone whitening towards the horizon.
        let mut prev = sky.radiance(1.5);
        for i in (0..150).rev() {
            let e = i as f64 * 0.01;
            let l = sky.radiance(e);
            assert!(l[0] >= prev[0] && l[0] / l[2] >= prev[0] / prev[2] - 1e-12);
            prev = l;
        }
    }

    #[test]
    fn sun_has_the_right_size_and_limb_darkening() {
        assert!((sun_angular_diameter_rad().to_degrees() - 0.5331).abs() < 1e-3);
        let sun = Sun {
            elevation_rad: 0.1,
            azimuth_rad: 1.0,
            angular_diameter_rad: sun_angular_diameter_rad(),
            limb_darkening: 0.6,
            intensity: 10.0,
        };
        let r = 0.5 * sun.angular_diameter_rad;
        assert!((sun.disc(1.0, 0.1) - 10.0).abs() < 1e-12);
        assert!(sun.disc(1.0, 0.1 + 1.001 * r) == 0.0);
        assert!(sun.disc(1.0, 0.1 + 0.999 * r) > 0.0);
        // At the limb μ → 0: I → 1 − u = 0.4.
        assert!((sun.disc(1.0, 0.1 + 0.99999 * r) - 4.0).abs() < 0.1);
        // Azimuth offsets shrink by cos(elevation).
        let daz = 0.999 * r / 0.1f64.cos();
        assert!(sun.disc(1.0 + daz, 0.1) > 0.0);
        assert!(sun.disc(1.0 + 1.01 * r / 0.1f64.cos(), 0.1) == 0.0);
    }

    fn hazy(visibility_m: f64, aerosol_scale_height_m: f64, rayleigh: f64) -> Extinction {
        let sky = Sky {
            rayleigh_optical_depth: rayleigh,
            aerial: Some(AerialPerspective {
                visibility_m,
                aerosol_scale_height_m,
            }),
            ..Sky::default()
        };
        sky.extinction().unwrap()
    }

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let nodes = gauss_legendre_unit(CHORD_NODES);
        assert!((nodes.iter().map(|n| n.1).sum::<f64>() - 1.0).abs() < 1e-14);
        // ∫₀¹ t^k dt = 1/(k+1) up to degree 2n − 1.
        for k in [1, 7, 20, 31] {
            let q: f64 = nodes.iter().map(|&(t, w)| w * t.powi(k)).sum();
            assert!((q - 1.0 / (k + 1) as f64).abs() < 1e-13, "{k}: {q}");
        }
    }

    #[test]
    fn visibility_is_the_total_extinction_at_550_nm() {
        // Green (549 nm) at the surface: 3.912 / V, up to (550/549)^1.3 ≈ 1.0024 on the aerosol
        // share (and (550/549)⁴ on the small Rayleigh share).
        let e = hazy(10_000.0, 1_000.0, 0.0975);
        let beta = e.coefficient_per_m(0.0);
        assert!(
            (beta[1] / (3.912 / 10_000.0) - 1.0).abs() < 3e-3,
            "{beta:?}"
        );
        assert!(beta[2] > beta[1] && beta[1] > beta[0]);
        // The aerosol share falls by e over its scale height, the Rayleigh share over 8 km.
        let up = e.coefficient_per_m(1_000.0);
        let expected =
            e.rayleigh_per_m[1] * (-1.0f64 / 8.0).exp() + e.aerosol_per_m[1] * (-1.0f64).exp();
        assert!((up[1] - expected).abs() < 1e-15);
    }

    #[test]
    fn chord_depth_matches_closed_forms() {
        // Uniform air (no Rayleigh share, aerosol scale height 1e12 m): τ = β × chord length
        // (law of cosines, independently).
        let e = hazy(5_000.0, 1e12, 0.0);
        let (r, h0, h1, d) = (6_371_000.0f64, 10.0, 300.0, 20_000.0);
        let (a, b) = (r + h0, r + h1);
        let chord = (a * a + b * b - 2.0 * a * b * (d / r).cos()).sqrt();
        let tau = e.chord_optical_depth(r, h0, h1, d);
        let beta = e.coefficient_per_m(0.0);
        for c in 0..3 {
            assert!(
                (tau[c] / (beta[c] * chord) - 1.0).abs() < 1e-6,
                "{c}: {tau:?}"
            );
        }
        // A vertical path from h0 to h1 on a flat-ish scale: ∫ β0 e^(−h/H) dh in closed form.
        let e = hazy(5_000.0, 1_000.0, 0.0975);
        let tau = e.chord_optical_depth(r, 0.0, 3_000.0, 0.0);
        let closed = |b0: f64, hs: f64| b0 * hs * (1.0 - (-3_000.0 / hs).exp());
        for c in 0..3 {
            let want = closed(e.rayleigh_per_m[c], RAYLEIGH_SCALE_HEIGHT_M)
                + closed(e.aerosol_per_m[c], 1_000.0);
            assert!((tau[c] / want - 1.0).abs() < 1e-10, "{c}: {tau:?} {want}");
        }
    }

    #[test]
    fn chord_error_for_refracted_rays_is_the_sag() {
        // A constant-curvature ray (k = κR) is exactly a straight line over an Earth of radius
        // R/(1 − k): its optical depth is the chord's over that sphere. The renderer uses the
        // chord over R instead; the difference is the documented sag error.
        let e = hazy(20_000.0, 1_000.0, 0.0975);
        let r = 6_371_000.0;
        for (k, d, bound) in [
            (0.13, 50_000.0, 0.01),
            (0.5, 50_000.0, 0.03),
            (0.13, 20_000.0, 2e-3),
        ] {
            // End at the height a horizontal ray from 10 m reaches over the effective Earth.
            let r_eff = r / (1.0 - k);
            let h1 = 10.0 + d * d / (2.0 * r_eff);
            let exact = e.chord_optical_depth(r_eff, 10.0, h1, d);
            let chord = e.chord_optical_depth(r, 10.0, h1, d);
            let relative = (chord[1] / exact[1] - 1.0).abs();
            eprintln!("k = {k}, d = {d} m: chord error {relative:.3e} of tau");
            assert!(relative < bound, "k = {k}, d = {d}: {relative:.2e}");
        }
    }

    #[test]
    fn attenuation_fades_to_the_horizon_sky() {
        let e = hazy(5_000.0, 1_000.0, 0.0975);
        let far = e.attenuate([0.0; 3], 1.0, [40.0; 3]);
        let horizon = Sky::default().radiance(0.0);
        for c in 0..3 {
            assert!((far[c] - horizon[c]).abs() < 1e-12);
        }
        assert_eq!(e.attenuate([0.3; 3], 1.0, [0.0; 3]), [0.3; 3]);
        assert_eq!(e.attenuate([0.3; 3], 1.0, [f64::NAN; 3]), horizon);
    }

    #[test]
    fn low_sun_is_reddened() {
        let sky = Sky::default();
        let t = sky.transmittance(0.0);
        assert!(t[0] > 3.0 * t[1] && t[1] > 10.0 * t[2], "{t:?}");
        let high = sky.transmittance(1.0);
        assert!(high.iter().zip(&t).all(|(h, l)| h > l));
        assert!(high[0] / high[2] < t[0] / t[2]);
    }
}
