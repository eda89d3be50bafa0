//! Jobs — the job loop. In: planned jobs ([`PlannedJob`]: a name, a validated request, the
//! SHA-256 of its inputs and its resolved parameters) and [`RunOptions`] (output folder, `-j N`,
//! `--force`, `--dry-run`, `--shard K/N`). Out: every job's outputs under `<out>/<job>/`, the
//! manifest, and a [`RunReport`] (status, time and outputs per job).
//!
//! A job whose key (program version, kind, parameters, input hashes) matches a successful
//! record of an earlier run, with every recorded output still present at its recorded size, is
//! skipped. A failing job is recorded as failed and the others go on. Outputs do not depend on
//! the thread count or the order jobs finish in.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use indicatif::ProgressBar;

use super::manifest::{
    JobRecord, JobStatus, MANIFEST_FORMAT, MANIFEST_NAME, Manifest, Shard, previous_records,
};
use super::writer::write_job_products;
use super::{AtmosphereCache, JobRequest};
use crate::output::{WriteError, remove_dead_temp_files, write_atomic};

/// A job ready to run: validated, its inputs hashed.
#[derive(Debug, Clone)]
pub struct PlannedJob {
    /// Unique name; also its output folder.
    pub name: String,
    /// What it does.
    pub request: JobRequest,
    /// Resolved parameters as recorded in the manifest.
    pub parameters: serde_json::Value,
    /// SHA-256 of every input file, by label.
    pub inputs: BTreeMap<String, String>,
    /// SHA-256 over program version, kind, parameters and inputs.
    pub key: String,
    /// Rough cost estimate (arbitrary units), for balancing shards and ordering the work.
    pub cost: f64,
}

impl PlannedJob {
    /// Plan `request` under `name`; `parameters` and `inputs` are what the manifest records.
    pub fn new(
        name: String,
        request: JobRequest,
        parameters: serde_json::Value,
        inputs: BTreeMap<String, String>,
    ) -> Self {
        let mut keyed = format!(
            "{}\0{}\0{}\0",
            program(),
            request.kind(),
            serde_json::to_string(&parameters).unwrap_or_default()
        );
        for (label, sha) in &inputs {
            keyed.push_str(&format!("{label}={sha}\0"));
        }
        let cost = cost_estimate(&request);
        PlannedJob {
            name,
            request,
            parameters,
            inputs,
            key: super::sha256_hex(keyed.as_bytes()),
            cost,
        }
    }
}

/// `ghostship <version>`.
pub fn program() -> String {
    format!("ghostship {}", env!("CARGO_PKG_VERSION"))
}

/// Rough work of a job: pixels × samples for renders, rays × distances for traces, a constant
/// for profiles (the units only need to be comparable).
fn cost_estimate(request: &JobRequest) -> f64 {
    match request {
        JobRequest::Profile(_) => 200_000.0,
        JobRequest::Trace(t) => (50_000.0 + 300.0 * t.ray_count() as f64) * (1 + t.ensemble) as f64,
        JobRequest::Compare(c) => c.cost(),
        // About one sounding per 4 kB of archive, each about as costly as a short trace.
        JobRequest::Survey(s) => {
            let bytes: u64 = s
                .files()
                .unwrap_or_default()
                .iter()
                .filter_map(|f| std::fs::metadata(f).ok())
                .map(|m| m.len())
                .sum();
            50_000.0 + 25.0 * bytes as f64
        }
        JobRequest::Sequence(s) => {
            let r = &s.render;
            let spp = r.settings.spp.unwrap_or(r.scene.camera.samples_per_pixel) as f64;
            let (w, h) =
                r.settings.sizes[0].unwrap_or((r.scene.camera.width, r.scene.camera.height));
            let frame = 0.3 * (w as f64) * (h as f64) * spp;
            // A sun sweep traces its rays once; an observer sweep prepares every frame.
            let count = s.frame_count() as f64;
            let setup = if s.sweep.moves_sun() {
                50_000.0
            } else {
                50_000.0 * count
            };
            setup + frame * count
        }
        JobRequest::Render(r) => {
            let spp = r.settings.spp.unwrap_or(r.scene.camera.samples_per_pixel) as f64;
            let (w, h) = (r.scene.camera.width, r.scene.camera.height);
            r.settings
                .sizes
                .iter()
                .map(|s| {
                    let (w, h) = s.unwrap_or((w, h));
                    50_000.0 + 0.3 * (w as f64) * (h as f64) * spp
                })
                .sum()
        }
    }
}

/// Which jobs (indices into `jobs`) belong to `shard`: the jobs sorted by cost (then name) and
/// dealt out greedily to the least-loaded shard, so the split does not depend on the order of
/// the pipeline file and every shard gets about the same work.
pub fn shard_jobs(jobs: &[PlannedJob], shard: Shard) -> Vec<usize> {
    let mut order: Vec<usize> = (0..jobs.len()).collect();
    order.sort_by(|&a, &b| {
        jobs[b]
            .cost
            .total_cmp(&jobs[a].cost)
            .then_with(|| jobs[a].name.cmp(&jobs[b].name))
    });
    let mut load = vec![0.0_f64; shard.count];
    let mut mine = Vec::new();
    for i in order {
        let (least, _) = load
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .unwrap_or((0, &0.0));
        load[least] += jobs[i].cost;
        if least + 1 == shard.index {
            mine.push(i);
        }
    }
    mine.sort();
    mine
}

/// How to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// The output folder (not a filesystem root).
    pub out_dir: PathBuf,
    /// Jobs run at the same time (≥ 1).
    pub parallel_jobs: usize,
    /// Rerun jobs even when unchanged.
    pub force: bool,
    /// Only say what would run.
    pub dry_run: bool,
    /// Run only this part of the jobs.
    pub shard: Option<Shard>,
    /// The pipeline's name (recorded in the manifest).
    pub pipeline: String,
    /// SHA-256 of the pipeline file (recorded in the manifest).
    pub pipeline_sha256: String,
}

/// What happened to one job.
#[derive(Debug, Clone, PartialEq)]
pub enum JobOutcome {
    /// It ran and wrote its outputs.
    Ran,
    /// It was unchanged since an earlier run.
    Skipped,
    /// It failed (the message names the file, line and reason).
    Failed(String),
    /// Dry run: it would run.
    WouldRun,
    /// Dry run: it would be skipped.
    WouldSkip,
}

/// One row of the run's summary.
#[derive(Debug, Clone)]
pub struct JobSummary {
    /// The job's name.
    pub name: String,
    /// `profile`, `trace` or `render`.
    pub kind: &'static str,
    /// What happened.
    pub outcome: JobOutcome,
    /// Wall-clock time spent on it.
    pub duration: Duration,
    /// Its outputs (paths under the output folder).
    pub outputs: Vec<PathBuf>,
}

/// The whole run.
#[derive(Debug, Clone)]
pub struct RunReport {
    /// One row per job of this run (or shard), in pipeline order.
    pub jobs: Vec<JobSummary>,
    /// Temporary files of dead runs that were removed.
    pub removed_temp_files: Vec<PathBuf>,
    /// The manifest written (`None` for a dry run).
    pub manifest: Option<PathBuf>,
}

impl RunReport {
    /// Jobs that failed.
    pub fn failed(&self) -> usize {
        self.jobs
            .iter()
            .filter(|j| matches!(j.outcome, JobOutcome::Failed(_)))
            .count()
    }
}

/// Why a run could not start or finish (a failing job is not one: it is in the report).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The output folder is a filesystem root.
    #[error("refusing to write into {0}: it is a filesystem root (give --out a folder of its own)")]
    RootFolder(PathBuf),
    /// Files could not be written or removed.
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// Whether `dir` (made absolute, symbolic links resolved as far as it exists) is a filesystem
/// root such as `/`.
pub fn is_filesystem_root(dir: &Path) -> bool {
    let absolute = std::path::absolute(dir).unwrap_or_else(|_| dir.to_path_buf());
    let mut existing = absolute.as_path();
    let mut rest = Vec::new();
    while !existing.exists() {
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                existing = parent;
            }
            _ => break,
        }
    }
    let mut resolved = existing
        .canonicalize()
        .unwrap_or_else(|_| existing.to_path_buf());
    for name in rest.iter().rev() {
        if name == ".." {
            resolved.pop();
        } else if name != "." {
            resolved.push(name);
        }
    }
    resolved.parent().is_none()
}

/// Run `jobs` (or the shard of them `options` names) into `options.out_dir`.
pub fn run_jobs(
    jobs: &[PlannedJob],
    options: &RunOptions,
    progress: &ProgressBar,
) -> Result<RunReport, RunError> {
    if is_filesystem_root(&options.out_dir) {
        return Err(RunError::RootFolder(options.out_dir.clone()));
    }
    let mine: Vec<usize> = match options.shard {
        Some(shard) => shard_jobs(jobs, shard),
        None => (0..jobs.len()).collect(),
    };
    let removed_temp_files = if options.dry_run {
        Vec::new()
    } else {
        remove_dead_temp_files(&options.out_dir)?
    };
    let (mut to_run, shared) = triage(jobs, &mine, options);
    if options.dry_run {
        return Ok(RunReport {
            jobs: shared.rows.into_values().collect(),
            removed_temp_files,
            manifest: None,
        });
    }
    // Costliest first, so the last job to finish is a short one.
    to_run.sort_by(|&a, &b| jobs[b].cost.total_cmp(&jobs[a].cost).then(a.cmp(&b)));
    let manifest_path = options.out_dir.join(
        options
            .shard
            .map_or_else(|| MANIFEST_NAME.to_string(), |s| s.manifest_name()),
    );
    let state = Mutex::new(shared);
    execute(jobs, &to_run, options, progress, &state, &manifest_path)?;
    let shared = state.into_inner().unwrap_or_else(|e| e.into_inner());
    write_atomic(&manifest_path, &shared.manifest.to_json())?;
    Ok(RunReport {
        jobs: shared.rows.into_values().collect(),
        removed_temp_files,
        manifest: Some(manifest_path),
    })
}

/// Split `mine` into the jobs to run and those unchanged since an earlier run (whose records
/// go into the new manifest as they are); in a dry run every job gets its row here.
fn triage(jobs: &[PlannedJob], mine: &[usize], options: &RunOptions) -> (Vec<usize>, Shared) {
    let previous = if options.force {
        BTreeMap::new()
    } else {
        previous_records(&options.out_dir)
    };
    let mut shared = Shared {
        manifest: empty_manifest(jobs, options),
        rows: BTreeMap::new(),
        last_save: Instant::now(),
    };
    let mut to_run = Vec::new();
    for &i in mine {
        let job = &jobs[i];
        let record = previous
            .get(&job.name)
            .filter(|r| r.key == job.key && outputs_present(&options.out_dir, r));
        if let Some(record) = record {
            shared
                .manifest
                .jobs
                .insert(job.name.clone(), record.clone());
        }
        let outcome = match (record.is_some(), options.dry_run) {
            (true, true) => JobOutcome::WouldSkip,
            (true, false) => JobOutcome::Skipped,
            (false, true) => JobOutcome::WouldRun,
            (false, false) => {
                to_run.push(i);
                continue;
            }
        };
        let outputs = record
            .map(|r| r.outputs.keys().map(|k| options.out_dir.join(k)).collect())
            .unwrap_or_default();
        shared
            .rows
            .insert(i, summary(job, outcome, Duration::ZERO, outputs));
    }
    (to_run, shared)
}

/// A manifest of `options`' run of `jobs`, without job records yet.
fn empty_manifest(jobs: &[PlannedJob], options: &RunOptions) -> Manifest {
    Manifest {
        format: MANIFEST_FORMAT.into(),
        program: program(),
        pipeline: options.pipeline.clone(),
        pipeline_sha256: options.pipeline_sha256.clone(),
        shard: options.shard,
        jobs_in_pipeline: jobs
            .iter()
            .map(|j| j.name.clone())
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect(),
        jobs: BTreeMap::new(),
    }
}

struct Shared {
    manifest: Manifest,
    rows: BTreeMap<usize, JobSummary>,
    last_save: Instant,
}

fn summary(
    job: &PlannedJob,
    outcome: JobOutcome,
    duration: Duration,
    outputs: Vec<PathBuf>,
) -> JobSummary {
    JobSummary {
        name: job.name.clone(),
        kind: job.request.kind(),
        outcome,
        duration,
        outputs,
    }
}

fn outputs_present(out_dir: &Path, record: &JobRecord) -> bool {
    record.status == JobStatus::Ok
        && record.outputs.iter().all(|(rel, out)| {
            std::fs::metadata(out_dir.join(rel)).is_ok_and(|m| m.is_file() && m.len() == out.bytes)
        })
}

/// Run `to_run` on `options.parallel_jobs` threads, recording each job as it finishes (the
/// manifest is saved at most once a second meanwhile, so a killed run keeps most of its work).
fn execute(
    jobs: &[PlannedJob],
    to_run: &[usize],
    options: &RunOptions,
    progress: &ProgressBar,
    state: &Mutex<Shared>,
    manifest_path: &Path,
) -> Result<(), RunError> {
    let cache = AtmosphereCache::new();
    for &i in to_run {
        if let Some(a) = jobs[i].request.atmosphere() {
            cache.expect(a);
        }
    }
    progress.set_length(to_run.len() as u64);
    let next = AtomicUsize::new(0);
    let running = Mutex::new(BTreeSet::new());
    let threads = options.parallel_jobs.clamp(1, to_run.len().max(1));
    std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| -> Result<(), RunError> {
                    while let Some(&i) = to_run.get(next.fetch_add(1, Ordering::SeqCst)) {
                        let job = &jobs[i];
                        set_running(&running, progress, &job.name, true);
                        let start = Instant::now();
                        let result = run_one(job, &options.out_dir, &cache);
                        if let Some(a) = job.request.atmosphere() {
                            cache.release(a);
                        }
                        set_running(&running, progress, &job.name, false);
                        progress.inc(1);
                        record(
                            state,
                            i,
                            job,
                            result,
                            start.elapsed(),
                            options,
                            manifest_path,
                        )?;
                    }
                    Ok(())
                })
            })
            .collect();
        // Jobs catch their own panics; a worker has nothing else that could panic.
        workers
            .into_iter()
            .try_for_each(|w| w.join().unwrap_or(Ok(())))
    })
}

fn set_running(running: &Mutex<BTreeSet<String>>, progress: &ProgressBar, name: &str, on: bool) {
    let mut set = running.lock().unwrap_or_else(|e| e.into_inner());
    if on {
        set.insert(name.to_string());
    } else {
        set.remove(name);
    }
    progress.set_message(set.iter().cloned().collect::<Vec<_>>().join(", "));
}

/// Run one job and write its products; a panic inside the job is a failure of that job only.
fn run_one(
    job: &PlannedJob,
    out_dir: &Path,
    cache: &AtmosphereCache,
) -> Result<BTreeMap<String, super::manifest::OutputRecord>, String> {
    let work = || -> Result<_, String> {
        let products = job.request.products(cache).map_err(|e| error_text(&e))?;
        write_job_products(out_dir, &job.name, &products).map_err(|e| error_text(&e))
    };
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(work))
        .unwrap_or_else(|_| Err("internal error: the job panicked".into()))
}

/// An error and its sources on one line, leaving out a source the text already ends with.
pub fn error_text(err: &dyn std::error::Error) -> String {
    let mut text = err.to_string();
    let mut source = err.source();
    while let Some(cause) = source {
        let part = cause.to_string();
        if !text.ends_with(&part) {
            text.push_str(": ");
            text.push_str(&part);
        }
        source = cause.source();
    }
    text
}

#[allow(clippy::too_many_arguments)] // the job, its result and where to record it
fn record(
    state: &Mutex<Shared>,
    index: usize,
    job: &PlannedJob,
    result: Result<BTreeMap<String, super::manifest::OutputRecord>, String>,
    duration: Duration,
    options: &RunOptions,
    manifest_path: &Path,
) -> Result<(), RunError> {
    let (status, error, outputs) = match result {
        Ok(outputs) => (JobStatus::Ok, None, outputs),
        Err(e) => (JobStatus::Failed, Some(e), BTreeMap::new()),
    };
    let paths = outputs.keys().map(|k| options.out_dir.join(k)).collect();
    let outcome = error.clone().map_or(JobOutcome::Ran, JobOutcome::Failed);
    let mut shared = state.lock().unwrap_or_else(|e| e.into_inner());
    shared.manifest.jobs.insert(
        job.name.clone(),
        JobRecord {
            kind: job.request.kind().into(),
            key: job.key.clone(),
            status,
            error,
            parameters: job.parameters.clone(),
            inputs: job.inputs.clone(),
            outputs,
        },
    );
    shared
        .rows
        .insert(index, summary(job, outcome, duration, paths));
    if shared.last_save.elapsed() >= Duration::from_secs(1) {
        write_atomic(manifest_path, &shared.manifest.to_json())?;
        shared.last_save = Instant::now();
    }
    Ok(())
}
