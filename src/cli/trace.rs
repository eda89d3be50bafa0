//! `ghostship trace`: arguments → [`TraceJobRequest`] → load the atmosphere, trace the fan (the
//! jobs layer), print the report (JSON or CSV) on stdout and optionally write the fan +
//! transfer plot; with `--ensemble N` also the sensitivity ensemble (its section in the JSON,
//! its summary on stderr).

use std::path::PathBuf;

use ghostship::jobs::trace::{ElevationSpec, parse_elevation_spec, trace_json};
use ghostship::jobs::{AtmosphereCache, Product, TraceJobRequest};
use ghostship::tracer::TracerConfig;

use super::profile::AtmosphereArgs;

/// How the report is printed on stdout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TraceFormat {
    /// The whole report: rays, images, horizons, trapped rays.
    Json,
    /// One row per ray of the fan, with its height at every distance.
    Csv,
}

/// Arguments of `ghostship trace`.
#[derive(Debug, clap::Args)]
pub struct TraceArgs {
    /// The atmosphere: a sounding file, a synthetic layered atmosphere (*.toml) or `us1976`.
    #[arg(long, short, value_name = "SOUNDING|ATMOSPHERE.toml|us1976")]
    pub atmosphere: String,
    /// Observer (eye) height in metres above the atmosphere's surface level.
    #[arg(long, value_name = "M")]
    pub observer_height_m: f64,
    /// Apparent elevations of the rays, in degrees: one value (0.5), a comma-separated list in
    /// strictly ascending order (-0.1,0,0.25; refused if out of order), or a fan FROM:TO:STEP
    /// (-0.4:0.6:0.001: rays at FROM, FROM+STEP, … up to TO). 1 to 100 000 rays. Every ray is
    /// reported; images and apparent horizons need a fan of at least 3 rays (with fewer, the
    /// JSON has empty `images` and `horizons` and says so in `notes`).
    #[arg(
        long,
        value_name = "DEG|DEG,DEG,...|FROM:TO:STEP",
        allow_hyphen_values = true,
        value_parser = parse_elevation_spec
    )]
    pub elevation_deg: ElevationSpec,
    /// Ground distances of the targets in metres, comma-separated (heights of every ray are
    /// reported there; images are searched there).
    #[arg(long, value_name = "M,...", value_delimiter = ',', default_values_t = [10_000.0, 20_000.0, 30_000.0])]
    pub distance_m: Vec<f64>,
    /// Heights of the targets standing at every distance, in metres, comma-separated: the images
    /// of [0, H] are found (erect or inverted, with magnification).
    #[arg(long, value_name = "M,...", value_delimiter = ',', default_values_t = [20.0])]
    pub target_height_m: Vec<f64>,
    /// Error tolerance on the ray heights at the requested distances, in metres (the paper used
    /// 1 cm per step; the default 1 mm is the knee of the time-against-error curve, see
    /// BENCHMARKS.md).
    #[arg(long, value_name = "M", default_value_t = 1e-3)]
    pub tolerance_m: f64,
    /// How to build the atmosphere.
    #[command(flatten)]
    pub atmosphere_options: AtmosphereArgs,
    /// Top of the atmosphere in metres above the surface: rays above it have escaped.
    #[arg(long, value_name = "M", default_value_t = 40_000.0)]
    pub top_m: f64,
    /// Safety limit on a ray's ground distance, in metres (default: none). Rays are traced to
    /// the ground or the top; one that provably oscillates in a duct past the last target
    /// distance ends `trapped` (Bouguer's invariant). A ray stopped at this limit ends
    /// `max_distance`, its fate undecided.
    #[arg(long, value_name = "M")]
    pub max_distance_m: Option<f64>,
    /// Straight rays: refractive index 1 everywhere (no refraction), for comparison.
    #[arg(long)]
    pub straight: bool,
    /// Sensitivity ensemble of N profiles (measured soundings only; at most 500): the temperature
    /// between the sounding's levels is moved within ±1 K of the fit (significant-level bound),
    /// the fan traced through each, and the spread of the images, the sea horizon and the ducts
    /// reported (an `ensemble` section in the JSON, a summary on stderr).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub ensemble: usize,
    /// Output on stdout.
    #[arg(long, value_enum, default_value_t = TraceFormat::Json)]
    pub format: TraceFormat,
    /// Also draw the ray fan and the transfer curves into this PNG file (a relative path is
    /// relative to the current folder).
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
}

/// Run `ghostship trace`.
pub fn run(args: TraceArgs, quiet: bool) -> anyhow::Result<()> {
    let tracer = TracerConfig {
        tolerance_m: args.tolerance_m,
        top_m: args.top_m,
        max_distance_m: args.max_distance_m,
        ..TracerConfig::default()
    };
    let request = TraceJobRequest::new(
        args.atmosphere_options.request(&args.atmosphere),
        args.observer_height_m,
        &args.elevation_deg,
        args.distance_m,
        args.target_height_m,
        tracer,
        args.straight,
    )?
    .with_ensemble(args.ensemble)?;
    let atm = AtmosphereCache::new().get(&request.atmosphere)?;
    let (report, png) = request.report(&atm, args.plot.is_some())?;
    let ensemble = request.ensemble_report(&atm, &report)?;
    if let Some(e) = ensemble.as_ref().filter(|_| !quiet) {
        eprintln!("{}", e.summary.join("\n"));
    }
    let text = match args.format {
        TraceFormat::Json => trace_json(&report, ensemble.as_ref())? + "\n",
        TraceFormat::Csv => String::from_utf8_lossy(&report.rays_csv()?).into_owned(),
    };
    super::print_stdout(&text)?;
    if let (Some(path), Some(png)) = (&args.plot, png) {
        super::write_files(&[(path.clone(), Product::new("trace.png", png))], quiet)?;
    }
    Ok(())
}
