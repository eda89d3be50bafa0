//! A real elevation model: the SRTM3 tile N22W160 (northern Kaua'i) shipped in
//! `data/scenes/terrain/` with the scene `fig17_kauai_fata_morgana`. The reader gives the
//! tile's own samples at their latitude and longitude (expected values read once from the file
//! with Python's `zipfile` and `struct`, independently of ghostship: see the README there), its
//! voids are filled as documented, and the rendered skyline stands where the independent
//! reference tracer's transfer curve through the Fata Morgana air puts it.

use std::io::Read;

use ghostship::profile::SyntheticAtmosphere;
use ghostship::render::{Film, RenderOptions, prepare_tracer, render_scene};
use ghostship::scene::{Dem, Scene};

use crate::scenes::atmosphere;
use crate::support::bisect;
use crate::support::data::{data_dir, repo_file};
use crate::support::reference::{BreakSource, atmosphere_index, reference_heights};

const TILE: &str = "data/scenes/terrain/N22W160v2.3a.hgt.zip";
const R: f64 = 6_371_000.0;

/// Latitude and longitude (°) of row `r`, column `c` of the tile (south-west corner 22° N,
/// 160° W; 1200 steps per degree, row 0 the northern edge).
fn cell_lat_lon(r: usize, c: usize) -> (f64, f64) {
    (23.0 - r as f64 / 1200.0, -160.0 + c as f64 / 1200.0)
}

#[test]
fn the_srtm_tile_reader_returns_the_tiles_own_samples() {
    let dem = Dem::from_file(&repo_file(TILE)).unwrap();
    assert_eq!((dem.rows, dem.cols), (1201, 1201));
    let (south, north, west, east) = dem.bounds_deg();
    assert_eq!((south, north, west, east), (22.0, 23.0, -160.0, -159.0));
    // (row, column, height m), read with Python's struct from the zip's N22W160.hgt.
    for (r, c, want) in [
        (1130, 603, 1579.0),
        (1000, 500, 296.0),
        (1100, 400, 1014.0),
        (950, 700, 103.0),
        (1050, 650, 366.0),
        (1200, 849, 0.0),
        (0, 0, 0.0),
    ] {
        let (lat, lon) = cell_lat_lon(r, c);
        assert_eq!(dem.sample(r, c), want as f32, "sample ({r}, {c})");
        let h = dem.height_at(lat, lon).unwrap();
        assert!((h - want).abs() < 1e-6, "({r}, {c}) at {lat}, {lon}: {h}");
    }
    // (941, 500) is a void whose four neighbours (255, 338, 266, 277 m) are known.
    assert!(dem.sample(941, 500).is_nan());
    let (lat, lon) = cell_lat_lon(941, 500);
    assert_eq!(dem.height_at(lat, lon), None);
}

#[test]
fn the_kauai_scene_fills_the_tiles_voids() {
    let scene = crate::scenes::load_scene("fig17_kauai_fata_morgana.toml");
    let t = scene.terrain.as_ref().expect("terrain");
    // Every one of the tile's 4 279 voids borders known samples somewhere.
    assert_eq!(t.voids_filled, 4279);
    assert_eq!(t.max_height_m, 1579.0);
    // An isolated void is the mean of its four neighbours (the harmonic fill).
    let filled = t.dem.sample(941, 500);
    let mean = (255.0 + 338.0 + 266.0 + 277.0) / 4.0;
    assert!((filled - mean).abs() < 0.01, "{filled} vs {mean}");
}

/// The tile's samples, read here from the zip (not by the reader under test): row-major, north
/// row first, `None` for voids.
fn raw_samples() -> Vec<Option<f64>> {
    let file = std::fs::File::open(repo_file(TILE)).unwrap();
    let mut archive = zip::ZipArchive::new(file).unwrap();
    let mut bytes = Vec::new();
    archive
        .by_name("N22W160.hgt")
        .unwrap()
        .read_to_end(&mut bytes)
        .unwrap();
    bytes
        .chunks_exact(2)
        .map(|b| match i16::from_be_bytes([b[0], b[1]]) {
            -32768 => None,
            v => Some(f64::from(v)),
        })
        .collect()
}

/// Heights (m) every `step_m` from `from_m` to `to_m` along the great circle leaving
/// (`lat0`, `lon0`) at azimuth `az` on the sphere of radius R, bilinear in `samples`, with the
/// distances; panics on a void (the chosen column crosses none).
fn profile(
    samples: &[Option<f64>],
    (lat0, lon0): (f64, f64),
    az: f64,
    range: (f64, f64),
    step_m: f64,
) -> Vec<(f64, f64)> {
    let (p1, l1) = (lat0.to_radians(), lon0.to_radians());
    let n = ((range.1 - range.0) / step_m) as usize;
    (0..=n)
        .filter_map(|i| {
            let d = range.0 + i as f64 * step_m;
            let delta = d / R;
            let p2 = (p1.sin() * delta.cos() + p1.cos() * delta.sin() * az.cos()).asin();
            let l2 =
                l1 + (az.sin() * delta.sin() * p1.cos()).atan2(delta.cos() - p1.sin() * p2.sin());
            let (r, c) = (
                (23.0 - p2.to_degrees()) * 1200.0,
                (l2.to_degrees() + 160.0) * 1200.0,
            );
            if !(0.0..1200.0).contains(&r) || !(0.0..1200.0).contains(&c) {
                return None;
            }
            let (r0, c0) = (r as usize, c as usize);
            let at = |i: usize, j: usize| samples[i * 1201 + j].expect("a void on the profile");
            let (tr, tc) = (r - r0 as f64, c - c0 as f64);
            let top = at(r0, c0) + (at(r0, c0 + 1) - at(r0, c0)) * tc;
            let bottom = at(r0 + 1, c0) + (at(r0 + 1, c0 + 1) - at(r0 + 1, c0)) * tc;
            Some((d, top + (bottom - top) * tr))
        })
        .collect()
}

fn render(scene: &Scene) -> Film {
    let atm = atmosphere(scene);
    let options = RenderOptions {
        quiet: true,
        samples_per_pixel: Some(1),
        ..RenderOptions::default()
    };
    let tracer = prepare_tracer(scene, Some(&atm), &options).unwrap();
    render_scene(scene, tracer.as_ref(), &options).unwrap()
}

#[test]
fn the_kauai_skyline_stands_where_the_reference_transfer_curve_puts_it() {
    // The column 0.3° west of south: its great circle crosses no void of the tile, and the
    // skyline there is the Nā Pali–Alaka'i rim ≈ 34 km away at ≈ 1.3 km. The terrain is drawn
    // pure red without haze (the geometry is the shipped scene's) so it can be told from sky.
    let mut scene = crate::scenes::load_scene("fig17_kauai_fata_morgana.toml");
    scene.sky.aerial = None;
    let t = scene.terrain.as_mut().unwrap();
    t.palette.rock_rgb = [1.0, 0.0, 0.0];
    let (lat0, lon0) = (t.observer_lat_deg, t.observer_lon_deg);
    let film = render(&scene);
    let frame = scene.camera.frame();
    let pixel_deg = scene.camera.hfov_rad.to_degrees() / scene.camera.width as f64;
    let x = scene.camera.width / 2 + (0.3 / pixel_deg).round() as u32;
    let is_red = |p: [f32; 4]| p[0] > 0.5 && p[1] < 0.1 && p[2] < 0.1;
    let top = (0..film.height)
        .find(|&y| is_red(film.pixel(x, y)))
        .expect("no terrain in the column");
    // The skyline's apparent elevation: the lowest at which the reference ray from the camera
    // clears the profile everywhere (bisection; the column's azimuth at the skyline row).
    let az = frame
        .view_direction(x as f64 + 0.5, top as f64 + 0.5)
        .azimuth_offset_rad()
        + scene.camera.heading_rad;
    let samples = raw_samples();
    let ground = profile(&samples, (lat0, lon0), az, (25_000.0, 50_000.0), 5.0);
    // The tile ends at 22° N, 50 km south of the camera: the profile reaches it.
    assert!(ground.len() > 4_990, "{} profile points", ground.len());
    let distances: Vec<f64> = ground.iter().map(|&(d, _)| d).collect();
    let atm = atmosphere(&scene);
    let column = SyntheticAtmosphere::from_file(&data_dir().join("fata_morgana.toml")).unwrap();
    let index = atmosphere_index(&atm, BreakSource::Synthetic(&column));
    let h0 = scene.camera.height_m;
    let clears = |alpha: f64| {
        let reach = reference_heights(&index, R, 40_000.0, h0, alpha, &distances);
        reach
            .iter()
            .zip(&ground)
            .all(|(r, &(_, z))| r.height_m().is_none_or(|h| h > z))
    };
    let (lo, hi) = bisect(1.5f64.to_radians(), 2.5f64.to_radians(), 24, clears);
    let skyline = 0.5 * (lo + hi);
    // The rendered top row is the first whose pixel-centre ray does not clear the skyline.
    let predicted = (0..film.height)
        .find(|&y| {
            frame
                .view_direction(x as f64 + 0.5, y as f64 + 0.5)
                .elevation_rad
                <= skyline
        })
        .unwrap();
    eprintln!(
        "column {x}: skyline {:.5}° (reference), rendered top row {top}, predicted {predicted}",
        skyline.to_degrees()
    );
    assert!(
        top.abs_diff(predicted) <= 1,
        "rendered skyline row {top}, reference transfer curve {predicted}"
    );
}
