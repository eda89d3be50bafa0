//! Jobs — sequence. In: a [`SequenceRequest`] (a loaded scene, one [`Sweep`] — the sun's true
//! elevation or the observer's height, FROM:TO:STEP — and the render settings of `render`) and
//! the scene's atmosphere from the [`AtmosphereCache`]. Out: the products `frame_0000.png`, …
//! (each the PNG a single `render` of that frame's scene writes), `sequence.gif` (every frame,
//! looping) and `frames.csv` (the swept value per frame; for a sun sweep the sun's apparent band
//! and number of strips from the traced map, see [`crate::render::sweep`]).
//!
//! A sun sweep traces its rays once for all frames ([`render_sun_sweep`]); an observer sweep
//! changes the view, so each frame prepares its own tracer (the atmosphere is fitted and
//! tabulated once, by the cache). Frames are rendered in parallel; the bytes do not depend on
//! the thread count.

use rayon::prelude::*;

use super::cache::AtmosphereRequest;
use super::render::{RenderSettings, provenance, render_film};
use super::trace::{RangeSyntax, parse_from_to_step};
use super::{AtmosphereCache, JobError, Product, RenderRequest};
use crate::output::film::{ImageFormat, encode_film};
use crate::render::sweep::{SunFrame, render_sun_sweep};
use crate::render::{Film, prepare_tracer};
use crate::scene::Scene;

/// Most frames a sequence may have (frame numbers have four digits).
pub const MAX_FRAMES: usize = 10_000;

/// Display time of one frame of `sequence.gif` (ms).
pub const GIF_FRAME_MS: u32 = 80;

/// Swept values are rounded to 1/this of their unit (degrees or metres).
const SWEEP_STEPS_PER_UNIT: f64 = 1e9;

/// What a sequence sweeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SweepKind {
    /// The sun's true (geometric) elevation, degrees.
    SunElevationDeg,
    /// The camera's height above the surface, metres.
    ObserverHeightM,
}

impl SweepKind {
    /// The `frames.csv` column of the swept value (unit in the name).
    pub fn column(self) -> &'static str {
        match self {
            SweepKind::SunElevationDeg => "sun_true_elevation_deg",
            SweepKind::ObserverHeightM => "observer_height_m",
        }
    }
}

/// An evenly spaced sweep: `count` values FROM + i·STEP.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Sweep {
    /// What is swept.
    pub kind: SweepKind,
    /// First value (degrees or metres, as [`SweepKind`] says).
    pub from: f64,
    /// Step between frames (> 0).
    pub step: f64,
    /// Number of frames (1 to [`MAX_FRAMES`]).
    pub count: usize,
}

impl Sweep {
    /// The swept value of every frame, in order: FROM + i·STEP rounded to 1e-9 units
    /// (so that −3 + 7 × 0.04 is −2.72, the number a scene file would give, not
    /// −2.7199999999999998).
    pub fn values(&self) -> Vec<f64> {
        (0..self.count)
            .map(|i| {
                let v = self.from + i as f64 * self.step;
                // An integer divided by 1e9 rounds once: the nearest f64 to the decimal.
                (v * SWEEP_STEPS_PER_UNIT).round() / SWEEP_STEPS_PER_UNIT
            })
            .collect()
    }
}

/// Parse a sweep `FROM:TO:STEP` of `kind` (the trace fan's syntax): sun elevations within
/// −90°…90°, observer heights ≥ 0 m, 1 to [`MAX_FRAMES`] frames.
pub fn parse_sweep(kind: SweepKind, text: &str) -> Result<Sweep, String> {
    let (label, unit, example) = match kind {
        SweepKind::SunElevationDeg => ("sun elevation sweep", "in degrees", "-3:1:0.04"),
        SweepKind::ObserverHeightM => ("observer height sweep", "in metres", "5:120:5"),
    };
    let syntax = RangeSyntax {
        label,
        unit,
        example,
        noun: "frames",
        max_count: MAX_FRAMES,
    };
    let (from, step, count) = parse_from_to_step(text, &syntax, |from, to| match kind {
        SweepKind::SunElevationDeg if from < -90.0 || to > 90.0 => {
            Err("sun elevations must lie within -90° and 90°".into())
        }
        SweepKind::ObserverHeightM if from < 0.0 => {
            Err("observer heights must be ≥ 0 m above the surface".into())
        }
        _ => Ok(()),
    })?;
    Ok(Sweep {
        kind,
        from,
        step,
        count,
    })
}

/// How a sequence renders, beyond what its scene says (the `render` command's defaults).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SequenceSettings {
    /// What to sweep.
    pub sweep: Sweep,
    /// Frame size (width, height) in pixels; `None` is the scene's own size.
    pub size: Option<(u32, u32)>,
    /// Samples per pixel (a square number); `None`: the scene's.
    pub spp: Option<u32>,
    /// The ray tracer's tolerance (m).
    pub tolerance_m: f64,
    /// PNG exposure (linear radiance multiplier).
    pub exposure: f64,
    /// Straight rays (n ≡ 1).
    pub straight: bool,
}

impl SequenceSettings {
    /// The `render` defaults around `sweep`.
    pub fn new(sweep: Sweep) -> Self {
        let render = RenderSettings::default();
        SequenceSettings {
            sweep,
            size: None,
            spp: None,
            tolerance_m: render.tolerance_m,
            exposure: render.exposure,
            straight: false,
        }
    }
}

/// A validated sequence request.
#[derive(Debug, Clone)]
pub struct SequenceRequest {
    /// The frames' common render request (scene, size, options; PNG only).
    pub render: RenderRequest,
    /// What is swept.
    pub sweep: Sweep,
}

impl SequenceRequest {
    /// Check `settings` against `scene`: the render settings as `render` checks them, and a
    /// sun sweep needs a `[sun]` and an RGB (not spectral) scene.
    pub fn new(scene: Scene, settings: SequenceSettings) -> Result<Self, JobError> {
        let sweep = settings.sweep;
        let valid = (1..=MAX_FRAMES).contains(&sweep.count)
            && sweep.step.is_finite()
            && sweep.step > 0.0
            && sweep.from.is_finite();
        if !valid {
            return Err(JobError::Invalid(format!(
                "a sweep needs 1 to {MAX_FRAMES} frames, a finite start and a step > 0"
            )));
        }
        let last = sweep.from + (sweep.count - 1) as f64 * sweep.step;
        match sweep.kind {
            SweepKind::SunElevationDeg => {
                if scene.sun.is_none() {
                    return Err(JobError::Invalid(
                        "the scene has no [sun]: a sun elevation sweep needs one to move".into(),
                    ));
                }
                if scene.spectral_bands.is_some() {
                    return Err(JobError::Invalid(
                        "sun sweeps of spectral scenes ([render] spectral_bands) are not \
                         supported yet"
                            .into(),
                    ));
                }
                if sweep.from < -90.0 || last > 90.0 {
                    return Err(JobError::Invalid(
                        "sun elevations must lie within -90° and 90°".into(),
                    ));
                }
            }
            SweepKind::ObserverHeightM if sweep.from < 0.0 => {
                return Err(JobError::Invalid(
                    "observer heights must be ≥ 0 m above the surface".into(),
                ));
            }
            SweepKind::ObserverHeightM => {}
        }
        let render = RenderRequest::new(
            scene,
            RenderSettings {
                sizes: vec![settings.size],
                formats: vec![ImageFormat::Png],
                spp: settings.spp,
                tolerance_m: settings.tolerance_m,
                exposure: settings.exposure,
                straight: settings.straight,
                ..RenderSettings::default()
            },
        )?;
        Ok(SequenceRequest { render, sweep })
    }

    /// The atmosphere the frames are rendered through (`None` for straight rays).
    pub fn atmosphere(&self) -> Option<&AtmosphereRequest> {
        self.render.atmosphere.as_ref()
    }

    /// The scene of every frame, at the request's size (sun or camera moved to each value).
    pub fn frame_scenes(&self) -> Vec<Scene> {
        let base = self.render.scene_at(self.render.settings.sizes[0]);
        self.sweep
            .values()
            .into_iter()
            .map(|v| {
                let mut scene = base.clone();
                match self.sweep.kind {
                    SweepKind::SunElevationDeg => {
                        if let Some(sun) = &mut scene.sun {
                            sun.elevation_rad = v.to_radians();
                        }
                    }
                    SweepKind::ObserverHeightM => scene.camera.height_m = v,
                }
                scene
            })
            .collect()
    }

    /// Render every frame: the films and, for a sun sweep, the sun's facts per frame.
    pub fn render_frames(&self, cache: &AtmosphereCache) -> Result<Frames, JobError> {
        let atmosphere = self.atmosphere().map(|a| cache.get(a)).transpose()?;
        let refractive = atmosphere.as_deref().map(|a| &a.refractive);
        let scene = self.render.scene_at(self.render.settings.sizes[0]);
        let options = self.render.options(true);
        let name = scene_name(&scene);
        match self.sweep.kind {
            SweepKind::SunElevationDeg => {
                let tracer = prepare_tracer(&scene, refractive, &options).map_err(|source| {
                    JobError::Prepare {
                        scene: name.clone(),
                        source,
                    }
                })?;
                let elevations: Vec<f64> =
                    self.sweep.values().iter().map(|d| d.to_radians()).collect();
                let frames = render_sun_sweep(&scene, tracer.as_ref(), &options, &elevations)
                    .map_err(|source| JobError::Render {
                        scene: name.clone(),
                        source,
                    })?;
                for (i, f) in frames.iter().enumerate() {
                    warn_non_finite(&name, i, &f.film);
                }
                Ok(Frames::Sun(frames))
            }
            SweepKind::ObserverHeightM => {
                let films = self
                    .frame_scenes()
                    .par_iter()
                    .map(|s| render_film(s, atmosphere.as_deref(), &options))
                    .collect::<Result<Vec<Film>, JobError>>()?;
                Ok(Frames::Plain(films))
            }
        }
    }

    /// Every product: the numbered frames, `sequence.gif` and `frames.csv`.
    pub fn products(&self, cache: &AtmosphereCache) -> Result<Vec<Product>, JobError> {
        let frames = self.render_frames(cache)?;
        self.products_of(&frames)
    }

    /// The products of rendered `frames` (see [`Self::products`]).
    pub fn products_of(&self, frames: &Frames) -> Result<Vec<Product>, JobError> {
        let scenes = self.frame_scenes();
        let options = self.render.options(true);
        let exposure = self.render.settings.exposure;
        let films = frames.films();
        let mut products = films
            .par_iter()
            .zip(&scenes)
            .enumerate()
            .map(|(i, (film, scene))| {
                let meta = provenance(scene, &options);
                let bytes = encode_film(film, ImageFormat::Png, &meta, exposure)?;
                Ok(Product::new(frame_name(i), bytes))
            })
            .collect::<Result<Vec<Product>, JobError>>()?;
        products.push(Product::new("sequence.gif", encode_gif(&films, exposure)?));
        products.push(Product::new(
            "frames.csv",
            frames_csv(&self.sweep, frames).into_bytes(),
        ));
        if let Frames::Sun(sun_frames) = frames {
            let scene = &self.render.scene;
            let title = format!("The sun through {}", scene_name(scene));
            let png = crate::render::sweep_plot::sun_sweep_png(
                sun_frames,
                scene.camera.height_m,
                scene.earth_radius_m,
                &title,
            )
            .map_err(JobError::Plot)?;
            products.push(Product::new("sun.png", png));
        }
        Ok(products)
    }
}

/// A sequence's rendered frames.
#[derive(Debug, Clone)]
pub enum Frames {
    /// A sun sweep's frames, with the sun's facts.
    Sun(Vec<SunFrame>),
    /// Frames without facts (observer sweeps).
    Plain(Vec<Film>),
}

impl Frames {
    /// The films, in order.
    pub fn films(&self) -> Vec<&Film> {
        match self {
            Frames::Sun(frames) => frames.iter().map(|f| &f.film).collect(),
            Frames::Plain(films) => films.iter().collect(),
        }
    }
}

/// `frame_0000.png`, … by frame index.
pub fn frame_name(index: usize) -> String {
    format!("frame_{index:04}.png")
}

/// The scene's file name for messages.
fn scene_name(scene: &Scene) -> String {
    scene
        .source_path
        .as_deref()
        .map_or_else(|| "scene".into(), |p| p.display().to_string())
}

/// Never silent about non-finite samples (as `render` reports them).
fn warn_non_finite(name: &str, index: usize, film: &Film) {
    if film.stats.non_finite_samples > 0 {
        eprintln!(
            "warning: {name}: frame {index}: {} sample(s) had non-finite radiance and were \
             shaded as horizon sky",
            film.stats.non_finite_samples
        );
    }
}

/// `frames.csv`: one row per frame with the swept value; a sun sweep adds the sun's apparent
/// band (degrees, empty when no row shows the sun) and its number of strips.
pub fn frames_csv(sweep: &Sweep, frames: &Frames) -> String {
    let values = sweep.values();
    let mut text = format!("frame,{}", sweep.kind.column());
    if let Frames::Sun(_) = frames {
        text.push_str(",sun_apparent_low_deg,sun_apparent_high_deg,sun_strips");
    }
    text.push('\n');
    let degrees = |v: Option<f64>| v.map_or_else(String::new, |r| format!("{:.6}", r.to_degrees()));
    for (i, value) in values.iter().enumerate() {
        text.push_str(&format!("{i},{value}"));
        if let Frames::Sun(frames) = frames {
            let facts = frames[i].facts;
            text.push_str(&format!(
                ",{},{},{}",
                degrees(facts.apparent_low_rad),
                degrees(facts.apparent_high_rad),
                facts.strips
            ));
        }
        text.push('\n');
    }
    text
}

/// An animated GIF of `films` (8-bit sRGB at `exposure`, each frame quantised to 256 colours,
/// [`GIF_FRAME_MS`] per frame, looping).
pub fn encode_gif(films: &[&Film], exposure: f64) -> Result<Vec<u8>, JobError> {
    use image::codecs::gif::{GifEncoder, Repeat};
    use image::{Delay, Frame, RgbaImage};
    let gif_error = JobError::Gif;
    let frames: Vec<Frame> = films
        .par_iter()
        .map(|film| {
            let rgb = crate::output::png::film_to_srgb8(film, exposure);
            let rgba: Vec<u8> = rgb
                .chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect();
            let image = RgbaImage::from_raw(film.width, film.height, rgba)
                .unwrap_or_else(|| RgbaImage::new(film.width, film.height));
            Frame::from_parts(image, 0, 0, Delay::from_numer_denom_ms(GIF_FRAME_MS, 1))
        })
        .collect();
    let mut bytes = Vec::new();
    {
        let mut encoder = GifEncoder::new_with_speed(&mut bytes, 10);
        encoder.set_repeat(Repeat::Infinite).map_err(gif_error)?;
        encoder.encode_frames(frames).map_err(gif_error)?;
    }
    Ok(bytes)
}
