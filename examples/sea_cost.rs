//! What the sea's reflections cost: every paper scene (data/scenes) rendered through the library's
//! render API (1 sample per pixel, fan path, `render_scene` alone) with `[sea] reflections` on and
//! off, interleaved, and the same with a mirror-calm sea (`wave_slope_deg = 0`, where the cards'
//! mirror images show and take the most work):
//! `cargo run --release --example sea_cost -- [RUNS] [WxH ...]` (median of RUNS, default 7).

use std::time::Instant;

use ghostship::render::{RenderOptions, prepare_tracer, render_scene};
use ghostship::scene::Scene;
use ghostship::verify::frames::load_paper_scenes;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let runs: usize = args.first().map(|a| a.parse()).transpose()?.unwrap_or(7);
    let mut sizes: Vec<(u32, u32)> = args
        .iter()
        .skip(1)
        .filter_map(|s| s.split_once('x'))
        .map(|(w, h)| Ok::<_, anyhow::Error>((w.parse()?, h.parse()?)))
        .collect::<Result<_, _>>()?;
    if sizes.is_empty() {
        sizes = vec![(400, 200), (1920, 1080)];
    }
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes");
    let options = RenderOptions {
        samples_per_pixel: Some(1),
        quiet: true,
        ..RenderOptions::default()
    };
    println!("| scene | sea | size | off (ms) | on (ms) | on / off | sea-fan rays |");
    println!("|---|---|---|---:|---:|---:|---:|");
    for ps in load_paper_scenes(&dir)? {
        if ps.scene.terrain.is_some() {
            continue;
        }
        for calm in [false, true] {
            for &(w, h) in &sizes {
                let variant = |reflections: bool| {
                    let mut s: Scene = ps.scene.clone();
                    s.camera.width = w;
                    s.camera.height = h;
                    s.sea.reflections = reflections;
                    if calm {
                        s.sea.wave_slope_rad = 0.0;
                    }
                    s
                };
                let (on, off) = (variant(true), variant(false));
                let tracer = prepare_tracer(&on, ps.refractive(), &options)?;
                let (mut t_on, mut t_off) = (Vec::new(), Vec::new());
                let mut rays = 0;
                for _ in 0..runs.max(1) {
                    let t = Instant::now();
                    let film = render_scene(&off, tracer.as_ref(), &options)?;
                    t_off.push(t.elapsed().as_secs_f64() * 1e3);
                    std::hint::black_box(film);
                    let t = Instant::now();
                    let film = render_scene(&on, tracer.as_ref(), &options)?;
                    t_on.push(t.elapsed().as_secs_f64() * 1e3);
                    rays = film.stats.sea_fan_rays;
                }
                let (a, b) = (median(t_off), median(t_on));
                println!(
                    "| {} | {} | {w}×{h} | {a:.2} | {b:.2} | {:.2}× | {rays} |",
                    ps.name,
                    if calm { "mirror" } else { "scene's" },
                    b / a
                );
            }
        }
    }
    Ok(())
}
