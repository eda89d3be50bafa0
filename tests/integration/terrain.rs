//! Terrain: the elevation-model readers against files written from known samples, and rendered
//! ridges of known geometry against line–sphere geometry (straight rays and the
//! constant-curvature model's effective radius R/(1−k)), the hidden base included; on a calm
//! sea a ridge's mirror image ends where the sphere's reflection geometry puts it.

use std::path::Path;

use ghostship::render::{ConstantCurvatureRays, Film, RenderOptions, StraightRays, render_scene};
use ghostship::scene::{Dem, Scene};

use crate::support::dem::{Grid, hgt_bytes, write_geotiff};

pub(crate) const R: f64 = 6_371_000.0;
/// Metres per degree of latitude on the scene's sphere.
const M_PER_DEG: f64 = R * std::f64::consts::PI / 180.0;
const OBSERVER: (f64, f64) = (45.0, 10.0);

pub(crate) fn quiet() -> RenderOptions {
    RenderOptions {
        quiet: true,
        ..RenderOptions::default()
    }
}

#[test]
fn hgt_reader_gives_known_samples_at_their_latitude_and_longitude() {
    let dir = tempfile::tempdir().unwrap();
    let f = |r: usize, c: usize| -> i16 {
        if (r, c) == (600, 601) {
            -32768
        } else {
            ((r * 7 + c * 3) % 3000) as i16 - 100
        }
    };
    let path = dir.path().join("N10W020.hgt");
    std::fs::write(&path, hgt_bytes(f)).unwrap();
    let dem = Dem::from_file(&path).unwrap();
    assert_eq!((dem.rows, dem.cols), (1201, 1201));
    // Row r lies at 11° − r/1200°, column c at −20° + c/1200°.
    for (r, c) in [(0, 0), (1200, 1200), (17, 1103), (599, 3), (1000, 600)] {
        let (lat, lon) = (11.0 - r as f64 / 1200.0, -20.0 + c as f64 / 1200.0);
        let h = dem.height_at(lat, lon).unwrap();
        assert!((h - f(r, c) as f64).abs() < 1e-6, "({r}, {c}): {h}");
    }
    // Halfway between two samples of a row: their mean.
    let mid = dem
        .height_at(11.0 - 5.0 / 1200.0, -20.0 + 5.5 / 1200.0)
        .unwrap();
    assert!((mid - 0.5 * (f(5, 5) + f(5, 6)) as f64).abs() < 1e-6);
    // The void and what borders it have no height; off the tile neither.
    assert_eq!(dem.height_at(11.0 - 0.5, -20.0 + 601.0 / 1200.0), None);
    assert_eq!(dem.height_at(11.01, -19.5), None);
}

#[test]
fn hgt_reader_refuses_wrong_sizes_and_names() {
    let dir = tempfile::tempdir().unwrap();
    let good = hgt_bytes(|_, _| 5);
    for (name, bytes, field) in [
        ("N10E020.hgt", &good[..good.len() - 2], "file size"),
        ("N10E020.hgt", &good[..1000], "file size"),
        ("tile.hgt", &good[..], "file name"),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let err = Dem::from_file(&path).unwrap_err().to_string();
        assert!(err.contains(name) && err.contains(field), "{err}");
    }
}

/// A 30 × 20 f32 grid from 46.0° N, 9.0° E in steps of 0.01° × 0.02°, height 10·row + col.
fn small_grid(heights: &[f32]) -> Grid<'_> {
    Grid {
        rows: 30,
        cols: 20,
        north_lat_deg: 46.0,
        west_lon_deg: 9.0,
        lat_step_deg: 0.01,
        lon_step_deg: 0.02,
        heights_m: heights,
    }
}

#[test]
fn geotiff_reader_gives_known_samples_and_refuses_projected_or_unplaced_grids() {
    let dir = tempfile::tempdir().unwrap();
    let heights: Vec<f32> = (0..600).map(|k| (10 * (k / 20) + k % 20) as f32).collect();
    let grid = small_grid(&heights);
    let path = dir.path().join("grid.tif");
    write_geotiff(&path, &grid, 2, true);
    let dem = Dem::from_file(&path).unwrap();
    for (r, c) in [(0usize, 0usize), (29, 19), (12, 7)] {
        let (lat, lon) = (46.0 - 0.01 * r as f64, 9.0 + 0.02 * c as f64);
        let h = dem.height_at(lat, lon).unwrap();
        assert!((h - (10 * r + c) as f64).abs() < 1e-4, "({r}, {c}): {h}");
    }
    let projected = dir.path().join("utm.tif");
    write_geotiff(&projected, &grid, 1, true);
    let err = Dem::from_file(&projected).unwrap_err().to_string();
    assert!(
        err.contains("utm.tif") && err.contains("GTModelTypeGeoKey") && err.contains("projected"),
        "{err}"
    );
    let unplaced = dir.path().join("unplaced.tif");
    write_geotiff(&unplaced, &grid, 2, false);
    let err = Dem::from_file(&unplaced).unwrap_err().to_string();
    assert!(
        err.contains("unplaced.tif") && err.contains("ModelTiepointTag"),
        "{err}"
    );
    let bytes = std::fs::read(&path).unwrap();
    let truncated = dir.path().join("cut.tif");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let err = Dem::from_file(&truncated).unwrap_err().to_string();
    assert!(err.contains("cut.tif"), "{err}");
}

/// An east–west ridge north of the observer: ground rising from 0 at `distance_m` − 10 m to
/// `height_m` at `distance_m`, flat for 1 km, then sea; 10 m grid north–south, 0.001° east–west.
fn ridge_scene(dir: &Path, distance_m: f64, height_m: f64, camera: &str) -> Scene {
    ridge_scene_with(dir, distance_m, height_m, camera, "")
}

/// [`ridge_scene`] with more scene text (cards) after the terrain section.
pub(crate) fn ridge_scene_with(
    dir: &Path,
    distance_m: f64,
    height_m: f64,
    camera: &str,
    extra: &str,
) -> Scene {
    let camera = format!("{camera}\nhfov_deg = 0.5\nwidth = 400\nheight = 200");
    ridge_scene_coloured(dir, distance_m, height_m, &camera, [1.0, 0.0, 0.0], extra)
}

/// [`ridge_scene_with`] with the whole `[camera]` table's body given and rock of colour
/// `rock_rgb`.
pub(crate) fn ridge_scene_coloured(
    dir: &Path,
    distance_m: f64,
    height_m: f64,
    camera: &str,
    rock_rgb: [f64; 3],
    extra: &str,
) -> Scene {
    let rows = 150u32;
    let cols = 41u32;
    let first = distance_m - 200.0; // distance of the southernmost row
    let north_d = first + 10.0 * (rows - 1) as f64;
    let mut heights = Vec::new();
    for r in 0..rows {
        let d = north_d - 10.0 * r as f64;
        let z = if (distance_m..=distance_m + 1000.0).contains(&d) {
            height_m
        } else {
            0.0
        };
        heights.extend(std::iter::repeat_n(z as f32, cols as usize));
    }
    let grid = Grid {
        rows,
        cols,
        north_lat_deg: OBSERVER.0 + north_d / M_PER_DEG,
        west_lon_deg: OBSERVER.1 - 0.02,
        lat_step_deg: 10.0 / M_PER_DEG,
        lon_step_deg: 0.001,
        heights_m: &heights,
    };
    write_geotiff(&dir.join("ridge.tif"), &grid, 2, true);
    // Rock lit from the zenith (pure red: a flat top shows [1, 0, 0]).
    let text = format!(
        "[camera]\n{camera}\n\
         [terrain]\ndem = \"ridge.tif\"\nobserver_lat_deg = {}\nobserver_lon_deg = {}\n\
         rock_rgb = {rock_rgb:?}\nsnow_line_m = 1e5\nice_slope_deg = 90\n\
         light_elevation_deg = 90\n{extra}",
        OBSERVER.0, OBSERVER.1
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    Scene::from_file(&path).unwrap()
}

pub(crate) fn is_terrain(p: [f32; 4]) -> bool {
    p[0] > 0.3 && p[1] < 0.1 && p[2] < 0.1
}

/// Rows of the centre column showing terrain.
pub(crate) fn terrain_rows(film: &Film) -> Vec<u32> {
    (0..film.height)
        .filter(|&y| is_terrain(film.pixel(film.width / 2, y)))
        .collect()
}

/// Apparent elevation of the point at height `h` and ground distance `d` from a camera at `h0`,
/// straight rays over a sphere of radius `r`: from (r+h)·cos(θ+α) = (r+h0)·cos α, θ = d/r.
pub(crate) fn geometric_elevation(h0: f64, h: f64, d: f64, r: f64) -> f64 {
    let theta = d / r;
    (((r + h) * theta.cos() - (r + h0)) / ((r + h) * theta.sin())).atan()
}

/// First film row (centre column, pitch `pitch`) whose centre lies at or below elevation `alpha`.
pub(crate) fn first_row_below(scene: &Scene, alpha: f64) -> i64 {
    let f = scene.camera.frame().focal_px;
    let boundary = 0.5 * scene.camera.height as f64 - f * (alpha - scene.camera.pitch_rad).tan();
    (boundary - 0.5).ceil() as i64
}

#[test]
fn a_ridge_top_appears_at_its_geometric_elevation() {
    for k in [0.0, 0.17] {
        let dir = tempfile::tempdir().unwrap();
        let (d, h, h0) = (15_000.0, 60.0, 10.0);
        let scene = ridge_scene(
            dir.path(),
            d,
            h,
            &format!("height_m = {h0}\npitch_deg = 0.1"),
        );
        let tracer = ConstantCurvatureRays::new(k, R).unwrap();
        let film = render_scene(&scene, &tracer, &quiet()).unwrap();
        let rows = terrain_rows(&film);
        let top = *rows.first().expect("ridge not visible") as i64;
        let predicted = first_row_below(&scene, geometric_elevation(h0, h, d, R / (1.0 - k)));
        assert!(
            (top - predicted).abs() <= 1,
            "k = {k}: ridge top at row {top}, geometry puts it at {predicted}"
        );
    }
}

#[test]
fn the_part_of_a_ridge_below_the_horizon_is_hidden() {
    // From 10 m the sea horizon is 11.3 km away and hides the lowest (30 − 11.3)²/2R ≈ 27 m
    // of anything at 30 km (straight rays).
    let (d, h0) = (30_000.0, 10.0);
    let dip = -(R / (R + h0)).acos();
    for (h, visible) in [(100.0, true), (20.0, false)] {
        let dir = tempfile::tempdir().unwrap();
        let scene = ridge_scene(dir.path(), d, h, &format!("height_m = {h0}"));
        let tracer = ConstantCurvatureRays::new(0.0, R).unwrap();
        let film = render_scene(&scene, &tracer, &quiet()).unwrap();
        let rows = terrain_rows(&film);
        if !visible {
            assert!(rows.is_empty(), "{h} m ridge shows in rows {rows:?}");
            continue;
        }
        let top = *rows.first().expect("ridge not visible") as i64;
        let bottom = *rows.last().unwrap() as i64;
        let top_predicted = first_row_below(&scene, geometric_elevation(h0, h, d, R));
        let first_sea = first_row_below(&scene, dip);
        assert!((top - top_predicted).abs() <= 1, "{top} vs {top_predicted}");
        // The ridge stands on the horizon: its lowest row is the last above the sea.
        assert!(
            (bottom + 1 - first_sea).abs() <= 1,
            "ridge bottom at row {bottom}, the sea starts at {first_sea}"
        );
        assert!(rows.windows(2).all(|w| w[1] == w[0] + 1), "{rows:?}");
    }
}

#[test]
fn cards_and_terrain_compose_in_depth_order() {
    // A green card 60 m tall in front of the 60 m ridge at 15 km hides it; the same card 5 km
    // behind the ridge is hidden where the ridge stands and shows above it.
    let (d, h, h0) = (15_000.0, 60.0, 10.0);
    let is_green = |p: [f32; 4]| p[1] > 0.5 && p[0] < 0.1;
    for (card_m, in_front) in [(10_000.0, true), (20_000.0, false)] {
        let dir = tempfile::tempdir().unwrap();
        let green = image::RgbaImage::from_pixel(8, 8, image::Rgba([0, 255, 0, 255]));
        green.save(dir.path().join("green.png")).unwrap();
        let card = format!(
            "[[cards]]\nimage = \"green.png\"\ndistance_m = {card_m}\nwidth_m = 500\n\
             height_m = 200\n"
        );
        let scene = ridge_scene_with(
            dir.path(),
            d,
            h,
            &format!("height_m = {h0}\npitch_deg = 0.1"),
            &card,
        );
        let tracer = ConstantCurvatureRays::new(0.0, R).unwrap();
        let film = render_scene(&scene, &tracer, &quiet()).unwrap();
        let ridge_top = first_row_below(&scene, geometric_elevation(h0, h, d, R));
        let x = film.width / 2;
        let below = film.pixel(x, (ridge_top + 3) as u32);
        let above = film.pixel(x, (ridge_top - 3) as u32);
        assert!(
            is_green(above),
            "card {card_m} m: above the ridge {above:?}"
        );
        if in_front {
            assert!(is_green(below), "card {card_m} m: over the ridge {below:?}");
        } else {
            assert!(
                is_terrain(below),
                "card {card_m} m: over the ridge {below:?}"
            );
        }
    }
}

#[test]
fn a_calm_sea_mirrors_a_ridge_where_the_sphere_geometry_puts_it() {
    // A red ridge 15 m high at 10 km seen from 10 m over a mirror sea, straight rays: the
    // lowest red row is the mirror image of the ridge's near top edge, which the law of
    // reflection on the sphere puts at about −(10 + 15)/10 000 rad (the sphere's curvature
    // lowers it by some 10 %; the waterline is near −10/10 000).
    let (d, h, h0) = (10_000.0, 15.0, 10.0);
    let sea = |extra: &str| {
        format!("[atmosphere]\nstraight = true\n[sea]\nwave_slope_deg = 0.0\n{extra}\n")
    };
    let camera = format!("height_m = {h0}\npitch_deg = -0.06");
    let expected = crate::support::mirror_elevation_rad(h0, h, d, R);
    // Sanity of the reference.
    assert!((expected * d / -(h0 + h) - 1.0).abs() < 0.15, "{expected}");
    let dir = tempfile::tempdir().unwrap();
    let scene = ridge_scene_with(dir.path(), d, h, &camera, &sea(""));
    let frame = scene.camera.frame();
    let pixel_rad = 1.0 / frame.focal_px;
    let x = scene.camera.width / 2;
    let elevation = |row: f64| frame.view_direction(x as f64 + 0.5, row).elevation_rad;
    for exact in [false, true] {
        let options = RenderOptions { exact, ..quiet() };
        let film = render_scene(&scene, &StraightRays::new(R).unwrap(), &options).unwrap();
        let rows = terrain_rows(&film);
        // The ridge and its image touch at the waterline: one run of rows.
        assert!(rows.windows(2).all(|w| w[1] == w[0] + 1), "{rows:?}");
        let top = *rows.first().expect("ridge not visible") as i64;
        let predicted = first_row_below(&scene, geometric_elevation(h0, h, d, R));
        assert!(
            (top - predicted).abs() <= 1,
            "exact={exact}: {top} vs {predicted}"
        );
        let y = *rows.last().unwrap() as f64;
        let (e_sea, e_red) = (elevation(y + 1.5), elevation(y + 0.5));
        assert!(
            e_sea - 0.5 * pixel_rad <= expected && expected <= e_red + 0.5 * pixel_rad,
            "exact={exact}: image edge between {e_sea} and {e_red}, expected {expected}"
        );
        assert!(e_red < -1.5 * h0 / d, "exact={exact}: {e_red}");
    }
    // Without reflections the sea below the waterline shows no ridge.
    let dir = tempfile::tempdir().unwrap();
    let off = ridge_scene_with(dir.path(), d, h, &camera, &sea("reflections = false"));
    let film = render_scene(&off, &StraightRays::new(R).unwrap(), &quiet()).unwrap();
    let waterline = first_row_below(&off, geometric_elevation(h0, 0.0, d, R)) as u32;
    let below: Vec<u32> = terrain_rows(&film)
        .into_iter()
        .filter(|&y| y > waterline + 2)
        .collect();
    assert!(
        below.is_empty(),
        "ridge rows below the waterline: {below:?}"
    );
}

/// On a wind-roughened sea (rms slope 3°) a black ridge's mirror image is the slope
/// distribution's blur of it, under straight rays: in every sea row of the centre column, what
/// the ridge takes from the sea (the render with it minus the render without) equals the
/// independent quadrature of `support::rough_sea` (20 000 slopes, a reflected ray blocked where
/// it passes at or below the ridge's near top edge) as `support::rough_sea::
/// assert_profile_matches` bounds it, and so does the column's sum. The 8 midpoint facet
/// classes the renderer used before showed the ridge as separate sharp copies instead.
#[test]
fn a_rough_sea_blurs_a_ridges_mirror_image_as_the_slope_distribution_does() {
    use crate::support::rough_sea::{
        assert_profile_matches, blurred_reflection, straight_height_m, straight_sea_hit,
    };
    let (d, h, h0, slope_deg) = (15_000.0, 60.0, 10.0, 3.0f64);
    // −2° … 0°, the ridge (4 km wide, ±7.6°) across the frame; black rock.
    let camera =
        format!("height_m = {h0}\npitch_deg = -1.0\nhfov_deg = 4.0\nwidth = 400\nheight = 200");
    let sea = format!("[atmosphere]\nstraight = true\n[sea]\nwave_slope_deg = {slope_deg}\n");
    let dir = tempfile::tempdir().unwrap();
    let with = ridge_scene_coloured(dir.path(), d, h, &camera, [0.0; 3], &sea);
    let mut without = with.clone();
    without.terrain = None;
    let frame = with.camera.frame();
    let sigma_along = slope_deg.to_radians().tan() / 2f64.sqrt();
    let x = with.camera.width / 2;
    let tracer = StraightRays::new(R).unwrap();
    for exact in [false, true] {
        let options = RenderOptions { exact, ..quiet() };
        let a = render_scene(&with, &tracer, &options).unwrap();
        let b = render_scene(&without, &tracer, &options).unwrap();
        assert_eq!(a.stats.non_finite_samples, 0);
        let mut rows = Vec::new();
        for y in 0..a.height {
            let alpha = frame
                .view_direction(x as f64 + 0.5, y as f64 + 0.5)
                .elevation_rad;
            let Some((d0, g)) = straight_sea_hit(h0, alpha, R) else {
                continue;
            };
            let blocked = |e: f64| match straight_height_m(e, d - d0, R) {
                Some(top) if top <= h => with.sky.radiance(e).map(|v| -v),
                _ => [0.0; 3],
            };
            let expected =
                blurred_reflection(g, sigma_along, with.sea.refractive_index, 20_000, blocked);
            let (p, q) = (a.pixel(x, y), b.pixel(x, y));
            let rendered = [0, 1, 2].map(|c| f64::from(p[c]) - f64::from(q[c]));
            rows.push((y, rendered, expected));
        }
        assert!(rows.len() > 150, "exact={exact}: {} sea rows", rows.len());
        let strongest = rows.iter().map(|r| r.2[2].abs()).fold(0.0, f64::max);
        assert!(
            strongest > 0.02,
            "exact={exact}: a faint image: {strongest}"
        );
        let expected: Vec<[f64; 3]> = rows.iter().map(|r| r.2).collect();
        let rendered: Vec<[f64; 3]> = rows.iter().map(|r| r.1).collect();
        assert_profile_matches(&rendered, &expected, strongest, exact);
    }
}

#[test]
fn an_orthophoto_colours_the_ground_it_covers_and_the_palette_the_rest() {
    // Over the red ridge at 15 km, an orthophoto 4 pixels wide (yellow, yellow, blue, blue) across
    // 0.0012° of longitude centred north of the observer (47 m each side at 15 km, 3.1 mrad of
    // the frame's ±4.4 mrad): between the centres of its two yellow pixels the ground is the
    // photograph's yellow exactly (not relit), between the blue ones blue; beyond its edges the
    // palette's lit red.
    let (d, h, h0) = (15_000.0, 60.0, 10.0);
    let dir = tempfile::tempdir().unwrap();
    let (yellow, blue) = ([255u8, 200, 0], [0u8, 64, 255]);
    let photo =
        image::RgbImage::from_fn(4, 1, |c, _| image::Rgb(if c < 2 { yellow } else { blue }));
    photo.save(dir.path().join("photo.png")).unwrap();
    let (south, north) = (
        OBSERVER.0 + (d - 300.0) / M_PER_DEG,
        OBSERVER.0 + (d + 1_300.0) / M_PER_DEG,
    );
    let (west, east) = (OBSERVER.1 - 0.0006, OBSERVER.1 + 0.0006);
    let extra = format!(
        "orthophoto = \"photo.png\"\northophoto_bounds_deg = [{south}, {west}, {north}, {east}]\n"
    );
    let camera = format!("height_m = {h0}\npitch_deg = 0.1");
    let scene = ridge_scene_with(dir.path(), d, h, &camera, &extra);
    let film = render_scene(&scene, &StraightRays::new(R).unwrap(), &quiet()).unwrap();
    let linear = |c: [u8; 3]| c.map(|v| ghostship::scene::card::srgb_to_linear(v as f64 / 255.0));
    // The ridge's rows in column x (anything that is not sky: the sky is brighter in blue).
    let ridge_rows = |x: u32| -> Vec<u32> {
        (0..film.height)
            .filter(|&y| {
                let p = film.pixel(x, y);
                p[2] < 0.5 * p[0].max(p[1]) || p[0] < 0.05
            })
            .collect()
    };
    let frame = scene.camera.frame();
    // Columns whose azimuth offset puts them `east_m` east of north at the ridge.
    let column = |east_m: f64| {
        let az = east_m / d;
        (0..film.width)
            .min_by(|&a, &b| {
                let da = (frame
                    .view_direction(a as f64 + 0.5, 100.0)
                    .azimuth_offset_rad()
                    - az)
                    .abs();
                let db = (frame
                    .view_direction(b as f64 + 0.5, 100.0)
                    .azimuth_offset_rad()
                    - az)
                    .abs();
                da.total_cmp(&db)
            })
            .unwrap()
    };
    let m_per_deg_lon = M_PER_DEG * OBSERVER.0.to_radians().cos();
    for (east_deg, expected) in [(-0.0003, linear(yellow)), (0.0003, linear(blue))] {
        let x = column(east_deg * m_per_deg_lon);
        let rows = ridge_rows(x);
        assert!(rows.len() > 10, "x = {x}: ridge rows {rows:?}");
        let p = film.pixel(x, rows[rows.len() / 2]);
        for c in 0..3 {
            assert!(
                (p[c] as f64 - expected[c]).abs() < 1e-5,
                "x = {x}: {p:?}, the photograph's {expected:?}"
            );
        }
    }
    // Beyond the photograph: the palette's red, lit.
    for x in [
        column(-0.0009 * m_per_deg_lon),
        column(0.0009 * m_per_deg_lon),
    ] {
        let rows = ridge_rows(x);
        let p = film.pixel(x, rows[rows.len() / 2]);
        assert!(is_terrain(p), "x = {x}: {p:?}");
    }
}

#[test]
fn orthophoto_settings_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let ok = ridge_scene_with(dir.path(), 15_000.0, 60.0, "height_m = 10", "");
    assert!(ok.terrain.unwrap().orthophoto.is_none());
    let path = dir.path().join("scene.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let cases = [
        (
            "orthophoto_bounds_deg = [45.0, 9.0, 46.0, 11.0]\n",
            "terrain.orthophoto_bounds_deg",
        ),
        ("orthophoto = \"missing.png\"\n", "missing.png"),
    ];
    image::RgbImage::new(2, 2)
        .save(dir.path().join("p.png"))
        .unwrap();
    let inverted = "orthophoto = \"p.png\"\northophoto_bounds_deg = [46.0, 9.0, 45.0, 11.0]\n";
    for (extra, named) in cases.into_iter().chain([(inverted, "south < north")]) {
        std::fs::write(&path, format!("{text}{extra}")).unwrap();
        let err = Scene::from_file(&path).unwrap_err().to_string();
        assert!(
            err.contains(named) && err.contains("scene.toml"),
            "{extra}: {err}"
        );
    }
    // Bounds default to the model's cells.
    std::fs::write(&path, format!("{text}orthophoto = \"p.png\"\n")).unwrap();
    let scene = Scene::from_file(&path).unwrap();
    let terrain = scene.terrain.unwrap();
    let photo = terrain.orthophoto.as_ref().unwrap();
    assert_eq!(photo.bounds_deg, terrain.model_area_deg());
}
