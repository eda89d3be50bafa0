//! `ghostship pipeline run`: a pipeline file → [`ResolvedPipeline`] → its profile, trace and
//! render jobs, one after another (each parallel inside), into `out/<pipeline name>/` or
//! `--out DIR`, with a progress bar over the jobs; then the list of files written. Render jobs
//! write `<name>_<W>x<H>.png/.exr` per size, or `<name>.png/.exr` at the scene's own size.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};

use anyhow::Context;
use ghostship::atmosphere::{AtmosphereOptions, AtmosphereSource, load_atmosphere};
use ghostship::output::film::write_films;
use ghostship::output::png::DEFAULT_EXPOSURE;
use ghostship::output::write_atomic;
use ghostship::pipeline::{ImageFormat, ProfileJob, RenderJob, ResolvedPipeline, TraceJob};
use ghostship::render::{RenderOptions, provenance};
use ghostship::scene::Scene;
use ghostship::tracer::TracerConfig;
use indicatif::{ProgressBar, ProgressStyle};

use super::profile::{
    DEFAULT_LAYERS_TOP_M, DEFAULT_PLOT_TOP_M, ProfileOptions, profile_products, write_profile,
};
use super::render::render_film;
use super::trace::{TraceOptions, trace_products};

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

fn atmosphere_options(
    wavelength_nm: Option<f64>,
    smooth_m: Option<f64>,
    igra2_time: Option<&str>,
) -> AtmosphereOptions {
    let d = AtmosphereOptions::default();
    AtmosphereOptions {
        smooth_m: smooth_m.unwrap_or(d.smooth_m),
        wavelength_nm: wavelength_nm.unwrap_or(d.wavelength_nm),
        igra2_time: igra2_time.map(str::to_string),
    }
}

fn profile_job(job: &ProfileJob, out: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let options = ProfileOptions {
        source: AtmosphereSource::parse(&job.atmosphere),
        atmosphere: atmosphere_options(job.wavelength_nm, job.smooth_m, job.igra2_time.as_deref()),
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
        atmosphere_options(job.wavelength_nm, job.smooth_m, job.igra2_time.as_deref()),
        job.observer_height_m,
        &job.elevation_deg,
        job.distances_m.clone(),
        job.target_heights_m.clone(),
        tracer,
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

fn render_job(
    job: &RenderJob,
    scene: &Scene,
    size: Option<(u32, u32)>,
    label: &str,
    out: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    let mut scene = scene.clone();
    if let Some((width, height)) = size {
        scene.camera.width = width;
        scene.camera.height = height;
    }
    let options = RenderOptions {
        samples_per_pixel: job.spp,
        quiet: true,
        tolerance_m: job
            .tolerance_m
            .unwrap_or(RenderOptions::default().tolerance_m),
        ..RenderOptions::default()
    };
    let film = render_film(&scene, &options)?;
    let meta = provenance(&scene, &options);
    let written: Vec<PathBuf> = job
        .formats
        .iter()
        .map(|format| {
            let ext = match format {
                ImageFormat::Png => "png",
                ImageFormat::Exr => "exr",
            };
            out.join(format!("{label}.{ext}"))
        })
        .collect();
    // PNG and EXR are encoded (and written) in parallel.
    write_films(&film, &written, &meta, DEFAULT_EXPOSURE)?;
    Ok(written)
}

fn run_pipeline(args: &RunArgs, quiet: bool) -> anyhow::Result<()> {
    let pipeline = ResolvedPipeline::from_file(&args.pipeline)?;
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
    // Load every scene before running anything, for the same reason.
    let scenes = pipeline
        .renders
        .iter()
        .map(|job| {
            Scene::from_file(&job.scene).with_context(|| {
                format!(
                    "invalid pipeline {}: render job {:?}",
                    args.pipeline.display(),
                    job.name
                )
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let renders: usize = pipeline.renders.iter().map(|r| r.sizes.len().max(1)).sum();
    let total = (pipeline.profiles.len() + pipeline.traces.len() + renders) as u64;
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
    for (job, scene) in pipeline.renders.iter().zip(&scenes) {
        let sizes: Vec<Option<(u32, u32)>> = if job.sizes.is_empty() {
            vec![None]
        } else {
            job.sizes.iter().copied().map(Some).collect()
        };
        for size in sizes {
            let label = match size {
                Some((w, h)) => format!("{}_{w}x{h}", job.name),
                None => job.name.clone(),
            };
            bar.set_message(format!("render {label}"));
            let files = render_job(job, scene, size, &label, &out)
                .with_context(|| format!("render job {label:?} failed"))?;
            written.extend(files);
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    if !quiet {
        let mut text = format!(
            "pipeline {}: {} job(s), {} file(s) in {}\n",
            pipeline.name,
            total,
            written.len(),
            out.display()
        );
        for path in &written {
            text.push_str(&format!("  {}\n", path.display()));
        }
        super::print_stdout(&text)?;
    }
    Ok(())
}
