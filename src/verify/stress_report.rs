//! The stress suite's figure and table — `ghostship bench stress`. In: the stress atmospheres
//! ([`stress_suite`]) and a [`StressConfig`] (tolerances, observers, launch set, distances). Out:
//! per atmosphere and tolerance, the worst height error at the target distances against a tight
//! self-reference, the worst Bouguer drift, the rays' terminations and any non-finite output
//! ([`StressResult`]); rendered as `STRESS.md` ([`stress_markdown`]) and a log-log plot of error
//! against tolerance ([`error_vs_tolerance_png`]).
//!
//! **Launch set** ([`launch_elevations_rad`]): elevations from −5° to +90° (0, ±1e-9 rad and a
//! spread of grazing angles among them) and rays launched exactly tangent to a layer corner and
//! to a break of the index: the elevation whose Bouguer invariant puts the turning point on that
//! height ([`tangent_elevation_rad`]).
//!
//! **Error**: |Δh| at the target distances against the tracer's own run at
//! [`StressConfig::reference_tolerance_m`] — a self-reference, because the library cannot use
//! the tests' independent reference tracer; `tests/integration/stress.rs` measures the same
//! suite against that independent tracer. Rays near a fold of h(α), |∂h/∂α| > `fold_factor`·D
//! (central differences of ±1e-6 rad on a run at [`FOLD_SLOPE_TOLERANCE_M`]), are left out of
//! the maximum and counted, as in [`accuracy`](super::accuracy).
//!
//! **Bouguer drift**: [`RayRecord::invariant_drift`], the largest |I − I₀|/(n₀r₀) along the ray,
//! I = n·r·cos ψ; the suite asserts it stays below [`bouguer_drift_bound`] (documented there and
//! in the README).

use std::collections::BTreeMap;
use std::path::PathBuf;

use plotters::prelude::*;
use rayon::prelude::*;

use super::stress::{StressAtmosphere, stress_suite};
use crate::atmosphere::{AtmosphereOptions, AtmosphereSource, load_atmosphere};
use crate::refractivity::RefractiveAtmosphere;
use crate::tracer::{RayRecord, StratifiedIndex, Tracer, TracerConfig, TracerError};

/// The seven tolerances of the suite (m), loosest first.
pub const STRESS_TOLERANCES_M: [f64; 7] = [10.0, 1.0, 0.1, 1e-2, 1e-3, 1e-4, 1e-5];
/// The observers of the suite (m above the surface): at the ground, in, above and far above
/// the layers, and 1 km below the 40 km top.
pub const STRESS_OBSERVERS_M: [f64; 5] = [0.1, 2.0, 100.0, 2_000.0, 39_000.0];
/// Ground distances (m) at which heights are compared.
pub const STRESS_DISTANCES_M: [f64; 4] = [5_000.0, 10_000.0, 20_000.0, 26_000.0];
/// The "tiny" launch elevations ±this (rad) beside the exactly level ray.
pub const TINY_ELEVATION_RAD: f64 = 1e-9;
/// Tolerance (m) of the runs that classify rays near folds (|∂h/∂α| by central differences).
pub const FOLD_SLOPE_TOLERANCE_M: f64 = 1e-6;
/// Launch-angle step (rad) of those central differences.
pub const FOLD_SLOPE_STEP_RAD: f64 = 1e-6;

/// The bound on Bouguer's invariant drift, [`RayRecord::invariant_drift`] (relative to n₀r₀),
/// that a ray traced at tolerance `tolerance_m` (m) with error length `error_length_m` (m: the
/// tracer's L, the larger of [`TracerConfig::error_length_m`] and the farthest target) must
/// meet: **T/L + 1e-11**.
///
/// Why: the error control charges a direction error ε of a step as the position error ε·L it
/// grows into over L, and lets the steps of a ray spend T in all, so the direction errors of a
/// ray add up to at most T/L (rad). Relative to n₀r₀, a direction error δψ changes I = n·r·cos ψ
/// by sin ψ·δψ ≤ δψ and a height error δh by about δh/R ≤ T/R, far less than T/L. The floor
/// 1e-11 is the rounding of I, ≈ 1e-16 relative per step, over the 10⁵ steps of the longest
/// rays.
pub fn bouguer_drift_bound(tolerance_m: f64, error_length_m: f64) -> f64 {
    tolerance_m / error_length_m + 1e-11
}

/// The error length L (m) of `config` for targets up to `farthest_target_m` (m), as the tracer
/// computes it: the larger of the two.
pub fn error_length_m(config: &TracerConfig, farthest_target_m: f64) -> f64 {
    config.error_length_m.max(farthest_target_m)
}

/// Which launch set: the CI's quick one or the long mode's dense one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LaunchSet {
    /// About 20 base elevations and the tangent rays to each corner and its neighbouring breaks.
    Fast,
    /// About 150 base elevations and tangent rays to every corner, its neighbours and every
    /// twentieth break below 2 km.
    Long,
}

/// Base elevations of the fast set (deg), −5°…+90°.
const FAST_ELEVATIONS_DEG: [f64; 17] = [
    -5.0, -1.0, -0.5, -0.2, -0.1, -0.01, 0.0, 0.01, 0.1, 0.2, 0.5, 1.0, 5.0, 10.0, 30.0, 60.0, 90.0,
];

/// The elevation (rad) at which a ray from `observer_m` has its turning point exactly at
/// `turning_m` (both m above the surface of `index`, over a sphere of `earth_radius_m`), by
/// Bouguer's invariant n·r·cos ψ = n(h_t)·(R + h_t): upward for a turning height above the
/// observer (an apex), downward below (a perigee). `None` if no launch direction has that
/// invariant (the index times radius is larger at `turning_m` than at the observer) or the
/// input is not finite. Computed from 1 − cos α, which keeps the grazing angles accurate.
pub fn tangent_elevation_rad<S: StratifiedIndex + ?Sized>(
    index: &S,
    earth_radius_m: f64,
    observer_m: f64,
    turning_m: f64,
) -> Option<f64> {
    if !(observer_m >= 0.0 && turning_m >= 0.0 && earth_radius_m > 0.0) {
        return None;
    }
    let (n0, _) = index.index_and_derivative(observer_m);
    let (nt, _) = index.index_and_derivative(turning_m);
    let (r0, rt) = (earth_radius_m + observer_m, earth_radius_m + turning_m);
    // n0·r0 − nt·rt, with the ones taken out of n to keep the digits.
    let difference = (observer_m - turning_m) + (n0 - 1.0) * r0 - (nt - 1.0) * rt;
    let one_minus_cos = difference / (n0 * r0);
    if !(one_minus_cos.is_finite() && (0.0..=1.0).contains(&one_minus_cos)) {
        return None;
    }
    let alpha = 2.0 * (0.5 * one_minus_cos).sqrt().asin();
    Some(if turning_m >= observer_m {
        alpha
    } else {
        -alpha
    })
}

/// The heights (m) to launch tangent rays to: every corner, the breaks of `index` next to it
/// (below and above), and for the long set every twentieth break below 2 km.
fn tangent_heights_m<S: StratifiedIndex + ?Sized>(
    index: &S,
    corner_heights_m: &[f64],
    set: LaunchSet,
) -> Vec<f64> {
    let breaks = index.breaks_m();
    let mut heights = corner_heights_m.to_vec();
    for &c in corner_heights_m {
        let i = breaks.partition_point(|&b| b < c - 1e-6);
        heights.extend(i.checked_sub(1).map(|j| breaks[j]));
        heights.extend(breaks[i..].iter().find(|&&b| b > c + 1e-6).copied());
    }
    if set == LaunchSet::Long {
        heights.extend(breaks.iter().filter(|&&b| b < 2_000.0).step_by(20));
    }
    heights
}

/// The launch elevations (rad, ascending, distinct) of `set` for an observer at `observer_m`:
/// the base elevations −5°…+90° with 0 and ±[`TINY_ELEVATION_RAD`], and the rays tangent to the
/// heights of `corner_heights_m` and to breaks of `index` ([`tangent_elevation_rad`]).
pub fn launch_elevations_rad<S: StratifiedIndex + ?Sized>(
    index: &S,
    earth_radius_m: f64,
    observer_m: f64,
    corner_heights_m: &[f64],
    set: LaunchSet,
) -> Vec<f64> {
    let mut out: Vec<f64> = match set {
        LaunchSet::Fast => FAST_ELEVATIONS_DEG.to_vec(),
        LaunchSet::Long => long_elevations_deg(),
    }
    .into_iter()
    .map(f64::to_radians)
    .collect();
    out.extend([-TINY_ELEVATION_RAD, TINY_ELEVATION_RAD]);
    for h in tangent_heights_m(index, corner_heights_m, set) {
        out.extend(tangent_elevation_rad(index, earth_radius_m, observer_m, h));
    }
    let half_pi = std::f64::consts::FRAC_PI_2;
    out.retain(|a| a.is_finite() && a.abs() <= half_pi);
    out.sort_by(f64::total_cmp);
    out.dedup();
    out
}

/// −5°…−1° every 0.5°, −1°…+1° every 0.02°, 1°…10° every 0.5°, 10°…90° every 5° (deg).
fn long_elevations_deg() -> Vec<f64> {
    let mut out = Vec::new();
    let mut push = |from: f64, step: f64, count: usize| {
        out.extend((0..count).map(|i| from + step * i as f64));
    };
    push(-5.0, 0.5, 8);
    push(-1.0, 0.02, 100);
    push(1.0, 0.5, 18);
    push(10.0, 5.0, 17);
    out
}
