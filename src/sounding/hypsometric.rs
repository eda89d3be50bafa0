//! Stage 1 — ingest: hypsometric heights. In: a column of levels ordered bottom to top, each with
//! pressure and virtual temperature, some with a reported height. Out: heights for the levels that
//! have none (e.g. WMO TEMP Part B significant levels), in the same geopotential metres as the
//! reported ones.
//!
//! The hypsometric equation gives the thickness of a layer between pressures p₁ > p₂ as
//! Δz = (R_d / g₀) · T̄_v · ln(p₁ / p₂). Between two levels the temperature is taken linear in
//! ln p (the usual sounding assumption), for which the mean virtual temperature over the layer in
//! ln p is exactly the mean of the two end values. With g₀ = standard gravity the result is
//! geopotential height, the same kind of height radiosonde formats report.
//!
//! Written by hand: it is a dozen lines of physics tied to our level type, not something a crate
//! offers.

use crate::units::{DRY_AIR_GAS_CONSTANT_J_KG_K, EPSILON_WATER_DRY, STANDARD_GRAVITY_M_S2};

/// Virtual temperature (K): the temperature dry air would need to have the density of the moist
/// sample, T_v = T / (1 − (e/p)(1 − ε)). Dry air (`vapour_pressure_pa = None`) gives T.
pub fn virtual_temperature_k(
    temperature_k: f64,
    vapour_pressure_pa: Option<f64>,
    pressure_pa: f64,
) -> f64 {
    match vapour_pressure_pa {
        Some(e) if pressure_pa > 0.0 => {
            temperature_k / (1.0 - (e / pressure_pa) * (1.0 - EPSILON_WATER_DRY))
        }
        _ => temperature_k,
    }
}

/// Geopotential thickness (m) of the layer between `bottom_pressure_pa` and `top_pressure_pa`
/// whose mean virtual temperature (in ln p) is `mean_virtual_temperature_k`.
pub fn thickness_m(
    bottom_pressure_pa: f64,
    top_pressure_pa: f64,
    mean_virtual_temperature_k: f64,
) -> f64 {
    DRY_AIR_GAS_CONSTANT_J_KG_K / STANDARD_GRAVITY_M_S2
        * mean_virtual_temperature_k
        * (bottom_pressure_pa / top_pressure_pa).ln()
}

/// One level of the column handed to [`fill_missing_heights`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HypsometricLevel {
    /// Pressure (Pa), > 0, strictly decreasing up the column.
    pub pressure_pa: f64,
    /// Virtual temperature (K), > 0.
    pub virtual_temperature_k: f64,
    /// Reported height (m), or `None` to have it computed.
    pub height_m: Option<f64>,
}

/// Why [`fill_missing_heights`] could not fill a column.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HypsometricError {
    /// No level has a height, so there is nothing to anchor the integration on.
    #[error("no level with both a height and a pressure to anchor the hypsometric heights on")]
    NoAnchor,
    /// Pressure does not strictly decrease from level `index` to the next, or a value is not
    /// positive and finite.
    #[error("pressure must be positive and strictly decrease up the column (level index {index})")]
    BadColumn {
        /// 0-based index of the lower level of the offending pair.
        index: usize,
    },
}

/// Fills every `height_m: None` of `column` (ordered bottom to top) from the hypsometric
/// equation, anchored on the levels that have heights:
/// * between two anchors, integrate up from the lower one, then remove the closure error at the
///   upper anchor in proportion to the integrated thickness, so both anchors are met exactly
///   (equivalently: a thickness-weighted blend of integrating up from below and down from above);
/// * below the lowest anchor or above the highest, integrate from that single anchor.
///
/// Returns the indices of the levels it filled.
pub fn fill_missing_heights(
    column: &mut [HypsometricLevel],
) -> Result<Vec<usize>, HypsometricError> {
    for (index, level) in column.iter().enumerate() {
        let ok = level.pressure_pa.is_finite()
            && level.pressure_pa > 0.0
            && level.virtual_temperature_k.is_finite()
            && level.virtual_temperature_k > 0.0
            && level.height_m.is_none_or(f64::is_finite);
        if !ok {
            return Err(HypsometricError::BadColumn { index });
        }
    }
    for index in 0..column.len().saturating_sub(1) {
        if column[index + 1].pressure_pa >= column[index].pressure_pa {
            // Equal pressures are harmless between two reported heights (1-s data repeat the
            // 0.1 hPa value); they only matter if a height must be computed across them.
            let both_anchored =
                column[index].height_m.is_some() && column[index + 1].height_m.is_some();
            if !(both_anchored && column[index + 1].pressure_pa == column[index].pressure_pa) {
                return Err(HypsometricError::BadColumn { index });
            }
        }
    }
    let anchors: Vec<usize> = (0..column.len())
        .filter(|&i| column[i].height_m.is_some())
        .collect();
    let (Some(&first), Some(&last)) = (anchors.first(), anchors.last()) else {
        if column.is_empty() {
            return Ok(Vec::new());
        }
        return Err(HypsometricError::NoAnchor);
    };

    // Cumulative hypsometric coordinate: z[i] = thickness from level 0 up to level i.
    let mut z = vec![0.0_f64; column.len()];
    for i in 1..column.len() {
        let mean_tv = 0.5 * (column[i - 1].virtual_temperature_k + column[i].virtual_temperature_k);
        z[i] = z[i - 1] + thickness_m(column[i - 1].pressure_pa, column[i].pressure_pa, mean_tv);
    }
    let height = |i: usize| column[i].height_m.unwrap_or(f64::NAN);

    let mut filled = Vec::new();
    let mut new_heights = Vec::new();
    for i in 0..column.len() {
        if column[i].height_m.is_some() {
            continue;
        }
        let h = if i < first {
            height(first) - (z[first] - z[i])
        } else if i > last {
            height(last) + (z[i] - z[last])
        } else {
            // Anchors a < i < b, the nearest on each side.
            let b_pos = anchors.partition_point(|&a| a < i);
            let (a, b) = (anchors[b_pos - 1], anchors[b_pos]);
            let span = z[b] - z[a];
            let up = height(a) + (z[i] - z[a]);
            let closure = height(a) + span - height(b);
            let weight = if span > 0.0 {
                (z[i] - z[a]) / span
            } else {
                0.5
            };
            up - weight * closure
        };
        filled.push(i);
        new_heights.push(h);
    }
    for (&i, &h) in filled.iter().zip(&new_heights) {
        column[i].height_m = Some(h);
    }
    Ok(filled)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn level(pressure_hpa: f64, t_k: f64, h: Option<f64>) -> HypsometricLevel {
        HypsometricLevel {
            pressure_pa: pressure_hpa * 100.0,
            virtual_temperature_k: t_k,
            height_m: h,
        }
    }

    #[test]
    fn isothermal_layer_matches_scale_height() {
        // Isothermal 250 K: z = H ln(p0/p) with H = R_d T / g0 = 287.05287 * 250 / 9.80665
        // = 7317.81 m, so 1000 → 500 hPa is H ln 2 = 5072.32 m.
        let mut col = vec![level(1000.0, 250.0, Some(0.0)), level(500.0, 250.0, None)];
        fill_missing_heights(&mut col).unwrap();
        let expected = 287.05287 * 250.0 / 9.80665 * 2f64.ln();
        assert!((col[1].height_m.unwrap() - expected).abs() < 1e-9);
        assert!((expected - 5072.32).abs() < 0.01, "{expected}");
    }

    #[test]
    fn closure_error_is_distributed_and_both_anchors_hold() {
        // Anchors deliberately 30 m off from the isothermal integral: the middle level (half the
        // thickness) gets half the correction.
        let h = 287.05287 * 250.0 / 9.80665;
        let mut col = vec![
            level(1000.0, 250.0, Some(100.0)),
            level(1000.0 / 2f64.sqrt(), 250.0, None),
            level(500.0, 250.0, Some(100.0 + h * 2f64.ln() + 30.0)),
        ];
        let filled = fill_missing_heights(&mut col).unwrap();
        assert_eq!(filled, vec![1]);
        let mid = col[1].height_m.unwrap();
        assert!(
            (mid - (100.0 + 0.5 * h * 2f64.ln() + 15.0)).abs() < 1e-9,
            "{mid}"
        );
        assert_eq!(col[0].height_m, Some(100.0));
    }

    #[test]
    fn single_anchor_above_and_below() {
        let h = 287.05287 * 260.0 / 9.80665;
        let mut col = vec![
            level(1000.0, 260.0, None),
            level(900.0, 260.0, Some(1000.0)),
            level(800.0, 260.0, None),
        ];
        fill_missing_heights(&mut col).unwrap();
        assert!((col[0].height_m.unwrap() - (1000.0 - h * (1000.0f64 / 900.0).ln())).abs() < 1e-9);
        assert!((col[2].height_m.unwrap() - (1000.0 + h * (900.0f64 / 800.0).ln())).abs() < 1e-9);
    }

    #[test]
    fn no_anchor_and_bad_columns_are_errors() {
        let mut col = vec![level(1000.0, 260.0, None), level(900.0, 260.0, None)];
        assert_eq!(
            fill_missing_heights(&mut col),
            Err(HypsometricError::NoAnchor)
        );
        let mut col = vec![level(900.0, 260.0, Some(0.0)), level(900.0, 260.0, None)];
        assert_eq!(
            fill_missing_heights(&mut col),
            Err(HypsometricError::BadColumn { index: 0 })
        );
        let mut col = vec![level(900.0, f64::NAN, Some(0.0))];
        assert!(fill_missing_heights(&mut col).is_err());
    }

    #[test]
    fn virtual_temperature_of_moist_air() {
        // e = 10 hPa at 1000 hPa, 300 K: Tv = 300 / (1 - 0.01 * 0.37802) = 301.138 K.
        let tv = virtual_temperature_k(300.0, Some(1000.0), 100_000.0);
        assert!((tv - 301.138).abs() < 1e-3, "{tv}");
        assert_eq!(virtual_temperature_k(300.0, None, 100_000.0), 300.0);
    }
}
