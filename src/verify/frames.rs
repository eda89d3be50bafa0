//! Verification, frames — the rendering half of the `bench accuracy` study. In: the paper scenes
//! (`data/scenes/*.toml`, loaded as `ghostship render` loads them: [`load_paper_scenes`]) and a
//! [`FrameConfig`]. Out: per scene and size, the time per frame of the fan path, the exact
//! per-pixel 3-D path and straight rays, with the fan tracer's rays and steps inside the frame
//! ([`FrameTiming`]); per curved scene and tolerance, the image error of both curved paths
//! against renders at a far tighter tolerance ([`SceneSweep`]); per spectral scene
//! ([`SPECTRAL_SCENES`]) and size, its spectral frame's time against its RGB frame's
//! ([`SpectralTiming`]). The tables and the plot are in
//! [`frames_report`](super::frames_report).
//!
//! Every frame is rendered through the library's render API ([`prepare_tracer`] and
//! [`render_scene`]) with one sample per pixel; the time is that of [`render_scene`] alone (not
//! loading the scene, the atmosphere or the cards, not preparing the tracer, not encoding), on
//! all threads.
//!
//! The reference renders are `ghostship render`'s at the tightest tolerance it accepts (the low
//! end of [`TRACER_TOLERANCE_RANGE_M`]; the ray study's 1e-7 m is outside that range), with the
//! renderer's own step budget. Rays that end [`FanEnd::Trapped`] (in a duct for ever) or
//! [`FanEnd::Lost`] (cut short by the step budget) are shaded as the horizon-sky fallback; every
//! render of the sweep counts both, apart, so a reference that has lost rays shows it.
//!
//! Image error is measured on the 8-bit sRGB pixels of the PNG output ([`film_to_srgb8`] at the
//! configured exposure): the fraction of pixels of which any channel differs, and the largest
//! channel difference (of 255).

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

use crate::atmosphere::{AtmosphereError, LoadedAtmosphere};
use crate::output::png::{DEFAULT_EXPOSURE, film_to_srgb8};
use crate::refractivity::RefractiveAtmosphere;
use crate::render::curved::cards_top_m;
use crate::render::spectral::{SpectralError, render_spectral};
use crate::render::{
    CurvedRays, FanEnd, FanRay, Film, PrepareError, RayTracer, RenderError, RenderOptions,
    TRACER_TOLERANCE_RANGE_M, prepare_tracer, render_scene, render_tracer_config,
};
use crate::scene::{Scene, SceneError};
use crate::tracer::{DensityPathsSoFar, PendingClimb, RayDensityPaths, RayRecord, TracerConfig};

use super::stats::median;

/// The scene files of the paper's figures (in `data/scenes/`, rendered by
/// `pipelines/paper.toml`).
pub const PAPER_SCENES: [&str; 9] = [
    "fig01_horizon_straight.toml",
    "fig01b_horizon_curved.toml",
    "fig02_horizon_distortion.toml",
    "fig04a_superior_mirage_paper_camera.toml",
    "fig04_superior_mirage.toml",
    "fig08_inferior_mirage.toml",
    "fig10_fata_morgana.toml",
    "fig12_novaya_zemlya.toml",
    "fig12b_novaya_zemlya_strips.toml",
];

/// Scene files (in `data/scenes/`) rendered spectrally (`[render] spectral_bands`), timed
/// against the same scene on the RGB path ([`time_spectral`]).
pub const SPECTRAL_SCENES: [&str; 1] = ["fig13_green_flash.toml"];

/// What to measure.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameConfig {
    /// Tracer tolerances (m) of the image-error sweep, loosest first; within
    /// [`TRACER_TOLERANCE_RANGE_M`].
    pub tolerances_m: Vec<f64>,
    /// Tolerance of the reference renders (m), below every swept one and within
    /// [`TRACER_TOLERANCE_RANGE_M`].
    pub reference_tolerance_m: f64,
    /// Frame size of the image-error sweep (width, height), both curved paths.
    pub sweep_size: (u32, u32),
    /// Frame sizes (width, height) timed at the render default tolerance.
    pub timing_sizes: Vec<(u32, u32)>,
    /// Timed renders per frame of the fan path and straight rays (the median is reported).
    pub repetitions: usize,
    /// Timed renders per frame of the exact path (the median is reported).
    pub exact_repetitions: usize,
    /// Exact-path frames with more pixels than this are timed on a proxy: the same scene at a
    /// size divided by the smallest integer that brings it within this many pixels (same field
    /// of view), its time scaled by the ratio of pixel counts (every pixel is traced).
    pub exact_max_pixels: u64,
    /// PNG exposure of the compared pixels.
    pub exposure: f64,
}

impl FrameConfig {
    /// The full study: tolerances 10 m … 1e-5 m at 200×100 against 1e-6 m; frames timed at
    /// 400×200 and 1920×1080, five runs (exact path: one run, 1920×1080 on a proxy of at most
    /// 400×200's pixel count).
    pub fn full() -> Self {
        FrameConfig {
            tolerances_m: vec![10.0, 1.0, 0.1, 0.01, 1e-3, 1e-4, 1e-5],
            reference_tolerance_m: TRACER_TOLERANCE_RANGE_M.0,
            sweep_size: (200, 100),
            timing_sizes: vec![(400, 200), (1920, 1080)],
            repetitions: 5,
            exact_repetitions: 1,
            exact_max_pixels: 80_000,
            exposure: DEFAULT_EXPOSURE,
        }
    }

    /// A quick run that takes every code path: three tolerances at 40×20, frames timed at 80×40
    /// and 192×108 (the exact path's 192×108 on a proxy), two runs.
    pub fn quick() -> Self {
        FrameConfig {
            tolerances_m: vec![1.0, 0.01, 1e-4],
            sweep_size: (40, 20),
            timing_sizes: vec![(80, 40), (192, 108)],
            repetitions: 2,
            exact_max_pixels: 3_200,
            ..Self::full()
        }
    }

    fn check(&self) -> Result<(), FrameError> {
        let bad = |m: &str| Err(FrameError::InvalidConfig(m.to_string()));
        let (lo, hi) = TRACER_TOLERANCE_RANGE_M;
        if self.tolerances_m.is_empty()
            || self
                .tolerances_m
                .iter()
                .any(|t| !(t.is_finite() && (lo..=hi).contains(t)))
        {
            return bad("sweep tolerances must lie within the render's tolerance range");
        }
        let tightest = self
            .tolerances_m
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        let r = self.reference_tolerance_m;
        if !(r >= lo && r < tightest) {
            return bad(
                "the reference tolerance must be within the render's range, below every swept one",
            );
        }
        let sizes = std::iter::once(&self.sweep_size).chain(&self.timing_sizes);
        if sizes.clone().any(|&(w, h)| w == 0 || h == 0) || self.timing_sizes.is_empty() {
            return bad("frame sizes must be at least 1×1, and at least one timing size");
        }
        if self.repetitions == 0 || self.exact_repetitions == 0 || self.exact_max_pixels == 0 {
            return bad("at least one run per frame and one pixel per exact frame");
        }
        if !(self.exposure.is_finite() && self.exposure > 0.0) {
            return bad("the exposure must be finite and > 0");
        }
        Ok(())
    }
}

/// Why the frame study could not run.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// A setting is out of range.
    #[error("invalid frame benchmark setting: {0}")]
    InvalidConfig(String),
    /// A scene file could not be loaded.
    #[error("cannot load the paper scene {path}")]
    Scene {
        /// The file.
        path: PathBuf,
        /// Why (boxed: the loader's error is large).
        #[source]
        source: Box<SceneError>,
    },
    /// A scene's atmosphere could not be loaded.
    #[error("cannot load the atmosphere of {name}")]
    Atmosphere {
        /// The scene.
        name: String,
        /// Why (boxed: the loader's error is large).
        #[source]
        source: Box<AtmosphereError>,
    },
    /// The ray tracer for a scene could not be built.
    #[error("cannot prepare the ray tracer for {name}")]
    Prepare {
        /// The scene.
        name: String,
        /// Why.
        #[source]
        source: PrepareError,
    },
    /// A render refused its options.
    #[error("cannot render {name}")]
    Render {
        /// The scene.
        name: String,
        /// Why.
        #[source]
        source: RenderError,
    },
    /// Two images of different sizes were compared.
    #[error("cannot compare images of {a} and {b} bytes (8-bit RGB, the same size)")]
    Compare {
        /// Bytes of the first.
        a: usize,
        /// Bytes of the second.
        b: usize,
    },
    /// The plot could not be drawn.
    #[error("cannot draw the frame-time plot: {0}")]
    Plot(String),
}

/// A paper scene with its atmosphere, loaded once.
pub struct PaperScene {
    /// The file's stem (table heading).
    pub name: String,
    /// The scene as the file gives it.
    pub scene: Scene,
    /// Its atmosphere; `None` for a straight-ray scene.
    pub atmosphere: Option<LoadedAtmosphere>,
}

impl PaperScene {
    /// The refractive atmosphere of a curved-ray scene.
    pub fn refractive(&self) -> Option<&RefractiveAtmosphere> {
        self.atmosphere.as_ref().map(|a| &a.refractive)
    }
}

/// Load every scene of [`PAPER_SCENES`] from `scenes_dir` with its atmosphere.
pub fn load_paper_scenes(scenes_dir: &Path) -> Result<Vec<PaperScene>, FrameError> {
    load_scenes(scenes_dir, &PAPER_SCENES)
}

/// Load every scene of [`SPECTRAL_SCENES`] from `scenes_dir` with its atmosphere.
pub fn load_spectral_scenes(scenes_dir: &Path) -> Result<Vec<PaperScene>, FrameError> {
    load_scenes(scenes_dir, &SPECTRAL_SCENES)
}

fn load_scenes(scenes_dir: &Path, files: &[&str]) -> Result<Vec<PaperScene>, FrameError> {
    files
        .iter()
        .map(|file| {
            let path = scenes_dir.join(file);
            let scene = Scene::from_file(&path).map_err(|source| FrameError::Scene {
                path: path.clone(),
                source: Box::new(source),
            })?;
            let name = file.trim_end_matches(".toml").to_string();
            let atmosphere = scene
                .atmosphere
                .load()
                .map_err(|source| FrameError::Atmosphere {
                    name: name.clone(),
                    source: Box::new(source),
                })?;
            Ok(PaperScene {
                name,
                scene,
                atmosphere,
            })
        })
        .collect()
}

/// How a frame's rays are traced.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RenderPath {
    /// Curved rays: one elevation fan per frame, interpolated per pixel ([`CurvedRays`]).
    Fan,
    /// Curved rays: the full 3-D ray equation per pixel sample ([`ExactRays`](crate::render::curved::ExactRays)).
    Exact,
    /// Straight rays (n ≡ 1, closed form), through the fan.
    Straight,
}

impl RenderPath {
    /// The name used in tables and legends.
    pub fn label(self) -> &'static str {
        match self {
            RenderPath::Fan => "fan",
            RenderPath::Exact => "exact 3-D",
            RenderPath::Straight => "straight rays",
        }
    }
}

/// `scene` at `size`, with straight rays if `straight` (as `render --size WxH [--straight]`).
fn variant(scene: &Scene, size: (u32, u32), straight: bool) -> Scene {
    let mut s = scene.clone();
    s.camera.width = size.0;
    s.camera.height = size.1;
    s.atmosphere.straight = s.atmosphere.straight || straight;
    s
}

/// Render options: one sample per pixel, no progress bar.
fn options(path: RenderPath, tolerance_m: f64) -> RenderOptions {
    RenderOptions {
        exact: path == RenderPath::Exact,
        samples_per_pixel: Some(1),
        quiet: true,
        tolerance_m,
        ..RenderOptions::default()
    }
}

/// The tracer `ghostship render` would use for `scene` (already a [`variant`]) on `path`.
fn prepared<'a>(
    ps: &'a PaperScene,
    scene: &Scene,
    path: RenderPath,
    tolerance_m: f64,
) -> Result<Box<dyn RayTracer + 'a>, FrameError> {
    let atmosphere = if path == RenderPath::Straight {
        None
    } else {
        ps.refractive()
    };
    prepare_tracer(scene, atmosphere, &options(path, tolerance_m)).map_err(|source| {
        FrameError::Prepare {
            name: ps.name.clone(),
            source,
        }
    })
}

/// Render `scene` through `tracer` on `path`, `runs` times; the median time (s) and the film.
/// `tolerance_m` is only checked by the render API (the tracer carries its own).
fn timed_render(
    name: &str,
    scene: &Scene,
    tracer: &dyn RayTracer,
    path: RenderPath,
    tolerance_m: f64,
    runs: usize,
) -> Result<(f64, Film), FrameError> {
    let opts = options(path, tolerance_m);
    let mut times = Vec::with_capacity(runs);
    let mut film = None;
    for _ in 0..runs.max(1) {
        let start = Instant::now();
        let f = render_scene(scene, tracer, &opts).map_err(|source| FrameError::Render {
            name: name.to_string(),
            source,
        })?;
        times.push(start.elapsed().as_secs_f64());
        film = Some(f);
    }
    let seconds = median(&mut times).unwrap_or(f64::NAN);
    film.map(|f| (seconds, f)).ok_or(FrameError::InvalidConfig(
        "at least one run per frame".into(),
    ))
}

/// How two 8-bit images differ.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PixelDiff {
    /// Pixels compared.
    pub pixels: usize,
    /// Pixels of which at least one channel differs.
    pub changed: usize,
    /// Largest difference of one channel (of 255).
    pub max_channel: u8,
}

impl PixelDiff {
    /// The fraction of pixels changed (0 for no pixels).
    pub fn changed_fraction(&self) -> f64 {
        if self.pixels == 0 {
            0.0
        } else {
            self.changed as f64 / self.pixels as f64
        }
    }

    /// Both comparisons as one: pixels and changes added, the larger maximum.
    pub fn combined(self, other: PixelDiff) -> PixelDiff {
        PixelDiff {
            pixels: self.pixels + other.pixels,
            changed: self.changed + other.changed,
            max_channel: self.max_channel.max(other.max_channel),
        }
    }
}

/// Compare two 8-bit RGB images (row-major, 3 bytes a pixel) of the same size.
pub fn pixel_diff(a: &[u8], b: &[u8]) -> Result<PixelDiff, FrameError> {
    if a.len() != b.len() || !a.len().is_multiple_of(3) {
        return Err(FrameError::Compare {
            a: a.len(),
            b: b.len(),
        });
    }
    let mut d = PixelDiff {
        pixels: a.len() / 3,
        ..PixelDiff::default()
    };
    for (p, q) in a.chunks_exact(3).zip(b.chunks_exact(3)) {
        let m = p
            .iter()
            .zip(q)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap_or(0);
        if m > 0 {
            d.changed += 1;
            d.max_channel = d.max_channel.max(m);
        }
    }
    Ok(d)
}

/// Compare two films as their PNG output would show them (8-bit sRGB at `exposure`).
pub fn film_diff(a: &Film, b: &Film, exposure: f64) -> Result<PixelDiff, FrameError> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(FrameError::Compare {
            a: a.pixels.len() * 3,
            b: b.pixels.len() * 3,
        });
    }
    pixel_diff(&film_to_srgb8(a, exposure), &film_to_srgb8(b, exposure))
}

/// One path at one tolerance of the sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct PathPoint {
    /// Median render time (ms).
    pub frame_ms: f64,
    /// Renders timed.
    pub runs: usize,
    /// The image against the path's reference.
    pub diff: PixelDiff,
    /// Rays traced for one render (the fan's rays, or one per pixel on the exact path).
    pub rays: u64,
    /// Of those, rays that ended [`FanEnd::Trapped`] (in a duct for ever; shaded as the
    /// fallback).
    pub trapped_rays: u64,
    /// Of those, rays that ended [`FanEnd::Lost`] (cut short by the step budget or non-finite;
    /// shaded as the fallback).
    pub lost_rays: u64,
}

/// A [`RayTracer`] that passes every call on and counts the calls, the trapped and the lost rays.
struct Counting<'t> {
    inner: &'t dyn RayTracer,
    calls: AtomicU64,
    trapped: AtomicU64,
    lost: AtomicU64,
}

impl<'t> Counting<'t> {
    fn new(inner: &'t dyn RayTracer) -> Self {
        Counting {
            inner,
            calls: AtomicU64::new(0),
            trapped: AtomicU64::new(0),
            lost: AtomicU64::new(0),
        }
    }
}

impl RayTracer for Counting<'_> {
    fn density_paths_m(&self, h: f64, elevation_rad: f64, scales: [f64; 2]) -> Option<[f64; 2]> {
        self.inner.density_paths_m(h, elevation_rad, scales)
    }

    fn density_paths_along(
        &self,
        h: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        scales: [f64; 2],
    ) -> Option<RayDensityPaths> {
        self.inner
            .density_paths_along(h, elevation_rad, distances_m, scales)
    }

    fn trace(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
    ) -> FanRay {
        let ray = self.inner.trace(
            camera_height_m,
            elevation_rad,
            distances_m,
            need_sky_direction,
        );
        self.count(ray)
    }

    fn trace_with_margin(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
        margin_m: f64,
    ) -> FanRay {
        self.count(self.inner.trace_with_margin(
            camera_height_m,
            elevation_rad,
            distances_m,
            need_sky_direction,
            margin_m,
        ))
    }
}

impl Counting<'_> {
    /// `ray`, counted as a call (and as trapped or lost).
    fn count(&self, ray: FanRay) -> FanRay {
        self.calls.fetch_add(1, Ordering::Relaxed);
        match ray.end {
            FanEnd::Trapped => self.trapped.fetch_add(1, Ordering::Relaxed),
            FanEnd::Lost => self.lost.fetch_add(1, Ordering::Relaxed),
            _ => 0,
        };
        ray
    }
}

/// Render `scene` on `path` at `tolerance_m` (`runs` times, through [`prepared`]): the point
/// against `reference` (or against itself when `None`) and the film.
fn sweep_point(
    ps: &PaperScene,
    scene: &Scene,
    path: RenderPath,
    tolerance_m: f64,
    runs: usize,
    reference: Option<&Film>,
    exposure: f64,
) -> Result<(PathPoint, Film), FrameError> {
    let tracer = prepared(ps, scene, path, tolerance_m)?;
    let counting = Counting::new(tracer.as_ref());
    let (s, film) = timed_render(&ps.name, scene, &counting, path, tolerance_m, runs)?;
    let diff = film_diff(&film, reference.unwrap_or(&film), exposure)?;
    let per_run = runs.max(1) as u64;
    let point = PathPoint {
        frame_ms: s * 1e3,
        runs,
        diff,
        rays: counting.calls.into_inner() / per_run,
        trapped_rays: counting.trapped.into_inner() / per_run,
        lost_rays: counting.lost.into_inner() / per_run,
    };
    Ok((point, film))
}

/// One tolerance of the sweep of one scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRow {
    /// Tracer tolerance (m).
    pub tolerance_m: f64,
    /// The fan path against the fan reference.
    pub fan: PathPoint,
    /// The exact path against the exact reference.
    pub exact: PathPoint,
}

/// The image-error sweep of one curved scene.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSweep {
    /// The scene's name.
    pub name: String,
    /// Frame size (width, height).
    pub size: (u32, u32),
    /// The fan path's reference render (its `diff` compares it with itself: nothing changed).
    pub fan_reference: PathPoint,
    /// The exact path's reference render, its `diff` against the fan reference (what the fan's
    /// interpolation changes).
    pub exact_reference: PathPoint,
    /// Straight rays against the fan reference (what refraction changes).
    pub straight: PathPoint,
    /// One row per tolerance, in the config's order.
    pub rows: Vec<SweepRow>,
}

/// Sweep the tolerances on `ps` (`None` for a straight-ray scene: the tolerance does not apply).
/// `progress` is called after the references and after every tolerance.
pub fn sweep_scene(
    ps: &PaperScene,
    config: &FrameConfig,
    progress: &mut dyn FnMut(),
) -> Result<Option<SceneSweep>, FrameError> {
    config.check()?;
    if ps.scene.atmosphere.straight {
        return Ok(None);
    }
    let exp = config.exposure;
    let scene = variant(&ps.scene, config.sweep_size, false);
    let rt = config.reference_tolerance_m;
    let (fan_reference, fan_ref) = sweep_point(ps, &scene, RenderPath::Fan, rt, 1, None, exp)?;
    let (exact_reference, exact_ref) =
        sweep_point(ps, &scene, RenderPath::Exact, rt, 1, Some(&fan_ref), exp)?;
    let flat = variant(&ps.scene, config.sweep_size, true);
    let reps = config.repetitions;
    let tol = RenderOptions::default().tolerance_m;
    let straight = RenderPath::Straight;
    let (straight, _) = sweep_point(ps, &flat, straight, tol, reps, Some(&fan_ref), exp)?;
    progress();
    let mut rows = Vec::new();
    for &t in &config.tolerances_m {
        let (fan, _) = sweep_point(ps, &scene, RenderPath::Fan, t, reps, Some(&fan_ref), exp)?;
        let ereps = config.exact_repetitions;
        let (exact, _) = sweep_point(
            ps,
            &scene,
            RenderPath::Exact,
            t,
            ereps,
            Some(&exact_ref),
            exp,
        )?;
        rows.push(SweepRow {
            tolerance_m: t,
            fan,
            exact,
        });
        progress();
    }
    Ok(Some(SceneSweep {
        name: ps.name.clone(),
        size: config.sweep_size,
        fan_reference,
        exact_reference,
        straight,
        rows,
    }))
}

/// One traced ray of a frame's fan, as the renderer asked for it and got it.
struct Call {
    camera_height_m: f64,
    elevation_rad: f64,
    distances_m: Vec<f64>,
    need_sky_direction: bool,
    ray: FanRay,
}

/// A [`RayTracer`] that passes every call on and records it, with the time spent inside.
struct Recording<'t> {
    inner: &'t dyn RayTracer,
    nanos: AtomicU64,
    calls: Mutex<Vec<Call>>,
}

impl Recording<'_> {
    /// `f`, its time added to the tracer time.
    fn timed<T>(&self, f: impl FnOnce() -> T) -> T {
        let start = Instant::now();
        let out = f();
        let ns = u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.nanos.fetch_add(ns, Ordering::Relaxed);
        out
    }
}

impl RayTracer for Recording<'_> {
    /// Passed on and timed with the traces (the sun's path integrals are tracer time too).
    fn density_paths_m(&self, h: f64, elevation_rad: f64, scales: [f64; 2]) -> Option<[f64; 2]> {
        self.timed(|| self.inner.density_paths_m(h, elevation_rad, scales))
    }

    /// Passed on and timed with the traces (one trace for both, as the inner tracer does it).
    fn trace_to_sky_with_density_paths(
        &self,
        h: f64,
        elevation_rad: f64,
        scales: [f64; 2],
    ) -> (FanRay, Option<[f64; 2]>) {
        self.timed(|| {
            self.inner
                .trace_to_sky_with_density_paths(h, elevation_rad, scales)
        })
    }

    /// Passed on and timed with the traces.
    fn trace_to_sky_deferring_density_paths(
        &self,
        h: f64,
        elevation_rad: f64,
        scales: [f64; 2],
    ) -> (FanRay, DensityPathsSoFar) {
        self.timed(|| {
            self.inner
                .trace_to_sky_deferring_density_paths(h, elevation_rad, scales)
        })
    }

    /// Passed on and timed with the traces.
    fn finish_density_paths(&self, climb: &PendingClimb) -> Option<[f64; 2]> {
        self.timed(|| self.inner.finish_density_paths(climb))
    }

    /// Passed on and timed with the traces.
    fn density_paths_along(
        &self,
        h: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        scales: [f64; 2],
    ) -> Option<RayDensityPaths> {
        self.timed(|| {
            self.inner
                .density_paths_along(h, elevation_rad, distances_m, scales)
        })
    }

    fn trace(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
    ) -> FanRay {
        let start = Instant::now();
        let ray = self.inner.trace(
            camera_height_m,
            elevation_rad,
            distances_m,
            need_sky_direction,
        );
        let ns = u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.nanos.fetch_add(ns, Ordering::Relaxed);
        if let Ok(mut calls) = self.calls.lock() {
            calls.push(Call {
                camera_height_m,
                elevation_rad,
                distances_m: distances_m.to_vec(),
                need_sky_direction,
                ray: ray.clone(),
            });
        }
        ray
    }

    /// Passed on and timed with the traces; not recorded (a re-trace with
    /// [`RayTracer::trace`]'s fate rule would stop it above the cards).
    fn trace_with_margin(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
        margin_m: f64,
    ) -> FanRay {
        self.timed(|| {
            self.inner.trace_with_margin(
                camera_height_m,
                elevation_rad,
                distances_m,
                need_sky_direction,
                margin_m,
            )
        })
    }
}

/// Whether a re-traced `record` is the ray the renderer got: the same heights (bit for bit) and
/// the same end point where the end says one.
fn same_ray(record: &RayRecord, ray: &FanRay) -> bool {
    let heights = ray.heights_m.iter().enumerate().all(|(k, h)| {
        let r = record.heights_m.get(k).copied().flatten();
        r.filter(|v| v.is_finite()).map(f64::to_bits) == h.map(f64::to_bits)
    });
    let end = match ray.end {
        FanEnd::Ground { distance_m, .. } => {
            distance_m.to_bits() == record.end.distance_m.to_bits()
        }
        FanEnd::Sky { elevation_rad } => {
            elevation_rad.to_bits() == record.end_observer_elevation_rad.to_bits()
        }
        _ => true,
    };
    heights && end
}

/// Mean steps per ray of the recorded `calls`, re-traced one by one with
/// [`CurvedRays::trace_record_into`] (the renderer's own path, fate rule included). `None` if any
/// re-traced ray differs from the renderer's or there are no calls.
fn fan_steps_per_ray(rays: &CurvedRays<'_, RefractiveAtmosphere>, calls: &[Call]) -> Option<f64> {
    let mut record = RayRecord::default();
    let mut steps = 0u64;
    for c in calls {
        let (h, a, d) = (c.camera_height_m, c.elevation_rad, &c.distances_m[..]);
        match rays.trace_record_into(h, a, d, c.need_sky_direction, &mut record) {
            Ok(()) if same_ray(&record, &c.ray) => steps += u64::from(record.steps()),
            Err(_) if c.ray.end == FanEnd::Lost => {}
            _ => return None,
        }
    }
    (!calls.is_empty()).then(|| steps as f64 / calls.len() as f64)
}

/// The fan tracer inside one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FanCounts {
    /// Rays traced for the frame's fan.
    pub fan_rays: usize,
    /// Time inside the tracer, summed over threads (s).
    pub tracer_s: f64,
    /// Steps (accepted + rejected) per fan ray; `None` if they could not be reproduced (a
    /// re-traced ray differs from the renderer's, or the recorded render's pixels from the timed
    /// one's).
    pub steps_per_ray: Option<f64>,
}

impl FanCounts {
    /// Rays per second of one thread inside the tracer.
    pub fn rays_per_s(&self) -> f64 {
        self.fan_rays as f64 / self.tracer_s
    }
    /// Steps per second of one thread inside the tracer.
    pub fn steps_per_s(&self) -> Option<f64> {
        self.steps_per_ray.map(|s| s * self.rays_per_s())
    }
}

/// The exact path's time for one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ExactTime {
    /// Time per frame at the timed size (ms), scaled to the full size when it was a proxy.
    pub frame_ms: f64,
    /// Renders timed.
    pub runs: usize,
    /// The size rendered (the full size, or the proxy).
    pub timed_size: (u32, u32),
}

/// The frame times of one scene at one size.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTiming {
    /// The scene's name.
    pub name: String,
    /// Frame size (width, height).
    pub size: (u32, u32),
    /// Straight rays (ms).
    pub straight_ms: f64,
    /// The fan path (ms); `None` for a straight-ray scene.
    pub fan_ms: Option<f64>,
    /// The fan tracer inside the frame; `None` for a straight-ray scene.
    pub fan: Option<FanCounts>,
    /// The exact path; `None` for a straight-ray scene.
    pub exact: Option<ExactTime>,
}

/// The size at which an exact frame of `size` is timed: divided by the smallest integer that
/// brings it within `max_pixels` (at least 1×1).
pub fn exact_proxy_size(size: (u32, u32), max_pixels: u64) -> (u32, u32) {
    let (w, h) = size;
    let mut k = 1u32;
    loop {
        let (pw, ph) = ((w / k).max(1), (h / k).max(1));
        if u64::from(pw) * u64::from(ph) <= max_pixels || (pw == 1 && ph == 1) {
            return (pw, ph);
        }
        k += 1;
    }
}

/// The fan tracer's rays, time and steps inside one fan-path frame of `scene` at `tolerance_m`
/// (`None` for a straight-ray scene). No steps if the recorded render's pixels differ from
/// `timed` (then the tracer built here is not the one `prepare_tracer` builds).
fn fan_counts(
    ps: &PaperScene,
    scene: &Scene,
    tolerance_m: f64,
    timed: &Film,
) -> Result<Option<FanCounts>, FrameError> {
    let Some(atm) = ps.refractive() else {
        return Ok(None);
    };
    // As `prepare_tracer` builds it (the pixels are compared below).
    let cfg = TracerConfig {
        tolerance_m,
        ..render_tracer_config(scene.earth_radius_m)
    };
    let rays =
        CurvedRays::new(atm, cfg, cards_top_m(scene)).map_err(|source| FrameError::Prepare {
            name: ps.name.clone(),
            source: PrepareError::Tracer(source),
        })?;
    let recording = Recording {
        inner: &rays,
        nanos: AtomicU64::new(0),
        calls: Mutex::new(Vec::new()),
    };
    let (_, film) = timed_render(&ps.name, scene, &recording, RenderPath::Fan, tolerance_m, 1)?;
    let same_pixels = film.pixels == timed.pixels;
    let calls = recording.calls.into_inner().unwrap_or_default();
    Ok(Some(FanCounts {
        fan_rays: calls.len(),
        tracer_s: recording.nanos.into_inner() as f64 * 1e-9,
        steps_per_ray: fan_steps_per_ray(&rays, &calls).filter(|_| same_pixels),
    }))
}

/// Time the frames of `ps` at `size` at the render default tolerance on every path.
pub fn time_scene(
    ps: &PaperScene,
    size: (u32, u32),
    config: &FrameConfig,
) -> Result<FrameTiming, FrameError> {
    config.check()?;
    let tol = RenderOptions::default().tolerance_m;
    let flat = variant(&ps.scene, size, true);
    let tracer = prepared(ps, &flat, RenderPath::Straight, tol)?;
    let (straight_s, _) = timed_render(
        &ps.name,
        &flat,
        tracer.as_ref(),
        RenderPath::Straight,
        tol,
        config.repetitions,
    )?;
    let mut timing = FrameTiming {
        name: ps.name.clone(),
        size,
        straight_ms: straight_s * 1e3,
        fan_ms: None,
        fan: None,
        exact: None,
    };
    if ps.scene.atmosphere.straight {
        return Ok(timing);
    }
    let scene = variant(&ps.scene, size, false);
    let tracer = prepared(ps, &scene, RenderPath::Fan, tol)?;
    let reps = config.repetitions;
    let (fan_s, film) = timed_render(
        &ps.name,
        &scene,
        tracer.as_ref(),
        RenderPath::Fan,
        tol,
        reps,
    )?;
    timing.fan_ms = Some(fan_s * 1e3);
    timing.fan = fan_counts(ps, &scene, tol, &film)?;
    let proxy = exact_proxy_size(size, config.exact_max_pixels);
    let small = variant(&ps.scene, proxy, false);
    let tracer = prepared(ps, &small, RenderPath::Exact, tol)?;
    let runs = config.exact_repetitions;
    let (exact_s, _) = timed_render(
        &ps.name,
        &small,
        tracer.as_ref(),
        RenderPath::Exact,
        tol,
        runs,
    )?;
    let scale = (f64::from(size.0) * f64::from(size.1)) / (f64::from(proxy.0) * f64::from(proxy.1));
    timing.exact = Some(ExactTime {
        frame_ms: exact_s * 1e3 * scale,
        runs,
        timed_size: proxy,
    });
    Ok(timing)
}

/// The cost of one spectral scene at one size: its RGB frame against its spectral frame.
#[derive(Debug, Clone, PartialEq)]
pub struct SpectralTiming {
    /// The scene's name.
    pub name: String,
    /// Frame size (width, height).
    pub size: (u32, u32),
    /// Its wavelength bands.
    pub bands: u32,
    /// The RGB fan path: `render_scene` alone (ms).
    pub rgb_ms: f64,
    /// The spectral frame: `render_spectral`, which prepares each band's atmosphere and
    /// tracer, renders every band and integrates them (ms).
    pub spectral_ms: f64,
}

/// Time the RGB and the spectral frame of `ps` (a scene with `[render] spectral_bands`) at
/// `size`, the render default tolerance, the median of `config.repetitions` renders each.
pub fn time_spectral(
    ps: &PaperScene,
    size: (u32, u32),
    config: &FrameConfig,
) -> Result<SpectralTiming, FrameError> {
    config.check()?;
    let Some(bands) = ps.scene.spectral_bands else {
        return Err(FrameError::InvalidConfig(format!(
            "{} has no [render] spectral_bands",
            ps.name
        )));
    };
    let tol = RenderOptions::default().tolerance_m;
    let scene = variant(&ps.scene, size, false);
    let tracer = prepared(ps, &scene, RenderPath::Fan, tol)?;
    let reps = config.repetitions;
    let (rgb_s, _) = timed_render(
        &ps.name,
        &scene,
        tracer.as_ref(),
        RenderPath::Fan,
        tol,
        reps,
    )?;
    let opts = options(RenderPath::Fan, tol);
    let mut times = Vec::with_capacity(reps);
    for _ in 0..reps.max(1) {
        let start = Instant::now();
        render_spectral(&scene, ps.refractive(), &opts, bands).map_err(|e| match e {
            SpectralError::Prepare(source) => FrameError::Prepare {
                name: ps.name.clone(),
                source,
            },
            SpectralError::Render(source) => FrameError::Render {
                name: ps.name.clone(),
                source,
            },
        })?;
        times.push(start.elapsed().as_secs_f64());
    }
    Ok(SpectralTiming {
        name: ps.name.clone(),
        size,
        bands,
        rgb_ms: rgb_s * 1e3,
        spectral_ms: median(&mut times).unwrap_or(f64::NAN) * 1e3,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_diff_counts_pixels_not_channels() {
        let a = [10u8, 20, 30, 0, 0, 0, 255, 255, 255, 1, 2, 3];
        // Pixel 0: two channels differ (by 1 and 7); pixel 2: one channel by 200; others same.
        let b = [11u8, 20, 23, 0, 0, 0, 255, 55, 255, 1, 2, 3];
        let d = pixel_diff(&a, &b).unwrap();
        assert_eq!(
            d,
            PixelDiff {
                pixels: 4,
                changed: 2,
                max_channel: 200
            }
        );
        assert_eq!(d.changed_fraction(), 0.5);
        assert_eq!(pixel_diff(&a, &a).unwrap().changed, 0);
    }

    #[test]
    fn pixel_diff_refuses_different_sizes() {
        assert!(matches!(
            pixel_diff(&[0; 6], &[0; 9]),
            Err(FrameError::Compare { a: 6, b: 9 })
        ));
        assert!(pixel_diff(&[0; 4], &[0; 4]).is_err());
        assert_eq!(PixelDiff::default().changed_fraction(), 0.0);
    }

    #[test]
    fn combined_diffs_add_pixels_and_keep_the_largest_difference() {
        let a = PixelDiff {
            pixels: 100,
            changed: 3,
            max_channel: 9,
        };
        let b = PixelDiff {
            pixels: 300,
            changed: 1,
            max_channel: 40,
        };
        let c = a.combined(b);
        assert_eq!((c.pixels, c.changed, c.max_channel), (400, 4, 40));
        assert_eq!(c.changed_fraction(), 0.01);
    }

    #[test]
    fn exact_proxy_keeps_small_frames_and_shrinks_large_ones() {
        assert_eq!(exact_proxy_size((400, 200), 80_000), (400, 200));
        // 1920×1080 / 5 = 384×216 = 82 944 px > 80 000, / 6 = 320×180.
        assert_eq!(exact_proxy_size((1920, 1080), 80_000), (320, 180));
        assert_eq!(exact_proxy_size((192, 108), 3_200), (64, 36));
        assert_eq!(exact_proxy_size((5, 3), 1), (1, 1));
    }

    #[test]
    fn configs_are_valid_and_bad_ones_refused() {
        FrameConfig::full().check().unwrap();
        FrameConfig::quick().check().unwrap();
        let mut c = FrameConfig::quick();
        c.tolerances_m = vec![1e-7];
        assert!(c.check().is_err(), "below the render's tolerance range");
        let mut c = FrameConfig::quick();
        c.timing_sizes = vec![(0, 10)];
        assert!(c.check().is_err());
    }
}
