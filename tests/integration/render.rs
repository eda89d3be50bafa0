//! Renderer: scene geometry against closed forms, the elevation fan against per-sample tracing,
//! exporters, determinism across thread counts, the committed card images and the scene files.

use std::path::{Path, PathBuf};

use ghostship::output::{exr, png, write_atomic};
use ghostship::render::{
    ConstantCurvatureRays, ElevationFan, FanEnd, FanRay, FanSpec, Film, RayTracer, RenderOptions,
    StraightRays, render_scene,
};
use ghostship::scene::{Scene, assets};

use crate::support::data::data_dir;
use crate::support::films::{at_edge, max_channel_difference};

const R: f64 = 6_371_000.0;
const ARCMIN: f64 = std::f64::consts::PI / (180.0 * 60.0);

fn quiet() -> RenderOptions {
    RenderOptions {
        quiet: true,
        ..RenderOptions::default()
    }
}

/// A scene in a temporary folder with a solid opaque red card image `red.png` (64 × 64).
fn scene_in_tempdir(text: &str) -> (tempfile::TempDir, Scene) {
    let dir = tempfile::tempdir().unwrap();
    let red = image::RgbaImage::from_pixel(64, 64, image::Rgba([255, 0, 0, 255]));
    red.save(dir.path().join("red.png")).unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = Scene::from_file(&path).unwrap();
    (dir, scene)
}

fn is_red(p: [f32; 4]) -> bool {
    p[0] > 0.9 && p[1] < 0.05 && p[2] < 0.05
}

/// Film row (pixel index) of the first pixel (from the top) in column `x` for which `pred` holds.
fn first_row(film: &Film, x: u32, pred: impl Fn([f32; 4]) -> bool) -> Option<u32> {
    (0..film.height).find(|&y| pred(film.pixel(x, y)))
}

#[test]
fn committed_card_images_equal_freshly_drawn_ones() {
    let dir = data_dir().join("cards");
    if std::env::var_os("GHOSTSHIP_WRITE_CARDS").is_some() {
        assets::write_card_images(&dir).unwrap();
    }
    for (name, fresh) in assets::card_images() {
        let path = dir.join(name);
        let committed = image::open(&path)
            .unwrap_or_else(|e| {
                panic!(
                    "{}: {e} (regenerate with GHOSTSHIP_WRITE_CARDS=1)",
                    path.display()
                )
            })
            .to_rgba8();
        assert_eq!(committed.dimensions(), fresh.dimensions(), "{name}");
        assert!(
            committed.as_raw() == fresh.as_raw(),
            "{name} differs from the drawing code"
        );
    }
}

/// Row where the sea starts in the centre column, for a camera at `h` with straight rays or
/// constant curvature `k`; pitch 0, 400 × 200, hfov 0.5°.
fn sea_start_row(h: f64, k: f64) -> (u32, f64) {
    let text = format!(
        "[camera]\nheight_m = {h}\nhfov_deg = 0.5\nwidth = 400\nheight = 200\n\
         [atmosphere]\nstraight = {}\n",
        k == 0.0
    );
    let (_dir, scene) = scene_in_tempdir(&text);
    let tracer = ConstantCurvatureRays::new(k, R).unwrap();
    let film = render_scene(&scene, &tracer, &quiet()).unwrap();
    // Sea and sky radiances at the horizon differ strongly in every channel: the sky there is
    // ≈ 0.97, the sea (Fresnel at the 3° facet slope) ≈ 0.6.
    let sky = scene.sky.radiance(0.0)[1];
    let sea = scene.sea.radiance(0.0, &scene.sky)[1];
    let threshold = 0.5 * (sky + sea) as f32;
    let row = first_row(&film, 200, |p| p[1] < threshold).expect("no sea in the frame");
    (row, scene.camera.frame().focal_px)
}

#[test]
fn horizon_row_matches_the_geometric_dip_for_straight_rays() {
    // docs/references.md §2.2: geometric dip 1.926′·√h (R = 6371 km).
    for h in [1.0f64, 10.0] {
        let (row, f) = sea_start_row(h, 0.0);
        let dip = 1.926 * h.sqrt() * ARCMIN;
        // Pixel row j (centre j + 0.5) is sea iff its elevation is below −dip.
        let boundary = 100.0 + f * dip.tan();
        let predicted_first_sea_row = (boundary - 0.5).ceil() as u32;
        assert!(
            (row as i64 - predicted_first_sea_row as i64).abs() <= 1,
            "h={h}: sea starts at row {row}, the dip predicts {predicted_first_sea_row} ({boundary})"
        );
    }
}

#[test]
fn horizon_row_matches_the_nautical_almanac_dip_with_refraction() {
    // Nautical Almanac dip 1.76′·√h ⇔ geometric × √(1 − k) with k ≈ 0.164
    // (docs/references.md §2.2).
    let (row, f) = sea_start_row(10.0, 0.164);
    let boundary = 100.0 + f * (1.76 * 10f64.sqrt() * ARCMIN).tan();
    let predicted = (boundary - 0.5).ceil() as i64;
    assert!((row as i64 - predicted).abs() <= 1, "{row} vs {predicted}");
}

/// Apparent elevation at which a ray from height `h0` reaches height `h` at ground distance `d`,
/// over an (effective) Earth of radius `r` with straight rays: from (r+h)·cos(θ+α) = (r+h0)·cos α.
fn elevation_reaching(h0: f64, h: f64, d: f64, r: f64) -> f64 {
    let theta = d / r;
    (((r + h) * theta.cos() - (r + h0)) / ((r + h) * theta.sin())).atan()
}

#[test]
fn card_edges_land_where_the_closed_form_puts_them() {
    for k in [0.0, 0.17] {
        let text = format!(
            "[camera]\nheight_m = 10\nhfov_deg = 0.5\nwidth = 400\nheight = 200\n\
             [atmosphere]\nstraight = {}\n\
             [[cards]]\nimage = \"red.png\"\ndistance_m = 5000\nazimuth_deg = 0.05\n\
             width_m = 30\nheight_m = 20\nbase_m = 2\n",
            k == 0.0
        );
        let (_dir, scene) = scene_in_tempdir(&text);
        let tracer = ConstantCurvatureRays::new(k, R).unwrap();
        let film = render_scene(&scene, &tracer, &quiet()).unwrap();
        let f = scene.camera.frame().focal_px;
        let r_eff = R / (1.0 - k);
        // Column of the card's centre: azimuth 0.05° → x = 200 + f·tan(0.05°).
        let x = (200.0 + f * 0.05f64.to_radians().tan()) as u32;
        let top = first_row(&film, x, is_red).expect("card not visible");
        let bottom = (0..film.height)
            .rev()
            .find(|&y| is_red(film.pixel(x, y)))
            .unwrap();
        for (what, row, h) in [("top", top, 22.0), ("bottom", bottom + 1, 2.0)] {
            let alpha = elevation_reaching(10.0, h, 5000.0, r_eff);
            let edge = 100.0 - f * alpha.tan();
            // The first red row's centre lies below the edge (and the one above it does not).
            let predicted = (edge - 0.5).ceil();
            assert!(
                (row as f64 - predicted).abs() <= 1.0,
                "k={k} {what}: row {row}, closed form {predicted} ({edge})"
            );
        }
        // Left and right edges: ±15 m at R·sin(D/R) ≈ D around azimuth 0.05°.
        let y = (top + bottom) / 2;
        let left = (0..film.width).find(|&x| is_red(film.pixel(x, y))).unwrap();
        let right = (0..film.width)
            .rev()
            .find(|&x| is_red(film.pixel(x, y)))
            .unwrap()
            + 1;
        let half = 15.0 / (R * (5000.0 / R).sin());
        for (edge_px, az) in [
            (left, 0.05f64.to_radians() - half),
            (right, 0.05f64.to_radians() + half),
        ] {
            let predicted = 200.0 + f * az.tan();
            assert!(
                (edge_px as f64 - predicted).abs() <= 1.0,
                "k={k}: column {edge_px} vs {predicted}"
            );
        }
    }
}

/// A test tracer with a FOLD in its transfer curve (like a superior mirage): the ray's initial
/// slope g(α) = α − β·w·tanh((α − α₀)/w) decreases with α for |α − α₀| < 0.88 w (β = 2), so
/// three elevations see the same height; heights h(d) = h₀ + g·d + d²/(2R′) (a parabola over an
/// effective Earth R′); sea hit at the first root; sky direction = final slope.
struct FoldRays {
    alpha0: f64,
    width: f64,
    beta: f64,
    r_eff: f64,
}

impl FoldRays {
    fn slope(&self, alpha: f64) -> f64 {
        alpha - self.beta * self.width * ((alpha - self.alpha0) / self.width).tanh()
    }
    fn dslope(&self, alpha: f64) -> f64 {
        let c = ((alpha - self.alpha0) / self.width).cosh();
        1.0 - self.beta / (c * c)
    }
}

impl RayTracer for FoldRays {
    fn trace(&self, h0: f64, alpha: f64, distances: &[f64], _need: bool) -> FanRay {
        let g = self.slope(alpha);
        let r = self.r_eff;
        let disc = g * g - 2.0 * h0 / r;
        let hit = (g < 0.0 && disc >= 0.0).then(|| r * (-g - disc.sqrt()));
        let heights_m = distances
            .iter()
            .map(|&d| match hit {
                Some(dh) if d > dh => None,
                _ => Some(h0 + g * d + d * d / (2.0 * r)),
            })
            .collect();
        let end = match hit {
            Some(d) => FanEnd::Ground {
                distance_m: d,
                grazing_rad: -(g + d / r),
            },
            None => FanEnd::Sky { elevation_rad: g },
        };
        FanRay {
            elevation_rad: alpha,
            heights_m,
            end,
            // The fold makes the family non-monotone in α whatever each ray does.
            monotone: false,
        }
    }
}

fn fold() -> FoldRays {
    FoldRays {
        alpha0: -0.0003,
        width: 4.4e-4,
        beta: 2.0,
        r_eff: R / 0.83,
    }
}

#[test]
fn fan_interpolation_error_stays_within_the_stated_bound_on_a_fold() {
    let tracer = fold();
    let pixel = 2.18e-5;
    let tol = 0.1;
    let distances = vec![10_000.0, 20_000.0];
    let spec = FanSpec {
        camera_height_m: 10.0,
        distances_m: distances.clone(),
        max_top_m: vec![1e9, 1e9],
        need_sky_direction: false,
        sun_band_rad: None,
        elevation_range_rad: (-0.003, 0.003),
        pixel_rad: pixel,
        tolerance_px: tol,
        max_depth: 12,
    };
    let fan = ElevationFan::build(&tracer, &spec);
    let alphas = fan.elevations_rad().to_vec();
    let mut heights = vec![None; 2];
    let (mut worst_smooth, mut worst_narrow) = (0.0f64, 0.0f64);
    let mut state = 12345u64;
    for _ in 0..20_000 {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let alpha = -0.003 + 0.006 * ((state >> 11) as f64 / (1u64 << 53) as f64);
        let i = alphas
            .partition_point(|&a| a <= alpha)
            .clamp(1, alphas.len() - 1)
            - 1;
        let width = alphas[i + 1] - alphas[i];
        fan.interpolate(alpha, &mut heights);
        let exact = tracer.trace(10.0, alpha, &distances, false);
        for (k, d) in distances.iter().enumerate() {
            if let (Some(hf), Some(he)) = (heights[k], exact.heights_m[k]) {
                // Misplacement of the feature at this height, in pixels: how far from α does the
                // exact transfer curve reach the interpolated height? First estimated through the
                // local slope; where that estimate exceeds the tolerance (near a turning point the
                // slope vanishes), measured by scanning the exact curve within ±2 px.
                let slope = (d * tracer.dslope(alpha)).abs();
                let mut err_px = (hf - he).abs() / slope / pixel;
                if err_px > tol {
                    let h_at = |a: f64| tracer.trace(10.0, a, &[*d], false).heights_m[0];
                    let step = 0.001 * pixel;
                    err_px = f64::INFINITY;
                    let mut prev = h_at(alpha - 2.0 * pixel);
                    for j in 1..=4000 {
                        let a = alpha - 2.0 * pixel + j as f64 * step;
                        let cur = h_at(a);
                        if let (Some(p), Some(c)) = (prev, cur)
                            && (p - hf) * (c - hf) <= 0.0
                        {
                            err_px = err_px.min((a - alpha).abs() / pixel);
                        }
                        prev = cur;
                    }
                }
                if width >= tol * pixel {
                    worst_smooth = worst_smooth.max(err_px);
                } else {
                    worst_narrow = worst_narrow.max(err_px.min(width / pixel));
                }
            }
        }
    }
    eprintln!(
        "fold: {} rays; worst misplacement {worst_smooth:.4} px in midpoint-tested intervals",
        alphas.len()
    );
    assert!(worst_smooth <= tol, "{worst_smooth} px");
    assert!(worst_narrow <= tol);
}

/// Calibration boards at 10 and 20 km, seen through `tracer`, rendered by the fan and exactly.
fn boards_scene() -> (tempfile::TempDir, Scene) {
    boards_scene_with("")
}

fn boards_scene_with(extra: &str) -> (tempfile::TempDir, Scene) {
    let board = data_dir().join("cards/calibration_board.png");
    let text = format!(
        "[camera]\nheight_m = 10\nhfov_deg = 0.5\nwidth = 200\nheight = 120\n\
         [[cards]]\nimage = {board:?}\ndistance_m = 10000\nazimuth_deg = -0.08\nwidth_m = 20\nheight_m = 20\n\
         [[cards]]\nimage = {board:?}\ndistance_m = 20000\nazimuth_deg = 0.08\nwidth_m = 40\nheight_m = 20\n\
         {extra}"
    );
    scene_in_tempdir(&text)
}

#[test]
fn fan_render_matches_exact_render_except_at_edges() {
    // The sun (radius 0.27°) sits just above the boards; with the fold tracer its final sky
    // directions are folded too (g(α) is not monotone), like a Novaya Zemlya sun.
    let (_dir1, plain) = boards_scene();
    let (_dir2, sunny) = boards_scene_with("[sun]\nelevation_deg = 0.05\nazimuth_deg = -0.1\n");
    for (name, scene, tracer) in [
        ("fold", &plain, Box::new(fold()) as Box<dyn RayTracer>),
        (
            "k=0.17",
            &plain,
            Box::new(ConstantCurvatureRays::new(0.17, R).unwrap()),
        ),
        ("fold+sun", &sunny, Box::new(fold())),
        (
            "straight+sun",
            &sunny,
            Box::new(StraightRays::new(R).unwrap()),
        ),
    ] {
        let fast = render_scene(scene, tracer.as_ref(), &quiet()).unwrap();
        let exact_opts = RenderOptions {
            exact: true,
            ..quiet()
        };
        let exact = render_scene(scene, tracer.as_ref(), &exact_opts).unwrap();
        assert!(fast.stats.fan_rays > 0 && exact.stats.fan_rays == 0);
        if name.ends_with("+sun") {
            let sky = scene.sky.radiance(0.0)[0] as f32;
            let lit = exact.pixels.iter().filter(|p| p[0] > sky + 0.05).count();
            assert!(
                lit > 100,
                "{name}: the sun should be in the frame ({lit} px)"
            );
        }
        let (w, h) = (exact.width, exact.height);
        let threshold = 0.02;
        let mut differing = 0;
        for y in 0..h {
            for x in 0..w {
                let e = exact.pixel(x, y);
                if max_channel_difference(e, fast.pixel(x, y)) <= threshold {
                    continue;
                }
                differing += 1;
                // A differing pixel must sit at an edge of the exact or the fan image: a neighbour
                // differs from it. The fan misplaces features by < 0.1 px, which moves an edge
                // across a pixel centre, or makes a sub-pixel feature (a 12 cm tick mark) fall on
                // or between pixel centres — never changes a pixel inside a uniform region.
                let near_edge = at_edge(&exact, x, y, threshold) || at_edge(&fast, x, y, threshold);
                assert!(
                    near_edge,
                    "{name}: pixel ({x}, {y}) differs away from any edge"
                );
            }
        }
        let fraction = differing as f64 / (w * h) as f64;
        eprintln!(
            "{name}: {differing} of {} pixels differ by > {threshold} (all at edges)",
            w * h
        );
        assert!(fraction < 0.01, "{name}: {fraction}");
    }
}

#[test]
fn exr_round_trip_keeps_pixels_and_provenance() {
    let (_dir, scene) = boards_scene();
    let tracer = StraightRays::new(R).unwrap();
    let film = render_scene(&scene, &tracer, &quiet()).unwrap();
    let meta = exr::ExrMetadata {
        scene_hash: scene.hash_hex.clone(),
        observer_height_m: 10.0,
        wavelength_nm: 550.0,
        tolerance_px: Some(0.1),
        tracer_tolerance_m: 0.01,
        extra: vec![("tracer".into(), "straight".into())],
    };
    let bytes = exr::encode_exr(&film, &meta).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.exr");
    write_atomic(&path, &bytes).unwrap();

    let (w, h) = (film.width as usize, film.height as usize);
    let image = ::exr::prelude::read_first_rgba_layer_from_file(
        &path,
        move |_res, _| vec![[0.0f32; 4]; w * h],
        move |buf: &mut Vec<[f32; 4]>,
              pos: ::exr::prelude::Vec2<usize>,
              (r, g, b, a): (f32, f32, f32, f32)| {
            buf[pos.y() * w + pos.x()] = [r, g, b, a];
        },
    )
    .unwrap();
    let layer = &image.layer_data;
    assert_eq!(layer.size.x(), w);
    assert!(
        layer.channel_data.pixels == film.pixels,
        "pixels changed in the round trip"
    );
    let chroma = image.attributes.chromaticities.expect("chromaticities");
    assert_eq!((chroma.white.x(), chroma.white.y()), (0.3127, 0.3290));
    assert_eq!((chroma.red.x(), chroma.red.y()), (0.64, 0.33));
    let attrs = &layer.attributes;
    assert_eq!(
        attrs.software_name.as_ref().unwrap().to_string(),
        format!("ghostship {}", env!("CARGO_PKG_VERSION"))
    );
    let lines: Vec<String> = match attrs
        .other
        .get(&::exr::meta::attribute::Text::from("ghostship"))
    {
        Some(::exr::meta::attribute::AttributeValue::TextVector(v)) => {
            v.iter().map(|t| t.to_string()).collect()
        }
        other => panic!("provenance attribute missing: {other:?}"),
    };
    for want in [
        format!("scene_sha256={}", scene.hash_hex),
        "observer_height_m=10".to_string(),
        "wavelength_nm=550".to_string(),
        "fan_tolerance_px=0.1".to_string(),
        "tracer_tolerance_m=0.01".to_string(),
        "tracer=straight".to_string(),
        format!("version={}", env!("CARGO_PKG_VERSION")),
    ] {
        assert!(lines.contains(&want), "{want} not in {lines:?}");
    }
}

#[test]
fn png_is_srgb_encoded() {
    let film = Film {
        width: 2,
        height: 1,
        pixels: vec![[0.625, 0.0, 1.0, 1.0], [0.18, 0.002, 2.0, 1.0]],
        stats: Default::default(),
    };
    let bytes = png::encode_png(&film, 1.0).unwrap();
    let img = image::load_from_memory(&bytes).unwrap().to_rgb8();
    // 0.625 linear → 207 (crates.md §1.5); 1.0 → 255.
    assert_eq!(img.get_pixel(0, 0).0, [207, 0, 255]);
    // Brighter than white: the whole colour is scaled so its largest channel is 1 (hue kept):
    // [0.18, 0.002, 2.0] → [0.09, 0.001, 1.0] → sRGB 0.3318 → 85, 12.92·0.001 → 3 (linear
    // segment), 255.
    assert_eq!(img.get_pixel(1, 0).0, [85, 3, 255]);
    // Exposure scales linear values before encoding.
    let bytes = png::encode_png(&film, 0.5).unwrap();
    let img = image::load_from_memory(&bytes).unwrap().to_rgb8();
    assert_eq!(img.get_pixel(0, 0)[2], png::encode_channel(0.5, 1.0));
}

#[test]
fn output_bytes_do_not_depend_on_the_thread_count() {
    let scene = Scene::from_file(&data_dir().join("scenes/fig04_superior_mirage.toml")).unwrap();
    let tracer = ConstantCurvatureRays::new(0.17, scene.earth_radius_m).unwrap();
    let render = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let film = render_scene(&scene, &tracer, &quiet()).unwrap();
            let meta = exr::ExrMetadata {
                scene_hash: scene.hash_hex.clone(),
                ..Default::default()
            };
            (
                exr::encode_exr(&film, &meta).unwrap(),
                png::encode_png(&film, png::DEFAULT_EXPOSURE).unwrap(),
            )
        })
    };
    let (exr1, png1) = render(1);
    let (exr2, png2) = render(2);
    assert!(exr1 == exr2, "EXR bytes differ between 1 and 2 threads");
    assert!(png1 == png2, "PNG bytes differ between 1 and 2 threads");
}

/// A hostile tracer: NaN heights, NaN and huge sky directions, lost rays.
struct HostileRays;

impl RayTracer for HostileRays {
    fn trace(&self, _h0: f64, alpha: f64, distances: &[f64], _need: bool) -> FanRay {
        let bucket = ((alpha * 1e4).floor() as i64).rem_euclid(4);
        let end = match bucket {
            0 => FanEnd::Sky {
                elevation_rad: f64::NAN,
            },
            1 => FanEnd::Lost,
            2 => FanEnd::Ground {
                distance_m: f64::INFINITY,
                grazing_rad: f64::NAN,
            },
            _ => FanEnd::Sky {
                elevation_rad: 1e300,
            },
        };
        FanRay {
            elevation_rad: alpha,
            heights_m: distances.iter().map(|_| Some(f64::NAN)).collect(),
            end,
            monotone: alpha.to_bits().is_multiple_of(2),
        }
    }
}

#[test]
fn no_pixel_is_ever_nan() {
    let board = data_dir().join("cards/calibration_board.png");
    let text = format!(
        "[camera]\nheight_m = 100\npitch_deg = 60\nhfov_deg = 170\nwidth = 64\nheight = 48\n\
         samples_per_pixel = 4\n[sun]\nelevation_deg = -3\nazimuth_deg = 10\n\
         [[cards]]\nimage = {board:?}\ndistance_m = 1000\nwidth_m = 50\nheight_m = 20\n"
    );
    let (_dir, scene) = scene_in_tempdir(&text);
    for exact in [false, true] {
        let opts = RenderOptions { exact, ..quiet() };
        for tracer in [
            Box::new(HostileRays) as Box<dyn RayTracer>,
            Box::new(StraightRays::new(R).unwrap()),
        ] {
            let film = render_scene(&scene, tracer.as_ref(), &opts).unwrap();
            assert!(film.pixels.iter().flatten().all(|v| v.is_finite()));
        }
    }
    // A narrow frame at one sample per pixel: the flat-row path (one elevation per row).
    let text = format!(
        "[camera]\nheight_m = 10\nhfov_deg = 1\nwidth = 64\nheight = 48\n\
         [sun]\nelevation_deg = 0.1\nazimuth_deg = 0.1\n\
         [[cards]]\nimage = {board:?}\ndistance_m = 1000\nwidth_m = 5\nheight_m = 20\n"
    );
    let (_dir, scene) = scene_in_tempdir(&text);
    let film = render_scene(&scene, &HostileRays, &quiet()).unwrap();
    assert!(film.pixels.iter().flatten().all(|v| v.is_finite()));
}

/// Rays that all come up by 2° (like strongly ducted air): final direction = α − 2°.
struct LiftedRays;

impl RayTracer for LiftedRays {
    fn trace(&self, _h0: f64, alpha: f64, distances: &[f64], need: bool) -> FanRay {
        assert!(need, "a scene with a sun must ask for sky directions");
        FanRay {
            elevation_rad: alpha,
            heights_m: vec![None; distances.len()],
            end: FanEnd::Sky {
                elevation_rad: alpha - 2f64.to_radians(),
            },
            monotone: false,
        }
    }
}

#[test]
fn a_sun_below_the_astronomical_horizon_is_seen_through_rays_that_come_up() {
    let text = "[camera]\nheight_m = 100\nhfov_deg = 2\nwidth = 200\nheight = 100\n\
                [sun]\nelevation_deg = -2\nazimuth_deg = 0\n";
    let (_dir, scene) = scene_in_tempdir(text);
    let film = render_scene(&scene, &LiftedRays, &quiet()).unwrap();
    // The sun (true elevation −2°) appears centred at apparent elevation 0: the middle of the
    // frame; its disc is 0.533° = 53 px across here (100 px per degree).
    let centre = film.pixel(100, 50);
    let sky = scene.sky.radiance(0.0);
    // Sun = intensity × limb darkening (μ ≈ 1 at the centre) × transmittance along the apparent
    // elevation (≈ 0: Kasten–Young air mass 37.9), on top of the sky.
    let sun = scene.sun.unwrap();
    let t = scene.sky.transmittance(0.0);
    for c in 0..3 {
        let excess = centre[c] as f64 - sky[c];
        let want = sun.intensity * t[c];
        assert!(
            (excess - want).abs() <= 0.02 * want + 1e-3,
            "channel {c}: {excess} vs {want}"
        );
    }
    // Reddened: the low sun's blue is almost gone.
    assert!(t[0] > t[1] && t[1] > 10.0 * t[2], "{t:?}");
    let rows: Vec<u32> = (0..100)
        .filter(|&y| film.pixel(100, y)[0] as f64 > sky[0] + 0.01)
        .collect();
    let (first, last) = (rows[0] as f64, *rows.last().unwrap() as f64 + 1.0);
    let f = scene.camera.frame().focal_px;
    let half = f * (0.5 * scene.sun.unwrap().angular_diameter_rad).tan();
    assert!(
        (first - (50.0 - half)).abs() <= 1.0 && (last - (50.0 + half)).abs() <= 1.0,
        "{first} {last} ±{half}"
    );
    // With straight rays the same sun is below the horizon: not seen.
    let film = render_scene(&scene, &StraightRays::new(R).unwrap(), &quiet()).unwrap();
    assert!(film.pixels.iter().all(|p| (p[0] as f64) < sky[0] + 0.01));
}

#[test]
fn figure_scenes_parse_and_render_with_constant_curvature() {
    let dir = data_dir().join("scenes");
    let mut names: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    names.sort();
    assert!(names.len() >= 6, "{names:?}");
    for path in names {
        let scene = Scene::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            (scene.camera.width, scene.camera.height),
            (400, 200),
            "{}",
            path.display()
        );
        let k = if scene.atmosphere.straight { 0.0 } else { 0.17 };
        let tracer = ConstantCurvatureRays::new(k, scene.earth_radius_m).unwrap();
        let opts = RenderOptions {
            samples_per_pixel: Some(1),
            ..quiet()
        };
        let film = render_scene(&scene, &tracer, &opts).unwrap();
        assert!(film.pixels.iter().flatten().all(|v| v.is_finite()));
        assert_eq!(
            film.stats.cards_in_view,
            scene.cards.len(),
            "{}",
            path.display()
        );
        assert_eq!(film.stats.non_finite_samples, 0);
    }
}

#[test]
fn scene_paths_resolve_against_the_scene_file() {
    let scene = Scene::from_file(&data_dir().join("scenes/fig04_superior_mirage.toml")).unwrap();
    match &scene.atmosphere.source {
        ghostship::atmosphere::AtmosphereSource::Synthetic(p) => {
            assert_eq!(
                p,
                &data_dir().join("scenes").join("../superior_mirage.toml")
            );
        }
        other => panic!("{other:?}"),
    }
    assert!(
        scene
            .cards
            .iter()
            .all(|c| c.image_path.starts_with(data_dir().join("scenes")))
    );
    let _: &Path = scene.source_path.as_deref().unwrap();
}

#[test]
fn card_alpha_lets_farther_cards_show_through() {
    let dir = tempfile::tempdir().unwrap();
    // Near card: left half opaque red, right half fully transparent. Far card: opaque blue.
    let half = image::RgbaImage::from_fn(64, 64, |x, _| {
        if x < 32 {
            image::Rgba([255, 0, 0, 255])
        } else {
            image::Rgba([0, 255, 0, 0])
        }
    });
    half.save(dir.path().join("half.png")).unwrap();
    image::RgbaImage::from_pixel(8, 8, image::Rgba([0, 0, 255, 255]))
        .save(dir.path().join("blue.png"))
        .unwrap();
    let text = "[camera]\nheight_m = 10\nhfov_deg = 0.5\nwidth = 200\nheight = 100\n\
                [atmosphere]\nstraight = true\n\
                [[cards]]\nimage = \"blue.png\"\ndistance_m = 4000\nwidth_m = 30\nheight_m = 40\n\
                [[cards]]\nimage = \"half.png\"\ndistance_m = 2000\nwidth_m = 10\nheight_m = 20\n";
    std::fs::write(dir.path().join("s.toml"), text).unwrap();
    let scene = Scene::from_file(&dir.path().join("s.toml")).unwrap();
    let film = render_scene(&scene, &StraightRays::new(R).unwrap(), &quiet()).unwrap();
    let f = scene.camera.frame().focal_px;
    // A row through both cards: height 10 m at 2 km (and ~15 m at 4 km) — the camera's own
    // height, so about the centre row.
    let y = 49;
    let column = |az_m_at_2km: f64| (100.0 + f * (az_m_at_2km / 2000.0)) as u32;
    let left = film.pixel(column(-2.5), y);
    let right = film.pixel(column(2.5), y);
    assert!(left[0] > 0.9 && left[2] < 0.05, "left {left:?}");
    assert!(
        right[2] > 0.9 && right[0] < 0.05 && right[1] < 0.05,
        "right {right:?}"
    );
}

/// Records what the renderer asks for.
struct Recorder {
    inner: StraightRays,
    calls: std::sync::Mutex<Vec<(Vec<f64>, bool)>>,
    /// Rays launched from the sea surface (the sea fan of its reflections): their distances.
    sea_calls: std::sync::Mutex<Vec<Vec<f64>>>,
}

impl RayTracer for Recorder {
    fn trace(&self, h0: f64, alpha: f64, distances: &[f64], need: bool) -> FanRay {
        if h0 == 0.0 {
            self.sea_calls.lock().unwrap().push(distances.to_vec());
            return self.inner.trace(h0, alpha, distances, need);
        }
        self.calls.lock().unwrap().push((distances.to_vec(), need));
        self.inner.trace(h0, alpha, distances, need)
    }
}

#[test]
fn the_tracer_is_asked_only_for_what_the_scene_needs() {
    let board = data_dir().join("cards/calibration_board.png");
    // One card in view (azimuth 0.1°), one far outside (azimuth 40°), no sun.
    let text = format!(
        "[camera]\nheight_m = 10\nhfov_deg = 1\nwidth = 40\nheight = 20\n\
         [[cards]]\nimage = {board:?}\ndistance_m = 9000\nazimuth_deg = 40\nwidth_m = 8\nheight_m = 20\n\
         [[cards]]\nimage = {board:?}\ndistance_m = 5000\nazimuth_deg = 0.1\nwidth_m = 8\nheight_m = 20\n"
    );
    let (_dir, scene) = scene_in_tempdir(&text);
    for exact in [false, true] {
        let rec = Recorder {
            inner: StraightRays::new(R).unwrap(),
            calls: Default::default(),
            sea_calls: Default::default(),
        };
        let opts = RenderOptions { exact, ..quiet() };
        let film = render_scene(&scene, &rec, &opts).unwrap();
        assert_eq!(film.stats.cards_in_view, 1);
        // The sea's reflections trace their own fan from the sea surface, to ranges up to the
        // card in view (not the one outside), once per frame.
        let sea_calls = rec.sea_calls.into_inner().unwrap();
        assert_eq!(sea_calls.len(), film.stats.sea_fan_rays, "exact={exact}");
        assert!(!sea_calls.is_empty());
        assert!(
            sea_calls
                .iter()
                .all(|d| d.last() == Some(&5000.0) && d[0] == 0.0)
        );
        let calls = rec.calls.into_inner().unwrap();
        assert!(!calls.is_empty());
        assert!(
            calls.iter().all(|(d, need)| d == &[5000.0] && !need),
            "exact={exact}"
        );
        if exact {
            // Every sample, and the frame's lowest ray for the sea's steepest grazing angle.
            assert_eq!(calls.len(), 40 * 20 + 1);
        } else {
            // The fan traces per elevation (≈ one ray per pixel row, plus refinement), never per
            // column.
            assert!(calls.len() < 40 * 20 / 4, "{}", calls.len());
        }
    }
}

#[test]
fn bad_render_options_are_rejected() {
    let (_dir, scene) =
        scene_in_tempdir("[camera]\nheight_m = 10\nhfov_deg = 1\nwidth = 4\nheight = 2\n");
    let t = StraightRays::new(R).unwrap();
    let opts = RenderOptions {
        samples_per_pixel: Some(2),
        ..quiet()
    };
    assert!(
        render_scene(&scene, &t, &opts)
            .unwrap_err()
            .to_string()
            .contains("square")
    );
    let opts = RenderOptions {
        tolerance_px: 0.0,
        ..quiet()
    };
    assert!(render_scene(&scene, &t, &opts).is_err());
    // 9 samples per pixel (3×3 strata) render.
    let opts = RenderOptions {
        samples_per_pixel: Some(9),
        ..quiet()
    };
    let film = render_scene(&scene, &t, &opts).unwrap();
    assert!(film.pixels.iter().flatten().all(|v| v.is_finite()));
}
