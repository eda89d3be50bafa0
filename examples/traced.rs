//! Render a scene with the real curved-ray tracer (or straight rays when the scene says so) and
//! report frame time and peak memory; optionally write the transfer plot of its atmosphere:
//! `cargo run --release --example traced -- SCENE.toml OUT.png [--size WxH] [--spp N] [--exact]
//! [--repeat N] [--plot PLOT.png] [--images] [--elev LO:HI] [--dist D1,D2] [--heights H1,H2] [--camera-height H]`.
//!
//! Any scene atmosphere (sounding, synthetic or us1976), loaded as the CLI does.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use ghostship::analysis::{TraceRequest, trace_plot_png, trace_report};
use ghostship::jobs::render::provenance;
use ghostship::output::film::write_film;
use ghostship::output::png;
use ghostship::render::{RenderOptions, prepare_tracer, render_scene};
use ghostship::scene::{AtmosphereSettings, Scene};

fn arg<T: std::str::FromStr>(args: &[String], name: &str) -> Option<T> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
}

/// Peak resident memory of this process (kB), from /proc/self/status (Linux).
fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene_path = PathBuf::from(args.first().context("scene path")?);
    let out = PathBuf::from(args.get(1).context("output path")?);
    let mut scene = Scene::from_file(&scene_path)?;
    if let Some(size) = arg::<String>(&args, "--size") {
        let (w, h) = size.split_once('x').context("--size WxH")?;
        scene.camera.width = w.parse()?;
        scene.camera.height = h.parse()?;
    }
    if let Some(h) = arg::<f64>(&args, "--camera-height") {
        scene.camera.height_m = h;
    }
    // The scene's air even for straight-ray scenes (the transfer plot needs it).
    let settings = AtmosphereSettings {
        straight: false,
        ..scene.atmosphere.clone()
    };
    let atmosphere = settings
        .load()?
        .context("a curved-ray atmosphere is always loaded")?
        .refractive;
    let options = RenderOptions {
        exact: args.iter().any(|a| a == "--exact"),
        samples_per_pixel: arg(&args, "--spp"),
        quiet: true,
        ..RenderOptions::default()
    };
    let tracer = prepare_tracer(&scene, Some(&atmosphere), &options)?;
    let repeat: usize = arg(&args, "--repeat").unwrap_or(1);
    let mut best = f64::INFINITY;
    let mut film = None;
    for _ in 0..repeat.max(1) {
        let t = Instant::now();
        film = Some(render_scene(&scene, tracer.as_ref(), &options)?);
        best = best.min(t.elapsed().as_secs_f64());
    }
    let film = film.expect("rendered");
    let t = Instant::now();
    let meta = provenance(&scene, &options);
    write_film(&film, &out, &meta, png::DEFAULT_EXPOSURE)?;
    let encode = t.elapsed().as_secs_f64();
    eprintln!(
        "{}: {}x{} render {:.1} ms, encode {:.1} ms, peak RSS {} kB, {:?}",
        scene_path.display(),
        film.width,
        film.height,
        best * 1e3,
        encode * 1e3,
        peak_rss_kb().unwrap_or(0),
        film.stats
    );
    if let Some(plot) = arg::<PathBuf>(&args, "--plot") {
        let mut distances: Vec<f64> = scene.cards.iter().map(|c| c.distance_m).collect();
        distances.sort_by(f64::total_cmp);
        distances.dedup();
        let mut heights: Vec<f64> = scene.cards.iter().map(|c| c.base_m + c.height_m).collect();
        heights.sort_by(f64::total_cmp);
        heights.dedup();
        let frame = scene.camera.frame();
        let half = 0.5 * scene.camera.height as f64 / frame.focal_px;
        let pitch = scene.camera.pitch_rad;
        let (lo, hi) = match arg::<String>(&args, "--elev") {
            Some(s) => {
                let (a, b) = s.split_once(':').context("--elev LO:HI (deg)")?;
                (a.parse()?, b.parse()?)
            }
            None => ((pitch - half).to_degrees(), (pitch + half).to_degrees()),
        };
        if let Some(list) = arg::<String>(&args, "--dist") {
            distances = list
                .split(',')
                .map(|d| d.parse::<f64>())
                .collect::<Result<_, _>>()?;
        }
        if let Some(list) = arg::<String>(&args, "--heights") {
            heights = list
                .split(',')
                .map(|d| d.parse::<f64>())
                .collect::<Result<_, _>>()?;
        }
        let request = TraceRequest {
            observer_height_m: scene.camera.height_m,
            elevation_min_deg: lo,
            elevation_max_deg: hi,
            elevation_count: 801,
            distances_m: distances,
            target_heights_m: heights,
            ..TraceRequest::default()
        };
        let report = trace_report(&atmosphere, &request)?;
        if args.iter().any(|a| a == "--images") {
            for im in &report.images {
                let row = |deg: f64| {
                    format!(
                        "{:.1}",
                        frame.centre_row_of_elevation(deg.to_radians(), pitch)
                    )
                };
                eprintln!(
                    "image D={} H={} {:.4}..{:.4} deg rows {}..{} erect={} h {:.1}->{:.1} mag {:.3}",
                    im.distance_m,
                    im.height_m,
                    im.elevation_min_deg,
                    im.elevation_max_deg,
                    row(im.elevation_max_deg),
                    row(im.elevation_min_deg),
                    im.erect,
                    im.height_at_min_m,
                    im.height_at_max_m,
                    im.magnification
                );
            }
            for h in &report.horizons {
                eprintln!("horizon {h:?}");
            }
        }
        std::fs::write(&plot, trace_plot_png(&atmosphere, &request, &report)?)?;
    }
    Ok(())
}
