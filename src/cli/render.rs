//! `ghostship render`: a scene file → [`Scene`] → its atmosphere (loaded like every other
//! command's) → the ray tracer the scene asks for → [`Film`] → PNG and/or EXR files.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use ghostship::atmosphere::load_scene_atmosphere;
use ghostship::output::film::{FilmFormat, write_films};
use ghostship::output::png::DEFAULT_EXPOSURE;
use ghostship::pipeline::parse_size;
use ghostship::render::{
    Film, RenderOptions, check_tracer_tolerance, prepare_tracer, provenance, render_scene,
};
use ghostship::scene::Scene;

/// Arguments of `ghostship render`.
#[derive(Debug, clap::Args)]
pub struct RenderArgs {
    /// The scene file (TOML: camera, atmosphere, earth, sky, sea, cards, sun).
    #[arg(value_name = "SCENE.toml")]
    pub scene: PathBuf,
    /// Output files; the format follows the extension: `.png` (8-bit sRGB) or `.exr` (linear f32
    /// RGBA with provenance). Repeatable [default: out/render/<scene stem>.png and .exr].
    #[arg(short = 'o', long = "output", value_name = "FILE")]
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
    #[arg(long, value_name = "WxH")]
    pub size: Option<String>,
    /// The ray tracer's error tolerance on the ray heights at the card distances, in metres (from
    /// 1e-6 to 10; default 1 mm; the paper used 1 cm per step). Recorded in the EXR provenance. Smaller is slower; straight rays (closed
    /// form) ignore it.
    #[arg(long, value_name = "M", default_value_t = ghostship::render::RenderOptions::default().tolerance_m)]
    pub tolerance_m: f64,
    /// PNG exposure: linear radiance (1 = the white horizon sky) is multiplied by this before the
    /// sRGB transfer function and 8-bit quantisation. EXR files are never scaled.
    #[arg(long, value_name = "X", default_value_t = DEFAULT_EXPOSURE)]
    pub exposure: f64,
}

/// Run `ghostship render`.
pub fn run(args: RenderArgs, quiet: bool) -> anyhow::Result<()> {
    let mut scene = Scene::from_file(&args.scene)?;
    if args.straight {
        scene.atmosphere.straight = true;
    }
    if let Some(size) = &args.size {
        let (width, height) = parse_size(size).map_err(|e| anyhow::anyhow!("--size: {e}"))?;
        scene.camera.width = width;
        scene.camera.height = height;
    }
    if !(args.exposure.is_finite() && args.exposure > 0.0) {
        anyhow::bail!(
            "--exposure must be a finite number > 0, got {}",
            args.exposure
        );
    }
    check_tracer_tolerance(args.tolerance_m).map_err(|e| anyhow::anyhow!("--tolerance-m: {e}"))?;
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
        args.outputs.clone()
    };
    for path in &outputs {
        if FilmFormat::from_path(path).is_none() {
            anyhow::bail!(
                "output {}: unknown image format (use a .png or .exr file name)",
                path.display()
            );
        }
    }
    let options = RenderOptions {
        exact: args.exact,
        samples_per_pixel: args.spp,
        quiet,
        tolerance_m: args.tolerance_m,
        ..RenderOptions::default()
    };
    let start = Instant::now();
    let film = render_film(&scene, &options)
        .with_context(|| format!("cannot render {}", args.scene.display()))?;
    let render_s = start.elapsed().as_secs_f64();
    let meta = provenance(&scene, &options);
    // PNG and EXR are encoded (and written) in parallel.
    write_films(&film, &outputs, &meta, args.exposure)?;
    if !quiet {
        for path in &outputs {
            eprintln!("wrote {}", path.display());
        }
    }
    if !quiet {
        eprintln!(
            "{}x{} in {:.0} ms ({} fan rays{})",
            film.width,
            film.height,
            render_s * 1e3,
            film.stats.fan_rays,
            if options.exact {
                format!(", {} per-sample rays", film.stats.sample_rays)
            } else {
                String::new()
            }
        );
    }
    Ok(())
}

/// Resolve the scene's atmosphere (unless it asks for straight rays), choose the tracer and
/// render. Shared with the pipeline's render jobs.
pub fn render_film(scene: &Scene, options: &RenderOptions) -> anyhow::Result<Film> {
    let atmosphere = load_scene_atmosphere(&scene.atmosphere)?;
    if !options.quiet
        && let Some(sounding) = atmosphere.as_ref().and_then(|a| a.sounding.as_ref())
    {
        // The same notes `profile` prints (skipped rows, suspect steps, ...).
        for w in &sounding.warnings {
            eprintln!("Ingest note: {w}");
        }
    }
    let tracer = prepare_tracer(scene, atmosphere.as_ref().map(|a| &a.refractive), options)?;
    let film = render_scene(scene, tracer.as_ref(), options)?;
    if film.stats.non_finite_samples > 0 {
        // Never silent, even with --quiet: these pixels are not what the physics says.
        eprintln!(
            "warning: {}: {} sample(s) had non-finite radiance and were shaded as horizon sky",
            scene
                .source_path
                .as_deref()
                .map_or_else(|| "scene".into(), |p| p.display().to_string()),
            film.stats.non_finite_samples
        );
    }
    Ok(film)
}
