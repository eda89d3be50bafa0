//! Jobs — sequence. In: a [`SequenceRequest`] (a loaded scene, one [`SweepSpec`] — the sun's true
//! elevation, the observer's height or any numeric scene key as FROM:TO:STEP; the sun's true
//! position over a UTC time span; the air between the scene's sounding and a later one — and the
//! render settings of `render`) and the atmospheres from the [`AtmosphereCache`]. Out: the
//! products `frame_0000.png`, … (each the PNG a single `render` of that frame's scene writes),
//! optionally `frame_0000.exr`, …, `sequence.gif` (every frame, looping), optionally
//! `sequence.mp4` (when `ffmpeg` is on the PATH), `frames.csv` (the swept values and the facts
//! of each frame from the traced map, see [`crate::render::sweep`]), `sun.png` for sweeps that
//! move the sun and `transfer.png` for sweeps of the observer's height.
//!
//! **Cost follows what changes.** Frames whose tracer would be the same (same atmosphere,
//! camera height, Earth and highest card) are rendered through one shared ray cache
//! ([`render_shared`]): a sun sweep, over elevations or over time, traces its rays once. Frames
//! that change the view (observer height) or the air (between soundings) each prepare their
//! own tracer; the atmospheres are fitted and tabulated once by the cache (a frame between
//! soundings blends the two fitted columns and builds its own n(h) table). Frames are rendered
//! in parallel; the bytes do not depend on the thread count.

mod output;
pub mod sweep;

use std::collections::BTreeMap;
use std::sync::Arc;

use rayon::prelude::*;

pub use output::{GIF_FRAME_MS, encode_gif, ffmpeg_args, find_on_path};
pub use sweep::{
    FramePlan, Range, SoundingPair, SweepKind, SweepSpec, TimeSpan, parse_key_sweep, parse_sweep,
};

use super::cache::AtmosphereRequest;
use super::render::{RenderSettings, provenance};
use super::{AtmosphereCache, JobError, Product, RenderRequest};
use crate::atmosphere::{LoadedAtmosphere, atmosphere_from_column};
use crate::output::film::{ImageFormat, encode_film};
use crate::profile::TimeBlend;
use crate::render::curved::cards_top_m;
use crate::render::sweep::{SweepFrame, render_shared};
use crate::render::{RenderStats, prepare_tracer};
use crate::scene::Scene;

/// Most frames a sequence may have (frame numbers have four digits).
pub const MAX_FRAMES: usize = 10_000;

/// How a sequence renders and what it writes, beyond what its scene says (the `render`
/// command's defaults).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SequenceSettings {
    /// What to sweep.
    pub sweep: SweepSpec,
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
    /// Also write every frame as EXR (linear radiance with provenance).
    pub exr: bool,
    /// Also write `sequence.mp4` when `ffmpeg` is on the PATH (a note otherwise).
    pub mp4: bool,
}

impl SequenceSettings {
    /// The `render` defaults around `sweep`, PNG frames only.
    pub fn new(sweep: SweepSpec) -> Self {
        let render = RenderSettings::default();
        SequenceSettings {
            sweep,
            size: None,
            spp: None,
            tolerance_m: render.tolerance_m,
            exposure: render.exposure,
            straight: false,
            exr: false,
            mp4: false,
        }
    }
}

/// A validated sequence request: every frame's scene is planned (and checked) when it is built.
#[derive(Debug, Clone)]
pub struct SequenceRequest {
    /// The frames' common render request (scene, size, options).
    pub render: RenderRequest,
    /// What is swept.
    pub sweep: SweepSpec,
    /// Write EXR frames too.
    pub exr: bool,
    /// Write `sequence.mp4` when ffmpeg is on the PATH.
    pub mp4: bool,
    /// Every frame.
    frames: Vec<FramePlan>,
    /// For a sweep between soundings: the second sounding and the times.
    pair: Option<SoundingPair>,
}

impl SequenceRequest {
    /// Check `settings` against `scene` (the render settings as `render` checks them; what the
    /// sweep needs of the scene) and plan every frame.
    pub fn new(scene: Scene, settings: SequenceSettings) -> Result<Self, JobError> {
        if scene.spectral_bands.is_some() {
            return Err(JobError::Invalid(
                "sequences of spectral scenes ([render] spectral_bands) are not supported yet"
                    .into(),
            ));
        }
        let formats = if settings.exr {
            vec![ImageFormat::Png, ImageFormat::Exr]
        } else {
            vec![ImageFormat::Png]
        };
        let render = RenderRequest::new(
            scene,
            RenderSettings {
                sizes: vec![settings.size],
                formats,
                spp: settings.spp,
                tolerance_m: settings.tolerance_m,
                exposure: settings.exposure,
                straight: settings.straight,
                ..RenderSettings::default()
            },
        )?;
        let base = render.scene_at(settings.size);
        let reparse = |text: &str| -> Result<Scene, JobError> {
            let path = base.source_path.clone().unwrap_or_default();
            let folder = path.parent().unwrap_or(std::path::Path::new("."));
            let mut scene = Scene::from_toml_str(text, folder, &path)?;
            share_assets(&mut scene, &base);
            scene.source_path = base.source_path.clone();
            scene.atmosphere.straight |= settings.straight;
            if let Some((w, h)) = settings.size {
                (scene.camera.width, scene.camera.height) = (w, h);
            }
            Ok(scene)
        };
        let (frames, pair) = sweep::plan_frames(&settings.sweep, &base, &reparse)?;
        if let Some(bad) = frames.iter().find(|f| f.scene.camera.height_m < 0.0) {
            return Err(JobError::Invalid(format!(
                "observer heights must be ≥ 0 m above the surface, got {}",
                bad.scene.camera.height_m
            )));
        }
        Ok(SequenceRequest {
            render,
            sweep: settings.sweep,
            exr: settings.exr,
            mp4: settings.mp4,
            frames,
            pair,
        })
    }

    /// The atmosphere of the scene (`None` for straight rays); a sweep of the atmosphere's own
    /// keys, or between soundings, loads others too.
    pub fn atmosphere(&self) -> Option<&AtmosphereRequest> {
        self.render.atmosphere.as_ref()
    }

    /// The second sounding of a sweep between soundings, as the cache loads it.
    pub fn second_atmosphere(&self) -> Option<AtmosphereRequest> {
        let pair = self.pair.as_ref()?;
        let first = self.atmosphere()?;
        Some(AtmosphereRequest {
            source: pair.second.clone(),
            options: crate::atmosphere::AtmosphereOptions {
                sounding_time: pair.second_time.clone(),
                ..first.options.clone()
            },
        })
    }

    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.frames.len()
    }

    /// The planned frames, in order.
    pub fn frames(&self) -> &[FramePlan] {
        &self.frames
    }

    /// The scene of every frame (the sun, camera or key moved to each value).
    pub fn frame_scenes(&self) -> Vec<Scene> {
        self.frames.iter().map(|f| f.scene.clone()).collect()
    }

    /// Frames that can share one tracer, by first frame: same atmosphere (and blend weight),
    /// camera height, Earth radius and highest card or terrain.
    fn groups(&self) -> Vec<Vec<usize>> {
        let mut groups: BTreeMap<String, Vec<usize>> = BTreeMap::new();
        for (i, f) in self.frames.iter().enumerate() {
            let s = &f.scene;
            let air = s
                .atmosphere
                .resolve()
                .map(|(source, options)| serde_json::to_string(&(source, options)).ok());
            let key = format!(
                "{air:?}|{:?}|{}|{}|{}",
                f.weight.map(f64::to_bits),
                s.camera.height_m.to_bits(),
                s.earth_radius_m.to_bits(),
                cards_top_m(s).to_bits()
            );
            groups.entry(key).or_default().push(i);
        }
        let mut groups: Vec<Vec<usize>> = groups.into_values().collect();
        groups.sort_by_key(|g| g[0]);
        groups
    }

    /// The air of frame `f`: its scene's atmosphere, or the blend between the two soundings.
    fn frame_air(
        &self,
        f: &FramePlan,
        cache: &AtmosphereCache,
    ) -> Result<Option<Arc<LoadedAtmosphere>>, JobError> {
        let own = |s: &Scene| {
            s.atmosphere
                .resolve()
                .map(|(source, options)| cache.get(&AtmosphereRequest { source, options }))
                .transpose()
        };
        let (Some(w), Some(second)) = (f.weight, self.second_atmosphere()) else {
            return own(&f.scene);
        };
        let first = own(&f.scene)?.ok_or_else(|| JobError::Invalid("no atmosphere".into()))?;
        let second = cache.get(&second)?;
        let (a, b) = (
            first.refractive.surface_height_m(),
            second.refractive.surface_height_m(),
        );
        if (a - b).abs() > 1.0 {
            return Err(JobError::Invalid(format!(
                "the two soundings start at different surfaces ({a} m and {b} m above sea \
                 level): not one station"
            )));
        }
        if w == 0.0 || w == 1.0 {
            return Ok(Some(if w == 0.0 { first } else { second }));
        }
        let column = Arc::new(TimeBlend::new(
            first.column.clone(),
            second.column.clone(),
            w,
        ));
        let description = format!("{} → {} at {:.4}", first.description, second.description, w);
        let wavelength_nm = self.render.scene.atmosphere.wavelength_nm;
        let air = atmosphere_from_column(&first.source, column, description, wavelength_nm)
            .map_err(|e| JobError::Atmosphere(Arc::new(e)))?;
        Ok(Some(Arc::new(air)))
    }

    /// Render the frames of one group through one tracer.
    fn render_group(
        &self,
        indices: &[usize],
        cache: &AtmosphereCache,
    ) -> Result<Vec<SweepFrame>, JobError> {
        let first = &self.frames[indices[0]];
        let name = scene_name(&first.scene);
        let air = self.frame_air(first, cache)?;
        let options = self.render.options(true);
        let tracer = prepare_tracer(
            &first.scene,
            air.as_deref().map(|a| &a.refractive),
            &options,
        )
        .map_err(|source| JobError::Prepare {
            scene: name.clone(),
            source,
        })?;
        let scenes: Vec<Scene> = indices
            .iter()
            .map(|&i| self.frames[i].scene.clone())
            .collect();
        let transfer = self.sweep.moves_observer();
        render_shared(&scenes, tracer.as_ref(), &options, transfer).map_err(|source| {
            JobError::Render {
                scene: name,
                source,
            }
        })
    }

    /// Render every frame, with its facts.
    pub fn render_frames(&self, cache: &AtmosphereCache) -> Result<Vec<SweepFrame>, JobError> {
        let groups = self.groups();
        let rendered = groups
            .par_iter()
            .map(|g| self.render_group(g, cache))
            .collect::<Result<Vec<_>, JobError>>()?;
        let mut frames: Vec<Option<SweepFrame>> = vec![None; self.frames.len()];
        for (group, films) in groups.iter().zip(rendered) {
            for (&i, f) in group.iter().zip(films) {
                frames[i] = Some(f);
            }
        }
        let frames: Vec<SweepFrame> = frames.into_iter().flatten().collect();
        let name = scene_name(&self.render.scene);
        for (i, f) in frames.iter().enumerate() {
            warn_non_finite(&name, i, f.image.stats());
        }
        Ok(frames)
    }

    /// Every product: frames, `sequence.gif`, `frames.csv`, plots (module docs).
    pub fn products(&self, cache: &AtmosphereCache) -> Result<Vec<Product>, JobError> {
        let frames = self.render_frames(cache)?;
        self.products_of(&frames)
    }

    /// The products of rendered `frames` (see [`Self::products`]).
    pub fn products_of(&self, frames: &[SweepFrame]) -> Result<Vec<Product>, JobError> {
        let options = self.render.options(true);
        let exposure = self.render.settings.exposure;
        let description = self.sweep.describe();
        let formats = &self.render.settings.formats;
        // Each frame's film is put together once (a frame of a sun sweep holds only the rows
        // it shaded), for its files and its GIF frame.
        let encoded = frames
            .par_iter()
            .zip(&self.frames)
            .enumerate()
            .map(|(i, (frame, plan))| {
                let mut meta = provenance(&plan.scene, &options);
                meta.extra
                    .push(("sequence_sweep".into(), description.clone()));
                meta.extra.push(("sequence_frame".into(), i.to_string()));
                meta.extra
                    .push(("sequence_values".into(), plan.values.join(",")));
                let film = frame.image.film();
                let files = formats
                    .iter()
                    .map(|&format| {
                        let bytes = encode_film(&film, format, &meta, exposure)?;
                        Ok(Product::new(frame_file(i, format), bytes))
                    })
                    .collect::<Result<Vec<Product>, JobError>>()?;
                let gif_frame = crate::output::png::film_to_srgb8(&film, exposure);
                Ok((files, gif_frame))
            })
            .collect::<Result<Vec<_>, JobError>>()?;
        let (files, gif_frames): (Vec<Vec<Product>>, Vec<Vec<u8>>) = encoded.into_iter().unzip();
        // PNGs first, then EXRs, each in frame order.
        let (mut products, exrs): (Vec<Product>, Vec<Product>) = files
            .into_iter()
            .flatten()
            .partition(|p| p.name.ends_with(".png"));
        let mp4 = if self.mp4 {
            output::encode_mp4(&products)?
        } else {
            None
        };
        products.extend(exrs);
        let (width, height) = frames.first().map_or((1, 1), |f| f.image.size());
        products.push(Product::new(
            "sequence.gif",
            encode_gif(&gif_frames, width, height)?,
        ));
        products.extend(mp4.map(|bytes| Product::new("sequence.mp4", bytes)));
        products.push(Product::new(
            "frames.csv",
            self.frames_csv(frames).into_bytes(),
        ));
        products.extend(self.plots(frames)?);
        Ok(products)
    }

    /// `frames.csv` of `frames` ([`output::frames_csv`]).
    pub fn frames_csv(&self, frames: &[SweepFrame]) -> String {
        output::frames_csv(&self.sweep.columns(), &self.frames, frames)
    }

    /// `sun.png` when the sun moves, `transfer.png` (at the farthest card) when the observer
    /// does and the scene has a card.
    fn plots(&self, frames: &[SweepFrame]) -> Result<Vec<Product>, JobError> {
        let scene = &self.render.scene;
        let name = scene_name(scene);
        let mut plots = Vec::new();
        if self.sweep.moves_sun() {
            let png = output::sun_plot(&self.sweep, &self.frames, frames, scene, &name)?;
            plots.push(Product::new("sun.png", png));
        }
        if self.sweep.moves_observer()
            && let Some(card) = crate::render::sweep::farthest_card(scene)
        {
            let png = output::transfer_plot(frames, card, &name)?;
            plots.push(Product::new("transfer.png", png));
        }
        Ok(plots)
    }
}

/// Give `scene` (loaded again from edited text) the decoded card images and elevation model of
/// `base` where it names the same files, so that frames do not hold copies.
fn share_assets(scene: &mut Scene, base: &Scene) {
    for card in &mut scene.cards {
        if let Some(b) = base.cards.iter().find(|b| b.image_path == card.image_path) {
            card.texture = b.texture.clone();
        }
    }
    if let (Some(t), Some(b)) = (&mut scene.terrain, &base.terrain)
        && t.dem_path == b.dem_path
    {
        t.dem = b.dem.clone();
    }
}

/// `frame_0000.png`, … by frame index.
pub fn frame_name(index: usize) -> String {
    frame_file(index, ImageFormat::Png)
}

/// `frame_0000.<ext>` of `format`.
fn frame_file(index: usize, format: ImageFormat) -> String {
    format!("frame_{index:04}.{}", format.extension())
}

/// The scene's file name for messages.
fn scene_name(scene: &Scene) -> String {
    scene
        .source_path
        .as_deref()
        .map_or_else(|| "scene".into(), |p| p.display().to_string())
}

/// Never silent about non-finite samples (as `render` reports them).
fn warn_non_finite(name: &str, index: usize, stats: &RenderStats) {
    if stats.non_finite_samples > 0 {
        eprintln!(
            "warning: {name}: frame {index}: {} sample(s) had non-finite radiance and were \
             shaded as horizon sky",
            stats.non_finite_samples
        );
    }
}
