//! `ghostship pipeline run`: a pipeline file → [`ResolvedPipeline`] → its profile and trace jobs,
//! one after another (each parallel inside), into `out/<pipeline name>/` or `--out DIR`, with a
//! progress bar over the jobs; then the list of files written.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use anyhow::Context;
use ghostship::atmosphere::{AtmosphereOptions, AtmosphereSource, load_atmosphere};
use ghostship::output::write_atomic;
use ghostship::pipeline::{ProfileJob, ResolvedPipeline, TraceJob};
use ghostship::tracer::TracerConfig;
use indicatif::{ProgressBar, ProgressStyle};

use super::profile::{
    DEFAULT_LAYERS_TOP_M, DEFAULT_PLOT_TOP_M, ProfileOptions, profile_products, write_profile,
};
use super::trace::{DEFAULT_TRAP_DISTANCE_M, TraceOptions, trace_products};

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
    /// Run every job of a pipeline file (profile jobs → <out>/<job>/profile.csv, layers.json,
    /// profile.png; trace jobs → <out>/<job>.json and <out>/<job>.png).
    Run(RunArgs),
}

/// Arguments of `ghostship pipeline run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The pipeline file (TOML with [[profile]], [[trace]] and [[render]] tables).
    #[arg(value_name = "PIPELINE.toml")]
    pub pipeline: PathBuf,
    /// Output folder [default: out/<pipeline name>/].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
}

/// Run `ghostship pipeline …`.
pub fn run(args: PipelineArgs, quiet: bool) -> anyhow::Result<()> {
    match args.action {
        PipelineAction::Run(run_args) => run_pipeline(&run_args, quiet),
    }
}

fn atmosphere_options(wavelength_nm: Option<f64>, smooth_m: Option<f64>) -> AtmosphereOptions {
    let d = AtmosphereOptions::default();
    AtmosphereOptions {
        smooth_m: smooth_m.unwrap_or(d.smooth_m),
        wavelength_nm: wavelength_nm.unwrap_or(d.wavelength_nm),
        igra2_time: None,
    }
}

fn profile_job(job: &ProfileJob, out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let options = ProfileOptions {
        source: AtmosphereSource::parse(&job.atmosphere),
        atmosphere: atmosphere_options(job.wavelength_nm, job.smooth_m),
        plot_top_agl_m: DEFAULT_PLOT_TOP_M,
        layers_top_agl_m: DEFAULT_LAYERS_TOP_M,
    };
    let atm = load_atmosphere(&options.source, &options.atmosphere)?;
    let products = profile_products(&atm, &options)?;
    write_profile(&out.join(&job.name), &products)
}

fn trace_options(job: &TraceJob) -> anyhow::Result<TraceOptions> {
    let tracer = TracerConfig {
        tolerance_m: job
            .tolerance_m
            .unwrap_or(TracerConfig::default().tolerance_m),
        ..TracerConfig::default()
    };
    TraceOptions::new(
        AtmosphereSource::parse(&job.atmosphere),
        atmosphere_options(job.wavelength_nm, job.smooth_m),
        job.observer_height_m,
        &job.elevation_deg,
        job.distances_m.clone(),
        job.target_heights_m.clone(),
        tracer,
        DEFAULT_TRAP_DISTANCE_M,
        false,
    )
}

fn trace_job(job: &TraceJob, options: &TraceOptions, out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let atm = load_atmosphere(&options.source, &options.atmosphere)?;
    let (report, png) = trace_products(&atm, options, true)?;
    let json_path = out.join(format!("{}.json", job.name));
    let mut json = report.to_json()?;
    json.push('\n');
    write_atomic(&json_path, json.as_bytes())?;
    let mut written = vec![json_path];
    if let Some(png) = png {
        let png_path = out.join(format!("{}.png", job.name));
        write_atomic(&png_path, &png)?;
        written.push(png_path);
    }
    Ok(written)
}

fn run_pipeline(args: &RunArgs, quiet: bool) -> anyhow::Result<()> {
    let pipeline = ResolvedPipeline::from_file(&args.pipeline)?;
    if !pipeline.renders.is_empty() {
        anyhow::bail!(
            "pipeline {} has {} render job(s) ({}): render jobs need the renderer (not in this build)",
            args.pipeline.display(),
            pipeline.renders.len(),
            pipeline
                .renders
                .iter()
                .map(|r| r.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    // Check every trace job before running anything, so a typo in the last one costs nothing.
    let traces = pipeline
        .traces
        .iter()
        .map(|job| {
            trace_options(job).with_context(|| {
                format!(
                    "invalid pipeline {}: trace job {:?}",
                    args.pipeline.display(),
                    job.name
                )
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("out").join(&pipeline.name));
    let total = (pipeline.profiles.len() + pipeline.traces.len()) as u64;
    let bar = if quiet || !std::io::stderr().is_terminal() {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(total)
    };
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} jobs  {msg}")
            .context("progress bar template")?
            .progress_chars("=> "),
    );
    let mut written = Vec::new();
    for job in &pipeline.profiles {
        bar.set_message(format!("profile {}", job.name));
        let files =
            profile_job(job, &out).with_context(|| format!("profile job {:?} failed", job.name))?;
        written.extend(files);
        bar.inc(1);
    }
    for (job, options) in pipeline.traces.iter().zip(&traces) {
        bar.set_message(format!("trace {}", job.name));
        let files = trace_job(job, options, &out)
            .with_context(|| format!("trace job {:?} failed", job.name))?;
        written.extend(files);
        bar.inc(1);
    }
    bar.finish_and_clear();
    if !quiet {
        println!(
            "pipeline {}: {} job(s), {} file(s) in {}",
            pipeline.name,
            total,
            written.len(),
            out.display()
        );
        for path in &written {
            println!("  {}", path.display());
        }
    }
    Ok(())
}
