//! Helpers for fans of rays checked against the reference tracer, shared by the accuracy and
//! stress tests: soundings fitted from files or CSV text, |∂h/∂α| to classify rays near folds,
//! and reference heights with a step-halving error estimate at chosen step limits.

use std::path::Path;

use ghostship::profile::{FitOptions, Profile};
use ghostship::sounding::{ReadOptions, read_sounding};
use ghostship::tracer::{StratifiedIndex, Tracer};

use super::reference::{RefReach, ReferenceIndex, ReferenceSteps, reference_heights_with_steps};

/// The sounding at `path`, fitted with smoothing scale `smooth_m` (m).
pub fn fitted_profile(path: &Path, smooth_m: f64) -> Profile {
    let s = read_sounding(path, &ReadOptions::default()).expect("sounding reads");
    let options = FitOptions {
        smooth_m,
        ..FitOptions::default()
    };
    Profile::from_sounding(&s, &options).expect("sounding fits")
}

/// The sounding `csv_text`, written to `dir/name.csv` and fitted unsmoothed (`smooth_m = 0`,
/// which keeps the corners of a layered stress sounding).
pub fn csv_profile(dir: &Path, name: &str, csv_text: &str) -> Profile {
    let path = dir.join(format!("{name}.csv"));
    std::fs::write(&path, csv_text).expect("stress sounding written");
    fitted_profile(&path, 0.0)
}

/// Launch-angle step (rad) of the central differences in [`fold_slopes`].
pub const FOLD_SLOPE_STEP_RAD: f64 = 1e-6;

/// |∂h/∂α| (m rad⁻¹) at each of `distances_m` by central differences of `tracer` (run it tight:
/// this only classifies rays near folds, where |∂h/∂α| > 3·D); +∞ where a neighbour does not
/// get there.
pub fn fold_slopes<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    observer_m: f64,
    elevation_rad: f64,
    distances_m: &[f64],
) -> Vec<f64> {
    let da = FOLD_SLOPE_STEP_RAD;
    let up = tracer.trace(observer_m, elevation_rad + da, distances_m);
    let down = tracer.trace(observer_m, elevation_rad - da, distances_m);
    let (Ok(up), Ok(down)) = (up, down) else {
        return vec![f64::INFINITY; distances_m.len()];
    };
    (0..distances_m.len())
        .map(|i| match (up.heights_m[i], down.heights_m[i]) {
            (Some(u), Some(d)) => ((u - d) / (2.0 * da)).abs(),
            _ => f64::INFINITY,
        })
        .collect()
}

/// The reference at each of `distances_m` with step limits `steps`, each with an error
/// estimate: the difference to a run with the steps halved (the finer result is returned;
/// for the sixth-order method the estimate is ≈ 63× the returned height's error). +∞ where the
/// two runs disagree on whether the ray got there, 0 where neither did.
pub fn reference_with_error(
    index: &ReferenceIndex,
    earth_radius_m: f64,
    top_m: f64,
    observer_m: f64,
    elevation_rad: f64,
    distances_m: &[f64],
    steps: ReferenceSteps,
) -> Vec<(RefReach, f64)> {
    let run = |steps| {
        reference_heights_with_steps(
            index,
            earth_radius_m,
            top_m,
            observer_m,
            elevation_rad,
            distances_m,
            steps,
        )
    };
    let coarse = run(steps);
    let fine = run(steps.halved());
    coarse
        .into_iter()
        .zip(fine)
        .map(|(c, f)| match (c.height_m(), f.height_m()) {
            (Some(x), Some(y)) => (f, (x - y).abs()),
            (None, None) => (f, 0.0),
            _ => (f, f64::INFINITY),
        })
        .collect()
}

/// How [`converged_reference`] refines.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refinement {
    /// The step limits to start from.
    pub steps: ReferenceSteps,
    /// Stop refining once every estimate is at most this (m).
    pub target_m: f64,
    /// Most halvings of the ground step.
    pub max_halvings: u32,
}

/// The reference at each of `distances_m`, refined until its error estimate meets
/// `refinement.target_m` (or the halvings run out), each height with that estimate (m). First
/// the classical step halving: a run with `refinement.steps` and one with every limit halved,
/// their difference the estimate. Where that misses the target, the ground step is halved
/// further until two runs agree within it (a ray that turns inside a thin strong layer needs
/// ground steps well below the turn's length, ~30 m in a 0.1 m, 30 K layer, while its height
/// steps are already short); then one more run with the height step halved estimates the
/// height step's share, and the estimate is the sum of the two differences. The finest run is
/// returned. +∞ where two runs disagree on whether the ray got there.
pub fn converged_reference(
    index: &ReferenceIndex,
    earth_radius_m: f64,
    top_m: f64,
    observer_m: f64,
    elevation_rad: f64,
    distances_m: &[f64],
    refinement: Refinement,
) -> Vec<(RefReach, f64)> {
    let run = |steps| {
        reference_heights_with_steps(
            index,
            earth_radius_m,
            top_m,
            observer_m,
            elevation_rad,
            distances_m,
            steps,
        )
    };
    let worst = |e: &[f64]| e.iter().fold(0.0, |a: f64, &b| a.max(b));
    let mut steps = refinement.steps.halved();
    let mut fine = run(steps);
    let estimate = differences(&run(refinement.steps), &fine);
    if worst(&estimate) <= refinement.target_m {
        return fine.into_iter().zip(estimate).collect();
    }
    let mut ground_estimate;
    let mut halvings = 0;
    loop {
        steps.max_ground_step_m *= 0.5;
        let finer = run(steps);
        ground_estimate = differences(&fine, &finer);
        fine = finer;
        halvings += 1;
        if worst(&ground_estimate) <= refinement.target_m || halvings >= refinement.max_halvings {
            break;
        }
    }
    steps = ReferenceSteps {
        max_ground_step_m: steps.max_ground_step_m,
        ..steps.halved()
    };
    let finest = run(steps);
    let height_estimate = differences(&fine, &finest);
    finest
        .into_iter()
        .zip(ground_estimate.iter().zip(height_estimate))
        .map(|(reach, (g, h))| (reach, g + h))
        .collect()
}

/// |Δh| between two runs at each distance: +∞ where one got there and the other did not, 0
/// where neither did.
fn differences(a: &[RefReach], b: &[RefReach]) -> Vec<f64> {
    a.iter()
        .zip(b)
        .map(|(x, y)| match (x.height_m(), y.height_m()) {
            (Some(x), Some(y)) => (x - y).abs(),
            (None, None) => 0.0,
            _ => f64::INFINITY,
        })
        .collect()
}

/// `value ≤ bound`, false for NaN (so `!within(..)` flags a NaN as a violation).
pub fn within(value: f64, bound: f64) -> bool {
    value <= bound
}
