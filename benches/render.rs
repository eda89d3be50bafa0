//! Frame time of the paper scenes with the real tracer: the fast path (elevation fan) at 400×200
//! and 1920×1080, 1 sample per pixel, render only; a sun sequence (100 sun elevations of the
//! Novaya Zemlya strips scene at 400×200 against one frame, both with the tracer prepared); the
//! cost per frame of every kind of sequence (the jobs layer's frames with their facts, against
//! one frame of the same scene, atmospheres loaded once); exact per-pixel 3-D tracing at 400×200
//! for every curved-ray scene (the baseline of the fan's speed-up, same 1 cm tracer tolerance);
//! PNG and EXR encoding of a 1920×1080 film; the cost of terrain, haze and the sun at 1920×1080
//! (`effects_1920x1080`: each scene of [`EFFECT_SCENES`] plain, with each of its effects alone
//! and as shipped; the interleaved medians of `examples/effects_cost.rs` are in
//! `docs/effects_cost.md`); and the process's peak resident memory (VmHWM, printed at the end).

use std::hint::black_box;
use std::path::PathBuf;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::SystemTime;

use criterion::{Criterion, criterion_group};
use ghostship::atmosphere::LoadedAtmosphere;
use ghostship::jobs::AtmosphereCache;
use ghostship::jobs::render::provenance;
use ghostship::jobs::sequence::{
    SequenceRequest, SequenceSettings, SweepKind, SweepSpec, TimeSpan, parse_key_sweep, parse_sweep,
};
use ghostship::output::{exr, png};
use ghostship::render::sweep::render_sun_sweep;
use ghostship::render::{RenderOptions, prepare_tracer, render_scene};
use ghostship::scene::Scene;
use ghostship::verify::effects::{EFFECT_SCENES, effects_of, with_effects};

const SCENES: [&str; 9] = [
    "fig01_horizon_straight",
    "fig01b_horizon_curved",
    "fig02_horizon_distortion",
    "fig04a_superior_mirage_paper_camera",
    "fig04_superior_mirage",
    "fig08_inferior_mirage",
    "fig10_fata_morgana",
    "fig12_novaya_zemlya",
    "fig12b_novaya_zemlya_strips",
];

fn load(name: &str, width: u32, height: u32) -> (Scene, Option<LoadedAtmosphere>) {
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/scenes"))
        .join(format!("{name}.toml"));
    let mut scene = Scene::from_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    scene.camera.width = width;
    scene.camera.height = height;
    let atm = scene
        .atmosphere
        .load()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
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
        let tracer = prepare_tracer(&scene, atm.as_ref().map(|a| &a.refractive), &opts).unwrap();
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
    // Every curved-ray scene (fig01 uses straight rays, for which exact mode is the same closed
    // form).
    for name in SCENES
        .into_iter()
        .filter(|n| *n != "fig01_horizon_straight")
    {
        let (scene, atm) = load(name, 400, 200);
        let opts = options(true);
        let tracer = prepare_tracer(&scene, atm.as_ref().map(|a| &a.refractive), &opts).unwrap();
        group.bench_function(name, |b| {
            b.iter(|| black_box(render_scene(&scene, tracer.as_ref(), &opts).unwrap()))
        });
    }
    group.finish();
}

/// 100 frames of a sunrise (true elevation −3° to +0.96° in steps of 0.04°) against one frame,
/// each preparing its tracer: the sequence traces its rays once and shades every frame.
/// Whether this process measured `sun_sequence`'s one frame and its 100 frames.
static SUN_SEQUENCE_RAN: [AtomicBool; 2] = [AtomicBool::new(false), AtomicBool::new(false)];

fn sun_sequence(c: &mut Criterion) {
    let (scene, atm) = load("fig12b_novaya_zemlya_strips", 400, 200);
    let opts = options(false);
    let refractive = atm.as_ref().map(|a| &a.refractive);
    let elevations: Vec<f64> = (0..100)
        .map(|i| (-3.0 + 0.04 * f64::from(i)).to_radians())
        .collect();
    let mut group = c.benchmark_group("sun_sequence_400x200");
    group.sample_size(10);
    group.bench_function("one_frame", |b| {
        SUN_SEQUENCE_RAN[0].store(true, Ordering::Relaxed);
        b.iter(|| {
            let tracer = prepare_tracer(&scene, refractive, &opts).unwrap();
            black_box(render_scene(&scene, tracer.as_ref(), &opts).unwrap())
        })
    });
    group.bench_function("100_sun_frames", |b| {
        SUN_SEQUENCE_RAN[1].store(true, Ordering::Relaxed);
        b.iter(|| {
            let tracer = prepare_tracer(&scene, refractive, &opts).unwrap();
            black_box(render_sun_sweep(&scene, tracer.as_ref(), &opts, &elevations).unwrap())
        })
    });
    group.finish();
}

/// A sequence request of `scene` at 400×200, 1 sample per pixel, sweeping `sweep`.
fn sequence_request(scene: &str, sweep: SweepSpec) -> SequenceRequest {
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/data/scenes")).join(scene);
    let scene = Scene::from_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let settings = SequenceSettings {
        size: Some((400, 200)),
        spp: Some(1),
        ..SequenceSettings::new(sweep)
    };
    SequenceRequest::new(scene, settings).unwrap()
}

/// One frame of `request`'s first scene, its tracer prepared, through the cached atmosphere.
fn one_frame(request: &SequenceRequest, cache: &AtmosphereCache) -> ghostship::render::Film {
    let scene = &request.frames()[0].scene;
    let air = request.atmosphere().map(|a| cache.get(a).unwrap());
    let opts = options(false);
    let tracer = prepare_tracer(scene, air.as_deref().map(|a| &a.refractive), &opts).unwrap();
    render_scene(scene, tracer.as_ref(), &opts).unwrap()
}

/// Every kind of sequence at 400×200: the frames the jobs layer renders (with their facts and,
/// for the observer, transfer curves), atmospheres fitted once (the cache outlives the
/// iterations), against one frame of the same scene. The sun over time: 100 frames (2 min
/// apart, the camera turning with the sun, Danmarkshavn's sounding); observer heights, a card's
/// distance and the air between two soundings: 10 frames.
fn sequence_kinds(c: &mut Criterion) {
    let time = TimeSpan::parse("2026-02-11T11:50Z/2026-02-11T15:08Z", 2.0).unwrap();
    let cases = [
        (
            "sun_time",
            sequence_request(
                "seq_danmarkshavn_sunrise.toml",
                SweepSpec::SunTime {
                    span: time,
                    lat_lon_deg: None,
                    follow_sun: true,
                },
            ),
        ),
        (
            "observer",
            sequence_request(
                "fig04_superior_mirage.toml",
                parse_sweep(SweepKind::ObserverHeightM, "30:120:10").unwrap(),
            ),
        ),
        (
            "card_distance",
            sequence_request(
                "fig04_superior_mirage.toml",
                parse_key_sweep("cards[1].distance_m=30000:75000:5000").unwrap(),
            ),
        ),
        (
            "soundings",
            sequence_request(
                "seq_utqiagvik_twelve_hours.toml",
                SweepSpec::Soundings {
                    to: PathBuf::from(concat!(
                        env!("CARGO_MANIFEST_DIR"),
                        "/tests/data/soundings/raw/USM00070026-data_2010-06-01_excerpt.txt"
                    )),
                    to_time: Some("2010-06-01 12".into()),
                    step_min: 80.0,
                },
            ),
        ),
    ];
    let mut group = c.benchmark_group("sequence_kinds_400x200");
    group.sample_size(10);
    for (name, request) in &cases {
        let cache = AtmosphereCache::new();
        eprintln!("{name}: {} frames", request.frame_count());
        group.bench_function(format!("{name}_one_frame"), |b| {
            b.iter(|| black_box(one_frame(request, &cache)))
        });
        group.bench_function(format!("{name}_{}_frames", request.frame_count()), |b| {
            b.iter(|| black_box(request.render_frames(&cache).unwrap()))
        });
    }
    group.finish();
}

/// Each effect scene at 1920×1080: plain (terrain, haze and sun taken out), with each of its
/// effects alone, and as shipped.
fn effects(c: &mut Criterion) {
    let mut group = c.benchmark_group("effects_1920x1080");
    group.sample_size(10);
    let opts = options(false);
    for name in EFFECT_SCENES {
        let (scene, atm) = load(name, 1920, 1080);
        let present = effects_of(&scene);
        let mut variants = vec![("plain".to_string(), with_effects(&scene, (1920, 1080), &[]))];
        for &e in &present {
            variants.push((
                e.label().to_string(),
                with_effects(&scene, (1920, 1080), &[e]),
            ));
        }
        variants.push(("shipped".to_string(), scene.clone()));
        for (label, variant) in variants {
            let tracer =
                prepare_tracer(&variant, atm.as_ref().map(|a| &a.refractive), &opts).unwrap();
            group.bench_function(format!("{name}/{label}"), |b| {
                b.iter(|| black_box(render_scene(&variant, tracer.as_ref(), &opts).unwrap()))
            });
        }
    }
    group.finish();
}

fn encoding(c: &mut Criterion) {
    let (scene, atm) = load("fig10_fata_morgana", 1920, 1080);
    let opts = options(false);
    let tracer = prepare_tracer(&scene, atm.as_ref().map(|a| &a.refractive), &opts).unwrap();
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

criterion_group!(
    name = benches;
    config = Criterion::default().output_directory(&criterion_dir());
    targets = small, large, sun_sequence, sequence_kinds, exact, effects, encoding
);

/// Where criterion writes its estimates: `$CRITERION_HOME`, else `criterion` in the cargo target
/// folder (`$CARGO_TARGET_DIR` or this package's `target`). Set explicitly, not left to
/// criterion (which runs `cargo metadata` to find the target folder, and outside cargo falls
/// back to a folder under the working directory), so that [`report_sun_sequence_target`] reads
/// what this run wrote wherever the bench binary is started from.
fn criterion_dir() -> PathBuf {
    if let Some(home) = std::env::var_os("CRITERION_HOME") {
        return PathBuf::from(home);
    }
    std::env::var_os("CARGO_TARGET_DIR")
        .map_or_else(
            || PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/target")),
            PathBuf::from,
        )
        .join("criterion")
}

/// When this process started (estimates written before it are an earlier run's).
static STARTED: OnceLock<SystemTime> = OnceLock::new();

/// Peak resident memory of this process (kB), from /proc/self/status (Linux).
fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// The median time (ns) criterion measured for `group/function` in this run, from its
/// `estimates.json` under [`criterion_dir`]; `None` when there is none written since this
/// process started.
fn criterion_median_ns(group: &str, function: &str) -> Option<f64> {
    let path = criterion_dir().join(format!("{group}/{function}/new/estimates.json"));
    let written = std::fs::metadata(&path).and_then(|m| m.modified()).ok()?;
    if written < *STARTED.get()? {
        return None;
    }
    let text = std::fs::read_to_string(path).ok()?;
    let json: serde_json::Value = serde_json::from_str(&text).ok()?;
    json["median"]["point_estimate"].as_f64()
}

/// The target for a sun sweep: 100 frames at 400×200 in at most 3 times one frame, from
/// the medians criterion wrote for `sun_sequence`, when this process measured both of its
/// benchmarks (not in `--test` or `--list` mode, which measure nothing).
fn report_sun_sequence_target() {
    let args: Vec<String> = std::env::args().collect();
    let measured = SUN_SEQUENCE_RAN.iter().all(|r| r.load(Ordering::Relaxed));
    if !measured || args.iter().any(|a| a == "--test" || a == "--list") {
        return;
    }
    let group = "sun_sequence_400x200";
    let (Some(one), Some(sweep)) = (
        criterion_median_ns(group, "one_frame"),
        criterion_median_ns(group, "100_sun_frames"),
    ) else {
        eprintln!(
            "{group}: no ratio: criterion's estimates of this run not found under {}",
            criterion_dir().display()
        );
        return;
    };
    let ratio = sweep / one;
    let verdict = if ratio <= 3.0 { "met" } else { "NOT met" };
    eprintln!(
        "{group}: 100 sun frames {:.2} ms / one frame {:.2} ms = {ratio:.2} (target ≤ 3: {verdict}; \
         criterion's medians of this run)",
        sweep * 1e-6,
        one * 1e-6
    );
}

fn main() {
    STARTED.get_or_init(SystemTime::now);
    benches();
    Criterion::default().configure_from_args().final_summary();
    report_sun_sequence_target();
    match peak_rss_kb() {
        Some(kb) => eprintln!("peak resident memory (VmHWM): {:.1} MB", kb as f64 / 1024.0),
        None => eprintln!("peak resident memory: /proc/self/status not available"),
    }
}
