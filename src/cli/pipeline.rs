//! `ghostship pipeline run|merge`: a pipeline file → [`ResolvedPipeline`] (every job expanded,
//! validated and planned) → the jobs layer's run ([`run_jobs`]) into `out/<pipeline>/` or
//! `--out DIR`, with a progress bar over the jobs → a summary table; `merge` combines the
//! manifests of a sharded run. The file format is documented in docs/pipeline.md.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use ghostship::jobs::manifest::{Shard, merge};
use ghostship::jobs::run::{JobOutcome, RunOptions, RunReport, run_jobs};
use ghostship::jobs::survey::JoinOutcome;
use ghostship::pipeline::ResolvedPipeline;
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `ghostship pipeline`.
#[derive(Debug, clap::Args)]
pub struct PipelineArgs {
    /// What to do with the pipeline.
    #[command(subcommand)]
    pub action: PipelineAction,
}

/// Pipeline sub-commands.
#[derive(Debug, clap::Subcommand)]
pub enum PipelineAction {
    /// Run the jobs of a pipeline file that changed since the last run (the file format:
    /// docs/pipeline.md). Each job writes into <out>/<job>/ (profile: profile.csv, layers.json,
    /// profile.png; trace: trace.json, trace.png; render: <W>x<H>.png/.exr); <out>/manifest.json
    /// records the SHA-256 of every input and output.
    Run(RunArgs),
    /// Combine the shard manifests (manifest-shard-K-of-N.json) of a run split with --shard into
    /// <first DIR>/manifest.json, checking that the shards hold exactly the pipeline's jobs, each
    /// once, all successful (outputs in other folders are copied into the first).
    Merge(MergeArgs),
}

/// `--jobs`: a whole number ≥ 1.
fn parse_parallel_jobs(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("{text:?} is not a whole number ≥ 1")),
    }
}

/// Arguments of `ghostship pipeline run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The pipeline file (TOML with [[profile]], [[trace]] and [[render]] tables; see
    /// docs/pipeline.md).
    #[arg(value_name = "PIPELINE.toml")]
    pub pipeline: PathBuf,
    /// Output folder, relative to the current folder [default: out/<pipeline name>/]. A
    /// filesystem root is refused.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Jobs run at the same time (each also uses every core inside).
    #[arg(short = 'j', long = "jobs", value_name = "N", default_value_t = 1, value_parser = parse_parallel_jobs)]
    pub parallel_jobs: usize,
    /// Rerun every job, even those unchanged since the last run.
    #[arg(long)]
    pub force: bool,
    /// List the jobs and whether each would run or be skipped; write nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Run only part K of N of the jobs (K = 1…N; the split is deterministic and balanced by
    /// estimated cost); writes <out>/manifest-shard-K-of-N.json. Combine with `pipeline merge`.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<Shard>,
    /// Also list every output file.
    #[arg(short, long)]
    pub verbose: bool,
}

/// Arguments of `ghostship pipeline merge`.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// Folders holding the shards' manifests and outputs (the merged manifest goes into the
    /// first).
    #[arg(value_name = "DIR", required = true)]
    pub dirs: Vec<PathBuf>,
}

/// Run `ghostship pipeline …`.
pub fn run(args: PipelineArgs, quiet: bool) -> anyhow::Result<()> {
    match args.action {
        PipelineAction::Run(run_args) => run_pipeline(&run_args, quiet),
        PipelineAction::Merge(merge_args) => {
            let merged = merge(&merge_args.dirs)?;
            if !quiet {
                let text = format!("merged into {}\n", merged.path.display());
                super::print_stdout(&(text + &joined_text(&merged.joined)))?;
            }
            check_joins(&merged.joined)
        }
    }
}

fn run_pipeline(args: &RunArgs, quiet: bool) -> anyhow::Result<()> {
    let start = Instant::now();
    let pipeline = ResolvedPipeline::from_file(&args.pipeline)?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("out").join(&pipeline.name));
    let options = RunOptions {
        out_dir: out.clone(),
        parallel_jobs: args.parallel_jobs,
        force: args.force,
        dry_run: args.dry_run,
        shard: args.shard,
        pipeline: pipeline.name.clone(),
        pipeline_sha256: pipeline.sha256.clone(),
    };
    let bar = if quiet || args.dry_run || !std::io::stderr().is_terminal() {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(0)
    };
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} jobs  {wide_msg}")
            .context("progress bar template")?
            .progress_chars("=> "),
    );
    let report = run_jobs(&pipeline.jobs, &options, &bar)?;
    bar.finish_and_clear();
    if !quiet {
        super::print_stdout(&joined_text(&report.joined))?;
        super::print_stdout(&summary_table(&report, &out, args, start.elapsed()))?;
    }
    check_joins(&report.joined)?;
    let failed: Vec<String> = report
        .jobs
        .iter()
        .filter_map(|j| match &j.outcome {
            JobOutcome::Failed(reason) => Some(format!("  {}: {reason}", j.name)),
            _ => None,
        })
        .collect();
    if !failed.is_empty() {
        const SHOWN: usize = 20;
        let more = failed.len().saturating_sub(SHOWN);
        anyhow::bail!(
            "{} of {} job(s) failed (every reason is in {}):\n{}{}",
            failed.len(),
            report.jobs.len(),
            report.manifest.as_deref().unwrap_or(&out).display(),
            failed[..failed.len().min(SHOWN)].join("\n"),
            if more > 0 {
                format!("\n  … and {more} more")
            } else {
                String::new()
            }
        );
    }
    Ok(())
}

/// One row per job that ran, failed or would run (unchanged jobs are counted on one line unless
/// `--verbose` or `--dry-run`), then the totals.
fn summary_table(
    report: &RunReport,
    out: &Path,
    args: &RunArgs,
    elapsed: std::time::Duration,
) -> String {
    let width = report
        .jobs
        .iter()
        .map(|j| j.name.len())
        .max()
        .unwrap_or(3)
        .max(3);
    let header = format!(
        "{:<width$}  {:<7}  {:<9}  {:>8}  outputs\n",
        "job", "kind", "status", "time"
    );
    let mut text = String::new();
    let (mut ran, mut skipped, mut failed) = (0, 0, 0);
    for job in &report.jobs {
        let status = match &job.outcome {
            JobOutcome::Ran => {
                ran += 1;
                "ok"
            }
            JobOutcome::Skipped | JobOutcome::WouldSkip => {
                skipped += 1;
                "unchanged"
            }
            JobOutcome::Failed(_) => {
                failed += 1;
                "FAILED"
            }
            JobOutcome::WouldRun => {
                ran += 1;
                "would run"
            }
        };
        let show = args.verbose
            || args.dry_run
            || !matches!(job.outcome, JobOutcome::Skipped | JobOutcome::WouldSkip);
        if !show {
            continue;
        }
        text.push_str(&format!(
            "{:<width$}  {:<7}  {:<9}  {:>7.2}s  {}\n",
            job.name,
            job.kind,
            status,
            job.duration.as_secs_f64(),
            job.outputs.len()
        ));
        if let JobOutcome::Failed(reason) = &job.outcome {
            text.push_str(&format!("    {reason}\n"));
        }
        if args.verbose {
            for path in &job.outputs {
                text.push_str(&format!("    {}\n", path.display()));
            }
        }
    }
    if !text.is_empty() {
        text.insert_str(0, &header);
    }
    let verb = if args.dry_run { "would run" } else { "ran" };
    text.push_str(&format!(
        "{} job(s){}: {ran} {verb}, {skipped} unchanged (skipped), {failed} failed; {:.2} s; output in {}\n",
        report.jobs.len(),
        args.shard.map(|s| format!(" in shard {s}")).unwrap_or_default(),
        elapsed.as_secs_f64(),
        out.display()
    ));
    if !report.removed_temp_files.is_empty() {
        text.push_str(&format!(
            "removed {} temporary file(s) left by killed runs\n",
            report.removed_temp_files.len()
        ));
    }
    text
}

/// One line per split survey joined.
fn joined_text(joined: &[JoinOutcome]) -> String {
    joined
        .iter()
        .filter(|j| j.result == Ok(true))
        .map(|j| format!("joined the survey parts into {}\n", j.dir.display()))
        .collect()
}

/// An error naming every split survey whose parts could not be joined.
fn check_joins(joined: &[JoinOutcome]) -> anyhow::Result<()> {
    let failed: Vec<String> = joined
        .iter()
        .filter_map(|j| {
            let e = j.result.as_ref().err()?;
            Some(format!("  {}: {e}", j.dir.display()))
        })
        .collect();
    if !failed.is_empty() {
        anyhow::bail!(
            "cannot join {} split survey(s):\n{}",
            failed.len(),
            failed.join("\n")
        );
    }
    Ok(())
}
