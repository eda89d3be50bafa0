//! `ghostship bench accuracy`: arguments → an [`AccuracyConfig`] and the standard cases → measure
//! every case ([`ghostship::verify::accuracy`]) with a progress bar → write `BENCHMARKS.md` and
//! `docs/time_vs_error.png` under the output folder.
//!
//! `ghostship bench stress`: the stress suite's atmospheres → a [`StressConfig`] → measure each
//! ([`ghostship::verify::stress_report`]) with a progress bar → write `STRESS.md` and
//! `docs/stress_error_vs_tolerance.png` under the output folder.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Context;
use ghostship::output::write_atomic;
use ghostship::verify::accuracy::{
    AccuracyConfig, CaseResult, benchmarks_markdown, measure_case, standard_cases,
    time_vs_error_png,
};
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
    /// 26 km with a 1e-7 m reference run, time the rays; writes BENCHMARKS.md and
    /// docs/time_vs_error.png.
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
    /// Folder to write BENCHMARKS.md and docs/time_vs_error.png into.
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub out: PathBuf,
    /// Folder holding the paper atmospheres and shipped soundings.
    #[arg(long, value_name = "DIR", default_value = "data")]
    pub data: PathBuf,
    /// Rays in the fan (elevations −0.5°…0.5°). Default: 101 (21 with --quick).
    #[arg(long, value_name = "N")]
    pub rays: Option<usize>,
    /// A quick run: tolerances 1, 1e-2 and 1e-4 m only, 21 rays.
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
    let mut config = if args.quick {
        AccuracyConfig::quick()
    } else {
        AccuracyConfig::full()
    };
    if let Some(n) = args.rays {
        if !(3..=super::trace::MAX_RAYS).contains(&n) {
            anyhow::bail!("--rays {n}: give 3 to {} rays", super::trace::MAX_RAYS);
        }
        config.rays = n;
    }
    let stress_dir = std::env::temp_dir().join(format!("ghostship-stress-{}", std::process::id()));
    std::fs::create_dir_all(&stress_dir)
        .with_context(|| format!("cannot create {}", stress_dir.display()))?;
    let measured = measure_all(&args, &config, &stress_dir, quiet);
    let _ = std::fs::remove_dir_all(&stress_dir);
    let results = measured?;

    let mut command = String::from("ghostship bench accuracy");
    if args.quick {
        command.push_str(" --quick");
    }
    if let Some(n) = args.rays {
        command.push_str(&format!(" --rays {n}"));
    }
    let md_path = args.out.join("BENCHMARKS.md");
    let png_path = args.out.join("docs").join("time_vs_error.png");
    let md = benchmarks_markdown(&results, &config, &command, "docs/time_vs_error.png");
    let png = time_vs_error_png(&results, 1400, 900)?;
    write_atomic(&png_path, &png)?;
    write_atomic(&md_path, md.as_bytes())?;
    if !quiet {
        eprintln!("wrote {}", md_path.display());
        eprintln!("wrote {}", png_path.display());
    }
    Ok(())
}

/// A progress bar of `len` runs (hidden when quiet or not on a terminal).
fn progress_bar(len: usize, quiet: bool) -> ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len as u64);
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
    let bar = progress_bar(runs, quiet);
    let mut results = Vec::new();
    for atmosphere in &suite {
        bar.set_message(atmosphere.name);
        results.push(measure_stress(atmosphere, dir, config, &mut || bar.inc(1))?);
    }
    bar.finish_and_clear();
    let study = suite.iter().map(|s| s.in_accuracy_study).collect();
    Ok((results, study))
}

fn measure_all(
    args: &AccuracyArgs,
    config: &AccuracyConfig,
    stress_dir: &std::path::Path,
    quiet: bool,
) -> anyhow::Result<Vec<CaseResult>> {
    let cases = standard_cases(&args.data, stress_dir)?;
    let bar = progress_bar(cases.len() * (config.tolerances_m.len() + 1), quiet);
    let mut results = Vec::new();
    for case in &cases {
        bar.set_message(case.name.clone());
        results.push(measure_case(case, config, &mut || bar.inc(1))?);
    }
    bar.finish_and_clear();
    Ok(results)
}
