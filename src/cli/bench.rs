//! `ghostship bench accuracy`: arguments → an [`AccuracyConfig`] and the standard cases → measure
//! every case ([`ghostship::verify::accuracy`]) with a progress bar → write `BENCHMARKS.md` and
//! `docs/time_vs_error.png` under the output folder.

use std::io::IsTerminal;
use std::path::PathBuf;

use anyhow::Context;
use ghostship::output::write_atomic;
use ghostship::verify::accuracy::{
    AccuracyConfig, CaseResult, benchmarks_markdown, measure_case, standard_cases,
    time_vs_error_png,
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

fn measure_all(
    args: &AccuracyArgs,
    config: &AccuracyConfig,
    stress_dir: &std::path::Path,
    quiet: bool,
) -> anyhow::Result<Vec<CaseResult>> {
    let cases = standard_cases(&args.data, stress_dir)?;
    let bar = if quiet || !std::io::stderr().is_terminal() {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::new((cases.len() * (config.tolerances_m.len() + 1)) as u64);
        if let Ok(style) =
            ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs  {msg}")
        {
            bar.set_style(style);
        }
        bar
    };
    let mut results = Vec::new();
    for case in &cases {
        bar.set_message(case.name.clone());
        results.push(measure_case(case, config, &mut || bar.inc(1))?);
    }
    bar.finish_and_clear();
    Ok(results)
}
