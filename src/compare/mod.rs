//! Stage 6 — comparison, measured against synthetic. In: what one scene shows through two
//! atmospheres — for each, the trace report of one fan from the scene's camera to its targets,
//! the refractive layers (ducts) and the rendered film — and, when the synthetic atmosphere was
//! fitted to the sounding, the [`LayerFit`]. Out: a [`Comparison`] that says in a user's terms
//! what differs (images of each target: count, erect or inverted, elevation band,
//! magnification; apparent horizons; trapped rays; ducts; image RMSE and SSIM), and its figures
//! ([`plot`]: side by side with the difference, T(h) and dN/dh overlays, transfer curves).
//!
//! The stages before this one make the inputs; [`crate::jobs`] runs them for the `compare`
//! command and the `[[compare]]` pipeline job.

pub mod metrics;
pub mod plot;

use serde::Serialize;

use crate::analysis::TraceReport;
use crate::analysis::report::Horizon;
use crate::profile::layer_fit::LayerFit;
use crate::profile::step_fit::StepFit;
use crate::refractivity::RefractiveLayer;

pub use metrics::{ImageMetrics, image_metrics};

/// Images of one target (a card of the scene: ground from 0 up to its top) at its distance.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TargetImages {
    /// Ground distance of the target (m).
    pub distance_m: f64,
    /// Height of the target's top above the surface (m).
    pub height_m: f64,
    /// Number of images.
    pub count: usize,
    /// Number of erect images.
    pub erect: usize,
    /// Number of inverted images (a superior or inferior mirage).
    pub inverted: usize,
    /// Lowest apparent elevation of any image (deg); `None` without images.
    pub elevation_min_deg: Option<f64>,
    /// Highest apparent elevation of any image (deg); `None` without images.
    pub elevation_max_deg: Option<f64>,
    /// Largest mean vertical magnification of an image; `None` without images.
    pub max_magnification: Option<f64>,
}

/// A duct (trapping layer) of one atmosphere.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DuctSummary {
    /// Base of the duct (m above the surface): where M comes back to its value at the top, or
    /// the surface.
    pub base_m: f64,
    /// Base of the trapping layer (m above the surface).
    pub trapping_base_m: f64,
    /// Top of the duct (m above the surface).
    pub top_m: f64,
    /// Modified-refractivity deficit ΔM across the duct (M units).
    pub m_deficit: f64,
    /// Whether the duct reaches the surface.
    pub surface_based: bool,
}

/// What one atmosphere shows through the scene.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SideSummary {
    /// The atmosphere's source (file or `fitted layers of …`).
    pub atmosphere: String,
    /// Its one-line description.
    pub description: String,
    /// Height of its surface (m above mean sea level): the camera stands this high plus its
    /// own height.
    pub surface_height_m: f64,
    /// Images of each target.
    pub targets: Vec<TargetImages>,
    /// Apparent horizon at each target distance, then the sea horizon.
    pub horizons: Vec<Horizon>,
    /// Number of the fan's rays that are trapped.
    pub trapped_rays: usize,
    /// Lowest and highest trapped elevation (deg), if any ray is trapped.
    pub trapped_elevation_range_deg: Option<(f64, f64)>,
    /// Ducts from the surface up to the layer search's top.
    pub ducts: Vec<DuctSummary>,
}

impl SideSummary {
    /// Summarise one atmosphere's trace report and refractive layers for `targets`
    /// ((distance m, height m) pairs; the report must have been asked for these distances and
    /// heights).
    pub fn new(
        atmosphere: String,
        description: String,
        surface_height_m: f64,
        report: &TraceReport,
        layers: &[RefractiveLayer],
        targets: &[(f64, f64)],
    ) -> Self {
        let targets = targets
            .iter()
            .map(|&(d, h)| target_images(report, d, h))
            .collect();
        let trapped = &report.trapped_elevations_deg;
        let range = trapped
            .iter()
            .copied()
            .fold(None, |acc: Option<(f64, f64)>, e| {
                Some(acc.map_or((e, e), |(lo, hi)| (lo.min(e), hi.max(e))))
            });
        SideSummary {
            atmosphere,
            description,
            surface_height_m,
            targets,
            horizons: report.horizons.clone(),
            trapped_rays: trapped.len(),
            trapped_elevation_range_deg: range,
            ducts: layers
                .iter()
                .filter_map(|l| l.duct.as_ref())
                .map(|d| DuctSummary {
                    base_m: d.base_agl_m,
                    trapping_base_m: d.trapping_base_m - (d.base_m - d.base_agl_m),
                    top_m: d.top_agl_m,
                    m_deficit: d.m_deficit,
                    surface_based: d.surface_based,
                })
                .collect(),
        }
    }
}

fn target_images(report: &TraceReport, distance_m: f64, height_m: f64) -> TargetImages {
    let images: Vec<_> = report
        .images
        .iter()
        .filter(|i| i.distance_m == distance_m && i.height_m == height_m)
        .collect();
    let erect = images.iter().filter(|i| i.erect).count();
    let fold = |f: fn(f64, f64) -> f64, pick: fn(&crate::analysis::Image) -> f64| {
        images.iter().map(|i| pick(i)).reduce(f)
    };
    TargetImages {
        distance_m,
        height_m,
        count: images.len(),
        erect,
        inverted: images.len() - erect,
        elevation_min_deg: fold(f64::min, |i| i.elevation_min_deg),
        elevation_max_deg: fold(f64::max, |i| i.elevation_max_deg),
        max_magnification: fold(f64::max, |i| i.magnification),
    }
}

/// One fitted layer as the comparison reports it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LayerSummary {
    /// Base (m above mean sea level).
    pub base_m: f64,
    /// Top (m above mean sea level).
    pub top_m: f64,
    /// Temperature change across the layer (K).
    pub delta_t_k: f64,
    /// dT/dh (K m⁻¹).
    pub gradient_k_per_m: f64,
}

/// The parameters and residuals of a layer fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitSummary {
    /// `smooth` (the paper's tanh layers on a lapse rate) or `linear` (constant-gradient
    /// layers).
    pub shape: String,
    /// Background lapse rate (K m⁻¹) of a smooth fit; `None` for linear layers.
    pub background_lapse_k_per_m: Option<f64>,
    /// Surface height (m above mean sea level).
    pub surface_height_m: f64,
    /// Surface temperature (K).
    pub surface_temperature_k: f64,
    /// Surface pressure (hPa).
    pub surface_pressure_hpa: f64,
    /// The layers, lowest first (a smooth layer's base and top are its centre ∓ half its
    /// thickness, its gradient ΔT over the thickness).
    pub layers: Vec<LayerSummary>,
    /// RMS residual over the fitted levels (K).
    pub rms_k: f64,
    /// Largest |residual| (K).
    pub max_abs_k: f64,
    /// RMS of one straight lapse line over the same levels (K): the baseline.
    pub lapse_only_rms_k: f64,
    /// Number of levels fitted.
    pub levels: usize,
    /// Why the breakpoint optimiser stopped.
    pub termination: String,
}

impl From<&StepFit> for FitSummary {
    fn from(fit: &StepFit) -> Self {
        FitSummary {
            shape: "smooth".into(),
            background_lapse_k_per_m: Some(fit.lapse_k_per_m),
            surface_height_m: fit.surface_height_m,
            surface_temperature_k: fit.surface_temperature_k,
            surface_pressure_hpa: fit.surface_pressure_pa / 100.0,
            layers: fit
                .layers
                .iter()
                .map(|l| LayerSummary {
                    base_m: l.centre_m - 0.5 * l.thickness_m,
                    top_m: l.centre_m + 0.5 * l.thickness_m,
                    delta_t_k: l.delta_t_k,
                    gradient_k_per_m: l.delta_t_k / l.thickness_m,
                })
                .collect(),
            rms_k: fit.rms_k,
            max_abs_k: fit.max_abs_k,
            lapse_only_rms_k: fit.lapse_only_rms_k,
            levels: fit.residuals.len(),
            termination: "Nelder-Mead best".into(),
        }
    }
}

impl From<&LayerFit> for FitSummary {
    fn from(fit: &LayerFit) -> Self {
        FitSummary {
            shape: "linear".into(),
            background_lapse_k_per_m: None,
            surface_height_m: fit.surface_height_m,
            surface_temperature_k: fit.surface_temperature_k,
            surface_pressure_hpa: fit.surface_pressure_pa / 100.0,
            layers: fit
                .layers
                .iter()
                .map(|l| LayerSummary {
                    base_m: l.base_m,
                    top_m: l.top_m,
                    delta_t_k: l.top_temperature_k - l.base_temperature_k,
                    gradient_k_per_m: l.gradient_k_per_m(),
                })
                .collect(),
            rms_k: fit.rms_k,
            max_abs_k: fit.max_abs_k,
            lapse_only_rms_k: fit.lapse_only_rms_k,
            levels: fit.residuals.len(),
            termination: fit.termination.to_string(),
        }
    }
}

/// The fan both atmospheres were traced with (to repeat it with `ghostship trace`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FanSummary {
    /// Observer (camera) height above the surface (m).
    pub observer_height_m: f64,
    /// Lowest elevation of the fan (deg): the bottom of the camera's field.
    pub elevation_min_deg: f64,
    /// Highest elevation of the fan (deg): the top of the camera's field.
    pub elevation_max_deg: f64,
    /// Number of rays, evenly spaced.
    pub rays: usize,
    /// The tracer's tolerance (m).
    pub tolerance_m: f64,
}

/// Measured against synthetic: both sides, the image metrics and the fit (if one was made).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Comparison {
    /// The fan traced through both.
    pub fan: FanSummary,
    /// Through the measured sounding.
    pub measured: SideSummary,
    /// Through the synthetic atmosphere.
    pub synthetic: SideSummary,
    /// The two renders compared.
    pub image: ImageMetrics,
    /// The layer fit, when the synthetic atmosphere was fitted to the sounding.
    pub fit: Option<FitSummary>,
    /// One line per difference a user would notice (image count or orientation of a target,
    /// horizon shifts over 0.5′, trapping in one atmosphere only, ducts), empty if none.
    pub differences: Vec<String>,
}

impl Comparison {
    /// Put the two sides together and list their differences.
    pub fn new(
        fan: FanSummary,
        measured: SideSummary,
        synthetic: SideSummary,
        image: ImageMetrics,
        fit: Option<FitSummary>,
    ) -> Self {
        let differences = differences(&measured, &synthetic);
        Comparison {
            fan,
            measured,
            synthetic,
            image,
            fit,
            differences,
        }
    }

    /// Readable summary: fit, per-target images side by side, horizons, differences, metrics.
    pub fn summary_text(&self) -> String {
        let mut out = String::new();
        if let Some(fit) = &self.fit {
            out += &format!(
                "Synthetic: {} {} layer(s) fitted to {} levels, rms {:.2} K, max {:.2} K (straight \
                 lapse line: rms {:.2} K)\n",
                fit.layers.len(),
                fit.shape,
                fit.levels,
                fit.rms_k,
                fit.max_abs_k,
                fit.lapse_only_rms_k
            );
        }
        out += &format!("Measured:  {}\n", self.measured.description);
        out += &format!("Synthetic: {}\n", self.synthetic.description);
        out += "target                 measured                 synthetic\n";
        for (m, s) in self.measured.targets.iter().zip(&self.synthetic.targets) {
            out += &format!(
                "{:>5.1} km, {:>5.1} m   {:<24} {}\n",
                m.distance_m / 1000.0,
                m.height_m,
                images_text(m),
                images_text(s)
            );
        }
        out += &format!(
            "sea horizon            {:<24} {}\n",
            horizon_text(self.measured.horizons.last()),
            horizon_text(self.synthetic.horizons.last())
        );
        out += &format!(
            "trapped rays           {:<24} {}\n",
            self.measured.trapped_rays, self.synthetic.trapped_rays
        );
        out += &format!(
            "ducts                  {:<24} {}\n",
            ducts_text(&self.measured.ducts),
            ducts_text(&self.synthetic.ducts)
        );
        out += &format!(
            "Images: RMSE {:.4}, SSIM {:.4} (8-bit luma, 0–1 scale)\n",
            self.image.rmse, self.image.ssim
        );
        if self.differences.is_empty() {
            out += "No difference a viewer would notice in images, horizon, trapping or ducts.\n";
        }
        for d in &self.differences {
            out += &format!("Difference: {d}\n");
        }
        out
    }
}

fn images_text(t: &TargetImages) -> String {
    match (t.elevation_min_deg, t.elevation_max_deg) {
        (Some(lo), Some(hi)) => format!(
            "{} ({}i) {:+.1}′…{:+.1}′",
            t.count,
            t.inverted,
            lo * 60.0,
            hi * 60.0
        ),
        _ => "none".into(),
    }
}

fn horizon_text(h: Option<&Horizon>) -> String {
    match h.and_then(|h| h.elevation_deg) {
        Some(e) => format!("{:+.2}′", e * 60.0),
        None => "below the fan".into(),
    }
}

fn ducts_text(ducts: &[DuctSummary]) -> String {
    if ducts.is_empty() {
        return "none".into();
    }
    ducts
        .iter()
        .map(|d| {
            format!(
                "{:.0}–{:.0} m above the surface",
                d.trapping_base_m, d.top_m
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Horizon shifts smaller than this (arcmin) are not listed as differences.
const HORIZON_NOTICE_ARCMIN: f64 = 0.5;
/// Duct bounds closer than this (m) are the same duct.
const DUCT_NOTICE_M: f64 = 10.0;
/// Surfaces closer than this (m) are the same ground.
const SURFACE_NOTICE_M: f64 = 5.0;

fn differences(m: &SideSummary, s: &SideSummary) -> Vec<String> {
    let mut out = Vec::new();
    if (m.surface_height_m - s.surface_height_m).abs() > SURFACE_NOTICE_M {
        out.push(format!(
            "surface: {:.0} m above sea level measured, {:.0} m synthetic (the camera and the \
             cards stand on different ground)",
            m.surface_height_m, s.surface_height_m
        ));
    }
    for (a, b) in m.targets.iter().zip(&s.targets) {
        if a.count != b.count || a.inverted != b.inverted {
            out.push(format!(
                "target {:.0} m high at {:.1} km: {} image(s), {} inverted, measured; {} image(s), \
                 {} inverted, synthetic",
                a.height_m,
                a.distance_m / 1000.0,
                a.count,
                a.inverted,
                b.count,
                b.inverted
            ));
        }
    }
    for (a, b) in m.horizons.iter().zip(&s.horizons) {
        let name = match a.distance_m {
            Some(d) => format!("apparent horizon at {:.1} km", d / 1000.0),
            None => "sea horizon".into(),
        };
        match (a.elevation_deg, b.elevation_deg) {
            (Some(x), Some(y)) if ((x - y) * 60.0).abs() > HORIZON_NOTICE_ARCMIN => {
                out.push(format!(
                    "{name}: {:+.2}′ measured, {:+.2}′ synthetic",
                    x * 60.0,
                    y * 60.0
                ))
            }
            (Some(_), None) | (None, Some(_)) => {
                out.push(format!("{name}: inside the fan in one atmosphere only"))
            }
            _ => {}
        }
    }
    if (m.trapped_rays > 0) != (s.trapped_rays > 0) {
        out.push(format!(
            "trapped rays: {} measured, {} synthetic",
            m.trapped_rays, s.trapped_rays
        ));
    }
    let moved = m.ducts.iter().zip(&s.ducts).any(|(a, b)| {
        (a.trapping_base_m - b.trapping_base_m).abs() > DUCT_NOTICE_M
            || (a.top_m - b.top_m).abs() > DUCT_NOTICE_M
    });
    if m.ducts.len() != s.ducts.len() || moved {
        out.push(format!(
            "ducts: {} measured ({}), {} synthetic ({})",
            m.ducts.len(),
            ducts_text(&m.ducts),
            s.ducts.len(),
            ducts_text(&s.ducts)
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn side(surface_m: f64, ducts: &[(f64, f64)]) -> SideSummary {
        SideSummary {
            atmosphere: "a".into(),
            description: "a".into(),
            surface_height_m: surface_m,
            targets: Vec::new(),
            horizons: Vec::new(),
            trapped_rays: 0,
            trapped_elevation_range_deg: None,
            ducts: ducts
                .iter()
                .map(|&(b, t)| DuctSummary {
                    base_m: b,
                    trapping_base_m: b,
                    top_m: t,
                    m_deficit: 1.0,
                    surface_based: b == 0.0,
                })
                .collect(),
        }
    }

    #[test]
    fn ducts_at_other_heights_are_a_difference() {
        let d = differences(&side(0.0, &[(370.0, 390.0)]), &side(0.0, &[(100.0, 120.0)]));
        assert_eq!(d.len(), 1, "{d:?}");
        assert!(d[0].starts_with("ducts:"), "{d:?}");
        let same = differences(&side(0.0, &[(370.0, 390.0)]), &side(0.0, &[(372.0, 391.0)]));
        assert!(same.is_empty(), "{same:?}");
    }

    #[test]
    fn different_ground_is_a_difference() {
        let d = differences(&side(2830.0, &[]), &side(0.0, &[]));
        assert!(d.iter().any(|x| x.starts_with("surface:")), "{d:?}");
    }
}
