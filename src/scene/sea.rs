//! Scene — the sea surface. In: the grazing angle at which a ray meets the sea, what the
//! reflected rays see (the renderer supplies it), and the sun. Out: linear RGB radiance of the
//! sea there: Fresnel-weighted reflection plus the water colour.
//!
//! Model: wave facets with the isotropic Gaussian slope distribution of Cox & Munk (1954), mean
//! square slope σ² = 0.003 + 5.12·10⁻³ U (U: wind speed, m/s; [`cox_munk_mean_square_slope`]).
//!
//! * **Mirror images and sky** ([`Sea::facet_nodes`]): a ray meeting the sea at grazing angle g
//!   sees facets tilted towards it by s along its vertical plane (s ~ N(0, σ²/2), only facets
//!   with g + s > 0 are visible, weighted by their projected area ∝ sin(g + s)). A facet
//!   reflects the ray upwards at elevation g + 2s (clamped to ≥ 0: a ray sent back into the sea
//!   is taken to skim it) with the Fresnel reflectance at its own grazing angle g + s. The sea is
//!   `Σ wᵢ (Fᵢ Lᵢ + (1 − Fᵢ) L_water)` over a few such facet classes, Lᵢ being what the reflected
//!   ray sees (sky, sun, cards). σ = 0 is a mirror: one class, the reflected ray at g. For the
//!   mirror images of cards and terrain, whose Lᵢ changes abruptly with the reflected elevation,
//!   the renderer integrates the density itself ([`Sea::facet_density`]) over intervals of
//!   slopes instead of sampling it at a few classes.
//! * **Sun glitter** ([`Sea::glint_per_irradiance`], σ > 0): the sun is too small to be found by
//!   a few reflected rays, so its reflection is the Cox–Munk glint radiance
//!   `L = E ρ(ω) p(z_x, z_y) / (4 cos θ_v cos⁴ β)` (E: solar irradiance normal to the beam, β the
//!   tilt of the facet that mirrors the sun into the ray, ω the incidence angle on it, θ_v the
//!   ray's zenith angle at the sea), capped at ρ × the sun's own radiance (no facet shows the sun
//!   brighter than a mirror would). Shadowing of facets by waves is not modelled.

use serde::Serialize;

/// Unpolarised Fresnel reflectance of a smooth interface from air (n = 1) into a medium of
/// refractive index `n`, for a ray at `grazing_rad` to the surface (incidence angle π/2 − grazing).
///
/// `n = 1` (no interface) reflects nothing. Where both Fresnel denominators vanish (exactly
/// grazing incidence with n = 1 handled above, or with n < 1 at total internal reflection) the
/// limit is total reflection, 1; the result is never NaN for finite `grazing_rad` and `n` > 0.
pub fn fresnel_reflectance(grazing_rad: f64, n: f64) -> f64 {
    if n == 1.0 {
        return 0.0;
    }
    let cos_i = grazing_rad.clamp(0.0, std::f64::consts::FRAC_PI_2).sin();
    let sin_i2 = 1.0 - cos_i * cos_i;
    let sin_t2 = sin_i2 / (n * n);
    let cos_t = (1.0 - sin_t2).max(0.0).sqrt();
    let (den_s, den_p) = (cos_i + n * cos_t, cos_t + n * cos_i);
    if den_s <= 0.0 || den_p <= 0.0 {
        return 1.0;
    }
    let rs = (cos_i - n * cos_t) / den_s;
    let rp = (cos_t - n * cos_i) / den_p;
    0.5 * (rs * rs + rp * rp)
}

/// Sea-surface parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sea {
    /// Radiance of the light coming up out of the water (linear RGB, film units: 1 = horizon sky).
    pub water_rgb: [f64; 3],
    /// Refractive index of sea water (1.333 in the visible; 1.34 for salt water).
    pub refractive_index: f64,
    /// Root-mean-square slope of the wave facets as an angle, atan σ (rad; σ² the Cox–Munk mean
    /// square slope, summed over both directions); 0 is a mirror-flat sea.
    pub wave_slope_rad: f64,
    /// The wind speed (m/s) `wave_slope_rad` was derived from by Cox–Munk; `None` when the slope
    /// was given directly.
    pub wind_speed_m_s: Option<f64>,
    /// Whether the renderer shows the cards' mirror images and the sun's glitter on the sea
    /// (`false`: the sky reflection alone, the cheaper model before they existed).
    pub reflections: bool,
}

impl Default for Sea {
    fn default() -> Self {
        Self {
            water_rgb: [0.004, 0.012, 0.018],
            refractive_index: 1.333,
            wave_slope_rad: cox_munk_rms_slope_rad(0.0),
            wind_speed_m_s: Some(0.0),
            reflections: true,
        }
    }
}

/// Cox & Munk (1954) clean-sea mean square slope σ² = 0.003 + 5.12·10⁻³ U for a wind speed U
/// (m/s, at 12.5 m above the sea; negative speeds count as 0), summed over the up- and
/// cross-wind directions.
pub fn cox_munk_mean_square_slope(wind_speed_m_s: f64) -> f64 {
    0.003 + 5.12e-3 * wind_speed_m_s.max(0.0)
}

/// The Cox–Munk rms slope at `wind_speed_m_s` as an angle, atan √σ² (rad).
pub fn cox_munk_rms_slope_rad(wind_speed_m_s: f64) -> f64 {
    cox_munk_mean_square_slope(wind_speed_m_s).sqrt().atan()
}

/// The isotropic Cox–Munk slope density p(z_x, z_y) = exp(−(z_x² + z_y²)/σ²) / (π σ²) at a facet
/// of tilt β (`tan2_tilt` = tan² β = z_x² + z_y²), for mean square slope `mean_square_slope`.
pub fn cox_munk_pdf(tan2_tilt: f64, mean_square_slope: f64) -> f64 {
    if mean_square_slope <= 0.0 {
        return 0.0;
    }
    (-tan2_tilt / mean_square_slope).exp() / (std::f64::consts::PI * mean_square_slope)
}

/// The along-ray slopes [lo, hi] = [max(−g, −4σ′), 4σ′] (rad) of the facets a ray meeting the
/// sea at grazing angle `grazing_rad` sees, for rms along-ray slope `sigma_along` (σ′): steeper
/// facets than −g face away from the ray, and beyond ±4σ′ lies 6·10⁻⁵ of the slopes.
pub fn facet_slope_range(grazing_rad: f64, sigma_along: f64) -> (f64, f64) {
    ((-grazing_rad).max(-4.0 * sigma_along), 4.0 * sigma_along)
}

/// One class of wave facets seen by a ray meeting the sea ([`Sea::facet_nodes`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FacetNode {
    /// Elevation of the reflected ray above the local horizontal (rad, ≥ 0).
    pub reflected_elevation_rad: f64,
    /// Share of the visible sea surface (the weights of a set sum to 1; 0: unused node).
    pub weight: f64,
    /// Fresnel reflectance at the facet.
    pub reflectance: f64,
}

impl Sea {
    /// Radiance of the sea for a ray arriving at `grazing_rad`, reflecting `sky` (no sun, no
    /// cards).
    pub fn radiance(&self, grazing_rad: f64, sky: &super::sky::Sky) -> [f64; 3] {
        self.radiance_with_sky_depths(grazing_rad, sky, sky.optical_depths())
    }

    /// [`Sea::radiance`] with `sky`'s optical depths `depths` (from
    /// [`Sky::optical_depths`](super::sky::Sky::optical_depths)) computed once by the caller:
    /// the same result, cheaper per call.
    pub fn radiance_with_sky_depths(
        &self,
        grazing_rad: f64,
        sky: &super::sky::Sky,
        depths: [f64; 3],
    ) -> [f64; 3] {
        self.radiance_reflecting(grazing_rad, |e| sky.radiance_with_depths(e, depths))
    }

    /// Radiance of the sea for a ray arriving at `grazing_rad` when a reflected ray leaving at
    /// elevation e sees `seen(e)` (the facet classes of [`Sea::facet_nodes`], 24 of them).
    pub fn radiance_reflecting(
        &self,
        grazing_rad: f64,
        seen: impl Fn(f64) -> [f64; 3],
    ) -> [f64; 3] {
        let mut out = [0.0; 3];
        for node in self.facet_nodes::<24>(grazing_rad) {
            if node.weight == 0.0 {
                continue;
            }
            let l = seen(node.reflected_elevation_rad);
            let f = node.reflectance;
            for c in 0..3 {
                out[c] += node.weight * (f * l[c] + (1.0 - f) * self.water_rgb[c]);
            }
        }
        out
    }

    /// `K` classes of the facets a ray meeting the sea at `grazing_rad` sees (see the module
    /// docs): along-ray slopes s at the midpoints of K equal cells over [max(−g, −4σ′), 4σ′]
    /// (σ′ = σ/√2), weighted by sin(g + s)·exp(−s²/2σ′²) and normalised. A mirror sea (σ = 0),
    /// or a non-finite grazing angle (taken as 0), gives one node at g with weight 1.
    pub fn facet_nodes<const K: usize>(&self, grazing_rad: f64) -> [FacetNode; K] {
        let half_pi = std::f64::consts::FRAC_PI_2;
        let g = if grazing_rad.is_finite() {
            grazing_rad.clamp(0.0, half_pi)
        } else {
            0.0
        };
        let n = self.refractive_index;
        let mut nodes = [FacetNode::default(); K];
        let sigma_along = self.wave_slope_rad.tan() * std::f64::consts::FRAC_1_SQRT_2;
        if K == 0 {
            return nodes;
        }
        if !(sigma_along > 0.0 && sigma_along.is_finite()) {
            nodes[0] = FacetNode {
                reflected_elevation_rad: g,
                weight: 1.0,
                reflectance: fresnel_reflectance(g, n),
            };
            return nodes;
        }
        let (lo, hi) = facet_slope_range(g, sigma_along);
        let step = (hi - lo) / K as f64;
        let mut total = 0.0;
        for (i, node) in nodes.iter_mut().enumerate() {
            let s = lo + (i as f64 + 0.5) * step;
            let (w, reflectance) = self.facet_density(g, s, sigma_along);
            total += w;
            *node = FacetNode {
                reflected_elevation_rad: (g + 2.0 * s).clamp(0.0, half_pi),
                weight: w,
                reflectance,
            };
        }
        if total > 0.0 {
            for node in &mut nodes {
                node.weight /= total;
            }
        } else {
            // Exactly grazing: no facet area faces the ray; the limit is the first class.
            nodes[0].weight = 1.0;
        }
        nodes
    }

    /// The rms along-ray slope σ′ = tan(wave slope)/√2 of the facets (0 for a mirror sea).
    pub fn along_ray_slope(&self) -> f64 {
        self.wave_slope_rad.tan() * std::f64::consts::FRAC_1_SQRT_2
    }

    /// The facets of along-ray slope `s` (rad) a ray meeting the sea at `grazing_rad` (in
    /// [0, π/2]) sees, for rms along-ray slope `sigma_along` ([`Sea::along_ray_slope`], > 0):
    /// their unnormalised share of the visible surface, sin(g + s)·exp(−s²/2σ′²) (g + s clamped
    /// to [0, π/2]), and their Fresnel reflectance. [`Sea::facet_nodes`] is the midpoint rule of
    /// this density over [`facet_slope_range`]; the renderer integrates it over cells of slopes.
    pub fn facet_density(&self, grazing_rad: f64, s: f64, sigma_along: f64) -> (f64, f64) {
        let facet_grazing = (grazing_rad + s).clamp(0.0, std::f64::consts::FRAC_PI_2);
        let w = facet_grazing.sin() * (-0.5 * (s / sigma_along).powi(2)).exp();
        (w, fresnel_reflectance(facet_grazing, self.refractive_index))
    }

    /// Cox–Munk sun glint (see the module docs) per unit solar irradiance normal to the beam:
    /// the radiance the sea sends along a ray that meets it at `grazing_rad`, from a sun at
    /// elevation `sun_elevation_rad` above the local horizontal and azimuth `sun_azimuth_rad`
    /// relative to the ray's own horizontal direction (0: the sun straight ahead of the ray). 0
    /// for a mirror sea (its sun is a mirror image), a sun below the local horizon, or a grazing
    /// angle ≤ 0.
    pub fn glint_per_irradiance(
        &self,
        grazing_rad: f64,
        sun_elevation_rad: f64,
        sun_azimuth_rad: f64,
    ) -> f64 {
        self.glint_geometry(grazing_rad)
            .per_irradiance(sun_elevation_rad, sun_azimuth_rad)
    }

    /// What [`Self::glint_per_irradiance`] needs of the sea and of the grazing angle, worked out
    /// once for many suns or azimuths (the same values).
    pub fn glint_geometry(&self, grazing_rad: f64) -> GlintGeometry {
        GlintGeometry {
            sigma2: self.wave_slope_rad.tan().powi(2),
            grazing_rad,
            sin_grazing: grazing_rad.sin(),
            cos_grazing: grazing_rad.cos(),
            refractive_index: self.refractive_index,
        }
    }

    /// Whether a ray meeting the sea at `grazing_rad` can show a glint of relative size above
    /// e⁻⁴⁰ from a sun at local elevation within `sun_elevation_rad` (lo, hi): the facet that
    /// mirrors it, tilted at least |e − g|/2, is within ≈ 9σ′ of level.
    pub fn may_glint(&self, grazing_rad: f64, sun_elevation_rad: (f64, f64)) -> bool {
        let sigma2 = self.wave_slope_rad.tan().powi(2);
        if !(sigma2 > 0.0 && grazing_rad > 0.0 && sun_elevation_rad.1 > 0.0) {
            return false;
        }
        let (lo, hi) = sun_elevation_rad;
        let gap = if grazing_rad < lo {
            lo - grazing_rad
        } else if grazing_rad > hi {
            grazing_rad - hi
        } else {
            0.0
        };
        (0.5 * gap).tan().powi(2) / sigma2 < 40.0
    }

    /// Whether [`Self::may_glint`] may hold for some grazing angle in `grazing_rad` (lo, hi)
    /// with a sun range inside `sun_elevation_rad`: when this is false, it is false for every
    /// such pair (the gap between the ranges is at most the gap between any two of their
    /// points, and the test only loosens as the gap narrows).
    pub fn may_glint_range(&self, grazing_rad: (f64, f64), sun_elevation_rad: (f64, f64)) -> bool {
        let sigma2 = self.wave_slope_rad.tan().powi(2);
        if !(sigma2 > 0.0 && grazing_rad.1 > 0.0 && sun_elevation_rad.1 > 0.0) {
            return false;
        }
        let gap = (grazing_rad.0 - sun_elevation_rad.1)
            .max(sun_elevation_rad.0 - grazing_rad.1)
            .max(0.0);
        (0.5 * gap).tan().powi(2) / sigma2 < 40.0
    }
}

/// A sea and one grazing angle, for [`Sea::glint_per_irradiance`] ([`Sea::glint_geometry`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlintGeometry {
    /// tan² of the wave slope: the facet slopes' variance.
    sigma2: f64,
    grazing_rad: f64,
    sin_grazing: f64,
    cos_grazing: f64,
    refractive_index: f64,
}

impl GlintGeometry {
    /// [`Sea::glint_per_irradiance`] at this grazing angle.
    pub fn per_irradiance(&self, sun_elevation_rad: f64, sun_azimuth_rad: f64) -> f64 {
        let (sigma2, g) = (self.sigma2, self.grazing_rad);
        if !(sigma2 > 0.0 && g > 0.0 && sun_elevation_rad > 0.0) {
            return 0.0;
        }
        let (se, ce) = sun_elevation_rad.sin_cos();
        let (sa, ca) = sun_azimuth_rad.sin_cos();
        // Towards the sun, and back along the ray towards the camera: (forward, right, up).
        let sun = [ce * ca, ce * sa, se];
        let view = [-self.cos_grazing, 0.0, self.sin_grazing];
        let h = [sun[0] + view[0], sun[1] + view[1], sun[2] + view[2]];
        let norm = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
        if norm.is_nan() || norm <= 0.0 || h[2] <= 0.0 {
            return 0.0;
        }
        let cos_tilt = h[2] / norm;
        let tan2 = (h[0] * h[0] + h[1] * h[1]) / (h[2] * h[2]);
        let cos_incidence = (h[0] * sun[0] + h[1] * sun[1] + h[2] * sun[2]) / norm;
        let rho = fresnel_reflectance(cos_incidence.clamp(-1.0, 1.0).asin(), self.refractive_index);
        rho * cox_munk_pdf(tan2, sigma2) / (4.0 * self.sin_grazing * cos_tilt.powi(4))
    }

    /// Upper bounds on [`Self::per_irradiance`] for every sun elevation in `sun_elevation_rad`
    /// (lo, hi): the terms of the elevation range, worked out once for many azimuth ranges
    /// ([`GlintBound::at`]).
    pub fn bound_over(&self, sun_elevation_rad: (f64, f64)) -> GlintBound {
        let (e_lo, e_hi) = sun_elevation_rad;
        let (sigma2, g) = (self.sigma2, self.grazing_rad);
        let (zero, unbounded) = if e_lo.is_nan() || e_hi.is_nan() || e_lo > e_hi {
            (false, true)
        } else if !(sigma2 > 0.0 && g > 0.0 && e_hi > 0.0) {
            (true, false)
        } else {
            (false, e_hi > std::f64::consts::FRAC_PI_2)
        };
        // Elevations ≤ 0 give 0; the rest lie in [max(e_lo, 0), e_hi] ⊂ [0, π/2].
        let e_lo = e_lo.max(0.0);
        let hz = e_hi.sin() + self.sin_grazing;
        GlintBound {
            zero,
            unbounded,
            cos_elevation: (e_hi.cos(), e_lo.cos()),
            cos_grazing: self.cos_grazing,
            inv_hz2: 1.0 / (hz * hz),
            sigma2,
            least_tan2: 2.0 * sigma2 - 1.0,
            // A relative margin for rounding; at low grazing angles T comes from a difference of
            // close cosines and may be off by more, which the callers' far larger margin covers.
            scale: (1.0 + 1e-9) / (4.0 * std::f64::consts::PI * sigma2 * self.sin_grazing),
        }
    }
}

/// Upper bounds on [`GlintGeometry::per_irradiance`] over a range of sun elevations and a range
/// of azimuths ([`GlintGeometry::bound_over`], [`Self::at`]).
///
/// With the half vector h = sun + view of [`GlintGeometry::per_irradiance`], its horizontal
/// part is H² = cos²e − 2 cos e cos g cos φ + cos²g and its vertical hz = sin e + sin g, so the
/// tilt's tan² is T = H²/hz², 1/cos⁴(tilt) = (1 + T)², and the factor is
/// ρ · exp(−T/σ²) (1 + T)² / (4π σ² sin g) with ρ ≤ 1. Over the ranges H² is at least the
/// squared gap between the ranges of cos e and cos g cos φ plus cos²g (1 − max cos²φ), hz at
/// most sin e_hi + sin g, and exp(−T/σ²) (1 + T)² falls with T beyond T = 2σ² − 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlintBound {
    /// The factor is 0 for every elevation of the range.
    zero: bool,
    /// No bound is derived (an elevation range past 90°, or not a range).
    unbounded: bool,
    /// Bounds (lo, hi) on cos e.
    cos_elevation: (f64, f64),
    cos_grazing: f64,
    /// 1 / (the greatest hz)².
    inv_hz2: f64,
    sigma2: f64,
    /// T below which exp(−T/σ²) (1 + T)² still rises.
    least_tan2: f64,
    /// The factor's constant 1 / (4π σ² sin g), with a margin.
    scale: f64,
}

impl GlintBound {
    /// An upper bound on the factor for every elevation of the range and every azimuth whose
    /// cosine is in `cos_azimuth` (lo, hi); +∞ where none is derived.
    #[inline]
    pub fn at(&self, cos_azimuth: (f64, f64)) -> f64 {
        let (c_lo, c_hi) = cos_azimuth;
        if self.unbounded || c_lo.is_nan() || c_hi.is_nan() || c_lo > c_hi {
            return f64::INFINITY;
        }
        if self.zero {
            return 0.0;
        }
        let (ce_lo, ce_hi) = self.cos_elevation;
        let (p_lo, p_hi) = (self.cos_grazing * c_lo, self.cos_grazing * c_hi);
        let gap = (ce_lo - p_hi).max(p_lo - ce_hi).max(0.0);
        let most_cos2 = (c_lo * c_lo).max(c_hi * c_hi).min(1.0);
        let h2 = gap * gap + self.cos_grazing * self.cos_grazing * (1.0 - most_cos2);
        let t = (h2 * self.inv_hz2).max(self.least_tan2);
        self.scale * (-t / self.sigma2).exp() * (1.0 + t) * (1.0 + t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_range_test_for_glint_holds_wherever_a_point_in_the_ranges_may_glint() {
        // Grazing and sun ranges from −2° to 10° in 0.25° steps: wherever the range test
        // says no, every point of the ranges says no too.
        let sea = Sea::default();
        let deg = |i: i32| f64::from(i) * 0.25f64.to_radians();
        let (mut refused, mut checked) = (0, 0);
        for g0 in -8..40 {
            for g1 in g0..(g0 + 6).min(40) {
                for s0 in -8..40 {
                    let s1 = s0 + 3;
                    let (g, sun) = ((deg(g0), deg(g1)), (deg(s0), deg(s1)));
                    if sea.may_glint_range(g, sun) {
                        continue;
                    }
                    refused += 1;
                    for k in 0..=4 {
                        let x = g.0 + (g.1 - g.0) * f64::from(k) / 4.0;
                        for j in 0..=4 {
                            let e = sun.0 + (sun.1 - sun.0) * f64::from(j) / 4.0;
                            checked += 1;
                            assert!(!sea.may_glint(x, (e, e)), "{x} {e}");
                            assert!(!sea.may_glint(x, (sun.0, e.max(sun.0))), "{x} {e}");
                        }
                    }
                }
            }
        }
        assert!(refused > 100 && checked > 1000, "{refused} {checked}");
    }

    #[test]
    fn the_glint_bound_holds_over_its_ranges_and_is_the_factor_over_a_point() {
        let deg = f64::to_radians;
        let mut checked = 0;
        // Winds of 0.5, 5 and 14 m/s, and the steepest slopes a scene accepts (40° and 45°:
        // σ² up to 1, where exp(−T/σ²)(1 + T)² rises up to T = 2σ² − 1).
        let slopes = [0.5, 5.0, 14.0].map(cox_munk_rms_slope_rad);
        for wave_slope_rad in slopes.into_iter().chain([deg(40.0), deg(45.0)]) {
            let wind = wave_slope_rad.to_degrees();
            let sea = Sea {
                wave_slope_rad,
                ..Sea::default()
            };
            for grazing in [0.01, 0.2, 1.2, 2.0, 20.0, 80.0] {
                let geometry = sea.glint_geometry(deg(grazing));
                for e_lo in [-1.0, 0.0, 0.05, 0.5, 1.2, 5.0, 40.0, 85.0] {
                    for e_width in [0.0, 0.005, 0.5, 5.0] {
                        let e = (deg(e_lo), deg((e_lo + e_width).min(90.0)));
                        let bound = geometry.bound_over(e);
                        for c_lo in [-1.0f64, -0.3, 0.5, 0.99, 0.999_99, 1.0] {
                            for c_width in [0.0f64, 1e-6, 1e-3, 0.3] {
                                let c = (c_lo, (c_lo + c_width).min(1.0));
                                let most = bound.at(c);
                                for i in 0..=6 {
                                    let se = e.0 + (e.1 - e.0) * f64::from(i) / 6.0;
                                    for j in 0..=6 {
                                        let ca = c.0 + (c.1 - c.0) * f64::from(j) / 6.0;
                                        for phi in [ca.acos(), -ca.acos()] {
                                            let k = geometry.per_irradiance(se, phi);
                                            checked += 1;
                                            assert!(
                                                k <= most,
                                                "{wind} {grazing} {se} {ca}: {k} > {most}"
                                            );
                                        }
                                    }
                                }
                                // Over a point, the factor up to its Fresnel reflectance (at
                                // least 0.02, at normal incidence), where σ² < ½ (the bound
                                // is then the factor's own expression but for ρ).
                                let calm = wave_slope_rad.tan().powi(2) < 0.5;
                                if calm && e_width == 0.0 && c_width == 0.0 {
                                    let k = geometry.per_irradiance(e.0, c.0.acos());
                                    if k > 1e-300 {
                                        assert!(
                                            most <= 51.0 * k,
                                            "{wind} {grazing} {e:?} {c:?}: {most} vs {k}"
                                        );
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(checked > 2_000_000, "{checked}");
        let sea = Sea::default();
        let geometry = sea.glint_geometry(0.01);
        // No bound past the zenith, or over NaN ranges; none needed below the horizon or over a
        // mirror sea.
        assert_eq!(
            geometry.bound_over((0.1, 1.6)).at((0.0, 1.0)),
            f64::INFINITY
        );
        assert_eq!(
            geometry.bound_over((f64::NAN, 0.1)).at((0.0, 1.0)),
            f64::INFINITY
        );
        assert_eq!(
            geometry.bound_over((0.0, 0.1)).at((f64::NAN, 1.0)),
            f64::INFINITY
        );
        assert_eq!(geometry.bound_over((-0.2, -0.1)).at((0.0, 1.0)), 0.0);
        let mirror = Sea {
            wave_slope_rad: 0.0,
            ..Sea::default()
        };
        assert_eq!(
            mirror
                .glint_geometry(0.01)
                .bound_over((0.0, 0.1))
                .at((0.0, 1.0)),
            0.0
        );
    }

    #[test]
    fn fresnel_limits() {
        // Normal incidence: ((n−1)/(n+1))² = 0.02037 for n = 1.333.
        let r0 = fresnel_reflectance(std::f64::consts::FRAC_PI_2, 1.333);
        assert!((r0 - (0.333f64 / 2.333).powi(2)).abs() < 1e-12);
        // Grazing incidence: total reflection.
        assert!((fresnel_reflectance(0.0, 1.333) - 1.0).abs() < 1e-12);
        // Brewster angle atan(n) from the normal: rp = 0, so R = rs²/2.
        let brewster_incidence = 1.333f64.atan();
        let g = std::f64::consts::FRAC_PI_2 - brewster_incidence;
        let cos_i = brewster_incidence.cos();
        let cos_t = (1.0 - brewster_incidence.sin().powi(2) / 1.333f64.powi(2)).sqrt();
        let rs = (cos_i - 1.333 * cos_t) / (cos_i + 1.333 * cos_t);
        assert!((fresnel_reflectance(g, 1.333) - 0.5 * rs * rs).abs() < 1e-12);
    }

    #[test]
    fn fresnel_is_finite_at_the_edges_of_the_scene_ranges() {
        // The scene accepts refractive_index = 1 and wave_slope_deg = 0: exactly grazing rays
        // on such a "sea" gave 0/0 = NaN, which the renderer replaced by the fallback colour.
        assert_eq!(fresnel_reflectance(0.0, 1.0), 0.0);
        for g in [0.0, 0.1, 1.0, std::f64::consts::FRAC_PI_2] {
            assert_eq!(fresnel_reflectance(g, 1.0), 0.0, "{g}");
        }
        let sea = Sea {
            refractive_index: 1.0,
            wave_slope_rad: 0.0,
            ..Sea::default()
        };
        let sky = super::super::sky::Sky::default();
        assert!(sea.radiance(0.0, &sky).iter().all(|v| v.is_finite()));
        // Total internal reflection side (n < 1, only reachable through the API): 1 at grazing.
        assert_eq!(fresnel_reflectance(0.0, 0.75), 1.0);
        // Ranges of the scene file: finite everywhere.
        for i in 0..=100 {
            let n = 1.0 + 2.0 * i as f64 / 100.0;
            for j in 0..=90 {
                let r = fresnel_reflectance((j as f64).to_radians(), n);
                assert!((0.0..=1.0).contains(&r), "n={n} g={j}°: {r}");
            }
        }
    }

    #[test]
    fn sea_darkens_away_from_horizon_but_never_exceeds_sky() {
        let sky = super::super::sky::Sky::default();
        let sea = Sea::default();
        let near = sea.radiance(0.0, &sky);
        let steep = sea.radiance(0.5, &sky);
        assert!(near[1] > steep[1]);
        assert!(near[1] < sky.radiance(0.0)[1]);
    }

    #[test]
    fn cox_munk_slopes_follow_the_published_formula() {
        // Cox & Munk (1954), clean surface: σ² = 0.003 + 5.12e-3 U ± 0.004, U in m/s at 12.5 m.
        for (u, sigma2) in [(0.0, 0.003), (5.0, 0.0286), (10.0, 0.0542), (14.0, 0.07468)] {
            assert!(
                (cox_munk_mean_square_slope(u) - sigma2).abs() < 1e-12,
                "{u}"
            );
            let angle = cox_munk_rms_slope_rad(u);
            assert!((angle.tan().powi(2) - sigma2).abs() < 1e-12, "{u}");
        }
        assert_eq!(cox_munk_mean_square_slope(-3.0), 0.003);
        // The isotropic density integrates to 1 over the slope plane (midpoint rule on ±6σ).
        let sigma2 = cox_munk_mean_square_slope(7.0);
        let (n, half) = (600, 6.0 * sigma2.sqrt());
        let step = 2.0 * half / n as f64;
        let mut total = 0.0;
        for i in 0..n {
            for j in 0..n {
                let zx = -half + (i as f64 + 0.5) * step;
                let zy = -half + (j as f64 + 0.5) * step;
                total += cox_munk_pdf(zx * zx + zy * zy, sigma2) * step * step;
            }
        }
        assert!((total - 1.0).abs() < 1e-6, "{total}");
        // Each slope component has variance σ²/2.
        let mut second = 0.0;
        for i in 0..n {
            let zx = -half + (i as f64 + 0.5) * step;
            for j in 0..n {
                let zy = -half + (j as f64 + 0.5) * step;
                second += zx * zx * cox_munk_pdf(zx * zx + zy * zy, sigma2) * step * step;
            }
        }
        assert!((second / (0.5 * sigma2) - 1.0).abs() < 1e-4, "{second}");
    }

    #[test]
    fn facet_nodes_are_normalised_and_a_mirror_reflects_at_the_grazing_angle() {
        let mirror = Sea {
            wave_slope_rad: 0.0,
            ..Sea::default()
        };
        let n = mirror.facet_nodes::<8>(0.01);
        assert_eq!(n[0].reflected_elevation_rad, 0.01);
        assert_eq!(n[0].weight, 1.0);
        assert!(n[1..].iter().all(|n| n.weight == 0.0));
        assert_eq!(n[0].reflectance, fresnel_reflectance(0.01, 1.333));
        let rough = Sea::default();
        for g in [0.0, 0.001, 0.05, 0.5, 1.5] {
            let n = rough.facet_nodes::<24>(g);
            let total: f64 = n.iter().map(|n| n.weight).sum();
            assert!((total - 1.0).abs() < 1e-12, "{g}");
            assert!(n.iter().all(|n| n.reflected_elevation_rad >= 0.0));
        }
        // Far from grazing the mean reflected elevation is the mirror direction.
        let n = rough.facet_nodes::<24>(0.5);
        let mean: f64 = n.iter().map(|n| n.weight * n.reflected_elevation_rad).sum();
        assert!((mean - 0.5).abs() < 0.02, "{mean}");
    }

    #[test]
    fn glint_peaks_at_the_specular_direction() {
        // Sun straight ahead of the ray at 20°: where the ray meets the sea at 20° a level
        // facet mirrors the sun, and the glint is symmetric in the sun's azimuth.
        let sea = Sea {
            wave_slope_rad: cox_munk_rms_slope_rad(2.0),
            ..Sea::default()
        };
        let e = 20f64.to_radians();
        // At the specular point the Cox–Munk radiance is ρ(incidence) p(0) / (4 cos θ_v).
        let rho = fresnel_reflectance(e, 1.333);
        let expected =
            rho / (std::f64::consts::PI * cox_munk_mean_square_slope(2.0)) / (4.0 * e.sin());
        assert!((sea.glint_per_irradiance(e, e, 0.0) / expected - 1.0).abs() < 1e-9);
        let (l, r) = (
            sea.glint_per_irradiance(0.3, e, 0.1),
            sea.glint_per_irradiance(0.3, e, -0.1),
        );
        assert!((l - r).abs() <= 1e-12 * l);
        assert!(sea.glint_per_irradiance(0.3, e, 0.1) < sea.glint_per_irradiance(0.3, e, 0.0));
        assert!(sea.may_glint(e, (e, e)));
        assert!(!sea.may_glint(0.01, (1.5, 1.5)));
    }
}
