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
use std::path::{Path, PathBuf};

use plotters::prelude::*;
use rayon::prelude::*;

use super::accuracy::{LINE_COLOURS, PLOT_FLOOR_M};
use super::stress::StressAtmosphere;
#[cfg(doc)]
use super::stress::stress_suite;
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
/// (below and above; breaks of either kind), and for the long set every twentieth break below
/// 2 km.
fn tangent_heights_m<S: StratifiedIndex + ?Sized>(
    index: &S,
    corner_heights_m: &[f64],
    set: LaunchSet,
) -> Vec<f64> {
    let mut breaks: Vec<f64> = index.breaks_m().to_vec();
    breaks.extend(index.minor_breaks().iter().map(|b| b.height_m));
    breaks.sort_by(f64::total_cmp);
    breaks.dedup();
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

/// What `bench stress` measures.
#[derive(Debug, Clone, PartialEq)]
pub struct StressConfig {
    /// Tolerances to measure (m), loosest first.
    pub tolerances_m: Vec<f64>,
    /// Tolerance of the self-reference run (m).
    pub reference_tolerance_m: f64,
    /// Step budget of the self-reference run.
    pub reference_max_steps: u32,
    /// Observer heights above the surface (m).
    pub observers_m: Vec<f64>,
    /// Ground distances (m, ascending) at which heights are compared.
    pub distances_m: Vec<f64>,
    /// Which launch elevations ([`launch_elevations_rad`]).
    pub launch_set: LaunchSet,
    /// A ray is near a fold at distance D when |∂h/∂α| exceeds this × D.
    pub fold_factor: f64,
}

impl StressConfig {
    /// The fast study: the seven tolerances, five observers, the fast launch set, 5/10/20/26 km,
    /// a 1e-7 m self-reference.
    pub fn fast() -> Self {
        StressConfig {
            tolerances_m: STRESS_TOLERANCES_M.to_vec(),
            reference_tolerance_m: 1e-7,
            reference_max_steps: 20_000_000,
            observers_m: STRESS_OBSERVERS_M.to_vec(),
            distances_m: STRESS_DISTANCES_M.to_vec(),
            launch_set: LaunchSet::Fast,
            fold_factor: 3.0,
        }
    }

    /// As [`fast`](Self::fast) with the long launch set.
    pub fn long() -> Self {
        StressConfig {
            launch_set: LaunchSet::Long,
            ..Self::fast()
        }
    }

    fn check(&self) -> Result<(), StressError> {
        let bad = |m: &str| Err(StressError::InvalidConfig(m.to_string()));
        let positive = |v: &f64| v.is_finite() && *v > 0.0;
        if self.tolerances_m.is_empty() || !self.tolerances_m.iter().all(positive) {
            return bad("tolerances must be finite and > 0");
        }
        if !positive(&self.reference_tolerance_m) || self.reference_max_steps == 0 {
            return bad("the self-reference needs a tolerance > 0 and a step budget");
        }
        let top = TracerConfig::default().top_m;
        if self.observers_m.is_empty() || !self.observers_m.iter().all(|h| *h >= 0.0 && *h < top) {
            return bad("observers must lie in [0, 40 km)");
        }
        if self.distances_m.is_empty()
            || !self.distances_m.iter().all(positive)
            || self.distances_m.windows(2).any(|w| w[1] <= w[0])
        {
            return bad("distances must be > 0 and ascending");
        }
        if !positive(&self.fold_factor) {
            return bad("the fold factor must be > 0");
        }
        Ok(())
    }

    /// The tracer settings for tolerance `tolerance_m` (m).
    fn tracer(&self, tolerance_m: f64) -> TracerConfig {
        TracerConfig {
            tolerance_m,
            ..TracerConfig::default()
        }
    }
}

/// Why the stress study could not run.
#[derive(Debug, thiserror::Error)]
pub enum StressError {
    /// A setting is out of range.
    #[error("invalid stress benchmark setting: {0}")]
    InvalidConfig(String),
    /// A stress sounding could not be written.
    #[error("cannot write the stress sounding {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A stress atmosphere could not be loaded.
    #[error("cannot load stress atmosphere {name}")]
    Atmosphere {
        /// The atmosphere.
        name: String,
        /// Why (boxed: the loader's error is large).
        #[source]
        source: Box<crate::atmosphere::AtmosphereError>,
    },
    /// The tracer refused the input.
    #[error("cannot trace stress atmosphere {name}")]
    Tracer {
        /// The atmosphere.
        name: String,
        /// Why.
        #[source]
        source: TracerError,
    },
    /// The plot could not be drawn.
    #[error("cannot draw the error-against-tolerance plot: {0}")]
    Plot(String),
}

/// Where a worst error was found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayAt {
    /// Observer height (m).
    pub observer_m: f64,
    /// Launch elevation (deg).
    pub elevation_deg: f64,
    /// Ground distance (m).
    pub distance_m: f64,
}

/// One tolerance of one atmosphere, over every observer and launch.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StressRow {
    /// Tolerance (m).
    pub tolerance_m: f64,
    /// Rays traced.
    pub rays: usize,
    /// Rays per termination (by [`Termination::name`](crate::tracer::Termination::name)).
    pub terminations: BTreeMap<&'static str, usize>,
    /// Rays without a termination (must be 0).
    pub untyped: usize,
    /// Rays with a non-finite height, end point, direction, refraction or drift (must be 0).
    pub non_finite: usize,
    /// Largest Bouguer drift of any ray.
    pub max_drift: f64,
    /// Rays whose drift exceeds [`bouguer_drift_bound`].
    pub drift_over_bound: usize,
    /// Ray·distances compared with the self-reference (reached in both runs, not near a fold).
    pub compared: usize,
    /// Ray·distances reached in both runs but left out as near a fold.
    pub near_fold: usize,
    /// Ray·distances left out because the self-reference differs from a run at
    /// [`FOLD_SLOPE_TOLERANCE_M`] by more than a tenth of this row's tolerance.
    pub unsettled: usize,
    /// Largest |Δh| over the compared ray·distances (m).
    pub max_error_m: Option<f64>,
    /// Where it was found.
    pub worst: Option<RayAt>,
}

/// The stress study of one atmosphere.
#[derive(Debug, Clone, PartialEq)]
pub struct StressResult {
    /// The atmosphere's name.
    pub name: String,
    /// What it is.
    pub description: String,
    /// Launches per tolerance (all observers).
    pub launches: usize,
    /// One row per tolerance, in the config's order.
    pub rows: Vec<StressRow>,
}

/// Whether every number of `rec` that reaches an image is finite.
fn record_is_finite(rec: &RayRecord) -> bool {
    let end = &rec.end;
    rec.heights_m.iter().flatten().all(|h| h.is_finite())
        && rec
            .target_elevations_rad
            .iter()
            .flatten()
            .all(|e| e.is_finite())
        && [
            end.arc_length_m,
            end.distance_m,
            end.height_m,
            end.elevation_rad,
            rec.end_observer_elevation_rad,
            rec.invariant_drift,
        ]
        .iter()
        .all(|v| v.is_finite())
        && rec.refraction_rad.is_none_or(|r| r.is_finite())
}

/// The self-reference of one launch, whether it is settled at each distance, and |∂h/∂α|.
struct Reference {
    record: RayRecord,
    /// |Δh| between the self-reference and a run at [`FOLD_SLOPE_TOLERANCE_M`] at each distance
    /// (+∞ where only one gets there): the self-reference's own error is not known to be
    /// smaller, so it judges a run at tolerance T there only if this is at most T/10.
    spread_m: Vec<f64>,
    slopes: Vec<f64>,
}

impl Reference {
    fn new<S: StratifiedIndex + ?Sized>(
        reference: &Tracer<'_, S>,
        check: &Tracer<'_, S>,
        observer_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
    ) -> Result<Self, TracerError> {
        let record = reference.trace(observer_m, elevation_rad, distances_m)?;
        let checked = check.trace(observer_m, elevation_rad, distances_m)?;
        let spread_m = record
            .heights_m
            .iter()
            .zip(&checked.heights_m)
            .map(|(a, b)| match (a, b) {
                (Some(a), Some(b)) => (a - b).abs(),
                _ => f64::INFINITY,
            })
            .collect();
        Ok(Reference {
            record,
            spread_m,
            slopes: fold_slopes(check, observer_m, elevation_rad, distances_m)?,
        })
    }
}

/// |∂h/∂α| at each distance by central differences of `tracer` (+∞ where a neighbour does not
/// get there).
fn fold_slopes<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    observer_m: f64,
    elevation_rad: f64,
    distances_m: &[f64],
) -> Result<Vec<f64>, TracerError> {
    let da = FOLD_SLOPE_STEP_RAD;
    let up = tracer.trace(observer_m, elevation_rad + da, distances_m)?;
    let down = tracer.trace(observer_m, elevation_rad - da, distances_m)?;
    Ok(up
        .heights_m
        .iter()
        .zip(&down.heights_m)
        .map(|(u, d)| match (u, d) {
            (Some(u), Some(d)) => ((u - d) / (2.0 * da)).abs(),
            _ => f64::INFINITY,
        })
        .collect())
}

/// `value ≤ bound`, false for NaN.
fn within(value: f64, bound: f64) -> bool {
    value <= bound
}

impl StressRow {
    /// Add the records of one observer's launches, traced at this row's tolerance.
    fn add(
        &mut self,
        observer_m: f64,
        records: &[RayRecord],
        references: &[Reference],
        config: &StressConfig,
    ) {
        let farthest = config.distances_m[config.distances_m.len() - 1];
        let tracer = config.tracer(self.tolerance_m);
        let bound = bouguer_drift_bound(self.tolerance_m, error_length_m(&tracer, farthest));
        for (rec, reference) in records.iter().zip(references) {
            self.rays += 1;
            match rec.termination {
                Some(t) => *self.terminations.entry(t.name()).or_default() += 1,
                None => self.untyped += 1,
            }
            self.non_finite += usize::from(!record_is_finite(rec));
            self.max_drift = self.max_drift.max(rec.invariant_drift);
            self.drift_over_bound += usize::from(!within(rec.invariant_drift, bound));
            for (k, &d) in config.distances_m.iter().enumerate() {
                let (Some(h), Some(r)) = (rec.heights_m[k], reference.record.heights_m[k]) else {
                    continue;
                };
                if !within(reference.slopes[k], config.fold_factor * d) {
                    self.near_fold += 1;
                    continue;
                }
                if !within(reference.spread_m[k], 0.1 * self.tolerance_m) {
                    self.unsettled += 1;
                    continue;
                }
                self.compared += 1;
                let err = (h - r).abs();
                if self.max_error_m.is_none_or(|m| err > m) {
                    self.max_error_m = Some(err);
                    self.worst = Some(RayAt {
                        observer_m,
                        elevation_deg: rec.elevation_rad.to_degrees(),
                        distance_m: d,
                    });
                }
            }
        }
    }
}

/// Measure one observer of `atm` into `rows` (one per tolerance); `progress` after the
/// self-reference and after each tolerance.
fn measure_observer(
    atm: &RefractiveAtmosphere,
    atmosphere: &StressAtmosphere,
    observer_m: f64,
    config: &StressConfig,
    rows: &mut [StressRow],
    progress: &mut dyn FnMut(),
) -> Result<usize, TracerError> {
    let radius = TracerConfig::default().earth_radius_m;
    let corners = &atmosphere.corner_heights_m;
    let elevations = launch_elevations_rad(atm, radius, observer_m, corners, config.launch_set);
    let distances = &config.distances_m;
    let reference = Tracer::new(
        atm,
        TracerConfig {
            max_steps: config.reference_max_steps,
            ..config.tracer(config.reference_tolerance_m)
        },
    )?;
    let check = Tracer::new(atm, config.tracer(FOLD_SLOPE_TOLERANCE_M))?;
    let references = elevations
        .par_iter()
        .map(|&a| Reference::new(&reference, &check, observer_m, a, distances))
        .collect::<Result<Vec<_>, TracerError>>()?;
    progress();
    for row in rows.iter_mut() {
        let tracer = Tracer::new(atm, config.tracer(row.tolerance_m))?;
        let records = tracer.trace_fan(observer_m, &elevations, distances)?;
        row.add(observer_m, &records, &references, config);
        progress();
    }
    Ok(elevations.len())
}

/// Write `atmosphere` into `dir`, load it unsmoothed and measure it. `progress` is called after
/// each observer's self-reference and after each of its tolerances.
pub fn measure_stress(
    atmosphere: &StressAtmosphere,
    dir: &Path,
    config: &StressConfig,
    progress: &mut dyn FnMut(),
) -> Result<StressResult, StressError> {
    config.check()?;
    let name = atmosphere.name.to_string();
    let path = dir.join(format!("{name}.csv"));
    std::fs::write(&path, &atmosphere.csv_text).map_err(|source| StressError::Io {
        path: path.clone(),
        source,
    })?;
    let options = AtmosphereOptions {
        smooth_m: 0.0,
        ..AtmosphereOptions::default()
    };
    let loaded =
        load_atmosphere(&AtmosphereSource::Sounding(path), &options).map_err(|source| {
            StressError::Atmosphere {
                name: name.clone(),
                source: Box::new(source),
            }
        })?;
    let mut rows: Vec<StressRow> = config
        .tolerances_m
        .iter()
        .map(|&tolerance_m| StressRow {
            tolerance_m,
            ..StressRow::default()
        })
        .collect();
    let mut launches = 0;
    for &h0 in &config.observers_m {
        launches += measure_observer(
            &loaded.refractive,
            atmosphere,
            h0,
            config,
            &mut rows,
            progress,
        )
        .map_err(|source| StressError::Tracer {
            name: name.clone(),
            source,
        })?;
    }
    Ok(StressResult {
        name,
        description: atmosphere.description.to_string(),
        launches,
        rows,
    })
}

fn fmt_m(v: f64) -> String {
    format!("{v:.1e}")
}

fn fmt_tol(t: f64) -> String {
    if (0.1..=100.0).contains(&t) {
        format!("{t}")
    } else {
        format!("{t:e}")
    }
}

/// The markdown table head `| first | <tolerances> |` and its rule.
fn tolerance_head(first: &str, config: &StressConfig) -> String {
    let mut head = format!("| {first} |");
    let mut rule = String::from("|---|");
    for t in &config.tolerances_m {
        head.push_str(&format!(" {} |", fmt_tol(*t)));
        rule.push_str("---:|");
    }
    format!("{head}\n{rule}\n")
}

/// Two neighbouring tolerances of one atmosphere whose worst error grows as the tolerance shrinks
/// (see [`growing_rows`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GrowingRow {
    /// The atmosphere.
    pub atmosphere: String,
    /// The looser tolerance (m) and its worst error (m).
    pub loose: (f64, f64),
    /// The tighter tolerance (m) and its worst error (m).
    pub tight: (f64, f64),
}

/// Each pair of neighbouring tolerances of an atmosphere whose worst error grows by more than
/// twice the self-reference's tolerance as the tolerance shrinks. Each measured error is off the
/// true error by at most the self-reference's own error, which its tolerance bounds, so a smaller
/// growth says nothing about the tracer.
pub fn growing_rows(results: &[StressResult], config: &StressConfig) -> Vec<GrowingRow> {
    let allowance_m = 2.0 * config.reference_tolerance_m;
    let mut out = Vec::new();
    for r in results {
        for pair in r.rows.windows(2) {
            if let (Some(loose), Some(tight)) = (pair[0].max_error_m, pair[1].max_error_m)
                && tight > loose + allowance_m
            {
                out.push(GrowingRow {
                    atmosphere: r.name.clone(),
                    loose: (pair[0].tolerance_m, loose),
                    tight: (pair[1].tolerance_m, tight),
                });
            }
        }
    }
    out
}

/// `STRESS.md`: the settings, the plot, and per atmosphere and tolerance the worst error against
/// the self-reference, the worst Bouguer drift, and the rays' terminations. `plot_rel` is the
/// plot's path relative to the file.
pub fn stress_markdown(
    results: &[StressResult],
    config: &StressConfig,
    command: &str,
    plot_rel: &str,
) -> String {
    let mut s = String::from("# Stress suite: error against tolerance\n\n");
    s.push_str(&format!(
        "Generated by `{command}` — every number below is measured by that command; do not \
         edit by hand, re-run it.\n\n"
    ));
    s.push_str(&settings_markdown(config));
    s.push_str(&format!("![error against tolerance]({plot_rel})\n\n"));
    s.push_str(&error_table(results, config));
    s.push_str(&drift_table(results, config));
    s.push_str(&termination_table(results));
    s
}

fn settings_markdown(config: &StressConfig) -> String {
    let km: Vec<String> = config
        .distances_m
        .iter()
        .map(|d| format!("{}", d / 1000.0))
        .collect();
    let observers: Vec<String> = config.observers_m.iter().map(|h| format!("{h}")).collect();
    let farthest = config.distances_m.last().copied().unwrap_or(0.0);
    let length = error_length_m(&config.tracer(1.0), farthest);
    format!(
        "* Atmospheres: the fourteen stress soundings of `ghostship::verify::stress` (listed in \
         the last table), fitted unsmoothed (`smooth_m = 0`).\n\
         * Observers {} m (top 40 km); launch set `{:?}`: elevations −5°…+90° with 0 and \
         ±1e-9 rad, and rays launched exactly tangent to every layer corner and its neighbouring \
         breaks (the elevation whose Bouguer invariant puts the turning point there).\n\
         * Error: largest |Δh| at {} km against the tracer's own run at {:e} m — a \
         **self-reference**: it shows how the error falls with the tolerance, not the absolute \
         accuracy, which `tests/integration/stress.rs` checks against the independent reference \
         tracer. Left out and counted: rays near a fold (|∂h/∂α| > {} × D), and ray·distances where \
         the self-reference is *unsettled* (it differs from a run at 1e-6 m by more than a tenth of \
         the tolerance judged, so its own error is not known to be small enough).\n\
         * Bouguer drift: the largest |I − I₀|/(n₀r₀) of any ray, I = n·r·cos ψ; the bound is \
         T/L + 1e-11 (T the tolerance, L = {} km the tracer's error length).\n\n",
        observers.join(", "),
        config.launch_set,
        km.join(", "),
        config.reference_tolerance_m,
        config.fold_factor,
        length / 1000.0,
    )
}

fn error_table(results: &[StressResult], config: &StressConfig) -> String {
    let mut s = String::from(
        "## Largest |Δh| (m) against the self-reference, by tolerance (m)\n\n\
         **Bold**: above the tolerance.\n\n",
    );
    s.push_str(&tolerance_head("atmosphere", config));
    let mut worst_ratio = vec![0.0f64; config.tolerances_m.len()];
    for r in results {
        s.push_str(&format!("| {} |", r.name));
        for (k, row) in r.rows.iter().enumerate() {
            let cell = match row.max_error_m {
                Some(e) if e > row.tolerance_m => format!("**{}**", fmt_m(e)),
                Some(e) => fmt_m(e),
                None => "–".into(),
            };
            worst_ratio[k] = worst_ratio[k].max(row.max_error_m.unwrap_or(0.0) / row.tolerance_m);
            s.push_str(&format!(" {cell} |"));
        }
        s.push('\n');
    }
    s.push_str("| *worst error / tolerance* |");
    for ratio in worst_ratio {
        s.push_str(&format!(" *{ratio:.2}* |"));
    }
    s.push_str("\n\n");
    s.push_str(&growing_rows_markdown(results, config));
    s.push_str(&worst_rays_table(results, config));
    s
}

/// The rows of [`growing_rows`], or a line saying there are none.
fn growing_rows_markdown(results: &[StressResult], config: &StressConfig) -> String {
    let allowance = 2.0 * config.reference_tolerance_m;
    let rows = growing_rows(results, config);
    if rows.is_empty() {
        return format!(
            "Every row falls (or stays) as the tolerance shrinks, to within {allowance:e} m \
             (twice the self-reference's tolerance).\n\n"
        );
    }
    let mut s = format!(
        "Rows whose worst error grows as the tolerance shrinks by more than {allowance:e} m \
             (twice the self-reference's tolerance):\n\n"
    );
    for row in rows {
        s.push_str(&format!(
            "* {}: {} m at {} m → {} m at {} m\n",
            row.atmosphere,
            fmt_m(row.loose.1),
            fmt_tol(row.loose.0),
            fmt_m(row.tight.1),
            fmt_tol(row.tight.0)
        ));
    }
    s.push('\n');
    s
}

/// Per tolerance, the ray with the largest error relative to the tolerance.
fn worst_rays_table(results: &[StressResult], config: &StressConfig) -> String {
    let mut s = String::from(
        "Where the largest error / tolerance is:\n\n\
         | tolerance (m) | atmosphere | observer (m) | elevation (°) | distance (km) | error (m) |\n\
         |---:|---|---:|---:|---:|---:|\n",
    );
    for (k, &t) in config.tolerances_m.iter().enumerate() {
        let worst = results
            .iter()
            .filter_map(|r| {
                let row = r.rows.get(k)?;
                Some((r.name.as_str(), row.max_error_m?, row.worst?))
            })
            .max_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((name, e, at)) = worst {
            s.push_str(&format!(
                "| {} | {name} | {} | {:.6} | {} | {} |\n",
                fmt_tol(t),
                at.observer_m,
                at.elevation_deg,
                at.distance_m / 1000.0,
                fmt_m(e)
            ));
        }
    }
    s.push('\n');
    s
}

fn drift_table(results: &[StressResult], config: &StressConfig) -> String {
    let farthest = config.distances_m.last().copied().unwrap_or(0.0);
    let mut s = String::from(
        "## Largest Bouguer drift, by tolerance (m)\n\n**Bold**: above the bound (first row).\n\n",
    );
    s.push_str(&tolerance_head("atmosphere", config));
    s.push_str("| *bound T/L + 1e-11* |");
    for &t in &config.tolerances_m {
        let bound = bouguer_drift_bound(t, error_length_m(&config.tracer(t), farthest));
        s.push_str(&format!(" *{}* |", fmt_m(bound)));
    }
    s.push('\n');
    for r in results {
        s.push_str(&format!("| {} |", r.name));
        for row in &r.rows {
            let cell = fmt_m(row.max_drift);
            if row.drift_over_bound > 0 {
                s.push_str(&format!(" **{cell}** ({} rays) |", row.drift_over_bound));
            } else {
                s.push_str(&format!(" {cell} |"));
            }
        }
        s.push('\n');
    }
    s.push('\n');
    s
}

fn termination_table(results: &[StressResult]) -> String {
    let mut s = String::from(
        "## Rays and how they ended (all tolerances together)\n\n\
         | atmosphere | what | rays | terminations | untyped | non-finite | near-fold / unsettled / compared |\n\
         |---|---|---:|---|---:|---:|---:|\n",
    );
    for r in results {
        let mut ends: BTreeMap<&str, usize> = BTreeMap::new();
        let (mut rays, mut untyped, mut non_finite) = (0, 0, 0);
        let (mut near, mut unsettled, mut compared) = (0, 0, 0);
        for row in &r.rows {
            for (k, v) in &row.terminations {
                *ends.entry(k).or_default() += v;
            }
            rays += row.rays;
            untyped += row.untyped;
            non_finite += row.non_finite;
            near += row.near_fold;
            unsettled += row.unsettled;
            compared += row.compared;
        }
        let ends: Vec<String> = ends.iter().map(|(k, v)| format!("{k} {v}")).collect();
        s.push_str(&format!(
            "| {} | {} | {rays} | {} | {untyped} | {non_finite} | {near} / {unsettled} / {compared} |\n",
            r.name,
            r.description,
            ends.join(", ")
        ));
    }
    s.push('\n');
    s
}

fn plot_err<E: std::fmt::Display>(e: E) -> StressError {
    StressError::Plot(e.to_string())
}

/// The chart the lines are drawn on: log tolerance against log error.
type LogChart<'a, 'b> = ChartContext<
    'a,
    BitMapBackend<'b>,
    Cartesian2d<
        plotters::coord::combinators::LogCoord<f64>,
        plotters::coord::combinators::LogCoord<f64>,
    >,
>;

/// Each result's (tolerance, largest error) points (errors of 0 drawn at [`PLOT_FLOOR_M`]) and
/// the axis ranges (x0, x1, y0, y1) around them and the line error = tolerance.
type PlotPoints = (Vec<Vec<(f64, f64)>>, (f64, f64, f64, f64));

fn plot_points(results: &[StressResult]) -> PlotPoints {
    let points: Vec<Vec<(f64, f64)>> = results
        .iter()
        .map(|r| {
            r.rows
                .iter()
                .filter_map(|row| Some((row.tolerance_m, row.max_error_m?.max(PLOT_FLOOR_M))))
                .collect()
        })
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
    for &(x, y) in points.iter().flatten() {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y.max(x)));
    }
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (1e-5, 10.0, 1e-9, 10.0);
    }
    (points, (x0 / 2.0, x1 * 2.0, y0 / 3.0, y1 * 3.0))
}

/// The line error = tolerance across `x0..x1` and one line per result (solid where `study`).
fn draw_lines(
    chart: &mut LogChart<'_, '_>,
    results: &[StressResult],
    points: &[Vec<(f64, f64)>],
    study: &[bool],
    (x0, x1): (f64, f64),
) -> Result<(), StressError> {
    let guide = RGBColor(90, 90, 90);
    chart
        .draw_series(DashedLineSeries::new(
            [(x0, x0), (x1, x1)],
            10,
            6,
            guide.stroke_width(2),
        ))
        .map_err(plot_err)?
        .label("error = tolerance")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], guide.stroke_width(2)));
    for (i, (r, pts)) in results.iter().zip(points).enumerate() {
        let colour = LINE_COLOURS[i % LINE_COLOURS.len()];
        let style = colour.stroke_width(2);
        let series = if study.get(i).copied().unwrap_or(true) {
            chart.draw_series(LineSeries::new(pts.clone(), style))
        } else {
            chart.draw_series(DashedLineSeries::new(pts.clone(), 8, 5, style))
        };
        series
            .map_err(plot_err)?
            .label(r.name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(3))
            });
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 4, colour.filled())))
            .map_err(plot_err)?;
    }
    Ok(())
}

/// The two lines under the plot: what the error is measured against and what the lines mean.
const PLOT_NOTE: [&str; 2] = [
    "Error against the tracer's own run at 1e-7 m (a self-reference; tests/integration/stress.rs \
     checks the same suite against an independent reference tracer).",
    "Left out: rays near a fold and where the self-reference is unsettled. Solid: the accuracy \
     study's six atmospheres; dashed: the other eight.",
];

/// The log-log plot of the largest error against the tolerance, one line per atmosphere (solid
/// where `study` says it is one of the accuracy study's six, dashed otherwise), with the line
/// error = tolerance and a note on what the error is measured against. PNG bytes,
/// `width × height` pixels.
pub fn error_vs_tolerance_png(
    results: &[StressResult],
    study: &[bool],
    width: u32,
    height: u32,
) -> Result<Vec<u8>, StressError> {
    crate::output::plot::register_plot_font().map_err(StressError::Plot)?;
    let font = crate::output::plot::PLOT_FONT;
    let (points, (x0, x1, y0, y1)) = plot_points(results);
    let mut buffer = vec![255u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let (plot_area, note_area) = root.split_vertically(height.saturating_sub(60));
        let mut chart = ChartBuilder::on(&plot_area)
            .caption(
                "Stress suite: largest |Δh| at 5–26 km against the tracer tolerance",
                (font, 24),
            )
            .margin(20)
            .x_label_area_size(50)
            .y_label_area_size(80)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("tolerance_m (m)")
            .y_desc("largest |Δh| over all rays and distances (m)")
            .x_label_formatter(&|v| format!("{v:.0e}"))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .label_style((font, 16))
            .axis_desc_style((font, 18))
            .draw()
            .map_err(plot_err)?;
        draw_lines(&mut chart, results, &points, study, (x0, x1))?;
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((font, 14))
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(plot_err)?;
        for (i, line) in PLOT_NOTE.iter().enumerate() {
            let at = (20, 6 + 22 * i as i32);
            note_area
                .draw(&Text::new(*line, at, (font, 15).into_font()))
                .map_err(plot_err)?;
        }
        root.present().map_err(plot_err)?;
    }
    crate::output::plot::rgb8_to_png(&buffer, width, height).map_err(StressError::Plot)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// n = 1 + a·exp(−h/H): a smooth index whose M = (n − 1 + h/R) grows with height.
    struct Exponential;

    impl StratifiedIndex for Exponential {
        fn index_and_derivative(&self, h: f64) -> (f64, f64) {
            let e = (-h / 8_000.0).exp();
            (1.0 + 2.8e-4 * e, -2.8e-4 * e / 8_000.0)
        }
    }

    #[test]
    fn tangent_elevation_puts_the_turning_point_on_the_height() {
        let r = 6_371_000.0;
        // Downward to a perigee at 10 m from 100 m: n·r·cos α = n(10)·(R + 10).
        let a = tangent_elevation_rad(&Exponential, r, 100.0, 10.0).unwrap();
        assert!(a < 0.0);
        let (n0, _) = Exponential.index_and_derivative(100.0);
        let (nt, _) = Exponential.index_and_derivative(10.0);
        let lhs = n0 * (r + 100.0) * a.cos();
        assert!((lhs - nt * (r + 10.0)).abs() < 1e-6, "{lhs}");
        // Upward from below: M grows with height, so no apex can lie above the observer.
        assert_eq!(tangent_elevation_rad(&Exponential, r, 10.0, 100.0), None);
        assert_eq!(
            tangent_elevation_rad(&Exponential, r, 10.0, 10.0),
            Some(0.0)
        );
        assert_eq!(tangent_elevation_rad(&Exponential, r, f64::NAN, 10.0), None);
    }

    #[test]
    fn launch_sets_span_the_elevations_and_include_the_tangents() {
        let r = 6_371_000.0;
        let fast = launch_elevations_rad(&Exponential, r, 100.0, &[10.0, 50.0], LaunchSet::Fast);
        assert!(fast.windows(2).all(|w| w[1] > w[0]));
        assert_eq!(fast[fast.len() - 1], std::f64::consts::FRAC_PI_2);
        assert!(fast.contains(&0.0) && fast.contains(&TINY_ELEVATION_RAD));
        let tangent = tangent_elevation_rad(&Exponential, r, 100.0, 50.0).unwrap();
        assert!(fast.contains(&tangent));
        let long = launch_elevations_rad(&Exponential, r, 100.0, &[10.0, 50.0], LaunchSet::Long);
        assert!(long.len() > 3 * fast.len());
    }

    #[test]
    fn configs_are_checked() {
        StressConfig::fast().check().unwrap();
        StressConfig::long().check().unwrap();
        let mut c = StressConfig::fast();
        c.observers_m.push(40_000.0);
        assert!(c.check().is_err());
        let mut c = StressConfig::fast();
        c.tolerances_m.push(0.0);
        assert!(c.check().is_err());
    }

    /// A made-up result: errors of 0.1 × the tolerance, one over it at 1 m.
    fn result(name: &str) -> StressResult {
        let rows = STRESS_TOLERANCES_M
            .iter()
            .map(|&t| StressRow {
                tolerance_m: t,
                rays: 10,
                terminations: BTreeMap::from([("ground", 4), ("targets_done", 6)]),
                max_error_m: Some(if t == 1.0 { 3.0 } else { 0.1 * t }),
                worst: Some(RayAt {
                    observer_m: 2.0,
                    elevation_deg: 0.1,
                    distance_m: 26_000.0,
                }),
                compared: 30,
                max_drift: 1e-12,
                ..StressRow::default()
            })
            .collect();
        StressResult {
            name: name.into(),
            description: "a test".into(),
            launches: 10,
            rows,
        }
    }

    #[test]
    fn markdown_and_plot_show_every_atmosphere_and_tolerance() {
        let results = [result("one"), result("two")];
        let config = StressConfig::fast();
        let md = stress_markdown(&results, &config, "ghostship bench stress", "docs/x.png");
        assert!(md.contains("![error against tolerance](docs/x.png)"));
        assert!(md.contains("| one | 1.0e0 | **3.0e0** |"), "{md}");
        assert!(
            md.contains("| *worst error / tolerance* | *0.10* | *3.00* |"),
            "{md}"
        );
        assert!(
            md.contains("| one | a test | 70 | ground 28, targets_done 42 |"),
            "{md}"
        );
        let png = error_vs_tolerance_png(&results, &[true, false], 700, 450).unwrap();
        let img = image::load_from_memory(&png).unwrap();
        assert_eq!((img.width(), img.height()), (700, 450));
    }

    #[test]
    fn drift_bound_scales_with_the_tolerance() {
        assert_eq!(bouguer_drift_bound(0.0, 30_000.0), 1e-11);
        let b = bouguer_drift_bound(3.0, 30_000.0);
        assert!((b - 1e-4 - 1e-11).abs() < 1e-18, "{b}");
    }
}
