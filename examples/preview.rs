//! Render a scene with the closed-form constant-curvature rays (no real atmosphere) to PNG/EXR —
//! a development preview of the renderer:
//! `cargo run --release --example preview -- SCENE.toml OUT.png [k] [--exact] [--spp N]
//! [--repeat N]` (reports the fastest of N renders, excluding encoding)..

use std::path::PathBuf;
use std::time::Instant;

use ghostship::jobs::render::provenance;
use ghostship::output::film::write_film;
use ghostship::output::png;
use ghostship::render::{ConstantCurvatureRays, RenderOptions, render_scene};
use ghostship::scene::Scene;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene_path = PathBuf::from(args.first().expect("scene path"));
    let out = PathBuf::from(args.get(1).expect("output path"));
    let k: f64 = args
        .get(2)
        .filter(|a| !a.starts_with("--"))
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(0.17);
    let exact = args.iter().any(|a| a == "--exact");
    let spp = args
        .iter()
        .position(|a| a == "--spp")
        .and_then(|i| args.get(i + 1))
        .map(|s| s.parse())
        .transpose()?;
    let scene = Scene::from_file(&scene_path)?;
    let k = if scene.atmosphere.straight { 0.0 } else { k };
    let tracer = ConstantCurvatureRays::new(k, scene.earth_radius_m)?;
    let options = RenderOptions {
        exact,
        samples_per_pixel: spp,
        quiet: true,
        ..RenderOptions::default()
    };
    let repeat: usize = args
        .iter()
        .position(|a| a == "--repeat")
        .and_then(|i| args.get(i + 1))
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(1);
    let mut film = render_scene(&scene, &tracer, &options)?;
    let mut dt = std::time::Duration::MAX;
    for _ in 0..repeat {
        let t = Instant::now();
        film = render_scene(&scene, &tracer, &options)?;
        dt = dt.min(t.elapsed());
    }
    eprintln!(
        "{}: {}x{} in {:.1} ms, {:?}",
        scene_path.display(),
        film.width,
        film.height,
        dt.as_secs_f64() * 1e3,
        film.stats
    );
    let mut meta = provenance(&scene, &options);
    meta.extra
        .push(("tracer".into(), format!("constant curvature k={k}")));
    write_film(&film, &out, &meta, png::DEFAULT_EXPOSURE)?;
    Ok(())
}
