//! `ghostship compare`: a measured sounding, an optional synthetic atmosphere and a scene →
//! [`CompareRequest`] (the jobs layer fits the synthetic layers when none is given, traces and
//! renders both) → the comparison summary on stdout and its files in the output folder.

use std::path::{Path, PathBuf};

use ghostship::atmosphere::AtmosphereSource;
use ghostship::jobs::compare::{CompareOptions, DEFAULT_COMPARE_RAYS, LayerShape};
use ghostship::jobs::render::{RenderSettings, parse_size};
use ghostship::jobs::{AtmosphereCache, CompareRequest};
use ghostship::output::png::DEFAULT_EXPOSURE;
use ghostship::render::RenderOptions;
use ghostship::scene::Scene;

use super::render::{parse_exposure, parse_tolerance};

/// How the summary is printed on stdout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum CompareFormat {
    /// Readable text: the fit, images of each target side by side, horizons, differences.
    Table,
    /// The content of compare.json.
    Json,
}

/// Arguments of `ghostship compare`.
#[derive(Debug, clap::Args)]
pub struct CompareArgs {
    /// The measured sounding (any format `profile` reads).
    #[arg(value_name = "MEASURED")]
    pub measured: PathBuf,
    /// The synthetic atmosphere to compare with (a layered `.toml` or `us1976`) [default: the
    /// paper-style layers fitted to MEASURED from the surface to +3000 m, written as
    /// fitted_layers.toml].
    #[arg(value_name = "SYNTHETIC")]
    pub synthetic: Option<String>,
    /// The scene both atmospheres are rendered through (its camera, cards, sun; its own
    /// atmosphere is replaced). Its cards are the targets whose images are compared.
    #[arg(long, value_name = "SCENE.toml")]
    pub scene: PathBuf,
    /// Output folder [default: out/compare/<measured stem>/].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Which sounding of a file holding several (IGRA2, a Wyoming page): "YYYY-MM-DD HH".
    #[arg(long = "time", visible_aliases = ["sounding-time"], value_name = "YYYY-MM-DD HH")]
    pub sounding_time: Option<String>,
    /// Smoothing scale of the sounding fit, in metres (0 = none) [default: the scene's, 20 m].
    #[arg(long, value_name = "M")]
    pub smooth_m: Option<f64>,
    /// Temperature fit between the sounding's levels: pchip, linear (in ln p) or auto (linear
    /// for significant-level soundings, PCHIP for dense ascents) [default: the scene's, auto].
    #[arg(long, value_name = "pchip|linear|auto", value_parser = super::profile::parse_fit)]
    pub fit: Option<ghostship::profile::TemperatureFit>,
    /// Image size, WIDTHxHEIGHT [default: the scene's].
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// Samples per pixel (a square number) [default: the scene's].
    #[arg(long, value_name = "N")]
    pub spp: Option<u32>,
    /// The ray tracer's tolerance, in metres (1e-6 to 10).
    #[arg(long, value_name = "M", value_parser = parse_tolerance,
          default_value_t = RenderOptions::default().tolerance_m)]
    pub tolerance_m: f64,
    /// PNG exposure (also the tone map the image metrics are computed on).
    #[arg(long, value_name = "X", value_parser = parse_exposure, default_value_t = DEFAULT_EXPOSURE)]
    pub exposure: f64,
    /// Form of the layers fitted when no SYNTHETIC is given: smooth (the paper's form: a lapse
    /// rate and one tanh layer per detected inversion) or linear (up to 10 constant-gradient
    /// layers, a closer fit to dense ascents).
    #[arg(long, value_enum, default_value_t = LayerShape::Smooth)]
    pub layers: LayerShape,
    /// Rays of the fan traced across the camera's vertical field for the image analysis.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_COMPARE_RAYS)]
    pub rays: usize,
    /// Summary printed on stdout.
    #[arg(long, value_enum, default_value_t = CompareFormat::Table)]
    pub format: CompareFormat,
}

/// Run `ghostship compare`.
pub fn run(args: CompareArgs, quiet: bool) -> anyhow::Result<()> {
    let scene = Scene::from_file(&args.scene)?;
    let settings = RenderSettings {
        sizes: vec![args.size],
        spp: args.spp,
        tolerance_m: args.tolerance_m,
        exposure: args.exposure,
        ..RenderSettings::default()
    };
    let request = CompareRequest::new(
        scene,
        AtmosphereSource::parse(&args.measured.to_string_lossy()),
        args.synthetic.as_deref().map(AtmosphereSource::parse),
        settings,
        &CompareOptions {
            sounding_time: args.sounding_time.clone(),
            smooth_m: args.smooth_m,
            fit: args.fit,
            rays: args.rays,
            layers: args.layers,
        },
    )?;
    let out_dir = args.out.clone().unwrap_or_else(|| {
        Path::new("out")
            .join("compare")
            .join(request.measured.source.stem())
    });
    let outcome = request.outcome(&AtmosphereCache::new())?;
    let text = match args.format {
        CompareFormat::Table => outcome.comparison.summary_text(),
        CompareFormat::Json => format!("{}\n", serde_json::to_string_pretty(&outcome.comparison)?),
    };
    super::print_stdout(&text)?;
    super::write_into(&out_dir, &outcome.into_products()?, quiet)
}
