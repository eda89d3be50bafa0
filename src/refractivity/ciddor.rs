//! The refractive index of moist air by Ciddor (1996), "Refractive index of air: new equations
//! for the visible and near infrared", Appl. Opt. 35, 1566–1573.
//!
//! In: vacuum wavelength, CO₂ content, and the air state (T, P, water-vapour partial pressure e),
//! either as plain numbers or as [`Dual`] numbers carrying d/dh. Out: the phase refractivity n − 1
//! (and with duals its height derivative, by the chain rule).
//!
//! The formula (written from the paper's equations; no code copied):
//! * dry-air dispersion at 15 °C, 101 325 Pa, 450 ppm CO₂:
//!   `(n_as − 1)·10⁸ = k1/(k0 − σ²) + k3/(k2 − σ²)`, σ = 1/λ in µm⁻¹, corrected for CO₂ by the
//!   factor `1 + 0.534·10⁻⁶ (x_c − 450)`;
//! * water vapour at 20 °C, 1333 Pa: `(n_ws − 1)·10⁸ = 1.022 (w0 + w1σ² + w2σ⁴ + w3σ⁶)`;
//! * each scaled by its density relative to the reference density, with the compressibility Z of
//!   moist air in the BIPM 1981/91 form Ciddor uses:
//!   `Z = 1 − (p/T)[a0 + a1 t + a2 t² + (b0 + b1 t) x_w + (c0 + c1 t) x_w²] + (p/T)² (d + e x_w²)`.
//!
//! The molar masses and the gas constant cancel in the density ratios, so the moist-air result is
//! `n − 1 = [(p − e)·D + e·W] / (Z·T)` with `D = (n_axs − 1)·Z_a·T₀/p₀` and
//! `W = (n_ws − 1)·Z_w·T_w/p_w` fixed per wavelength and CO₂ content.

use super::dual::Dual;
use crate::units::ZERO_CELSIUS_K;

// Dry-air dispersion (Ciddor 1996, eq. 1), σ² in µm⁻².
const K0: f64 = 238.0185;
const K1: f64 = 5_792_105.0;
const K2: f64 = 57.362;
const K3: f64 = 167_917.0;
// Water-vapour dispersion (eq. 3) and its correction factor.
const W0: f64 = 295.235;
const W1: f64 = 2.6422;
const W2: f64 = -0.032_380;
const W3: f64 = 0.004_028;
const CF: f64 = 1.022;
// Compressibility (BIPM 1981/91 as quoted by Ciddor, appendix A).
const A0: f64 = 1.581_23e-6;
const A1: f64 = -2.9331e-8;
const A2: f64 = 1.1043e-10;
const B0: f64 = 5.707e-6;
const B1: f64 = -2.051e-8;
const C0: f64 = 1.9898e-4;
const C1: f64 = -2.376e-6;
const D: f64 = 1.83e-11;
const E: f64 = -0.765e-8;
// Reference conditions of the two dispersion formulas.
const DRY_REF_PRESSURE_PA: f64 = 101_325.0;
const DRY_REF_TEMPERATURE_K: f64 = 288.15;
const WET_REF_PRESSURE_PA: f64 = 1_333.0;
const WET_REF_TEMPERATURE_K: f64 = 293.15;

/// Default CO₂ content (ppm), the value Ciddor's standard dry air is defined with.
pub const DEFAULT_CO2_PPM: f64 = 450.0;

/// Compressibility of moist air at pressure `p` (Pa), temperature `t_k` (K) and water-vapour mole
/// fraction `x_w`, generic over plain numbers and duals.
fn compressibility(p: Dual, t_k: Dual, x_w: Dual) -> Dual {
    let t_c = t_k - ZERO_CELSIUS_K;
    let p_over_t = p / t_k;
    let bracket =
        A0 + A1 * t_c + A2 * t_c.square() + (B0 + B1 * t_c) * x_w + (C0 + C1 * t_c) * x_w.square();
    1.0 - p_over_t * bracket + p_over_t.square() * (D + E * x_w.square())
}

/// Everything of the Ciddor formula that depends only on wavelength and CO₂: evaluate it once,
/// then call [`CiddorDispersion::refractivity`] per air state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CiddorDispersion {
    /// Vacuum wavelength (m).
    pub wavelength_m: f64,
    /// CO₂ content (ppm by mole).
    pub co2_ppm: f64,
    /// Dry-air coefficient D (K Pa⁻¹): n − 1 contributed per unit p_dry/(Z·T).
    dry_coefficient: f64,
    /// Water-vapour coefficient W (K Pa⁻¹).
    wet_coefficient: f64,
}

impl CiddorDispersion {
    /// Precompute the dispersion terms for a vacuum wavelength (m) and CO₂ content (ppm).
    pub fn new(wavelength_m: f64, co2_ppm: f64) -> Self {
        let sigma2 = (1e-6 / wavelength_m).powi(2);
        let n_as = 1e-8 * (K1 / (K0 - sigma2) + K3 / (K2 - sigma2));
        let n_axs = n_as * (1.0 + 0.534e-6 * (co2_ppm - 450.0));
        let n_ws = 1e-8 * CF * (W0 + sigma2 * (W1 + sigma2 * (W2 + sigma2 * W3)));
        let z_a = compressibility(
            DRY_REF_PRESSURE_PA.into(),
            DRY_REF_TEMPERATURE_K.into(),
            0.0.into(),
        )
        .value;
        let z_w = compressibility(
            WET_REF_PRESSURE_PA.into(),
            WET_REF_TEMPERATURE_K.into(),
            1.0.into(),
        )
        .value;
        Self {
            wavelength_m,
            co2_ppm,
            dry_coefficient: n_axs * z_a * DRY_REF_TEMPERATURE_K / DRY_REF_PRESSURE_PA,
            wet_coefficient: n_ws * z_w * WET_REF_TEMPERATURE_K / WET_REF_PRESSURE_PA,
        }
    }

    /// Phase refractivity n − 1 of moist air with temperature (K), total pressure (Pa) and
    /// water-vapour partial pressure (Pa), each a dual carrying its height derivative; the result's
    /// derivative is d(n − 1)/dh = dn/dh.
    #[inline]
    pub fn refractivity(
        &self,
        temperature_k: Dual,
        pressure_pa: Dual,
        vapour_pressure_pa: Dual,
    ) -> Dual {
        let x_w = vapour_pressure_pa / pressure_pa;
        let z = compressibility(pressure_pa, temperature_k, x_w);
        ((pressure_pa - vapour_pressure_pa) * self.dry_coefficient
            + vapour_pressure_pa * self.wet_coefficient)
            / (z * temperature_k)
    }

    /// n − 1 for plain numbers (no derivative).
    #[inline]
    pub fn refractivity_value(
        &self,
        temperature_k: f64,
        pressure_pa: f64,
        vapour_pressure_pa: f64,
    ) -> f64 {
        self.refractivity(
            temperature_k.into(),
            pressure_pa.into(),
            vapour_pressure_pa.into(),
        )
        .value
    }
}

/// Phase refractive index n of moist air by Ciddor (1996).
///
/// `wavelength_m` is the vacuum wavelength (the formula is fitted for 0.3–1.7 µm; outside that it
/// is evaluated anyway and is an extrapolation), `temperature_k` the air temperature,
/// `pressure_pa` the total pressure, `vapour_pressure_pa` the water-vapour partial pressure (0 for
/// dry air; mole fraction x_w = e/p) and `co2_ppm` the CO₂ content (450 is Ciddor's standard).
/// Non-physical inputs (p ≤ 0, T ≤ 0) give non-finite or meaningless results; the validated entry
/// point is [`RefractiveAtmosphere`](super::RefractiveAtmosphere).
pub fn ciddor_refractive_index(
    wavelength_m: f64,
    temperature_k: f64,
    pressure_pa: f64,
    vapour_pressure_pa: f64,
    co2_ppm: f64,
) -> f64 {
    1.0 + CiddorDispersion::new(wavelength_m, co2_ppm).refractivity_value(
        temperature_k,
        pressure_pa,
        vapour_pressure_pa,
    )
}

/// Saturation vapour pressure over liquid water (Pa) by the IAPWS-IF97 formula, as given in the
/// appendix of the NIST "Refractive index of air" calculator documentation (the formula Ciddor's
/// humidity inputs are usually converted with). Valid above 0 °C.
pub fn saturation_vapour_pressure_iapws_pa(temperature_k: f64) -> f64 {
    const N: [f64; 10] = [
        1.167_052_145_28e3,
        -7.242_131_670_32e5,
        -1.707_384_694_01e1,
        1.202_082_470_25e4,
        -3.232_555_032_23e6,
        1.491_510_861_35e1,
        -4.823_265_736_16e3,
        4.051_134_054_21e5,
        -2.385_555_756_78e-1,
        6.501_753_484_48e2,
    ];
    let omega = temperature_k + N[8] / (temperature_k - N[9]);
    let a = omega * omega + N[0] * omega + N[1];
    let b = N[2] * omega * omega + N[3] * omega + N[4];
    let c = N[5] * omega * omega + N[6] * omega + N[7];
    let x = -b + (b * b - 4.0 * a * c).sqrt();
    1e6 * (2.0 * c / x).powi(4)
}

/// Water-vapour partial pressure (Pa) of air at `temperature_k` and `pressure_pa` with relative
/// humidity `relative_humidity_percent` (over water), including the enhancement factor
/// f = 1.00062 + 3.14·10⁻⁸ p + 5.6·10⁻⁷ t² (t in °C) of the NIST documentation: e = f·RH·e_sat.
pub fn vapour_pressure_from_relative_humidity_pa(
    temperature_k: f64,
    pressure_pa: f64,
    relative_humidity_percent: f64,
) -> f64 {
    let t_c = temperature_k - ZERO_CELSIUS_K;
    let enhancement = 1.000_62 + 3.14e-8 * pressure_pa + 5.6e-7 * t_c * t_c;
    enhancement * relative_humidity_percent / 100.0
        * saturation_vapour_pressure_iapws_pa(temperature_k)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn moist(rh: f64, t_c: f64) -> f64 {
        let t = t_c + ZERO_CELSIUS_K;
        let e = vapour_pressure_from_relative_humidity_pa(t, 101_325.0, rh);
        ciddor_refractive_index(633e-9, t, 101_325.0, e, 450.0)
    }

    /// Check values of the `ref_index` package (NIST Stone & Zimmerman), docs/references.md §2.6.
    #[test]
    fn matches_nist_ref_index_moist_air_values() {
        // README's accuracy table quotes the first point at its bound, 1e-11.
        for (rh, t_c, expected, bound) in [
            (20.0, 20.0, 1.000_271_628_534_057_8, 1e-11),
            (80.0, 20.0, 1.000_271_118_347_262_6, 1e-9),
            (80.0, 60.0, 1.000_234_024_175_405_5, 1e-9),
        ] {
            let n = moist(rh, t_c);
            eprintln!("RH {rh} t {t_c}: n − reference {:+.1e}", n - expected);
            assert!(
                (n - expected).abs() < bound,
                "RH {rh} t {t_c}: {n} vs {expected}"
            );
        }
    }

    /// Dry air at 15 °C, 101 325 Pa, 450 ppm: the Ciddor column of docs/references.md §2.6.
    #[test]
    fn matches_dry_air_dispersion_table() {
        for (lambda_um, expected) in [
            (0.45, 280.533e-6),
            (0.55, 277.838e-6),
            (0.6328, 276.533e-6),
            (0.70, 275.804e-6),
        ] {
            let n = ciddor_refractive_index(lambda_um * 1e-6, 288.15, 101_325.0, 0.0, 450.0);
            eprintln!("{lambda_um} µm: n − 1 − table {:+.3e}", n - 1.0 - expected);
            // The table gives 6 significant digits: n − 1 must round to it (±0.5e-9), as README's
            // accuracy table says.
            assert!(
                (n - 1.0 - expected).abs() < 5e-10,
                "{lambda_um} µm: {}",
                n - 1.0
            );
        }
    }

    #[test]
    fn co2_raises_the_index_by_the_published_factor() {
        let a = ciddor_refractive_index(550e-9, 288.15, 101_325.0, 0.0, 450.0) - 1.0;
        let b = ciddor_refractive_index(550e-9, 288.15, 101_325.0, 0.0, 1450.0) - 1.0;
        assert!(((b / a - 1.0) - 0.534e-3).abs() < 1e-12);
    }

    #[test]
    fn iapws_saturation_pressure_matches_steam_tables() {
        // IAPWS-IF97 saturation pressure: 20 °C 2339.2 Pa, 60 °C 19946 Pa, 100 °C 101418 Pa.
        for (t_c, p) in [(20.0, 2339.2), (60.0, 19_946.0), (100.0, 101_418.0)] {
            let e = saturation_vapour_pressure_iapws_pa(t_c + ZERO_CELSIUS_K);
            assert!((e / p - 1.0).abs() < 2e-4, "{t_c}: {e}");
        }
    }

    #[test]
    fn compressibility_of_standard_dry_air() {
        // Z of dry air at 15 °C, 101 325 Pa ≈ 0.99959 (BIPM; Ciddor's Za = 0.9995922).
        let z = compressibility(101_325.0.into(), 288.15.into(), 0.0.into()).value;
        assert!((z - 0.999_592_2).abs() < 1e-7, "{z}");
    }
}
