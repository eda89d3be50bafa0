//! Stage 3 — refract. In: an [`AirColumn`](crate::profile::AirColumn) (a fitted profile, a
//! synthetic layered atmosphere or the standard atmosphere), a wavelength and a CO₂ content. Out:
//! a [`RefractiveAtmosphere`] giving n(h) and dn/dh — exactly (Ciddor 1996 through dual numbers)
//! or from a fast, error-checked table that implements the tracer's
//! [`StratifiedIndex`](crate::tracer::StratifiedIndex) — and the refractive regimes (trapping
//! layers and ducts, super-refraction, inferior-mirage layers) found in it.

mod atmosphere;
pub mod ciddor;
pub mod columns;
pub mod dual;
pub mod regimes;
mod table;

pub use atmosphere::{
    DEFAULT_WAVELENGTH_NM, RefractiveAtmosphere, RefractiveSample, TableError, TableSpec,
    WAVELENGTH_RANGE_NM,
};
pub use ciddor::{CiddorDispersion, ciddor_refractive_index};
pub use regimes::{
    Duct, RefractiveLayer, RegimeKind, RegimeOptions, critical_temperature_gradient_k_per_m,
    detect_regimes, ducts,
};
pub use table::GridError;

/// Why a refractive atmosphere could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RefractivityError {
    /// The wavelength is outside the range the Ciddor formula is fitted for.
    #[error("wavelength {wavelength_nm} nm is outside 300–1700 nm")]
    WavelengthOutOfRange {
        /// The wavelength given (nm).
        wavelength_nm: f64,
    },
    /// The CO₂ content is not within 0–10 000 ppm.
    #[error("CO2 content {co2_ppm} ppm is outside 0–10000 ppm")]
    InvalidCo2 {
        /// The value given (ppm).
        co2_ppm: f64,
    },
    /// The table layout is unusable (non-positive steps, tops out of order, too many cells).
    #[error("invalid refractivity table layout: {0}")]
    InvalidTableSpec(String),
    /// The air column gave a state the formula cannot take.
    #[error(
        "air at {height_m} m is not physical: T = {temperature_k} K, P = {pressure_pa} Pa, \
         e = {vapour_pressure_pa} Pa"
    )]
    InvalidAir {
        /// Height above mean sea level (m).
        height_m: f64,
        /// Temperature (K).
        temperature_k: f64,
        /// Pressure (Pa).
        pressure_pa: f64,
        /// Water-vapour partial pressure (Pa).
        vapour_pressure_pa: f64,
    },
    /// A height or a result was not finite.
    #[error("non-finite refractive index or height at {height_m} m")]
    NonFinite {
        /// Height above mean sea level (m).
        height_m: f64,
    },
}
