//! `ghostship survey`: arguments → [`SurveyRequest`] → its rows and products (through the jobs
//! layer) → a summary on stdout and `survey.csv`, `survey.parquet`, `survey.json` and the plots
//! in the output folder.

use std::path::PathBuf;

use ghostship::atmosphere::AtmosphereOptions;
use ghostship::jobs::SurveyRequest;
use ghostship::jobs::survey::SURVEY_FILES;
use ghostship::survey::sources::DateRange;
use ghostship::survey::{SurveyError, SurveyOptions};
use indicatif::{ProgressBar, ProgressStyle};

use super::profile::parse_fit;

/// Arguments of `ghostship survey`.
#[derive(Debug, clap::Args)]
pub struct SurveyArgs {
    /// Sounding sources: files (an IGRA2 data or derived record — every sounding in it — a
    /// Wyoming TEXT:LIST page, any single sounding), folders (every file in them except *.md)
    /// or quoted glob patterns ("archive/*.txt").
    #[arg(value_name = "SOURCE", required = true)]
    pub sources: Vec<PathBuf>,
    /// Observer heights above the surface in metres, comma-separated.
    #[arg(long, value_name = "M,...", value_delimiter = ',', default_values_t = [10.0])]
    pub observer_height_m: Vec<f64>,
    /// Target distances in metres, comma-separated.
    #[arg(long, value_name = "M,...", value_delimiter = ',', default_values_t = [20_000.0])]
    pub distance_m: Vec<f64>,
    /// Height of the target (a ship's mast) in metres.
    #[arg(long, value_name = "M", default_value_t = 20.0)]
    pub target_height_m: f64,
    /// Keep soundings from this day on (YYYY-MM-DD, nominal time).
    #[arg(long, value_name = "YYYY-MM-DD")]
    pub from: Option<String>,
    /// Keep soundings up to this day (YYYY-MM-DD, inclusive).
    #[arg(long, value_name = "YYYY-MM-DD")]
    pub to: Option<String>,
    /// Inversions and ducts are searched up to this many metres above the surface.
    #[arg(long, value_name = "M", default_value_t = SurveyOptions::default().layers_top_m)]
    pub layers_top_m: f64,
    /// Tracer tolerance in metres.
    #[arg(long, value_name = "M", default_value_t = SurveyOptions::default().tolerance_m)]
    pub tolerance_m: f64,
    /// Spacing of the ray fan in degrees (the lowest visible sun is resolved to it).
    #[arg(long, value_name = "DEG", default_value_t = SurveyOptions::default().fan_step_deg)]
    pub fan_step_deg: f64,
    /// Smoothing scale of the sounding fit, in metres.
    #[arg(long, value_name = "M", default_value_t = 20.0)]
    pub smooth_m: f64,
    /// Temperature between sounding levels: pchip, linear or auto.
    #[arg(long, value_name = "pchip|linear|auto", default_value = "auto", value_parser = parse_fit)]
    pub fit: ghostship::profile::TemperatureFit,
    /// Vacuum wavelength for the refractive index, in nanometres (300–1700).
    #[arg(long, value_name = "NM", default_value_t = ghostship::refractivity::DEFAULT_WAVELENGTH_NM)]
    pub wavelength_nm: f64,
    /// A sounding whose levels contradict each other within 3 km of its lowest level is unusable
    /// (its row says why) instead of having those levels dropped with a note.
    #[arg(long)]
    pub strict: bool,
    /// Survey only the K-th of N contiguous runs of the soundings (every file is still read, to
    /// number them) and add part.json; join the N folders with `ghostship survey-merge`.
    #[arg(long, value_name = "K/N")]
    pub shard: Option<ghostship::jobs::manifest::Shard>,
    /// Output folder [default: out/survey].
    #[arg(long, value_name = "DIR", default_value = "out/survey")]
    pub out: PathBuf,
}

impl SurveyArgs {
    /// The validated request.
    pub fn request(&self) -> anyhow::Result<SurveyRequest> {
        let options = SurveyOptions {
            observer_heights_m: self.observer_height_m.clone(),
            distances_m: self.distance_m.clone(),
            target_height_m: self.target_height_m,
            atmosphere: AtmosphereOptions {
                smooth_m: self.smooth_m,
                fit: self.fit,
                wavelength_nm: self.wavelength_nm,
                strict: self.strict,
                ..AtmosphereOptions::default()
            },
            layers_top_m: self.layers_top_m,
            tolerance_m: self.tolerance_m,
            fan_step_deg: self.fan_step_deg,
            ..SurveyOptions::default()
        };
        let dates = DateRange {
            from: self.from.clone(),
            to: self.to.clone(),
        };
        let request = SurveyRequest::new(self.sources.clone(), dates, options).map_err(|e| {
            // Name the flag: the library names the pipeline key.
            let key = match &e {
                ghostship::jobs::JobError::Survey(SurveyError::BadOption { key, .. }) => *key,
                _ => "",
            };
            let flag = match key {
                "" => return anyhow::Error::new(e),
                "observer_height_m" => "observer-height-m".to_string(),
                "distances_m" => "distance-m".to_string(),
                k => k.replace('_', "-"),
            };
            anyhow::Error::new(e).context(format!("--{flag}"))
        })?;
        Ok(match self.shard {
            Some(shard) => request.with_shard(shard),
            None => request,
        })
    }
}

/// Run `ghostship survey`.
pub fn run(args: SurveyArgs, quiet: bool) -> anyhow::Result<()> {
    let request = args.request()?;
    let progress = if quiet {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::new(0);
        bar.set_style(
            ProgressStyle::with_template(
                "surveying {bar:40} {pos}/{len} soundings, {per_sec}, ETA {eta}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar
    };
    let start = std::time::Instant::now();
    let outcome = request.run(&progress)?;
    progress.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    let products = request.products(&outcome)?;
    let rows = &outcome.rows;
    let usable = rows.iter().filter(|r| r.unusable.is_none()).count();
    let mut text = if rows.is_empty() {
        "Surveyed 0 soundings: no sounding of the sources is within the dates asked for\n".into()
    } else {
        format!(
            "Surveyed {} soundings ({usable} usable) in {seconds:.2} s ({:.1} ms per sounding)\n",
            rows.len(),
            1e3 * seconds / rows.len() as f64
        )
    };
    for row in rows.iter().filter(|r| r.unusable.is_some()) {
        let reason = row.unusable.as_deref().unwrap_or_default();
        text.push_str(&format!("unusable: {}: {reason}\n", row.origin));
    }
    super::print_stdout(&text)?;
    write_survey(&args.out, &products, quiet)
}

/// Write a survey's products into `dir`, deleting the survey files of an earlier run there that
/// this one does not write (an unsplit survey into a part's folder leaves no `part.json`).
fn write_survey(
    dir: &std::path::Path,
    products: &[ghostship::jobs::Product],
    quiet: bool,
) -> anyhow::Result<()> {
    ghostship::jobs::writer::replace_products_in(dir, products, SURVEY_FILES)?;
    if !quiet {
        for product in products {
            eprintln!("wrote {}", dir.join(&product.name).display());
        }
    }
    Ok(())
}

/// Arguments of `ghostship survey-merge`.
#[derive(Debug, clap::Args)]
pub struct SurveyMergeArgs {
    /// The folders of the parts (`ghostship survey --shard K/N` outputs, or a pipeline's
    /// `<name>_part_K_of_N` jobs), in any order.
    #[arg(value_name = "PART_DIR", required = true)]
    pub parts: Vec<PathBuf>,
    /// Output folder for the joined survey.
    #[arg(long, value_name = "DIR", default_value = "out/survey")]
    pub out: PathBuf,
}

/// Run `ghostship survey-merge`.
pub fn merge(args: SurveyMergeArgs, quiet: bool) -> anyhow::Result<()> {
    // The joined survey would mix with (and delete the part.json of) a part in its folder.
    let out = std::fs::canonicalize(&args.out).ok();
    if let Some(part) = args
        .parts
        .iter()
        .find(|p| out.is_some() && std::fs::canonicalize(p).ok() == out)
    {
        anyhow::bail!(
            "--out {} is one of the parts ({}); give the joined survey a folder of its own",
            args.out.display(),
            part.display()
        );
    }
    let products = ghostship::jobs::survey::merge_parts(&args.parts)?;
    write_survey(&args.out, &products, quiet)
}
