//! Jobs — render. In: a [`RenderRequest`] (a loaded scene, the sizes and formats to write, render
//! options, and optionally another atmosphere or camera height than the scene's) and the
//! scene's atmosphere from the [`AtmosphereCache`]. Out: a [`Film`] per size and the products
//! `<W>x<H>.png` / `.exr` (or `image.png` / `.exr` at the scene's own size).

use std::sync::Arc;

use super::cache::AtmosphereRequest;
use super::{AtmosphereCache, JobError, Product};
use crate::atmosphere::{AtmosphereSource, LoadedAtmosphere};
use crate::output::exr::ExrMetadata;
use crate::output::film::{ImageFormat, encode_film};
use crate::render::spectral::{SpectralError, render_spectral};
use crate::render::{Film, RenderOptions, check_tracer_tolerance, prepare_tracer, render_scene};
use crate::scene::{Scene, samples_per_pixel_root};

/// How a render job renders, beyond what its scene says. Every field has the `render`
/// command's default.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RenderSettings {
    /// Sizes (width, height) in pixels; `None` is the scene's own size.
    pub sizes: Vec<Option<(u32, u32)>>,
    /// Formats to write.
    pub formats: Vec<ImageFormat>,
    /// Samples per pixel (a square number); `None`: the scene's.
    pub spp: Option<u32>,
    /// The ray tracer's tolerance (m).
    pub tolerance_m: f64,
    /// PNG exposure (linear radiance multiplier; EXR is never scaled).
    pub exposure: f64,
    /// Trace every sample with the 3-D integrator.
    pub exact: bool,
    /// Straight rays (n ≡ 1).
    pub straight: bool,
    /// Another atmosphere than the scene's (a pipeline matrix over atmospheres).
    pub atmosphere: Option<AtmosphereSource>,
    /// With `atmosphere`: which sounding of a multi-sounding IGRA2 file.
    pub sounding_time: Option<String>,
    /// Another camera height (m above the surface) than the scene's.
    pub observer_height_m: Option<f64>,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            sizes: vec![None],
            formats: vec![ImageFormat::Png, ImageFormat::Exr],
            spp: None,
            tolerance_m: RenderOptions::default().tolerance_m,
            exposure: crate::output::png::DEFAULT_EXPOSURE,
            exact: false,
            straight: false,
            atmosphere: None,
            sounding_time: None,
            observer_height_m: None,
        }
    }
}

/// A validated render request.
#[derive(Debug, Clone)]
pub struct RenderRequest {
    /// The scene, with the settings' overrides applied.
    pub scene: Arc<Scene>,
    /// The settings it was built from.
    pub settings: RenderSettings,
    /// The atmosphere to load; `None` for straight rays.
    pub atmosphere: Option<AtmosphereRequest>,
}

impl RenderRequest {
    /// Check `settings` against `scene` and apply its overrides.
    pub fn new(mut scene: Scene, settings: RenderSettings) -> Result<Self, JobError> {
        let invalid = |m: String| Err(JobError::Invalid(m));
        if settings.sizes.is_empty() || settings.formats.is_empty() {
            return invalid("give at least one size and one format".into());
        }
        if let Some(spp) = settings.spp
            && samples_per_pixel_root(spp).is_none()
        {
            return invalid(format!(
                "spp must be a square number (1, 4, 9, 16, …, {}), got {spp}",
                crate::scene::MAX_SAMPLES_PER_PIXEL
            ));
        }
        check_tracer_tolerance(settings.tolerance_m)
            .map_err(|e| JobError::Invalid(e.to_string()))?;
        if !(settings.exposure.is_finite() && settings.exposure > 0.0) {
            return invalid(format!(
                "exposure must be a finite number > 0, got {}",
                settings.exposure
            ));
        }
        apply_overrides(&mut scene, &settings)?;
        let atmosphere = scene
            .atmosphere
            .resolve()
            .map(|(source, options)| AtmosphereRequest { source, options });
        Ok(RenderRequest {
            scene: Arc::new(scene),
            settings,
            atmosphere,
        })
    }

    /// The render options for this request (`quiet`: no per-frame progress bar).
    pub fn options(&self, quiet: bool) -> RenderOptions {
        RenderOptions {
            exact: self.settings.exact,
            samples_per_pixel: self.settings.spp,
            quiet,
            tolerance_m: self.settings.tolerance_m,
            ..RenderOptions::default()
        }
    }

    /// The scene at `size` (its own size for `None`).
    pub fn scene_at(&self, size: Option<(u32, u32)>) -> Scene {
        let mut scene = (*self.scene).clone();
        if let Some((width, height)) = size {
            scene.camera.width = width;
            scene.camera.height = height;
        }
        scene
    }

    /// Render at `size` through `atmosphere` (the loaded [`Self::atmosphere`]).
    pub fn film(
        &self,
        size: Option<(u32, u32)>,
        atmosphere: Option<&LoadedAtmosphere>,
        quiet: bool,
    ) -> Result<(Film, ExrMetadata), JobError> {
        let scene = self.scene_at(size);
        let options = self.options(quiet);
        let film = render_film(&scene, atmosphere, &options)?;
        Ok((film, provenance(&scene, &options)))
    }

    /// Every size in every format, as products named `<W>x<H>.<ext>` (`image.<ext>` at the
    /// scene's own size). PNG and EXR of one size are encoded in parallel.
    pub fn products(&self, cache: &AtmosphereCache) -> Result<Vec<Product>, JobError> {
        let atmosphere = self.atmosphere.as_ref().map(|a| cache.get(a)).transpose()?;
        let mut products = Vec::new();
        for &size in &self.settings.sizes {
            let (film, meta) = self.film(size, atmosphere.as_deref(), true)?;
            let stem = match size {
                Some((w, h)) => format!("{w}x{h}"),
                None => "image".to_string(),
            };
            let encoded: Vec<Result<Product, JobError>> = {
                use rayon::prelude::*;
                self.settings
                    .formats
                    .par_iter()
                    .map(|&format| {
                        let bytes = encode_film(&film, format, &meta, self.settings.exposure)?;
                        Ok(Product::new(
                            format!("{stem}.{}", format.extension()),
                            bytes,
                        ))
                    })
                    .collect()
            };
            for product in encoded {
                products.push(product?);
            }
        }
        Ok(products)
    }
}

/// Most pixels along either side of an image.
pub const MAX_IMAGE_SIDE: u32 = 16_384;

/// Parse an image size `"WIDTHxHEIGHT"` (e.g. `"400x200"`), each side 1 to [`MAX_IMAGE_SIDE`].
pub fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{text:?} is not WIDTHxHEIGHT (e.g. \"400x200\")"))?;
    let parse = |s: &str| {
        s.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=MAX_IMAGE_SIDE).contains(v))
            .ok_or_else(|| {
                format!("{text:?}: {s:?} is not a size from 1 to {MAX_IMAGE_SIDE} pixels")
            })
    };
    Ok((parse(w)?, parse(h)?))
}

/// Point the scene at the settings' atmosphere and camera height, and fold them into its hash.
fn apply_overrides(scene: &mut Scene, settings: &RenderSettings) -> Result<(), JobError> {
    if settings.straight {
        scene.atmosphere.straight = true;
    }
    if let Some(source) = &settings.atmosphere {
        scene.atmosphere.source = source.clone();
        scene.atmosphere.sounding_time = settings.sounding_time.clone();
    }
    if let Some(h) = settings.observer_height_m {
        if !(h.is_finite() && h >= 0.0) {
            return Err(JobError::Invalid(format!(
                "observer_height_m must be a finite height ≥ 0 m, got {h}"
            )));
        }
        scene.camera.height_m = h;
    }
    if settings.straight || settings.atmosphere.is_some() || settings.observer_height_m.is_some() {
        // File names and contents only, so the hash does not depend on where the files are.
        let mut salt = scene.hash_hex.clone().into_bytes();
        let file_name =
            |p: &std::path::Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
        salt.extend(
            format!(
                "{:?}{:?}{}{:?}",
                settings
                    .atmosphere
                    .as_ref()
                    .map(|s| s.path().map(file_name)),
                settings.sounding_time,
                scene.atmosphere.straight,
                scene.camera.height_m
            )
            .bytes(),
        );
        if let Some(path) = settings.atmosphere.as_ref().and_then(|s| s.path()) {
            let bytes = crate::input::read_limited(path, crate::input::MAX_SOUNDING_BYTES)
                .unwrap_or_default();
            salt.extend(super::sha256_hex(&bytes).bytes());
        }
        scene.hash_hex = super::sha256_hex(&salt);
    }
    Ok(())
}

/// Choose the tracer `scene` asks for (through `atmosphere` unless it traces straight rays) and
/// render. A frame with non-finite samples is reported on stderr, even when `quiet`.
pub fn render_film(
    scene: &Scene,
    atmosphere: Option<&LoadedAtmosphere>,
    options: &RenderOptions,
) -> Result<Film, JobError> {
    let name = scene
        .source_path
        .as_deref()
        .map_or_else(|| "scene".into(), |p| p.display().to_string());
    let prepare = |source| JobError::Prepare {
        scene: name.clone(),
        source,
    };
    let render = |source| JobError::Render {
        scene: name.clone(),
        source,
    };
    let refractive = atmosphere.map(|a| &a.refractive);
    let film = match scene.spectral_bands {
        Some(bands) => {
            render_spectral(scene, refractive, options, bands)
                .map_err(|e| match e {
                    SpectralError::Prepare(source) => prepare(source),
                    SpectralError::Render(source) => render(source),
                })?
                .film
        }
        None => {
            let tracer = prepare_tracer(scene, refractive, options).map_err(prepare)?;
            render_scene(scene, tracer.as_ref(), options).map_err(render)?
        }
    };
    if film.stats.non_finite_samples > 0 {
        // Never silent: these pixels are not what the physics says.
        eprintln!(
            "warning: {name}: {} sample(s) had non-finite radiance and were shaded as horizon sky",
            film.stats.non_finite_samples
        );
    }
    Ok(film)
}

/// Provenance for an EXR of `scene` rendered with `options` (scene hash, observer height,
/// wavelength, fan tolerance or "exact", tracer tolerance, samples per pixel; for a spectral
/// render the number of bands and their centre wavelengths, which replace `wavelength_nm`).
pub fn provenance(scene: &Scene, options: &RenderOptions) -> ExrMetadata {
    let spp = options
        .samples_per_pixel
        .unwrap_or(scene.camera.samples_per_pixel);
    let mut extra = vec![
        ("samples_per_pixel".into(), spp.to_string()),
        (
            "straight_rays".into(),
            scene.atmosphere.straight.to_string(),
        ),
        ("earth_radius_m".into(), scene.earth_radius_m.to_string()),
    ];
    if let Some(bands) = scene.spectral_bands {
        let centres: Vec<String> = crate::render::spectral::band_centres_nm(bands)
            .iter()
            .map(|nm| nm.to_string())
            .collect();
        extra.push(("spectral_bands".into(), bands.to_string()));
        extra.push(("spectral_band_centres_nm".into(), centres.join(",")));
    }
    ExrMetadata {
        scene_hash: scene.hash_hex.clone(),
        observer_height_m: scene.camera.height_m,
        wavelength_nm: scene.atmosphere.wavelength_nm,
        tolerance_px: (!options.exact).then_some(options.tolerance_px),
        tracer_tolerance_m: options.tolerance_m,
        extra,
    }
}
