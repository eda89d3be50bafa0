//! The render bench's sun sequence (`cargo bench --bench render -- sun_sequence_400x200`) as one
//! process per side, for an instruction counter: the Novaya Zemlya strips scene at 400×200, one
//! sample per pixel, its atmosphere loaded and its tracer prepared, then nothing more (`load`),
//! one frame (`one`) or the 100 frames of the sunrise −3° … +0.96° in steps of 0.04° (`sweep`).
//! `valgrind --tool=callgrind target/release/examples/sun_sweep_cost MODE` for each mode: the
//! sweep costs (sweep − load) / (one − load) frames, a count that does not depend on the load of
//! a shared machine.

use std::path::PathBuf;

use ghostship::render::sweep::render_sun_sweep;
use ghostship::render::{RenderOptions, prepare_tracer, render_scene};
use ghostship::scene::Scene;

fn main() -> anyhow::Result<()> {
    let mode = std::env::args().nth(1).unwrap_or_else(|| "one".to_string());
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/scenes"))
        .join("fig12b_novaya_zemlya_strips.toml");
    let mut scene = Scene::from_file(&path)?;
    (scene.camera.width, scene.camera.height) = (400, 200);
    let atm = scene.atmosphere.load()?;
    let options = RenderOptions {
        samples_per_pixel: Some(1),
        quiet: true,
        ..RenderOptions::default()
    };
    let tracer = prepare_tracer(&scene, atm.as_ref().map(|a| &a.refractive), &options)?;
    match mode.as_str() {
        "load" => println!("loaded"),
        "one" => {
            let film = render_scene(&scene, tracer.as_ref(), &options)?;
            println!("one frame: {:?}", film.stats);
        }
        "sweep" => {
            let elevations: Vec<f64> = (0..100)
                .map(|i| (-3.0 + 0.04 * f64::from(i)).to_radians())
                .collect();
            let frames = render_sun_sweep(&scene, tracer.as_ref(), &options, &elevations)?;
            let rows: u32 = frames.iter().map(|f| f.rows_shaded).sum();
            println!("{} frames, {rows} rows shaded", frames.len());
        }
        other => anyhow::bail!("unknown mode {other:?}: use `load`, `one` or `sweep`"),
    }
    Ok(())
}
