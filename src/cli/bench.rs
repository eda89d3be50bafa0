//! `ghostship bench accuracy`: arguments → an [`AccuracyConfig`] with the standard cases and a
//! [`FrameConfig`] with the paper scenes → measure every case ([`ghostship::verify::accuracy`])
//! and every scene's frames ([`ghostship::verify::frames`]) with a progress bar → write
//! `BENCHMARKS.md`, `docs/time_vs_error.png` and `docs/frame_time_vs_error.png` under the output
//! folder.
//!
//! `ghostship bench stress`: the stress suite's atmospheres → a [`StressConfig`] → measure each
//! ([`ghostship::verify::stress_report`]) with a progress bar → write `STRESS.md` and
//! `docs/stress_error_vs_tolerance.png` under the output folder.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Context;
use ghostship::output::write_atomic;
use ghostship::verify::accuracy::{
    AccuracyConfig, BenchCase, CaseResult, measure_case, rays_markdown, standard_cases,
    time_vs_error_png,
};
use ghostship::verify::benchmarks::benchmarks_markdown;
use ghostship::verify::frames::{
    FrameConfig, FrameTiming, PaperScene, SceneSweep, SpectralTiming, load_paper_scenes,
    load_spectral_scenes, sweep_scene, time_scene, time_spectral,
};
use ghostship::verify::frames_report::{frame_time_vs_error_png, frames_markdown};
use ghostship::verify::stress::stress_suite;
use ghostship::verify::stress_report::{
    StressConfig, StressResult, error_vs_tolerance_png, measure_stress, stress_markdown,
};
use indicatif::{ProgressBar, ProgressStyle};

/// Arguments of `ghostship bench`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Which benchmark.
    #[command(subcommand)]
    pub which: BenchCommand,
}

/// The benchmarks.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// Time against error: trace a fan through every paper atmosphere, two shipped soundings and
    /// the stress soundings at tolerances 10 m … 1e-5 m, compare the heights at 5, 10, 20 and
    /// 26 km and the image boundaries of a 20 m target with a 1e-7 m reference run, time the
    /// rays; render the paper scenes (data/scenes) at those tolerances on the fan and exact 3-D
    /// paths and compare the pixels with 1e-7 m renders; time frames at 400×200 and 1920×1080
    /// on the fan, exact 3-D and straight-ray paths. Writes BENCHMARKS.md,
    /// docs/time_vs_error.png and docs/frame_time_vs_error.png.
    Accuracy(AccuracyArgs),
    /// The stress suite's figure: trace the fourteen stress atmospheres (superadiabatic layers,
    /// 0.1 m layers with 30 K jumps, near-critical ducts, …) from five observers at elevations
    /// −5°…+90° and tangent to every layer corner, at tolerances 10 m … 1e-5 m; the largest
    /// error at 5–26 km against a 1e-7 m self-reference, Bouguer drift and terminations; writes
    /// STRESS.md and docs/stress_error_vs_tolerance.png.
    Stress(StressArgs),
}

/// Arguments of `ghostship bench stress`.
#[derive(Debug, clap::Args)]
pub struct StressArgs {
    /// Folder to write STRESS.md and docs/stress_error_vs_tolerance.png into.
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub out: PathBuf,
    /// The long launch set (about 150 elevations per observer and rays tangent to every
    /// twentieth break below 2 km) instead of the fast one.
    #[arg(long)]
    pub long: bool,
}

/// Arguments of `ghostship bench accuracy`.
#[derive(Debug, clap::Args)]
pub struct AccuracyArgs {
    /// Folder to write BENCHMARKS.md, docs/time_vs_error.png and docs/frame_time_vs_error.png
    /// into.
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub out: PathBuf,
    /// Folder holding the paper atmospheres and shipped soundings, and the paper scenes in its
    /// `scenes` folder.
    #[arg(long, value_name = "DIR", default_value = "data")]
    pub data: PathBuf,
    /// Rays in the fan (elevations −0.5°…0.5°). Default: 101 (21 with --quick).
    #[arg(long, value_name = "N")]
    pub rays: Option<usize>,
    /// A quick run that takes every code path: tolerances 1, 1e-2 and 1e-4 m only, 21 rays,
    /// frames at small sizes (sweep 40×20, timed at 80×40 and 192×108), two runs per frame.
    #[arg(long)]
    pub quick: bool,
}

/// Run `ghostship bench`.
pub fn run(args: BenchArgs, quiet: bool) -> anyhow::Result<()> {
    match args.which {
        BenchCommand::Accuracy(a) => accuracy(a, quiet),
        BenchCommand::Stress(a) => stress(a, quiet),
    }
}

fn accuracy(args: AccuracyArgs, quiet: bool) -> anyhow::Result<()> {
    let (mut config, frame_config) = if args.quick {
        (AccuracyConfig::quick(), FrameConfig::quick())
    } else {
        (AccuracyConfig::full(), FrameConfig::full())
    };
    if let Some(n) = args.rays {
        if !(3..=ghostship::jobs::trace::MAX_RAYS).contains(&n) {
            anyhow::bail!(
                "--rays {n}: give 3 to {} rays",
                ghostship::jobs::trace::MAX_RAYS
            );
        }
        config.rays = n;
    }
    let scenes_dir = args.data.join("scenes");
    let scenes = load_paper_scenes(&scenes_dir)
        .with_context(|| format!("cannot load the paper scenes from {}", scenes_dir.display()))?;
    let spectral_scenes = load_spectral_scenes(&scenes_dir).with_context(|| {
        format!(
            "cannot load the spectral scenes from {}",
            scenes_dir.display()
        )
    })?;
    let stress_dir = std::env::temp_dir().join(format!("ghostship-stress-{}", std::process::id()));
    std::fs::create_dir_all(&stress_dir)
        .with_context(|| format!("cannot create {}", stress_dir.display()))?;
    let measured = standard_cases(&args.data, &stress_dir)
        .map_err(anyhow::Error::from)
        .and_then(|cases| {
            let curved = scenes
                .iter()
                .filter(|s| !s.scene.atmosphere.straight)
                .count();
            let runs = cases.len() * (config.tolerances_m.len() + 1)
                + (scenes.len() + spectral_scenes.len()) * frame_config.timing_sizes.len()
                + curved * (frame_config.tolerances_m.len() + 1);
            let bar = progress_bar(quiet, runs as u64);
            measure_rays(&cases, &config, &bar).map(|r| (r, bar))
        });
    let _ = std::fs::remove_dir_all(&stress_dir);
    let (results, bar) = measured?;
    let (timings, sweeps) = measure_frames(&scenes, &frame_config, &bar)?;
    let spectral = measure_spectral(&spectral_scenes, &frame_config, &bar)?;
    bar.finish_and_clear();

    let mut command = String::from("ghostship bench accuracy");
    if args.quick {
        command.push_str(" --quick");
    }
    if let Some(n) = args.rays {
        command.push_str(&format!(" --rays {n}"));
    }
    let md = benchmarks_markdown(
        &command,
        &[
            frames_markdown(&timings, &spectral, &sweeps, &frame_config, FRAME_PLOT),
            rays_markdown(&results, &config, RAY_PLOT),
        ],
    );
    let ray_png = time_vs_error_png(&results, 1400, 900)?;
    let frame_png = frame_time_vs_error_png(&sweeps, &frame_config, 1400, 900)?;
    let md_path = args.out.join("BENCHMARKS.md");
    let written = [
        (args.out.join(RAY_PLOT), ray_png),
        (args.out.join(FRAME_PLOT), frame_png),
        (md_path, md.into_bytes()),
    ];
    for (path, bytes) in &written {
        write_atomic(path, bytes)?;
    }
    if !quiet {
        for (path, _) in &written {
            eprintln!("wrote {}", path.display());
        }
    }
    Ok(())
}

/// The plots, relative to the output folder (and to BENCHMARKS.md in it).
const RAY_PLOT: &str = "docs/time_vs_error.png";
const FRAME_PLOT: &str = "docs/frame_time_vs_error.png";

fn progress_bar(quiet: bool, len: u64) -> ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    if let Ok(style) =
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs  {msg}")
    {
        bar.set_style(style);
    }
    bar
}

fn stress(args: StressArgs, quiet: bool) -> anyhow::Result<()> {
    let config = if args.long {
        StressConfig::long()
    } else {
        StressConfig::fast()
    };
    let dir = std::env::temp_dir().join(format!("ghostship-stress-suite-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let measured = measure_stress_suite(&config, &dir, quiet);
    let _ = std::fs::remove_dir_all(&dir);
    let (results, study) = measured?;
    let command = if args.long {
        "ghostship bench stress --long"
    } else {
        "ghostship bench stress"
    };
    let md_path = args.out.join("STRESS.md");
    let png_path = args.out.join("docs").join("stress_error_vs_tolerance.png");
    let md = stress_markdown(
        &results,
        &config,
        command,
        "docs/stress_error_vs_tolerance.png",
    );
    let png = error_vs_tolerance_png(&results, &study, 1400, 900)?;
    write_atomic(&png_path, &png)?;
    write_atomic(&md_path, md.as_bytes())?;
    if !quiet {
        eprintln!("wrote {}", md_path.display());
        eprintln!("wrote {}", png_path.display());
    }
    Ok(())
}

/// Measure every stress atmosphere; also says which belong to the accuracy study.
fn measure_stress_suite(
    config: &StressConfig,
    dir: &std::path::Path,
    quiet: bool,
) -> anyhow::Result<(Vec<StressResult>, Vec<bool>)> {
    let suite = stress_suite();
    let runs = suite.len() * config.observers_m.len() * (config.tolerances_m.len() + 1);
    let bar = progress_bar(quiet, runs as u64);
    let mut results = Vec::new();
    for atmosphere in &suite {
        bar.set_message(atmosphere.name);
        results.push(measure_stress(atmosphere, dir, config, &mut || bar.inc(1))?);
    }
    bar.finish_and_clear();
    let study = suite.iter().map(|s| s.in_accuracy_study).collect();
    Ok((results, study))
}

fn measure_rays(
    cases: &[BenchCase],
    config: &AccuracyConfig,
    bar: &ProgressBar,
) -> anyhow::Result<Vec<CaseResult>> {
    let mut results = Vec::new();
    for case in cases {
        bar.set_message(format!("rays: {}", case.name));
        results.push(measure_case(case, config, &mut || bar.inc(1))?);
    }
    Ok(results)
}

fn measure_spectral(
    scenes: &[PaperScene],
    config: &FrameConfig,
    bar: &ProgressBar,
) -> anyhow::Result<Vec<SpectralTiming>> {
    let mut timings = Vec::new();
    for &size in &config.timing_sizes {
        for ps in scenes {
            bar.set_message(format!("spectral: {} at {}×{}", ps.name, size.0, size.1));
            timings.push(time_spectral(ps, size, config)?);
            bar.inc(1);
        }
    }
    Ok(timings)
}

fn measure_frames(
    scenes: &[PaperScene],
    config: &FrameConfig,
    bar: &ProgressBar,
) -> anyhow::Result<(Vec<FrameTiming>, Vec<SceneSweep>)> {
    let mut timings = Vec::new();
    for &size in &config.timing_sizes {
        for ps in scenes {
            bar.set_message(format!("frames: {} at {}×{}", ps.name, size.0, size.1));
            timings.push(time_scene(ps, size, config)?);
            bar.inc(1);
        }
    }
    let mut sweeps = Vec::new();
    for ps in scenes {
        bar.set_message(format!("tolerance sweep: {}", ps.name));
        sweeps.extend(sweep_scene(ps, config, &mut || bar.inc(1))?);
    }
    Ok((timings, sweeps))
}
