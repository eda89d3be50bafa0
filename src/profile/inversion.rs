//! Stage 2 — inversion detection. In: any [`AirColumn`] and a height to search up to. Out: the
//! temperature-inversion layers ([`InversionLayer`]) in it, lowest first.
//!
//! Method: sample T on a uniform grid (step [`InversionOptions::grid_step_m`]) from the surface to
//! `top_m`. Every maximal run of grid intervals over which T rises (by more than
//! [`FLAT_TOLERANCE_K`], so that float noise on an isothermal stretch is not warming) is a
//! candidate layer (its base is a local minimum of T, its top a local maximum). Neighbouring
//! candidates are merged when the non-inversion gap between them is thin (≤ `max_gap_m`) and
//! cools little (≤ `max_gap_cooling_k` and by no more than either layer warms, so that a merge
//! never weakens a layer), or when it is isothermal and thinner than both layers (a pause inside
//! one inversion). Finally
//! layers that warm by less than `min_delta_t_k` are dropped: with smoothed sounding data these
//! are sensor noise and 0.1 K reporting steps, not structure.

use super::{AirColumn, InversionKind, InversionLayer};

/// Thresholds of [`detect_inversions`].
#[derive(Debug, Clone, PartialEq)]
pub struct InversionOptions {
    /// Grid step (m) at which T is sampled; base and top are located to this resolution.
    /// Default 1 m.
    pub grid_step_m: f64,
    /// Smallest temperature increase (K) a layer must have to be reported. Default **1.0 K**:
    /// twice the largest noise-level wiggle (+0.5 K in the raw data of the Ny-Ålesund 2024-02-26
    /// 11 UTC RS41 sounding, 0.38 K after the default smoothing) and ten reporting steps of
    /// 0.1 K; the weakest real layers of the test soundings (+3.5 K Bjørnøya) are well above it.
    /// (Ny-Ålesund does have real weak layers higher up, +1.0 K at 1.3–1.5 km and +2.0 K at
    /// 2.0–2.15 km, spread over 30–40 levels each; they are reported.)
    pub min_delta_t_k: f64,
    /// Thickest non-inversion gap (m) across which two layers are merged. Default 10 m: it
    /// joins fragments that residual noise splits (after the default 20 m smoothing the noise is
    /// correlated over ≈10 m) but keeps the paper's Fata Morgana layers, whose gap is ≈15 m,
    /// apart.
    pub max_gap_m: f64,
    /// Largest cooling (K) inside such a gap that still allows the merge. Default 0.3 K.
    pub max_gap_cooling_k: f64,
    /// A layer whose base is at most this far above the surface (m) is surface-based.
    /// Default 10 m.
    pub surface_tolerance_m: f64,
}

impl Default for InversionOptions {
    fn default() -> Self {
        InversionOptions {
            grid_step_m: 1.0,
            min_delta_t_k: 1.0,
            max_gap_m: 10.0,
            max_gap_cooling_k: 0.3,
            surface_tolerance_m: 10.0,
        }
    }
}

/// Most grid intervals sampled (bounds memory and time for tiny steps or huge spans).
const MAX_INTERVALS: usize = 1_000_000;

/// A grid interval warms only if T rises by more than this (K). Evaluating a cubic segment at
/// the edges of two knots, or the same flat segment at two heights, differs in the last bits
/// (≈6·10⁻¹⁴ K at 280 K), and such rises on an isothermal stretch used to extend a layer's base
/// far into it (Norman 2018-12-22 12 UTC: 7.2 °C from 701 to 1320 m, base reported at 1277 m).
/// 10⁻⁹ K is 10⁴ times that noise and 10⁹ times less than the smallest layer reported.
pub const FLAT_TOLERANCE_K: f64 = 1e-9;

/// A candidate layer: grid indices of base and top.
#[derive(Debug, Clone, Copy)]
struct Run {
    base: usize,
    top: usize,
}

/// Whether the non-warming gap between the warming stretches `below` and `above` is part of one
/// layer: it is thin (≤ `max_gap_m`) and cools little (≤ `max_gap_cooling_k`, and no more than
/// either stretch warms), or it is isothermal (cools by no more than float noise) and thinner
/// than both stretches — a pause in one inversion, as in the Utqiagvik 2026-02-06 00 UTC surface
/// inversion, which holds −14.9 °C over 27 m (912–909 hPa) and then warms 0.8 K more.
fn bridges(heights: &[f64], t: &[f64], below: Run, above: Run, options: &InversionOptions) -> bool {
    let gap_m = heights[above.base] - heights[below.top];
    let cooling_k = t[below.top] - t[above.base];
    let warm_below_k = t[below.top] - t[below.base];
    let warm_above_k = t[above.top] - t[above.base];
    let thin_and_mild = gap_m <= options.max_gap_m
        && cooling_k <= options.max_gap_cooling_k
        && cooling_k <= warm_below_k.min(warm_above_k);
    let intervals = (above.base - below.top) as f64;
    let isothermal_pause = cooling_k <= FLAT_TOLERANCE_K * intervals
        && gap_m < heights[below.top] - heights[below.base]
        && gap_m < heights[above.top] - heights[above.base];
    thin_and_mild || isothermal_pause
}

/// The inversion layers of `column` between its surface and `top_m` (m above mean sea level),
/// lowest first. Non-finite or non-positive options, a `top_m` at or below the surface, or
/// non-finite temperatures give an empty list (never a panic). At most 10⁶ grid intervals are
/// sampled (the step is widened if needed).
pub fn detect_inversions(
    column: &dyn AirColumn,
    top_m: f64,
    options: &InversionOptions,
) -> Vec<InversionLayer> {
    let surface = column.surface_height_m();
    if !(surface.is_finite() && top_m.is_finite() && top_m > surface) {
        return Vec::new();
    }
    if !(options.grid_step_m > 0.0 && options.grid_step_m.is_finite()) {
        return Vec::new();
    }
    let span = top_m - surface;
    let intervals = ((span / options.grid_step_m).ceil() as usize).clamp(1, MAX_INTERVALS);
    let step = span / intervals as f64;
    let heights: Vec<f64> = (0..=intervals).map(|i| surface + step * i as f64).collect();
    let (t, gradient): (Vec<f64>, Vec<f64>) = heights
        .iter()
        .map(|&h| {
            let air = column.air_at(h);
            (air.temperature_k, air.dtemperature_dh_k_per_m)
        })
        .unzip();
    if t.iter().any(|v| !v.is_finite()) {
        return Vec::new();
    }

    // Candidate runs of rising temperature.
    let mut runs: Vec<Run> = Vec::new();
    let mut i = 0;
    let warms = |i: usize| t[i + 1] - t[i] > FLAT_TOLERANCE_K;
    while i < intervals {
        if warms(i) {
            let base = i;
            while i < intervals && warms(i) {
                i += 1;
            }
            runs.push(Run { base, top: i });
        } else {
            i += 1;
        }
    }

    // Merge across thin, weakly cooling gaps, and across isothermal pauses.
    let mut merged: Vec<Run> = Vec::new();
    for run in runs {
        if let Some(last) = merged.last_mut()
            && bridges(&heights, &t, *last, run, options)
        {
            last.top = run.top;
            continue;
        }
        merged.push(run);
    }

    merged
        .into_iter()
        .filter_map(|run| {
            let delta_t_k = t[run.top] - t[run.base];
            if delta_t_k < options.min_delta_t_k {
                return None;
            }
            let base_m = heights[run.base];
            let top_m = heights[run.top];
            let max_gradient_k_per_m = gradient[run.base..=run.top]
                .iter()
                .copied()
                .fold(f64::NEG_INFINITY, f64::max);
            let base_agl_m = base_m - surface;
            Some(InversionLayer {
                base_m,
                top_m,
                base_agl_m,
                top_agl_m: top_m - surface,
                delta_t_k,
                max_gradient_k_per_m,
                kind: if base_agl_m <= options.surface_tolerance_m {
                    InversionKind::Surface
                } else {
                    InversionKind::Elevated
                },
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profile::AirSample;

    /// T(h) from a closure; P irrelevant here.
    struct Column<F: Fn(f64) -> (f64, f64) + Send + Sync>(F);

    impl<F: Fn(f64) -> (f64, f64) + Send + Sync> AirColumn for Column<F> {
        fn surface_height_m(&self) -> f64 {
            0.0
        }
        fn air_at(&self, h: f64) -> AirSample {
            let (t, dt) = (self.0)(h);
            AirSample {
                temperature_k: t,
                dtemperature_dh_k_per_m: dt,
                pressure_pa: 100_000.0,
                ..AirSample::default()
            }
        }
    }

    /// Piecewise-linear T through (h, T) corners.
    fn piecewise(corners: &'static [(f64, f64)]) -> impl Fn(f64) -> (f64, f64) + Send + Sync {
        move |h| {
            for w in corners.windows(2) {
                if h <= w[1].0 {
                    let g = (w[1].1 - w[0].1) / (w[1].0 - w[0].0);
                    return (w[0].1 + g * (h - w[0].0), g);
                }
            }
            let &(_, t) = corners.last().unwrap();
            (t, 0.0)
        }
    }

    #[test]
    fn finds_a_surface_and_an_elevated_layer() {
        let c = Column(piecewise(&[
            (0.0, 260.0),
            (100.0, 265.0),
            (300.0, 263.0),
            (400.0, 270.0),
            (1000.0, 266.0),
        ]));
        let layers = detect_inversions(&c, 1000.0, &InversionOptions::default());
        assert_eq!(layers.len(), 2, "{layers:?}");
        let (a, b) = (&layers[0], &layers[1]);
        assert_eq!(a.kind, InversionKind::Surface);
        assert!((a.base_m - 0.0).abs() < 1e-9 && (a.top_m - 100.0).abs() < 1e-9);
        assert!((a.delta_t_k - 5.0).abs() < 1e-9);
        assert!((a.max_gradient_k_per_m - 0.05).abs() < 1e-12);
        assert_eq!(b.kind, InversionKind::Elevated);
        assert!((b.base_m - 300.0).abs() < 1e-9 && (b.top_m - 400.0).abs() < 1e-9);
        assert!((b.delta_t_k - 7.0).abs() < 1e-9);
        assert!((b.top_agl_m - 400.0).abs() < 1e-9);
    }

    #[test]
    fn thin_gaps_merge_and_weak_layers_are_dropped() {
        // Two +2 K halves separated by a 10 m, −0.2 K gap → one +3.8 K layer; a +0.4 K bump is
        // dropped; a 100 m gap keeps layers apart.
        let c = Column(piecewise(&[
            (0.0, 260.0),
            (50.0, 259.7),
            (70.0, 261.7),
            (80.0, 261.5),
            (100.0, 263.5),
            (200.0, 263.0),
            (210.0, 263.4),
            (300.0, 262.8),
            (320.0, 264.8),
            (420.0, 264.0),
            (440.0, 266.0),
            (600.0, 265.0),
        ]));
        let layers = detect_inversions(&c, 600.0, &InversionOptions::default());
        assert_eq!(layers.len(), 3, "{layers:?}");
        assert!((layers[0].base_m - 50.0).abs() < 1e-9 && (layers[0].top_m - 100.0).abs() < 1e-9);
        assert!((layers[0].delta_t_k - 3.8).abs() < 1e-9);
        assert!((layers[1].base_m - 300.0).abs() < 1e-9);
        assert!((layers[2].base_m - 420.0).abs() < 1e-9);
        let strict = InversionOptions {
            max_gap_m: 5.0,
            ..InversionOptions::default()
        };
        assert_eq!(detect_inversions(&c, 600.0, &strict).len(), 4);
    }

    /// `piecewise` plus last-bit noise (±6·10⁻¹⁴ K, as cubic evaluation leaves on a flat stretch).
    fn noisy(corners: &'static [(f64, f64)]) -> impl Fn(f64) -> (f64, f64) + Send + Sync {
        let clean = piecewise(corners);
        move |h| {
            let (t, g) = clean(h);
            (t + 6e-14 * (h * 7.3).sin(), g)
        }
    }

    #[test]
    fn float_noise_on_an_isothermal_stretch_is_not_warming() {
        // Warming 0–100 m, isothermal 100–700 m, warming 700–800 m (the Norman 2018-12-22 shape):
        // two layers whose bounds are the corners, not points inside the flat stretch.
        let c = Column(noisy(&[
            (0.0, 260.0),
            (100.0, 263.0),
            (700.0, 263.0),
            (800.0, 266.0),
            (900.0, 265.0),
        ]));
        let layers = detect_inversions(&c, 900.0, &InversionOptions::default());
        assert_eq!(layers.len(), 2, "{layers:?}");
        assert_eq!((layers[0].base_m, layers[0].top_m), (0.0, 100.0));
        assert_eq!((layers[1].base_m, layers[1].top_m), (700.0, 800.0));
    }

    #[test]
    fn an_isothermal_pause_thinner_than_both_stretches_does_not_end_the_layer() {
        // The Utqiagvik 2026-02-06 shape: +5 K over 300 m, 27 m isothermal, +1 K over 73 m.
        let c = Column(noisy(&[
            (0.0, 260.0),
            (300.0, 265.0),
            (327.0, 265.0),
            (400.0, 266.0),
            (500.0, 265.0),
        ]));
        let layers = detect_inversions(&c, 500.0, &InversionOptions::default());
        assert_eq!(layers.len(), 1, "{layers:?}");
        assert_eq!((layers[0].base_m, layers[0].top_m), (0.0, 400.0));
        assert!((layers[0].delta_t_k - 6.0).abs() < 1e-9);
        // A pause thicker than the stretch above it ends the layer (the +0.8 K above is too weak
        // to be reported on its own).
        let c = Column(noisy(&[
            (0.0, 260.0),
            (300.0, 265.0),
            (400.0, 265.0),
            (473.0, 265.8),
            (500.0, 265.0),
        ]));
        let layers = detect_inversions(&c, 500.0, &InversionOptions::default());
        assert_eq!(layers.len(), 1, "{layers:?}");
        assert_eq!((layers[0].base_m, layers[0].top_m), (0.0, 300.0));
    }

    #[test]
    fn degenerate_inputs_give_nothing() {
        let c = Column(piecewise(&[(0.0, 260.0), (100.0, 270.0)]));
        assert!(detect_inversions(&c, 0.0, &InversionOptions::default()).is_empty());
        assert!(detect_inversions(&c, f64::NAN, &InversionOptions::default()).is_empty());
        let bad = InversionOptions {
            grid_step_m: 0.0,
            ..InversionOptions::default()
        };
        assert!(detect_inversions(&c, 100.0, &bad).is_empty());
        let nan = Column(|_| (f64::NAN, 0.0));
        assert!(detect_inversions(&nan, 100.0, &InversionOptions::default()).is_empty());
    }
}
