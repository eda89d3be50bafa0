//! Reference images: a small set of scenes rendered small (160×80, one sample per pixel) through
//! the same path as `ghostship render` (`jobs::render::render_film`, then the PNG's sRGB
//! encoding at the default exposure) and compared with the PNGs in `tests/reference/images/`.
//!
//! This is a regression guard, not a physics check (the physics is tested against independent
//! references elsewhere): it catches any change in what is drawn. A frame passes when at most
//! [`MAX_CHANGED_FRACTION`] of its pixels differ by more than [`CHANNEL_TOLERANCE`] in any channel
//! (room for libm differences between machines, not for a moved edge). On failure the render and
//! an amplified difference image are written to `target/tmp/reference-images/` and named in the
//! message. `GHOSTSHIP_BLESS=1 cargo test --release --test integration reference_images` writes
//! the current renders as the new references (look at them before committing).

use std::path::{Path, PathBuf};

use ghostship::jobs::render::render_film;
use ghostship::output::png::{DEFAULT_EXPOSURE, film_to_srgb8};
use ghostship::render::RenderOptions;
use ghostship::scene::Scene;

use crate::support::data::data_dir;

/// Largest difference of one 8-bit channel that does not count as a change.
const CHANNEL_TOLERANCE: u8 = 2;
/// Largest share of a frame's pixels that may change.
const MAX_CHANGED_FRACTION: f64 = 0.002;
/// The size every reference is rendered at.
const SIZE: (u32, u32) = (160, 80);

/// The scenes: every kind of thing the renderer draws (straight and curved rays, the three
/// mirages, the ducted sun and its strips, the spectral path, terrain, the calm and the rough
/// sea).
const SCENES: [&str; 10] = [
    "fig01_horizon_straight",
    "fig01b_horizon_curved",
    "fig04_superior_mirage",
    "fig08_inferior_mirage",
    "fig10_fata_morgana",
    "fig12b_novaya_zemlya_strips",
    "fig13_green_flash",
    "fig14_island_terrain",
    "fig15_calm_sea",
    "fig16_sun_glitter",
];

fn reference_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/reference/images")
        .join(format!("{name}_{}x{}.png", SIZE.0, SIZE.1))
}

/// The scene rendered as `ghostship render --size 160x80 --spp 1` renders it: sRGB8 pixels.
fn render_srgb8(name: &str) -> Vec<u8> {
    let path = data_dir().join("scenes").join(format!("{name}.toml"));
    let mut scene = Scene::from_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (scene.camera.width, scene.camera.height) = SIZE;
    let atmosphere = scene
        .atmosphere
        .load()
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let options = RenderOptions {
        samples_per_pixel: Some(1),
        quiet: true,
        ..RenderOptions::default()
    };
    let film = render_film(&scene, atmosphere.as_ref(), &options)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(film.stats.non_finite_samples, 0, "{name}");
    film_to_srgb8(&film, DEFAULT_EXPOSURE)
}

fn save_rgb(path: &Path, rgb: &[u8]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::RgbImage::from_raw(SIZE.0, SIZE.1, rgb.to_vec())
        .unwrap()
        .save(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

/// Pixels (of `a` against `b`) of which some channel differs by more than the tolerance, and
/// the difference image: |a − b| × 8 per channel.
fn compare(a: &[u8], b: &[u8]) -> (usize, Vec<u8>) {
    let diff: Vec<u8> = a
        .iter()
        .zip(b)
        .map(|(&x, &y)| x.abs_diff(y).saturating_mul(8))
        .collect();
    let changed = a
        .chunks_exact(3)
        .zip(b.chunks_exact(3))
        .filter(|(p, q)| {
            p.iter()
                .zip(*q)
                .any(|(x, y)| x.abs_diff(*y) > CHANNEL_TOLERANCE)
        })
        .count();
    (changed, diff)
}

#[test]
fn reference_images_match_within_tolerance() {
    let bless = std::env::var("GHOSTSHIP_BLESS").is_ok_and(|v| v == "1");
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("reference-images");
    let pixels = (SIZE.0 * SIZE.1) as usize;
    let mut failures = Vec::new();
    for name in SCENES {
        let got = render_srgb8(name);
        let reference = reference_path(name);
        if bless {
            save_rgb(&reference, &got);
            eprintln!("blessed {}", reference.display());
            continue;
        }
        let want = match image::open(&reference) {
            Ok(img) => img.to_rgb8(),
            Err(e) => {
                failures.push(format!(
                    "{name}: cannot read {} ({e}); render it with GHOSTSHIP_BLESS=1",
                    reference.display()
                ));
                continue;
            }
        };
        assert_eq!(want.dimensions(), SIZE, "{}", reference.display());
        let (changed, diff) = compare(&got, want.as_raw());
        let fraction = changed as f64 / pixels as f64;
        eprintln!("{name}: {changed} of {pixels} pixels changed ({fraction:.2e})");
        if fraction > MAX_CHANGED_FRACTION {
            let (render, diff_path) = (
                out.join(format!("{name}_render.png")),
                out.join(format!("{name}_diff.png")),
            );
            save_rgb(&render, &got);
            save_rgb(&diff_path, &diff);
            failures.push(format!(
                "{name}: {changed} pixels changed ({fraction:.2e} > {MAX_CHANGED_FRACTION}); \
                 render {}, difference ×8 {}",
                render.display(),
                diff_path.display()
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn a_moved_edge_is_a_change() {
    // The comparison itself: one row of a frame shifted by a pixel is well above the share.
    let w = SIZE.0 as usize * 3;
    let a: Vec<u8> = (0..SIZE.0 as usize * SIZE.1 as usize * 3)
        .map(|i| if i / w < 40 { 200 } else { 20 })
        .collect();
    let mut b = a.clone();
    b[40 * w..41 * w].fill(200);
    let (changed, diff) = compare(&a, &b);
    assert_eq!(changed, SIZE.0 as usize);
    assert!(changed as f64 / (SIZE.0 * SIZE.1) as f64 > MAX_CHANGED_FRACTION);
    assert_eq!(diff[40 * w], 255);
    // Noise of one or two levels is not a change.
    let c: Vec<u8> = a.iter().map(|&v| v + 2).collect();
    assert_eq!(compare(&a, &c).0, 0);
}
