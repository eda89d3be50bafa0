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
    /// Height bands (m above mean sea level) where the column changes on a vertical scale
    /// shorter than the tracer's default step would resolve and no break marks it (a smooth bump
    /// such as the join above a sounding's top): each with the largest height change a step may
    /// make there. Default: none.
    fn fine_zones_m(&self) -> Vec<FineZone> {
        Vec::new()
    }
}

/// A height band where the air changes on a short vertical scale without a break (see
/// [`AirColumn::fine_zones_m`]). Heights are above mean sea level in an [`AirColumn`] and above
/// the surface in a [`StratifiedIndex`](crate::tracer::StratifiedIndex).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FineZone {
    /// Bottom of the band (m).
    pub lo_m: f64,
    /// Top of the band (m).
    pub hi_m: f64,
    /// Largest height change (m) of one integration step inside the band or reaching into it.
    pub max_rise_m: f64,
}

impl FineZone {
    /// The same band `offset_m` lower (heights above the surface from heights above sea level).
    pub fn lowered(self, offset_m: f64) -> Self {
        FineZone {
            lo_m: self.lo_m - offset_m,
            hi_m: self.hi_m - offset_m,
            ..self
        }
    }

    /// The largest height change allowed to a step from `height_m` that may change height by up
    /// to `limit_m`: `limit_m`, or less where the step could reach one of `zones`.
    pub fn limit_rise_m(zones: &[FineZone], height_m: f64, limit_m: f64) -> f64 {
        zones.iter().fold(limit_m, |limit, z| {
            if height_m + limit > z.lo_m && height_m - limit < z.hi_m {
                limit.min(z.max_rise_m)
            } else {
                limit
            }
        })
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

#[cfg(test)]
mod tests {
    use super::FineZone;

    #[test]
    fn a_step_that_could_reach_a_fine_zone_takes_its_cap() {
        let zones = [FineZone {
            lo_m: 1000.0,
            hi_m: 1500.0,
            max_rise_m: 20.0,
        }];
        // Inside, and within reach below and above: the zone's cap.
        assert_eq!(FineZone::limit_rise_m(&zones, 1200.0, 100.0), 20.0);
        assert_eq!(FineZone::limit_rise_m(&zones, 950.0, 100.0), 20.0);
        assert_eq!(FineZone::limit_rise_m(&zones, 1550.0, 100.0), 20.0);
        // Out of reach: the caller's limit; a smaller limit than the zone's is kept.
        assert_eq!(FineZone::limit_rise_m(&zones, 800.0, 100.0), 100.0);
        assert_eq!(FineZone::limit_rise_m(&zones, 1200.0, 5.0), 5.0);
        let lowered = zones[0].lowered(300.0);
        assert_eq!(
            (lowered.lo_m, lowered.hi_m, lowered.max_rise_m),
            (700.0, 1200.0, 20.0)
        );
    }
}
