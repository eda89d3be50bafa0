//! Sun sweeps shade only the rows their sun can change: every frame of `render_sun_sweep` is
//! `render_scene` of its scene (pixels and counters; its facts those `frame_facts` reads from the
//! scene's own rays, although the sweep traces the sun's column once), with 1 thread and with 2,
//! over scenes that
//! exercise each table a frame shares with the sweep's first frame (strips through a
//! near-critical duct, a rough sea's glitter under haze with a card, a mirror sea's sun image
//! with two cards, terrain), and the strips sweep of the render bench shades few of its rows.

use ghostship::render::sweep::{SweepFrame, frame_facts, render_sun_sweep};
use ghostship::render::{RenderOptions, prepare_tracer, render_scene};
use ghostship::scene::Scene;

use crate::scenes::{atmosphere, load_scene};

fn options(spp: u32) -> RenderOptions {
    RenderOptions {
        samples_per_pixel: Some(spp),
        quiet: true,
        ..RenderOptions::default()
    }
}

/// `scene` at `width`×`height` with the sun of the glitter scene at `azimuth_deg`, when it has
/// none of its own.
fn with_size_and_sun(mut scene: Scene, (width, height): (u32, u32), azimuth_deg: f64) -> Scene {
    scene.camera.width = width;
    scene.camera.height = height;
    if scene.sun.is_none() {
        let mut sun = load_scene("fig16_sun_glitter.toml").sun.unwrap();
        sun.azimuth_rad = azimuth_deg.to_radians();
        scene.sun = Some(sun);
    }
    scene
}

/// The sun sweep of `scene` over `elevations_deg` with `threads` rayon threads, each frame
/// checked against the single render of its scene; the rows each frame shaded, and the rows of
/// each frame that differ from the first frame's.
fn sweep_equals_single_renders(
    scene: &Scene,
    spp: u32,
    elevations_deg: &[f64],
    threads: usize,
) -> (Vec<u32>, Vec<u32>) {
    let atm = atmosphere(scene);
    let opts = options(spp);
    let tracer = prepare_tracer(scene, Some(&atm), &opts).unwrap();
    let elevations: Vec<f64> = elevations_deg.iter().map(|e| e.to_radians()).collect();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let frames: Vec<SweepFrame> = pool
        .install(|| render_sun_sweep(scene, tracer.as_ref(), &opts, &elevations))
        .unwrap();
    assert_eq!(frames.len(), elevations.len());
    for (frame, &elevation_rad) in frames.iter().zip(&elevations) {
        let mut single = scene.clone();
        single.sun.as_mut().unwrap().elevation_rad = elevation_rad;
        let want = render_scene(&single, tracer.as_ref(), &opts).unwrap();
        let deg = elevation_rad.to_degrees();
        let film = frame.image.film();
        assert_eq!(film.stats, want.stats, "sun {deg:.3}°, {threads} threads");
        assert_eq!(frame.image.stats(), &want.stats);
        for y in 0..want.height {
            let w = want.width as usize;
            let want_row = &want.pixels[y as usize * w..(y as usize + 1) * w];
            assert!(
                bits(frame.image.row(y)) == bits(want_row),
                "sun {deg:.3}°: row {y}"
            );
        }
        assert!(
            bits(&film.pixels) == bits(&want.pixels),
            "sun {deg:.3}°, {threads} threads: {} rows shaded, pixels differ",
            frame.rows_shaded
        );
        let facts = frame_facts(&single, tracer.as_ref());
        assert_eq!(frame.facts, facts, "sun {deg:.3}°, {threads} threads");
    }
    let width = scene.camera.width as usize;
    let first = frames[0].image.film();
    let differ = frames
        .iter()
        .map(|f| {
            let film = f.image.film();
            let rows = film.pixels.chunks(width).zip(first.pixels.chunks(width));
            rows.filter(|(a, b)| bits(a) != bits(b)).count() as u32
        })
        .collect();
    (frames.iter().map(|f| f.rows_shaded).collect(), differ)
}

/// The bits of `pixels` (so that −0 and +0 differ, as bytes would).
fn bits(pixels: &[[f32; 4]]) -> Vec<[u32; 4]> {
    pixels.iter().map(|p| p.map(f32::to_bits)).collect()
}

/// From `from` in `count` steps of `step` (degrees).
fn steps(from: f64, step: f64, count: u32) -> Vec<f64> {
    (0..count).map(|i| from + step * f64::from(i)).collect()
}

#[test]
fn the_strips_sunrise_of_the_bench_shades_few_rows_and_equals_single_renders() {
    let scene = with_size_and_sun(
        load_scene("fig12b_novaya_zemlya_strips.toml"),
        (400, 200),
        0.0,
    );
    // The render bench's sweep: −3° to +0.96° in steps of 0.04°.
    let elevations = steps(-3.0, 0.04, 100);
    let (rows, differ) = sweep_equals_single_renders(&scene, 1, &elevations, 2);
    // The first frame is rendered whole; the others shade the rows their sun reaches (the
    // strips, the sun's glitter on the sea once it is up, far out while it is still below
    // the camera's horizon) and copy the rest: few more than the rows that differ from the
    // first frame's.
    assert_eq!(rows[0], 200);
    let shaded: u32 = rows[1..].iter().sum();
    let changed: u32 = differ[1..].iter().sum();
    eprintln!("rows shaded: {rows:?}\nrows that differ from the first frame: {differ:?}");
    assert!(
        10 * (shaded - changed) < shaded,
        "{shaded} rows shaded, {changed} changed"
    );
    assert!(rows.iter().filter(|&&r| r == 0).count() >= 20, "{rows:?}");
}

#[test]
fn sun_sweep_frames_equal_single_renders_whatever_the_thread_count() {
    let cases = [
        // The strips with the scene's own 4 samples per pixel (jittered samples, no flat rows).
        (
            with_size_and_sun(
                load_scene("fig12b_novaya_zemlya_strips.toml"),
                (160, 80),
                0.0,
            ),
            4,
            steps(-2.2, 0.2, 8),
        ),
        // A rough sea's glitter under haze, with a card.
        (
            with_size_and_sun(load_scene("fig16_sun_glitter.toml"), (200, 100), 1.0),
            1,
            steps(-1.0, 0.75, 8),
        ),
        // A mirror sea's sun image, two cards, haze.
        (
            with_size_and_sun(load_scene("fig15_calm_sea.toml"), (200, 100), 0.1),
            1,
            steps(-0.6, 0.2, 8),
        ),
        // Terrain and a mirror sea.
        (
            with_size_and_sun(load_scene("fig14_island_terrain.toml"), (200, 100), 5.0),
            1,
            steps(-0.5, 1.0, 6),
        ),
    ];
    for (scene, spp, elevations) in &cases {
        let one = sweep_equals_single_renders(scene, *spp, elevations, 1);
        let two = sweep_equals_single_renders(scene, *spp, elevations, 2);
        assert_eq!(one, two);
        eprintln!("{:?}: rows shaded {:?}", scene.source_path, one.0);
    }
}
