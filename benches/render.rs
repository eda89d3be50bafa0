//! Frame time of the paper scenes with the real tracer: the fast path (elevation fan) at 400×200
//! and 1920×1080, 1 sample per pixel, render only; exact per-pixel 3-D tracing at 400×200 for the
//! superior mirage and the Fata Morgana (the baseline of the fan's speed-up, same 1 cm tracer
//! tolerance); PNG and EXR encoding of a 1920×1080 film; and the process's peak resident memory
//! (VmHWM, printed at the end).

use std::hint::black_box;
use std::path::PathBuf;
use std::sync::Arc;

use criterion::{Criterion, criterion_group};
use ghostship::output::{exr, png};
use ghostship::profile::{AirColumn, StandardAtmosphere, SyntheticAtmosphere};
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::render::{RenderOptions, prepare_tracer, provenance, render_scene};
use ghostship::scene::{AtmosphereSpec, Scene};

const SCENES: [&str; 6] = [
    "fig01_horizon_straight",
    "fig02_horizon_distortion",
    "fig04_superior_mirage",
    "fig08_inferior_mirage",
    "fig10_fata_morgana",
    "fig12_novaya_zemlya",
];

fn load(name: &str, width: u32, height: u32) -> (Scene, RefractiveAtmosphere) {
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/scenes"))
        .join(format!("{name}.toml"));
    let mut scene = Scene::from_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    scene.camera.width = width;
    scene.camera.height = height;
    let column: Arc<dyn AirColumn> = match &scene.atmosphere.source {
        AtmosphereSpec::Synthetic(p) => Arc::new(SyntheticAtmosphere::from_file(p).unwrap()),
        AtmosphereSpec::Us1976 => Arc::new(StandardAtmosphere::default()),
        AtmosphereSpec::Sounding(p) => panic!("no soundings in the paper scenes: {}", p.display()),
    };
    let atm = RefractiveAtmosphere::new(column, scene.atmosphere.wavelength_nm).unwrap();
    (scene, atm)
}

fn options(exact: bool) -> RenderOptions {
    RenderOptions {
        exact,
        samples_per_pixel: Some(1),
        quiet: true,
        ..RenderOptions::default()
    }
}

fn frames(c: &mut Criterion, width: u32, height: u32) {
    let mut group = c.benchmark_group(format!("frame_{width}x{height}"));
    for name in SCENES {
        let (scene, atm) = load(name, width, height);
        let opts = options(false);
        let tracer = prepare_tracer(&scene, Some(&atm), &opts).unwrap();
        let film = render_scene(&scene, tracer.as_ref(), &opts).unwrap();
        eprintln!("{name} {width}x{height}: {:?}", film.stats);
        group.bench_function(name, |b| {
            b.iter(|| black_box(render_scene(&scene, tracer.as_ref(), &opts).unwrap()))
        });
    }
    group.finish();
}

fn small(c: &mut Criterion) {
    frames(c, 400, 200);
}

fn large(c: &mut Criterion) {
    frames(c, 1920, 1080);
}

fn exact(c: &mut Criterion) {
    let mut group = c.benchmark_group("exact_400x200");
    group.sample_size(10);
    for name in ["fig04_superior_mirage", "fig10_fata_morgana"] {
        let (scene, atm) = load(name, 400, 200);
        let opts = options(true);
        let tracer = prepare_tracer(&scene, Some(&atm), &opts).unwrap();
        group.bench_function(name, |b| {
            b.iter(|| black_box(render_scene(&scene, tracer.as_ref(), &opts).unwrap()))
        });
    }
    group.finish();
}

fn encoding(c: &mut Criterion) {
    let (scene, atm) = load("fig10_fata_morgana", 1920, 1080);
    let opts = options(false);
    let tracer = prepare_tracer(&scene, Some(&atm), &opts).unwrap();
    let film = render_scene(&scene, tracer.as_ref(), &opts).unwrap();
    let meta = provenance(&scene, &opts);
    let mut group = c.benchmark_group("encode_1920x1080");
    group.sample_size(10);
    group.bench_function("png", |b| {
        b.iter(|| black_box(png::encode_png(&film, png::DEFAULT_EXPOSURE).unwrap()))
    });
    group.bench_function("exr", |b| {
        b.iter(|| black_box(exr::encode_exr(&film, &meta).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, small, large, exact, encoding);

/// Peak resident memory of this process (kB), from /proc/self/status (Linux).
fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn main() {
    benches();
    Criterion::default().configure_from_args().final_summary();
    match peak_rss_kb() {
        Some(kb) => eprintln!("peak resident memory (VmHWM): {:.1} MB", kb as f64 / 1024.0),
        None => eprintln!("peak resident memory: /proc/self/status not available"),
    }
}
