//! Time against error — the `bench accuracy` study. In: atmospheres ([`BenchCase`]: the paper's
//! layered TOMLs, shipped soundings, the [`stress`](super::stress) soundings) and an
//! [`AccuracyConfig`] (tolerances, fan, distances). Out: per atmosphere and tolerance, the error
//! of the ray heights at the target distances against a reference run of the same tracer at a
//! far tighter tolerance, and the time and steps each ray took ([`CaseResult`]); rendered as
//! `BENCHMARKS.md` ([`benchmarks_markdown`](super::benchmarks::benchmarks_markdown)) and a log-log plot ([`time_vs_error_png`]).
//!
//! The error is measured against the tracer's own tight run (a self-reference: it shows how the
//! error falls with the tolerance, not the tracer's absolute accuracy, which the tests check
//! against an independent reference tracer). Rays that do not reach a distance in both runs are
//! skipped there. Near a fold of the height map h(α) a tiny launch-angle or path error turns into
//! a large height difference, so rays with |∂h/∂α| > [`AccuracyConfig::fold_factor`] × D (central
//! differences on the reference fan; a straight ray has ∂h/∂α ≈ D) are left out of the maximum
//! and counted separately; the 95th percentile includes them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use plotters::prelude::*;

use super::image_bounds::{BoundaryComparison, compare_boundaries, fan_images};
use super::stats::{median, percentile_95};
use crate::analysis::FoldTest;
use crate::atmosphere::{AtmosphereOptions, AtmosphereSource, load_atmosphere};
use crate::tracer::{NoHook, RayRecord, StratifiedIndex, Tracer, TracerConfig, TracerError};

/// What to measure.
#[derive(Debug, Clone, PartialEq)]
pub struct AccuracyConfig {
    /// Tolerances to measure (m), loosest first.
    pub tolerances_m: Vec<f64>,
    /// Tolerance of the reference run (m).
    pub reference_tolerance_m: f64,
    /// Step budget of the reference run.
    pub reference_max_steps: u32,
    /// Rays in the fan.
    pub rays: usize,
    /// Lowest and highest launch elevation (deg).
    pub elevation_deg: (f64, f64),
    /// Ground distances (m, ascending) at which heights are compared.
    pub distances_m: Vec<f64>,
    /// Timed repetitions of each fan (the median is reported).
    pub repetitions: usize,
    /// A ray is near a fold at distance D when |∂h/∂α| exceeds this × D.
    pub fold_factor: f64,
    /// Heights H (m) of the targets [0, H] standing at every distance whose images' boundaries
    /// are compared ([`image_bounds`](super::image_bounds)).
    pub target_heights_m: Vec<f64>,
}

impl AccuracyConfig {
    /// The full study: 10 m … 1e-5 m, 101 rays over −0.5°…0.5°, 5/10/20/26 km, reference 1e-7 m,
    /// images of a 20 m target (the height of the paper scenes' calibration boards).
    pub fn full() -> Self {
        AccuracyConfig {
            tolerances_m: vec![10.0, 1.0, 0.1, 0.01, 1e-3, 1e-4, 1e-5],
            reference_tolerance_m: 1e-7,
            reference_max_steps: 20_000_000,
            rays: 101,
            elevation_deg: (-0.5, 0.5),
            distances_m: vec![5_000.0, 10_000.0, 20_000.0, 26_000.0],
            repetitions: 3,
            fold_factor: 3.0,
            target_heights_m: vec![20.0],
        }
    }

    /// A quick run: three tolerances (1, 1e-2, 1e-4 m), 21 rays.
    pub fn quick() -> Self {
        AccuracyConfig {
            tolerances_m: vec![1.0, 0.01, 1e-4],
            rays: 21,
            ..Self::full()
        }
    }

    fn check(&self) -> Result<(), AccuracyError> {
        let bad = |m: &str| Err(AccuracyError::InvalidConfig(m.to_string()));
        if self.rays < 3 {
            return bad("the fan needs at least 3 rays");
        }
        if self.tolerances_m.is_empty()
            || self
                .tolerances_m
                .iter()
                .any(|t| !(t.is_finite() && *t > 0.0))
        {
            return bad("tolerances must be finite and > 0");
        }
        if self.repetitions == 0 {
            return bad("at least one repetition");
        }
        let (a, b) = self.elevation_deg;
        if !(a.is_finite() && b.is_finite() && a < b) {
            return bad("the elevation range must be FROM < TO");
        }
        if self.distances_m.is_empty()
            || self.distances_m.windows(2).any(|w| w[1] <= w[0])
            || self
                .distances_m
                .iter()
                .any(|d| !(d.is_finite() && *d > 0.0))
        {
            return bad("distances must be > 0 and ascending");
        }
        if self
            .target_heights_m
            .iter()
            .any(|h| !(h.is_finite() && *h > 0.0))
        {
            return bad("target heights must be finite and > 0");
        }
        Ok(())
    }

    /// The launch elevations (rad).
    pub fn elevations_rad(&self) -> Vec<f64> {
        let (a, b) = self.elevation_deg;
        (0..self.rays)
            .map(|i| (a + (b - a) * i as f64 / (self.rays - 1) as f64).to_radians())
            .collect()
    }
}

/// Why the study could not run.
#[derive(Debug, thiserror::Error)]
pub enum AccuracyError {
    /// A setting is out of range.
    #[error("invalid accuracy benchmark setting: {0}")]
    InvalidConfig(String),
    /// An atmosphere could not be loaded.
    #[error("cannot load benchmark atmosphere {name}")]
    Atmosphere {
        /// The case.
        name: String,
        /// Why (boxed: the loader's error is large).
        #[source]
        source: Box<crate::atmosphere::AtmosphereError>,
    },
    /// The tracer refused the input.
    #[error("cannot trace benchmark atmosphere {name}")]
    Tracer {
        /// The case.
        name: String,
        /// Why.
        #[source]
        source: TracerError,
    },
    /// The stress soundings could not be written.
    #[error("cannot write the stress sounding {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The plot could not be drawn.
    #[error("cannot draw the time-against-error plot: {0}")]
    Plot(String),
}

/// One atmosphere of the study.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchCase {
    /// Short name (table heading, plot legend).
    pub name: String,
    /// What kind: "paper", "sounding", "stress".
    pub kind: &'static str,
    /// What to load.
    pub source: AtmosphereSource,
    /// How to load it.
    pub options: AtmosphereOptions,
    /// Observer height above the surface (m).
    pub observer_height_m: f64,
}

/// The paper atmospheres (observer 20 m).
pub const PAPER_ATMOSPHERES: [&str; 4] = [
    "superior_mirage.toml",
    "inferior_mirage.toml",
    "fata_morgana.toml",
    "novaya_zemlya.toml",
];
/// The shipped real soundings (observer 20 m, default smoothing).
pub const REAL_SOUNDINGS: [&str; 2] = [
    "Utqiagvik-70026_2026020600_all-levels.csv",
    "Bjornoya-01028_2024022611.csv",
];
/// Observer height for the paper atmospheres and real soundings (m).
pub const OBSERVER_M: f64 = 20.0;
/// Observer height for the stress soundings (m): inside or below most of their layers.
pub const STRESS_OBSERVER_M: f64 = 10.0;

/// Every case of the study: the paper atmospheres and real soundings from `data_dir`, and the
/// stress soundings, written as CSV files into `stress_dir` and loaded with `smooth_m = 0`.
pub fn standard_cases(data_dir: &Path, stress_dir: &Path) -> Result<Vec<BenchCase>, AccuracyError> {
    let mut cases = Vec::new();
    for file in PAPER_ATMOSPHERES {
        cases.push(BenchCase {
            name: file.trim_end_matches(".toml").to_string(),
            kind: "paper",
            source: AtmosphereSource::Synthetic(data_dir.join(file)),
            options: AtmosphereOptions::default(),
            observer_height_m: OBSERVER_M,
        });
    }
    for file in REAL_SOUNDINGS {
        cases.push(BenchCase {
            name: file.trim_end_matches(".csv").to_string(),
            kind: "sounding",
            source: AtmosphereSource::Sounding(data_dir.join(file)),
            // Pinned: the study measures the tracer on these profiles, and BENCHMARKS.md was
            // measured on their PCHIP fits (auto would fit Utqiagvik's significant levels
            // linearly).
            options: AtmosphereOptions {
                fit: crate::profile::TemperatureFit::Pchip,
                ..AtmosphereOptions::default()
            },
            observer_height_m: OBSERVER_M,
        });
    }
    for (name, text) in super::stress::stress_soundings() {
        let path = stress_dir.join(format!("{name}.csv"));
        std::fs::write(&path, text).map_err(|source| AccuracyError::Io {
            path: path.clone(),
            source,
        })?;
        cases.push(BenchCase {
            name: name.to_string(),
            kind: "stress",
            source: AtmosphereSource::Sounding(path),
            options: AtmosphereOptions {
                smooth_m: 0.0,
                ..AtmosphereOptions::default()
            },
            observer_height_m: STRESS_OBSERVER_M,
        });
    }
    Ok(cases)
}

/// The error at one distance, for one tolerance.
#[derive(Debug, Clone, PartialEq)]
pub struct DistanceError {
    /// Ground distance (m).
    pub distance_m: f64,
    /// Rays reaching the distance in both runs.
    pub compared: usize,
    /// Of those, rays near a fold (left out of `max_m`).
    pub near_fold: usize,
    /// Largest |Δh| over the compared rays not near a fold (m); `None` if there are none.
    pub max_m: Option<f64>,
    /// 95th percentile of |Δh| over all compared rays (m); `None` if there are none.
    pub p95_m: Option<f64>,
}

/// One tolerance of one atmosphere.
#[derive(Debug, Clone, PartialEq)]
pub struct ToleranceRow {
    /// Tolerance (m).
    pub tolerance_m: f64,
    /// The error at every distance.
    pub errors: Vec<DistanceError>,
    /// Median time per ray over the repetitions, single thread (µs).
    pub us_per_ray: f64,
    /// Steps (accepted + rejected) per ray.
    pub steps_per_ray: f64,
    /// The image boundaries of the targets against the reference run's.
    pub boundaries: BoundaryComparison,
    /// Wall-clock time of the image search on this fan (ms, all threads).
    pub images_ms: f64,
}

impl ToleranceRow {
    /// Rays per second (single thread).
    pub fn rays_per_s(&self) -> f64 {
        1e6 / self.us_per_ray
    }
    /// Steps per second (single thread).
    pub fn steps_per_s(&self) -> f64 {
        self.steps_per_ray * self.rays_per_s()
    }
}

/// The study of one atmosphere.
#[derive(Debug, Clone, PartialEq)]
pub struct CaseResult {
    /// The case's name.
    pub name: String,
    /// Its kind.
    pub kind: &'static str,
    /// The atmosphere's one-line description.
    pub description: String,
    /// Observer height (m).
    pub observer_height_m: f64,
    /// Steps per ray of the reference run.
    pub reference_steps_per_ray: f64,
    /// Images the reference run finds, over all targets.
    pub reference_images: usize,
    /// One row per tolerance, in the config's order.
    pub rows: Vec<ToleranceRow>,
}

/// Trace the fan once on one thread, timing it; the records are kept.
fn timed_fan(
    tracer: &Tracer<'_, dyn StratifiedIndex + '_>,
    observer_m: f64,
    elevations: &[f64],
    distances: &[f64],
    records: &mut Vec<RayRecord>,
) -> Result<f64, TracerError> {
    records.resize_with(elevations.len(), RayRecord::default);
    let start = Instant::now();
    for (e, rec) in elevations.iter().zip(records.iter_mut()) {
        tracer.trace_into(observer_m, *e, distances, &mut NoHook, rec, None)?;
    }
    Ok(start.elapsed().as_secs_f64())
}

/// Which rays of the reference fan are near a fold at distance index `k`.
fn near_folds(
    reference: &[RayRecord],
    elevations: &[f64],
    k: usize,
    d: f64,
    factor: f64,
) -> Vec<bool> {
    let n = reference.len();
    (0..n)
        .map(|i| {
            let h = |j: usize| reference[j].heights_m[k];
            let lo = if i > 0 && h(i - 1).is_some() {
                i - 1
            } else {
                i
            };
            let hi = if i + 1 < n && h(i + 1).is_some() {
                i + 1
            } else {
                i
            };
            match (h(lo), h(hi)) {
                (Some(a), Some(b)) if hi > lo => {
                    let slope = (b - a) / (elevations[hi] - elevations[lo]);
                    slope.abs() > factor * d
                }
                // No neighbour to difference with: cannot tell, count as near a fold.
                _ => true,
            }
        })
        .collect()
}

/// The error at every distance of one run's fan `records` against the `reference` fan, with
/// the reference's near-fold flags `folds` (per distance, per ray).
fn distance_errors(
    records: &[RayRecord],
    reference: &[RayRecord],
    folds: &[Vec<bool>],
    distances: &[f64],
) -> Vec<DistanceError> {
    distances
        .iter()
        .enumerate()
        .map(|(k, &d)| {
            let mut all = Vec::new();
            let mut max: Option<f64> = None;
            let mut near_fold = 0;
            for (i, (rec, refr)) in records.iter().zip(reference).enumerate() {
                let (Some(h), Some(r)) = (rec.heights_m[k], refr.heights_m[k]) else {
                    continue;
                };
                let err = (h - r).abs();
                all.push(err);
                if folds[k][i] {
                    near_fold += 1;
                } else {
                    max = Some(max.map_or(err, |m: f64| m.max(err)));
                }
            }
            DistanceError {
                distance_m: d,
                compared: all.len(),
                near_fold,
                max_m: max,
                p95_m: percentile_95(&mut all),
            }
        })
        .collect()
}

/// What [`measure_index`] measured.
#[derive(Debug, Clone, PartialEq)]
pub struct IndexResult {
    /// One row per tolerance, in the config's order.
    pub rows: Vec<ToleranceRow>,
    /// Steps per ray of the reference run.
    pub reference_steps_per_ray: f64,
    /// Images the reference run finds, over all targets.
    pub reference_images: usize,
}

/// Measure one atmosphere `index` with observer at `observer_m`. `progress` is called after the
/// reference run and after every tolerance.
pub fn measure_index(
    index: &dyn StratifiedIndex,
    observer_m: f64,
    config: &AccuracyConfig,
    progress: &mut dyn FnMut(),
) -> Result<IndexResult, TracerError> {
    let elevations = config.elevations_rad();
    let distances = &config.distances_m;
    let heights = &config.target_heights_m;
    let reference_tracer = Tracer::new(
        index,
        TracerConfig {
            tolerance_m: config.reference_tolerance_m,
            max_steps: config.reference_max_steps,
            ..TracerConfig::default()
        },
    )?;
    let reference = reference_tracer.trace_fan(observer_m, &elevations, distances)?;
    let reference_images = fan_images(
        &reference_tracer,
        observer_m,
        &elevations,
        &reference,
        distances,
        heights,
    );
    progress();
    let n = elevations.len() as f64;
    let reference_steps = reference.iter().map(|r| r.steps() as f64).sum::<f64>() / n;
    let folds: Vec<Vec<bool>> = distances
        .iter()
        .enumerate()
        .map(|(k, &d)| near_folds(&reference, &elevations, k, d, config.fold_factor))
        .collect();

    let mut rows = Vec::new();
    let mut records = Vec::new();
    for &tol in &config.tolerances_m {
        let tracer = Tracer::new(
            index,
            TracerConfig {
                tolerance_m: tol,
                ..TracerConfig::default()
            },
        )?;
        let mut times = Vec::new();
        for _ in 0..config.repetitions {
            times.push(timed_fan(
                &tracer,
                observer_m,
                &elevations,
                distances,
                &mut records,
            )?);
        }
        let seconds = median(&mut times).unwrap_or(f64::NAN);
        let steps_per_ray = records.iter().map(|r| r.steps() as f64).sum::<f64>() / n;
        let images = fan_images(
            &tracer,
            observer_m,
            &elevations,
            &records,
            distances,
            heights,
        );
        rows.push(ToleranceRow {
            tolerance_m: tol,
            errors: distance_errors(&records, &reference, &folds, distances),
            us_per_ray: seconds * 1e6 / n,
            steps_per_ray,
            boundaries: compare_boundaries(&images.targets, &reference_images.targets),
            images_ms: images.seconds * 1e3,
        });
        progress();
    }
    Ok(IndexResult {
        rows,
        reference_steps_per_ray: reference_steps,
        reference_images: reference_images.targets.iter().map(Vec::len).sum(),
    })
}

/// Load and measure one case. `progress` as for [`measure_index`].
pub fn measure_case(
    case: &BenchCase,
    config: &AccuracyConfig,
    progress: &mut dyn FnMut(),
) -> Result<CaseResult, AccuracyError> {
    config.check()?;
    let atm = load_atmosphere(&case.source, &case.options).map_err(|source| {
        AccuracyError::Atmosphere {
            name: case.name.clone(),
            source: Box::new(source),
        }
    })?;
    let measured = measure_index(&atm.refractive, case.observer_height_m, config, progress)
        .map_err(|source| AccuracyError::Tracer {
            name: case.name.clone(),
            source,
        })?;
    Ok(CaseResult {
        name: case.name.clone(),
        kind: case.kind,
        description: atm.description.clone(),
        observer_height_m: case.observer_height_m,
        reference_steps_per_ray: measured.reference_steps_per_ray,
        reference_images: measured.reference_images,
        rows: measured.rows,
    })
}

fn fmt_err(v: Option<f64>) -> String {
    match v {
        Some(v) => format!("{v:.2e}"),
        None => "–".into(),
    }
}

/// A tolerance for a table: plain from 0.1 to 100, else scientific, to three significant digits
/// with trailing zeros dropped (1e-6 rather than 1.0000000000000002e-6).
pub(super) fn fmt_tol(t: f64) -> String {
    if (0.1..=100.0).contains(&t) {
        let s = format!("{t:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        let s = format!("{t:.2e}");
        match s.split_once('e') {
            Some((m, e)) => format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.')),
            None => s,
        }
    }
}

fn km(d: f64) -> String {
    format!("{}", d / 1000.0)
}

/// The settings of the ray study, as bullets.
fn rays_settings(config: &AccuracyConfig) -> String {
    let last = config.distances_m.len() - 1;
    let heights: Vec<String> = config
        .target_heights_m
        .iter()
        .map(|h| format!("{h} m"))
        .collect();
    format!(
        "* Timings are single-threaded, the median of {reps} repetitions of the whole fan.\n\
         * Fan: {rays} rays, elevations {e0}°…{e1}°, observer 20 m (paper atmospheres and real \
         soundings, default smoothing) or 10 m (stress soundings, `smooth_m = 0`).\n\
         * Height error: |Δh| at ground distances {dists} km against a reference run of the same \
         tracer at tolerance {rt:e} m (max {rs} steps per ray): a self-reference, showing how the \
         error falls with the tolerance (the tests check the tracer against an independent \
         reference). Rays not reaching a distance in both runs are skipped there. The **max** \
         leaves out rays near a fold, |∂h/∂α| > {ff} × D on the reference fan (central \
         differences), counted in the *near-fold* column (at {dl} km); **p95** is over all \
         compared rays.\n\
         * Image boundaries (second table of each atmosphere): the images of a target 0…{hs} tall \
         at each of those distances, found on the same fan by the library's image finder \
         (`analysis::find_images`, as `ghostship trace` reports them: folds and band edges \
         refined on rays re-traced at the *re-trace tolerance* shown), against the images the \
         reference run's finder gives (re-trace tolerance {rr:e} m). Images are matched by their \
         order per target; **max |Δ|** is the largest shift of a lower or upper edge's apparent \
         elevation, in arcseconds, over targets where both runs find the same number of images; \
         targets where the counts differ are not compared but counted. The finder bisects edges \
         to a fixed resolution in elevation, so 0 means both searches ended in the same bracket. \
         *Image search* is the \
         wall-clock time of that search (all threads).\n\
         * Tolerance: the tracer's `tolerance_m`, an error budget on the height at the targets \
         spread over max(30 km, farthest target) of path (see `src/tracer/ray.rs`).\n",
        reps = config.repetitions,
        rays = config.rays,
        e0 = config.elevation_deg.0,
        e1 = config.elevation_deg.1,
        dists = config
            .distances_m
            .iter()
            .map(|d| km(*d))
            .collect::<Vec<_>>()
            .join(", "),
        rt = config.reference_tolerance_m,
        rs = config.reference_max_steps,
        ff = config.fold_factor,
        dl = km(config.distances_m[last]),
        hs = heights.join(" / "),
        rr = FoldTest::default().retrace_tolerance_m(config.reference_tolerance_m),
    )
}

/// The height-error table of one atmosphere.
fn height_table(r: &CaseResult, config: &AccuracyConfig) -> String {
    use std::fmt::Write as _;
    let last = config.distances_m.len() - 1;
    let mut head = String::from("| tolerance (m) |");
    let mut rule = String::from("|---:|");
    for d in &config.distances_m {
        let _ = write!(head, " max err {} km (m) |", km(*d));
        rule.push_str("---:|");
    }
    let _ = write!(
        head,
        " p95 {} km (m) | near-fold / compared | µs/ray | steps/ray | rays/s | steps/s |",
        km(config.distances_m[last])
    );
    rule.push_str("---:|---:|---:|---:|---:|---:|");
    let mut s = format!("{head}\n{rule}\n");
    for row in &r.rows {
        let mut line = format!("| {} |", fmt_tol(row.tolerance_m));
        for e in &row.errors {
            let _ = write!(line, " {} |", fmt_err(e.max_m));
        }
        let e = &row.errors[last];
        let _ = writeln!(
            line,
            " {} | {} / {} | {:.1} | {:.1} | {:.0} | {:.3e} |",
            fmt_err(e.p95_m),
            e.near_fold,
            e.compared,
            row.us_per_ray,
            row.steps_per_ray,
            row.rays_per_s(),
            row.steps_per_s()
        );
        s.push_str(&line);
    }
    s
}

/// The image-boundary table of one atmosphere.
fn boundary_table(r: &CaseResult) -> String {
    use std::fmt::Write as _;
    let mut s = String::from(
        "| tolerance (m) | re-trace tolerance (m) | images / reference | targets with another \
         count | max \\|Δ\\| boundary (″) | image search (ms) |\n|---:|---:|---:|---:|---:|---:|\n",
    );
    for row in &r.rows {
        let b = &row.boundaries;
        let _ = writeln!(
            s,
            "| {} | {} | {} / {} | {} / {} | {} | {:.1} |",
            fmt_tol(row.tolerance_m),
            fmt_tol(FoldTest::default().retrace_tolerance_m(row.tolerance_m)),
            b.images,
            b.reference_images,
            b.count_mismatches,
            b.targets,
            b.max_arcsec.map_or("–".into(), |v| format!("{v:.2e}")),
            row.images_ms
        );
    }
    s
}

/// The ray study's section of `BENCHMARKS.md` (a `##` heading, the settings, the plot, and per
/// atmosphere a `###` heading with its height-error and image-boundary tables). `plot_rel` is
/// the plot's path relative to the file.
pub fn rays_markdown(results: &[CaseResult], config: &AccuracyConfig, plot_rel: &str) -> String {
    use std::fmt::Write as _;
    let mut s = String::from("## Rays: height and image-boundary error against time per ray\n\n");
    s.push_str(&rays_settings(config));
    let _ = writeln!(s, "\n![time per ray against height error]({plot_rel})\n");
    for r in results {
        let _ = writeln!(s, "### {} ({})\n", r.name, r.kind);
        let _ = writeln!(
            s,
            "{}; observer {} m; reference {:.0} steps/ray, {} images.\n",
            r.description, r.observer_height_m, r.reference_steps_per_ray, r.reference_images
        );
        s.push_str(&height_table(r, config));
        s.push('\n');
        s.push_str(&boundary_table(r));
        s.push('\n');
    }
    s
}

fn plot_err<E: std::fmt::Display>(e: E) -> AccuracyError {
    AccuracyError::Plot(e.to_string())
}

/// Line colours, dark enough to read on white: distinct for the twelve standard cases here and
/// the fourteen stress atmospheres of [`super::stress_report`].
pub(crate) const LINE_COLOURS: [RGBColor; 14] = [
    RGBColor(220, 20, 60),
    RGBColor(34, 139, 34),
    RGBColor(218, 145, 0),
    RGBColor(31, 119, 180),
    RGBColor(255, 100, 0),
    RGBColor(128, 0, 128),
    RGBColor(0, 160, 160),
    RGBColor(230, 0, 200),
    RGBColor(120, 120, 0),
    RGBColor(140, 86, 75),
    RGBColor(0, 0, 0),
    RGBColor(100, 100, 255),
    RGBColor(0, 90, 50),
    RGBColor(150, 150, 150),
];

/// Smallest error drawn (m): a run identical to the reference has error 0.
pub(crate) const PLOT_FLOOR_M: f64 = 1e-10;

/// The log-log plot: x = µs per ray, y = max error at the farthest distance, one line per
/// atmosphere with its points labelled by tolerance, and a dashed line at 1e-5 m (the peer goal
/// at 20 km). PNG bytes, `width × height` pixels.
pub fn time_vs_error_png(
    results: &[CaseResult],
    width: u32,
    height: u32,
) -> Result<Vec<u8>, AccuracyError> {
    crate::output::plot::register_plot_font().map_err(AccuracyError::Plot)?;
    let font = crate::output::plot::PLOT_FONT;
    let points: Vec<Vec<(f64, f64, f64)>> = results
        .iter()
        .map(|r| {
            r.rows
                .iter()
                .filter_map(|row| {
                    let e = row.errors.last()?.max_m?;
                    Some((row.us_per_ray, e.max(PLOT_FLOOR_M), row.tolerance_m))
                })
                .collect()
        })
        .collect();
    let all = points.iter().flatten();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, 0.0f64, 1e-5f64, 1e-5f64);
    for &(x, y, _) in all {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !x0.is_finite() {
        (x0, x1) = (1.0, 10.0);
    }
    let (x0, x1, y0, y1) = (x0 / 1.5, x1 * 1.5, y0 / 3.0, y1 * 3.0);

    let mut buffer = vec![255u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "Time against error: max |Δh| at 26 km vs. the 1e-7 m reference",
                (font, 24),
            )
            .margin(20)
            .x_label_area_size(50)
            .y_label_area_size(80)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("time per ray (µs, one thread)")
            .y_desc("max error at 26 km (m)")
            .x_labels(30)
            .y_labels(12)
            .x_label_formatter(&|v| {
                // Label 1, 2 and 5 of each decade only (the others crowd).
                let m = v / 10f64.powf(v.log10().floor());
                if [1.0, 2.0, 5.0, 10.0].iter().any(|k| (m - k).abs() < 1e-6) {
                    format!("{v:.0}")
                } else {
                    String::new()
                }
            })
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .label_style((font, 16))
            .axis_desc_style((font, 18))
            .draw()
            .map_err(plot_err)?;
        let guide = RGBColor(120, 120, 120);
        chart
            .draw_series(DashedLineSeries::new(
                [(x0, 1e-5), (x1, 1e-5)],
                10,
                6,
                guide.stroke_width(2),
            ))
            .map_err(plot_err)?
            .label("1e-5 m: peer goal at 20 km")
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], guide.stroke_width(2))
            });
        for (i, (r, pts)) in results.iter().zip(&points).enumerate() {
            let colour = LINE_COLOURS[i % LINE_COLOURS.len()];
            let line: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, p.1)).collect();
            chart
                .draw_series(LineSeries::new(line, colour.stroke_width(2)))
                .map_err(plot_err)?
                .label(r.name.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(3))
                });
            chart
                .draw_series(pts.iter().map(|&(x, y, t)| {
                    EmptyElement::at((x, y))
                        + Circle::new((0, 0), 4, colour.filled())
                        + Text::new(
                            if i == 0 { fmt_tol(t) } else { String::new() },
                            (6, -14),
                            (font, 13).into_font(),
                        )
                }))
                .map_err(plot_err)?;
        }
        root.draw(&Text::new(
            "each line: tolerance 10 m (top left) … 1e-5 m; points labelled on the first line",
            (110, height as i32 - 95),
            (font, 15).into_font(),
        ))
        .map_err(plot_err)?;
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((font, 14))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
    }
    crate::output::plot::rgb8_to_png(&buffer, width, height).map_err(AccuracyError::Plot)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tolerances_print_short() {
        assert_eq!(fmt_tol(10.0), "10");
        assert_eq!(fmt_tol(0.1), "0.1");
        assert_eq!(fmt_tol(1e-2), "1e-2");
        assert_eq!(fmt_tol(1e-4 * 0.01), "1e-6");
        assert_eq!(fmt_tol(2.5e-5), "2.5e-5");
    }

    #[test]
    fn configs_are_valid() {
        AccuracyConfig::full().check().unwrap();
        AccuracyConfig::quick().check().unwrap();
        let mut c = AccuracyConfig::quick();
        c.rays = 2;
        assert!(c.check().is_err());
    }
}
