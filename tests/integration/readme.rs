//! README's gallery numbers, computed from the shipped scene files with the library (tracer,
//! transfer curves, `find_images`, sea horizons; no renders): each number the gallery states is
//! asserted to the digits README prints it with, so a change of scene, atmosphere or tracer that
//! moves one shows here.

use ghostship::analysis::Image;
use ghostship::render::curved::render_tracer_config;
use ghostship::tracer::UniformIndex;
use ghostship::tracer::{StratifiedIndex, Termination, Tracer, TracerConfig};
use ghostship::units::ARCMIN_PER_RAD;

use super::scenes::{atmosphere, load_scene, predicted_images};
use super::tracer::sea_horizon_rad;

fn tracer_for<S: StratifiedIndex>(index: &S, radius_m: f64) -> Tracer<'_, S> {
    let cfg = TracerConfig {
        earth_radius_m: radius_m,
        ..TracerConfig::default()
    };
    Tracer::new(index, cfg).unwrap()
}

/// `value` rounds to `printed` at the digits printed (half a unit of the last digit).
fn rounds_to(value: f64, printed: &str) -> bool {
    let target: f64 = printed.parse().unwrap();
    let decimals = printed.split_once('.').map_or(0, |(_, d)| d.len());
    (value - target).abs() <= 0.5 * 10f64.powi(-(decimals as i32))
}

fn show(images: &[Image]) -> String {
    images
        .iter()
        .map(|i| format!("{:.1}–{:.1} m", i.height_at_min_m, i.height_at_max_m))
        .collect::<Vec<_>>()
        .join(", ")
}

fn orientations(images: &[Image]) -> String {
    images
        .iter()
        .map(|i| if i.erect { 'E' } else { 'I' })
        .collect()
}

/// Every image of each card of `scene_name` (target [0, base + height] at its distance).
fn card_images(scene_name: &str) -> Vec<Vec<Image>> {
    let scene = load_scene(scene_name);
    let atm = atmosphere(&scene);
    scene
        .cards
        .iter()
        .map(|c| predicted_images(&atm, &scene, c.distance_m, c.base_m + c.height_m))
        .collect()
}

/// Height at `distance_m` of the ray that grazes the sea horizon from the scene's camera: the
/// part of a card at that distance hidden below the horizon.
fn hidden_m<S: StratifiedIndex>(tracer: &Tracer<'_, S>, h0: f64, distance_m: f64) -> f64 {
    let horizon = sea_horizon_rad(tracer, h0);
    tracer.trace(h0, horizon, &[distance_m]).unwrap().heights_m[0].expect("reaches the card")
}

#[test]
fn fig01_horizon_dip_and_hidden_hulls() {
    let scene = load_scene("fig01b_horizon_curved.toml");
    let straight_scene = load_scene("fig01_horizon_straight.toml");
    assert!(straight_scene.atmosphere.straight && !scene.atmosphere.straight);
    let h0 = scene.camera.height_m;
    let far = scene.cards[1].distance_m;
    let (r, near) = (scene.earth_radius_m, scene.cards[0].distance_m);
    // "a ship at 8 km …, one at 20 km beyond the 11.3 km geometric horizon of a 10 m camera".
    let geometric_horizon_m = r * (r / (r + h0)).acos();
    assert!(rounds_to(h0, "10") && rounds_to(near / 1000.0, "8") && rounds_to(far / 1000.0, "20"));
    assert!(
        rounds_to(geometric_horizon_m / 1000.0, "11.3"),
        "{geometric_horizon_m}"
    );
    // Straight rays: its hull hidden by ≈ 6 m of sea; dip 6.09′.
    let straight = tracer_for(&UniformIndex, r);
    let hidden_straight = hidden_m(&straight, h0, far);
    let dip_straight = -sea_horizon_rad(&straight, h0) * ARCMIN_PER_RAD;
    // Curved rays through US1976: dip 5.55′, ≈ 3.8 m hidden.
    let atm = atmosphere(&scene);
    let curved = tracer_for(&atm, r);
    let hidden_curved = hidden_m(&curved, h0, far);
    let dip_curved = -sea_horizon_rad(&curved, h0) * ARCMIN_PER_RAD;
    eprintln!(
        "fig01: hidden {hidden_straight:.3} m straight, {hidden_curved:.3} m curved; dip \
         {dip_straight:.4}′ / {dip_curved:.4}′"
    );
    assert!(rounds_to(hidden_straight, "6"), "{hidden_straight}");
    assert!(rounds_to(dip_straight, "6.09"), "{dip_straight}");
    assert!(rounds_to(dip_curved, "5.55"), "{dip_curved}");
    assert!(rounds_to(hidden_curved, "3.8"), "{hidden_curved}");
}

#[test]
fn fig02_board_magnifications() {
    // "calibration boards at 3, 6, 9 and 12 km …: vertical magnification 1.07, 1.18, 0.51, 0.23".
    let scene = load_scene("fig02_horizon_distortion.toml");
    let images = card_images("fig02_horizon_distortion.toml");
    for ((card, im), (km, m)) in scene.cards.iter().zip(&images).zip([
        ("3", "1.07"),
        ("6", "1.18"),
        ("9", "0.51"),
        ("12", "0.23"),
    ]) {
        assert!(rounds_to(card.distance_m / 1000.0, km));
        assert_eq!(orientations(im), "E", "{km} km: {im:?}");
        eprintln!("fig02 {km} km: magnification {:.4}", im[0].magnification);
        assert!(
            rounds_to(im[0].magnification, m),
            "{km} km: {}",
            im[0].magnification
        );
    }
}

#[test]
fn fig04a_ship_hull_down() {
    // "the ship hull-down by 11.5 m": one erect image of the 26 km ship, from 11.5 m up.
    let images = card_images("fig04a_superior_mirage_paper_camera.toml");
    for im in &images {
        assert_eq!(orientations(im), "E", "{im:?}");
    }
    let bottom = images[1][0].height_at_min_m;
    eprintln!("fig04a: ship visible from {bottom:.3} m");
    assert!(rounds_to(bottom, "11.5"), "{bottom}");
}

#[test]
fn fig08_board_shows_its_upper_bands_again_inverted() {
    // "the calibration board at 12 km seen from 20 m shows its 14.8–18.3 m bands a second time,
    // inverted, below an erect image".
    let scene = load_scene("fig08_inferior_mirage.toml");
    assert!(rounds_to(scene.camera.height_m, "20"));
    assert!(rounds_to(scene.cards[0].distance_m / 1000.0, "12"));
    let im = &card_images("fig08_inferior_mirage.toml")[0];
    assert_eq!(orientations(im), "EIE", "{im:?}");
    let inverted = &im[1];
    let (lo, hi) = (
        inverted.height_at_min_m.min(inverted.height_at_max_m),
        inverted.height_at_min_m.max(inverted.height_at_max_m),
    );
    eprintln!("fig08: inverted bands {lo:.3}–{hi:.3} m");
    assert!(rounds_to(lo, "14.8") && rounds_to(hi, "18.3"), "{lo}–{hi}");
}

#[test]
fn fig10_fata_morgana_images() {
    // "the ice cliff at 20 km shows three stacked images — the direct view cut flat at 59 m, an
    // inverted slice stretched 7× into towers, a squeezed erect crest — and the hull-down ship at
    // 44 km floats upside down (with a small erect copy)".
    let images = card_images("fig10_fata_morgana.toml");
    let cliff = &images[0];
    assert_eq!(orientations(cliff), "EIE", "{cliff:?}");
    eprintln!(
        "fig10: cliff cut at {:.3} m, inverted ×{:.3}, crest ×{:.3}; ship {}",
        cliff[0].height_at_max_m,
        cliff[1].magnification,
        cliff[2].magnification,
        orientations(&images[1])
    );
    assert!(rounds_to(cliff[0].height_at_max_m, "59"));
    assert!(rounds_to(cliff[1].magnification, "7"));
    assert!(cliff[2].magnification < 1.0);
    let ship = &images[1];
    assert!(ship[0].height_at_min_m > 0.0, "hull-down: {ship:?}");
    assert!(orientations(ship).ends_with("IE"), "{ship:?}");
    assert!(
        ship[ship.len() - 1].magnification < 1.0,
        "a small erect copy: {ship:?}"
    );
}

/// Apparent elevations (rad) of the rays from the scene's camera that leave towards the sun's
/// disc, as runs of a fan of `n` rays over [lo, hi] (rad), with the render's tracer settings.
fn sun_strips(scene_name: &str, lo: f64, hi: f64, n: usize) -> (Vec<(f64, f64)>, f64) {
    let scene = load_scene(scene_name);
    let sun = scene.sun.expect("a sun");
    let radius = 0.5 * sun.angular_diameter_rad;
    let atm = atmosphere(&scene);
    let t = Tracer::new(&atm, render_tracer_config(scene.earth_radius_m)).unwrap();
    let step = (hi - lo) / (n - 1) as f64;
    let (mut runs, mut open) = (Vec::new(), None);
    for i in 0..n {
        let alpha = lo + step * i as f64;
        let rec = t.trace(scene.camera.height_m, alpha, &[]).unwrap();
        let inside = rec.termination == Some(Termination::Escaped)
            && (rec.end_observer_elevation_rad - sun.elevation_rad).abs() <= radius;
        match (inside, open) {
            (true, None) => open = Some(alpha),
            (false, Some(a)) => {
                runs.push((a, alpha - step));
                open = None;
            }
            _ => {}
        }
    }
    assert!(open.is_none(), "the fan must extend past the disc");
    (runs, sun.angular_diameter_rad)
}

#[test]
fn fig12_novaya_zemlya_sun_strips() {
    let (lo, hi) = ((-0.4f64).to_radians(), 0.1f64.to_radians());
    // "the sun, its true centre 1.5° below the astronomical horizon …, is seen squeezed ≈ 32×
    // into a flat, reddened strip": one strip, the 0.533° disc in 1/32 of it.
    let scene = load_scene("fig12_novaya_zemlya.toml");
    assert!(rounds_to(
        -scene.sun.unwrap().elevation_rad.to_degrees(),
        "1.5"
    ));
    let (strips, disc) = sun_strips("fig12_novaya_zemlya.toml", lo, hi, 20_001);
    assert_eq!(strips.len(), 1, "{strips:?}");
    let squeeze = disc / (strips[0].1 - strips[0].0);
    eprintln!("fig12: squeezed {squeeze:.2}×");
    assert!(rounds_to(squeeze, "32"), "{squeeze}");
    // "three stacked, flattened strips (each squeezed 17–30×) … true centre 1.55° below": strips
    // taller than a pixel of the 400×200 frame (slivers of less are left aside).
    let scene = load_scene("fig12b_novaya_zemlya_strips.toml");
    assert!(rounds_to(
        -scene.sun.unwrap().elevation_rad.to_degrees(),
        "1.55"
    ));
    let pixel = scene.camera.hfov_rad / scene.camera.width as f64;
    let (strips, disc) = sun_strips("fig12b_novaya_zemlya_strips.toml", lo, hi, 20_001);
    let squeezes: Vec<f64> = strips
        .iter()
        .filter(|(a, b)| b - a > pixel)
        .map(|(a, b)| disc / (b - a))
        .collect();
    eprintln!(
        "fig12b: {} runs, squeezes of those over a pixel {squeezes:.2?}",
        strips.len()
    );
    assert_eq!(squeezes.len(), 3, "{strips:?}");
    assert!(
        squeezes.iter().all(|&s| (16.5..30.5).contains(&s)),
        "{squeezes:?}"
    );
}

#[test]
fn superior_mirage_duct_and_critical_angle() {
    use ghostship::refractivity::{RegimeOptions, detect_regimes, ducts};
    // "What the physics says": the +10 K layer at 100 m turns back only rays that meet it at
    // less than ≈ 0.23° (README said 0.27° until this test); the duct it forms reaches down to
    // ≈ 28 m.
    let scene = load_scene("fig04_superior_mirage.toml");
    let atm = atmosphere(&scene);
    let layers = detect_regimes(&atm, 500.0, &RegimeOptions::default());
    let found = ducts(&layers);
    assert_eq!(found.len(), 1, "{found:?}");
    let duct = &found[0];
    // The steepest ray the layer turns back, launched where M is largest below the layer (where
    // a ray from below meets the layer's bending): bisect between turned back (ground or trapped)
    // and escaped.
    let radius = scene.earth_radius_m;
    let m = |h: f64| ((atm.index_and_derivative(h).0 - 1.0) + h / radius) * 1e6;
    let h_max = (0..=4000)
        .map(|i| duct.base_agl_m + (duct.top_agl_m - duct.base_agl_m) * i as f64 / 4000.0)
        .max_by(|a, b| m(*a).total_cmp(&m(*b)))
        .unwrap();
    let t = tracer_for(&atm, radius);
    let escapes =
        |a: f64| t.trace(h_max, a, &[]).unwrap().termination == Some(Termination::Escaped);
    let critical_deg = crate::support::bisect(0.0, 2f64.to_radians(), 50, escapes)
        .0
        .to_degrees();
    let from_m = (2.0 * duct.m_deficit * 1e-6).sqrt().to_degrees();
    eprintln!(
        "superior mirage duct {:.2}–{:.2} m AGL, M deficit {:.3} (√(2ΔM) {from_m:.4}°); M largest at \
         {h_max:.2} m, steepest ray turned back from there {critical_deg:.4}°",
        duct.base_agl_m, duct.top_agl_m, duct.m_deficit
    );
    assert!(rounds_to(duct.base_agl_m, "28"), "{duct:?}");
    assert!(rounds_to(critical_deg, "0.23"), "{critical_deg}");
}

#[test]
fn flat_rows_of_the_paper_frames() {
    use ghostship::render::{FLAT_ROW_FRACTION, RenderOptions, flat_bands};
    // "each row is cut into a few bands of columns … whose elevations span less than 0.01 px
    // (one band per row of these ≤ 1.1° frames at 400×200, one to three at 1920×1080)": the
    // renderer's own band cutting, applied to every row of every curved-ray paper scene.
    let limit_px = FLAT_ROW_FRACTION * RenderOptions::default().tolerance_px;
    assert!(rounds_to(limit_px, "0.01"), "{limit_px}");
    let mut most_1080 = 0;
    for name in ghostship::verify::frames::PAPER_SCENES {
        let scene = load_scene(name);
        if scene.atmosphere.straight {
            continue; // straight rays take no fan
        }
        assert!(scene.camera.hfov_rad.to_degrees() <= 1.1, "{name}");
        for (w, h) in [(400, 200), (1920, 1080)] {
            let mut cam = scene.camera;
            (cam.width, cam.height) = (w, h);
            let frame = cam.frame();
            let limit = limit_px * cam.min_pixel_angle_rad();
            let bands: Vec<usize> = (0..h)
                .map(|y| flat_bands(&frame, y, w, limit).map_or(usize::MAX, |b| b.len()))
                .collect();
            let most = bands.iter().copied().max().unwrap_or(0);
            eprintln!("{name} {w}×{h}: at most {most} band(s) per row");
            if w == 400 {
                assert_eq!(most, 1, "{name}: one band per row at 400×200");
            } else {
                most_1080 = most_1080.max(most);
            }
        }
    }
    eprintln!("1920×1080: at most {most_1080} bands per row");
    assert_eq!(most_1080, 3, "one to three bands at 1920×1080");
}

#[test]
fn fata_morgana_from_10_m_upper_layer_only() {
    // "From 10 m only the upper layer bends rays back: they turn above 121 m and reach the sea
    // 65–82 km out. A 250 m target shows three images from 40 to 60 km, two from 65 to 90 km."
    // Turning heights from Bouguer's invariant (where n·r falls to n₀·r₀·cos α).
    let scene = load_scene("fig10_fata_morgana.toml");
    let atm = atmosphere(&scene);
    let radius = scene.earth_radius_m;
    let t = tracer_for(&atm, radius);
    let h0 = 10.0;
    let nr = |h: f64| atm.index_and_derivative(h).0 * (radius + h);
    let (mut lowest_turn, mut near, mut far) = (f64::INFINITY, f64::INFINITY, 0.0f64);
    for i in 1..=1000 {
        let alpha = (0.5 * i as f64 / 1000.0).to_radians();
        let rec = t.trace(h0, alpha, &[]).unwrap();
        if rec.termination != Some(Termination::Ground) {
            continue;
        }
        let invariant = nr(h0) * alpha.cos();
        let turn = (0..)
            .map(|k| h0 + 0.01 * k as f64)
            .find(|&h| nr(h) <= invariant || h > 1000.0)
            .unwrap();
        lowest_turn = lowest_turn.min(turn);
        near = near.min(rec.end.distance_m);
        far = far.max(rec.end.distance_m);
    }
    eprintln!(
        "Fata Morgana from 10 m: rays turned back from {lowest_turn:.2} m up, landing {:.1}–{:.1} km",
        near / 1000.0,
        far / 1000.0
    );
    let mut ten = scene.clone();
    ten.camera.height_m = h0;
    for km in (40..=90).step_by(5) {
        let im = predicted_images(&atm, &ten, km as f64 * 1000.0, 250.0);
        eprintln!("  {km} km: {} {}", orientations(&im), show(&im));
        let expected = if km <= 60 { "EIE" } else { "IE" };
        assert_eq!(orientations(&im), expected, "{km} km: {im:?}");
    }
    // The layers: +5 K centred at 80 m and +15 K at 120 m, each 15 m thick.
    assert!(
        lowest_turn > 80.0 + 7.5 && lowest_turn < 120.0 + 7.5,
        "{lowest_turn}"
    );
    assert!(lowest_turn > 121.0, "{lowest_turn}");
    assert!(
        rounds_to(near / 1000.0, "65") && rounds_to(far / 1000.0, "82"),
        "{near}–{far}"
    );
}
