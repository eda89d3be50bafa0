//! `ghostship sequence`: frames of every kind of sweep are the single renders of the same scene,
//! byte for byte; the frame index's strip and image counts follow the traced map (the analysis
//! tracer, not the renderer); the sun's position over time matches the NREL SPA paper; sweeps
//! over time share their rays; bad sweeps are clear errors; the bytes do not depend on the
//! thread count.

use std::path::Path;

use ghostship::jobs::AtmosphereCache;
use ghostship::jobs::sequence::{
    SequenceRequest, SequenceSettings, SweepKind, frame_name, parse_sweep,
};
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::render::render_tracer_config;
use ghostship::scene::Scene;
use ghostship::tracer::{Termination, Tracer};

use crate::scenes::atmosphere;
use crate::support::cli::{fails, ghostship, ok, output_tree, usage_error};
use crate::support::data::data_dir;

const STRIPS: &str = "fig12b_novaya_zemlya_strips.toml";

fn scene_path(name: &str) -> String {
    data_dir().join("scenes").join(name).display().to_string()
}

/// `ghostship sequence` of the strips scene at 200×100, 1 sample per pixel, into `out`.
fn sequence(out: &Path, sweep: &str, threads: &str) {
    let status = ghostship()
        .env("RAYON_NUM_THREADS", threads)
        .args([
            "sequence",
            &scene_path(STRIPS),
            "--out",
            out.to_str().unwrap(),
            &format!("--sun-elevation-deg={sweep}"),
            "--size",
            "200x100",
            "--spp",
            "1",
            "--quiet",
        ])
        .output()
        .expect("binary runs");
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
}

#[test]
fn sun_sweep_frames_are_the_single_renders_of_their_sun_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("seq");
    sequence(&out, "-1.8:-1.5:0.1", "2");
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 4, "{csv}");
    let text = std::fs::read_to_string(scene_path(STRIPS)).unwrap();
    let atmosphere = data_dir().join("novaya_zemlya_strips.toml");
    for (i, row) in rows.iter().enumerate() {
        let value = row.split(',').nth(1).unwrap();
        // The same scene with the sun at the frame's elevation, as a user would write it.
        let moved = text
            .replace("elevation_deg = -1.55", &format!("elevation_deg = {value}"))
            .replace(
                "\"../novaya_zemlya_strips.toml\"",
                &format!("{:?}", atmosphere.display().to_string()),
            );
        assert_ne!(moved, text);
        let scene = dir.path().join(format!("sun_{i}.toml"));
        std::fs::write(&scene, moved).unwrap();
        let png = dir.path().join(format!("sun_{i}.png"));
        ok(&[
            "render",
            scene.to_str().unwrap(),
            "-o",
            png.to_str().unwrap(),
            "--size",
            "200x100",
            "--spp",
            "1",
            "--quiet",
        ]);
        let single = std::fs::read(&png).unwrap();
        let frame = std::fs::read(out.join(frame_name(i))).unwrap();
        assert!(
            single == frame,
            "frame {i} (sun {value}°) differs from render"
        );
    }
    // The frames differ from each other (the sun moved).
    let first = std::fs::read(out.join(frame_name(0))).unwrap();
    let last = std::fs::read(out.join(frame_name(3))).unwrap();
    assert_ne!(first, last);
    assert!(out.join("sequence.gif").is_file());
    // The sun sweep's figure: the sun's band against its true elevation, strips below.
    let plot = image::open(out.join("sun.png")).unwrap();
    assert_eq!((plot.width(), plot.height()), (1200, 900));
}

#[test]
fn sequence_bytes_do_not_depend_on_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let (one, two) = (dir.path().join("one"), dir.path().join("two"));
    sequence(&one, "-2:-1:0.25", "1");
    sequence(&two, "-2:-1:0.25", "2");
    let (a, b) = (output_tree(&one), output_tree(&two));
    assert_eq!(a.len(), 5 + 3, "{:?}", a.keys());
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        assert!(bytes == &b[name], "{name} differs between 1 and 2 threads");
    }
}

/// Strips along the centre column by the analysis tracer: runs of rows whose escaping ray's
/// final direction lies within the sun's disc.
fn traced_strips(scene: &Scene, tracer: &Tracer<'_, RefractiveAtmosphere>) -> usize {
    let sun = scene.sun.unwrap();
    let frame = scene.camera.frame();
    let x = scene.camera.width / 2;
    let mut strips = 0;
    let mut previous = false;
    for y in 0..scene.camera.height {
        let (azimuth, alpha) = frame.direction(x as f64 + 0.5, y as f64 + 0.5);
        let r = tracer.trace(scene.camera.height_m, alpha, &[]).unwrap();
        let shows = r.termination == Some(Termination::Escaped) && {
            let e = r.end_observer_elevation_rad;
            let d_az = (azimuth - sun.azimuth_rad) * e.cos();
            (e - sun.elevation_rad).hypot(d_az) <= 0.5 * sun.angular_diameter_rad
        };
        if shows && !previous {
            strips += 1;
        }
        previous = shows;
    }
    strips
}

#[test]
fn frame_index_strips_match_the_traced_map() {
    let scene = Scene::from_file(Path::new(&scene_path(STRIPS))).unwrap();
    let sun = scene.sun.unwrap();
    // The column the index reads is the centre one: the sun is straight ahead.
    assert_eq!(sun.azimuth_rad, scene.camera.heading_rad);
    let sweep = parse_sweep(SweepKind::SunElevationDeg, "-2.1:-0.9:0.15").unwrap();
    let request = SequenceRequest::new(
        scene.clone(),
        SequenceSettings {
            spp: Some(1),
            ..SequenceSettings::new(sweep)
        },
    )
    .unwrap();
    let frames = request.render_frames(&AtmosphereCache::new()).unwrap();
    let atm = atmosphere(&scene);
    let tracer = Tracer::new(&atm, render_tracer_config(scene.earth_radius_m)).unwrap();
    let scenes = request.frame_scenes();
    let mut counts = Vec::new();
    for (frame, scene) in frames.iter().zip(&scenes) {
        let want = traced_strips(scene, &tracer);
        let facts = frame.facts.sun.expect("the scene has a sun");
        let elevation = scene.sun.unwrap().elevation_rad.to_degrees();
        assert_eq!(facts.strips, want, "sun at {elevation:.3}°");
        assert_eq!(facts.apparent_low_rad.is_some(), want > 0);
        counts.push(want);
    }
    // The sweep shows the stacked strips: several strips in some frame, none in the first.
    assert_eq!(counts[0], 0, "{counts:?}");
    assert!(counts.iter().any(|&n| n >= 3), "{counts:?}");
    let csv = request.frames_csv(&frames);
    assert!(csv.starts_with(
        "frame,sun_true_elevation_deg,sun_apparent_low_deg,sun_apparent_high_deg,sun_strips\n"
    ));
}

#[test]
fn bad_sweeps_are_clear_errors() {
    let scene = scene_path(STRIPS);
    for (sweep, message) in [
        ("--sun-elevation-deg=1:0:0.1", "TO must not be below FROM"),
        ("--sun-elevation-deg=-3:1:0", "STEP must be > 0"),
        ("--sun-elevation-deg=-3:1", "is not FROM:TO:STEP in degrees"),
        ("--sun-elevation-deg=a:1:0.1", "FROM \"a\" is not a number"),
        ("--sun-elevation-deg=-95:0:1", "within -90° and 90°"),
        (
            "--sun-elevation-deg=-3:1:0.0001",
            "at most 10000 are allowed",
        ),
        ("--observer-height-m=-5:10:5", "≥ 0 m"),
    ] {
        let r = usage_error(&["sequence", &scene, sweep]);
        assert!(r.stderr.contains(message), "{sweep}: {}", r.stderr);
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let r = fails(&[
        "sequence",
        &scene,
        "--out",
        out,
        "--sun-elevation-deg=-2:-1:0.5",
        "--observer-height-m=5:10:5",
    ]);
    assert!(r.stderr.contains("one sweep per run"), "{}", r.stderr);
    let r = fails(&["sequence", &scene, "--out", out]);
    assert!(r.stderr.contains("give a sweep"), "{}", r.stderr);
    let no_sun = scene_path("fig04_superior_mirage.toml");
    let r = fails(&[
        "sequence",
        &no_sun,
        "--out",
        out,
        "--sun-elevation-deg=0:1:0.5",
    ]);
    assert!(r.stderr.contains("no [sun]"), "{}", r.stderr);
}

#[test]
fn observer_sweep_frames_are_the_single_renders_at_that_height() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("climb");
    let scene = scene_path("fig04_superior_mirage.toml");
    ok(&[
        "sequence",
        &scene,
        "--out",
        out.to_str().unwrap(),
        "--observer-height-m=5:25:10",
        "--size",
        "160x80",
        "--spp",
        "1",
        "--quiet",
    ]);
    let csv = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    let heights: Vec<&str> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap())
        .collect();
    assert_eq!(heights, ["5", "15", "25"], "{csv}");
    assert!(
        csv.starts_with("frame,observer_height_m,card0_images,card0_apparent_low_deg,"),
        "{csv}"
    );
    assert!(
        !out.join("sun.png").exists(),
        "only sweeps that move the sun have the sun's figure"
    );
    // The transfer curves against observer height.
    let plot = image::open(out.join("transfer.png")).unwrap();
    assert_eq!((plot.width(), plot.height()), (1200, 800));
    // The library's render job at the same height gives the same PNG.
    let base = Scene::from_file(Path::new(&scene)).unwrap();
    let request = ghostship::jobs::RenderRequest::new(
        base,
        ghostship::jobs::render::RenderSettings {
            sizes: vec![Some((160, 80))],
            formats: vec![ghostship::output::film::ImageFormat::Png],
            spp: Some(1),
            observer_height_m: Some(15.0),
            ..Default::default()
        },
    )
    .unwrap();
    let products = request.products(&AtmosphereCache::new()).unwrap();
    let frame = std::fs::read(out.join(frame_name(1))).unwrap();
    assert!(
        products[0].bytes == frame,
        "frame 1 differs from render at 15 m"
    );
}

#[test]
fn a_pipeline_sequence_job_writes_the_frames_the_command_writes() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = dir.path().join("seq.toml");
    std::fs::write(
        &pipeline,
        format!(
            "[[sequence]]\nname = \"sunrise\"\nscene = {:?}\nsun_elevation_deg = \"-2:-1:0.5\"\n\
             size = \"200x100\"\nspp = 1\n",
            scene_path(STRIPS)
        ),
    )
    .unwrap();
    let out = dir.path().join("out");
    crate::support::cli::pipeline_ok(&pipeline, &out, &[]);
    let single = dir.path().join("single");
    sequence(&single, "-2:-1:0.5", "2");
    crate::support::cli::assert_same_tree(&out.join("sunrise"), &single);
    // Both sweeps in one table is a diagnostic, not a job.
    std::fs::write(
        &pipeline,
        format!(
            "[[sequence]]\nscene = {:?}\nsun_elevation_deg = \"-2:-1:0.5\"\n\
             observer_height_m = \"5:10:5\"\n",
            scene_path(STRIPS)
        ),
    )
    .unwrap();
    let r = crate::support::cli::pipeline_run(&pipeline, &out, &[]);
    assert_ne!(r.code, Some(0));
    assert!(r.stderr.contains("one sweep per sequence"), "{}", r.stderr);
}
