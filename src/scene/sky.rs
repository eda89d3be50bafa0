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
//! `exp(−τ_c · m(e))` with e the ray's APPARENT elevation at the camera (clamped at 0): this reddens
//! the low sun. Where the disc is seen is decided by the ray's FINAL direction, so a sun below the
//! astronomical horizon can be seen through rays that come up (Novaya Zemlya).

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
}

impl Default for Sky {
    fn default() -> Self {
        Self {
            brightness: 1.0,
            rayleigh_optical_depth: 0.0975,
            aerosol_optical_depth: 0.02,
        }
    }
}

impl Sky {
    /// Optical depth τ_c of each channel (zenith path).
    pub fn optical_depths(&self) -> [f64; 3] {
        CHANNEL_WAVELENGTHS_NM.map(|l| {
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
        let radius = 0.5 * self.angular_diameter_rad;
        if !(elevation_rad.is_finite() && azimuth_rad.is_finite()) {
            return 0.0;
        }
        // Quick reject on elevation (cheap), then the haversine distance on the sphere.
        if (elevation_rad - self.elevation_rad).abs() > radius {
            return 0.0;
        }
        let dlat = 0.5 * (elevation_rad - self.elevation_rad);
        let dlon = 0.5 * (azimuth_rad - self.azimuth_rad);
        let a = dlat.sin().powi(2)
            + elevation_rad.cos() * self.elevation_rad.cos() * dlon.sin().powi(2);
        let distance = 2.0 * a.sqrt().min(1.0).asin();
        if distance >= radius {
            return 0.0;
        }
        let s = distance / radius;
        let mu = (1.0 - s * s).sqrt();
        self.intensity * (1.0 - self.limb_darkening * (1.0 - mu))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
