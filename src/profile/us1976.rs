//! U.S. Standard Atmosphere 1976 below 86 km (the seven geopotential layers with linear lapse).
//!
//! In: a height. Out: temperature, pressure and the temperature gradient of the standard
//! atmosphere there. Used as the background above a sounding's top and as the `us1976` atmosphere.
//! Written by hand (about forty lines): the crates that offer it are young, undocumented or pull in
//! much more than these seven layers.

use crate::units::{DRY_AIR_GAS_CONSTANT_J_KG_K, STANDARD_GRAVITY_M_S2, STANDARD_PRESSURE_PA};

/// Effective Earth radius of the US1976 geopotential definition (m).
pub const US1976_EARTH_RADIUS_M: f64 = 6_356_766.0;
/// Sea-level temperature of the standard (K).
pub const US1976_SEA_LEVEL_TEMPERATURE_K: f64 = 288.15;
/// Geopotential height of the top of the model (m′), 86 km geometric.
pub const US1976_TOP_GEOPOTENTIAL_M: f64 = 84_852.0;

/// Layer bases (geopotential m′) and lapse rates (K per m′, positive = warming with height).
const LAYERS: [(f64, f64); 7] = [
    (0.0, -0.0065),
    (11_000.0, 0.0),
    (20_000.0, 0.001),
    (32_000.0, 0.0028),
    (47_000.0, 0.0),
    (51_000.0, -0.0028),
    (71_000.0, -0.002),
];

/// The state of the standard atmosphere at one height.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StandardAir {
    /// Temperature (K).
    pub temperature_k: f64,
    /// Pressure (Pa).
    pub pressure_pa: f64,
    /// dT/dH with respect to the height coordinate that was passed in (K m⁻¹).
    pub dtemperature_dh_k_per_m: f64,
}

/// Geometric heights above mean sea level (m) of the US1976 layer bases above the ground (11, 20,
/// 32, 47, 51 and 71 km geopotential): dT/dh jumps there.
pub fn layer_bases_geometric_m() -> impl Iterator<Item = f64> {
    LAYERS[1..]
        .iter()
        .map(|&(base, _)| geopotential_to_geometric_m(base))
}

/// Geopotential height (m′) → geometric height above mean sea level (m).
pub fn geopotential_to_geometric_m(geopotential_m: f64) -> f64 {
    US1976_EARTH_RADIUS_M * geopotential_m / (US1976_EARTH_RADIUS_M - geopotential_m)
}

/// Geometric height above mean sea level (m) → geopotential height (m′).
pub fn geometric_to_geopotential_m(height_m: f64) -> f64 {
    US1976_EARTH_RADIUS_M * height_m / (US1976_EARTH_RADIUS_M + height_m)
}

/// The standard atmosphere at a geopotential height (m′), anchored at a sea-level temperature and
/// pressure (288.15 K and 101 325 Pa give the standard itself). Heights above 84 852 m′ are clamped
/// to the top, heights below −5 km to −5 km; both ends are far outside any use here.
pub fn us1976_at_geopotential(
    geopotential_m: f64,
    sea_level_temperature_k: f64,
    sea_level_pressure_pa: f64,
) -> StandardAir {
    let h = geopotential_m.clamp(-5_000.0, US1976_TOP_GEOPOTENTIAL_M);
    let g_over_r = STANDARD_GRAVITY_M_S2 / DRY_AIR_GAS_CONSTANT_J_KG_K;
    let mut base_t = sea_level_temperature_k;
    let mut base_p = sea_level_pressure_pa;
    let mut index = 0;
    while index + 1 < LAYERS.len() && h >= LAYERS[index + 1].0 {
        let (base_h, lapse) = LAYERS[index];
        let top_h = LAYERS[index + 1].0;
        let (t, p) = layer_state(base_t, base_p, lapse, top_h - base_h, g_over_r);
        base_t = t;
        base_p = p;
        index += 1;
    }
    let (base_h, lapse) = LAYERS[index];
    let (t, p) = layer_state(base_t, base_p, lapse, h - base_h, g_over_r);
    StandardAir {
        temperature_k: t,
        pressure_pa: p,
        dtemperature_dh_k_per_m: lapse,
    }
}

/// The standard atmosphere itself (288.15 K, 101 325 Pa at sea level) at a geometric height (m).
/// The returned gradient is per geometric metre.
pub fn us1976(height_m: f64) -> StandardAir {
    let geopotential = geometric_to_geopotential_m(height_m);
    let mut air = us1976_at_geopotential(
        geopotential,
        US1976_SEA_LEVEL_TEMPERATURE_K,
        STANDARD_PRESSURE_PA,
    );
    // dH/dz = (r0 / (r0 + z))²
    let ratio = US1976_EARTH_RADIUS_M / (US1976_EARTH_RADIUS_M + height_m);
    air.dtemperature_dh_k_per_m *= ratio * ratio;
    air
}

/// The standard atmosphere's temperature (K) and dT/dh (K per geometric m) at a geometric
/// height (m): exactly [`us1976`]'s, without the pressure (no `powf` per layer), for the
/// temperature blend above a sounding's top, which the hydrostatic column evaluates thousands
/// of times per sounding.
pub fn us1976_temperature(height_m: f64) -> (f64, f64) {
    let h = geometric_to_geopotential_m(height_m).clamp(-5_000.0, US1976_TOP_GEOPOTENTIAL_M);
    let mut base_t = US1976_SEA_LEVEL_TEMPERATURE_K;
    let mut index = 0;
    while index + 1 < LAYERS.len() && h >= LAYERS[index + 1].0 {
        let (base_h, lapse) = LAYERS[index];
        base_t = layer_temperature(base_t, lapse, LAYERS[index + 1].0 - base_h);
        index += 1;
    }
    let (base_h, lapse) = LAYERS[index];
    let ratio = US1976_EARTH_RADIUS_M / (US1976_EARTH_RADIUS_M + height_m);
    (
        layer_temperature(base_t, lapse, h - base_h),
        lapse * (ratio * ratio),
    )
}

/// The temperature `dh` above a layer base, as [`layer_state`] computes it.
fn layer_temperature(base_t: f64, lapse: f64, dh: f64) -> f64 {
    if lapse == 0.0 {
        base_t
    } else {
        base_t + lapse * dh
    }
}

fn layer_state(base_t: f64, base_p: f64, lapse: f64, dh: f64, g_over_r: f64) -> (f64, f64) {
    let t = layer_temperature(base_t, lapse, dh);
    if lapse == 0.0 {
        (t, base_p * (-g_over_r * dh / base_t).exp())
    } else {
        (t, base_p * (base_t / t).powf(g_over_r / lapse))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_temperature_alone_is_the_full_models_bit_for_bit() {
        for i in 0..=20_000 {
            // −6 km to 88 km: every layer, the clamps at both ends.
            let h = -6_000.0 + f64::from(i) * 4.7;
            let full = us1976(h);
            let (t, dt) = us1976_temperature(h);
            assert_eq!(t.to_bits(), full.temperature_k.to_bits(), "T at {h} m");
            assert_eq!(
                dt.to_bits(),
                full.dtemperature_dh_k_per_m.to_bits(),
                "dT at {h} m"
            );
        }
    }

    fn standard(h: f64) -> StandardAir {
        us1976_at_geopotential(h, US1976_SEA_LEVEL_TEMPERATURE_K, STANDARD_PRESSURE_PA)
    }

    #[test]
    fn geopotential_and_geometric_heights_differ_as_readme_says() {
        // README (profile.csv): about h²/6357 km, 0.16 m at 1 km, 0.63 m at 2 km; 11.019 / 20.063 /
        // 32.162 km geometric for the table's 11 / 20 / 32 km geopotential.
        let d = geopotential_to_geometric_m(1000.0) - 1000.0;
        assert!((d - 0.16).abs() < 0.005, "{d}");
        let d = geopotential_to_geometric_m(2000.0) - 2000.0;
        assert!((d - 0.63).abs() < 0.005, "{d}");
        for (geo, geometric) in [
            (11_000.0, 11_019.0),
            (20_000.0, 20_063.0),
            (32_000.0, 32_162.0),
        ] {
            let h = geopotential_to_geometric_m(geo);
            assert!((h - geometric).abs() < 0.5, "{geo}: {h}");
            assert!((geometric_to_geopotential_m(h) - geo).abs() < 1e-6);
        }
    }

    #[test]
    fn matches_the_published_table() {
        // COESA 1976 table values at geopotential heights.
        let s0 = standard(0.0);
        assert!((s0.temperature_k - 288.15).abs() < 1e-9);
        assert!((s0.pressure_pa - 101_325.0).abs() < 1e-6);
        let s11 = standard(11_000.0);
        assert!((s11.temperature_k - 216.65).abs() < 1e-9);
        assert!(
            (s11.pressure_pa / 100.0 - 226.32).abs() < 0.01,
            "{}",
            s11.pressure_pa
        );
        let s20 = standard(20_000.0);
        assert!((s20.temperature_k - 216.65).abs() < 1e-9);
        assert!(
            (s20.pressure_pa / 100.0 - 54.748).abs() < 0.001,
            "{}",
            s20.pressure_pa
        );
        let s32 = standard(32_000.0);
        assert!((s32.temperature_k - 228.65).abs() < 1e-9);
        assert!(
            (s32.pressure_pa / 100.0 - 8.6801).abs() < 0.0001,
            "{}",
            s32.pressure_pa
        );
        let s47 = standard(47_000.0);
        assert!((s47.temperature_k - 270.65).abs() < 1e-9);
        assert!(
            (s47.pressure_pa / 100.0 - 1.1091).abs() < 0.0005,
            "{}",
            s47.pressure_pa
        );
    }

    #[test]
    fn continuous_at_layer_boundaries() {
        for &(h, _) in &LAYERS[1..] {
            let below = standard(h - 1e-6);
            let above = standard(h + 1e-6);
            assert!((below.temperature_k - above.temperature_k).abs() < 1e-6);
            assert!((below.pressure_pa / above.pressure_pa - 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn geometric_gradient_is_scaled() {
        let a = us1976(1000.0);
        let b = us1976(1000.01);
        let fd = (b.temperature_k - a.temperature_k) / 0.01;
        assert!((fd - a.dtemperature_dh_k_per_m).abs() < 1e-9);
    }
}
