//! `ghostship sequence`: a scene file and one sweep (`--sun-elevation-deg`,
//! `--observer-height-m` or `--sweep KEY=…`, FROM:TO:STEP; `--time-utc FROM/TO` for the sun's
//! position; `--to-sounding FILE` for the air between two soundings) → [`SequenceRequest`] (the
//! jobs layer renders the frames) → `frame_0000.png` …, `sequence.gif`, `frames.csv` and plots
//! in `--out DIR`.

use std::path::PathBuf;
use std::time::Instant;

use ghostship::jobs::render::parse_size;
use ghostship::jobs::sequence::{
    SequenceSettings, SweepKind, SweepSpec, TimeSpan, parse_key_sweep, parse_sweep,
};
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
    /// Output folder for frame_0000.png …, sequence.gif, frames.csv and plots [default:
    /// out/sequence/<scene stem>].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Sweep the sun's true elevation, FROM:TO:STEP in degrees (e.g. -3:1:0.04 for 101 frames).
    /// The rays are traced once for the whole sweep; only the shading is per frame.
    #[arg(long, value_name = "FROM:TO:STEP", allow_hyphen_values = true,
          value_parser = |s: &str| parse_sweep(SweepKind::SunElevationDeg, s))]
    pub sun_elevation_deg: Option<SweepSpec>,
    /// Sweep the camera's height above the surface, FROM:TO:STEP in metres (e.g. 5:120:5).
    #[arg(long, value_name = "FROM:TO:STEP", allow_hyphen_values = true,
          value_parser = |s: &str| parse_sweep(SweepKind::ObserverHeightM, s))]
    pub observer_height_m: Option<SweepSpec>,
    /// Sweep any numeric scene key, KEY=FROM:TO:STEP in the key's unit (e.g.
    /// cards[0].distance_m=10000:60000:5000, camera.heading_deg=-5:5:0.5). Each frame is the
    /// scene file with that key set.
    #[arg(long, value_name = "KEY=FROM:TO:STEP", allow_hyphen_values = true,
          value_parser = parse_key_sweep)]
    pub sweep: Option<SweepSpec>,
    /// Sweep the sun's true position over a UTC time span FROM/TO (e.g.
    /// 2026-02-12T11:00Z/2026-02-12T15:00Z) in steps of --step-min, by NREL's solar position
    /// algorithm at --lat-deg/--lon-deg (default: the scene's terrain observer, else its
    /// sounding's station). The rays are traced once for the whole sweep.
    #[arg(long, value_name = "FROM/TO", requires = "step_min")]
    pub time_utc: Option<String>,
    /// Minutes between frames of --time-utc or --to-sounding.
    #[arg(long, value_name = "MIN")]
    pub step_min: Option<f64>,
    /// The observer's latitude for --time-utc, degrees north.
    #[arg(
        long,
        value_name = "DEG",
        allow_hyphen_values = true,
        requires = "lon_deg"
    )]
    pub lat_deg: Option<f64>,
    /// The observer's longitude for --time-utc, degrees east.
    #[arg(
        long,
        value_name = "DEG",
        allow_hyphen_values = true,
        requires = "lat_deg"
    )]
    pub lon_deg: Option<f64>,
    /// With --time-utc: turn the camera to the sun's azimuth in every frame.
    #[arg(long)]
    pub follow_sun: bool,
    /// Sweep the air from the scene's sounding to this later sounding of the same station,
    /// interpolated linearly in time at fixed heights, in steps of --step-min.
    #[arg(long, value_name = "SOUNDING", requires = "step_min")]
    pub to_sounding: Option<PathBuf>,
    /// Which sounding of a multi-sounding --to-sounding file (IGRA2, Wyoming page):
    /// "YYYY-MM-DD HH" (UTC).
    #[arg(long, value_name = "YYYY-MM-DD HH", requires = "to_sounding")]
    pub to_sounding_time: Option<String>,
    /// Also write every frame as EXR (linear radiance, with provenance).
    #[arg(long)]
    pub exr: bool,
    /// Also write sequence.mp4 when ffmpeg is on the PATH (otherwise a note says it was skipped).
    #[arg(long)]
    pub mp4: bool,
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

/// The one sweep the arguments ask for.
fn sweep_of(args: &SequenceArgs) -> anyhow::Result<SweepSpec> {
    let mut given: Vec<SweepSpec> = Vec::new();
    given.extend(args.sun_elevation_deg.clone());
    given.extend(args.observer_height_m.clone());
    given.extend(args.sweep.clone());
    let step_min = args.step_min.unwrap_or(f64::NAN);
    if let Some(span) = &args.time_utc {
        given.push(SweepSpec::SunTime {
            span: TimeSpan::parse(span, step_min).map_err(anyhow::Error::msg)?,
            lat_lon_deg: args.lat_deg.zip(args.lon_deg),
            follow_sun: args.follow_sun,
        });
    }
    if let Some(to) = &args.to_sounding {
        given.push(SweepSpec::Soundings {
            to: to.clone(),
            to_time: args.to_sounding_time.clone(),
            step_min,
        });
    }
    if args.time_utc.is_none() && (args.follow_sun || args.lat_deg.is_some()) {
        anyhow::bail!("--follow-sun, --lat-deg and --lon-deg go with --time-utc");
    }
    match given.len() {
        1 => Ok(given.remove(0)),
        0 => anyhow::bail!(
            "give a sweep: --sun-elevation-deg, --observer-height-m or --sweep KEY= with \
             FROM:TO:STEP, --time-utc FROM/TO or --to-sounding FILE (with --step-min)"
        ),
        _ => anyhow::bail!(
            "give one sweep per run: one of --sun-elevation-deg, --observer-height-m, --sweep, \
             --time-utc and --to-sounding"
        ),
    }
}

/// Run `ghostship sequence`.
pub fn run(args: SequenceArgs, quiet: bool) -> anyhow::Result<()> {
    let sweep = sweep_of(&args)?;
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
            exr: args.exr,
            mp4: args.mp4,
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
            request.frame_count(),
            render_s * 1e3,
            products.len(),
            out.display()
        );
    }
    Ok(())
}
