//! Stage 2 — fit. In: a [`Sounding`] (levels sorted by height, SI). Out: a [`Profile`], an
//! [`AirColumn`] with smooth, monotone-safe T(h), P(h), e(h) and their analytic derivatives from
//! the surface to 86 km.
//!
//! * **Smoothing** (dense soundings only): every quantity is first passed through a tricube
//!   local-linear regression of half-width [`FitOptions::smooth_m`] (see `smooth.rs` for why).
//!   Levels with no neighbour within `smooth_m` keep their measured values exactly.
//! * **Temperature** ([`FitOptions::temperature_fit`], see `temperature.rs`): PCHIP
//!   (Fritsch–Butland) through the (smoothed) levels — C¹, no extremum between levels, so the fit
//!   never invents an inversion — or linear in ln p between levels (C⁰, what significant levels
//!   are chosen for); by default linear for significant-level soundings and PCHIP for dense
//!   ascents. dT/dh is the analytic derivative of the same piece. The hydrostatic fill below
//!   integrates through the linear fit taken linear in height (P is not known yet); the two
//!   differ by far less than the 1 K significant levels promise.
//! * **Pressure**: PCHIP of ln P through one knot per level, ln P = H + R: H is the hydrostatic
//!   d(ln P)/dh = −g₀/(R_d·T_v) integrated through the fitted T and e (virtual temperature), R the
//!   residual to the measured pressures — smoothed where levels are dense (over 5·smooth_m,
//!   widened as 1/P, where ≥ 10 levels fall in it, since pressure is reported at a fixed
//!   0.1 hPa), linear in height across gaps
//!   without pressure, constant beyond the measured range. Sparse measured pressures are met
//!   exactly; where no level has a pressure the integration starts from
//!   [`FitOptions::surface_pressure_pa`] or the US1976 pressure at the surface height. Measured
//!   pressures that do not decrease with height are treated as missing. dP/dh = P·d(ln P)/dh
//!   from the same cubic, so P and dP/dh are consistent (and close to hydrostatic).
//! * **Vapour pressure**: PCHIP of e through the levels that have humidity (non-negative, since
//!   PCHIP never leaves the range of its knots); below the lowest of them the mixing ratio e/P is
//!   held; above the highest, e/P relaxes from the measured ratio with a C¹ join (see
//!   [`Profile`]). A sounding without humidity is dry (e = 0).
//! * **Above the sounding top**: T(h) = T₇₆(h) + δ·e^(−x/τ) + (σ + δ/τ)·x·e^(−x/τₛ), x = h − top,
//!   where δ and σ are the temperature and gradient differences to US1976 at the top,
//!   τ = [`FitOptions::blend_scale_m`] and τₛ = τ/10 (shortened when needed so that the slope-
//!   matching bump stays within 5 K). Value and slope are continuous at the top and T relaxes to
//!   the standard over a few τ. P above the top is hydrostatic from the top pressure through this
//!   T, plus a term c·x·e^(−x/τₛ) in ln P that matches the fitted slope at the top (C¹).
//! * **Below the surface** (the lowest level) nothing is extrapolated: the surface air is
//!   returned; heights below the surface are a caller error. Above 86 km the 86 km air is returned.

use std::path::PathBuf;

use super::hydrostatic::{
    G_OVER_R, HydrostaticTable, grid_with_nodes, integrate_ln_p, virtual_temperature_k,
};
use super::monotone::MonotoneCubic;
use super::smooth::{local_linear, local_linear_varying};
use super::standard::StandardAtmosphere;
use super::temperature::{FitChoice, TemperatureCurve, TemperatureFit, choose_fit};
use super::us1976::{us1976, us1976_temperature};
use super::{AirColumn, AirSample, FineZone, MODEL_TOP_M, ProfileError};
use crate::sounding::Sounding;

/// Options of [`Profile::from_sounding`].
#[derive(Debug, Clone, PartialEq)]
pub struct FitOptions {
    /// Smoothing scale (m): the half-width of the tricube local-linear smoother applied to T
    /// and e before fitting (and, 5× wider and widening as 1/P where levels are dense, to the
    /// pressure's departure from hydrostatic); 0 disables smoothing. Default **20 m**: at the
    /// 4–11 m spacing of 1-second soundings it averages 4–9 levels (0.1 K white noise →
    /// ≈0.04 K), while a 15 m, +3 K layer keeps its temperature change to within 10 % (it
    /// widens to ≈35 m), and T and e of sparse soundings (levels ≥ 20 m apart) are not touched
    /// at all. Chosen on the three 1-second test soundings: 10 m still leaves 125 noise
    /// warmings in Ny-Ålesund's lowest 5 km (877 unsmoothed), 20 m leaves 16; 30 m starts to
    /// shave the Bjørnøya layer (base 74 m instead of 86 m).
    pub smooth_m: f64,
    /// e-folding height (m) over which the temperature offset to US1976 found at the sounding top
    /// decays above it. Default 2000 m.
    pub blend_scale_m: f64,
    /// Surface pressure (Pa) to start the hydrostatic integration from when no level has a
    /// pressure; `None` takes the US1976 pressure at the surface height.
    pub surface_pressure_pa: Option<f64>,
    /// How temperature is interpolated between levels. Default [`TemperatureFit::Auto`]:
    /// linear in ln p for significant-level soundings, PCHIP for dense ascents (see
    /// [`choose_fit`](super::choose_fit) for the criterion and its reason).
    pub temperature_fit: TemperatureFit,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            smooth_m: 20.0,
            blend_scale_m: 2000.0,
            surface_pressure_pa: None,
            temperature_fit: TemperatureFit::Auto,
        }
    }
}

/// One knot of the fit (one sounding level after smoothing), for plotting and inspection.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ProfileKnot {
    /// Height above mean sea level (m).
    pub height_m: f64,
    /// Fitted (smoothed) temperature (K).
    pub temperature_k: f64,
    /// Fitted pressure (Pa).
    pub pressure_pa: f64,
    /// Whether the pressure knot came from a measured pressure (else hydrostatic).
    pub pressure_measured: bool,
    /// Fitted vapour pressure (Pa); 0 for a dry sounding.
    pub vapour_pressure_pa: f64,
}

/// A single point or a cubic: the fitted curve of one quantity.
#[derive(Debug, Clone)]
enum Curve {
    /// One knot: the value and a slope to report there.
    Point {
        value: f64,
        slope: f64,
    },
    Cubic(MonotoneCubic),
}

impl Curve {
    fn new(x: &[f64], y: &[f64], single_slope: f64) -> Curve {
        if x.len() >= 2 {
            Curve::Cubic(MonotoneCubic::new(x, y))
        } else {
            Curve::Point {
                value: y[0],
                slope: single_slope,
            }
        }
    }

    fn value_slope(&self, h: f64) -> (f64, f64) {
        match self {
            Curve::Point { value, slope } => (*value, *slope),
            Curve::Cubic(c) => c.value_slope(h),
        }
    }
}

/// e-folding height (m) of the vapour join above the highest humidity level.
const VAPOUR_JOIN_M: f64 = 100.0;

/// The vapour-pressure fit: a curve inside the humidity data, mixing-ratio rules outside.
#[derive(Debug, Clone)]
struct VapourFit {
    curve: Curve,
    lo_m: f64,
    hi_m: f64,
    /// e/P at the lowest humidity level.
    ratio_lo: f64,
    /// e/P at the highest humidity level.
    ratio_hi: f64,
    /// d ln(e/P)/dh just below the highest humidity level (m⁻¹), limited to ±0.02.
    rate_hi: f64,
}

impl VapourFit {
    /// e and de/dh at `h` given P and d(ln P)/dh there.
    fn at(&self, h: f64, p: f64, dlnp: f64) -> (f64, f64) {
        if h < self.lo_m {
            (self.ratio_lo * p, self.ratio_lo * p * dlnp)
        } else if h <= self.hi_m {
            let (e, de) = self.curve.value_slope(h);
            (e.max(0.0), de)
        } else {
            let ratio = self.ratio_above(h);
            let x = h - self.hi_m;
            let decay = (-x / VAPOUR_JOIN_M).exp();
            let e = ratio * p;
            (
                e,
                e * (dlnp + self.rate_hi * (1.0 - x / VAPOUR_JOIN_M) * decay),
            )
        }
    }

    /// e/P above the highest humidity level: ratio_hi·exp(rate·x·e^(−x/τ)) (C¹ at the join).
    fn ratio_above(&self, h: f64) -> f64 {
        let x = h - self.hi_m;
        self.ratio_hi * (self.rate_hi * x * (-x / VAPOUR_JOIN_M).exp()).exp()
    }
}

/// Temperature above the top of the data (see the module doc).
#[derive(Debug, Clone)]
struct TemperatureBlend {
    top_m: f64,
    /// T offset to US1976 at the top (K).
    delta_k: f64,
    /// σ + δ/τ (K m⁻¹): amplitude of the slope-matching term.
    slope_term: f64,
    tau_m: f64,
    tau_s_m: f64,
}

impl TemperatureBlend {
    /// Where the blend's terms vary faster than the standard atmosphere: over six of each decay
    /// length above the top (e⁻⁶ of a term left), steps no taller than half of it. The
    /// slope-matching bump (τₛ, a few hundred metres) sits above the top with no break to end
    /// steps on, and a step several τₛ long across it misleads the integrator's error estimate
    /// (a 50° ray from 2 km through a 20 km top came out 1.6e-4 m off at 1 mm, 3e-6 m with
    /// these steps).
    fn fine_zones_m(&self) -> [FineZone; 2] {
        [self.tau_s_m, self.tau_m].map(|scale_m| FineZone {
            lo_m: self.top_m,
            hi_m: self.top_m + 6.0 * scale_m,
            max_rise_m: 0.5 * scale_m,
        })
    }

    fn at(&self, h: f64) -> (f64, f64) {
        let x = (h - self.top_m).max(0.0);
        let (std_t, std_dt) = us1976_temperature(h);
        let e1 = (-x / self.tau_m).exp();
        let e2 = (-x / self.tau_s_m).exp();
        let t = std_t + self.delta_k * e1 + self.slope_term * x * e2;
        let dt = std_dt - self.delta_k / self.tau_m * e1
            + self.slope_term * (1.0 - x / self.tau_s_m) * e2;
        (t, dt)
    }
}

/// Temperature and ln P above the top of the data.
#[derive(Debug, Clone)]
struct AboveTop {
    temperature: TemperatureBlend,
    /// ln P slope mismatch at the top (m⁻¹), relaxed over τₛ.
    lnp_slope_term: f64,
    /// Hydrostatic ln P from the top through the blended temperature.
    table: HydrostaticTable,
}

impl AboveTop {
    fn ln_pressure(&self, h: f64) -> (f64, f64) {
        let t = &self.temperature;
        let x = (h - t.top_m).max(0.0);
        let e2 = (-x / t.tau_s_m).exp();
        let (lnp, s) = self.table.ln_p_and_slope(h);
        (
            lnp + self.lnp_slope_term * x * e2,
            s + self.lnp_slope_term * (1.0 - x / t.tau_s_m) * e2,
        )
    }
}

/// A sounding fitted into a smooth column of air (see the module doc for the method).
#[derive(Debug, Clone)]
pub struct Profile {
    source: PathBuf,
    surface_height_m: f64,
    top_m: f64,
    knots: Vec<ProfileKnot>,
    fit: FitChoice,
    temperature: TemperatureCurve,
    ln_pressure: Curve,
    vapour: Option<VapourFit>,
    above: AboveTop,
}

/// Plausible range of sounding temperatures (K).
const TEMPERATURE_RANGE_K: (f64, f64) = (150.0, 350.0);

impl Profile {
    /// Fit a sounding. Fails (never panics) on an empty sounding, non-finite or unsorted heights,
    /// temperatures outside 150…350 K, non-positive or non-finite pressures, negative or
    /// non-finite vapour pressures, and on invalid options.
    pub fn from_sounding(
        sounding: &Sounding,
        options: &FitOptions,
    ) -> Result<Profile, ProfileError> {
        check_options(options)?;
        let path = sounding.source.clone();
        let levels = &sounding.levels;
        let bad = |line: usize, message: String| ProfileError::BadSounding {
            path: path.clone(),
            line,
            message,
        };
        if levels.is_empty() {
            return Err(bad(0, "the sounding has no levels".into()));
        }
        for (i, level) in levels.iter().enumerate() {
            if !level.height_m.is_finite() || level.height_m.abs() > 100_000.0 {
                return Err(bad(
                    level.line,
                    format!("height {} m is not usable", level.height_m),
                ));
            }
            if i > 0 && level.height_m <= levels[i - 1].height_m {
                return Err(bad(
                    level.line,
                    format!(
                        "height {} m does not increase (previous level {} m)",
                        level.height_m,
                        levels[i - 1].height_m
                    ),
                ));
            }
            let t = level.temperature_k;
            if !(TEMPERATURE_RANGE_K.0..=TEMPERATURE_RANGE_K.1).contains(&t) {
                return Err(bad(
                    level.line,
                    format!("temperature {t} K is outside 150…350 K"),
                ));
            }
            if let Some(p) = level.pressure_pa
                && !(p.is_finite() && p > 0.0 && p < 200_000.0)
            {
                return Err(bad(level.line, format!("pressure {p} Pa is not usable")));
            }
            if let Some(e) = level.vapour_pressure_pa
                && !(0.0..20_000.0).contains(&e)
            {
                return Err(bad(
                    level.line,
                    format!("vapour pressure {e} Pa is not usable"),
                ));
            }
        }
        if levels.last().map_or(0.0, |l| l.height_m) >= MODEL_TOP_M {
            return Err(bad(0, "the sounding reaches above 86 km".into()));
        }

        let smooth = options.smooth_m;
        let heights: Vec<f64> = levels.iter().map(|l| l.height_m).collect();
        let surface_height_m = heights[0];
        let top_m = heights[heights.len() - 1];

        // Temperature (gaps linear in ln p get their ln P once the pressure is fitted).
        let fit = choose_fit(options.temperature_fit, &heights);
        let raw_t: Vec<f64> = levels.iter().map(|l| l.temperature_k).collect();
        let t_knots = local_linear(&heights, &raw_t, smooth);
        let mut temperature = TemperatureCurve::new(
            &heights,
            &t_knots,
            fit.used,
            us1976(top_m).dtemperature_dh_k_per_m,
        );

        // Vapour pressure (values only; its outside rules need P, set below).
        let e_levels: Vec<(f64, f64)> = levels
            .iter()
            .filter_map(|l| l.vapour_pressure_pa.map(|e| (l.height_m, e)))
            .collect();
        let e_curve = if e_levels.is_empty() {
            None
        } else {
            let xe: Vec<f64> = e_levels.iter().map(|p| p.0).collect();
            let ye: Vec<f64> = e_levels.iter().map(|p| p.1).collect();
            let se = local_linear(&xe, &ye, smooth);
            Some((Curve::new(&xe, &se, 0.0), xe[0], xe[xe.len() - 1]))
        };
        // Provisional vapour model for the hydrostatic fill: e/P held constant outside the
        // humidity levels (refined after P is known). Only T_v depends on it (a ≤0.6 % effect).
        let provisional = e_curve.as_ref().map(|(curve, lo, hi)| {
            let p_guess = |h: f64| us1976(h).pressure_pa;
            let (e_lo, _) = curve.value_slope(*lo);
            let (e_hi, _) = curve.value_slope(*hi);
            VapourFit {
                curve: curve.clone(),
                lo_m: *lo,
                hi_m: *hi,
                ratio_lo: e_lo / p_guess(*lo),
                ratio_hi: e_hi / p_guess(*hi),
                rate_hi: 0.0,
            }
        });
        let t_of = |h: f64| temperature.at(h, None).0;
        let tv_provisional = |h: f64, p: f64| {
            let e = provisional.as_ref().map_or(0.0, |v| v.at(h, p, 0.0).0);
            virtual_temperature_k(t_of(h), e, p)
        };

        // Pressure knots: ln P = hydrostatic ln P through the fitted T_v + a residual R(h) that
        // carries the measurements (see `pressure_knots`).
        let n = heights.len();
        let (ln_p, is_measured) =
            pressure_knots(levels, &heights, options, surface_height_m, &tv_provisional);
        let single_lnp_slope = -G_OVER_R / tv_provisional(top_m, ln_p[n - 1].exp());
        let ln_pressure = Curve::new(&heights, &ln_p, single_lnp_slope);
        if ln_p.iter().any(|v| !v.is_finite()) {
            return Err(bad(0, "the pressure fit is not finite".into()));
        }
        temperature.set_ln_pressure((0..n).map(|i| is_measured[i].then_some(ln_p[i])).collect());

        // Vapour model with the fitted pressure.
        let lnp_at = |h: f64| ln_pressure.value_slope(h);
        let vapour = e_curve.map(|(curve, lo, hi)| {
            let (e_lo, _) = curve.value_slope(lo);
            let (e_hi, de_hi) = curve.value_slope(hi);
            let (lnp_lo, _) = lnp_at(lo);
            let (lnp_hi, dlnp_hi) = lnp_at(hi);
            let rate_hi = if e_hi > 0.0 {
                (de_hi / e_hi - dlnp_hi).clamp(-0.02, 0.02)
            } else {
                0.0
            };
            VapourFit {
                curve,
                lo_m: lo,
                hi_m: hi,
                ratio_lo: e_lo.max(0.0) / lnp_lo.exp(),
                ratio_hi: e_hi.max(0.0) / lnp_hi.exp(),
                rate_hi,
            }
        });

        // Above the top: blend into US1976.
        let (t_top, dt_top) = temperature.at(top_m, Some(ln_pressure.value_slope(top_m)));
        let std_top = us1976(top_m);
        let delta_k = t_top - std_top.temperature_k;
        let tau_m = options.blend_scale_m;
        let slope_term = dt_top - std_top.dtemperature_dh_k_per_m + delta_k / tau_m;
        // Keep the slope-matching bump |slope_term|·τₛ/e within 5 K.
        let tau_s_m = if slope_term.abs() > 0.0 {
            (tau_m / 10.0).min(5.0 * std::f64::consts::E / slope_term.abs())
        } else {
            tau_m / 10.0
        };
        let (lnp_top, dlnp_top) = ln_pressure.value_slope(top_m);
        let p_top = lnp_top.exp();
        let blend = TemperatureBlend {
            top_m,
            delta_k,
            slope_term,
            tau_m,
            tau_s_m,
        };
        let (blend_above, vapour_above) = (blend.clone(), vapour.clone());
        let tv_above = move |h: f64, p: f64| {
            let t = blend_above.at(h).0;
            let e = vapour_above
                .as_ref()
                .map_or(0.0, |v| v.ratio_above(h.max(v.hi_m)) * p);
            virtual_temperature_k(t, e, p)
        };
        // Lazy: a scene traced to a 40 km top reads little of the column up to 86 km.
        // 10 m nodes through the blend's first 3 km (its bump decays over τₛ ≥ a few hundred
        // metres), 100 m above, the US 1976 layer bases as nodes: n and dn/dh within 1e-14 of
        // a fine integration's (hydrostatic.rs tests).
        let kinks: Vec<f64> = super::us1976::layer_bases_geometric_m().collect();
        let grid = grid_with_nodes(&[(top_m + 3000.0, 10.0), (f64::INFINITY, 100.0)], &kinks);
        let table = HydrostaticTable::lazy(
            top_m,
            p_top,
            MODEL_TOP_M,
            &grid,
            std::sync::Arc::new(tv_above),
        );
        let lnp_slope_term = dlnp_top - table.ln_p_and_slope(top_m).1;
        let above = AboveTop {
            temperature: blend,
            lnp_slope_term,
            table,
        };

        let mut profile = Profile {
            source: path.clone(),
            surface_height_m,
            top_m,
            knots: Vec::new(),
            fit,
            temperature,
            ln_pressure,
            vapour,
            above,
        };
        profile.knots = (0..n)
            .map(|i| {
                let air = profile.air_at(heights[i]);
                ProfileKnot {
                    height_m: heights[i],
                    temperature_k: t_knots[i],
                    pressure_pa: ln_p[i].exp(),
                    pressure_measured: is_measured[i],
                    vapour_pressure_pa: air.vapour_pressure_pa,
                }
            })
            .collect();
        Ok(profile)
    }

    /// Height of the highest level of the sounding (m above mean sea level): the fit is data
    /// below it and the US1976 blend above it.
    pub fn top_of_data_m(&self) -> f64 {
        self.top_m
    }

    /// The knots of the fit (one per sounding level, after smoothing), lowest first.
    pub fn levels(&self) -> &[ProfileKnot] {
        &self.knots
    }

    /// The file the sounding came from.
    pub fn source(&self) -> &std::path::Path {
        &self.source
    }

    /// The temperature fit used, and why.
    pub fn fit_choice(&self) -> &FitChoice {
        &self.fit
    }

    /// Number of gaps between levels (levels − 1).
    pub fn gaps(&self) -> usize {
        self.temperature.gaps()
    }

    /// The same profile with a smooth bump a·sin(πu) added to the temperature in every gap
    /// between two levels, `bumps_k[k]` (K) in gap k (u: the gap's ln p fraction where it is
    /// linear in ln p, else its height fraction), so that T is unchanged at every level. P and e
    /// are not refitted: a departure of a kelvin changes the hydrostatic d ln P/dh by 0.4 %, and
    /// the measured pressures stay met. Fails when `bumps_k` does not hold one finite value per
    /// gap.
    pub fn perturbed(&self, bumps_k: &[f64]) -> Result<Profile, ProfileError> {
        if bumps_k.len() != self.gaps() || bumps_k.iter().any(|a| !a.is_finite()) {
            return Err(ProfileError::BadOption {
                name: "bumps_k",
                message: format!(
                    "{} finite amplitudes needed (one per gap between levels), got {}",
                    self.gaps(),
                    bumps_k.len()
                ),
            });
        }
        Ok(Profile {
            temperature: self.temperature.with_bumps(bumps_k.to_vec()),
            ..self.clone()
        })
    }
}

/// Pressure above which the pressure residual is smoothed with `smooth_m` itself (Pa).
const PRESSURE_WINDOW_REFERENCE_PA: f64 = 100_000.0;

/// How much wider than `smooth_m` the pressure residual is smoothed (at 1000 hPa) where levels
/// are dense. The residual has no fine structure of its own (the layering of P comes through the
/// fitted T in the hydrostatic part), so a wide window costs nothing physical; 5 keeps dP/dh of
/// 1-second soundings within ≈1 % of hydrostatic despite the 0.1 hPa reporting steps.
const PRESSURE_WINDOW_FACTOR: f64 = 5.0;

/// Number of measured levels inside the widened pressure window from which the data count as
/// dense (1-second soundings have hundreds there; significant-level soundings a few).
const DENSE_LEVELS: usize = 10;

/// Integration step limit (m) for the hydrostatic knots. Each integration runs from one level
/// to the next, where T_v is smooth (the fit's kinks are at the levels), so RK4 at 25 m is
/// within 1e-11 of the exact ln P per gap even through a strong inversion (about 1e-8 hPa per
/// gap at the surface, far below the 0.1 hPa a sounding reports; test
/// `hydrostatic_knots_need_no_finer_steps`).
pub(crate) const HYDROSTATIC_STEP_M: f64 = 25.0;

/// ln P at every level, and whether it carries a measured pressure.
///
/// ln P_i = H_i + R_i, where H is d(ln P)/dh = −g₀/(R_d·T_v) integrated level to level through
/// the fitted T and e, and R is the residual ln P_measured − H at the levels with a pressure:
/// smoothed (local-linear, tricube) with a half-width of 5·`smooth_m`·max(1, 1000 hPa / P)
/// where at least ten measured levels fall inside that window (else `smooth_m`), linear in
/// height between measured levels and constant beyond the first and last. So measured
/// pressures are met (exactly where no other measured level is inside the window), gaps are
/// hydrostatic and anchored at both ends, and dP/dh stays close to hydrostatic. The window is
/// wide because the residual has no structure of its own, and widens as 1/P because sondes
/// report P at a fixed absolute resolution (0.1 hPa): at 14 hPa a 0.1 hPa step is 0.7 %, ten
/// times the change of ln P between 1-second levels, and a 20 m window would turn that
/// staircase into ±50 % noise on dP/dh. Measured pressures that would not decrease with height
/// are treated as missing.
fn pressure_knots(
    levels: &[crate::sounding::Level],
    heights: &[f64],
    options: &FitOptions,
    surface_height_m: f64,
    tv: &dyn Fn(f64, f64) -> f64,
) -> (Vec<f64>, Vec<bool>) {
    let n = heights.len();
    let first_measured = levels.iter().position(|l| l.pressure_pa.is_some());
    // Hydrostatic H, anchored at the first measured pressure (or the surface guess).
    let (start, start_ln_p) = match first_measured {
        Some(i) => (i, levels[i].pressure_pa.unwrap_or(1.0).ln()),
        None => {
            let p0 = options.surface_pressure_pa.unwrap_or_else(|| {
                StandardAtmosphere::default()
                    .air_at(surface_height_m)
                    .pressure_pa
            });
            (0, p0.ln())
        }
    };
    let mut hydro = vec![0.0; n];
    hydro[start] = start_ln_p;
    for i in (0..start).rev() {
        hydro[i] = integrate_ln_p(
            heights[i + 1],
            hydro[i + 1],
            heights[i],
            HYDROSTATIC_STEP_M,
            tv,
        );
    }
    for i in start + 1..n {
        hydro[i] = integrate_ln_p(
            heights[i - 1],
            hydro[i - 1],
            heights[i],
            HYDROSTATIC_STEP_M,
            tv,
        );
    }
    let measured: Vec<(usize, f64)> = levels
        .iter()
        .enumerate()
        .filter_map(|(i, l)| l.pressure_pa.map(|p| (i, p)))
        .collect();
    if measured.is_empty() {
        return (hydro, vec![false; n]);
    }
    let mx: Vec<f64> = measured.iter().map(|m| heights[m.0]).collect();
    let residual: Vec<f64> = measured.iter().map(|&(i, p)| p.ln() - hydro[i]).collect();
    // Widen the window as 1/P only where the data are dense enough for the reporting
    // resolution to matter (at least DENSE_LEVELS measured levels inside the widened window);
    // sparse levels keep `smooth_m` and so pass through their measurements.
    let half_width = |k: usize| {
        let wide = options.smooth_m
            * PRESSURE_WINDOW_FACTOR
            * (PRESSURE_WINDOW_REFERENCE_PA / measured[k].1).max(1.0);
        let lo = mx.partition_point(|&h| h <= mx[k] - wide);
        let hi = mx.partition_point(|&h| h < mx[k] + wide);
        if hi - lo >= DENSE_LEVELS {
            wide
        } else {
            options.smooth_m
        }
    };
    let smoothed = local_linear_varying(&mx, &residual, &half_width);
    // Anchors: measured levels whose smoothed ln P keeps decreasing with height.
    let mut anchors: Vec<(usize, f64)> = Vec::with_capacity(measured.len());
    for (k, &(i, _)) in measured.iter().enumerate() {
        let ln_p = hydro[i] + smoothed[k];
        if anchors.last().is_none_or(|&(j, r)| ln_p < hydro[j] + r) {
            anchors.push((i, smoothed[k]));
        }
    }
    let mut ln_p = vec![0.0; n];
    let mut is_measured = vec![false; n];
    let mut next = 0;
    for i in 0..n {
        while next < anchors.len() && anchors[next].0 < i {
            next += 1;
        }
        let r = if next < anchors.len() && anchors[next].0 == i {
            is_measured[i] = true;
            anchors[next].1
        } else if next == 0 {
            anchors[0].1
        } else if next == anchors.len() {
            anchors[anchors.len() - 1].1
        } else {
            let (a, ra) = anchors[next - 1];
            let (b, rb) = anchors[next];
            ra + (rb - ra) * (heights[i] - heights[a]) / (heights[b] - heights[a])
        };
        ln_p[i] = hydro[i] + r;
    }
    (ln_p, is_measured)
}

fn check_options(options: &FitOptions) -> Result<(), ProfileError> {
    if !(options.smooth_m.is_finite() && (0.0..=10_000.0).contains(&options.smooth_m)) {
        return Err(ProfileError::BadOption {
            name: "smooth_m",
            message: format!("{} m is outside 0…10 000 m", options.smooth_m),
        });
    }
    if !(options.blend_scale_m.is_finite() && (10.0..=100_000.0).contains(&options.blend_scale_m)) {
        return Err(ProfileError::BadOption {
            name: "blend_scale_m",
            message: format!("{} m is outside 10…100 000 m", options.blend_scale_m),
        });
    }
    if let Some(p) = options.surface_pressure_pa
        && !(10_000.0..=120_000.0).contains(&p)
    {
        return Err(ProfileError::BadOption {
            name: "surface_pressure_pa",
            message: format!("{p} Pa is outside 10 000…120 000 Pa"),
        });
    }
    Ok(())
}

impl AirColumn for Profile {
    fn surface_height_m(&self) -> f64 {
        self.surface_height_m
    }

    /// The fitted air; below the surface the surface air, above 86 km the 86 km air, and an
    /// all-NaN sample for a NaN height.
    fn air_at(&self, height_m: f64) -> AirSample {
        if height_m.is_nan() {
            return AirSample::nan();
        }
        let h = height_m.clamp(self.surface_height_m, MODEL_TOP_M);
        let ((t, dt), (lnp, dlnp)) = if h <= self.top_m {
            let ln_p = self.ln_pressure.value_slope(h);
            (self.temperature.at(h, Some(ln_p)), ln_p)
        } else {
            (self.above.temperature.at(h), self.above.ln_pressure(h))
        };
        let p = lnp.exp();
        let (e, de) = self
            .vapour
            .as_ref()
            .map_or((0.0, 0.0), |v| v.at(h, p, dlnp));
        AirSample {
            temperature_k: t,
            dtemperature_dh_k_per_m: dt,
            pressure_pa: p,
            dpressure_dh_pa_per_m: p * dlnp,
            vapour_pressure_pa: e,
            dvapour_pressure_dh_pa_per_m: de,
        }
    }

    /// The knots of the piecewise fits (every level: ln P is a piecewise cubic, C¹ at them, and
    /// T one too or, for the linear fit, C⁰ with dT/dh jumping there), the ends of the humidity data, the top of the data (where the blend into US1976
    /// starts, C¹) and the US1976 layer bases above it.
    fn breaks_m(&self) -> Vec<f64> {
        let mut breaks: Vec<f64> = self.knots.iter().map(|k| k.height_m).collect();
        if let Some(v) = &self.vapour {
            breaks.extend([v.lo_m, v.hi_m]);
        }
        breaks.push(self.top_m);
        breaks.extend(super::us1976::layer_bases_geometric_m().filter(|&h| h > self.top_m));
        breaks.push(MODEL_TOP_M);
        breaks.retain(|&h| h > self.surface_height_m);
        super::normalise_breaks(breaks)
    }

    fn fine_zones_m(&self) -> Vec<FineZone> {
        self.above.temperature.fine_zones_m().to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sounding::{HeightSource, Level, SoundingFormat};

    fn sounding(levels: &[(f64, f64, Option<f64>, Option<f64>)]) -> Sounding {
        Sounding {
            source: PathBuf::from("unit"),
            format: SoundingFormat::NormalizedCsv,
            metadata: Default::default(),
            warnings: Vec::new(),
            levels: levels
                .iter()
                .enumerate()
                .map(|(i, &(h, t, p, e))| Level {
                    height_m: h,
                    pressure_pa: p,
                    temperature_k: t,
                    vapour_pressure_pa: e,
                    height_source: HeightSource::Measured,
                    line: i + 1,
                })
                .collect(),
        }
    }

    #[test]
    fn steps_across_the_top_join_are_short_where_its_bump_is() {
        // A sounding to 20 km, 6 K colder than US 1976 at its top and isothermal there: above
        // the top, the join's dT/dh climbs from 0 to a peak within a few hundred metres (the
        // slope-matching bump), with no break in it, while the default cap of a step's height
        // change at 20 km is 1 km (2 m + 5 % of the height).
        let s = sounding(&[
            (0.0, 262.0, Some(100_000.0), None),
            (11_000.0, 210.65, Some(22_000.0), None),
            (20_000.0, 210.65, Some(5_400.0), None),
        ]);
        let p = Profile::from_sounding(&s, &FitOptions::default()).unwrap();
        // Where dT/dh of the fitted air peaks above the top (every metre up to 3 km).
        let slope = |h: f64| p.air_at(h).dtemperature_dh_k_per_m;
        let peak_m = (0..3000)
            .map(f64::from)
            .max_by(|a, b| slope(20_000.0 + a).total_cmp(&slope(20_000.0 + b)))
            .unwrap();
        let default_cap = 2.0 + 0.05 * 20_000.0;
        assert!(peak_m > 50.0 && peak_m < default_cap / 2.0, "{peak_m}");
        // Steps from the top to well past the peak rise by at most half the climb to it.
        let zones = p.fine_zones_m();
        for x in [0.0, 0.5 * peak_m, peak_m, 2.0 * peak_m] {
            let rise = FineZone::limit_rise_m(&zones, 20_000.0 + x, default_cap);
            assert!(rise <= 0.5 * peak_m, "{x}: {rise}");
        }
    }

    #[test]
    fn top_join_is_c1_even_inside_an_inversion() {
        // A TEMP-like sounding that ends inside a strong inversion: the blend must still join
        // with value and slope, and the slope-matching bump stays bounded.
        let s = sounding(&[
            (10.0, 250.0, Some(101_000.0), Some(100.0)),
            (200.0, 255.0, Some(98_700.0), Some(120.0)),
            (400.0, 262.0, Some(96_300.0), Some(90.0)),
        ]);
        let p = Profile::from_sounding(&s, &FitOptions::default()).unwrap();
        let (a, b) = (p.air_at(400.0 - 1e-7), p.air_at(400.0 + 1e-7));
        assert!((a.temperature_k - b.temperature_k).abs() < 1e-6);
        assert!((a.dtemperature_dh_k_per_m - b.dtemperature_dh_k_per_m).abs() < 1e-6);
        assert!((a.dpressure_dh_pa_per_m / b.dpressure_dh_pa_per_m - 1.0).abs() < 1e-6);
        assert!((a.dvapour_pressure_dh_pa_per_m - b.dvapour_pressure_dh_pa_per_m).abs() < 1e-9);
        // T_top = 262 K is 23.5 K colder than US1976 at 400 m. Above, T relaxes towards the
        // (cooling) standard — that alone peaks at ≈264.9 K about 1.2 km above the top — and
        // the slope-matching bump adds at most 5 K, so T stays below 270 K and above 200 K.
        let mut h = 400.0;
        while h < 20_000.0 {
            let t = p.air_at(h).temperature_k;
            assert!(t < 270.0 && t > 200.0, "{h}: {t}");
            h += 10.0;
        }
    }

    #[test]
    fn linear_fit_is_linear_in_ln_p_and_bumps_keep_the_levels() {
        // Three levels with pressures; linear in ln p between them, by hand: halfway in ln p
        // between 1000 hPa (250 K) and 980 hPa (252 K), at √(1000·980) hPa, T = 251 K.
        let s = sounding(&[
            (0.0, 250.0, Some(100_000.0), None),
            (170.0, 252.0, Some(98_000.0), None),
            (600.0, 249.0, Some(93_000.0), None),
        ]);
        let options = FitOptions {
            temperature_fit: TemperatureFit::Linear,
            ..FitOptions::default()
        };
        let fit = Profile::from_sounding(&s, &options).unwrap();
        assert_eq!(fit.fit_choice().used, TemperatureFit::Linear);
        let p_mid = (100_000.0f64 * 98_000.0).sqrt();
        let (mut lo, mut hi) = (0.0, 170.0);
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if fit.air_at(mid).pressure_pa > p_mid {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let h_mid = 0.5 * (lo + hi);
        assert!((fit.air_at(h_mid).temperature_k - 251.0).abs() < 1e-9);
        // The analytic slope matches a central difference of the same curve.
        let d = 1e-4;
        let numeric =
            (fit.air_at(h_mid + d).temperature_k - fit.air_at(h_mid - d).temperature_k) / (2.0 * d);
        assert!((numeric - fit.air_at(h_mid).dtemperature_dh_k_per_m).abs() < 1e-8);
        // Bumps: the levels stay, the mid-ln-p point moves by exactly the amplitude.
        let bumped = fit.perturbed(&[0.7, -0.4]).unwrap();
        for level in &s.levels {
            let t = bumped.air_at(level.height_m).temperature_k;
            assert!((t - level.temperature_k).abs() < 1e-9, "{level:?}");
        }
        assert!((bumped.air_at(h_mid).temperature_k - 251.7).abs() < 1e-9);
        assert!(fit.perturbed(&[0.1]).is_err());
        assert!(fit.perturbed(&[0.1, f64::NAN]).is_err());
    }

    #[test]
    fn missing_pressures_are_hydrostatic_and_anchored() {
        // Isothermal 260 K, dry: ln P is linear in h, so a pressure withheld in the middle is
        // recovered exactly (up to the RK4 error) from its neighbours.
        let g = G_OVER_R / 260.0;
        let p = |h: f64| 100_000.0 * (-g * h).exp();
        let s = sounding(&[
            (0.0, 260.0, Some(p(0.0)), None),
            (300.0, 260.0, None, None),
            (700.0, 260.0, Some(p(700.0)), None),
        ]);
        let fit = Profile::from_sounding(&s, &FitOptions::default()).unwrap();
        assert!((fit.air_at(300.0).pressure_pa / p(300.0) - 1.0).abs() < 1e-12);
        assert!(!fit.levels()[1].pressure_measured && fit.levels()[2].pressure_measured);
        // No pressure at all: from the given surface pressure.
        let s = sounding(&[(0.0, 260.0, None, None), (500.0, 260.0, None, None)]);
        let options = FitOptions {
            surface_pressure_pa: Some(100_000.0),
            ..FitOptions::default()
        };
        let fit = Profile::from_sounding(&s, &options).unwrap();
        assert!((fit.air_at(500.0).pressure_pa / p(500.0) - 1.0).abs() < 1e-12);
        // Dry sounding: no vapour.
        assert_eq!(fit.air_at(250.0).vapour_pressure_pa, 0.0);
    }
}
