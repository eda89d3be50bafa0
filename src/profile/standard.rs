//! Stage 2 — fit: the U.S. Standard Atmosphere 1976 as an [`AirColumn`]. In: a surface height,
//! temperature and pressure (default: 0 m, 15 °C, 1013.25 hPa). Out: dry air by height with
//! analytic derivatives, the US1976 layer shape shifted so that it passes through the given
//! surface values.

use super::hydrostatic::G_OVER_R;
use super::us1976::{US1976_EARTH_RADIUS_M, geometric_to_geopotential_m, us1976_at_geopotential};
use super::{AirColumn, AirSample, MODEL_TOP_M, ProfileError};
use crate::units::{STANDARD_PRESSURE_PA, celsius_to_kelvin};

/// US1976 as an air column (dry). Heights are geometric metres above mean sea level; the
/// temperature is the standard's plus a constant offset and the pressure the standard's times a
/// constant factor, chosen so that the surface values match (with the defaults it is the
/// standard itself). Below the surface the surface air is returned; above 86 km, the 86 km air.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StandardAtmosphere {
    surface_height_m: f64,
    sea_level_temperature_k: f64,
    sea_level_pressure_pa: f64,
}

impl Default for StandardAtmosphere {
    /// The standard itself: surface at 0 m, 288.15 K, 101 325 Pa.
    fn default() -> Self {
        StandardAtmosphere {
            surface_height_m: 0.0,
            sea_level_temperature_k: celsius_to_kelvin(15.0),
            sea_level_pressure_pa: STANDARD_PRESSURE_PA,
        }
    }
}

impl StandardAtmosphere {
    /// The US1976 shape through the given surface: `surface_height_m` (m MSL, −500…9000),
    /// `surface_temperature_k` (150…350 K) and `surface_pressure_pa` (10 000…120 000 Pa).
    pub fn with_surface(
        surface_height_m: f64,
        surface_temperature_k: f64,
        surface_pressure_pa: f64,
    ) -> Result<Self, ProfileError> {
        let bad = |name, message: String| ProfileError::BadOption { name, message };
        if !(-500.0..=9000.0).contains(&surface_height_m) {
            return Err(bad(
                "surface_height_m",
                format!("{surface_height_m} m is outside −500…9000 m"),
            ));
        }
        if !(150.0..=350.0).contains(&surface_temperature_k) {
            return Err(bad(
                "surface_temperature_k",
                format!("{surface_temperature_k} K is outside 150…350 K"),
            ));
        }
        if !(10_000.0..=120_000.0).contains(&surface_pressure_pa) {
            return Err(bad(
                "surface_pressure_pa",
                format!("{surface_pressure_pa} Pa is outside 10 000…120 000 Pa"),
            ));
        }
        let geo = geometric_to_geopotential_m(surface_height_m);
        // T is the standard plus an offset; P scales linearly with the sea-level pressure.
        let standard = us1976_at_geopotential(geo, 288.15, STANDARD_PRESSURE_PA);
        let sea_level_temperature_k = surface_temperature_k - (standard.temperature_k - 288.15);
        let unit = us1976_at_geopotential(geo, sea_level_temperature_k, 1.0);
        Ok(StandardAtmosphere {
            surface_height_m,
            sea_level_temperature_k,
            sea_level_pressure_pa: surface_pressure_pa / unit.pressure_pa,
        })
    }

    /// The surface temperature (K).
    pub fn surface_temperature_k(&self) -> f64 {
        self.air_at(self.surface_height_m).temperature_k
    }
}

impl AirColumn for StandardAtmosphere {
    fn surface_height_m(&self) -> f64 {
        self.surface_height_m
    }

    /// Dry air; a NaN height gives an all-NaN sample.
    fn air_at(&self, height_m: f64) -> AirSample {
        if height_m.is_nan() {
            return AirSample::nan();
        }
        let z = height_m.clamp(self.surface_height_m, MODEL_TOP_M);
        let geo = geometric_to_geopotential_m(z);
        let air = us1976_at_geopotential(
            geo,
            self.sea_level_temperature_k,
            self.sea_level_pressure_pa,
        );
        // dH/dz = (r0 / (r0 + z))²
        let ratio = US1976_EARTH_RADIUS_M / (US1976_EARTH_RADIUS_M + z);
        let dgeo_dz = ratio * ratio;
        AirSample {
            temperature_k: air.temperature_k,
            dtemperature_dh_k_per_m: air.dtemperature_dh_k_per_m * dgeo_dz,
            pressure_pa: air.pressure_pa,
            dpressure_dh_pa_per_m: -air.pressure_pa * G_OVER_R / air.temperature_k * dgeo_dz,
            vapour_pressure_pa: 0.0,
            dvapour_pressure_dh_pa_per_m: 0.0,
        }
    }

    /// The US1976 layer bases (dT/dh jumps there) and the 86 km top of the model.
    fn breaks_m(&self) -> Vec<f64> {
        super::normalise_breaks(
            super::us1976::layer_bases_geometric_m()
                .chain([MODEL_TOP_M])
                .filter(|&h| h > self.surface_height_m)
                .collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Geometric height of a geopotential height (m).
    fn geometric(geo: f64) -> f64 {
        US1976_EARTH_RADIUS_M * geo / (US1976_EARTH_RADIUS_M - geo)
    }

    #[test]
    fn default_matches_the_coesa_table() {
        // COESA 1976 (geopotential km → T, P): 0: 288.15 K, 1013.25 hPa; 11: 216.65, 226.32;
        // 20: 216.65, 54.748; 32: 228.65, 8.6801; 47: 270.65, 1.1091.
        // pressures within one unit of the table's last digit to 32 km (README's accuracy table).
        let s = StandardAtmosphere::default();
        for (geo, t, p_hpa, tol) in [
            (0.0, 288.15, 1013.25, 1e-6),
            (11_000.0, 216.65, 226.32, 0.01),
            (20_000.0, 216.65, 54.748, 0.001),
            (32_000.0, 228.65, 8.6801, 0.0001),
            (47_000.0, 270.65, 1.1091, 0.0005),
        ] {
            let a = s.air_at(geometric(geo));
            assert!(
                (a.temperature_k - t).abs() < 1e-6,
                "{geo}: {}",
                a.temperature_k
            );
            assert!(
                (a.pressure_pa / 100.0 - p_hpa).abs() < tol,
                "{geo}: {}",
                a.pressure_pa
            );
            assert_eq!(a.vapour_pressure_pa, 0.0);
        }
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let s = StandardAtmosphere::with_surface(120.0, 263.15, 99_000.0).unwrap();
        for z in [200.0, 1500.0, 9000.0, 25_000.0, 60_000.0] {
            let dz = 0.01;
            let (a, b, c) = (s.air_at(z - dz), s.air_at(z), s.air_at(z + dz));
            let dt = (c.temperature_k - a.temperature_k) / (2.0 * dz);
            let dp = (c.pressure_pa - a.pressure_pa) / (2.0 * dz);
            assert!((dt - b.dtemperature_dh_k_per_m).abs() < 1e-8, "{z}");
            assert!(
                (dp - b.dpressure_dh_pa_per_m).abs() < 1e-6 * b.dpressure_dh_pa_per_m.abs(),
                "{z}: {dp} {}",
                b.dpressure_dh_pa_per_m
            );
        }
    }

    #[test]
    fn surface_values_are_honoured_and_the_ground_is_not_extrapolated() {
        let s = StandardAtmosphere::with_surface(120.0, 263.15, 99_000.0).unwrap();
        let a = s.air_at(120.0);
        assert!((a.temperature_k - 263.15).abs() < 1e-9);
        assert!((a.pressure_pa - 99_000.0).abs() < 1e-6);
        assert_eq!(s.air_at(-50.0), a);
        assert!(s.air_at(f64::NAN).temperature_k.is_nan());
        assert!(StandardAtmosphere::with_surface(0.0, 50.0, 1e5).is_err());
        assert!(StandardAtmosphere::with_surface(f64::NAN, 280.0, 1e5).is_err());
    }
}
