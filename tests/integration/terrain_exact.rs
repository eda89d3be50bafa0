//! Terrain through refracting air, fan and exact mode (`--exact`: every pixel sample traced on
//! its own by the 3-D integrator, no fan): exact and fan renders of terrain seen through a paper
//! atmosphere agree but for sub-pixel shifts of edges; a ridge's top lies where an independent
//! tracer's transfer curve puts it (and, with closed-form rays, where line–sphere geometry puts
//! it); terrain seen through haze has the contrast of the optical depth along the refracted
//! ray's own path.

use ghostship::render::{ConstantCurvatureRays, Film, RenderOptions, prepare_tracer, render_scene};
use ghostship::scene::Scene;

use crate::aerial::{film_chord_tau, green_extinction_per_m};
use crate::scenes::atmosphere;
use crate::support::bisect;
use crate::support::data::data_dir;
use crate::support::films::differing_and_edge_pixels;
use crate::support::reference::{
    BreakSource, atmosphere_index, reference_density_paths, reference_heights,
};
use crate::terrain::{
    R, first_row_below, geometric_elevation, is_terrain, ridge_scene_with, terrain_rows,
};
use ghostship::profile::SyntheticAtmosphere;

/// The `[atmosphere]` table of the paper's superior mirage (+10 K over 15 m at 100 m).
fn superior_mirage() -> String {
    let path = data_dir().join("superior_mirage.toml");
    format!(
        "[atmosphere]\nsynthetic = {:?}\n",
        path.display().to_string()
    )
}

/// `scene` rendered through its own atmosphere with the renderer's tracer: `exact` per sample
/// (`ExactRays`, the 3-D integrator), else the fan (`CurvedRays`).
fn render_real(scene: &Scene, exact: bool) -> Film {
    let atm = atmosphere(scene);
    let options = RenderOptions {
        exact,
        quiet: true,
        samples_per_pixel: Some(1),
        ..RenderOptions::default()
    };
    let tracer = prepare_tracer(scene, Some(&atm), &options).unwrap();
    render_scene(scene, tracer.as_ref(), &options).unwrap()
}

#[test]
fn exact_and_fan_renders_of_a_ridge_in_a_superior_mirage_agree() {
    // From 50 m the layer at 100 m bends back every ray within ±0.13° of the horizontal: a
    // 45 m ridge at 60 km, far below the 25 km geometric horizon, shows only through the
    // layer (its parts above ≈ 29.5 m, inverted). A nearer 60 m ridge at 15 km would hide it,
    // so the frame looks past its own one ridge; the sea fills the rest.
    let dir = tempfile::tempdir().unwrap();
    let camera = "height_m = 50\npitch_deg = 0.05";
    let mut scene = ridge_scene_with(dir.path(), 60_000.0, 45.0, camera, &superior_mirage());
    scene.camera.width = 160;
    scene.camera.height = 80;
    let fan = render_real(&scene, false);
    let exact = render_real(&scene, true);
    assert!(exact.stats.sample_rays > 0 && exact.stats.fan_rays == 0);
    assert!(fan.stats.fan_rays > 0);
    let (fan_rows, exact_rows) = (terrain_rows(&fan), terrain_rows(&exact));
    assert!(
        exact_rows.len() >= 3,
        "the ridge's mirage shows in rows {exact_rows:?} (fan: {fan_rows:?})"
    );
    let (diff, edges) = differing_and_edge_pixels(&fan, &exact, 0.02);
    eprintln!(
        "terrain fan/exact: {diff} differing pixels, {edges} edge pixels, terrain rows fan \
         {fan_rows:?} exact {exact_rows:?}"
    );
    // As for the paper scenes (scenes::fast_vs_exact): the fan places features within 0.1 px
    // of per-sample tracing, so at most a quarter of the edge pixels may change, and only at
    // edges (differing_and_edge_pixels panics on a pixel that differs inside a region).
    assert!(
        diff * 4 <= edges.max(4),
        "{diff} pixels differ, {edges} edge pixels"
    );
}

#[test]
fn a_ridge_top_appears_where_the_reference_tracer_puts_it_in_exact_mode() {
    // A 60 m ridge 15 km away from 10 m through the superior-mirage air, rendered by the 3-D
    // integrator per sample; the top's apparent elevation is where the independent reference
    // tracer's ray from the camera reaches 60 m at 15 km (bisection on the elevation).
    let (d, h, h0) = (15_000.0, 60.0, 10.0);
    let dir = tempfile::tempdir().unwrap();
    let camera = format!("height_m = {h0}\npitch_deg = 0.1");
    let mut scene = ridge_scene_with(dir.path(), d, h, &camera, &superior_mirage());
    // A narrow strip of the frame (same pixel size): the test reads the centre column.
    let half = (0.5 * scene.camera.hfov_rad).tan() * 40.0 / scene.camera.width as f64;
    scene.camera.hfov_rad = 2.0 * half.atan();
    scene.camera.width = 40;
    let film = render_real(&scene, true);
    assert!(film.stats.sample_rays > 0);
    let atm = atmosphere(&scene);
    let column = SyntheticAtmosphere::from_file(&data_dir().join("superior_mirage.toml")).unwrap();
    let index = atmosphere_index(&atm, BreakSource::Synthetic(&column));
    let height_at = |alpha: f64| {
        reference_heights(&index, R, 40_000.0, h0, alpha, &[d])[0]
            .height_m()
            .unwrap_or(f64::NEG_INFINITY)
    };
    let (lo, hi) = bisect(0.0, 0.01, 50, |a| height_at(a) > h);
    let alpha_top = 0.5 * (lo + hi);
    let predicted = first_row_below(&scene, alpha_top);
    let top = *terrain_rows(&film).first().expect("ridge not visible") as i64;
    eprintln!("exact ridge top row {top}, reference {predicted} ({alpha_top:.6e} rad)");
    assert!(
        (top - predicted).abs() <= 1,
        "ridge top at row {top}, the reference tracer puts it at {predicted}"
    );
    // Refraction matters here: straight rays would put the top elsewhere.
    let straight = first_row_below(&scene, geometric_elevation(h0, h, d, R));
    assert!(straight != predicted, "rows {straight} and {predicted}");
}

#[test]
fn a_ridge_top_appears_at_its_geometric_elevation_in_exact_mode() {
    // Closed-form rays (straight, and the constant-curvature model's effective radius) traced
    // per sample, the renderer's exact path, against line–sphere geometry.
    for k in [0.0, 0.17] {
        let dir = tempfile::tempdir().unwrap();
        let (d, h, h0) = (15_000.0, 60.0, 10.0);
        let scene = ridge_scene_with(
            dir.path(),
            d,
            h,
            &format!("height_m = {h0}\npitch_deg = 0.1"),
            "",
        );
        let tracer = ConstantCurvatureRays::new(k, R).unwrap();
        let options = RenderOptions {
            exact: true,
            quiet: true,
            ..RenderOptions::default()
        };
        let film = render_scene(&scene, &tracer, &options).unwrap();
        assert!(film.stats.sample_rays > 0);
        let rows = terrain_rows(&film);
        let top = *rows.first().expect("ridge not visible") as i64;
        let predicted = first_row_below(&scene, geometric_elevation(h0, h, d, R / (1.0 - k)));
        assert!(
            (top - predicted).abs() <= 1,
            "k = {k}: ridge top at row {top}, geometry puts it at {predicted}"
        );
        assert!(rows.windows(2).all(|w| w[1] == w[0] + 1), "{rows:?}");
        assert!(is_terrain(film.pixel(film.width / 2, top as u32)));
    }
}

/// A 20 m ridge 30 km away seen from 10 m through the Novaya Zemlya ground inversion (exactly
/// critical: a level ray follows the Earth) in haze of 30 km visibility, rendered red: its green
/// channel is the path radiance alone, so its contrast against the saturated horizon sky
/// (aerosol optical depth 1: radiance 1) is e^(−τ) with τ along the ray's own path, computed
/// from the independent reference tracer's heights — within 1 %, fan and exact, and far from
/// what the straight chord would give.
#[test]
fn haze_towards_terrain_follows_the_refracted_ray_fan_and_exact() {
    let (d, h, visibility_m) = (30_000.0, 20.0, 30_000.0);
    let nz = data_dir().join("novaya_zemlya.toml");
    let extra = format!(
        "[atmosphere]\nsynthetic = {:?}\n[sky]\naerosol_optical_depth = 1.0\n\
         visibility_km = {}\n",
        nz.display().to_string(),
        visibility_m / 1000.0
    );
    let dir = tempfile::tempdir().unwrap();
    let mut scene = ridge_scene_with(dir.path(), d, h, "height_m = 10", &extra);
    let half = (0.5 * scene.camera.hfov_rad).tan() * 40.0 / scene.camera.width as f64;
    scene.camera.hfov_rad = 2.0 * half.atan();
    scene.camera.width = 40;
    let atm = atmosphere(&scene);
    let column = SyntheticAtmosphere::from_file(&nz).unwrap();
    let index = atmosphere_index(&atm, BreakSource::Synthetic(&column));
    let beta = green_extinction_per_m(visibility_m);
    // Where the ridge is: the same view without haze (which does not move it).
    let mut clear = scene.clone();
    clear.sky.aerial = None;
    let rows = terrain_rows(&render_real(&clear, false));
    assert!(rows.len() >= 3, "ridge rows {rows:?}");
    // The middle of the ridge's face: its ray meets the ground within 10 m of d.
    let y = rows[rows.len() / 2];
    for exact in [false, true] {
        let film = render_real(&scene, exact);
        assert_eq!(film.stats.sample_rays > 0, exact);
        let (_, alpha) = scene
            .camera
            .frame()
            .direction(film.width as f64 / 2.0 + 0.5, y as f64 + 0.5);
        let contrast = 1.0 - film.pixel(film.width / 2, y)[1] as f64;
        let along = reference_density_paths(&index, 10.0, alpha, d, 10.0, [8_000.0, 1_000.0]);
        let tau = beta[0] * along[0] + beta[1] * along[1];
        let relative = contrast / (-tau).exp() - 1.0;
        eprintln!(
            "exact = {exact}: contrast {contrast} vs e^(−τ) {} ({relative:+.5})",
            (-tau).exp()
        );
        assert!(relative.abs() < 0.01, "exact = {exact}: {relative:+e}");
        let chord_tau = film_chord_tau(&scene, alpha, d, &atm, beta);
        assert!(
            (-chord_tau).exp() / (-tau).exp() < 0.97,
            "chord τ {chord_tau} vs path τ {tau}"
        );
    }
}
