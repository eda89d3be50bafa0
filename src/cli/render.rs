//! `ghostship render`: a scene file → [`RenderRequest`] (the jobs layer: its atmosphere loaded
//! like every other command's, the ray tracer the scene asks for) → a film → the PNG and/or EXR
//! files named by `-o` (the format follows each file's extension).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use ghostship::jobs::render::{RenderSettings, parse_size};
use ghostship::jobs::{AtmosphereCache, RenderRequest};
use ghostship::output::film::{ImageFormat, encode_film};
use ghostship::output::png::DEFAULT_EXPOSURE;
use ghostship::output::{StagedFile, commit_staged};
use ghostship::render::{RenderOptions, check_tracer_tolerance};
use ghostship::scene::Scene;
use rayon::prelude::*;

/// `-o FILE`: a path whose extension names a known image format.
fn parse_output(text: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(text);
    match ImageFormat::from_path(&path) {
        Some(_) => Ok(path),
        None => Err(format!(
            "{text}: unknown image format (use a .png or .exr file name)"
        )),
    }
}

/// `--tolerance-m`: within the tracer's accepted range.
pub(super) fn parse_tolerance(text: &str) -> Result<f64, String> {
    let v: f64 = text
        .parse()
        .map_err(|_| format!("{text:?} is not a number"))?;
    check_tracer_tolerance(v).map_err(|e| e.to_string())?;
    Ok(v)
}

/// `--exposure`: finite and > 0.
pub(super) fn parse_exposure(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{text:?} is not a finite number > 0")),
    }
}

/// Arguments of `ghostship render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// The scene file (TOML; every key, unit, default and range: docs/scene.md).
    #[arg(value_name = "SCENE.toml")]
    pub scene: PathBuf,
    /// Output files; the format follows the extension: `.png` (8-bit sRGB) or `.exr` (linear f32
    /// RGBA with provenance). Repeatable. Relative paths are relative to the current folder
    /// [default: out/render/<scene stem>.png and .exr].
    #[arg(short = 'o', long = "output", value_name = "FILE", value_parser = parse_output)]
    pub outputs: Vec<PathBuf>,
    /// Trace every pixel sample's ray with the full 3-D integrator (the paper's method; slow —
    /// it validates the fast elevation-fan path).
    #[arg(long)]
    pub exact: bool,
    /// Straight rays (n ≡ 1): the horizon and cards without any refraction.
    #[arg(long)]
    pub straight: bool,
    /// Samples per pixel (a square number: 1, 4, 9, 16, …) [default: the scene's].
    #[arg(long, value_name = "N")]
    pub spp: Option<u32>,
    /// Image size in pixels, WIDTHxHEIGHT (e.g. 1920x1080) [default: the scene's]. The
    /// horizontal field of view stays; the vertical one follows the aspect ratio.
    #[arg(long, value_name = "WxH", value_parser = parse_size)]
    pub size: Option<(u32, u32)>,
    /// The ray tracer's error tolerance on the ray heights at the card distances, in metres (from
    /// 1e-6 to 10; default 1 mm; the paper used 1 cm per step). Recorded in the EXR provenance.
    /// Smaller is slower; straight rays (closed form) ignore it.
    #[arg(long, value_name = "M", value_parser = parse_tolerance,
          default_value_t = RenderOptions::default().tolerance_m)]
    pub tolerance_m: f64,
    /// PNG exposure: linear radiance (1 = the white horizon sky) is multiplied by this before the
    /// sRGB transfer function and 8-bit quantisation. EXR files are never scaled.
    #[arg(long, value_name = "X", value_parser = parse_exposure, default_value_t = DEFAULT_EXPOSURE)]
    pub exposure: f64,
}

/// Run `ghostship render`.
pub fn run(args: RenderArgs, quiet: bool) -> anyhow::Result<()> {
    let scene = Scene::from_file(&args.scene)?;
    let outputs = if args.outputs.is_empty() {
        let stem = args
            .scene
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "render".into());
        let dir = Path::new("out").join("render");
        vec![
            dir.join(format!("{stem}.png")),
            dir.join(format!("{stem}.exr")),
        ]
    } else {
        // A file named twice is written once.
        let mut unique: Vec<PathBuf> = Vec::with_capacity(args.outputs.len());
        for path in &args.outputs {
            if !unique.contains(path) {
                unique.push(path.clone());
            }
        }
        unique
    };
    let request = RenderRequest::new(
        scene,
        RenderSettings {
            sizes: vec![args.size],
            spp: args.spp,
            tolerance_m: args.tolerance_m,
            exposure: args.exposure,
            exact: args.exact,
            straight: args.straight,
            ..RenderSettings::default()
        },
    )?;
    let atmosphere = match &request.atmosphere {
        Some(a) => Some(AtmosphereCache::new().get(a)?),
        None => None,
    };
    if !quiet {
        // The same notes `profile` prints (skipped rows, suspect steps, ...).
        for w in atmosphere.iter().filter_map(|a| a.sounding.as_ref()) {
            for note in &w.warnings {
                eprintln!("Ingest note: {note}");
            }
        }
    }
    let start = Instant::now();
    let (film, meta) = request
        .film(args.size, atmosphere.as_deref(), quiet)
        .with_context(|| format!("cannot render {}", args.scene.display()))?;
    let render_s = start.elapsed().as_secs_f64();
    // Each output is encoded and written to its temporary file (flushed to disk) in parallel,
    // as soon as it is ready — the PNG's disk flush overlaps the EXR's encoding — and all are
    // renamed into place together once every one is written (none if any fails).
    let staged = outputs
        .par_iter()
        .map(|path| {
            let format = ImageFormat::from_path(path).unwrap_or(ImageFormat::Png);
            let bytes = encode_film(&film, format, &meta, args.exposure)?;
            Ok(StagedFile::write(path, &bytes)?)
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    commit_staged(staged, &[])?;
    if !quiet {
        for path in &outputs {
            eprintln!("wrote {}", path.display());
        }
    }
    if !quiet {
        eprintln!(
            "{}x{} in {:.0} ms ({} fan rays{}{}{})",
            film.width,
            film.height,
            render_s * 1e3,
            film.stats.fan_rays,
            if args.exact {
                format!(", {} per-sample rays", film.stats.sample_rays)
            } else {
                String::new()
            },
            match film.stats.sun_rays {
                0 => String::new(),
                n => format!(", {n} sun paths"),
            },
            match film.stats.air_path_rays {
                0 => String::new(),
                n => format!(", {n} haze paths"),
            }
        );
    }
    Ok(())
}
