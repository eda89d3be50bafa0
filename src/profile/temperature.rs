//! Stage 2 — fit: the temperature between the levels. In: the (smoothed) level temperatures and
//! heights, the fitted ln P at the levels that carry a measured pressure, and the fit asked for
//! ([`TemperatureFit`]). Out: T(h) and its analytic dT/dh from the lowest to the highest level,
//! with the choice made and its reason ([`FitChoice`]).
//!
//! * **PCHIP** ([`TemperatureFit::Pchip`]): the monotone cubic of `monotone.rs` in height; C¹,
//!   no extremum between levels.
//! * **Linear** ([`TemperatureFit::Linear`]): T linear in ln p between adjacent levels that both
//!   carry a measured pressure (T(h) = T₀ + (T₁ − T₀)·(ln P(h) − ln P₀)/(ln P₁ − ln P₀) through the
//!   fitted ln P(h), so dT/dh = (T₁ − T₀)/(ln P₁ − ln P₀)·d ln P/dh), linear in height where one
//!   of them has none. C⁰: dT/dh jumps at every level, which the profile lists as breaks.
//! * **Auto** ([`TemperatureFit::Auto`]): linear for significant-level soundings, PCHIP for dense
//!   ascents, by the median level spacing in the lowest 3 km ([`choose_fit`]).
//!
//! Either curve can carry a smooth bump a·sin(πu) per gap between two levels (u the gap's own
//! coordinate: the ln p fraction where the gap is linear in ln p, else the height fraction),
//! which vanishes at both levels: the members of a sensitivity ensemble (`ensemble.rs`).

use std::f64::consts::PI;

use super::monotone::{KnotIndex, MonotoneCubic};

/// How the temperature of a sounding is interpolated between its levels.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum TemperatureFit {
    /// PCHIP in height through the (smoothed) levels: C¹, never an extremum between levels.
    /// Right for dense ascents, whose levels sample the curve itself.
    Pchip,
    /// Linear in ln p between levels (in height where a level has no pressure): what WMO's
    /// significant levels are chosen for.
    Linear,
    /// Linear for significant-level soundings, PCHIP for dense ascents ([`choose_fit`]).
    #[default]
    Auto,
}

impl TemperatureFit {
    /// The name used on the command line and in files: `pchip`, `linear`, `auto`.
    pub fn name(self) -> &'static str {
        match self {
            TemperatureFit::Pchip => "pchip",
            TemperatureFit::Linear => "linear",
            TemperatureFit::Auto => "auto",
        }
    }

    /// Whether this is [`TemperatureFit::Auto`] (the default, left out of serialised options).
    pub fn is_auto(&self) -> bool {
        *self == TemperatureFit::Auto
    }
}

impl std::fmt::Display for TemperatureFit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for TemperatureFit {
    type Err = String;

    /// `pchip`, `linear` or `auto` (any case).
    fn from_str(text: &str) -> Result<Self, String> {
        match text.trim().to_ascii_lowercase().as_str() {
            "pchip" => Ok(TemperatureFit::Pchip),
            "linear" => Ok(TemperatureFit::Linear),
            "auto" => Ok(TemperatureFit::Auto),
            _ => Err(format!(
                "unknown temperature fit {text:?} (use pchip, linear or auto)"
            )),
        }
    }
}

/// Height above the lowest level (m) over which [`choose_fit`] measures the level spacing: the
/// layer mirages come from.
pub const AUTO_SPACING_RANGE_M: f64 = 3_000.0;

/// Median level spacing (m) above which [`choose_fit`] takes a sounding for significant levels.
/// Dense ascents report every 1–2 s at 4–6 m s⁻¹: medians of 4–11 m in the shipped ones
/// (Ny-Ålesund, Trois-Rivières, Bjørnøya). Significant-level soundings (TEMP, IGRA2, Wyoming,
/// SHARPpy, NOAA GSL) are 48 m apart at the closest of the shipped ones (Utqiagvik 2026-02-06,
/// many levels in a strong surface inversion) and 50–2240 m otherwise. 25 m lies between, a
/// factor of two from either side.
pub const AUTO_SPARSE_SPACING_M: f64 = 25.0;

/// The temperature fit a profile was made with, and why.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FitChoice {
    /// What was asked for.
    pub requested: TemperatureFit,
    /// What was used: [`TemperatureFit::Pchip`] or [`TemperatureFit::Linear`].
    pub used: TemperatureFit,
    /// Median spacing of the levels in the lowest [`AUTO_SPACING_RANGE_M`] (m); `None` for a
    /// sounding of one level.
    pub median_spacing_m: Option<f64>,
    /// Whether the levels are sparse (median spacing > [`AUTO_SPARSE_SPACING_M`]): significant
    /// levels, with the profile between them unknown.
    pub significant_levels: bool,
    /// One sentence saying why.
    pub reason: String,
}

/// The fit to use for levels at `heights_m` (ascending) when `requested` is asked for.
///
/// Auto: **linear in ln p** when the median spacing of the levels in the lowest 3 km exceeds
/// 25 m, else **PCHIP**. Why: WMO selects significant levels (TEMP Part B, and so IGRA2 and
/// Wyoming lists) so that linear interpolation in ln p between them stays within about 1 K of the
/// measured profile; the profile between them is unknown, and a cubic through them concentrates
/// the gradient in thin layers it invents (Cherskiy 2026-02-06: 0.081 K/m between 1002 and
/// 1000 hPa, where the data warm 0.8 K over 13.4 m, 0.060 K/m: over the 0.077 K/m trapping
/// gradient, a 5 m "duct" the levels do not show).
/// A dense 1-second ascent measures the curve itself every few metres; there PCHIP through the
/// smoothed levels follows its curvature without the corners a polyline puts at every level.
pub fn choose_fit(requested: TemperatureFit, heights_m: &[f64]) -> FitChoice {
    let median_spacing_m = median_spacing(heights_m);
    let significant_levels = median_spacing_m.is_some_and(|s| s > AUTO_SPARSE_SPACING_M);
    let spacing = median_spacing_m.map_or("one level".to_string(), |s| {
        format!("median level spacing {s:.0} m in the lowest 3 km")
    });
    let (used, reason) = match requested {
        TemperatureFit::Auto if significant_levels => (
            TemperatureFit::Linear,
            format!(
                "auto: {spacing} (> {AUTO_SPARSE_SPACING_M:.0} m: significant levels, chosen by \
                 WMO so that linear interpolation in ln p stays within about 1 K of the profile)"
            ),
        ),
        TemperatureFit::Auto => (
            TemperatureFit::Pchip,
            format!(
                "auto: {spacing} (≤ {AUTO_SPARSE_SPACING_M:.0} m: a dense ascent, whose levels \
                 sample the curve itself)"
            ),
        ),
        other => (other, format!("as requested ({spacing})")),
    };
    FitChoice {
        requested,
        used,
        median_spacing_m,
        significant_levels,
        reason,
    }
}

/// Median spacing (m) of the levels within [`AUTO_SPACING_RANGE_M`] of the lowest; the first gap
/// when fewer than two levels lie there; `None` for one level.
fn median_spacing(heights_m: &[f64]) -> Option<f64> {
    let first = *heights_m.first()?;
    let inside = heights_m.partition_point(|&h| h <= first + AUTO_SPACING_RANGE_M);
    let upto = inside.max(2).min(heights_m.len());
    let mut gaps: Vec<f64> = heights_m[..upto].windows(2).map(|w| w[1] - w[0]).collect();
    if gaps.is_empty() {
        return None;
    }
    gaps.sort_by(f64::total_cmp);
    let n = gaps.len();
    Some(if n % 2 == 1 {
        gaps[n / 2]
    } else {
        0.5 * (gaps[n / 2 - 1] + gaps[n / 2])
    })
}

/// The shape between levels.
#[derive(Debug, Clone)]
enum Shape {
    /// One level: its value, and a slope to report there.
    Point { value_k: f64, slope_k_per_m: f64 },
    /// PCHIP in height.
    Pchip(MonotoneCubic),
    /// Linear in each gap's coordinate.
    Linear,
}

/// T(h) between the lowest and highest level (see the module doc).
#[derive(Debug, Clone)]
pub(crate) struct TemperatureCurve {
    /// The levels' heights (m), with the segment search over them.
    knots: KnotIndex,
    values_k: Vec<f64>,
    shape: Shape,
    /// ln P (fitted) at each level whose pressure was measured; a gap with both ends `Some` is
    /// linear in ln p. All `None` until [`Self::set_ln_pressure`].
    ln_p: Vec<Option<f64>>,
    /// Bump amplitude per gap (K), `heights_m.len() − 1` of them, or empty (none).
    bumps_k: Vec<f64>,
}

impl TemperatureCurve {
    /// The curve through `(heights_m, values_k)` (heights strictly increasing, at least one) with
    /// `used` (PCHIP or linear); a single level reports `single_slope` as its slope.
    pub(crate) fn new(
        heights_m: &[f64],
        values_k: &[f64],
        used: TemperatureFit,
        single_slope: f64,
    ) -> Self {
        let shape = if heights_m.len() < 2 {
            Shape::Point {
                value_k: values_k[0],
                slope_k_per_m: single_slope,
            }
        } else if used == TemperatureFit::Linear {
            Shape::Linear
        } else {
            Shape::Pchip(MonotoneCubic::new(heights_m, values_k))
        };
        TemperatureCurve {
            knots: KnotIndex::new(heights_m),
            values_k: values_k.to_vec(),
            shape,
            ln_p: vec![None; heights_m.len()],
            bumps_k: Vec::new(),
        }
    }

    /// Make gaps between two levels with a measured pressure linear in ln p: `ln_p[i]` is the
    /// fitted ln P at level i where its pressure was measured. Gaps where ln P does not decrease
    /// stay linear in height.
    pub(crate) fn set_ln_pressure(&mut self, ln_p: Vec<Option<f64>>) {
        debug_assert_eq!(ln_p.len(), self.knots.knots_m().len());
        self.ln_p = ln_p;
    }

    /// The same curve with bump amplitudes `bumps_k` (K, one per gap).
    pub(crate) fn with_bumps(&self, bumps_k: Vec<f64>) -> Self {
        debug_assert_eq!(bumps_k.len() + 1, self.knots.knots_m().len().max(1));
        TemperatureCurve {
            bumps_k,
            ..self.clone()
        }
    }

    /// Number of gaps between levels.
    pub(crate) fn gaps(&self) -> usize {
        self.knots.knots_m().len().saturating_sub(1)
    }

    /// T and dT/dh at `h` (inside the levels; clamped to them), given the fitted ln P and
    /// d ln P/dh there (`None`: every gap is taken linear in height — the provisional curve the
    /// hydrostatic fill integrates through before P is known).
    pub(crate) fn at(&self, h: f64, ln_p: Option<(f64, f64)>) -> (f64, f64) {
        if let Shape::Point {
            value_k,
            slope_k_per_m,
        } = &self.shape
        {
            return (*value_k, *slope_k_per_m);
        }
        let k = self.gap_of(h);
        let (u, du_dh) = self.coordinate(k, h, ln_p);
        let (t0, t1) = (self.values_k[k], self.values_k[k + 1]);
        let (mut t, mut dt) = match &self.shape {
            Shape::Pchip(curve) => curve.value_slope(h),
            _ => (t0 + (t1 - t0) * u, (t1 - t0) * du_dh),
        };
        if let Some(&a) = self.bumps_k.get(k)
            && a != 0.0
        {
            t += a * (PI * u).sin();
            dt += a * PI * (PI * u).cos() * du_dh;
        }
        (t, dt)
    }

    /// The gap [k, k + 1] holding `h` (the upper one at a level).
    fn gap_of(&self, h: f64) -> usize {
        self.knots.segment(h)
    }

    /// The coordinate u ∈ [0, 1] of gap k at `h`, and du/dh: the ln p fraction where both levels
    /// have a measured pressure (and ln P is known), else the height fraction.
    fn coordinate(&self, k: usize, h: f64, ln_p: Option<(f64, f64)>) -> (f64, f64) {
        let (h0, h1) = (self.knots.knots_m()[k], self.knots.knots_m()[k + 1]);
        if let (Some((lnp, dlnp)), Some(a), Some(b)) = (ln_p, self.ln_p[k], self.ln_p[k + 1])
            && a - b > 1e-12
        {
            let width = b - a;
            return (((lnp - a) / width).clamp(0.0, 1.0), dlnp / width);
        }
        let width = h1 - h0;
        (((h - h0) / width).clamp(0.0, 1.0), 1.0 / width)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_reads_the_spacing_of_the_lowest_3_km() {
        // 1-s ascent: 5 m apart → PCHIP.
        let dense: Vec<f64> = (0..1000).map(|i| 10.0 + 5.0 * i as f64).collect();
        let c = choose_fit(TemperatureFit::Auto, &dense);
        assert_eq!(c.used, TemperatureFit::Pchip);
        assert_eq!(c.median_spacing_m, Some(5.0));
        assert!(!c.significant_levels);
        // Gaps 10, 100, 200, 400 below 3 km (median 150 m), a big one above that is ignored.
        let sparse = [0.0, 10.0, 110.0, 310.0, 710.0, 9000.0];
        let c = choose_fit(TemperatureFit::Auto, &sparse);
        assert_eq!(c.used, TemperatureFit::Linear);
        assert_eq!(c.median_spacing_m, Some(150.0));
        assert!(c.reason.contains("significant levels"), "{}", c.reason);
        // An explicit choice is kept, and still says what the levels are.
        let c = choose_fit(TemperatureFit::Pchip, &sparse);
        assert_eq!(c.used, TemperatureFit::Pchip);
        assert!(c.significant_levels);
        // One level in the lowest 3 km: the first gap decides.
        assert_eq!(median_spacing(&[0.0, 5000.0]), Some(5000.0));
        assert_eq!(median_spacing(&[0.0]), None);
    }

    #[test]
    fn names_parse_back() {
        for fit in [
            TemperatureFit::Pchip,
            TemperatureFit::Linear,
            TemperatureFit::Auto,
        ] {
            assert_eq!(fit.name().parse::<TemperatureFit>(), Ok(fit));
        }
        assert!("cubic".parse::<TemperatureFit>().is_err());
    }

    #[test]
    fn linear_gaps_and_bumps() {
        let h = [0.0, 100.0, 300.0];
        let t = [250.0, 252.0, 251.0];
        let mut c = TemperatureCurve::new(&h, &t, TemperatureFit::Linear, 0.0);
        // Linear in height: at 50 m halfway, slope 0.02 K/m.
        let (v, s) = c.at(50.0, None);
        assert!((v - 251.0).abs() < 1e-12 && (s - 0.02).abs() < 1e-15);
        // Linear in ln p on the first gap: ln P 11.5 → 11.49; at ln P 11.4975 (u = 1/4).
        c.set_ln_pressure(vec![Some(11.5), Some(11.49), None]);
        let (v, s) = c.at(30.0, Some((11.4975, -1.2e-4)));
        assert!((v - 250.5).abs() < 1e-9, "{v}");
        assert!((s - 2.0 / -0.01 * -1.2e-4).abs() < 1e-12, "{s}");
        // A bump of 0.5 K on the second gap: +0.5 K halfway, zero at both levels.
        let b = c.with_bumps(vec![0.0, 0.5]);
        assert!((b.at(200.0, None).0 - (251.5 + 0.5)).abs() < 1e-12);
        assert!((b.at(300.0, None).0 - 251.0).abs() < 1e-12);
        assert!((b.at(100.0, None).0 - 252.0).abs() < 1e-12);
        // Its slope at the lower level: −1/200 + 0.5·π/200.
        let s = b.at(100.0, None).1;
        assert!((s - (-1.0 / 200.0 + 0.5 * PI / 200.0)).abs() < 1e-12, "{s}");
    }
}
