//! Small analytic air columns: a constant lapse rate (isothermal as a special case), the U.S.
//! Standard Atmosphere 1976, and a smooth sharp inversion. All are exactly hydrostatic where
//! stated and give exact height derivatives, so they serve as test oracles for the refractivity
//! stage and as simple inputs for other stages' tests.
//!
//! In: a few parameters. Out: an [`AirColumn`].

use crate::profile::{AirColumn, AirSample, us1976::us1976};
use crate::units::{DRY_AIR_GAS_CONSTANT_J_KG_K, STANDARD_GRAVITY_M_S2};

const G_OVER_R: f64 = STANDARD_GRAVITY_M_S2 / DRY_AIR_GAS_CONSTANT_J_KG_K;

/// Hydrostatic column with a constant temperature gradient (0 = isothermal) up to
/// `isothermal_above_agl_m` and isothermal above it (a tropopause, so that a lapse rate does not
/// reach 0 K), with a constant water-vapour partial pressure (capped at half the local pressure
/// high up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LapseRateColumn {
    /// Surface height above mean sea level (m).
    pub surface_height_m: f64,
    /// Temperature at the surface (K).
    pub surface_temperature_k: f64,
    /// Pressure at the surface (Pa).
    pub surface_pressure_pa: f64,
    /// dT/dh (K m⁻¹); negative = cooling with height.
    pub gradient_k_per_m: f64,
    /// Water-vapour partial pressure (Pa), constant with height.
    pub vapour_pressure_pa: f64,
    /// Height above the surface (m) from which the air is isothermal (`f64::INFINITY`: never).
    pub isothermal_above_agl_m: f64,
}

impl AirColumn for LapseRateColumn {
    fn surface_height_m(&self) -> f64 {
        self.surface_height_m
    }

    fn air_at(&self, height_m: f64) -> AirSample {
        let z = height_m - self.surface_height_m;
        let zt = self.isothermal_above_agl_m.max(0.0);
        let t0 = self.surface_temperature_k;
        let gradient = self.gradient_k_per_m;
        let (zl, g) = if z <= zt { (z, gradient) } else { (zt, 0.0) };
        let t = t0 + gradient * zl;
        // P = P0·exp(−(g/R)∫dz/T): ∫dz/T = ln(T/T0)/Γ in the gradient part (z/T0 when
        // isothermal), plus (z − zt)/T above the tropopause.
        // ln_1p, not ln(T/T0): for a tiny gradient T/T0 − 1 is ~1e-9 and ln(T/T0) would lose
        // half its digits, which a finite difference of n over millimetres then shows.
        let lower = if gradient.abs() < 1e-12 {
            zl / t0
        } else {
            (gradient * zl / t0).ln_1p() / gradient
        };
        let integral = lower + (z - zl) / t;
        let p = self.surface_pressure_pa * (-G_OVER_R * integral).exp();
        let e = self.vapour_pressure_pa.min(0.5 * p);
        let de = if e < self.vapour_pressure_pa {
            -0.5 * G_OVER_R * p / t
        } else {
            0.0
        };
        AirSample {
            temperature_k: t,
            dtemperature_dh_k_per_m: g,
            pressure_pa: p,
            dpressure_dh_pa_per_m: -G_OVER_R * p / t,
            vapour_pressure_pa: e,
            dvapour_pressure_dh_pa_per_m: de,
        }
    }

    /// The start of the isothermal air, where dT/dh jumps.
    fn breaks_m(&self) -> Vec<f64> {
        let top = self.surface_height_m + self.isothermal_above_agl_m.max(0.0);
        if top.is_finite() {
            vec![top]
        } else {
            Vec::new()
        }
    }
}

/// The U.S. Standard Atmosphere 1976 (dry) from a surface height (m above mean sea level).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StandardAtmosphereColumn {
    /// Surface height above mean sea level (m).
    pub surface_height_m: f64,
}

impl AirColumn for StandardAtmosphereColumn {
    fn surface_height_m(&self) -> f64 {
        self.surface_height_m
    }

    fn air_at(&self, height_m: f64) -> AirSample {
        let s = us1976(height_m);
        AirSample {
            temperature_k: s.temperature_k,
            dtemperature_dh_k_per_m: s.dtemperature_dh_k_per_m,
            pressure_pa: s.pressure_pa,
            // Hydrostatic in geometric height with standard gravity scaled like the geopotential.
            dpressure_dh_pa_per_m: -STANDARD_GRAVITY_M_S2 * s.pressure_pa
                / (DRY_AIR_GAS_CONSTANT_J_KG_K * s.temperature_k)
                * geopotential_factor(height_m),
            vapour_pressure_pa: 0.0,
            dvapour_pressure_dh_pa_per_m: 0.0,
        }
    }

    /// The US1976 layer bases (dT/dh jumps there).
    fn breaks_m(&self) -> Vec<f64> {
        crate::profile::us1976::layer_bases_geometric_m()
            .filter(|&h| h > self.surface_height_m)
            .collect()
    }
}

/// dH/dz of the US1976 geopotential height H = R·z/(R + z).
fn geopotential_factor(height_m: f64) -> f64 {
    let r = crate::profile::us1976::US1976_EARTH_RADIUS_M;
    (r / (r + height_m)).powi(2)
}

/// A smooth, exactly hydrostatic, sharp inversion: the inverse temperature 1/T steps from
/// 1/T_below to 1/T_above along a tanh of half-width `half_width_m` centred at `centre_agl_m`
/// (the bulk of the step, 96 %, lies within ±2 half-widths), isothermal outside it; the pressure
/// is the closed-form hydrostatic integral. Water vapour decays exponentially with a 2 km scale.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SmoothInversionColumn {
    /// Surface height above mean sea level (m).
    pub surface_height_m: f64,
    /// Surface pressure (Pa).
    pub surface_pressure_pa: f64,
    /// Temperature below the inversion (K).
    pub temperature_below_k: f64,
    /// Temperature above the inversion (K).
    pub temperature_above_k: f64,
    /// Height of the middle of the inversion above the surface (m).
    pub centre_agl_m: f64,
    /// Half-width w of the tanh (m); a "15 m inversion" has w = 3.75 m.
    pub half_width_m: f64,
    /// Water-vapour partial pressure at the surface (Pa).
    pub surface_vapour_pressure_pa: f64,
}

/// ln cosh(x), without overflow.
fn ln_cosh(x: f64) -> f64 {
    let a = x.abs();
    a + (-2.0 * a).exp().ln_1p() - std::f64::consts::LN_2
}

impl AirColumn for SmoothInversionColumn {
    fn surface_height_m(&self) -> f64 {
        self.surface_height_m
    }

    fn air_at(&self, height_m: f64) -> AirSample {
        let z = height_m - self.surface_height_m;
        let w = self.half_width_m;
        let u0 = 1.0 / self.temperature_below_k;
        let du = 1.0 / self.temperature_above_k - u0;
        let x = (z - self.centre_agl_m) / w;
        let x0 = -self.centre_agl_m / w;
        let th = x.tanh();
        let s = 0.5 * (1.0 + th);
        let ds = 0.5 * (1.0 - th * th) / w;
        let u = u0 + du * s;
        // ∫₀^z s dz' = (z + w·(ln cosh x − ln cosh x0)) / 2.
        let integral = u0 * z + du * 0.5 * (z + w * (ln_cosh(x) - ln_cosh(x0)));
        let p = self.surface_pressure_pa * (-G_OVER_R * integral).exp();
        let e = self.surface_vapour_pressure_pa * (-z / 2000.0).exp();
        AirSample {
            temperature_k: 1.0 / u,
            dtemperature_dh_k_per_m: -du * ds / (u * u),
            pressure_pa: p,
            dpressure_dh_pa_per_m: -G_OVER_R * p * u,
            vapour_pressure_pa: e,
            dvapour_pressure_dh_pa_per_m: -e / 2000.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check_derivatives(column: &dyn AirColumn, heights: &[f64]) {
        for &h in heights {
            let d = 1e-3;
            let a = column.air_at(h - d);
            let b = column.air_at(h + d);
            let s = column.air_at(h);
            let fd_t = (b.temperature_k - a.temperature_k) / (2.0 * d);
            let fd_p = (b.pressure_pa - a.pressure_pa) / (2.0 * d);
            let fd_e = (b.vapour_pressure_pa - a.vapour_pressure_pa) / (2.0 * d);
            assert!((fd_t - s.dtemperature_dh_k_per_m).abs() < 1e-6, "T' at {h}");
            assert!((fd_p - s.dpressure_dh_pa_per_m).abs() < 1e-5, "P' at {h}");
            assert!(
                (fd_e - s.dvapour_pressure_dh_pa_per_m).abs() < 1e-7,
                "e' at {h}"
            );
        }
    }

    #[test]
    fn columns_are_self_consistent_and_hydrostatic() {
        let lapse = LapseRateColumn {
            surface_height_m: 10.0,
            surface_temperature_k: 280.0,
            surface_pressure_pa: 100_000.0,
            gradient_k_per_m: -0.0065,
            vapour_pressure_pa: 500.0,
            isothermal_above_agl_m: 2_000.0,
        };
        check_derivatives(&lapse, &[10.5, 100.0, 3000.0]);
        let inversion = SmoothInversionColumn {
            surface_height_m: 0.0,
            surface_pressure_pa: 101_325.0,
            temperature_below_k: 263.15,
            temperature_above_k: 273.15,
            centre_agl_m: 30.0,
            half_width_m: 3.75,
            surface_vapour_pressure_pa: 150.0,
        };
        check_derivatives(&inversion, &[1.0, 25.0, 30.0, 33.0, 500.0]);
        let a = inversion.air_at(0.0);
        assert!((a.pressure_pa - 101_325.0).abs() < 1e-9);
        assert!((a.temperature_k - 263.15).abs() < 0.01);
        assert!((inversion.air_at(60.0).temperature_k - 273.15).abs() < 0.01);
        let std = StandardAtmosphereColumn {
            surface_height_m: 0.0,
        };
        check_derivatives(&std, &[0.5, 1000.0, 15_000.0]);
    }
}
