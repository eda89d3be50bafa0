//! Stage 2 — layer fit. In: a measured [`Sounding`]. Out: a [`LayerFit`], the paper-style
//! synthetic layered atmosphere (Gutierrez et al. 2005: a surface temperature plus a stack of
//! constant-gradient layers) that best matches the sounding's temperatures by least squares, so
//! that measured and synthetic air can be compared or traced.
//!
//! Method (variable projection): T(h) is piecewise linear with knots at the range bottom, at
//! free interior breakpoints and at the range top. For fixed breakpoints the knot temperatures
//! are a linear least-squares problem (tridiagonal normal equations, solved directly); the
//! breakpoint heights are optimised over that reduced residual by argmin's Nelder–Mead solver
//! (derivative-free, since the reduced residual is only piecewise smooth in the breakpoints).
//! Breakpoints are kept inside the range and at least `min_thickness_m` apart by projection.
//! Initial breakpoints: the best polyline through the levels themselves (dynamic programming over
//! the level heights). Knots of layers holding fewer than two levels are then moved onto levels,
//! and the better of the optimised and the initial knots is kept.

use std::path::Path;

use argmin::core::{CostFunction, Executor, State, TerminationStatus};
use argmin::solver::neldermead::NelderMead;

use super::{ProfileError, SyntheticAtmosphere};
use crate::sounding::Sounding;

/// Background lapse rate written into the synthetic TOML (K m⁻¹); the fitted layers' gradients
/// are stored relative to it, so above the fitted range the air follows the standard lapse.
const BACKGROUND_LAPSE_K_PER_M: f64 = -0.0065;

/// Options of [`fit_layers`].
#[derive(Debug, Clone, PartialEq)]
pub struct LayerFitOptions {
    /// Bottom of the fitted range (m above the surface, i.e. above the lowest level).
    pub range_bottom_above_surface_m: f64,
    /// Top of the fitted range (m above the surface).
    pub range_top_above_surface_m: f64,
    /// Largest number of linear layers (default 10).
    pub max_layers: usize,
    /// Smallest layer thickness (m).
    pub min_thickness_m: f64,
    /// Per-level weights, one per entry of `Sounding::levels` (None: all 1).
    pub level_weights: Option<Vec<f64>>,
    /// Iteration cap of the breakpoint optimiser.
    pub max_iterations: u64,
}

impl Default for LayerFitOptions {
    fn default() -> Self {
        LayerFitOptions {
            range_bottom_above_surface_m: 0.0,
            range_top_above_surface_m: 3000.0,
            max_layers: 10,
            min_thickness_m: 5.0,
            level_weights: None,
            max_iterations: 2000,
        }
    }
}

/// One fitted layer: a linear temperature change between two heights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FittedLayer {
    /// Bottom (m above mean sea level).
    pub base_m: f64,
    /// Top (m above mean sea level).
    pub top_m: f64,
    /// Temperature at the base (K).
    pub base_temperature_k: f64,
    /// Temperature at the top (K).
    pub top_temperature_k: f64,
}

impl FittedLayer {
    /// dT/dh inside the layer (K m⁻¹).
    pub fn gradient_k_per_m(&self) -> f64 {
        (self.top_temperature_k - self.base_temperature_k) / (self.top_m - self.base_m)
    }
}

/// Measured and fitted temperature at one sounding level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LevelResidual {
    /// Height (m above mean sea level).
    pub height_m: f64,
    /// The sounding's temperature (K).
    pub measured_k: f64,
    /// The fitted layers' temperature (K).
    pub fitted_k: f64,
}

/// The result of [`fit_layers`].
#[derive(Debug, Clone)]
pub struct LayerFit {
    /// Fitted layers, lowest first, contiguous.
    pub layers: Vec<FittedLayer>,
    /// Height of the surface (m above mean sea level): the sounding's lowest level.
    pub surface_height_m: f64,
    /// Surface temperature (K) of the synthetic atmosphere.
    pub surface_temperature_k: f64,
    /// Surface pressure (Pa): the lowest level's, or 1013.25 hPa if it has none.
    pub surface_pressure_pa: f64,
    /// One entry per level inside the fitted range.
    pub residuals: Vec<LevelResidual>,
    /// Weighted RMS of the residuals (K).
    pub rms_k: f64,
    /// Largest |residual| (K).
    pub max_abs_k: f64,
    /// RMS (K) of one straight line fitted over the same levels: the baseline to beat.
    pub lapse_only_rms_k: f64,
    /// Why argmin stopped (NotTerminated if no breakpoints had to be optimised).
    pub termination: TerminationStatus,
}

/// Fit a stack of linear layers to `sounding` in the options' height range.
pub fn fit_layers(
    sounding: &Sounding,
    options: &LayerFitOptions,
) -> Result<LayerFit, ProfileError> {
    check_options(options)?;
    let data = select_levels(sounding, options)?;
    let lo = data.h[0];
    let hi = data.h[data.h.len() - 1];
    let n_inner = options
        .max_layers
        .saturating_sub(1)
        .min(data.h.len().saturating_sub(2));
    let init = initial_breakpoints(&data, n_inner, options.min_thickness_m);
    let init_knots = init.clone();
    let problem = Reduced {
        data: &data,
        lo,
        hi,
        min_gap_m: options.min_thickness_m,
    };
    let (breaks, termination) = if init.is_empty() {
        (Vec::new(), TerminationStatus::NotTerminated)
    } else {
        optimise(problem.clone(), init, options.max_iterations).map_err(|e| {
            ProfileError::LayerFitFailed {
                path: sounding.source.clone(),
                message: e.to_string(),
            }
        })?
    };
    let optimised = anchor_unsupported_knots(&problem.knots(&breaks), &data.h);
    let on_levels: Vec<f64> = [lo].into_iter().chain(init_knots).chain([hi]).collect();
    // The optimiser starts from the level polyline; anchoring may undo some of its gain, so
    // the better of the two (by the least-squares residual) is kept.
    let sse = |k: &[f64]| weighted_sse(&data, k, &solve_knot_temperatures(&data, k));
    let knots = if sse(&optimised) <= sse(&on_levels) {
        optimised
    } else {
        on_levels
    };
    let temps = solve_knot_temperatures(&data, &knots);
    let (knots, temps) = merge_collinear(&knots, &temps);
    Ok(assemble(sounding, &data, &knots, &temps, termination))
}

/// Gradients closer than this (K m⁻¹) are one layer.
const SAME_GRADIENT_K_PER_M: f64 = 1e-6;

/// The knots without those between two layers of the same gradient: when the sounding needs
/// fewer layers than allowed, the spare breakpoints fall inside a straight stretch, and one
/// layer is what a user expects to read there. A dropped knot's temperature moves by less than
/// the gradient tolerance times the merged layer's thickness (sub-millikelvin over a kilometre).
fn merge_collinear(knots: &[f64], temps: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let slope = |a: usize, b: usize| (temps[b] - temps[a]) / (knots[b] - knots[a]);
    let (mut k, mut t) = (vec![knots[0]], vec![temps[0]]);
    let mut start = 0;
    for i in 1..knots.len() - 1 {
        if (slope(start, i) - slope(i, i + 1)).abs() >= SAME_GRADIENT_K_PER_M {
            k.push(knots[i]);
            t.push(temps[i]);
            start = i;
        }
    }
    k.push(knots[knots.len() - 1]);
    t.push(temps[temps.len() - 1]);
    (k, t)
}

/// Knots moved onto the nearest level where no level lies strictly inside the nearer half of either layer
/// next to them.
///
/// A knot's temperature is held by the levels whose hat-basis weight on it is large; a knot
/// whose neighbouring levels all sit near the layers' far ends (weight ≤ ½) is fixed only by
/// small weights, so the least squares extrapolates it freely: between sparse significant levels
/// the optimiser can place knots in a gap and draw a 20 K spike through it at zero residual. A
/// knot on a level is held by that level's own temperature. Knots of well-sampled layers stay
/// where the optimiser put them; knots that land on the same level are merged.
fn anchor_unsupported_knots(knots: &[f64], levels_m: &[f64]) -> Vec<f64> {
    let last = knots.len() - 1;
    let support = |i: usize| -> f64 {
        let (k, lo, hi) = (knots[i], knots[i - 1], knots[i + 1]);
        levels_m
            .iter()
            .filter(|&&h| h >= lo && h <= hi)
            .map(|&h| {
                let span = if h < k { k - lo } else { hi - k };
                if span > 0.0 {
                    1.0 - (h - k).abs() / span
                } else {
                    1.0
                }
            })
            .fold(0.0, f64::max)
    };
    let mut out: Vec<f64> = Vec::with_capacity(knots.len());
    for (i, &k) in knots.iter().enumerate() {
        let k = if 0 < i && i < last && support(i) <= 0.5 {
            levels_m
                .iter()
                .copied()
                .min_by(|a, b| (a - k).abs().total_cmp(&(b - k).abs()))
                .unwrap_or(k)
        } else {
            k
        };
        if out.last().is_none_or(|&p| k > p) {
            out.push(k);
        }
    }
    if out.len() < 2 {
        return vec![knots[0], knots[last]];
    }
    out
}

/// Check the range, layer count and minimum thickness.
pub(super) fn check_options(o: &LayerFitOptions) -> Result<(), ProfileError> {
    let bad = |name, message: &str| {
        Err(ProfileError::BadOption {
            name,
            message: message.into(),
        })
    };
    if !(o.range_bottom_above_surface_m.is_finite() && o.range_top_above_surface_m.is_finite())
        || o.range_top_above_surface_m <= o.range_bottom_above_surface_m
    {
        return bad(
            "range_top_above_surface_m",
            "range must be finite with top above bottom",
        );
    }
    if o.max_layers == 0 {
        return bad("max_layers", "must be at least 1");
    }
    if !(o.min_thickness_m.is_finite() && o.min_thickness_m > 0.0) {
        return bad("min_thickness_m", "must be finite and positive");
    }
    Ok(())
}

/// The levels inside the range: heights, temperatures, weights.
#[derive(Debug, Clone)]
struct Data {
    h: Vec<f64>,
    t: Vec<f64>,
    w: Vec<f64>,
}

fn select_levels(s: &Sounding, o: &LayerFitOptions) -> Result<Data, ProfileError> {
    let surface = s.levels.first().map_or(f64::NAN, |l| l.height_m);
    let range = (
        surface + o.range_bottom_above_surface_m,
        surface + o.range_top_above_surface_m,
    );
    if let Some(w) = &o.level_weights
        && w.len() != s.levels.len()
    {
        return Err(ProfileError::BadOption {
            name: "level_weights",
            message: format!("{} weights for {} levels", w.len(), s.levels.len()),
        });
    }
    let mut d = Data {
        h: vec![],
        t: vec![],
        w: vec![],
    };
    for (i, l) in s.levels.iter().enumerate() {
        let w = o.level_weights.as_ref().map_or(1.0, |w| w[i]);
        let ok = l.height_m.is_finite() && l.temperature_k.is_finite() && w.is_finite() && w > 0.0;
        if ok && l.height_m >= range.0 && l.height_m <= range.1 {
            d.h.push(l.height_m);
            d.t.push(l.temperature_k);
            d.w.push(w);
        }
    }
    // Two levels fit exactly as one straight layer; fewer leave nothing to fit.
    if d.h.len() < 2 {
        return Err(ProfileError::BadSounding {
            path: s.source.clone(),
            line: s.levels.first().map_or(0, |l| l.line),
            message: format!(
                "{} usable levels between {:.0} m and {:.0} m; a layer fit needs at least 2",
                d.h.len(),
                range.0,
                range.1
            ),
        });
    }
    Ok(d)
}

/// Largest number of candidate heights tried per greedy step of [`initial_breakpoints`].
const MAX_CANDIDATES: usize = 400;

/// Up to `n` interior breakpoints, at least `gap_m` apart, on level heights: the optimal
/// polyline through the levels themselves (knot temperatures = the measured ones) with at most
/// n + 1 segments, by dynamic programming over the candidate levels (exact for that polyline; the
/// least squares and the optimiser then free the temperatures and heights). Unlike a greedy
/// choice it keeps a thin surface step that only a pair of knots can follow.
fn initial_breakpoints(d: &Data, n: usize, gap_m: f64) -> Vec<f64> {
    let stride = d.h.len().div_ceil(MAX_CANDIDATES).max(1);
    let mut cand: Vec<usize> = (0..d.h.len()).step_by(stride).collect();
    if cand.last() != Some(&(d.h.len() - 1)) {
        cand.push(d.h.len() - 1);
    }
    let m = cand.len();
    // seg[a][b]: weighted SSE of the chord from candidate a to candidate b.
    let chord = |a: usize, b: usize| -> f64 {
        let (i, j) = (cand[a], cand[b]);
        let slope = (d.t[j] - d.t[i]) / (d.h[j] - d.h[i]);
        (i..=j)
            .map(|k| d.w[k] * (d.t[i] + slope * (d.h[k] - d.h[i]) - d.t[k]).powi(2))
            .sum()
    };
    let seg: Vec<Vec<f64>> = (0..m)
        .map(|a| {
            (0..m)
                .map(|b| {
                    let ok = b > a && d.h[cand[b]] - d.h[cand[a]] >= gap_m;
                    if ok { chord(a, b) } else { f64::INFINITY }
                })
                .collect()
        })
        .collect();
    // cost[s][b], from[s][b]: best polyline of s + 1 segments from candidate 0 to b.
    let mut cost = vec![seg[0].clone()];
    let mut from: Vec<Vec<usize>> = vec![vec![0; m]];
    for s in 1..=n {
        let (mut c, mut f) = (vec![f64::INFINITY; m], vec![0; m]);
        for b in 1..m {
            for a in 1..b {
                let v = cost[s - 1][a] + seg[a][b];
                if v < c[b] {
                    (c[b], f[b]) = (v, a);
                }
            }
        }
        cost.push(c);
        from.push(f);
    }
    // The fewest segments within a hair of the best error.
    let best = cost.iter().map(|c| c[m - 1]).fold(f64::INFINITY, f64::min);
    let Some(s) = (0..=n).find(|&s| cost[s][m - 1] <= best * (1.0 + 1e-9) + 1e-18) else {
        return Vec::new();
    };
    let (mut knots, mut b) = (Vec::new(), m - 1);
    for level in (1..=s).rev() {
        b = from[level][b];
        knots.push(d.h[cand[b]]);
    }
    knots.reverse();
    knots
}

/// The reduced least-squares problem in the breakpoint heights.
#[derive(Clone)]
struct Reduced<'a> {
    data: &'a Data,
    lo: f64,
    hi: f64,
    min_gap_m: f64,
}

impl Reduced<'_> {
    /// All knots (bottom, projected breakpoints, top), ascending and `min_gap_m` apart.
    fn knots(&self, breaks: &[f64]) -> Vec<f64> {
        let mut b: Vec<f64> = breaks
            .iter()
            .map(|x| if x.is_finite() { *x } else { self.lo })
            .collect();
        b.sort_by(f64::total_cmp);
        let n = b.len();
        let mut knots = vec![self.lo];
        for (i, x) in b.into_iter().enumerate() {
            let room_above = self.hi - self.min_gap_m * (n - i) as f64;
            let prev = knots[knots.len() - 1];
            knots.push(x.max(prev + self.min_gap_m).min(room_above.max(prev)));
        }
        knots.push(self.hi);
        knots
    }
}

impl CostFunction for Reduced<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, breaks: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        let knots = self.knots(breaks);
        let temps = solve_knot_temperatures(self.data, &knots);
        Ok(weighted_sse(self.data, &knots, &temps))
    }
}

fn optimise(
    problem: Reduced<'_>,
    init: Vec<f64>,
    max_iterations: u64,
) -> Result<(Vec<f64>, TerminationStatus), argmin::core::Error> {
    let step = ((problem.hi - problem.lo) / (4.0 * (init.len() + 1) as f64)).max(problem.min_gap_m);
    let mut simplex = vec![init.clone()];
    for i in 0..init.len() {
        let mut v = init.clone();
        v[i] += if i % 2 == 0 { step } else { -step };
        simplex.push(v);
    }
    let solver = NelderMead::new(simplex).with_sd_tolerance(1e-10)?;
    let result = Executor::new(problem, solver)
        .configure(|s| s.max_iters(max_iterations))
        .run()?;
    let state = result.state();
    let best = state.get_best_param().cloned().unwrap_or(init);
    Ok((best, state.get_termination_status().clone()))
}

/// Linear interpolation weights of `h` on `knots`: (interval index, weight of its upper knot).
fn locate(knots: &[f64], h: f64) -> (usize, f64) {
    let k = knots.partition_point(|x| *x <= h).clamp(1, knots.len() - 1) - 1;
    let span = knots[k + 1] - knots[k];
    let u = if span > 0.0 {
        ((h - knots[k]) / span).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (k, u)
}

fn evaluate(knots: &[f64], temps: &[f64], h: f64) -> f64 {
    let (k, u) = locate(knots, h);
    temps[k] * (1.0 - u) + temps[k + 1] * u
}

fn weighted_sse(d: &Data, knots: &[f64], temps: &[f64]) -> f64 {
    (0..d.h.len())
        .map(|i| d.w[i] * (evaluate(knots, temps, d.h[i]) - d.t[i]).powi(2))
        .sum()
}

/// Knot temperatures minimising the weighted squared residual; the normal equations of the hat
/// basis are tridiagonal, solved by the Thomas algorithm (hand-written: a 3-band solve is a few
/// lines and needs no matrix crate). A tiny first-difference ridge keeps knots without data
/// determined (they take their neighbours' value).
fn solve_knot_temperatures(d: &Data, knots: &[f64]) -> Vec<f64> {
    let n = knots.len();
    let (mut diag, mut off, mut rhs) = (vec![0.0; n], vec![0.0; n - 1], vec![0.0; n]);
    for i in 0..d.h.len() {
        let (k, u) = locate(knots, d.h[i]);
        let w = d.w[i];
        diag[k] += w * (1.0 - u) * (1.0 - u);
        diag[k + 1] += w * u * u;
        off[k] += w * u * (1.0 - u);
        rhs[k] += w * (1.0 - u) * d.t[i];
        rhs[k + 1] += w * u * d.t[i];
    }
    let ridge = 1e-9 * d.w.iter().sum::<f64>();
    for k in 0..n - 1 {
        diag[k] += ridge;
        diag[k + 1] += ridge;
        off[k] -= ridge;
    }
    thomas(&diag, &off, &rhs)
}

fn thomas(diag: &[f64], off: &[f64], rhs: &[f64]) -> Vec<f64> {
    let n = diag.len();
    let (mut c, mut r) = (vec![0.0; n], vec![0.0; n]);
    c[0] = if n > 1 { off[0] / diag[0] } else { 0.0 };
    r[0] = rhs[0] / diag[0];
    for i in 1..n {
        let m = diag[i] - off[i - 1] * c[i - 1];
        c[i] = if i < n - 1 { off[i] / m } else { 0.0 };
        r[i] = (rhs[i] - off[i - 1] * r[i - 1]) / m;
    }
    for i in (0..n - 1).rev() {
        r[i] -= c[i] * r[i + 1];
    }
    r
}

/// RMS of the weighted least-squares straight line through the levels.
fn lapse_only_rms_k(d: &Data) -> f64 {
    let knots = [d.h[0], d.h[d.h.len() - 1]];
    let temps = solve_knot_temperatures(d, &knots);
    (weighted_sse(d, &knots, &temps) / d.w.iter().sum::<f64>()).sqrt()
}

fn assemble(
    s: &Sounding,
    d: &Data,
    knots: &[f64],
    temps: &[f64],
    termination: TerminationStatus,
) -> LayerFit {
    let layers: Vec<FittedLayer> = (0..knots.len() - 1)
        .map(|k| FittedLayer {
            base_m: knots[k],
            top_m: knots[k + 1],
            base_temperature_k: temps[k],
            top_temperature_k: temps[k + 1],
        })
        .collect();
    let residuals: Vec<LevelResidual> = (0..d.h.len())
        .map(|i| LevelResidual {
            height_m: d.h[i],
            measured_k: d.t[i],
            fitted_k: evaluate(knots, temps, d.h[i]),
        })
        .collect();
    let surface = &s.levels[0];
    let below_m = knots[0] - surface.height_m;
    LayerFit {
        layers,
        surface_height_m: surface.height_m,
        surface_temperature_k: temps[0] - BACKGROUND_LAPSE_K_PER_M * below_m,
        surface_pressure_pa: surface.pressure_pa.unwrap_or(101_325.0),
        rms_k: (weighted_sse(d, knots, temps) / d.w.iter().sum::<f64>()).sqrt(),
        max_abs_k: residuals
            .iter()
            .map(|r| (r.fitted_k - r.measured_k).abs())
            .fold(0.0, f64::max),
        residuals,
        lapse_only_rms_k: lapse_only_rms_k(d),
        termination,
    }
}

impl LayerFit {
    /// The fit as a synthetic TOML that `ghostship profile` accepts: the standard lapse
    /// background plus one constant-gradient layer per fitted layer (gradient relative to it).
    pub fn to_toml(&self) -> String {
        let mut out = format!(
            "description = \"layer fit: {} layers, rms {:.3} K\"\nsurface_height_m = {:?}\n\
             surface_temperature_c = {:?}\nsurface_pressure_hpa = {:?}\nbackground = {:?}\n",
            self.layers.len(),
            self.rms_k,
            self.surface_height_m,
            self.surface_temperature_k - 273.15,
            self.surface_pressure_pa / 100.0,
            BACKGROUND_LAPSE_K_PER_M,
        );
        for l in &self.layers {
            out += &format!(
                "\n[[layers]]\nfrom_m = {:?}\nto_m = {:?}\ngradient_k_per_m = {:?}\n",
                l.base_m,
                l.top_m,
                l.gradient_k_per_m() - BACKGROUND_LAPSE_K_PER_M
            );
        }
        out
    }

    /// The fit as the project's synthetic atmosphere (parsed from [`LayerFit::to_toml`]).
    pub fn to_synthetic(&self) -> Result<SyntheticAtmosphere, ProfileError> {
        SyntheticAtmosphere::from_toml_str(&self.to_toml(), Path::new("<layer fit>"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_knot_whose_levels_sit_at_the_far_ends_is_anchored() {
        // Levels cluster near 0–11 m and 1999–2000 m; the knot at 1000 m has levels in both
        // neighbouring layers, but none in the nearer half of either.
        let levels = [0.0, 5.0, 9.0, 10.5, 11.0, 1999.0, 2000.0];
        let knots = anchor_unsupported_knots(&[0.0, 10.0, 1000.0, 2000.0], &levels);
        assert_eq!(knots, vec![0.0, 10.0, 11.0, 2000.0]);
        // The fitted temperatures then stay on the line (no spike from a 0.05 K wiggle).
        let t: Vec<f64> = levels.iter().map(|h| 288.0 - 0.0065 * h).collect();
        let mut t = t;
        t[5] += 0.05;
        let d = Data {
            h: levels.to_vec(),
            t: t.clone(),
            w: vec![1.0; levels.len()],
        };
        let temps = solve_knot_temperatures(&d, &knots);
        for (k, tk) in knots.iter().zip(&temps) {
            assert!((tk - (288.0 - 0.0065 * k)).abs() < 0.1, "{k} m: {tk} K");
        }
    }

    #[test]
    fn knots_of_well_sampled_layers_stay_and_the_range_ends_never_move() {
        let levels: Vec<f64> = (0..=100).map(|i| 10.0 * i as f64).collect();
        let knots = [0.0, 95.0, 402.5, 1000.0];
        assert_eq!(anchor_unsupported_knots(&knots, &levels), knots.to_vec());
        // Two knots snapping onto one level merge.
        let sparse = [0.0, 500.0, 1000.0];
        assert_eq!(
            anchor_unsupported_knots(&[0.0, 480.0, 520.0, 1000.0], &sparse),
            vec![0.0, 500.0, 1000.0]
        );
    }

    #[test]
    fn collinear_layers_merge_and_kinks_stay() {
        let knots = [0.0, 10.0, 20.0, 30.0];
        let temps = [0.0, 1.0, 2.0, 1.0];
        let (k, t) = merge_collinear(&knots, &temps);
        assert_eq!(k, vec![0.0, 20.0, 30.0]);
        assert_eq!(t, vec![0.0, 2.0, 1.0]);
    }
}
