//! Jobs — profile. In: a [`ProfileRequest`] and its loaded atmosphere. Out: the layers report and
//! the products `profile.csv` (n(h) on a grid), `layers.json` (inversions, ducts, refractive
//! layers) and `profile.png` (the profile plot); for a measured sounding also
//! `fitted_layers.toml`, the paper-style synthetic layers fitted to it
//! ([`crate::profile::layer_fit`]), an atmosphere every command accepts.

use super::cache::AtmosphereRequest;
use super::{JobError, Product};
use crate::atmosphere::LoadedAtmosphere;
use crate::profile::layer_fit::{LayerFit, LayerFitOptions, fit_layers};
use crate::profile::{InversionOptions, ProfileError, detect_inversions};
use crate::refractivity::{RegimeOptions, detect_regimes};
use crate::report::{
    InputReport, LayersReport, PlotOptions, ProfileGrid, ProfilePlot, layers_json, profile_csv,
    profile_png,
};

/// Default top of profile.png's height axis (m above the surface): where mirage layers live.
pub const DEFAULT_PLOT_TOP_M: f64 = 1_500.0;
/// Default top of the layer search (m above the surface).
pub const DEFAULT_LAYERS_TOP_M: f64 = 10_000.0;

/// A validated profile request.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ProfileRequest {
    /// The atmosphere.
    pub atmosphere: AtmosphereRequest,
    /// Top of the plot's height axis (m above the surface).
    pub plot_top_m: f64,
    /// Top of the layer search (m above the surface).
    pub layers_top_m: f64,
}

impl ProfileRequest {
    /// Build and check a request (heights finite and > 0, atmosphere options in range).
    pub fn new(
        atmosphere: AtmosphereRequest,
        plot_top_m: f64,
        layers_top_m: f64,
    ) -> Result<Self, JobError> {
        atmosphere.validate()?;
        for (key, v) in [("plot_top_m", plot_top_m), ("layers_top_m", layers_top_m)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(JobError::Invalid(format!(
                    "{key} must be a height > 0 m above the surface, got {v}"
                )));
            }
        }
        Ok(ProfileRequest {
            atmosphere,
            plot_top_m,
            layers_top_m,
        })
    }

    /// Find the layers of `atm` and make every product.
    pub fn products(&self, atm: &LoadedAtmosphere) -> Result<ProfileProducts, JobError> {
        let surface_m = atm.refractive.surface_height_m();
        let mut top_m = surface_m + self.layers_top_m;
        if let Some(top_of_data) = atm.top_of_data_m {
            top_m = top_m.min(top_of_data);
        }
        let inversions =
            detect_inversions(atm.column.as_ref(), top_m, &InversionOptions::default());
        let regimes = detect_regimes(&atm.refractive, top_m, &RegimeOptions::default());
        let mut report = LayersReport::new(&atm.refractive, &inversions, &regimes);
        report.input = match &atm.sounding {
            Some(sounding) => InputReport {
                fit: atm.profile.as_ref().map(|p| p.fit_choice().clone()),
                ..InputReport::of_sounding(&atm.source.to_string(), &atm.description, sounding)
            },
            None => InputReport {
                source: atm.source.to_string(),
                description: atm.description.clone(),
                ..InputReport::default()
            },
        };
        let levels = atm
            .sounding
            .as_ref()
            .map(|s| s.levels.as_slice())
            .unwrap_or(&[]);
        let plot = ProfilePlot {
            atmosphere: &atm.refractive,
            levels,
            inversions: &inversions,
            regimes: &regimes,
            title: &atm.description,
        };
        let plot_options = PlotOptions {
            top_agl_m: self.plot_top_m,
            ..PlotOptions::default()
        };
        let png = profile_png(&plot, &plot_options).map_err(|source| JobError::Report {
            atmosphere: atm.source.to_string(),
            source,
        })?;
        let layer_fit = atm
            .sounding
            .as_ref()
            .map(|s| fit_layers(s, &LayerFitOptions::default()));
        Ok(ProfileProducts {
            layer_fit,
            csv: profile_csv(&atm.refractive, &ProfileGrid::default()),
            json: layers_json(&report),
            report,
            png,
        })
    }
}

/// The profile job's products, as bytes (nothing written yet).
pub struct ProfileProducts {
    /// The layers report (summary text and JSON are made from it).
    pub report: LayersReport,
    /// `profile.csv`.
    pub csv: Vec<u8>,
    /// `layers.json`.
    pub json: Vec<u8>,
    /// `profile.png`.
    pub png: Vec<u8>,
    /// For a measured sounding: the synthetic layers fitted to it over
    /// [`LayerFitOptions::default`]'s range, or why no fit could be made (too few levels).
    /// `None` for model atmospheres.
    pub layer_fit: Option<Result<LayerFit, ProfileError>>,
}

impl ProfileProducts {
    /// One summary line on the layer fit, for a measured sounding.
    pub fn layer_fit_line(&self) -> Option<String> {
        Some(match self.layer_fit.as_ref()? {
            Ok(fit) => format!(
                "Fitted synthetic layers (surface to +{:.0} m): {} layers, rms {:.2} K, max {:.2} K \
                 (one straight lapse line: rms {:.2} K) -> fitted_layers.toml",
                LayerFitOptions::default().range_top_above_surface_m,
                fit.layers.len(),
                fit.rms_k,
                fit.max_abs_k,
                fit.lapse_only_rms_k
            ),
            Err(e) => format!("Fitted synthetic layers: none ({e})"),
        })
    }

    /// The files: `profile.csv`, `layers.json`, `profile.png`, and `fitted_layers.toml` when a
    /// layer fit was made.
    pub fn into_products(self) -> Vec<Product> {
        let mut products = vec![
            Product::new("profile.csv", self.csv),
            Product::new("layers.json", self.json),
            Product::new("profile.png", self.png),
        ];
        if let Some(Ok(fit)) = &self.layer_fit {
            products.push(Product::new(
                "fitted_layers.toml",
                fit.to_toml().into_bytes(),
            ));
        }
        products
    }
}
