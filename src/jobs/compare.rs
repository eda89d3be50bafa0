//! Jobs — compare. In: a [`CompareRequest`] (a measured sounding, optionally a synthetic
//! atmosphere file, a scene) and the atmosphere cache. Out: a [`CompareOutcome`] and the
//! products `compare.json`, `measured.png`, `synthetic.png`, `side_by_side.png`,
//! `profiles.png`, `transfer.png` and, when the synthetic atmosphere is the layer fit,
//! `fitted_layers.toml`.
//!
//! Without a synthetic file, the synthetic atmosphere is fitted to the sounding from the surface
//! to +3000 m: by default in the paper's form ([`crate::profile::step_fit`]: a lapse rate and one
//! smooth layer per detected inversion), or as linear layers ([`crate::profile::layer_fit`]). Both atmospheres are traced
//! with one fan spanning the camera's vertical field (targets: the scene's cards, ground to top)
//! and rendered through the same scene at the same size.

use std::sync::Arc;

use super::cache::AtmosphereRequest;
use super::render::{RenderRequest, RenderSettings};
use super::trace::{ElevationSpec, TraceJobRequest};
use super::{AtmosphereCache, JobError, Product};
use crate::atmosphere::{AtmosphereSource, LoadedAtmosphere, atmosphere_from_column};
use crate::compare::metrics::side_by_side_png;
use crate::compare::plot::{ProfilesPlot, profiles_png, transfer_png};
use crate::compare::{Comparison, FanSummary, FitSummary, SideSummary, image_metrics};
use crate::profile::layer_fit::{LayerFitOptions, fit_layers};
use crate::profile::step_fit::fit_steps;
use crate::refractivity::{RegimeOptions, detect_regimes};
use crate::scene::Scene;
use crate::tracer::TracerConfig;

/// Default number of rays of the comparison fan across the camera's vertical field.
pub const DEFAULT_COMPARE_RAYS: usize = 801;
/// Targets used when the scene has no cards: (distance m, height m).
pub const DEFAULT_TARGETS: [(f64, f64); 2] = [(10_000.0, 20.0), (20_000.0, 20.0)];
/// Top of the duct search and of `profiles.png` (m above the surface).
const PROFILE_TOP_M: f64 = 1_500.0;

/// The form of the synthetic layers fitted to the sounding.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "snake_case")]
pub enum LayerShape {
    /// The paper's form: a lapse-rate background and one smooth (tanh) layer per detected
    /// inversion, centre, thickness and ΔT fitted ([`crate::profile::step_fit`]).
    #[default]
    Smooth,
    /// Up to 10 contiguous constant-gradient layers ([`crate::profile::layer_fit`]): a closer
    /// fit to dense ascents, but not the paper's parameters.
    Linear,
}

/// How a comparison reads the sounding and traces, beyond the render settings.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareOptions {
    /// Which sounding of a multi-sounding file.
    pub sounding_time: Option<String>,
    /// Smoothing scale of the sounding fit (m); `None`: the scene's (default 20 m).
    pub smooth_m: Option<f64>,
    /// Temperature fit between the sounding's levels; `None`: the scene's (default auto).
    pub fit: Option<crate::profile::TemperatureFit>,
    /// Rays of the fan across the camera's vertical field.
    pub rays: usize,
    /// The form of the fitted layers (when no synthetic atmosphere is given).
    pub layers: LayerShape,
}

impl Default for CompareOptions {
    fn default() -> Self {
        CompareOptions {
            sounding_time: None,
            smooth_m: None,
            fit: None,
            rays: DEFAULT_COMPARE_RAYS,
            layers: LayerShape::default(),
        }
    }
}

/// A validated comparison request.
#[derive(Debug, Clone)]
pub struct CompareRequest {
    /// The scene rendered through the measured sounding (its request names the sounding).
    pub render: RenderRequest,
    /// The measured sounding.
    pub measured: AtmosphereRequest,
    /// The synthetic atmosphere file; `None`: the layers fitted to the sounding.
    pub synthetic: Option<AtmosphereRequest>,
    /// The fan traced through both.
    pub trace: TraceJobRequest,
    /// The targets, (distance m, top height m): the scene's cards, or [`DEFAULT_TARGETS`].
    pub targets: Vec<(f64, f64)>,
    /// The form of the fitted layers.
    pub layers: LayerShape,
}

impl CompareRequest {
    /// Check the parts: `measured` must be a sounding and `synthetic` (if given) a synthetic
    /// TOML or `us1976`; `settings` render the scene (its atmosphere replaced by `measured`).
    pub fn new(
        scene: Scene,
        measured: AtmosphereSource,
        synthetic: Option<AtmosphereSource>,
        settings: RenderSettings,
        options: &CompareOptions,
    ) -> Result<Self, JobError> {
        let rays = options.rays;
        let invalid = |m: String| Err(JobError::Invalid(m));
        if !matches!(measured, AtmosphereSource::Sounding(_)) {
            return invalid(format!(
                "the measured atmosphere must be a sounding file, not {measured}"
            ));
        }
        if matches!(synthetic, Some(AtmosphereSource::Sounding(_))) {
            let name = synthetic
                .as_ref()
                .map(|s| s.to_string())
                .unwrap_or_default();
            return invalid(format!(
                "the synthetic atmosphere must be a .toml file or us1976, not the sounding {name}"
            ));
        }
        if !(3..=super::trace::MAX_RAYS).contains(&rays) {
            return invalid(format!(
                "rays must be 3 to {}, got {rays}",
                super::trace::MAX_RAYS
            ));
        }
        let settings = RenderSettings {
            atmosphere: Some(measured),
            sounding_time: options.sounding_time.clone(),
            straight: false,
            sizes: vec![settings.sizes.first().copied().flatten()],
            ..settings
        };
        let scene_name = scene
            .source_path
            .as_ref()
            .map_or_else(|| "the scene".into(), |p| p.display().to_string());
        let render = RenderRequest::new(scene, settings)?;
        let Some(mut measured) = render.atmosphere.clone() else {
            return invalid(format!(
                "{scene_name} sets atmosphere.straight = true (n ≡ 1): there is nothing to compare"
            ));
        };
        if let Some(smooth_m) = options.smooth_m {
            measured.options.smooth_m = smooth_m;
        }
        if let Some(fit) = options.fit {
            measured.options.fit = fit;
        }
        measured.validate()?;
        let synthetic = synthetic.map(|source| AtmosphereRequest {
            source,
            options: crate::atmosphere::AtmosphereOptions {
                sounding_time: None,
                ..measured.options.clone()
            },
        });
        let targets = scene_targets(&render.scene);
        let trace = fan_request(&render, &measured, &targets, rays)?;
        Ok(CompareRequest {
            render,
            measured,
            synthetic,
            trace,
            targets,
            layers: options.layers,
        })
    }

    /// Rough work: two renders and two fans.
    pub fn cost(&self) -> f64 {
        let (w, h) = self
            .render
            .settings
            .sizes
            .first()
            .copied()
            .flatten()
            .unwrap_or((
                self.render.scene.camera.width,
                self.render.scene.camera.height,
            ));
        let spp = self
            .render
            .settings
            .spp
            .unwrap_or(self.render.scene.camera.samples_per_pixel) as f64;
        2.0 * (50_000.0 + 0.3 * w as f64 * h as f64 * spp + 300.0 * self.trace.ray_count() as f64)
    }

    /// Run the comparison: load (or fit) both atmospheres, trace, render, compare.
    pub fn outcome(&self, cache: &AtmosphereCache) -> Result<CompareOutcome, JobError> {
        let measured = cache.get(&self.measured)?;
        let (synthetic, fit) = match &self.synthetic {
            Some(request) => (cache.get(request)?, None),
            None => {
                let (atm, fit) = fitted_atmosphere(&measured, &self.measured, self.layers)?;
                (Arc::new(atm), Some(fit))
            }
        };
        let side = |atm: &LoadedAtmosphere| -> Result<_, JobError> {
            let (report, _) = self.trace.report(atm, false)?;
            let top = atm.refractive.surface_height_m() + PROFILE_TOP_M;
            let layers = detect_regimes(&atm.refractive, top, &RegimeOptions::default());
            let size = self.render.settings.sizes.first().copied().flatten();
            let (film, _) = self.render.film(size, Some(atm), true)?;
            Ok((report, layers, film))
        };
        let (m, s) = (side(&measured)?, side(&synthetic)?);
        let exposure = self.render.settings.exposure;
        let metric_err =
            |e: crate::compare::metrics::CompareError| JobError::Compare(e.to_string());
        let image = image_metrics(&m.2, &s.2, exposure).map_err(metric_err)?;
        let r = &self.trace.request;
        let fan = FanSummary {
            observer_height_m: r.observer_height_m,
            elevation_min_deg: r.elevation_min_deg,
            elevation_max_deg: r.elevation_max_deg,
            rays: r.elevation_count,
            tolerance_m: r.tracer.tolerance_m,
        };
        let comparison = Comparison::new(
            fan,
            SideSummary::new(
                measured.source.to_string(),
                measured.description.clone(),
                measured.refractive.surface_height_m(),
                &m.0,
                &m.1,
                &self.targets,
            ),
            SideSummary::new(
                synthetic.source.to_string(),
                synthetic.description.clone(),
                synthetic.refractive.surface_height_m(),
                &s.0,
                &s.1,
                &self.targets,
            ),
            image,
            fit.as_ref().map(|f| f.0.clone()),
        );
        let figures = figures(
            &measured,
            &synthetic,
            &comparison,
            (&m.0, &s.0),
            &self.targets,
        )?;
        let gain = crate::compare::metrics::DIFFERENCE_GAIN;
        let labels = [
            "measured",
            "synthetic",
            &format!("|synthetic − measured| × {gain}"),
        ];
        let side_by_side = side_by_side_png(&m.2, &s.2, exposure, labels).map_err(metric_err)?;
        let png = |f: &crate::render::Film| {
            crate::output::png::encode_png(f, exposure)
                .map_err(|e| JobError::Compare(e.to_string()))
        };
        Ok(CompareOutcome {
            measured_png: png(&m.2)?,
            synthetic_png: png(&s.2)?,
            side_by_side_png: side_by_side,
            profiles_png: figures.0,
            transfer_png: figures.1,
            fitted_toml: fit.map(|f| f.1),
            comparison,
        })
    }

    /// The products (see the module documentation).
    pub fn products(&self, cache: &AtmosphereCache) -> Result<Vec<Product>, JobError> {
        self.outcome(cache)?.into_products()
    }
}

/// The scene's cards as targets (distance, top height), in order, duplicates dropped; the
/// [`DEFAULT_TARGETS`] for a scene without cards.
fn scene_targets(scene: &Scene) -> Vec<(f64, f64)> {
    let mut targets: Vec<(f64, f64)> = Vec::new();
    for c in &scene.cards {
        let t = (c.distance_m, c.base_m + c.height_m);
        if !targets.contains(&t) {
            targets.push(t);
        }
    }
    if targets.is_empty() {
        targets = DEFAULT_TARGETS.to_vec();
    }
    targets
}

/// The fan: the camera's vertical field at the rendered size (the horizontal field stays, the
/// vertical follows the aspect ratio), from the camera height, to every target.
fn fan_request(
    render: &RenderRequest,
    measured: &AtmosphereRequest,
    targets: &[(f64, f64)],
    rays: usize,
) -> Result<TraceJobRequest, JobError> {
    let scene = &render.scene_at(render.settings.sizes.first().copied().flatten());
    let frame = scene.camera.frame();
    let (w, h) = (scene.camera.width as f64, scene.camera.height as f64);
    let elevations: Vec<f64> = [
        (0.0, 0.0),
        (w / 2.0, 0.0),
        (w, 0.0),
        (0.0, h),
        (w / 2.0, h),
        (w, h),
    ]
    .iter()
    .map(|&(x, y)| frame.direction(x, y).1.to_degrees())
    .collect();
    let lo = elevations.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = elevations.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut distances: Vec<f64> = targets.iter().map(|t| t.0).collect();
    let mut heights: Vec<f64> = targets.iter().map(|t| t.1).collect();
    for v in [&mut distances, &mut heights] {
        v.sort_by(f64::total_cmp);
        v.dedup();
    }
    let tracer = TracerConfig {
        tolerance_m: render.settings.tolerance_m,
        ..TracerConfig::default()
    };
    let spec = ElevationSpec::Range {
        from_deg: lo,
        to_deg: hi,
        count: rays,
    };
    TraceJobRequest::new(
        measured.clone(),
        scene.camera.height_m,
        &spec,
        distances,
        heights,
        tracer,
        false,
    )
}

/// The synthetic atmosphere fitted to `measured`'s sounding in the form `shape`, refracted like
/// it, with the fit's summary and TOML.
fn fitted_atmosphere(
    measured: &LoadedAtmosphere,
    request: &AtmosphereRequest,
    shape: LayerShape,
) -> Result<(LoadedAtmosphere, (FitSummary, String)), JobError> {
    let Some(sounding) = measured.sounding.as_ref() else {
        return Err(JobError::Invalid(format!(
            "{} is not a sounding; nothing to fit",
            measured.source
        )));
    };
    let profile_err = |e: crate::profile::ProfileError| {
        JobError::Compare(format!(
            "cannot fit layers to {}: {e}; give a SYNTHETIC atmosphere to compare with",
            measured.source
        ))
    };
    let options = LayerFitOptions::default();
    let (summary, toml, column) = match shape {
        LayerShape::Smooth => {
            let fit = fit_steps(sounding, &options).map_err(profile_err)?;
            let column = fit.to_synthetic().map_err(profile_err)?;
            (FitSummary::from(&fit), fit.to_toml(), column)
        }
        LayerShape::Linear => {
            let fit = fit_layers(sounding, &options).map_err(profile_err)?;
            let column = fit.to_synthetic().map_err(profile_err)?;
            (FitSummary::from(&fit), fit.to_toml(), column)
        }
    };
    let stem = measured.source.stem();
    let source = AtmosphereSource::Synthetic(format!("{stem}.fitted_layers.toml").into());
    let description = format!(
        "{} {} layer(s) fitted to {} (rms {:.2} K)",
        summary.layers.len(),
        summary.shape,
        measured.description,
        summary.rms_k
    );
    let atm = atmosphere_from_column(
        &source,
        Arc::new(column),
        description,
        request.options.wavelength_nm,
    )?;
    Ok((atm, (summary, toml)))
}

/// `profiles.png` and `transfer.png`.
fn figures(
    measured: &LoadedAtmosphere,
    synthetic: &LoadedAtmosphere,
    comparison: &Comparison,
    reports: (&crate::analysis::TraceReport, &crate::analysis::TraceReport),
    targets: &[(f64, f64)],
) -> Result<(Vec<u8>, Vec<u8>), JobError> {
    let plot_err = |m: String| JobError::Compare(format!("cannot draw the figures: {m}"));
    let layers = comparison
        .fit
        .as_ref()
        .map(|f| f.layers.as_slice())
        .unwrap_or(&[]);
    let levels = measured
        .sounding
        .as_ref()
        .map(|s| s.levels.as_slice())
        .unwrap_or(&[]);
    let title = format!("{} — measured and synthetic", measured.source.stem());
    let profiles = profiles_png(&ProfilesPlot {
        measured: &measured.refractive,
        synthetic: &synthetic.refractive,
        levels,
        layers,
        top_agl_m: PROFILE_TOP_M,
        title: &title,
    })
    .map_err(plot_err)?;
    let transfer = transfer_png(reports.0, reports.1, targets).map_err(plot_err)?;
    Ok((profiles, transfer))
}

/// What a comparison made, as bytes (nothing written yet).
pub struct CompareOutcome {
    /// The comparison (summary text and `compare.json` are made from it).
    pub comparison: Comparison,
    /// The render through the measured sounding.
    pub measured_png: Vec<u8>,
    /// The render through the synthetic atmosphere.
    pub synthetic_png: Vec<u8>,
    /// measured | synthetic | difference.
    pub side_by_side_png: Vec<u8>,
    /// T(h) and dN/dh of both.
    pub profiles_png: Vec<u8>,
    /// Both transfer curves.
    pub transfer_png: Vec<u8>,
    /// The fitted layers as a synthetic TOML, when the synthetic atmosphere is the fit.
    pub fitted_toml: Option<String>,
}

impl CompareOutcome {
    /// The files (see the module documentation).
    pub fn into_products(self) -> Result<Vec<Product>, JobError> {
        let mut json = serde_json::to_string_pretty(&self.comparison)?;
        json.push('\n');
        let mut products = vec![
            Product::new("compare.json", json.into_bytes()),
            Product::new("measured.png", self.measured_png),
            Product::new("synthetic.png", self.synthetic_png),
            Product::new("side_by_side.png", self.side_by_side_png),
            Product::new("profiles.png", self.profiles_png),
            Product::new("transfer.png", self.transfer_png),
        ];
        if let Some(toml) = self.fitted_toml {
            products.push(Product::new("fitted_layers.toml", toml.into_bytes()));
        }
        Ok(products)
    }
}
