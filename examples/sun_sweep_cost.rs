//! The render bench's sun sequence (`cargo bench --bench render -- sun_sequence_400x200`) as one
//! process per side, for an instruction counter: the Novaya Zemlya strips scene at 400×200, one
//! sample per pixel, its atmosphere loaded and one frame rendered to warm what the atmosphere
//! builds on first use (its n(h) table is filled lazily, as the bench's warm-up iterations do),
//! then nothing more (`load`), a tracer prepared and one frame (`one`), a tracer prepared and the
//! 100 frames of the sunrise −3° … +0.96° in steps of 0.04° (`sweep`), or a tracer prepared and
//! the sweep's first frame with the frame at `X` degrees (`pairX`) or with it and the next one,
//! 0.04° higher (`pairX+`: the difference of the two is the cost of one later frame there).
//! `valgrind --tool=callgrind target/release/examples/sun_sweep_cost MODE` for each mode: the
//! sweep costs (sweep − load) / (one − load) frames, a count that does not depend on the load of
//! a shared machine. Mode `alternate` (run without valgrind) renders one frame and the sweep in
//! turn, six times each, each with a tracer prepared for it, and prints each one's wall time
//! and the minor page faults it took (Linux: /proc/self/stat).

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
    let refractive = atm.as_ref().map(|a| &a.refractive);
    let options = RenderOptions {
        samples_per_pixel: Some(1),
        quiet: true,
        ..RenderOptions::default()
    };
    let warm_up = prepare_tracer(&scene, refractive, &options)?;
    render_scene(&scene, warm_up.as_ref(), &options)?;
    if mode == "load" {
        println!("loaded");
        return Ok(());
    }
    let tracer = prepare_tracer(&scene, refractive, &options)?;
    let sweep = |elevations_deg: &[f64]| {
        let elevations: Vec<f64> = elevations_deg.iter().map(|e| e.to_radians()).collect();
        render_sun_sweep(&scene, tracer.as_ref(), &options, &elevations)
    };
    if mode == "one" {
        let film = render_scene(&scene, tracer.as_ref(), &options)?;
        println!("one frame: {:?}", film.stats);
    } else if mode == "sweep" {
        let elevations: Vec<f64> = (0..100).map(|i| -3.0 + 0.04 * f64::from(i)).collect();
        let frames = sweep(&elevations)?;
        let rows: u32 = frames.iter().map(|f| f.rows_shaded).sum();
        println!("{} frames, {rows} rows shaded", frames.len());
    } else if mode == "alternate" {
        let elevations: Vec<f64> = (0..100).map(|i| -3.0 + 0.04 * f64::from(i)).collect();
        for _ in 0..6 {
            let (f0, t0) = (minor_faults(), std::time::Instant::now());
            let tracer = prepare_tracer(&scene, refractive, &options)?;
            drop(render_scene(&scene, tracer.as_ref(), &options)?);
            let (f1, t1) = (minor_faults(), std::time::Instant::now());
            // Each side prepares its own tracer, as the bench does.
            let tracer = prepare_tracer(&scene, refractive, &options)?;
            let radians: Vec<f64> = elevations.iter().map(|e| e.to_radians()).collect();
            drop(render_sun_sweep(
                &scene,
                tracer.as_ref(),
                &options,
                &radians,
            )?);
            let (f2, t2) = (minor_faults(), std::time::Instant::now());
            let ms = |a: std::time::Instant, b: std::time::Instant| (b - a).as_secs_f64() * 1e3;
            let faults = |a: Option<u64>, b: Option<u64>| b.zip(a).map(|(b, a)| b - a);
            println!(
                "one frame {:.1} ms, {:?} faults; 100 frames {:.1} ms, {:?} faults",
                ms(t0, t1),
                faults(f0, f1),
                ms(t1, t2),
                faults(f1, f2)
            );
        }
    } else if let Some(at) = mode.strip_prefix("pair") {
        let (at, next) = at.strip_suffix('+').map_or((at, false), |a| (a, true));
        let x: f64 = at.parse()?;
        let mut elevations = vec![-3.0, x];
        if next {
            elevations.push(x + 0.04);
        }
        let frames = sweep(&elevations)?;
        println!(
            "rows shaded: {:?}",
            frames.iter().map(|f| f.rows_shaded).collect::<Vec<_>>()
        );
    } else {
        anyhow::bail!(
            "unknown mode {mode:?}: use `load`, `one`, `sweep`, `pairX`, `pairX+` or `alternate`"
        );
    }
    Ok(())
}

/// This process's minor page faults so far (Linux), else `None`.
fn minor_faults() -> Option<u64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The fields after the command name (which is in parentheses and may hold spaces).
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    fields.get(7)?.parse().ok()
}
