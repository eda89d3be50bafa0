//! Spectral rendering (`[render] spectral_bands`): the dispersion of the refraction at the
//! horizon through US1976 from the tracer at single wavelengths against Bouguer's refraction
//! integral (an independent computation), the sun's upper limb in every band of a spectral
//! render where the single-wavelength traces put it (US1976, and the near-critical
//! fig13_green_flash scene), the green rim above the red limb, the colour pipeline's white
//! point and neutrality, the RGB path unchanged with the setting off, and determinism whatever
//! the thread count.

use ghostship::atmosphere::load_atmosphere;
use ghostship::jobs::render::render_film;
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::render::spectral::{BandColour, SpectralFilm, render_spectral, xyz_to_rec709};
use ghostship::render::{CurvedRays, FanEnd, RayTracer, RenderOptions, render_tracer_config};
use ghostship::scene::Scene;

use crate::support::bisect;
use crate::support::data::repo_file;
use crate::support::reference::bouguer_escape_elevation;

const R: f64 = ghostship::units::EARTH_RADIUS_M;
const ARCSEC: f64 = std::f64::consts::PI / (180.0 * 3600.0);

/// The US1976 sunset: camera 10 m, the sun's TRUE centre 0.46° below the horizon (its upper
/// limb at −0.19°, seen about 0.3° up), a 0.5° frame on the upper limb.
const US1976_SUNSET: &str = "[camera]\nheight_m = 10.0\npitch_deg = 0.25\nhfov_deg = 0.5\n\
    width = 400\nheight = 200\n[atmosphere]\nstandard = \"us1976\"\n[render]\n\
    spectral_bands = 8\n[sun]\nelevation_deg = -0.46\nazimuth_deg = 0.0\n";

fn scene_from(text: &str) -> (tempfile::TempDir, Scene) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = Scene::from_file(&path).unwrap();
    (dir, scene)
}

fn atmosphere(scene: &Scene) -> RefractiveAtmosphere {
    let (source, options) = scene.atmosphere.resolve().unwrap();
    load_atmosphere(&source, &options).unwrap().refractive
}

fn options() -> RenderOptions {
    RenderOptions {
        quiet: true,
        samples_per_pixel: Some(1),
        ..RenderOptions::default()
    }
}

/// The elevation (rad, against the observer's horizontal) in which the renderer's tracer says
/// the ray from `h0` at apparent elevation `alpha` leaves the atmosphere.
fn escape_elevation(rays: &dyn RayTracer, h0: f64, alpha: f64) -> f64 {
    match rays.trace(h0, alpha, &[], true).end {
        FanEnd::Sky { elevation_rad } => elevation_rad,
        // A ray that meets the sea is below every part of the sky.
        FanEnd::Ground { .. } => f64::NEG_INFINITY,
        other => panic!("α = {alpha}: {other:?}"),
    }
}

/// The apparent elevation (rad) of the sun's upper limb (TRUE elevation `limb_rad`) at
/// `wavelength_nm` from the tracer: where the escape elevation crosses it, searched in
/// `bracket_rad` (ε(α) increasing there).
fn traced_limb_rad(
    atm: &RefractiveAtmosphere,
    h0: f64,
    limb_rad: f64,
    wavelength_nm: f64,
    bracket_rad: (f64, f64),
) -> f64 {
    let atm = atm.at_wavelength_nm(wavelength_nm).unwrap();
    let rays = CurvedRays::new(&atm, render_tracer_config(R), 0.0).unwrap();
    let (lo, hi) = bisect(bracket_rad.0, bracket_rad.1, 50, |a| {
        escape_elevation(&rays, h0, a) >= limb_rad
    });
    0.5 * (lo + hi)
}

/// The apparent elevation (rad) of the sea horizon at `wavelength_nm` (the lowest ray that
/// does not meet the sea), if the lowest ray of `bracket_rad` meets it.
fn sea_horizon_rad(
    atm: &RefractiveAtmosphere,
    h0: f64,
    wavelength_nm: f64,
    bracket_rad: (f64, f64),
) -> Option<f64> {
    let atm = atm.at_wavelength_nm(wavelength_nm).unwrap();
    let rays = CurvedRays::new(&atm, render_tracer_config(R), 0.0).unwrap();
    let meets_sea = |a: f64| matches!(rays.trace(h0, a, &[], true).end, FanEnd::Ground { .. });
    let lowest = bracket_rad.0 - 0.05f64.to_radians();
    meets_sea(lowest).then(|| bisect(lowest, bracket_rad.1, 50, |a| !meets_sea(a)).1)
}

/// The same from Bouguer's refraction integral (secant iteration on the escape elevation).
fn integral_limb_rad(
    atm: &RefractiveAtmosphere,
    h0: f64,
    limb_rad: f64,
    wavelength_nm: f64,
    start_rad: f64,
) -> f64 {
    let atm = atm.at_wavelength_nm(wavelength_nm).unwrap();
    let top_m = render_tracer_config(R).top_m;
    let n = |h: f64| atm.exact(h).0;
    let f = |a: f64| bouguer_escape_elevation(&n, R, top_m, h0, a, 40_000) - limb_rad;
    let (mut a0, mut a1) = (start_rad - 2e-5, start_rad + 2e-5);
    let (mut f0, mut f1) = (f(a0), f(a1));
    for _ in 0..12 {
        let a2 = a1 - f1 * (a1 - a0) / (f1 - f0);
        (a0, f0) = (a1, f1);
        a1 = a2;
        f1 = f(a1);
        if (a1 - a0).abs() < 1e-10 {
            break;
        }
    }
    a1
}

/// The rows of the centre column: the apparent elevation (rad) of each row's centre.
fn centre_column_elevations(scene: &Scene) -> Vec<f64> {
    let frame = scene.camera.frame();
    let x = scene.camera.width as f64 / 2.0 + 0.5;
    (0..scene.camera.height)
        .map(|y| frame.view_direction(x, y as f64 + 0.5).elevation_rad)
        .collect()
}

/// The first row (from the top) of the centre column where band `band` shows the sun, among
/// the rows above `rows` (the band's sea horizon: below it the sea mirrors the sun): its
/// radiance exceeds the sky of the top row by a tenth of the column's excess at its brightest;
/// `None` if the band's sun is not brighter than twice that sky (extinguished).
fn top_sun_row(film: &SpectralFilm, band: usize, rows: usize) -> Option<usize> {
    let w = film.film.width as usize;
    let column: Vec<f32> = (0..rows).map(|y| film.bands[band][y * w + w / 2]).collect();
    let sky = column[0];
    let brightest = column.iter().copied().fold(0.0, f32::max);
    if brightest <= 2.0 * sky {
        return None;
    }
    column
        .iter()
        .position(|&l| l > sky + 0.1 * (brightest - sky))
}

/// Every band's upper limb in `scene`'s spectral render lies in the row whose centre the
/// single-wavelength trace at the band's centre puts first below the limb (within one row);
/// returns the bands' traced limbs (rad) and top rows for the bands whose sun is not
/// extinguished (at least `seen` of them).
fn check_limbs(scene: &Scene, bracket_rad: (f64, f64), seen: usize) -> Vec<(f64, f64, usize)> {
    let atm = atmosphere(scene);
    let film =
        render_spectral(scene, Some(&atm), &options(), scene.spectral_bands.unwrap()).unwrap();
    assert_eq!(film.film.stats.non_finite_samples, 0);
    let sun = scene.sun.unwrap();
    let limb_rad = sun.elevation_rad + 0.5 * sun.angular_diameter_rad;
    let rows = centre_column_elevations(scene);
    let mut out = Vec::new();
    for (k, &wavelength_nm) in film.wavelengths_nm.iter().enumerate() {
        let alpha = traced_limb_rad(
            &atm,
            scene.camera.height_m,
            limb_rad,
            wavelength_nm,
            bracket_rad,
        );
        let predicted = rows.iter().position(|&e| e <= alpha).unwrap();
        let above_sea = sea_horizon_rad(&atm, scene.camera.height_m, wavelength_nm, bracket_rad)
            .map_or(rows.len(), |h| {
                rows.iter().position(|&e| e <= h).unwrap_or(rows.len())
            });
        let Some(found) = top_sun_row(&film, k, above_sea) else {
            continue;
        };
        assert!(
            found.abs_diff(predicted) <= 1,
            "{wavelength_nm} nm: limb in row {found}, traced {predicted}"
        );
        out.push((wavelength_nm, alpha, found));
    }
    assert!(out.len() >= seen, "{out:?}");
    // The green rim: the topmost sun rows are green or blue rather than red; well inside the
    // disc (10 rows below the reddest limb) red dominates.
    let w = film.film.width as usize;
    let px = |y: usize| film.film.pixels[y * w + w / 2];
    let top = out.iter().map(|o| o.2).min().unwrap();
    let inside = out.iter().map(|o| o.2).max().unwrap() + 10;
    let rim = px(top);
    assert!(rim[1] > rim[0] || rim[2] > rim[0], "rim row {top}: {rim:?}");
    let body = px(inside);
    assert!(
        body[0] > body[1] && body[1] > body[2],
        "row {inside}: {body:?}"
    );
    out
}

#[test]
fn dispersion_at_the_horizon_through_us1976_matches_the_refraction_integral() {
    let (_dir, scene) = scene_from(US1976_SUNSET);
    let atm = atmosphere(&scene);
    let sun = scene.sun.unwrap();
    let limb_rad = sun.elevation_rad + 0.5 * sun.angular_diameter_rad;
    let h0 = scene.camera.height_m;
    let bracket = (0.0, 1f64.to_radians());
    let [t450, t650] = [450.0, 650.0].map(|l| traced_limb_rad(&atm, h0, limb_rad, l, bracket));
    let [i450, i650] = [(450.0, t450), (650.0, t650)]
        .map(|(l, start)| integral_limb_rad(&atm, h0, limb_rad, l, start));
    let traced = (t450 - t650) / ARCSEC;
    let integral = (i450 - i650) / ARCSEC;
    eprintln!(
        "upper limb apparent elevation: 450 nm {:.2}″ (integral {:.2}″), 650 nm {:.2}″ \
         (integral {:.2}″); separation {traced:.2}″ (integral {integral:.2}″)",
        t450 / ARCSEC,
        i450 / ARCSEC,
        t650 / ARCSEC,
        i650 / ARCSEC
    );
    for (t, i) in [(t450, i450), (t650, i650)] {
        assert!(
            (t - i).abs() < 1.0 * ARCSEC,
            "{} vs {}",
            t / ARCSEC,
            i / ARCSEC
        );
    }
    assert!((traced - integral).abs() < 0.3, "{traced} vs {integral}");
    assert!((15.0..30.0).contains(&traced), "{traced}″");
}

#[test]
fn us1976_spectral_limbs_lie_where_single_wavelength_traces_put_them() {
    let (_dir, scene) = scene_from(US1976_SUNSET);
    let limbs = check_limbs(&scene, (0.0, 1f64.to_radians()), 7);
    // Blue above red: the limb rows do not increase with wavelength, and the bluest seen
    // band's limb is several rows above the reddest's.
    assert!(limbs.windows(2).all(|w| w[0].2 <= w[1].2), "{limbs:?}");
    assert!(limbs[limbs.len() - 1].2 >= limbs[0].2 + 3, "{limbs:?}");
}

#[test]
fn fig13_green_rim_lies_where_single_wavelength_traces_put_it() {
    let scene = Scene::from_file(&repo_file("data/scenes/fig13_green_flash.toml")).unwrap();
    let limbs = check_limbs(&scene, ((-0.055f64).to_radians(), 0.1f64.to_radians()), 6);
    eprintln!("fig13 limbs (nm, apparent °, row): {limbs:?}");
    assert!(limbs.windows(2).all(|w| w[0].2 <= w[1].2), "{limbs:?}");
}

#[test]
fn a_flat_spectrum_is_white_and_the_colour_tables_are_the_cie_ones() {
    let colour = BandColour::new(8);
    let xyz = colour.xyz(|_| 1.0);
    // The CIE 1931 functions have equal integrals (the equal-energy white E at x = y = 1/3),
    // ∫ȳ dλ = 106.857 (1 nm table, 360–830 nm).
    let sum = xyz[0] + xyz[1] + xyz[2];
    assert!((xyz[0] / sum - 1.0 / 3.0).abs() < 2e-3, "{xyz:?}");
    assert!((xyz[1] / sum - 1.0 / 3.0).abs() < 2e-3, "{xyz:?}");
    assert!((xyz[1] - 106.857).abs() < 0.5, "{xyz:?}");
    // The matrix maps the D65 white (x 0.3127, y 0.3290) to (1, 1, 1).
    let (x, y) = (0.3127, 0.3290);
    let d65 = xyz_to_rec709([x / y, 1.0, (1.0 - x - y) / y]);
    assert!(d65.iter().all(|v| (v - 1.0).abs() < 1e-3), "{d65:?}");
    for bands in [8, 13, 60] {
        let white = BandColour::new(bands).rec709(|_| 1.0);
        assert!(
            white.iter().all(|v| (v - 1.0).abs() < 1e-3),
            "{bands}: {white:?}"
        );
    }
}

#[test]
fn a_sky_white_at_every_wavelength_renders_neutral() {
    // An optically thick sky (τ_R = 10) has radiance `brightness` at every wavelength in every
    // direction: through the bands, CIE XYZ and Rec.709 it must stay grey.
    let text = "[camera]\nheight_m = 10.0\npitch_deg = 10.0\nhfov_deg = 10.0\nwidth = 40\n\
        height = 20\n[sky]\nbrightness = 0.5\nrayleigh_optical_depth = 10.0\n[render]\n\
        spectral_bands = 8\n";
    let (_dir, scene) = scene_from(text);
    let atm = atmosphere(&scene);
    let film = render_spectral(&scene, Some(&atm), &options(), 8).unwrap();
    for p in &film.film.pixels {
        for c in 0..3 {
            assert!((p[c] - 0.5).abs() < 1e-3, "{p:?}");
        }
    }
}

#[test]
fn with_the_setting_off_the_rgb_render_is_unchanged() {
    let base = US1976_SUNSET.replace("[render]\nspectral_bands = 8\n", "");
    let off = US1976_SUNSET.replace("spectral_bands = 8", "spectral_bands = 0");
    let (_a, a) = scene_from(&base);
    let (_b, b) = scene_from(&off);
    assert_eq!(a.spectral_bands, None);
    assert_eq!(b.spectral_bands, None);
    let atm = a.atmosphere.load().unwrap();
    let fa = render_film(&a, atm.as_ref(), &options()).unwrap();
    let fb = render_film(&b, atm.as_ref(), &options()).unwrap();
    assert!(fa.pixels == fb.pixels);
    // And the spectral render is another image.
    let (_c, c) = scene_from(US1976_SUNSET);
    let fc = render_film(&c, atm.as_ref(), &options()).unwrap();
    assert!(fa.pixels != fc.pixels);
}

#[test]
fn spectral_renders_do_not_depend_on_the_thread_count() {
    let text = US1976_SUNSET.replace("width = 400\nheight = 200", "width = 100\nheight = 50");
    let (_dir, scene) = scene_from(&text);
    let atm = atmosphere(&scene);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let o = RenderOptions {
                samples_per_pixel: None,
                ..options()
            };
            render_spectral(&scene, Some(&atm), &o, 8).unwrap()
        })
    };
    assert!(
        run(1) == run(2),
        "spectral frames differ between 1 and 2 threads"
    );
}

#[test]
fn out_of_range_band_counts_are_refused() {
    for bands in [1, 7, 61] {
        let text =
            US1976_SUNSET.replace("spectral_bands = 8", &format!("spectral_bands = {bands}"));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scene.toml");
        std::fs::write(&path, text).unwrap();
        let err = Scene::from_file(&path).unwrap_err().to_string();
        assert!(err.contains("render.spectral_bands"), "{bands}: {err}");
    }
}
