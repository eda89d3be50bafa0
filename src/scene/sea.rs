//! Scene — the sea surface. In: the grazing angle at which a ray meets the sea, and the sky.
//! Out: linear RGB radiance of the sea there.
//!
//! Model (plausible, not a wave simulation): the sea reflects the sky with the unpolarised Fresnel
//! reflectance of water, and lets the dark water colour through the rest:
//!
//! ```text
//! g'  = √(g² + s²)                     effective grazing angle (s: typical wave-facet slope)
//! L   = F(g') · L_sky(g') + (1 − F(g')) · L_water
//! ```
//!
//! Wave facets are tilted by about s (Cox–Munk rms slopes are 0.1–0.2 rad in moderate wind; the
//! default 3° is a calm arctic sea), so the reflection is never exactly grazing: the sea stays a
//! little darker than the sky right up to the horizon, which keeps the horizon visible. The
//! reflected ray is not traced again (it would see the sky at elevation g'); reflections of cards
//! and of the sun (glitter) are not modelled.

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
    /// Typical slope of the wave facets (rad); 0 is a mirror-flat sea.
    pub wave_slope_rad: f64,
}

impl Default for Sea {
    fn default() -> Self {
        Self {
            water_rgb: [0.004, 0.012, 0.018],
            refractive_index: 1.333,
            wave_slope_rad: 3f64.to_radians(),
        }
    }
}

impl Sea {
    /// Radiance of the sea for a ray arriving at `grazing_rad`, reflecting `sky`.
    pub fn radiance(&self, grazing_rad: f64, sky: &super::sky::Sky) -> [f64; 3] {
        self.radiance_with_sky_depths(grazing_rad, sky, sky.optical_depths())
    }

    /// [`Sea::radiance`] with `sky`'s optical depths `depths` (from
    /// [`Sky::optical_depths`](super::sky::Sky::optical_depths)) computed once by the caller:
    /// the same result, cheaper per call.
    #[inline]
    pub fn radiance_with_sky_depths(
        &self,
        grazing_rad: f64,
        sky: &super::sky::Sky,
        depths: [f64; 3],
    ) -> [f64; 3] {
        let g = grazing_rad.hypot(self.wave_slope_rad);
        let f = fresnel_reflectance(g, self.refractive_index);
        let s = sky.radiance_with_depths(g, depths);
        [0, 1, 2].map(|c| f * s[c] + (1.0 - f) * self.water_rgb[c])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
