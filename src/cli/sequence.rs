//! `ghostship sequence`: a scene file and one sweep (`--sun-elevation-deg` or
//! `--observer-height-m`, FROM:TO:STEP) → [`SequenceRequest`] (the jobs layer renders the
//! frames) → `frame_0000.png` …, `sequence.gif` and `frames.csv` in `--out DIR`.

use std::path::PathBuf;
use std::time::Instant;

use ghostship::jobs::render::parse_size;
use ghostship::jobs::sequence::{SequenceSettings, SweepKind, parse_sweep};
use ghostship::jobs::{AtmosphereCache, SequenceRequest};
use ghostship::output::png::DEFAULT_EXPOSURE;
use ghostship::render::RenderOptions;
use ghostship::scene::Scene;

use super::render::{parse_exposure, parse_tolerance};

/// Arguments of `ghostship sequence`.
#[derive(Debug, clap::Args)]
pub struct SequenceArgs {
    /// The scene file (TOML; docs/scene.md). A sun sweep needs its `[sun]`.
    #[arg(value_name = "SCENE.toml")]
    pub scene: PathBuf,
    /// Output folder for frame_0000.png …, sequence.gif and frames.csv [default:
    /// out/sequence/<scene stem>].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Sweep the sun's true elevation, FROM:TO:STEP in degrees (e.g. -3:1:0.04 for 101 frames).
    /// The rays are traced once for the whole sweep; only the shading is per frame.
    #[arg(long, value_name = "FROM:TO:STEP", allow_hyphen_values = true,
          value_parser = |s: &str| parse_sweep(SweepKind::SunElevationDeg, s))]
    pub sun_elevation_deg: Option<ghostship::jobs::sequence::Sweep>,
    /// Sweep the camera's height above the surface, FROM:TO:STEP in metres (e.g. 5:120:5).
    #[arg(long, value_name = "FROM:TO:STEP", allow_hyphen_values = true,
          value_parser = |s: &str| parse_sweep(SweepKind::ObserverHeightM, s))]
    pub observer_height_m: Option<ghostship::jobs::sequence::Sweep>,
    /// Straight rays (n ≡ 1).
    #[arg(long)]
    pub straight: bool,
    /// Samples per pixel (a square number: 1, 4, 9, 16, …) [default: the scene's].
    #[arg(long, value_name = "N")]
    pub spp: Option<u32>,
    /// Frame size in pixels, WIDTHxHEIGHT (e.g. 400x200) [default: the scene's].
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// The ray tracer's error tolerance in metres (as `render`).
    #[arg(long, value_name = "M", value_parser = parse_tolerance,
          default_value_t = RenderOptions::default().tolerance_m)]
    pub tolerance_m: f64,
    /// PNG and GIF exposure (as `render`).
    #[arg(long, value_name = "X", value_parser = parse_exposure, default_value_t = DEFAULT_EXPOSURE)]
    pub exposure: f64,
}

/// Run `ghostship sequence`.
pub fn run(args: SequenceArgs, quiet: bool) -> anyhow::Result<()> {
    let sweep = match (args.sun_elevation_deg, args.observer_height_m) {
        (Some(sweep), None) | (None, Some(sweep)) => sweep,
        (Some(_), Some(_)) => anyhow::bail!(
            "give one sweep per run: --sun-elevation-deg or --observer-height-m, not both"
        ),
        (None, None) => anyhow::bail!(
            "give a sweep: --sun-elevation-deg FROM:TO:STEP or --observer-height-m FROM:TO:STEP"
        ),
    };
    let scene = Scene::from_file(&args.scene)?;
    let out = args.out.clone().unwrap_or_else(|| {
        let stem = args
            .scene
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "sequence".into());
        PathBuf::from("out").join("sequence").join(stem)
    });
    let request = SequenceRequest::new(
        scene,
        SequenceSettings {
            size: args.size,
            spp: args.spp,
            tolerance_m: args.tolerance_m,
            exposure: args.exposure,
            straight: args.straight,
            ..SequenceSettings::new(sweep)
        },
    )?;
    let start = Instant::now();
    let frames = request.render_frames(&AtmosphereCache::new())?;
    let render_s = start.elapsed().as_secs_f64();
    let products = request.products_of(&frames)?;
    super::write_into(&out, &products, true)?;
    if !quiet {
        eprintln!(
            "{} frames rendered in {:.0} ms; wrote {} files to {}",
            sweep.count,
            render_s * 1e3,
            products.len(),
            out.display()
        );
    }
    Ok(())
}
