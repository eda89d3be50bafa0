//! The sea's reflections: on a mirror sea (calm) the mirror image of a card under straight rays
//! ends where the sphere's reflection geometry puts it (`support::mirror_elevation_rad`:
//! bisection on the law of reflection, independently of the renderer's sea fan), in the fan and
//! the exact render alike,
//! and through the Novaya Zemlya inversion where the independent reference tracer's rays put it;
//! the sun's Cox–Munk glitter on a wind-roughened sea is centred under the sun and below the
//! horizon; and frames with reflections do not depend on the thread count.

use ghostship::render::{Film, RenderOptions, StraightRays, render_scene};
use ghostship::scene::Scene;

use crate::support::bisect;
use crate::support::films::max_channel_difference;

const R: f64 = 6_371_000.0;
const CAMERA_M: f64 = 10.0;
const CARD_M: f64 = 5_000.0;
const CARD_TOP_M: f64 = 15.0;

/// A straight-ray scene from `CAMERA_M`: `camera` and `sea` are the bodies of those tables,
/// `rest` more tables (cards, sun); a red 8×8 card image `red.png` is available.
fn scene(camera: &str, sea: &str, rest: &str) -> (tempfile::TempDir, Scene) {
    let dir = tempfile::tempdir().unwrap();
    let image = image::RgbaImage::from_pixel(8, 8, image::Rgba([255, 0, 0, 255]));
    image.save(dir.path().join("red.png")).unwrap();
    let text = format!(
        "[camera]\nheight_m = {CAMERA_M}\n{camera}\n[atmosphere]\nstraight = true\n\
         [earth]\nradius_m = {R}\n[sea]\n{sea}\n{rest}\n"
    );
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = Scene::from_file(&path).unwrap();
    (dir, scene)
}

fn render(scene: &Scene, exact: bool) -> Film {
    let options = RenderOptions {
        quiet: true,
        exact,
        samples_per_pixel: Some(1),
        ..RenderOptions::default()
    };
    let film = render_scene(scene, &StraightRays::new(R).unwrap(), &options).unwrap();
    assert_eq!(film.stats.non_finite_samples, 0);
    film
}

/// [`support::mirror_elevation_rad`] from this file's camera on its sphere.
fn mirror_elevation_rad(top_m: f64, distance_m: f64) -> f64 {
    crate::support::mirror_elevation_rad(CAMERA_M, top_m, distance_m, R)
}

/// The lowest row of column `x` whose pixel is the red card (green < half the reflected sky's
/// just below it): the bottom of the mirror image.
fn lowest_red_row(film: &Film, x: u32) -> u32 {
    let sea_g = film.pixel(x, film.height - 1)[1];
    (0..film.height)
        .rev()
        .find(|&y| {
            let p = film.pixel(x, y);
            p[1] < 0.5 * sea_g && p[0] > 2.0 * p[1]
        })
        .expect("no red card pixel in the column")
}

/// The image edge at column `x` lies between the centres of row `y` (red) and `y + 1` (the sky's
/// reflection); assert that `expected` (rad) is there, within half a pixel, and return the two
/// rows' elevations (below, above).
fn assert_edge_at(
    frame: &ghostship::scene::camera::CameraFrame,
    x: u32,
    y: u32,
    expected: f64,
    what: &str,
) -> (f64, f64) {
    let pixel_rad = 1.0 / frame.focal_px;
    let at = |row: f64| frame.view_direction(x as f64 + 0.5, row).elevation_rad;
    let (e_sky, e_red) = (at(y as f64 + 1.5), at(y as f64 + 0.5));
    assert!(
        e_sky - 0.5 * pixel_rad <= expected && expected <= e_red + 0.5 * pixel_rad,
        "{what}: image edge between {e_sky} and {e_red}, expected {expected}"
    );
    (e_sky, e_red)
}

#[test]
fn calm_mirror_image_of_a_card_lies_where_the_sphere_geometry_puts_it() {
    let card = format!(
        "[[cards]]\nimage = \"red.png\"\ndistance_m = {CARD_M}\nwidth_m = 20\n\
         height_m = {CARD_TOP_M}\nbase_m = 0\n"
    );
    let camera = "pitch_deg = -0.12\nhfov_deg = 1.0\nwidth = 400\nheight = 200";
    let (_dir, calm) = scene(camera, "wave_slope_deg = 0.0", &card);
    let expected = mirror_elevation_rad(CARD_TOP_M, CARD_M);
    // Sanity of the reference: about −(h_c + H)/D, below the direct waterline.
    assert!(
        (expected + (CAMERA_M + CARD_TOP_M) / CARD_M).abs() < 2e-4,
        "{expected}"
    );
    let frame = calm.camera.frame();
    for exact in [false, true] {
        let film = render(&calm, exact);
        let x = film.width / 2;
        let y = lowest_red_row(&film, x);
        let (_, e_red) = assert_edge_at(&frame, x, y, expected, &format!("exact={exact}"));
        // Well below the direct waterline (≈ −h_c/D): a mirror image, not the card itself.
        assert!(e_red < -1.5 * CAMERA_M / CARD_M, "{e_red}");
        // Fresnel-weighted: darker than the card itself (red 1.0 in linear units) by F < 1,
        // brighter than the water (0.004).
        let mirrored = film.pixel(x, y - 2);
        assert!(mirrored[0] < 1.0 && mirrored[0] > 0.5, "{mirrored:?}");
    }
    // Without reflections the same pixel is sea.
    let (_dir2, off) = scene(camera, "wave_slope_deg = 0.0\nreflections = false", &card);
    let film = render(&off, false);
    let y = lowest_red_row(&render(&calm, false), film.width / 2);
    let p = film.pixel(film.width / 2, y - 2);
    assert!(p[0] < 2.0 * p[1], "no mirror image expected: {p:?}");
}

#[test]
fn fan_and_exact_renders_agree_with_reflections() {
    let card = format!(
        "[[cards]]\nimage = \"red.png\"\ndistance_m = {CARD_M}\nwidth_m = 20\n\
         height_m = {CARD_TOP_M}\nbase_m = 0\n"
    );
    let camera = "pitch_deg = -0.12\nhfov_deg = 1.0\nwidth = 200\nheight = 100";
    for sea in [
        "wave_slope_deg = 0.0",
        "wave_slope_deg = 0.2",
        "wind_speed_m_s = 0.0",
    ] {
        let (_dir, s) = scene(camera, sea, &card);
        let (fan, exact) = (render(&s, false), render(&s, true));
        let mut off = 0;
        for (a, b) in fan.pixels.iter().zip(&exact.pixels) {
            if max_channel_difference(*a, *b) > 0.02 {
                off += 1;
            }
        }
        // Only pixels on an edge may differ (a sub-pixel shift there): one or two rows.
        assert!(off <= 2 * fan.width as usize, "{sea}: {off} pixels differ");
    }
}

#[test]
fn glitter_is_centred_under_the_sun_and_below_the_horizon() {
    let sun_azimuth_deg = 3.0;
    let sun = format!("[sun]\nelevation_deg = 8.0\nazimuth_deg = {sun_azimuth_deg}\n");
    // A 20° frame from +2° to −8°: the sun (8°) is out of it, its glitter in it.
    let camera = "pitch_deg = -3.0\nhfov_deg = 20.0\nwidth = 400\nheight = 200";
    let (_dir, s) = scene(camera, "wind_speed_m_s = 5.0", &sun);
    let film = render(&s, false);
    let frame = s.camera.frame();
    let luminance = |p: [f32; 4]| p[0] + p[1] + p[2];
    let mut best = (0u32, 0u32, f32::MIN);
    let mut column_sums = vec![0.0f64; film.width as usize];
    for y in 0..film.height {
        for x in 0..film.width {
            let l = luminance(film.pixel(x, y));
            column_sums[x as usize] += l as f64;
            if l > best.2 {
                best = (x, y, l);
            }
        }
    }
    let (bx, by, _) = best;
    let brightest = frame.view_direction(bx as f64 + 0.5, by as f64 + 0.5);
    assert!(brightest.elevation_rad < 0.0, "{}", brightest.elevation_rad);
    let column = (0..film.width as usize)
        .max_by(|&a, &b| column_sums[a].total_cmp(&column_sums[b]))
        .unwrap();
    let horizon_row = film.height / 5; // 2° of 10° from the top: the horizon
    let az = frame
        .view_direction(column as f64 + 0.5, (horizon_row + 20) as f64)
        .azimuth_offset_rad()
        .to_degrees();
    let pixel_deg = 20.0 / film.width as f64;
    assert!(
        (az - sun_azimuth_deg).abs() <= 1.5 * pixel_deg,
        "glitter column at {az}°, sun at {sun_azimuth_deg}°"
    );
    // The glitter stands out: its column is far brighter than one 8° away from the sun.
    let away = film.width as usize / 2 - (5.0 / pixel_deg) as usize;
    assert!(column_sums[column] > 3.0 * column_sums[away]);
    // On a mirror sea there is no glitter: only the disc's mirror image, at ≈ −8° (the frame's
    // bottom edge); above −7° the sea is the reflected sky.
    let (_dir2, calm) = scene(camera, "wave_slope_deg = 0.0", &sun);
    let calm_film = render(&calm, false);
    let mut calm_max = 0.0f32;
    for y in 0..calm_film.height {
        for x in 0..calm_film.width {
            let d = frame.view_direction(x as f64 + 0.5, y as f64 + 0.5);
            if d.elevation_rad > -7f64.to_radians() {
                calm_max = calm_max.max(luminance(calm_film.pixel(x, y)));
            }
        }
    }
    assert!(calm_max < 4.0, "{calm_max}");
}

#[test]
fn reflections_do_not_depend_on_the_thread_count() {
    let card = format!(
        "[[cards]]\nimage = \"red.png\"\ndistance_m = {CARD_M}\nwidth_m = 20\n\
         height_m = {CARD_TOP_M}\nbase_m = 0\n[sun]\nelevation_deg = 0.2\nazimuth_deg = 0.3\n"
    );
    let camera = "pitch_deg = -0.12\nhfov_deg = 1.0\nwidth = 200\nheight = 100";
    for sea in ["wave_slope_deg = 0.0", "wind_speed_m_s = 3.0"] {
        let (_dir, s) = scene(camera, sea, &card);
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| render(&s, false).pixels)
        };
        assert!(
            run(1) == run(2),
            "{sea}: pixels differ between 1 and 2 threads"
        );
    }
}

#[test]
fn a_mirror_sea_shows_the_sun_disc_mirrored_below_the_horizon() {
    // Sun 0.3° up, 0.2° right; a mirror sea; no cards. Straight rays from 10 m: the image of a
    // point at infinity at elevation e lies at −e − 2d/R ≈ −e (d = 10 m / e ≈ 2 km: 0.6 mrad).
    let (e_s, a_s) = (0.3f64.to_radians(), 0.2f64.to_radians());
    let sun = format!(
        "[sun]\nelevation_deg = {}\nazimuth_deg = {}\n",
        e_s.to_degrees(),
        a_s.to_degrees()
    );
    let camera = "pitch_deg = -0.2\nhfov_deg = 2.0\nwidth = 400\nheight = 200";
    let (_dir, s) = scene(camera, "wave_slope_deg = 0.0", &sun);
    let film = render(&s, false);
    let frame = s.camera.frame();
    let luminance = |p: [f32; 4]| p[0] + p[1] + p[2];
    let mut best = (0u32, 0u32, f32::MIN);
    for y in 0..film.height {
        for x in 0..film.width {
            let d = frame.view_direction(x as f64 + 0.5, y as f64 + 0.5);
            let l = luminance(film.pixel(x, y));
            if d.elevation_rad < -1e-3 && l > best.2 {
                best = (x, y, l);
            }
        }
    }
    let d = frame.view_direction(best.0 as f64 + 0.5, best.1 as f64 + 0.5);
    let radius = 0.5 * 0.533f64.to_radians();
    let expected = -e_s - 2.0 * (CAMERA_M / e_s) / R;
    assert!(best.2 > 100.0, "no bright mirror image: {}", best.2);
    assert!(
        (d.elevation_rad - expected).abs() < radius,
        "{} vs {expected}",
        d.elevation_rad
    );
    assert!(
        (d.azimuth_offset_rad() - a_s).abs() < radius,
        "{}",
        d.azimuth_offset_rad()
    );
}

/// Through a refracting atmosphere (the Novaya Zemlya inversion, whose rays bend almost with the
/// Earth), the calm sea's mirror image of a card's top lies where the independent reference
/// tracer puts it. By the mirror symmetry of a spherically stratified field, the ray reflected
/// at ground distance d rises as the camera ray came down, mirrored about d: its height at
/// distance D is the camera ray's height at 2d − D when 2d ≥ D, else the height at D − 2d of the
/// camera ray continued backwards, which is the camera's ray launched at −α. So the expected
/// image comes from rays traced from the camera alone, not from the renderer's sea fan.
#[test]
fn calm_mirror_image_through_a_refracting_atmosphere_lies_where_the_reference_rays_put_it() {
    use crate::support::data::data_dir;
    use crate::support::reference::{BreakSource, RefReach, atmosphere_index, reference_heights};
    use ghostship::profile::SyntheticAtmosphere;
    use ghostship::refractivity::RefractiveAtmosphere;
    use std::sync::Arc;

    let r = ghostship::units::EARTH_RADIUS_M;
    let (camera_m, card_m, top_m) = (10.0, 20_000.0, 15.0);
    let path = data_dir().join("novaya_zemlya.toml");
    let nz = SyntheticAtmosphere::from_file(&path).unwrap();
    let atm = RefractiveAtmosphere::new(Arc::new(nz.clone()), 550.0).unwrap();
    let index = atmosphere_index(&atm, BreakSource::Synthetic(&nz));
    let height_at =
        |alpha: f64, x: f64| reference_heights(&index, r, 40e3, camera_m, alpha, &[x])[0];
    // Where the camera ray at `alpha` meets the sea (bisection on the ground distance).
    let sea_hit_m = |alpha: f64| {
        let (lo, hi) = bisect(0.0, 60_000.0, 40, |x| {
            matches!(height_at(alpha, x), RefReach::GroundBefore)
        });
        0.5 * (lo + hi)
    };
    let mirrored_height_m = |alpha: f64| {
        let d = sea_hit_m(alpha);
        let reach = if 2.0 * d >= card_m {
            height_at(alpha, 2.0 * d - card_m)
        } else {
            height_at(-alpha, card_m - 2.0 * d)
        };
        reach.height_m().expect("the mirrored ray reaches the card")
    };
    // Steeper rays meet the sea nearer and their reflections pass the card higher.
    let (lo, hi) = bisect(-0.003, -0.0006, 40, |alpha| {
        mirrored_height_m(alpha) < top_m
    });
    let expected = 0.5 * (lo + hi);
    assert_eq!((camera_m, r), (CAMERA_M, R));
    let straight = mirror_elevation_rad(top_m, card_m);

    let dir = tempfile::tempdir().unwrap();
    let image = image::RgbaImage::from_pixel(8, 8, image::Rgba([255, 0, 0, 255]));
    image.save(dir.path().join("red.png")).unwrap();
    let text = format!(
        "[camera]\nheight_m = {camera_m}\npitch_deg = -0.12\nhfov_deg = 1.0\nwidth = 400\n\
         height = 200\n[atmosphere]\nsynthetic = {path:?}\n[earth]\nradius_m = {r}\n\
         [sea]\nwave_slope_deg = 0.0\n[[cards]]\nimage = \"red.png\"\ndistance_m = {card_m}\n\
         width_m = 20\nheight_m = {top_m}\nbase_m = 0\n"
    );
    let scene_path = dir.path().join("scene.toml");
    std::fs::write(&scene_path, text).unwrap();
    let scene = Scene::from_file(&scene_path).unwrap();
    let frame = scene.camera.frame();
    let pixel_rad = 1.0 / frame.focal_px;
    eprintln!(
        "mirror image of the card top: {expected:.7} rad through the inversion, {straight:.7} rad \
         with straight rays ({:.1} px apart)",
        (expected - straight) / pixel_rad
    );
    // The test means something only if refraction moves the image by several pixels.
    assert!((expected - straight).abs() > 3.0 * pixel_rad);
    let loaded = scene.atmosphere.load().unwrap();
    for exact in [false, true] {
        let options = RenderOptions {
            quiet: true,
            exact,
            samples_per_pixel: Some(1),
            ..RenderOptions::default()
        };
        let tracer = ghostship::render::prepare_tracer(
            &scene,
            loaded.as_ref().map(|a| &a.refractive),
            &options,
        )
        .unwrap();
        let film = render_scene(&scene, tracer.as_ref(), &options).unwrap();
        let x = film.width / 2;
        let y = lowest_red_row(&film, x);
        let (e_sky, e_red) = assert_edge_at(&frame, x, y, expected, &format!("exact={exact}"));
        eprintln!("exact={exact}: image edge between {e_sky:.7} and {e_red:.7}");
    }
}

/// Fig. 12's ducted sun (true centre 1.5° below the horizon, camera 100 m in the critical
/// Novaya Zemlya inversion) on the default Cox–Munk sea: the glitter at each sea point lies where
/// Cox–Munk puts it for the sun seen from *that* point. A point d from the camera has its
/// vertical tilted by d/R, so the sun's true elevation there is −1.5° + d/R·cos φ, and its
/// apparent elevation e is where a ray launched from the sea leaves towards it (Bouguer's
/// integral, `support::reference`, not the renderer's tracer); the camera ray's sea point comes
/// from the independent reference rays. With the facet tilt tan²β of the half vector between
/// the sun and the ray, the glitter is exp(−tan²β/σ²) times at most ~10⁵ of the sun's
/// irradiance: where tan²β/σ² > 40 it must be absent (the renderer had added the camera foot's
/// 1.54° refraction to every point, so far out its sun stood ~1° too high and the glitter
/// spread across the whole frame), and where it is < 1 present.
#[test]
fn ducted_sun_glitter_lies_where_cox_munk_puts_it_for_each_sea_points_own_sun() {
    use crate::support::data::repo_file;
    use crate::support::reference::{
        BreakSource, RefReach, atmosphere_index, bouguer_escape_elevation, reference_heights,
    };
    use ghostship::jobs::render::render_film;
    use ghostship::profile::SyntheticAtmosphere;
    use ghostship::refractivity::RefractiveAtmosphere;
    use ghostship::render::render_tracer_config;
    use std::sync::Arc;

    let path = repo_file("data/scenes/fig12_novaya_zemlya.toml");
    let scene = Scene::from_file(&path).unwrap();
    let mut away = scene.clone();
    // The same frame with the sun 90° off to the side: no glitter can reach it.
    away.sun.as_mut().unwrap().azimuth_rad = 90f64.to_radians();
    let loaded = scene.atmosphere.load().unwrap();
    let options = RenderOptions {
        quiet: true,
        samples_per_pixel: Some(1),
        ..RenderOptions::default()
    };
    let film = render_film(&scene, loaded.as_ref(), &options).unwrap();
    let base = render_film(&away, loaded.as_ref(), &options).unwrap();

    let r = scene.earth_radius_m;
    let sun = scene.sun.unwrap();
    let sigma2 = scene.sea.wave_slope_rad.tan().powi(2);
    let h0 = scene.camera.height_m;
    let nz = SyntheticAtmosphere::from_file(&repo_file("data/novaya_zemlya.toml")).unwrap();
    let atm = RefractiveAtmosphere::new(Arc::new(nz.clone()), 550.0).unwrap();
    let index = atmosphere_index(&atm, BreakSource::Synthetic(&nz));
    let top_m = render_tracer_config(r).top_m;
    let n = |h: f64| atm.exact(h).0;
    let below = |alpha: f64, x: f64| {
        matches!(
            reference_heights(&index, r, 40e3, h0, alpha, &[x])[0],
            RefReach::GroundBefore
        )
    };
    // The sun's apparent elevation from the sea surface at true elevation `s`.
    let apparent = |s: f64| {
        let (lo, hi) = bisect(1e-7, 0.2, 40, |a| {
            bouguer_escape_elevation(&n, r, top_m, 0.0, a, 4000) >= s
        });
        0.5 * (lo + hi)
    };
    let frame = scene.camera.frame();
    let (mut absent, mut present) = (0, 0);
    for y in (0..film.height).step_by(4) {
        let centre = frame.view_direction(0.5 * film.width as f64, y as f64 + 0.5);
        let alpha = centre.elevation_rad;
        if !below(alpha, 600e3) {
            continue; // sky, or the sea too near the horizon to locate
        }
        // The sea point: bisection on the ground distance; its grazing angle from Bouguer's
        // invariant n(h)(R + h) cos = const.
        let (lo, hi) = bisect(0.0, 600e3, 40, |x| below(alpha, x));
        let d = 0.5 * (lo + hi);
        let grazing = (n(h0) * (r + h0) * alpha.cos() / (n(0.0) * r)).acos();
        for x in (0..film.width).step_by(8) {
            let dir = frame.view_direction(x as f64 + 0.5, y as f64 + 0.5);
            let phi = sun.azimuth_rad - dir.azimuth_offset_rad();
            let e = apparent(sun.elevation_rad + d / r * phi.cos());
            let (se, ce) = e.sin_cos();
            let h = [
                ce * phi.cos() - grazing.cos(),
                ce * phi.sin(),
                se + grazing.sin(),
            ];
            let x2 = (h[0] * h[0] + h[1] * h[1]) / (h[2] * h[2]) / sigma2;
            let glitter = max_channel_difference(film.pixel(x, y), base.pixel(x, y));
            if x2 > 40.0 {
                absent += 1;
                assert!(
                    glitter < 1e-3,
                    "({x}, {y}): d {:.1} km, e {:.4}°, tan²β/σ² {x2:.1}: glitter {glitter}",
                    d / 1e3,
                    e.to_degrees()
                );
            } else if x2 < 1.0 {
                present += 1;
                assert!(
                    glitter > 0.05,
                    "({x}, {y}): tan²β/σ² {x2:.2}: glitter {glitter}"
                );
            }
        }
    }
    eprintln!("{absent} samples without glitter, {present} with");
    assert!(absent > 100 && present > 10, "{absent} {present}");
}

/// On a wind-roughened sea (rms slope 3°) the mirror image of a tall uniform card, under
/// straight rays, is the slope distribution's blur of it, not copies of it at a few slopes: in
/// every row of a column through it, what the card adds to the sea (the render with it minus
/// the render without) equals the independent quadrature of `support::rough_sea` (20 000
/// slopes, the card met where the straight reflected ray is within its height at its range) as
/// `support::rough_sea::assert_profile_matches` bounds it, and so does the column's sum; the
/// profile rises towards the horizon without an interior extremum. The 8 midpoint facet
/// classes the renderer used before jumped by a class's whole share between rows instead (a
/// row off by a tenth of the image's strongest value).
#[test]
fn a_rough_sea_blurs_a_cards_mirror_image_as_the_slope_distribution_does() {
    use crate::support::rough_sea::{
        assert_profile_matches, blurred_reflection, straight_height_m, straight_sea_hit,
    };
    let (distance_m, top_m, slope_deg) = (3_000.0, 300.0, 3.0f64);
    let card = format!(
        "[[cards]]\nimage = \"red.png\"\ndistance_m = {distance_m}\nwidth_m = 4000\n\
         height_m = {top_m}\nbase_m = 0\n"
    );
    // −5.5° … −0.5°: sea in every row, the card (up to 5.7° above the horizon) out of view.
    let camera = "pitch_deg = -3.0\nhfov_deg = 10.0\nwidth = 400\nheight = 200";
    let sea = format!("wave_slope_deg = {slope_deg}");
    let (_dir, with) = scene(camera, &sea, &card);
    let (_dir2, without) = scene(camera, &sea, "");
    let frame = with.camera.frame();
    let sigma_along = slope_deg.to_radians().tan() / 2f64.sqrt();
    for exact in [false, true] {
        let (a, b) = (render(&with, exact), render(&without, exact));
        let x = a.width / 2;
        let mut rendered = Vec::new();
        let mut expected = Vec::new();
        for y in 0..a.height {
            let alpha = frame
                .view_direction(x as f64 + 0.5, y as f64 + 0.5)
                .elevation_rad;
            let (d, g) = straight_sea_hit(CAMERA_M, alpha, R).expect("every row is sea");
            let card_over_sky = |e: f64| match straight_height_m(e, distance_m - d, R) {
                Some(h) if (0.0..=top_m).contains(&h) => {
                    let sky = with.sky.radiance(e);
                    [1.0 - sky[0], -sky[1], -sky[2]]
                }
                _ => [0.0; 3],
            };
            let (p, q) = (a.pixel(x, y), b.pixel(x, y));
            rendered.push([0, 1, 2].map(|c| f64::from(p[c]) - f64::from(q[c])));
            expected.push(blurred_reflection(
                g,
                sigma_along,
                with.sea.refractive_index,
                20_000,
                card_over_sky,
            ));
        }
        // The green channel carries the image (a red card hides the whitish sky).
        let strongest = expected.iter().map(|v| v[1].abs()).fold(0.0, f64::max);
        assert!(
            strongest > 0.05,
            "exact={exact}: a faint image: {strongest}"
        );
        assert_profile_matches(&rendered, &expected, strongest, exact);
        // Darkest (the card's image strongest) at the top row, fading monotonically downwards.
        let green: Vec<f64> = rendered.iter().map(|v| v[1]).collect();
        let extrema = green
            .windows(3)
            .filter(|w| (w[1] - w[0]) * (w[2] - w[1]) < -1e-12)
            .count();
        let reference_extrema = expected
            .windows(3)
            .filter(|w| (w[1][1] - w[0][1]) * (w[2][1] - w[1][1]) < -1e-12)
            .count();
        assert_eq!(reference_extrema, 0, "the reference profile is monotone");
        assert_eq!(
            extrema, 0,
            "exact={exact}: {extrema} interior extrema: {green:?}"
        );
    }
}

/// The rough sea's blurred mirror images are continuous in the camera: fig01b's scene (US 1976,
/// two ships on the default Cox–Munk sea) at 200×100, 1 spp, rendered from camera heights
/// 10.0 m, 10.00005 m, … 10.0005 m. A 50 µm move shifts every point in view by under 0.001
/// pixel (50 µm seen from the nearest sea point in view, ≈ 2 km away, subtends 2.5e-8 rad; a
/// pixel is 8.7e-5 rad), and the
/// fan places features to `RenderOptions::tolerance_px` = 0.1 pixel, so between neighbouring
/// heights no pixel may change by more than 0.1 of its contrast to its four neighbours (its
/// change were the image to move a whole pixel). The blurred images used to jump by up to a
/// third of their value between such heights (the sea fan's rays stopped once above the
/// ships, and whether a blurred part ending on such a ray still saw the ship's top depended on
/// rounding).
#[test]
fn rough_sea_mirror_images_change_continuously_with_the_camera_height() {
    use crate::support::data::data_file;
    use crate::support::films::neighbour_contrast;
    use ghostship::render::prepare_tracer;
    let path = data_file("scenes/fig01b_horizon_curved.toml");
    let films: Vec<Film> = (0..=10)
        .map(|k| {
            let mut scene = Scene::from_file(&path).unwrap();
            assert!(scene.sea.wave_slope_rad > 0.0, "fig01b has a rough sea");
            scene.camera.height_m = 10.0 + 5e-5 * f64::from(k);
            (scene.camera.width, scene.camera.height) = (200, 100);
            let atmosphere = scene.atmosphere.load().unwrap();
            let options = RenderOptions {
                quiet: true,
                samples_per_pixel: Some(1),
                ..RenderOptions::default()
            };
            let refractive = atmosphere.as_ref().map(|a| &a.refractive);
            let tracer = prepare_tracer(&scene, refractive, &options).unwrap();
            let film = render_scene(&scene, tracer.as_ref(), &options).unwrap();
            assert_eq!(film.stats.non_finite_samples, 0);
            film
        })
        .collect();
    let mut worst: Option<(f32, u32, u32, usize)> = None;
    for (k, pair) in films.windows(2).enumerate() {
        let (a, b) = (&pair[0], &pair[1]);
        for y in 0..a.height {
            for x in 0..a.width {
                let (p, q) = (a.pixel(x, y), b.pixel(x, y));
                let change = (0..3).map(|c| (p[c] - q[c]).abs()).fold(0.0, f32::max);
                // (1e-6: the film's f32 rounding.)
                let excess = change - 0.1 * neighbour_contrast(a, x, y) - 1e-6;
                if excess > worst.map_or(0.0, |w| w.0) {
                    worst = Some((excess, x, y, k));
                }
            }
        }
    }
    if let Some((excess, x, y, k)) = worst {
        panic!(
            "pixel ({x}, {y}) changed by {excess} more than 0.1 of its contrast between camera \
             heights {} and {} m",
            10.0 + 5e-5 * k as f64,
            10.0 + 5e-5 * (k + 1) as f64
        );
    }
}
