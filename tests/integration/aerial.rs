//! Aerial perspective: a card seen through haze has Koschmieder's contrast e^(−βd) and a card
//! far beyond the visibility fades into the horizon sky beside it (straight rays: the geometry is
//! exact, so the only approximation left is the quadrature along the chord); and through a
//! refracting inversion the haze follows the ray's own path, not the chord.

use ghostship::profile::SyntheticAtmosphere;
use ghostship::render::{Film, RenderOptions, StraightRays, render_scene};
use ghostship::scene::Scene;

use crate::support::reference::{BreakSource, atmosphere_index, reference_density_paths};

const R: f64 = 6_371_000.0;

/// Render a 400 × 200, 0.5° frame from 10 m, pitch 0, with straight rays and one opaque card of
/// colour `rgb` at ground distance `distance_m`, centred on the line of sight at elevation 0 and
/// 2 mrad wide and high; `sky` is the body of the `[sky]` table.
fn render_card(rgb: [u8; 3], distance_m: f64, sky: &str) -> Film {
    let dir = tempfile::tempdir().unwrap();
    let image = image::RgbaImage::from_pixel(8, 8, image::Rgba([rgb[0], rgb[1], rgb[2], 255]));
    image.save(dir.path().join("card.png")).unwrap();
    // Height of the horizontal line of sight at the card: 10 m + d²/2R.
    let centre_m = 10.0 + distance_m * distance_m / (2.0 * R);
    let size_m = 0.002 * distance_m;
    let text = format!(
        "[camera]\nheight_m = 10\nhfov_deg = 0.5\nwidth = 400\nheight = 200\n\
         [atmosphere]\nstraight = true\n[earth]\nradius_m = {R}\n[sky]\n{sky}\n\
         [[cards]]\nimage = \"card.png\"\ndistance_m = {distance_m}\nwidth_m = {size_m}\n\
         height_m = {size_m}\nbase_m = {}\n",
        centre_m - 0.5 * size_m
    );
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = Scene::from_file(&path).unwrap();
    let options = RenderOptions {
        quiet: true,
        ..RenderOptions::default()
    };
    let film = render_scene(&scene, &StraightRays::new(R).unwrap(), &options).unwrap();
    assert_eq!(film.stats.non_finite_samples, 0);
    film
}

/// Card pixel (frame centre) and the sky beside it in the same row (near the left edge, 1.4 mrad
/// left of a card at most 1 mrad wide each side).
fn card_and_sky(film: &Film) -> ([f32; 4], [f32; 4]) {
    (film.pixel(200, 100), film.pixel(5, 100))
}

#[test]
fn black_card_contrast_is_koschmieder() {
    // A saturated horizon sky (aerosol optical depth 1: 1 − e^(−37) = 1 in every channel) makes
    // the sky beside the card exactly the path radiance, and a huge aerosol scale height makes
    // the haze uniform. The Rayleigh part of the extinction varies by e^(−10 m/8 km) along the
    // path: 0.1 % of β. Visibility = total extinction at 550 nm: β = 3.912 / V.
    let visibility_m = 4_000.0;
    let beta = 3.912 / visibility_m;
    let sky = format!(
        "aerosol_optical_depth = 1.0\nvisibility_km = {}\naerosol_scale_height_m = 1e9",
        visibility_m / 1000.0
    );
    for distance_m in [500.0, 1_000.0, 2_000.0] {
        let film = render_card([0, 0, 0], distance_m, &sky);
        let (card, sky_px) = card_and_sky(&film);
        let contrast = |c: usize| (sky_px[c] - card[c]) as f64 / sky_px[c] as f64;
        let expected = (-beta * distance_m).exp();
        // Green stands for 550 nm; at 549 nm the aerosol share is (550/549)^1.3 = 1.0024 larger,
        // which moves the contrast by 0.24 % × βd (0.5 % at 2 km).
        let relative = contrast(1) / expected - 1.0;
        eprintln!(
            "d = {distance_m} m: contrast {} vs e^(−βd) {expected} ({relative:+.5})",
            contrast(1)
        );
        assert!(
            relative.abs() < 0.01,
            "d = {distance_m}: contrast {} vs e^(−βd) = {expected} ({relative:+.4})",
            contrast(1)
        );
        // Shorter wavelengths are more extinguished (Rayleigh λ⁻⁴, aerosol λ^−1.3).
        assert!(
            contrast(0) > contrast(1) && contrast(1) > contrast(2),
            "{card:?}"
        );
    }
}

#[test]
fn card_far_beyond_the_visibility_fades_into_the_horizon_sky() {
    // The default sky (not saturated: its radiance changes with elevation near the horizon); a
    // red card at 5 × the visibility (contrast e^(−19.6)) must match the sky beside it.
    let distance_m = 10_000.0;
    let clear = render_card([255, 0, 0], distance_m, "");
    let (card, sky_px) = card_and_sky(&clear);
    assert!(
        card[0] > 0.9 && card[1] < 0.05,
        "without haze the card is red: {card:?}"
    );
    let hazy = render_card([255, 0, 0], distance_m, "visibility_km = 2.0");
    let (card, sky_px_hazy) = card_and_sky(&hazy);
    // The sky itself is not changed by the setting.
    assert_eq!(sky_px, sky_px_hazy);
    for c in 0..3 {
        let relative = (card[c] - sky_px[c]).abs() / sky_px[c];
        eprintln!(
            "far card channel {c}: {} vs sky {} ({relative:.2e})",
            card[c], sky_px[c]
        );
        assert!(relative < 0.02, "channel {c}: card {card:?} sky {sky_px:?}");
    }
    // The sea just below the horizon (ray dip at 10 m: 1.8 mrad = 81 px; row 190 meets the sea about 7 km away) fades too,
    // to the horizon sky, from the much darker clear-air sea.
    let (sea_clear, sea_hazy) = (clear.pixel(5, 190), hazy.pixel(5, 190));
    let horizon = ghostship::scene::Sky::default().radiance(0.0);
    for c in 0..3 {
        assert!(sea_clear[c] < 0.8 * horizon[c] as f32, "{sea_clear:?}");
        assert!(
            (sea_hazy[c] as f64 / horizon[c] - 1.0).abs() < 0.02,
            "{sea_hazy:?} {horizon:?}"
        );
    }
}

#[test]
fn hazy_fan_render_matches_per_sample_tracing() {
    // Refracted rays (k = 0.13) through a 3 km haze: the fan's interpolated card heights and sea
    // distances give the same image as tracing every sample, away from edges.
    let dir = tempfile::tempdir().unwrap();
    let image = image::RgbaImage::from_pixel(8, 8, image::Rgba([0, 0, 0, 255]));
    image.save(dir.path().join("card.png")).unwrap();
    let text = "[camera]\nheight_m = 10\nhfov_deg = 0.5\nwidth = 200\nheight = 100\n\
         [sky]\nvisibility_km = 3.0\n\
         [[cards]]\nimage = \"card.png\"\ndistance_m = 2500\nwidth_m = 10\nheight_m = 10\nbase_m = 5\n";
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = Scene::from_file(&path).unwrap();
    let tracer = ghostship::render::ConstantCurvatureRays::new(0.13, R).unwrap();
    let render = |exact| {
        let options = RenderOptions {
            quiet: true,
            exact,
            ..RenderOptions::default()
        };
        render_scene(&scene, &tracer, &options).unwrap()
    };
    let (fast, exact) = (render(false), render(true));
    let mut large = 0;
    for y in 0..fast.height {
        for x in 0..fast.width {
            let (a, b) = (fast.pixel(x, y), exact.pixel(x, y));
            if (0..3).any(|c| (a[c] - b[c]).abs() > 1e-3) {
                large += 1;
            }
        }
    }
    eprintln!("hazy fan vs exact: {large} of 20000 pixels differ by > 1e-3");
    // Edges (card outline, sea horizon): at most a row and a card outline's worth of pixels.
    assert!(large <= 400, "{large} pixels differ by more than 1e-3");
    // The card is hazed to Koschmieder's contrast e^(−βd) against the horizon sky beside it,
    // with β = 3.912 / 3 km thinned by the default 1 km aerosol scale height at the path's
    // ≈ 10 m: e^(−10/1000) (the Rayleigh share, 1 % of β, thins less: 1e-4 of τ). Refraction
    // and the 549 nm channel change τ by well under the 2 % allowed.
    let (card, sky_px) = (fast.pixel(100, 50), fast.pixel(5, 50));
    let contrast = (sky_px[1] - card[1]) as f64 / sky_px[1] as f64;
    let expected = (-3.912f64 / 3_000.0 * 2_500.0 * (-0.01f64).exp()).exp();
    assert!(
        (contrast / expected - 1.0).abs() < 0.02,
        "{contrast} vs {expected}: {card:?} {sky_px:?}"
    );
}

/// Refracted rays: a black card 30 km away seen from 10 m through the Novaya Zemlya ground
/// inversion (exactly critical: a level ray follows the Earth) in haze of 30 km visibility. Its
/// contrast against the path radiance is e^(−τ) with τ along the ray's own path — computed here
/// from the independent reference tracer's heights — within 1 %, and far from what the straight
/// chord (18 m below the ray at mid-distance, in denser haze) would give.
#[test]
fn haze_towards_a_card_follows_the_refracted_ray() {
    let dir = tempfile::tempdir().unwrap();
    let image = image::RgbaImage::from_pixel(8, 8, image::Rgba([0, 0, 0, 255]));
    image.save(dir.path().join("card.png")).unwrap();
    let nz = crate::support::data::data_dir().join("novaya_zemlya.toml");
    let (visibility_m, distance_m) = (30_000.0, 30_000.0);
    let text = format!(
        "[camera]\nheight_m = 10\nhfov_deg = 0.5\nwidth = 400\nheight = 200\n\
         [atmosphere]\nsynthetic = {nz:?}\n[sky]\naerosol_optical_depth = 1.0\n\
         visibility_km = {}\n[[cards]]\nimage = \"card.png\"\ndistance_m = {distance_m}\n\
         width_m = 200\nheight_m = 20\nbase_m = 0\n",
        visibility_m / 1000.0
    );
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = Scene::from_file(&path).unwrap();
    let atm = crate::scenes::atmosphere(&scene);
    let options = RenderOptions {
        quiet: true,
        samples_per_pixel: Some(1),
        ..RenderOptions::default()
    };
    let tracer = ghostship::render::prepare_tracer(&scene, Some(&atm), &options).unwrap();
    let film = render_scene(&scene, tracer.as_ref(), &options).unwrap();
    assert!(film.stats.air_path_rays > 0);
    let (_, alpha) = scene.camera.frame().direction(200.5, 100.5);
    // The saturated horizon sky (aerosol optical depth 1) is the path radiance, 1.
    let contrast = 1.0 - film.pixel(200, 100)[1] as f64;
    let nz_atm = SyntheticAtmosphere::from_file(&nz).unwrap();
    let index = atmosphere_index(&atm, BreakSource::Synthetic(&nz_atm));
    let scales = [8_000.0, 1_000.0];
    let along = reference_density_paths(&index, 10.0, alpha, distance_m, 10.0, scales);
    let beta = green_extinction_per_m(visibility_m);
    let tau = beta[0] * along[0] + beta[1] * along[1];
    let relative = contrast / (-tau).exp() - 1.0;
    eprintln!(
        "contrast {contrast} vs e^(−τ) {} ({relative:+.4}), τ = {tau}",
        (-tau).exp()
    );
    assert!(
        relative.abs() < 0.01,
        "contrast {contrast} vs {} ({relative:+e})",
        (-tau).exp()
    );
    // The chord's optical depth is larger by more than 3 % of e^(−τ): the test tells them apart.
    let chord_tau = film_chord_tau(&scene, alpha, distance_m, &atm, beta);
    assert!(
        (-chord_tau).exp() / (-tau).exp() < 0.97,
        "chord τ {chord_tau} vs path τ {tau}"
    );
}

/// The documented model's extinction coefficients (1/m) at the surface in the green channel
/// (549 nm) for `visibility_m` and the default sky (Rayleigh optical depth 0.0975 over 8 km):
/// [Rayleigh, aerosol].
pub(crate) fn green_extinction_per_m(visibility_m: f64) -> [f64; 2] {
    let r = 550.0f64 / 549.0;
    let rayleigh = 0.0975 / 8_000.0;
    [
        rayleigh * r.powi(4),
        (3.912 / visibility_m - rayleigh) * r.powf(1.3),
    ]
}

/// τ along the straight chord from the camera to the ray's point at `distance_m` (1 m pieces).
pub(crate) fn film_chord_tau(
    scene: &Scene,
    alpha: f64,
    distance_m: f64,
    atm: &ghostship::refractivity::RefractiveAtmosphere,
    beta: [f64; 2],
) -> f64 {
    use ghostship::render::RayTracer;
    let rays = ghostship::render::CurvedRays::new(
        atm,
        ghostship::render::curved::render_tracer_config(R),
        1_000.0,
    )
    .unwrap();
    let end_m = rays
        .trace(scene.camera.height_m, alpha, &[distance_m], false)
        .heights_m[0]
        .unwrap();
    let h0 = scene.camera.height_m;
    let theta = distance_m / R;
    let (bx, by) = (
        (R + end_m) * theta.sin(),
        (R + end_m) * theta.cos() - (R + h0),
    );
    let length = bx.hypot(by);
    let n = length.ceil() as usize;
    (0..n)
        .map(|i| {
            let t = (i as f64 + 0.5) / n as f64;
            let h = (t * bx).hypot(R + h0 + t * by) - R;
            (beta[0] * (-h / 8_000.0).exp() + beta[1] * (-h / 1_000.0).exp()) * length / n as f64
        })
        .sum()
}
