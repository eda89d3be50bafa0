//! Stage 2 — fit. In: a [`Sounding`](crate::sounding::Sounding) or a synthetic layer description.
//! Out: a [`Profile`]: smooth, monotone-safe T(h), P(h) and vapour pressure e(h) with their height
//! derivatives, blended into the U.S. Standard Atmosphere 1976 above the data, plus the inversion
//! layers and refractive regimes found in it; and ([`ensemble`]) perturbed member profiles for
//! sensitivity studies.

mod blend;
pub mod ensemble;
mod error;
mod fit;
mod hydrostatic;
mod inversion;
pub mod layer_fit;
mod monotone;
mod smooth;
mod standard;
pub mod step_fit;
mod synthetic;
mod temperature;
pub mod us1976;

pub use blend::TimeBlend;
pub use error::ProfileError;
pub use fit::{FitOptions, Profile, ProfileKnot};
pub use inversion::{InversionOptions, detect_inversions};
pub use standard::StandardAtmosphere;
pub use synthetic::{Background, SyntheticAtmosphere, SyntheticLayer};
pub use temperature::{
    AUTO_SPACING_RANGE_M, AUTO_SPARSE_SPACING_M, FitChoice, TemperatureFit, choose_fit,
};

/// Highest height any column here models (m): the top of the U.S. Standard Atmosphere 1976
/// (86 km geometric). Above it every column returns its 86 km air.
pub const MODEL_TOP_M: f64 = 86_000.0;

/// The state of the air at one height, with height derivatives (SI).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AirSample {
    /// Temperature (K).
    pub temperature_k: f64,
    /// dT/dh (K m⁻¹).
    pub dtemperature_dh_k_per_m: f64,
    /// Pressure (Pa).
    pub pressure_pa: f64,
    /// dP/dh (Pa m⁻¹).
    pub dpressure_dh_pa_per_m: f64,
    /// Water-vapour partial pressure (Pa); 0 for dry air.
    pub vapour_pressure_pa: f64,
    /// de/dh (Pa m⁻¹).
    pub dvapour_pressure_dh_pa_per_m: f64,
}

impl AirSample {
    /// A sample whose every field is NaN: what the columns here return for a NaN height, so that
    /// the caller's NaN check sees it (they never panic on one).
    pub fn nan() -> Self {
        AirSample {
            temperature_k: f64::NAN,
            dtemperature_dh_k_per_m: f64::NAN,
            pressure_pa: f64::NAN,
            dpressure_dh_pa_per_m: f64::NAN,
            vapour_pressure_pa: f64::NAN,
            dvapour_pressure_dh_pa_per_m: f64::NAN,
        }
    }
}

/// A column of air: anything that gives T, P, e and their derivatives by height above mean sea
/// level. Implemented by fitted profiles, synthetic layered atmospheres and the standard atmosphere.
pub trait AirColumn: Send + Sync {
    /// Height of the ground (m above mean sea level); the column is not defined below it.
    fn surface_height_m(&self) -> f64;
    /// Air at `height_m` above mean sea level (at or above the surface).
    fn air_at(&self, height_m: f64) -> AirSample;
    /// Heights above mean sea level (ascending) where the column is not smooth: where dT/dh, or
    /// a second derivative of T, P or e, may jump (knots of a piecewise fit, edges of a
    /// constant-gradient layer, layer bases of the standard atmosphere). A ray integrator loses
    /// its order in a step that straddles one, so the tracer ends its steps on them. Default:
    /// none (a smooth column).
    fn breaks_m(&self) -> Vec<f64> {
        Vec::new()
    }
}

/// Sort heights, drop non-finite ones and merge those closer than 1 mm (one break).
pub fn normalise_breaks(mut heights_m: Vec<f64>) -> Vec<f64> {
    heights_m.retain(|h| h.is_finite());
    heights_m.sort_by(f64::total_cmp);
    heights_m.dedup_by(|a, b| (*a - *b).abs() < 1e-3);
    heights_m
}

/// Whether an inversion starts at the ground or aloft.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InversionKind {
    /// The layer's base is at the surface.
    Surface,
    /// The layer's base is above the surface.
    Elevated,
}

/// A temperature inversion layer (temperature increasing with height) found in a profile.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InversionLayer {
    /// Base height above mean sea level (m).
    pub base_m: f64,
    /// Top height above mean sea level (m).
    pub top_m: f64,
    /// Base height above ground level (m).
    pub base_agl_m: f64,
    /// Top height above ground level (m).
    pub top_agl_m: f64,
    /// Temperature increase from base to top (K), positive.
    pub delta_t_k: f64,
    /// Largest dT/dh inside the layer (K m⁻¹).
    pub max_gradient_k_per_m: f64,
    /// Surface-based or elevated.
    pub kind: InversionKind,
}
