//! Physical constants and unit conversions shared by every stage.
//!
//! Everything inside ghostship is SI (metres, pascals, kelvin, radians). Values cross into and out
//! of the program with their unit in the name (`height_m`, `pressure_hpa`, `temperature_c`); the
//! conversions live here so that no other module multiplies by 100 or adds 273.15 on its own.

/// Mean Earth radius used by the paper and as the default everywhere (m).
pub const EARTH_RADIUS_M: f64 = 6_371_000.0;
/// Standard gravity (m s⁻²), as used by the U.S. Standard Atmosphere 1976.
pub const STANDARD_GRAVITY_M_S2: f64 = 9.806_65;
/// Specific gas constant of dry air (J kg⁻¹ K⁻¹), US1976 value (R* / M0).
pub const DRY_AIR_GAS_CONSTANT_J_KG_K: f64 = 287.052_87;
/// Ratio of the molar masses of water vapour and dry air (ε = Mw / Md).
pub const EPSILON_WATER_DRY: f64 = 0.621_98;
/// 0 °C in kelvin.
pub const ZERO_CELSIUS_K: f64 = 273.15;
/// Standard sea-level pressure (Pa).
pub const STANDARD_PRESSURE_PA: f64 = 101_325.0;
/// Diameter of the Sun (m): 1 392 000 km, as in the paper.
pub const SUN_DIAMETER_M: f64 = 1.392e9;
/// Mean Earth–Sun distance (m): 149.6 million km.
pub const SUN_DISTANCE_M: f64 = 1.496e11;

/// Degrees Celsius → kelvin.
#[inline]
pub fn celsius_to_kelvin(temperature_c: f64) -> f64 {
    temperature_c + ZERO_CELSIUS_K
}

/// Kelvin → degrees Celsius.
#[inline]
pub fn kelvin_to_celsius(temperature_k: f64) -> f64 {
    temperature_k - ZERO_CELSIUS_K
}

/// Hectopascal → pascal.
#[inline]
pub fn hpa_to_pa(pressure_hpa: f64) -> f64 {
    pressure_hpa * 100.0
}

/// Pascal → hectopascal.
#[inline]
pub fn pa_to_hpa(pressure_pa: f64) -> f64 {
    pressure_pa / 100.0
}

/// Arc minutes per radian.
pub const ARCMIN_PER_RAD: f64 = 180.0 * 60.0 / std::f64::consts::PI;

/// Saturation vapour pressure over liquid water (Pa) at `temperature_k`, by the Magnus form of
/// Alduchov & Eskridge (1996); it is the formula radiosonde dewpoints are usually converted with,
/// so applying it to a dewpoint gives the actual vapour pressure of the sample.
#[inline]
pub fn saturation_vapour_pressure_pa(temperature_k: f64) -> f64 {
    let t_c = kelvin_to_celsius(temperature_k);
    610.94 * (17.625 * t_c / (t_c + 243.04)).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_round_trip() {
        assert_eq!(kelvin_to_celsius(celsius_to_kelvin(-12.5)), -12.5);
        assert_eq!(pa_to_hpa(hpa_to_pa(1013.25)), 1013.25);
    }

    #[test]
    fn saturation_pressure_at_triple_point_region() {
        // 0 °C: 6.1094 hPa by construction of the Magnus form; 20 °C ≈ 23.37 hPa (WMO tables 23.39).
        assert!((saturation_vapour_pressure_pa(273.15) - 610.94).abs() < 1e-9);
        let e20 = saturation_vapour_pressure_pa(293.15);
        assert!((e20 - 2337.0).abs() < 10.0, "{e20}");
    }
}
