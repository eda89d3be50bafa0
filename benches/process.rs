//! Whole-process wall time of one frame: the built release binary runs
//! `ghostship render data/scenes/<scene>.toml --size 1920x1080 --spp 1 -o f.png -o f.exr --quiet`
//! (and the same with `-o f.png` only) for every paper scene, several times each, and the median
//! is printed — start-up, scene and atmosphere loading, fan tracing, shading, encoding and the
//! atomic writes, everything a user waits for.
//!
//! Then, to show where the time goes, the same frame's stages are timed in this process with the
//! library (median of the same number of runs): scene file, atmosphere (read, fit, table),
//! tracer preparation, rendering (fan + shading), PNG and EXR encoding, and writing; plus the
//! start-up of the binary alone (`ghostship --version`).
//!
//! The paper scenes are held to the 0.1 s per frame, the terrain scenes (fig14, fig17) to
//! issue 11's 0.5 s; the table prints each scene's target and whether its median meets it.
//!
//! `cargo bench --bench process` (builds the binary in the bench profile first). Environment:
//! `GHOSTSHIP_BENCH_RUNS` (runs per scene and output set, default 7), `GHOSTSHIP_BENCH_BIN`
//! (other binaries to time instead, separated by `:`, e.g. an older build and this one: their
//! runs are interleaved, so a busy spell of a shared machine hits them alike); a further
//! argument filters scenes by name.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use ghostship::jobs::render::provenance;
use ghostship::output::film::write_films;
use ghostship::output::{exr, png, write_atomic};
use ghostship::render::{RenderOptions, prepare_tracer, render_scene};
use ghostship::scene::Scene;

/// The scenes, each with its target for one encoded 1920×1080 frame at 1 spp (s).
const SCENES: [(&str, f64); 11] = [
    ("fig01_horizon_straight", PAPER_TARGET_S),
    ("fig01b_horizon_curved", PAPER_TARGET_S),
    ("fig02_horizon_distortion", PAPER_TARGET_S),
    ("fig04a_superior_mirage_paper_camera", PAPER_TARGET_S),
    ("fig04_superior_mirage", PAPER_TARGET_S),
    ("fig08_inferior_mirage", PAPER_TARGET_S),
    ("fig10_fata_morgana", PAPER_TARGET_S),
    ("fig12_novaya_zemlya", PAPER_TARGET_S),
    ("fig12b_novaya_zemlya_strips", PAPER_TARGET_S),
    ("fig14_island_terrain", TERRAIN_TARGET_S),
    ("fig17_kauai_fata_morgana", TERRAIN_TARGET_S),
];

/// The paper scenes' target (s): the 0.1 s per frame.
const PAPER_TARGET_S: f64 = 0.1;
/// The terrain scenes' target (s): issue 11's 0.5 s per 1920×1080 terrain frame.
const TERRAIN_TARGET_S: f64 = 0.5;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Wall time (s) of one run of `bin render scene … -o outputs…`; panics if it fails.
fn run_once(bin: &Path, scene: &Path, outputs: &[PathBuf]) -> f64 {
    let mut cmd = Command::new(bin);
    cmd.arg("render")
        .arg(scene)
        .args(["--size", "1920x1080", "--spp", "1", "--quiet"]);
    for o in outputs {
        cmd.arg("-o").arg(o);
    }
    let start = Instant::now();
    let out = cmd.output().expect("cannot start the ghostship binary");
    let wall = start.elapsed().as_secs_f64();
    assert!(
        out.status.success(),
        "{} failed: {}",
        scene.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    wall
}

/// Seconds taken by `f`, and its result.
fn timed<T>(f: impl FnOnce() -> T) -> (f64, T) {
    let start = Instant::now();
    let v = f();
    (start.elapsed().as_secs_f64(), v)
}

/// In-process stage times (s) of one 1920×1080, 1 spp frame of `scene_path`: scene, atmosphere,
/// tracer, render, png encoding, exr encoding, writing both files; then both encoded and written
/// as `ghostship render` does it (`write_films`: PNG and EXR in parallel).
fn stages(scene_path: &Path, dir: &Path) -> [f64; 8] {
    let (t_scene, scene) = timed(|| {
        let mut scene = Scene::from_file(scene_path).expect("scene");
        scene.camera.width = 1920;
        scene.camera.height = 1080;
        scene
    });
    let options = RenderOptions {
        samples_per_pixel: Some(1),
        quiet: true,
        ..RenderOptions::default()
    };
    let (t_atm, atm) = timed(|| scene.atmosphere.load().expect("atmosphere"));
    let (t_tracer, tracer) = timed(|| {
        prepare_tracer(&scene, atm.as_ref().map(|a| &a.refractive), &options).expect("tracer")
    });
    let (t_render, film) =
        timed(|| render_scene(&scene, tracer.as_ref(), &options).expect("render"));
    let meta = provenance(&scene, &options);
    let (t_png, png_bytes) = timed(|| png::encode_png(&film, png::DEFAULT_EXPOSURE).expect("png"));
    let (t_exr, exr_bytes) = timed(|| exr::encode_exr(&film, &meta).expect("exr"));
    let (t_write, ()) = timed(|| {
        write_atomic(&dir.join("stage.png"), &png_bytes).expect("write");
        write_atomic(&dir.join("stage.exr"), &exr_bytes).expect("write");
    });
    let paths = [dir.join("joined.png"), dir.join("joined.exr")];
    let (t_joined, ()) =
        timed(|| write_films(&film, &paths, &meta, png::DEFAULT_EXPOSURE).expect("write_films"));
    [
        t_scene, t_atm, t_tracer, t_render, t_png, t_exr, t_write, t_joined,
    ]
}

fn main() {
    let bins: Vec<PathBuf> = match std::env::var_os("GHOSTSHIP_BENCH_BIN") {
        Some(list) => std::env::split_paths(&list).collect(),
        None => vec![PathBuf::from(env!("CARGO_BIN_EXE_ghostship"))],
    };
    let runs: usize = std::env::var("GHOSTSHIP_BENCH_RUNS")
        .ok()
        .and_then(|s| s.parse().ok())
        .filter(|&n| n > 0)
        .unwrap_or(7);
    // cargo passes `--bench`; anything else not starting with '-' filters scene names.
    let filter: Option<String> = std::env::args().skip(1).find(|a| !a.starts_with('-'));
    let scenes_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/scenes");
    let tmp = tempfile::tempdir().expect("temp dir");
    let png = tmp.path().join("frame.png");
    let exr = tmp.path().join("frame.exr");
    let both = [png.clone(), exr];
    let png_only = [png];
    let scenes: Vec<(&str, f64)> = SCENES
        .into_iter()
        .filter(|(name, _)| filter.as_deref().is_none_or(|f| name.contains(f)))
        .collect();
    // medians[bin][scene] = (png+exr, png only, fastest png+exr run)
    let mut medians = vec![Vec::new(); bins.len()];
    for (name, _) in &scenes {
        let scene = scenes_dir.join(format!("{name}.toml"));
        for bin in &bins {
            // One warm-up run (page cache, binary mapped), not counted.
            run_once(bin, &scene, &both);
        }
        let mut t_both = vec![Vec::with_capacity(runs); bins.len()];
        let mut t_png = vec![Vec::with_capacity(runs); bins.len()];
        // Interleaved, so a slow spell of the shared machine hits every binary and set alike.
        for _ in 0..runs {
            for (b, bin) in bins.iter().enumerate() {
                t_both[b].push(run_once(bin, &scene, &both));
                t_png[b].push(run_once(bin, &scene, &png_only));
            }
        }
        for b in 0..bins.len() {
            let fastest = t_both[b].iter().copied().fold(f64::INFINITY, f64::min);
            medians[b].push((
                median(std::mem::take(&mut t_both[b])),
                median(std::mem::take(&mut t_png[b])),
                fastest,
            ));
        }
    }
    for (bin, per_scene) in bins.iter().zip(&medians) {
        println!(
            "whole process, 1920x1080, 1 spp, median of {runs} runs ({}):",
            bin.display()
        );
        println!(
            "{:<38} {:>12} {:>12}  {:>8}  {:>4}  {:>12}",
            "scene", "png+exr", "png only", "target", "met", "fastest run"
        );
        for (&(name, target_s), &(mb, mp, fastest)) in scenes.iter().zip(per_scene) {
            println!(
                "{name:<38} {:>9.1} ms {:>9.1} ms  {:>6.1} s  {:>4}  {:>9.1} ms",
                mb * 1e3,
                mp * 1e3,
                target_s,
                if mb <= target_s { "yes" } else { "no" },
                fastest * 1e3
            );
        }
        if !per_scene.is_empty() {
            println!(
                "{:<38} {:>9.1} ms {:>9.1} ms\n",
                "median over scenes",
                median(per_scene.iter().map(|m| m.0).collect()) * 1e3,
                median(per_scene.iter().map(|m| m.1).collect()) * 1e3
            );
        }
    }
    let bin = bins.last().expect("a binary");

    let startup: Vec<f64> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            let out = Command::new(bin).arg("--version").output().expect("binary");
            assert!(out.status.success());
            start.elapsed().as_secs_f64()
        })
        .collect();
    println!(
        "\nstart-up alone (`ghostship --version`): {:.1} ms",
        median(startup) * 1e3
    );
    println!("in-process stages of the same frame (library, median of {runs} runs, ms):");
    let names = [
        "scene", "atmosph", "tracer", "render", "png", "exr", "write", "png||exr",
    ];
    print!("{:<38}", "scene");
    for n in names {
        print!(" {n:>8}");
    }
    println!();
    for (name, _) in &scenes {
        let scene = scenes_dir.join(format!("{name}.toml"));
        stages(&scene, tmp.path()); // warm-up
        let samples: Vec<[f64; 8]> = (0..runs).map(|_| stages(&scene, tmp.path())).collect();
        print!("{name:<38}");
        for k in 0..names.len() {
            print!(
                " {:>8.1}",
                median(samples.iter().map(|s| s[k]).collect()) * 1e3
            );
        }
        println!();
    }
}
