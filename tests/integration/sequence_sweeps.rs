//! `ghostship sequence` beyond the sun's elevation and the observer's height: the sun's true
//! position over time (NREL SPA, checked against the paper's published example), the air between
//! two soundings of one station, any numeric scene key, EXR frames and MP4 through an `ffmpeg`
//! on the PATH, the cards' images in the frame index, and the `[[sequence]]` keys of the
//! pipeline and its documentation.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use ghostship::jobs::AtmosphereCache;
use ghostship::jobs::sequence::{
    SequenceRequest, SequenceSettings, SweepSpec, TimeSpan, frame_name,
};
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::render::sweep::render_shared;
use ghostship::render::{
    ConstantCurvatureRays, FanRay, MemoRays, RayTracer, RenderOptions, prepare_tracer,
    render_tracer_config,
};
use ghostship::scene::Scene;
use ghostship::solar::{Site, UtcTime, sun_position_with_delta_t};
use ghostship::tracer::{DensityPathsSoFar, PendingClimb, RayDensityPaths, Tracer};
use ghostship::units::EARTH_RADIUS_M;

use crate::scenes::atmosphere;
use crate::support::cli::{fails, ghostship, ok, output_tree, usage_error};
use crate::support::data::{data_dir, repo_file, sounding};

const DANMARKSHAVN: &str = "seq_danmarkshavn_sunrise.toml";
const UTQIAGVIK: &str = "seq_utqiagvik_twelve_hours.toml";
const GHOST_SHIP: &str = "fig04_superior_mirage.toml";
/// The 2010-06-01 00 and 12 UTC IGRA2 soundings of Utqiagvik.
const IGRA2_PAIR: &str = "raw/USM00070026-data_2010-06-01_excerpt.txt";

fn scene_path(name: &str) -> String {
    data_dir().join("scenes").join(name).display().to_string()
}

/// `ghostship sequence SCENE ARGS… --size 200x100 --spp 1 --out OUT --quiet` with
/// `threads` rayon threads, which must succeed.
fn sequence(scene: &str, out: &Path, args: &[&str], threads: &str) {
    let mut all = vec!["sequence", scene, "--out", out.to_str().unwrap()];
    all.extend(args);
    all.extend(["--size", "200x100", "--spp", "1", "--quiet"]);
    let r = ghostship()
        .env("RAYON_NUM_THREADS", threads)
        .args(&all)
        .output()
        .expect("binary runs");
    assert!(
        r.status.success(),
        "{all:?}: {}",
        String::from_utf8_lossy(&r.stderr)
    );
}

/// `ghostship render SCENE_FILE --size 200x100 --spp 1` → the PNG's bytes.
fn single_render(scene: &Path, dir: &Path) -> Vec<u8> {
    let png = dir.join(format!(
        "{}.png",
        scene.file_stem().unwrap().to_string_lossy()
    ));
    ok(&[
        "render",
        scene.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--size",
        "200x100",
        "--spp",
        "1",
        "--quiet",
    ]);
    std::fs::read(&png).unwrap()
}

/// The rows of `frames.csv` in `out`, each split at commas, after the header (returned first).
fn frames_csv(out: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(out.join("frames.csv")).unwrap();
    let mut lines = text
        .lines()
        .map(|l| l.split(',').map(String::from).collect());
    (lines.next().unwrap(), lines.collect())
}

/// `original` with `edits` (text → replacement; each must change the text) written to
/// `dir/name`, its relative paths (`"../…`) made absolute so that they still hold there.
fn edited_scene(original: &str, dir: &Path, name: &str, edits: &[(&str, String)]) -> PathBuf {
    let mut text = std::fs::read_to_string(original).unwrap();
    for (from, to) in edits {
        assert!(text.contains(from), "{original} has no {from:?}");
        text = text.replacen(from, to, 1);
    }
    let folder = Path::new(original).parent().unwrap().display().to_string();
    let text = text.replace("= \"../", &format!("= \"{folder}/../"));
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Reda & Andreas (2003), Solar Energy 76, 577–589, the example of §A.5 / Table A5.1:
/// 2003-10-17 12:30:30 local time, 7 h west of Greenwich, at 39.742476° N, 105.1786° W,
/// 1830.14 m, ΔT = 67 s, 820 mbar, 11 °C → topocentric zenith 50.11162°, azimuth 194.34024°
/// (zenith with the paper's refraction correction, eq. 42). The refraction is computed here, by
/// the paper's formula, on the unrefracted elevation the program gives.
#[test]
fn the_sun_position_matches_the_nrel_spa_paper_example() {
    let time = UtcTime::parse("2003-10-17T19:30:30Z").unwrap();
    let site = Site {
        lat_deg: 39.742476,
        lon_deg: -105.1786,
        height_m: 1830.14,
    };
    let p = sun_position_with_delta_t(time, &site, 67.0).unwrap();
    let e0 = p.elevation_deg;
    let (pressure_mbar, temperature_c) = (820.0, 11.0);
    let refraction_deg = pressure_mbar / 1010.0 * 283.0 / (273.0 + temperature_c) * 1.02
        / (60.0 * (e0 + 10.3 / (e0 + 5.11)).to_radians().tan());
    let zenith = 90.0 - (e0 + refraction_deg);
    // The paper gives five decimals.
    assert!((zenith - 50.11162).abs() < 1e-5, "zenith {zenith}");
    assert!(
        (p.azimuth_deg - 194.34024).abs() < 1e-5,
        "azimuth {}",
        p.azimuth_deg
    );
}

/// A tracer that counts the calls asked of it, by kind: plain traces, density paths, both at
/// once (their climb out left for later or not), density paths along a ray, climbs out
/// finished.
struct Counting<'a> {
    inner: &'a dyn RayTracer,
    calls: [AtomicUsize; 5],
}

impl<'a> Counting<'a> {
    fn new(inner: &'a dyn RayTracer) -> Self {
        Counting {
            inner,
            calls: Default::default(),
        }
    }

    fn count(&self, kind: usize) {
        self.calls[kind].fetch_add(1, Ordering::Relaxed);
    }

    /// The calls so far, by kind.
    fn calls(&self) -> [usize; 5] {
        self.calls.each_ref().map(|c| c.load(Ordering::Relaxed))
    }
}

impl RayTracer for Counting<'_> {
    fn trace(&self, h: f64, alpha: f64, distances: &[f64], sky: bool) -> FanRay {
        self.count(0);
        self.inner.trace(h, alpha, distances, sky)
    }
    fn density_paths_m(&self, h: f64, alpha: f64, scales: [f64; 2]) -> Option<[f64; 2]> {
        self.count(1);
        self.inner.density_paths_m(h, alpha, scales)
    }
    fn trace_to_sky_with_density_paths(
        &self,
        h: f64,
        alpha: f64,
        scales: [f64; 2],
    ) -> (FanRay, Option<[f64; 2]>) {
        self.count(2);
        self.inner.trace_to_sky_with_density_paths(h, alpha, scales)
    }
    fn trace_to_sky_deferring_density_paths(
        &self,
        h: f64,
        alpha: f64,
        scales: [f64; 2],
    ) -> (FanRay, DensityPathsSoFar) {
        self.count(2);
        self.inner
            .trace_to_sky_deferring_density_paths(h, alpha, scales)
    }
    fn finish_density_paths(&self, climb: &PendingClimb) -> Option<[f64; 2]> {
        self.count(4);
        self.inner.finish_density_paths(climb)
    }
    fn density_paths_along(
        &self,
        h: f64,
        alpha: f64,
        distances: &[f64],
        scales: [f64; 2],
    ) -> Option<RayDensityPaths> {
        self.count(3);
        self.inner.density_paths_along(h, alpha, distances, scales)
    }
}

#[test]
fn with_density_paths_sky_fan_rays_bring_their_paths_and_nothing_else_does() {
    let plain = ConstantCurvatureRays::new(0.13, EARTH_RADIUS_M).unwrap();
    let inner = Counting::new(&plain);
    let scales = [8_000.0, 1_200.0];
    let memo = MemoRays::new(&inner).with_density_paths(Some(scales));
    let alphas: Vec<f64> = (0..50).map(|i| -0.004 + 1e-4 * f64::from(i)).collect();
    for &alpha in &alphas {
        assert_eq!(
            memo.trace(10.0, alpha, &[], true),
            plain.trace(10.0, alpha, &[], true)
        );
    }
    assert_eq!(inner.calls(), [0, 0, 50, 0, 0]);
    // Their paths are remembered: the same values, not asked again.
    let mut escaping = 0;
    for &alpha in &alphas {
        let paths = memo.density_paths_m(10.0, alpha, scales);
        assert_eq!(paths, plain.density_paths_m(10.0, alpha, scales));
        escaping += usize::from(paths.is_some());
    }
    assert!(escaping > 10 && escaping < 50, "{escaping}");
    assert_eq!(inner.calls(), [0, 0, 50, 0, 0]);
    // Rays with distances or without the sky direction are traced alone, and other scale
    // heights are other paths.
    memo.trace(10.0, 0.001, &[5_000.0], true);
    memo.trace(10.0, 0.001, &[], false);
    memo.density_paths_m(10.0, 0.001, [8_000.0, 1_000.0]);
    assert_eq!(inner.calls(), [2, 1, 50, 0, 0]);
    // Without scale heights a sky-fan ray is a plain trace.
    let memo = MemoRays::new(&inner).with_density_paths(None);
    memo.trace(10.0, 0.001, &[], true);
    assert_eq!(inner.calls(), [3, 1, 50, 0, 0]);
}

#[test]
fn a_memo_integrates_a_sky_rays_climb_out_only_when_its_paths_are_asked_for() {
    // The real tracer of a measured sounding, whose sky rays leave their climb out to the top
    // for later.
    let scene = Scene::from_file(Path::new(&scene_path(DANMARKSHAVN))).unwrap();
    let atm = scene.atmosphere.load().unwrap();
    let options = RenderOptions {
        samples_per_pixel: Some(1),
        quiet: true,
        ..RenderOptions::default()
    };
    let tracer = prepare_tracer(&scene, atm.as_ref().map(|a| &a.refractive), &options).unwrap();
    let inner = Counting::new(tracer.as_ref());
    let scales = scene.sky.sun_extinction().scale_heights_m();
    let memo = MemoRays::new(&inner).with_density_paths(Some(scales));
    let h = scene.camera.height_m;
    let alphas: Vec<f64> = (0..40).map(|i| -0.002 + 2e-4 * f64::from(i)).collect();
    for &alpha in &alphas {
        assert_eq!(
            memo.trace(h, alpha, &[], true),
            tracer.trace(h, alpha, &[], true)
        );
    }
    assert_eq!(inner.calls(), [0, 0, 40, 0, 0]);
    // Every other ray's paths, twice: the values of the tracer's own call, each climb
    // integrated once, on the first asking.
    let mut first_climbs = None;
    for pass in 0..2 {
        let mut escaping = 0;
        for &alpha in alphas.iter().step_by(2) {
            let paths = memo.density_paths_m(h, alpha, scales);
            assert_eq!(paths, tracer.density_paths_m(h, alpha, scales), "{alpha}");
            escaping += usize::from(paths.is_some());
        }
        assert!(escaping > 5, "{escaping}");
        let [traces, paths, both, along, climbs] = inner.calls();
        assert_eq!([traces, paths, both, along], [0, 0, 40, 0], "pass {pass}");
        assert!(climbs > 5 && climbs <= escaping, "{climbs} of {escaping}");
        assert_eq!(*first_climbs.get_or_insert(climbs), climbs, "pass {pass}");
    }
}

/// A sweep of the sun over time through the Danmarkshavn sounding, the camera turning with it.
fn danmarkshavn_over_time(span: &str, step_min: f64) -> SequenceRequest {
    let scene = Scene::from_file(Path::new(&scene_path(DANMARKSHAVN))).unwrap();
    let sweep = SweepSpec::SunTime {
        span: TimeSpan::parse(span, step_min).unwrap(),
        lat_lon_deg: None,
        follow_sun: true,
    };
    let settings = SequenceSettings {
        size: Some((200, 100)),
        spp: Some(1),
        ..SequenceSettings::new(sweep)
    };
    SequenceRequest::new(scene, settings).unwrap()
}

#[test]
fn a_sun_sweep_over_time_traces_its_rays_once_though_sun_and_camera_turn() {
    let request = danmarkshavn_over_time("2026-02-11T12:30Z/2026-02-11T14:30Z", 12.0);
    let scenes = request.frame_scenes();
    assert_eq!(scenes.len(), 11);
    // The site is the sounding's station: the sun turns by ~30° in azimuth over two hours.
    let turn = scenes[10].camera.heading_rad - scenes[0].camera.heading_rad;
    assert!(turn.to_degrees() > 25.0, "{}", turn.to_degrees());
    let cache = AtmosphereCache::new();
    let air = cache.get(request.atmosphere().unwrap()).unwrap();
    let options = RenderOptions {
        samples_per_pixel: Some(1),
        quiet: true,
        ..RenderOptions::default()
    };
    let tracer = prepare_tracer(&scenes[0], Some(&air.refractive), &options).unwrap();
    let rays = |scenes: &[Scene]| {
        let counting = Counting::new(tracer.as_ref());
        let frames = render_shared(scenes, &counting, &options, false).unwrap();
        (counting.calls()[..4].iter().sum::<usize>(), frames)
    };
    let (one, _) = rays(&scenes[5..6]);
    let (all, frames) = rays(&scenes);
    // Each further frame traces at most a fifth of the rays of a frame alone: the new rays
    // around its sun (ten frames rendered apart would trace ten times `one`).
    assert!(
        5 * (all - one) <= 10 * one,
        "{all} rays for 11 frames, {one} for one"
    );
    // The sun is seen through this air though its true elevation stays below −0.6°.
    let seen = frames
        .iter()
        .filter(|f| f.facts.sun.unwrap().strips > 0)
        .count();
    assert!(seen >= 5, "{seen}");
    assert!(
        scenes
            .iter()
            .all(|s| s.sun.unwrap().elevation_rad.to_degrees() < -0.6)
    );
}

#[test]
fn sun_frames_over_time_are_single_renders_of_the_sun_where_spa_puts_it() {
    let dir = tempfile::tempdir().unwrap();
    let (two, one) = (dir.path().join("two"), dir.path().join("one"));
    let args = [
        "--time-utc",
        "2026-02-11T12:00Z/2026-02-11T14:00Z",
        "--step-min",
        "40",
        "--follow-sun",
    ];
    let scene = scene_path(DANMARKSHAVN);
    sequence(&scene, &two, &args, "2");
    let (header, rows) = frames_csv(&two);
    assert_eq!(
        header[..5],
        [
            "frame",
            "time_utc",
            "sun_true_elevation_deg",
            "sun_azimuth_deg",
            "camera_heading_deg"
        ]
    );
    assert_eq!(rows.len(), 4);
    assert_eq!(rows[3][1], "2026-02-11T14:00:00Z");
    for (i, row) in rows.iter().enumerate() {
        let (elevation, azimuth) = (&row[2], &row[3]);
        let path = edited_scene(
            &scene,
            dir.path(),
            &format!("sun_time_{i}.toml"),
            &[
                (
                    "elevation_deg = -1.0",
                    format!("elevation_deg = {elevation}"),
                ),
                ("azimuth_deg = 180.0", format!("azimuth_deg = {azimuth}")),
                ("heading_deg = 180.0", format!("heading_deg = {azimuth}")),
            ],
        );
        let single = single_render(&path, dir.path());
        let frame = std::fs::read(two.join(frame_name(i))).unwrap();
        assert!(
            single == frame,
            "frame {i} ({}) differs from render",
            row[1]
        );
    }
    // The time sweep's figure and the same bytes with one thread.
    assert!(image::open(two.join("sun.png")).is_ok());
    sequence(&scene, &one, &args, "1");
    let (a, b) = (output_tree(&one), output_tree(&two));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, bytes) in &a {
        assert!(bytes == &b[name], "{name} differs between 1 and 2 threads");
    }
}

#[test]
fn the_air_between_two_soundings_starts_and_ends_at_each() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("twelve");
    let scene = scene_path(UTQIAGVIK);
    let pair = sounding(IGRA2_PAIR);
    let pair = pair.to_str().unwrap();
    let args = [
        "--to-sounding",
        pair,
        "--to-sounding-time",
        "2010-06-01 12",
        "--step-min",
        "240",
    ];
    sequence(&scene, &out, &args, "2");
    let (header, rows) = frames_csv(&out);
    assert_eq!(header[1..3], ["time_utc", "second_sounding_weight"]);
    let times: Vec<&str> = rows.iter().map(|r| r[1].as_str()).collect();
    assert_eq!(
        times,
        [
            "2010-06-01T00:00:00Z",
            "2010-06-01T04:00:00Z",
            "2010-06-01T08:00:00Z",
            "2010-06-01T12:00:00Z"
        ]
    );
    let weights: Vec<f64> = rows.iter().map(|r| r[2].parse().unwrap()).collect();
    assert_eq!(weights[0], 0.0);
    assert!((weights[1] - 1.0 / 3.0).abs() < 1e-15 && weights[3] == 1.0);
    // The first frame is the 00 UTC scene, the last the same scene at 12 UTC.
    let first = single_render(Path::new(&scene), dir.path());
    let noon = edited_scene(
        &scene,
        dir.path(),
        "noon.toml",
        &[(
            "sounding_time = \"2010-06-01 00\"",
            "sounding_time = \"2010-06-01 12\"".into(),
        )],
    );
    let last = single_render(&noon, dir.path());
    let frame = |i: usize| std::fs::read(out.join(frame_name(i))).unwrap();
    assert!(frame(0) == first, "frame 0 is not the 00 UTC render");
    assert!(frame(3) == last, "frame 3 is not the 12 UTC render");
    assert!(first != last, "the twelve hours change nothing");
    // Between them the air is neither: the middle frames differ from both ends.
    assert!(frame(1) != first && frame(2) != last);
}

#[test]
fn bad_sweeps_between_soundings_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let pair = sounding(IGRA2_PAIR);
    let pair = pair.to_str().unwrap();
    let danmarkshavn = repo_file("data/Danmarkshavn-04320_2026020523_all-levels.csv");
    for (scene, to, time, message) in [
        // Another station.
        (
            UTQIAGVIK,
            danmarkshavn.to_str().unwrap(),
            None,
            "not of one station",
        ),
        // The same sounding is not later.
        (UTQIAGVIK, pair, Some("2010-06-01 00"), "must be later"),
        // A scene whose air is not a sounding.
        (
            GHOST_SHIP,
            pair,
            Some("2010-06-01 12"),
            "must name a `sounding`",
        ),
        // A time the file does not hold.
        (UTQIAGVIK, pair, Some("2010-06-05 12"), "2010-06-05 12"),
    ] {
        let scene = scene_path(scene);
        let mut args = vec!["sequence", &scene, "--out", out, "--to-sounding", to];
        args.extend(["--step-min", "60"]);
        if let Some(t) = time {
            args.extend(["--to-sounding-time", t]);
        }
        let r = fails(&args);
        assert!(r.stderr.contains(message), "{args:?}: {}", r.stderr);
    }
    let r = usage_error(&["sequence", &scene_path(UTQIAGVIK), "--to-sounding", pair]);
    assert!(r.stderr.contains("--step-min"), "{}", r.stderr);
}

#[test]
fn a_key_sweep_renders_the_scene_file_with_that_key_set() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("distance");
    let scene = scene_path(GHOST_SHIP);
    sequence(
        &scene,
        &out,
        &["--sweep", "cards[1].distance_m=40000:60000:10000"],
        "2",
    );
    let (header, rows) = frames_csv(&out);
    assert_eq!(header[1], "cards[1].distance_m");
    let values: Vec<&str> = rows.iter().map(|r| r[1].as_str()).collect();
    assert_eq!(values, ["40000", "50000", "60000"]);
    for (i, value) in values.iter().enumerate() {
        let path = edited_scene(
            &scene,
            dir.path(),
            &format!("key_{i}.toml"),
            &[("distance_m = 60000.0", format!("distance_m = {value}.0"))],
        );
        let frame = std::fs::read(out.join(frame_name(i))).unwrap();
        assert!(
            single_render(&path, dir.path()) == frame,
            "frame {i} ({value} m)"
        );
    }
    // The nearer ship is not swept: its facts are the same in every frame.
    let near: Vec<&[String]> = rows.iter().map(|r| &r[2..5]).collect();
    assert!(near.windows(2).all(|w| w[0] == w[1]), "{near:?}");
}

#[test]
fn bad_key_sweeps_are_clear_errors() {
    let scene = scene_path(GHOST_SHIP);
    for (sweep, message) in [
        ("camera.width=100:200:100", "not a numeric scene key"),
        ("camera.width=100:200:100", "cards[].distance_m"),
        ("camera.hfov_deg", "KEY=FROM:TO:STEP"),
        ("cards[x].base_m=0:1:1", "whole number"),
        ("sun.azimuth_deg=2:1:1", "TO must not be below FROM"),
    ] {
        let r = usage_error(&["sequence", &scene, "--sweep", sweep]);
        assert!(r.stderr.contains(message), "{sweep}: {}", r.stderr);
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    for (sweep, message) in [
        (
            "cards[2].distance_m=1000:2000:1000",
            "the scene has 2 card(s)",
        ),
        ("sun.azimuth_deg=0:10:5", "no [sun]"),
        ("camera.hfov_deg=0:1:0.5", "camera.hfov_deg"),
        ("camera.hfov_deg=0:1:0.5", "the value 0 is refused"),
    ] {
        let r = fails(&["sequence", &scene, "--out", out, "--sweep", sweep]);
        assert!(r.stderr.contains(message), "{sweep}: {}", r.stderr);
    }
}

/// Images of `card` along column `x` by the analysis tracer: runs of rows whose ray passes the
/// card's distance between its base and top.
fn traced_images(
    scene: &Scene,
    card: usize,
    x: u32,
    tracer: &Tracer<'_, RefractiveAtmosphere>,
) -> usize {
    let c = &scene.cards[card];
    let frame = scene.camera.frame();
    let (mut images, mut previous) = (0, false);
    for y in 0..scene.camera.height {
        let alpha = frame
            .view_direction(x as f64 + 0.5, y as f64 + 0.5)
            .elevation_rad;
        let r = tracer
            .trace(scene.camera.height_m, alpha, &[c.distance_m])
            .unwrap();
        let shows = r.heights_m[0].is_some_and(|h| h >= c.base_m && h <= c.base_m + c.height_m);
        if shows && !previous {
            images += 1;
        }
        previous = shows;
    }
    images
}

#[test]
fn the_frame_index_counts_each_cards_images_as_the_traced_map_shows_them() {
    let scene = Scene::from_file(Path::new(&scene_path(GHOST_SHIP))).unwrap();
    let sweep = ghostship::jobs::sequence::parse_sweep(
        ghostship::jobs::sequence::SweepKind::ObserverHeightM,
        "20:110:10",
    )
    .unwrap();
    let settings = SequenceSettings {
        spp: Some(1),
        ..SequenceSettings::new(sweep)
    };
    let request = SequenceRequest::new(scene.clone(), settings).unwrap();
    let frames = request.render_frames(&AtmosphereCache::new()).unwrap();
    let atm = atmosphere(&scene);
    let tracer = Tracer::new(&atm, render_tracer_config(scene.earth_radius_m)).unwrap();
    let mut far = Vec::new();
    for (frame, s) in frames.iter().zip(request.frame_scenes()) {
        for (k, facts) in frame.facts.cards.iter().enumerate() {
            let x = ghostship::render::sweep::card_column(&s, &s.cards[k]).expect("in view");
            let facts = facts.expect("the card is in view");
            let want = traced_images(&s, k, x, &tracer);
            assert_eq!(facts.images, want, "card {k} from {} m", s.camera.height_m);
            if k == 1 {
                far.push(want);
            }
        }
        // The transfer curve is sampled at the far ship's distance.
        let t = frame
            .transfer
            .as_ref()
            .expect("an observer sweep samples its transfer curve");
        assert_eq!(t.distance_m, 60_000.0);
        assert_eq!(t.camera_height_m, s.camera.height_m);
    }
    // The far ship: hidden from 20 m, a mirage of it from higher up, two images at 100 m.
    assert_eq!(far[0], 0, "{far:?}");
    assert!(far.iter().any(|&n| n >= 2), "{far:?}");
}

#[test]
fn exr_frames_carry_the_render_pixels_and_the_swept_value() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("exr");
    let scene = scene_path(GHOST_SHIP);
    sequence(
        &scene,
        &out,
        &["--observer-height-m=30:40:10", "--exr"],
        "2",
    );
    let tree = output_tree(&out);
    assert!(tree.contains_key("frame_0000.exr") && tree.contains_key("frame_0001.exr"));
    // The EXR's pixels are the film behind the PNG: rendered alone at 40 m, the same.
    let base = Scene::from_file(Path::new(&scene)).unwrap();
    let request = ghostship::jobs::RenderRequest::new(
        base,
        ghostship::jobs::render::RenderSettings {
            sizes: vec![Some((200, 100))],
            spp: Some(1),
            observer_height_m: Some(40.0),
            ..Default::default()
        },
    )
    .unwrap();
    let cache = AtmosphereCache::new();
    let air = cache.get(request.atmosphere.as_ref().unwrap()).unwrap();
    let (film, _) = request.film(Some((200, 100)), Some(&air), true).unwrap();
    let path = out.join("frame_0001.exr");
    let image = ::exr::prelude::read_first_rgba_layer_from_file(
        &path,
        |_res, _| vec![[0.0f32; 4]; 200 * 100],
        |buf: &mut Vec<[f32; 4]>,
         pos: ::exr::prelude::Vec2<usize>,
         (r, g, b, a): (f32, f32, f32, f32)| {
            buf[pos.y() * 200 + pos.x()] = [r, g, b, a];
        },
    )
    .unwrap();
    assert!(
        image.layer_data.channel_data.pixels == film.pixels,
        "EXR pixels differ"
    );
    let lines: Vec<String> = match image
        .layer_data
        .attributes
        .other
        .get(&::exr::meta::attribute::Text::from("ghostship"))
    {
        Some(::exr::meta::attribute::AttributeValue::TextVector(v)) => {
            v.iter().map(|t| t.to_string()).collect()
        }
        other => panic!("no provenance: {other:?}"),
    };
    for want in [
        "observer_height_m=40",
        "sequence_frame=1",
        "sequence_values=40",
    ] {
        assert!(lines.iter().any(|l| l == want), "{want}: {lines:?}");
    }
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("sequence_sweep=camera.height_m")),
        "{lines:?}"
    );
}

#[test]
fn without_ffmpeg_on_the_path_the_mp4_is_skipped_with_a_note() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("nompeg");
    let r = ghostship()
        .env("PATH", "")
        .args([
            "sequence",
            &scene_path(GHOST_SHIP),
            "--out",
            out.to_str().unwrap(),
            "--observer-height-m=30:40:10",
            "--size",
            "80x40",
            "--spp",
            "1",
            "--mp4",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{stderr}");
    assert!(stderr.contains("ffmpeg is not on the PATH"), "{stderr}");
    assert!(!out.join("sequence.mp4").exists());
    assert!(out.join("sequence.gif").is_file() && out.join(frame_name(1)).is_file());
}

/// A stand-in `ffmpeg` on the PATH receives the frames and the arguments, and what it writes is
/// `sequence.mp4`.
#[cfg(unix)]
#[test]
fn the_mp4_is_what_ffmpeg_on_the_path_writes_from_the_numbered_frames() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let fake = bin.join("ffmpeg");
    // Writes its arguments and the files in the output's folder (shell built-ins only: the PATH
    // holds nothing else) to the output file.
    std::fs::write(
        &fake,
        "#!/bin/sh\nfor last; do :; done\n\
         { echo \"$*\"; for f in \"${last%/*}\"/*; do echo \"${f##*/}\"; done; } > \"$last\"\n",
    )
    .unwrap();
    std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
    let out = dir.path().join("mp4");
    let r = ghostship()
        .env("PATH", &bin)
        .args([
            "sequence",
            &scene_path(GHOST_SHIP),
            "--out",
            out.to_str().unwrap(),
            "--observer-height-m=30:50:10",
            "--size",
            "81x41",
            "--spp",
            "1",
            "--mp4",
            "--quiet",
        ])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let mp4 = std::fs::read_to_string(out.join("sequence.mp4")).unwrap();
    let mut lines = mp4.lines();
    let args = lines.next().unwrap();
    for want in [
        "-framerate 1000/80",
        "frame_%04d.png",
        "-c:v libx264",
        "-pix_fmt yuv420p",
    ] {
        assert!(args.contains(want), "{want}: {args}");
    }
    // It saw the three frames, numbered as the output's.
    let files: Vec<&str> = lines.collect();
    for i in 0..3 {
        assert!(files.contains(&frame_name(i).as_str()), "{files:?}");
    }
    // The scratch folder is gone.
    let folder = Path::new(args.rsplit(' ').next().unwrap())
        .parent()
        .unwrap()
        .to_path_buf();
    assert!(!folder.exists(), "{}", folder.display());
    // A failing ffmpeg is an error that says so.
    std::fs::write(&fake, "#!/bin/sh\necho no encoder >&2\nexit 3\n").unwrap();
    let r = ghostship()
        .env("PATH", &bin)
        .args([
            "sequence",
            &scene_path(GHOST_SHIP),
            "--out",
            out.to_str().unwrap(),
            "--observer-height-m=30:30:10",
            "--size",
            "40x20",
            "--spp",
            "1",
            "--mp4",
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("ffmpeg") && stderr.contains("no encoder"),
        "{stderr}"
    );
}

#[test]
fn pipeline_sequences_of_every_kind_resolve_and_bad_tables_are_located() {
    let shipped = repo_file("pipelines/sequences.toml");
    let p = ghostship::pipeline::ResolvedPipeline::from_file(&shipped)
        .unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<&str> = p.jobs.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "novaya_zemlya_sunrise",
            "climbing_observer",
            "danmarkshavn_sunrise",
            "danmarkshavn_day",
            "utqiagvik_twelve_hours",
        ]
    );
    let dir = tempfile::tempdir().unwrap();
    let pipeline = dir.path().join("p.toml");
    for (table, message) in [
        (
            format!(
                "scene = {:?}\ntime_utc = \"2026-02-11T12:00Z\"\nstep_min = 5\n",
                scene_path(DANMARKSHAVN)
            ),
            "FROM/TO",
        ),
        (
            format!(
                "scene = {:?}\nsweep = \"camera.heading_deg=0:1:1\"\nobserver_height_m = \"5:6:1\"\n",
                scene_path(GHOST_SHIP)
            ),
            "one sweep per sequence",
        ),
        (
            format!(
                "scene = {:?}\ntime_utc = \"2026-02-11T12:00Z/2026-02-11T13:00Z\"\nstep_min = 5\nlat_deg = 70\n",
                scene_path(DANMARKSHAVN)
            ),
            "give both lat_deg and lon_deg",
        ),
        (
            format!(
                "scene = {:?}\nsweep = \"camera.width=1:2:1\"\n",
                scene_path(GHOST_SHIP)
            ),
            "not a numeric scene key",
        ),
    ] {
        std::fs::write(&pipeline, format!("[[sequence]]\n{table}")).unwrap();
        let e = ghostship::pipeline::ResolvedPipeline::from_file(&pipeline)
            .unwrap_err()
            .to_string();
        assert!(e.contains(message), "{table}: {e}");
        assert!(e.contains("line"), "{e}");
    }
}

/// The keys of the `[[sequence]]` table of docs/pipeline.md: its first column.
fn documented_sequence_keys() -> Vec<String> {
    let doc = std::fs::read_to_string(repo_file("docs/pipeline.md")).unwrap();
    let start = doc
        .find("## `[[sequence]]`")
        .expect("a [[sequence]] section");
    let section = &doc[start..];
    let end = section[3..].find("\n## ").map_or(section.len(), |e| e + 3);
    section[..end]
        .lines()
        .filter_map(|l| l.strip_prefix("| `"))
        .filter_map(|l| l.split('`').next())
        .map(String::from)
        .collect()
}

#[test]
fn docs_pipeline_md_documents_exactly_the_sequence_keys() {
    let mut documented = documented_sequence_keys();
    let mut accepted: Vec<String> = ghostship::pipeline::SEQUENCE_KEYS
        .iter()
        .map(|k| k.to_string())
        .collect();
    documented.sort();
    accepted.sort();
    assert_eq!(documented, accepted);
}
