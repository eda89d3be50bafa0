//! The stress suite (issue 8, item 4). Fast mode runs with `cargo test --release`; the long mode
//! (denser fans, rays tangent to many more breaks, the 3-D path and the 5 000 km duct at every
//! tolerance) is `#[ignore]`d: `cargo test --release --test integration stress -- --ignored`.
//!
//! Atmospheres: the fourteen of [`stress_suite`] — the accuracy study's six and superadiabatic
//! surface layers, 0.1 m layers with 30 K jumps, surface layers of 0.105/0.110/0.115/0.120 K/m
//! and a long elevated duct — fitted unsmoothed. Observers 0.1 m, 2 m, 100 m, 2 km and 39 km
//! (top 40 km). Elevations −5°…+90° with 0, ±1e-9 rad and rays exactly tangent to every layer
//! corner and its neighbouring breaks ([`launch_elevations_rad`]). For every ray at each of the
//! seven tolerances 10 m … 0.01 mm:
//!
//! * it ends with a typed termination; its heights at the targets are finite or `None`; its end
//!   point, directions, refraction and drift are finite (no NaN reaches an image);
//! * its Bouguer drift is at most [`bouguer_drift_bound`] = T/L + 1e-11 (T the tolerance, L
//!   the tracer's error length, 30 km here; README, "Stress suite");
//! * if |α| ≤ 30° (the independent reference's range) and it is not near a fold
//!   (|∂h/∂α| > 3·D), its height at 5/10/20/26 km is within the tolerance of the **independent**
//!   reference tracer ([`crate::support::reference`]), wherever that reference has converged to
//!   a tenth of the tolerance (refined per ray, [`converged_reference`]; ray·distances where
//!   it does not are counted and printed, and may be at most 5 % of those compared);
//! * per atmosphere, the worst such error does not grow as the tolerance shrinks, beyond
//!   [`MONOTONE_ALLOWANCE_M`], over the rays whose reference is converged to
//!   [`REFERENCE_TARGET_M`].
//!
//! Also: a level ray carried 5 000 km by the long duct, the 3-D path ([`trace_field`]) against
//! the same reference, and a render of stress atmospheres with no non-finite pixel.

use std::sync::{Arc, OnceLock};

use glam::DVec3;
use rayon::prelude::*;

use ghostship::profile::Profile;
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::render::{RenderOptions, prepare_tracer, render_scene};
use ghostship::scene::Scene;
use ghostship::tracer::{
    Ground, NoHook, RayRecord, Spherical, Termination, Tracer, TracerConfig, trace_field,
};
use ghostship::verify::stress::{LONG_DUCT_OBSERVER_M, StressAtmosphere, stress_suite};
use ghostship::verify::stress_report::{
    FOLD_SLOPE_TOLERANCE_M, LaunchSet, STRESS_DISTANCES_M, STRESS_OBSERVERS_M, STRESS_TOLERANCES_M,
    bouguer_drift_bound, error_length_m, launch_elevations_rad,
};

use crate::support::fans::{Refinement, converged_reference, csv_profile, fold_slopes, within};
use crate::support::reference::{
    BreakSource, FineSteps, RefReach, ReferenceSteps, atmosphere_index,
    reference_heights_with_steps,
};

const R: f64 = ghostship::units::EARTH_RADIUS_M;
const TOP_M: f64 = 40_000.0;
/// Rays steeper than this (deg) are checked for termination, finiteness and drift only: the
/// θ-parametrised reference is built for near-horizontal rays (it refuses 60°).
const REFERENCE_MAX_ELEVATION_DEG: f64 = 30.0;
/// The reference is refined per ray until its error estimate is at most this (m).
const REFERENCE_TARGET_M: f64 = 5e-8;
/// At most this many further halvings of the reference's ground step.
const REFERENCE_MAX_HALVINGS: u32 = 3;
/// How much the worst error of an atmosphere may exceed the worst error at the next looser
/// tolerance (m), over the rays whose reference estimate is at most [`REFERENCE_TARGET_M`]. Both
/// errors are measured against the same reference heights, each within its estimate of the
/// truth (the estimate is a difference of successive refinements, ≈ 63× the actual error once
/// the sixth-order method is in its asymptotic range), so two measured errors of rays with the
/// same true error differ by at most twice the estimate. The allowance is that — the
/// reference's own accuracy, nothing more.
const MONOTONE_ALLOWANCE_M: f64 = 2.0 * REFERENCE_TARGET_M;

/// The stress soundings' layers lie below this height (m): levels 0.5 m apart (0.1 m at the
/// thin jumps), where the reference takes its fine height steps.
const LAYERS_TOP_M: f64 = 310.0;

/// One stress atmosphere, fitted, refracted, with the column for the reference's breaks.
struct Loaded {
    stress: StressAtmosphere,
    profile: Profile,
    atm: RefractiveAtmosphere,
    /// A quarter of the smallest gap between breaks below [`LAYERS_TOP_M`] (m): the reference's
    /// height step there, so that its steps subdivide every layer.
    fine_height_step_m: f64,
    /// The reference's first ground step for grazing rays (m): a twentieth of the shortest
    /// ground length over which a layer can turn a grazing ray round
    /// ([`shortest_turn_m`]), at most 50 m.
    grazing_ground_step_m: f64,
}

/// The shortest ground length (m) over which a layer of `atm` between consecutive corners (and
/// the ground) can turn a ray round: a ray grazing a layer of thickness d whose |dn/dh| is κ
/// turns back within it at up to ψ = √(2κd) and needs 2ψ/κ = 2√(2d/κ) of ground to do so
/// (≈ 40 m for the 0.1 m layers with 30 K jumps, kilometres for the other stress layers).
fn shortest_turn_m(atm: &RefractiveAtmosphere, corner_heights_m: &[f64]) -> f64 {
    let bounds: Vec<f64> = std::iter::once(0.0)
        .chain(corner_heights_m.iter().copied())
        .collect();
    bounds
        .windows(2)
        .map(|w| {
            let d = w[1] - w[0];
            let kappa = (1..20)
                .map(|i| atm.exact(w[0] + d * i as f64 / 20.0).1.abs())
                .fold(0.0, f64::max);
            2.0 * (2.0 * d / kappa).sqrt()
        })
        .fold(f64::INFINITY, f64::min)
}

fn load_suite(dir: &std::path::Path) -> Vec<Loaded> {
    stress_suite()
        .into_iter()
        .map(|stress| {
            let profile = csv_profile(dir, stress.name, &stress.csv_text);
            let atm =
                RefractiveAtmosphere::new(Arc::new(profile.clone()), 550.0).expect("refracts");
            let low: Vec<f64> = profile
                .levels()
                .iter()
                .map(|l| l.height_m - atm.surface_height_m())
                .filter(|&h| h <= LAYERS_TOP_M)
                .collect();
            let gap = low
                .windows(2)
                .map(|w| w[1] - w[0])
                .fold(f64::INFINITY, f64::min);
            let turn = shortest_turn_m(&atm, &stress.corner_heights_m);
            Loaded {
                stress,
                profile,
                fine_height_step_m: 0.25 * gap,
                grazing_ground_step_m: (turn / 20.0).min(50.0),
                atm,
            }
        })
        .collect()
}

fn config(tolerance_m: f64) -> TracerConfig {
    TracerConfig {
        tolerance_m,
        top_m: TOP_M,
        ..TracerConfig::default()
    }
}

/// The reference's first step limits for a ray: short ground steps for grazing rays from low
/// observers, which run along the layers ([`Loaded::grazing_ground_step_m`]); longer ones, and
/// longer height steps above the layers, for steep rays and for observers at 2 km and above,
/// whose rays within 26 km stay above the layers unless steep. In the layers the
/// height step is at most 0.1 m and a quarter of the thinnest layer
/// ([`Loaded::fine_height_step_m`]).
fn reference_start(loaded: &Loaded, observer_m: f64, elevation_rad: f64) -> ReferenceSteps {
    let a = elevation_rad.to_degrees().abs();
    let (max_ground_step_m, max_height_step_m) = if a <= 2.0 && observer_m < 1_000.0 {
        (loaded.grazing_ground_step_m, 0.2)
    } else if a <= 10.0 {
        (200.0, 0.5)
    } else {
        (200.0, 2.0)
    };
    ReferenceSteps {
        max_ground_step_m,
        max_height_step_m,
        fine: Some(FineSteps {
            below_m: LAYERS_TOP_M,
            max_height_step_m: loaded.fine_height_step_m.min(0.1),
        }),
    }
}

/// One launch: its reference (heights with error estimates) if in the reference's range, and
/// |∂h/∂α| at each distance.
struct Launch {
    elevation_rad: f64,
    reference: Option<Vec<(RefReach, f64)>>,
    slopes: Vec<f64>,
}

fn launches(loaded: &Loaded, observer_m: f64, set: LaunchSet) -> Vec<Launch> {
    let corners = &loaded.stress.corner_heights_m;
    let elevations = launch_elevations_rad(&loaded.atm, R, observer_m, corners, set);
    launches_at(loaded, observer_m, &elevations)
}

/// The launches at `elevations_rad` from `observer_m`, with their references and fold slopes.
fn launches_at(loaded: &Loaded, observer_m: f64, elevations_rad: &[f64]) -> Vec<Launch> {
    let atm = &loaded.atm;
    let index = atmosphere_index(atm, BreakSource::Profile(&loaded.profile));
    let tight = Tracer::new(atm, config(FOLD_SLOPE_TOLERANCE_M)).unwrap();
    elevations_rad
        .par_iter()
        .map(|&a| Launch {
            elevation_rad: a,
            reference: (a.to_degrees().abs() <= REFERENCE_MAX_ELEVATION_DEG).then(|| {
                let refinement = Refinement {
                    steps: reference_start(loaded, observer_m, a),
                    target_m: REFERENCE_TARGET_M,
                    max_halvings: REFERENCE_MAX_HALVINGS,
                };
                converged_reference(
                    &index,
                    R,
                    TOP_M,
                    observer_m,
                    a,
                    &STRESS_DISTANCES_M,
                    refinement,
                )
            }),
            slopes: fold_slopes(&tight, observer_m, a, &STRESS_DISTANCES_M),
        })
        .collect()
}

/// Which property a problem breaks (one test each).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// No typed termination, a non-finite number, or an end outside the atmosphere.
    Record,
    /// Bouguer drift above the bound.
    Drift,
    /// |Δh| against the reference above the tolerance.
    Tolerance,
    /// The worst error grew as the tolerance shrank.
    Monotone,
}

/// What a ray record must satisfy whatever the atmosphere: a typed end, finite numbers, drift
/// within the bound. Returns the problems found (empty if none).
fn record_problems(rec: &RayRecord, config: &TracerConfig, farthest_m: f64) -> Vec<(Kind, String)> {
    let mut out: Vec<(Kind, String)> = Vec::new();
    let mut push = |kind, text: String| out.push((kind, text));
    if rec.termination.is_none() {
        push(Kind::Record, "no termination".into());
    }
    if rec.heights_m.iter().flatten().any(|h| !h.is_finite()) {
        push(
            Kind::Record,
            format!("non-finite height {:?}", rec.heights_m),
        );
    }
    if rec
        .target_elevations_rad
        .iter()
        .flatten()
        .any(|e| !e.is_finite())
    {
        push(Kind::Record, "non-finite target elevation".into());
    }
    let end = &rec.end;
    let end_values = [
        end.arc_length_m,
        end.distance_m,
        end.height_m,
        end.elevation_rad,
        rec.end_observer_elevation_rad,
        rec.invariant_drift,
    ];
    if end_values.iter().any(|v| !v.is_finite())
        || rec.refraction_rad.is_some_and(|r| !r.is_finite())
    {
        push(Kind::Record, format!("non-finite end {end:?}"));
    }
    if end.height_m < -1e-6 || end.height_m > config.top_m + 1e-6 {
        push(
            Kind::Record,
            format!("ended outside the atmosphere at {} m", end.height_m),
        );
    }
    let bound = bouguer_drift_bound(config.tolerance_m, error_length_m(config, farthest_m));
    if !within(rec.invariant_drift, bound) {
        let drift = rec.invariant_drift;
        push(
            Kind::Drift,
            format!("Bouguer drift {drift:.3e} > bound {bound:.3e}"),
        );
    }
    out
}

/// One observer's launches, traced at every tolerance.
struct ObserverRun {
    observer_m: f64,
    launches: Vec<Launch>,
    /// Per tolerance, one record per launch.
    records: Vec<Vec<RayRecord>>,
}

fn run_observer(
    loaded: &Loaded,
    observer_m: f64,
    tolerances_m: &[f64],
    set: LaunchSet,
) -> ObserverRun {
    let launches = launches(loaded, observer_m, set);
    let records = tolerances_m
        .iter()
        .map(|&tol| {
            let tracer = Tracer::new(&loaded.atm, config(tol)).unwrap();
            launches
                .par_iter()
                .map(|l| {
                    tracer
                        .trace(observer_m, l.elevation_rad, &STRESS_DISTANCES_M)
                        .unwrap()
                })
                .collect()
        })
        .collect();
    ObserverRun {
        observer_m,
        launches,
        records,
    }
}

/// The worst of one atmosphere at one tolerance.
#[derive(Debug, Clone, Default)]
struct Worst {
    error_m: f64,
    /// Observer (m), elevation (deg) and distance (m) of the worst error.
    at: (f64, f64, f64),
    /// Ray·distances compared with the reference.
    compared: usize,
    /// Ray·distances left out as near a fold.
    near_fold: usize,
    /// Ray·distances left out because the reference did not converge to a tenth of the
    /// tolerance.
    unconverged: usize,
    rays: usize,
    drift: f64,
    reference_estimate_m: f64,
}

/// One compared ray·distance: the error at each tolerance (`None` where not compared) and the
/// reference's estimate.
struct Comparison {
    errors_m: Vec<Option<f64>>,
    estimate_m: f64,
    /// Observer height (m), launch elevation (°) and distance (m): where, for the messages.
    at: (f64, f64, f64),
}

/// Check every record of `run` (problems pushed with their context), fill `worst` (one per
/// tolerance) and return the comparisons for the monotonicity check.
fn check_observer(
    name: &str,
    run: &ObserverRun,
    tolerances_m: &[f64],
    worst: &mut [Worst],
    problems: &mut Vec<(Kind, String)>,
) -> Vec<Comparison> {
    let h0 = run.observer_m;
    let farthest = STRESS_DISTANCES_M[STRESS_DISTANCES_M.len() - 1];
    let mut comparisons = Vec::new();
    for (i, l) in run.launches.iter().enumerate() {
        let deg = l.elevation_rad.to_degrees();
        let context = |tol: f64| format!("{name} h0 {h0} m α {deg:.9}° tol {tol:e} m");
        for (t, &tol) in tolerances_m.iter().enumerate() {
            let rec = &run.records[t][i];
            worst[t].rays += 1;
            worst[t].drift = worst[t].drift.max(rec.invariant_drift);
            for (kind, p) in record_problems(rec, &config(tol), farthest) {
                problems.push((kind, format!("{}: {p}", context(tol))));
            }
        }
        let Some(reference) = &l.reference else {
            continue;
        };
        for (k, &d) in STRESS_DISTANCES_M.iter().enumerate() {
            let (reach, estimate) = reference[k];
            let Some(want) = reach.height_m() else {
                continue;
            };
            let mut errors_m = vec![None; tolerances_m.len()];
            for (t, &tol) in tolerances_m.iter().enumerate() {
                let Some(got) = run.records[t][i].heights_m[k] else {
                    continue;
                };
                let w = &mut worst[t];
                if l.slopes[k] > 3.0 * d {
                    w.near_fold += 1;
                    continue;
                }
                if !within(estimate, 0.1 * tol) {
                    w.unconverged += 1;
                    continue;
                }
                let err = (got - want).abs();
                w.compared += 1;
                w.reference_estimate_m = w.reference_estimate_m.max(estimate);
                if err > w.error_m {
                    w.error_m = err;
                    w.at = (h0, deg, d);
                }
                if !within(err, tol) {
                    let text = format!("{}: |Δh| {err:.3e} m at {d} m", context(tol));
                    problems.push((Kind::Tolerance, text));
                }
                errors_m[t] = Some(err);
            }
            comparisons.push(Comparison {
                at: (h0, deg, d),
                errors_m,
                estimate_m: estimate,
            });
        }
    }
    comparisons
}

/// The worst error over the well-converged comparisons must not grow as the tolerance shrinks
/// (beyond [`MONOTONE_ALLOWANCE_M`]); compared over the ray·distances compared at both.
fn monotone_problems(
    name: &str,
    comparisons: &[Comparison],
    tolerances_m: &[f64],
    problems: &mut Vec<(Kind, String)>,
) {
    for k in 0..tolerances_m.len().saturating_sub(1) {
        let (mut loose, mut tight) = (0.0f64, 0.0f64);
        let mut worst_tight = None;
        for c in comparisons
            .iter()
            .filter(|c| c.estimate_m <= REFERENCE_TARGET_M)
        {
            if let (Some(a), Some(b)) = (c.errors_m[k], c.errors_m[k + 1]) {
                loose = loose.max(a);
                if b > tight {
                    tight = b;
                    worst_tight = Some((c.at, a));
                }
            }
        }
        if tight > loose + MONOTONE_ALLOWANCE_M {
            let ((h0, deg, d), its_loose) = worst_tight.expect("a comparison gave the worst");
            let text = format!(
                "{name}: worst error grows from {loose:.3e} m at tolerance {:e} m to {tight:.3e} m \
                 at {:e} m (h0 {h0} m α {deg:.9}° at {d} m, there {its_loose:.3e} m at the looser)",
                tolerances_m[k],
                tolerances_m[k + 1]
            );
            problems.push((Kind::Monotone, text));
        }
    }
}

/// The outcome of the suite: per atmosphere the worst per tolerance, and every problem found.
struct SuiteRun {
    table: Vec<Vec<Worst>>,
    problems: Vec<(Kind, String)>,
}

impl SuiteRun {
    /// Panic listing the problems of `kind` for which `selected` holds, if any.
    fn assert_none_where(&self, kind: Kind, selected: impl Fn(&str) -> bool) {
        let found: Vec<&str> = self
            .problems
            .iter()
            .filter(|(k, p)| *k == kind && selected(p))
            .map(|(_, p)| p.as_str())
            .collect();
        assert!(
            found.is_empty(),
            "{} {kind:?} problems:\n{}",
            found.len(),
            found.join("\n")
        );
    }

    /// Panic listing every problem of `kind`, if any.
    fn assert_none(&self, kind: Kind) {
        self.assert_none_where(kind, |_| true);
    }
}

/// The suite over `atmospheres`: every observer, every launch of `set`, every tolerance.
fn run_suite(
    atmospheres: &[Loaded],
    observers_m: &[f64],
    tolerances_m: &[f64],
    set: LaunchSet,
) -> SuiteRun {
    let mut problems = Vec::new();
    let mut table = Vec::new();
    for loaded in atmospheres {
        let name = loaded.stress.name;
        let mut worst = vec![Worst::default(); tolerances_m.len()];
        let mut comparisons = Vec::new();
        for &h0 in observers_m {
            let run = run_observer(loaded, h0, tolerances_m, set);
            comparisons.extend(check_observer(
                name,
                &run,
                tolerances_m,
                &mut worst,
                &mut problems,
            ));
        }
        monotone_problems(name, &comparisons, tolerances_m, &mut problems);
        table.push(worst);
    }
    print_table(atmospheres, &table, tolerances_m);
    SuiteRun { table, problems }
}

fn print_table(atmospheres: &[Loaded], table: &[Vec<Worst>], tolerances_m: &[f64]) {
    for (loaded, worst) in atmospheres.iter().zip(table) {
        for (w, tol) in worst.iter().zip(tolerances_m) {
            eprintln!(
                "{:26} tol {tol:7.0e} m: worst |Δh| {:.2e} m (ratio {:.3}) at h0 {} m α {:.6}° D {} m; \
                 {} compared, {} near folds, {} unconverged, {} rays; drift {:.2e}; reference \
                 estimate ≤ {:.1e} m",
                loaded.stress.name,
                w.error_m,
                w.error_m / tol,
                w.at.0,
                w.at.1,
                w.at.2,
                w.compared,
                w.near_fold,
                w.unconverged,
                w.rays,
                w.drift,
                w.reference_estimate_m
            );
        }
    }
    for (k, tol) in tolerances_m.iter().enumerate() {
        let ratio = table.iter().map(|w| w[k].error_m / tol).fold(0.0, f64::max);
        let drift = table.iter().map(|w| w[k].drift).fold(0.0, f64::max);
        let unconverged: usize = table.iter().map(|w| w[k].unconverged).sum();
        eprintln!(
            "tolerance {tol:e} m: worst error/tolerance {ratio:.3}, worst drift {drift:.2e}, \
             {unconverged} ray·distances without a converged reference"
        );
    }
}

/// The suite compared something at every tolerance, and the reference converged for at least
/// 95 % of what it could compare.
fn check_coverage(run: &SuiteRun) {
    for w in run.table.iter().flatten() {
        assert!(w.compared > 0, "a tolerance compared nothing");
        assert!(
            w.unconverged * 20 <= w.compared,
            "the reference did not converge for {} of {} ray·distances",
            w.unconverged,
            w.compared
        );
    }
}

/// Fast mode, computed once for the four tests that check it: all fourteen atmospheres, all five
/// observers, the fast launch set, all seven tolerances.
fn fast_suite() -> &'static SuiteRun {
    static SUITE: OnceLock<SuiteRun> = OnceLock::new();
    SUITE.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let atmospheres = load_suite(dir.path());
        let run = run_suite(
            &atmospheres,
            &STRESS_OBSERVERS_M,
            &STRESS_TOLERANCES_M,
            LaunchSet::Fast,
        );
        check_coverage(&run);
        run
    })
}

#[test]
fn stress_rays_end_with_a_typed_reason_and_finite_numbers() {
    fast_suite().assert_none(Kind::Record);
}

#[test]
fn stress_bouguer_drift_stays_within_its_bound() {
    fast_suite().assert_none(Kind::Drift);
}

#[test]
fn stress_error_is_within_the_tolerance_of_the_independent_reference() {
    fast_suite().assert_none(Kind::Tolerance);
}

#[test]
fn stress_error_does_not_grow_as_the_tolerance_shrinks() {
    fast_suite().assert_none(Kind::Monotone);
}

/// Long mode: the dense launch set (≈ 150 elevations and tangent rays to every twentieth break
/// below 2 km per observer), every property at once.
#[test]
#[ignore = "long stress mode: cargo test --release --test integration stress -- --ignored"]
fn stress_suite_long() {
    let dir = tempfile::tempdir().unwrap();
    let atmospheres = load_suite(dir.path());
    let run = run_suite(
        &atmospheres,
        &STRESS_OBSERVERS_M,
        &STRESS_TOLERANCES_M,
        LaunchSet::Long,
    );
    check_coverage(&run);
    let problems: Vec<String> = run
        .problems
        .iter()
        .map(|(kind, p)| format!("{kind:?}: {p}"))
        .collect();
    for kind in [Kind::Record, Kind::Drift, Kind::Tolerance, Kind::Monotone] {
        let n = run.problems.iter().filter(|(k, _)| *k == kind).count();
        eprintln!("long mode: {n} {kind:?} problems");
    }
    assert!(
        problems.is_empty(),
        "{} problems:\n{}",
        problems.len(),
        problems.join("\n")
    );
}

/// Which stress atmosphere.
fn by_name<'a>(atmospheres: &'a [Loaded], name: &str) -> &'a Loaded {
    atmospheres
        .iter()
        .find(|l| l.stress.name == name)
        .unwrap_or_else(|| panic!("no stress atmosphere {name}"))
}

/// A level ray (and, in long mode, two tilted ones) from the middle of the long duct's inversion
/// is carried 5 000 km: every 500 km it is still in the duct, it ends with a typed reason
/// (`targets_done` at 5 000 km), its Bouguer drift is within the bound for L = 5 000 km, and its
/// height is within the tolerance of the independent reference (which converges there to a few
/// 1e-8 m; none of these rays is near a fold).
fn duct_5000_km(elevations_deg: &[f64], tolerances_m: &[f64]) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    let atmospheres = load_suite(dir.path());
    let loaded = by_name(&atmospheres, "long_duct");
    let index = atmosphere_index(&loaded.atm, BreakSource::Profile(&loaded.profile));
    let distances: Vec<f64> = (1..=10).map(|k| k as f64 * 500_000.0).collect();
    let h0 = LONG_DUCT_OBSERVER_M;
    let mut problems = Vec::new();
    for &deg in elevations_deg {
        let a = deg.to_radians();
        let refinement = Refinement {
            steps: ReferenceSteps::default(),
            target_m: 1e-7,
            max_halvings: 2,
        };
        let reference = converged_reference(&index, R, TOP_M, h0, a, &distances, refinement);
        // |∂h/∂α| from the reference itself (the tracer at 1e-6 m would take ~10⁷ steps).
        let run =
            |a| reference_heights_with_steps(&index, R, TOP_M, h0, a, &distances, refinement.steps);
        let (up, down) = (run(a + 1e-6), run(a - 1e-6));
        let slopes: Vec<f64> = up
            .iter()
            .zip(&down)
            .map(|(u, v)| match (u.height_m(), v.height_m()) {
                (Some(u), Some(v)) => ((u - v) / 2e-6).abs(),
                _ => f64::INFINITY,
            })
            .collect();
        for &tol in tolerances_m {
            let context = format!("5000 km duct α {deg}° tol {tol:e} m");
            let rec = duct_ray(loaded, a, &distances, tol, &context, &mut problems);
            let (found, compared) = height_problems(
                &context,
                &rec.heights_m,
                &reference,
                &slopes,
                &distances,
                tol,
            );
            problems.extend(found);
            assert_eq!(
                compared,
                distances.len(),
                "{context}: the reference must judge every distance"
            );
        }
    }
    problems
}

/// The long duct's ray at `elevation_rad` traced at `tolerance_m` to `distances_m`; problems
/// with its record, its end and its staying in the duct are pushed to `problems`.
fn duct_ray(
    loaded: &Loaded,
    elevation_rad: f64,
    distances_m: &[f64],
    tolerance_m: f64,
    context: &str,
    problems: &mut Vec<String>,
) -> RayRecord {
    let cfg = TracerConfig {
        max_steps: 10_000_000,
        ..config(tolerance_m)
    };
    let rec = Tracer::new(&loaded.atm, cfg.clone())
        .unwrap()
        .trace(LONG_DUCT_OBSERVER_M, elevation_rad, distances_m)
        .unwrap();
    eprintln!(
        "{context}: {:?}, {} steps, drift {:.2e}, h(5000 km) {:?}",
        rec.termination,
        rec.steps(),
        rec.invariant_drift,
        rec.heights_m.last(),
    );
    let farthest = distances_m[distances_m.len() - 1];
    for (_, p) in record_problems(&rec, &cfg, farthest) {
        problems.push(format!("{context}: {p}"));
    }
    if rec.termination != Some(Termination::TargetsDone) {
        problems.push(format!("{context}: ended {:?}", rec.termination));
    }
    for (h, d) in rec.heights_m.iter().zip(distances_m) {
        match h {
            Some(h) if (30.0..=200.0).contains(h) => {}
            Some(h) => problems.push(format!("{context}: left the duct, {h} m at {d} m")),
            None => problems.push(format!("{context}: did not reach {d} m")),
        }
    }
    rec
}

/// |Δh| of `heights_m` against `reference` at `distances_m`, where the ray is not near a fold
/// (`slopes` ≤ 3·D) and the reference has converged to a tenth of `tolerance_m`: the distances
/// where it exceeds the tolerance, and how many were compared.
fn height_problems(
    context: &str,
    heights_m: &[Option<f64>],
    reference: &[(RefReach, f64)],
    slopes: &[f64],
    distances_m: &[f64],
    tolerance_m: f64,
) -> (Vec<String>, usize) {
    let mut problems = Vec::new();
    let mut compared = 0;
    for (k, &d) in distances_m.iter().enumerate() {
        let (reach, estimate) = reference[k];
        let (Some(want), Some(got)) = (reach.height_m(), heights_m[k]) else {
            continue;
        };
        if slopes[k] > 3.0 * d || !within(estimate, 0.1 * tolerance_m) {
            continue;
        }
        compared += 1;
        let err = (got - want).abs();
        if !within(err, tolerance_m) {
            problems.push(format!("{context}: |Δh| {err:.3e} m at {d} m"));
        }
    }
    (problems, compared)
}

#[test]
fn stress_duct_carries_a_level_ray_5000_km() {
    let problems = duct_5000_km(&[0.0], &[1e-1, 1e-3]);
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
#[ignore = "long stress mode: cargo test --release --test integration stress -- --ignored"]
fn stress_duct_5000_km_long() {
    let problems = duct_5000_km(&[-0.1, 0.0, 0.05], &STRESS_TOLERANCES_M);
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The 3-D path ([`trace_field`] through [`Spherical`]) on the same launches: a typed end,
/// finite numbers, drift within the bound and the error within the tolerance of the
/// independent reference.
fn three_d_path(
    names: &[&str],
    observers_m: &[f64],
    elevations_deg: &[f64],
    tolerances_m: &[f64],
) -> Vec<String> {
    let dir = tempfile::tempdir().unwrap();
    let atmospheres = load_suite(dir.path());
    let farthest = STRESS_DISTANCES_M[STRESS_DISTANCES_M.len() - 1];
    let elevations: Vec<f64> = elevations_deg.iter().map(|d| d.to_radians()).collect();
    let mut problems = Vec::new();
    for name in names {
        let loaded = by_name(&atmospheres, name);
        for &h0 in observers_m {
            let launches = launches_at(loaded, h0, &elevations);
            for &tol in tolerances_m {
                let cfg = config(tol);
                for l in &launches {
                    let a = l.elevation_rad;
                    let rec = trace_3d(&loaded.atm, h0, a, &cfg);
                    let deg = a.to_degrees();
                    let context = format!("3-D {name} h0 {h0} m α {deg:.6}° tol {tol:e} m");
                    for (_, p) in record_problems(&rec, &cfg, farthest) {
                        problems.push(format!("{context}: {p}"));
                    }
                    if let Some(reference) = &l.reference {
                        let (h, d) = (&rec.heights_m, &STRESS_DISTANCES_M);
                        problems
                            .extend(height_problems(&context, h, reference, &l.slopes, d, tol).0);
                    }
                }
            }
        }
    }
    problems
}

/// One ray through `atm` seen as a 3-D field ([`Spherical`]), from `observer_m` above an
/// arbitrary point of the sphere, in an arbitrary azimuth, at `elevation_rad`.
fn trace_3d(
    atm: &RefractiveAtmosphere,
    observer_m: f64,
    elevation_rad: f64,
    cfg: &TracerConfig,
) -> RayRecord {
    let field = Spherical {
        index: atm,
        earth_radius_m: R,
    };
    let up = DVec3::new(0.3, -0.5, 0.8).normalize();
    let east = up.cross(DVec3::Z).normalize();
    let dir = east * elevation_rad.cos() + up * elevation_rad.sin();
    trace_field(
        &field,
        Ground::Sphere { radius_m: R },
        cfg,
        up * (R + observer_m),
        dir,
        &STRESS_DISTANCES_M,
        &mut NoHook,
        None,
    )
    .unwrap()
}

#[test]
fn stress_3d_path_meets_the_same_bounds() {
    let problems = three_d_path(
        &[
            "near_critical_0115",
            "superadiabatic_desert",
            "surface_duct",
            "thin_jumps_30k",
        ],
        &[2.0, 100.0],
        &[-1.0, -0.1, 0.0, 0.05, 0.2, 1.0, 10.0, 90.0],
        &[1e-1, 1e-3, 1e-5],
    );
    assert!(
        problems.is_empty(),
        "{} problems:\n{}",
        problems.len(),
        problems.join("\n")
    );
}

#[test]
#[ignore = "long stress mode: cargo test --release --test integration stress -- --ignored"]
fn stress_3d_path_long() {
    let names: Vec<&str> = stress_suite().iter().map(|s| s.name).collect();
    let elevations: Vec<f64> = (-10..=10)
        .map(|i| 0.05 * i as f64)
        .chain([-5.0, 2.0, 10.0, 30.0, 60.0, 90.0])
        .collect();
    let problems = three_d_path(
        &names,
        &STRESS_OBSERVERS_M,
        &elevations,
        &STRESS_TOLERANCES_M,
    );
    assert!(
        problems.is_empty(),
        "{} problems:\n{}",
        problems.len(),
        problems.join("\n")
    );
}

/// A small frame of stress atmospheres through the library's render path (scene → atmosphere →
/// tracer → film), fan and exact: every pixel finite, no sample replaced by the fallback colour.
#[test]
fn stress_render_has_no_non_finite_pixel() {
    let dir = tempfile::tempdir().unwrap();
    let ship = crate::support::data::data_file("cards/ship.png");
    for name in [
        "thin_jumps_30k",
        "near_critical_0120",
        "superadiabatic_desert",
    ] {
        let stress = stress_suite().into_iter().find(|s| s.name == name).unwrap();
        let sounding = dir.path().join(format!("{name}.csv"));
        std::fs::write(&sounding, &stress.csv_text).unwrap();
        for (camera_m, exact) in [(2.0, false), (100.0, false), (2.0, true)] {
            let text = format!(
                "[camera]\nheight_m = {camera_m}\npitch_deg = 0.0\nhfov_deg = 2.0\nwidth = 64\n\
                 height = 32\nsamples_per_pixel = 1\n\
                 [atmosphere]\nsounding = {sounding:?}\nsmooth_m = 0.0\n\
                 [[cards]]\nimage = {ship:?}\ndistance_m = 8000.0\nazimuth_deg = 0.0\n\
                 width_m = 80.0\nheight_m = 25.0\n"
            );
            let path = dir.path().join("scene.toml");
            std::fs::write(&path, text).unwrap();
            let scene = Scene::from_file(&path).unwrap();
            let atm = scene.atmosphere.load().unwrap().expect("curved rays");
            let options = RenderOptions {
                exact,
                quiet: true,
                ..RenderOptions::default()
            };
            let tracer = prepare_tracer(&scene, Some(&atm.refractive), &options).unwrap();
            let film = render_scene(&scene, tracer.as_ref(), &options).unwrap();
            let bad = film
                .pixels
                .iter()
                .filter(|p| p.iter().any(|c| !c.is_finite()))
                .count();
            assert_eq!(
                bad, 0,
                "{name} camera {camera_m} m exact {exact}: {bad} non-finite pixels"
            );
            assert_eq!(
                film.stats.non_finite_samples, 0,
                "{name} camera {camera_m} m exact {exact}"
            );
            assert_eq!(film.pixels.len(), 64 * 32);
        }
    }
}

/// A level ray from 0.1 m meets the +30 K, 0.1 m jump at 30 m near 21.9 km, grazing at 2.7 mrad,
/// and must reflect (the layer turns rays up to 0.44°). Two faults once broke it: a step aimed at
/// a break that went elsewhere was taken as landed, so at 1 cm the ray tunnelled through the
/// jump (Bouguer drift 3.1e-5, the index step); and with Earth-centred positions their ~1e-9 m
/// rounding, times d²n/dh² ≈ 0.02 m⁻² in the jump, was force noise that held steps near a
/// millimetre at 1e-6 m (11 898 accepted steps). Both tolerances now reflect it with the drift
/// of a smooth field, the tight one in a few hundred steps, and agree at 26 km.
#[test]
fn a_grazing_ray_reflects_off_a_thin_jump_at_loose_and_tight_tolerances() {
    let dir = tempfile::tempdir().unwrap();
    let stress = stress_suite()
        .into_iter()
        .find(|s| s.name == "thin_jumps_30k")
        .unwrap();
    let profile = csv_profile(dir.path(), stress.name, &stress.csv_text);
    let atm = RefractiveAtmosphere::new(Arc::new(profile), 550.0).unwrap();
    let records: Vec<RayRecord> = [1e-2, 1e-6]
        .iter()
        .map(|&tol| {
            Tracer::new(&atm, config(tol))
                .unwrap()
                .trace(0.1, 0.0, &STRESS_DISTANCES_M)
                .unwrap()
        })
        .collect();
    for rec in &records {
        assert!(
            rec.invariant_drift < 1e-10,
            "drift {:e}",
            rec.invariant_drift
        );
        let h26 = rec.heights_m[3].unwrap();
        assert!(h26 < 30.0, "not reflected: {h26} m at 26 km");
    }
    assert!(
        records[1].accepted_steps < 1_000,
        "{} steps",
        records[1].accepted_steps
    );
    let (loose, tight) = (records[0].heights_m[3], records[1].heights_m[3]);
    assert!((loose.unwrap() - tight.unwrap()).abs() < 1e-2);
}

/// The worst ray of `two_thin_layers` in STRESS.md (observer 2 m, 0.08°): it climbs into the
/// +6 K layer at 40–43 m, turns in it near 16.8 km and comes back down. At 1 m a step that
/// started on the knot at 42.5 m went over its apex above the knot and back down through it and
/// the knot at 40.5 m in one step: the ray loop took the return crossing for the one at the
/// step's start and accepted the step whole, straddling both. The ray was then 4.5 m off at
/// 26 km (0.25 m at 10 m) against the independent reference; each tolerance must hold.
#[test]
fn a_ray_turning_inside_a_thin_layer_aloft_meets_the_tolerance() {
    let steps = ReferenceSteps {
        max_ground_step_m: 20.0,
        max_height_step_m: 0.05,
        fine: None,
    };
    let ray = ("two_thin_layers", 2.0, 0.08);
    assert_error_against_the_reference(ray, steps, &[10.0, 1.0, 0.1, 1e-2], false);
}

/// One ray's error against the independent reference at each of `tolerances_m` (loosest
/// first), at every stress distance: per distance, the error at each tolerance must be within
/// it and at most the error at the next looser tolerance plus [`MONOTONE_ALLOWANCE_M`] (the
/// reference's own accuracy; the reference must be converged to [`REFERENCE_TARGET_M`]).
fn assert_error_falls_with_the_tolerance(
    name: &str,
    observer_m: f64,
    elevation_deg: f64,
    reference_steps: ReferenceSteps,
    tolerances_m: &[f64],
) {
    let ray = (name, observer_m, elevation_deg);
    assert_error_against_the_reference(ray, reference_steps, tolerances_m, true);
}

/// One ray `(atmosphere, observer m, elevation °)` against the independent reference at each of
/// `tolerances_m` (loosest first), at every stress distance, away from any fold there (as the
/// suite's rows): within the tolerance, and with `falling`, at most the error at the next looser
/// tolerance plus [`MONOTONE_ALLOWANCE_M`].
fn assert_error_against_the_reference(
    (name, observer_m, elevation_deg): (&str, f64, f64),
    reference_steps: ReferenceSteps,
    tolerances_m: &[f64],
    falling: bool,
) {
    let dir = tempfile::tempdir().unwrap();
    let stress = stress_suite().into_iter().find(|s| s.name == name).unwrap();
    let profile = csv_profile(dir.path(), stress.name, &stress.csv_text);
    let atm = RefractiveAtmosphere::new(Arc::new(profile.clone()), 550.0).unwrap();
    let index = atmosphere_index(&atm, BreakSource::Profile(&profile));
    let elevation_rad = elevation_deg.to_radians();
    let refinement = Refinement {
        steps: reference_steps,
        target_m: REFERENCE_TARGET_M,
        max_halvings: 2,
    };
    let reference = converged_reference(
        &index,
        R,
        TOP_M,
        observer_m,
        elevation_rad,
        &STRESS_DISTANCES_M,
        refinement,
    );
    let tight = Tracer::new(&atm, config(FOLD_SLOPE_TOLERANCE_M)).unwrap();
    let slopes = fold_slopes(&tight, observer_m, elevation_rad, &STRESS_DISTANCES_M);
    for (&slope, &d) in slopes.iter().zip(&STRESS_DISTANCES_M) {
        assert!(slope < 3.0 * d, "{name}: near a fold at {d} m: {slope}");
    }
    let mut looser: Vec<Option<f64>> = vec![None; STRESS_DISTANCES_M.len()];
    for &tolerance_m in tolerances_m {
        let rec = Tracer::new(&atm, config(tolerance_m))
            .unwrap()
            .trace(observer_m, elevation_rad, &STRESS_DISTANCES_M)
            .unwrap();
        for (k, &d) in STRESS_DISTANCES_M.iter().enumerate() {
            let (reach, estimate_m) = reference[k];
            let want = reach.height_m().expect("the reference ray gets there");
            assert!(
                estimate_m <= REFERENCE_TARGET_M,
                "reference unsettled at {d} m: {estimate_m:e}"
            );
            let got = rec.heights_m[k].expect("the ray gets there");
            let err = (got - want).abs();
            let context = format!("{name} h0 {observer_m} m α {elevation_deg}° at {d} m");
            assert!(
                within(err, tolerance_m),
                "{context}: |Δh| {err:.3e} m at tolerance {tolerance_m} m"
            );
            if let Some(previous) = looser[k].filter(|_| falling) {
                assert!(
                    within(err, previous + MONOTONE_ALLOWANCE_M),
                    "{context}: |Δh| grows from {previous:.3e} m to {err:.3e} m at {tolerance_m} m"
                );
            }
            looser[k] = Some(err);
        }
    }
}

/// The worst ray of `thin_jumps_30k` in STRESS.md at 1 mm (observer 2 m, 15°): it crosses the
/// 0.1 m, 30 K jumps at 30 and 60 m within 230 m of ground. After a step had landed just short
/// of a break, the next step's first stage was the field 1e-4 m further along the ray, 2.6e-5 m
/// higher, where d²n/dh² ≈ 0.017 m⁻² inside the jump makes dn/dh differ by 4e-7 m⁻¹; the
/// error estimate weighs the first stage 74 times less than the solution does, so at 1 cm and
/// 1 mm an 8 cm step into the jump at 60 m passed with a 3e-9 rad kick. At 26 km the ray was
/// 2.2e-4 / 9.5e-5 / 3.4e-5 / 7.7e-5 / 2.2e-7 m off at 1 m … 0.1 mm (it grew from 1 cm to
/// 1 mm). Every stage now sees the field of the step's own interval, continued back to the
/// landing point.
#[test]
fn a_steep_ray_across_the_thin_jumps_gets_more_accurate_as_the_tolerance_shrinks() {
    let steps = ReferenceSteps {
        max_ground_step_m: 50.0,
        max_height_step_m: 0.1,
        fine: Some(FineSteps {
            below_m: LAYERS_TOP_M,
            max_height_step_m: 0.025,
        }),
    };
    let tolerances_m = [1.0, 0.1, 1e-2, 1e-3, 1e-4];
    assert_error_falls_with_the_tolerance("thin_jumps_30k", 2.0, 15.0, steps, &tolerances_m);
}

/// The row of `thin_jumps_30k` whose worst error grew as the tolerance shrank (observer 2 m,
/// 0.46°, 168 m high at 26 km). Between the jumps at 30 and 60 m the sounding's levels are 0.5 m
/// apart with temperatures written to 1e-6 K; their fit meets at each knot with nearly equal
/// curvature (jump ≈ 3e-15 m⁻²) but a kink (d³n/dh³ jumps by ≈ 9e-11 m⁻³). Costed by the
/// curvature jump alone, those knots were dropped at 1 m … 1 cm, and steps 4 m high and up to
/// 1 160 m long crossed eight of them each: the Dormand–Prince weights on that field turn the
/// ray by 0.9–1.5e-9 rad per step, while the 5(4) estimate sees 1.2e-10 rad. At 26 km the ray
/// was 3.3e-5 / 2.8e-5 / 4.1e-5 / 6.2e-9 m off at 1 m / 0.1 m / 1 cm / 1 mm; the kink now
/// enters each knot's straddle cost, and the error falls with the tolerance.
#[test]
fn a_ray_across_the_kinked_knots_between_the_thin_jumps_gets_more_accurate_as_the_tolerance_shrinks()
 {
    // Short ground steps: at 0.46° the reference is settled to 3e-10 m with these (to 3e-6 m
    // with 2 m ground steps).
    let steps = ReferenceSteps {
        max_ground_step_m: 0.5,
        max_height_step_m: 0.05,
        fine: Some(FineSteps {
            below_m: LAYERS_TOP_M,
            max_height_step_m: 0.00625,
        }),
    };
    let tolerances_m = [1.0, 0.1, 1e-2, 1e-3, 1e-4];
    assert_error_falls_with_the_tolerance("thin_jumps_30k", 2.0, 0.46, steps, &tolerances_m);
}

/// A 50° ray from 2 km through `arctic_surface_inversion` crosses the US 1976 layer base at
/// 32.16 km (dn/dh jumps by 1.4e-11 m⁻¹) just before 26 km of ground. The step landing just
/// short of it is over a kilometre long, and its last internal stages, less accurate than its
/// end, fell beyond the base and saw the layer above: 2.3e-9 rad at 1 mm, and at 26 km the
/// ray was 2.8e-6 / 3.3e-6 / 2.7e-7 m off at 1 cm / 1 mm / 0.1 mm. Checked from 1 cm down:
/// from 1 cm to 0.1 mm the steps between the levels at 10.75 and 11 km are as long as the
/// 250 m level spacing allows at every tolerance and leave the same ≈ 2.8e-7 m at 26 km; at
/// 0.1 m errors of opposite sign made below and above 10 km partly cancel (1.7e-7 m).
#[test]
fn a_steep_ray_across_the_32_km_base_gets_more_accurate_as_the_tolerance_shrinks() {
    let steps = ReferenceSteps {
        max_ground_step_m: 200.0,
        max_height_step_m: 0.1,
        fine: None,
    };
    let tolerances_m = [1e-2, 1e-3, 1e-4, 1e-5];
    assert_error_falls_with_the_tolerance(
        "arctic_surface_inversion",
        2_000.0,
        50.0,
        steps,
        &tolerances_m,
    );
}

/// The hot road ray of STRESS.md (observer 2 m, −0.16°) dips to 0.5 m and climbs back through
/// the 0.5 m interval between the levels at 1.5 and 2 m, the PCHIP cubic that joins the
/// −4 K/m road layer to the lapse rate above. At 10 m … 0.1 m the step there was 202 m long,
/// crossing the whole interval in one go: its field varied on the scale of the step, its 5(4)
/// error estimate (3.7e-4 m) was ~750× below its error, and the ray was 0.22 m off at 26 km at
/// every one of those tolerances. A step now climbs at most a share of its interval (0.79 at
/// 10 m, 0.25 at 1 cm and below).
#[test]
fn a_ray_climbing_out_of_the_hot_road_layer_meets_the_tolerance() {
    let steps = ReferenceSteps {
        max_ground_step_m: 50.0,
        max_height_step_m: 0.1,
        fine: Some(FineSteps {
            below_m: LAYERS_TOP_M,
            max_height_step_m: 0.025,
        }),
    };
    let tolerances_m = [10.0, 1.0, 0.1, 1e-2, 1e-3, 1e-4];
    assert_error_against_the_reference(("hot_road", 2.0, -0.16), steps, &tolerances_m, false);
}
