//! Stage 4 (trace), break handling: which levels of a piecewise field a step crosses.
//!
//! In: the field's breaks (heights where dn/dh or d²n/dh² jumps, ascending), the ray's current
//! height interval between two neighbouring breaks, and one accepted step (its end heights,
//! climb signs and dense output). Out: the first point of the step at which the ray leaves its
//! interval, so the ray loop can shorten the step to end exactly there. A Runge–Kutta step that
//! straddles a break integrates a right-hand side that is not smooth inside the step and drops
//! from fifth to first or second order; ending steps on breaks keeps the method's order (the
//! same treatment a careful reference integrator gives a discontinuity).

//!
//! Which breaks a ray loop honours is settled once per tracer setting ([`settle`]): a field
//! lists its breaks where dn/dh jumps (always kept) and its *minor* breaks, where dn/dh is
//! continuous and d²n/dh² or d³n/dh³ jumps, by known amounts ([`MinorBreak`]). A minor break
//! that a step straddles costs a direction error bounded by the jumps, the step's length and
//! its height change; those whose worst case, summed over all of them, fits a share of the
//! error budget are dropped (a densely written sounding has thousands of knots that matter to
//! no ray), the rest are kept.

use super::TracerConfig;

/// A level of a field where dn/dh is continuous but d²n/dh² or d³n/dh³ jumps (a knot of a C¹
/// fit, say; where the fitted cubics happen to meet with equal curvature, as a monotone fit of
/// nearly linear data does, only d³n/dh³ jumps).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MinorBreak {
    /// Height above the surface (m).
    pub height_m: f64,
    /// |Δ(d²n/dh²)| across the level (m⁻²).
    pub curvature_jump_per_m2: f64,
    /// |Δ(d³n/dh³)| across the level (m⁻³).
    pub curvature_kink_per_m3: f64,
}

/// Largest error, per unit of h² (step length h), of Dormand–Prince 5(4)'s quadrature weights on
/// a ramp max(s − s₀, 0) with its kink anywhere in the step: max over u of
/// |Σ bᵢ·(cᵢ − u)₊ − (1 − u)²/2| = 0.02247 (at u = 4/5, computed from the tableau). A step of
/// length L and height change H that straddles a jump Δκ of d²n/dh² integrates the ray's
/// curvature dn/dh with a ramp of slope Δκ·H/L in arc length, so its direction is off by at
/// most this × Δκ·H·L. Rounded up, for the nonlinear stages that are not pure quadrature.
const STRADDLE_KERNEL: f64 = 0.03;

/// The same for a kink max(s − s₀, 0)² of the step's curvature dn/dh (a jump J of d³n/dh³):
/// max over u of ½·|Σ bᵢ·(cᵢ − u)₊² − (1 − u)³/3| = 0.001135 (at u ≈ 0.39, computed from the
/// tableau). A step of length L and height change H that straddles it integrates the ray's
/// curvature with a term ½·J·(H/L)²·(s − s₀)₊², so its direction is off by at most this × J·H²·L.
/// Rounded up as [`STRADDLE_KERNEL`] is. A knot of a fit to rounded, nearly linear data (the
/// stress suite's 0.5 m levels with temperatures to 1e-6 K) has a curvature jump of ~3e-15 m⁻²
/// but a kink of ~9e-11 m⁻³: a 4 m high, 1 150 m long step across eight such knots turned the
/// ray by 1.5e-9 rad (the Dormand–Prince weights on the field itself), unseen by the 5(4) error
/// estimate (1.2e-10 rad), while the curvature jumps alone bound it by 1e-12 rad.
const STRADDLE_KINK_KERNEL: f64 = 0.0015;

/// Share of the tolerance that straddled minor breaks may use up together. Far below the error
/// the integration itself leaves (the stress suite measures its worst at 0.6–6 % of the
/// tolerance): the error of a dropped break's straddle depends on where the steps fall, not on
/// the tolerance, so a share comparable to the integration's own error lets *which* breaks are
/// dropped set the error, and a tighter tolerance can then be less accurate
/// (with 10 %, the 0.1 m layers with 30 K jumps were 5.8e-5 m off at 1 cm and 7.0e-5 m at 1 mm, of
/// which ≈ 6.5e-5 m came from straddled knots).
const STRADDLE_SHARE: f64 = 1e-3;

/// The breaks a ray loop with `config` must end its steps on, ascending: every one of `major`,
/// and the minor breaks whose straddling could matter, for rays whose error budget
/// `config.tolerance_m` is spread over `error_length_m`: a direction error ε costs ε × the error
/// length, so the dropped minor breaks' worst-case direction errors, summed, stay within
/// [`STRADDLE_SHARE`] × tolerance / error length. The worst case of one straddle takes the longest step
/// (`max_step_m`) and the largest height change a step can have there (the vertical cap at the
/// break, reached from a start up to one cap above it), and adds the costs of its two jumps
/// ([`STRADDLE_KERNEL`], [`STRADDLE_KINK_KERNEL`]).
pub(crate) fn settle(
    major: &[f64],
    minor: &[MinorBreak],
    config: &TracerConfig,
    error_length_m: f64,
) -> Vec<f64> {
    let tolerance_per_m = config.tolerance_m / error_length_m;
    let k = config.vertical_step_per_height.min(0.5);
    let worst_rad = |b: &MinorBreak| {
        let cap = (config.vertical_step_base_m + k * b.height_m.max(0.0)) / (1.0 - k);
        straddle_rad(b, cap.min(config.max_step_m), config.max_step_m)
    };
    let mut ranked: Vec<(f64, f64)> = minor.iter().map(|b| (worst_rad(b), b.height_m)).collect();
    ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
    let budget_rad = STRADDLE_SHARE * tolerance_per_m;
    let mut spent_rad = 0.0;
    let mut kept: Vec<f64> = major.to_vec();
    for (worst, height_m) in ranked {
        spent_rad += worst;
        if spent_rad > budget_rad {
            kept.push(height_m);
        }
    }
    kept.sort_by(f64::total_cmp);
    kept.dedup();
    kept
}

/// Worst-case direction error (rad) of one step of length `step_m` and height change
/// `height_change_m` that straddles `b`.
fn straddle_rad(b: &MinorBreak, height_change_m: f64, step_m: f64) -> f64 {
    let jump = STRADDLE_KERNEL * b.curvature_jump_per_m2;
    let kink = STRADDLE_KINK_KERNEL * b.curvature_kink_per_m3 * height_change_m;
    (jump + kink) * height_change_m * step_m
}

/// The height interval between two neighbouring breaks that a step integrates in, with the
/// field of that interval continued smoothly past its bounds. Every stage of a Runge–Kutta step
/// then sees one smooth function: a stage whose height lies beyond a bound (the internal stages
/// of a step that ends just short of a break overshoot it when the ray is steep, and a step that
/// starts just short of a break it has landed on starts outside the interval it enters) gets the
/// interval's own quadratic continuation from the bound — n, dn/dh and a one-sided difference
/// of dn/dh there — not the neighbouring interval's values, which differ by the break's jump.
/// The independent reference tracer of the tests treats its layers the same way.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Layer {
    /// Lower bound (m above the ground; −∞ below the lowest break).
    pub lower_m: f64,
    /// Upper bound (m; +∞ above the highest break).
    pub upper_m: f64,
}

/// How far inside its interval the field is evaluated for a continuation (m): far above the
/// rounding of the heights (~1e-11 m at 40 km), far below any effect on a ray.
const INSIDE_M: f64 = 1e-9;

/// Step (m) of the one-sided difference of dn/dh that gives a continuation its curvature (at
/// most a quarter of the interval).
const CURVATURE_PROBE_M: f64 = 1e-4;

impl Layer {
    /// No bounds: the field as it is everywhere.
    pub const EVERYWHERE: Layer = Layer {
        lower_m: f64::NEG_INFINITY,
        upper_m: f64::INFINITY,
    };

    /// Whether `height_m` is inside the interval, at least [`INSIDE_M`] from its bounds, where
    /// [`Self::index_at`] is the field itself.
    #[inline]
    pub fn contains(self, height_m: f64) -> bool {
        let (lo, hi) = (self.lower_m + INSIDE_M, self.upper_m - INSIDE_M);
        (height_m >= lo && height_m <= hi)
            || lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less)
            || height_m.is_nan()
    }

    /// The height inside the interval nearest to `height_m`, at least [`INSIDE_M`] from its
    /// bounds (where the continuation starts).
    pub fn nearest_inside(self, height_m: f64) -> f64 {
        height_m.clamp(self.lower_m + INSIDE_M, self.upper_m - INSIDE_M)
    }

    /// n and dn/dh at `height_m` for a step in this interval: `index(height_m)` inside it, and
    /// outside (or within [`INSIDE_M`] of a bound, where a lookup could pick either side) the
    /// quadratic continuation of `index` from [`INSIDE_M`] inside the nearer bound. NaN in, NaN
    /// out.
    #[inline]
    pub fn index_at(self, height_m: f64, index: impl Fn(f64) -> (f64, f64)) -> (f64, f64) {
        if self.contains(height_m) {
            return index(height_m);
        }
        let (lo, hi) = (self.lower_m + INSIDE_M, self.upper_m - INSIDE_M);
        let edge = height_m.clamp(lo, hi);
        let (n, slope) = index(edge);
        let beyond = height_m - edge;
        let probe = CURVATURE_PROBE_M.min(0.25 * (hi - lo)).copysign(beyond);
        let (_, inner_slope) = index(edge - probe);
        let curvature = (slope - inner_slope) / probe;
        (
            n + beyond * (slope + 0.5 * curvature * beyond),
            slope + curvature * beyond,
        )
    }
}

/// A root finder: `locate(g, a, c)` returns a root of `g` on [a, c].
pub(crate) type Locate<'a> = dyn FnMut(&mut dyn FnMut(f64) -> f64, f64, f64) -> f64 + 'a;

/// The open height interval between two neighbouring breaks in which the ray currently is.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bracket<'b> {
    breaks: &'b [f64],
    /// Number of breaks below the interval: it is (`breaks[k − 1]`, `breaks[k]`).
    k: usize,
}

/// Where a step first leaves its interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Exit {
    /// Fraction of the step (0 < t ≤ 1).
    pub t: f64,
    /// The break height it crosses (m).
    pub height_m: f64,
    /// Whether it crosses upwards.
    pub up: bool,
}

impl<'b> Bracket<'b> {
    /// The interval of a ray at `height_m`; on a break, the side it is heading to.
    pub fn new(breaks: &'b [f64], height_m: f64, climbing: bool) -> Self {
        let k = if climbing {
            breaks.partition_point(|&b| b <= height_m)
        } else {
            breaks.partition_point(|&b| b < height_m)
        };
        Bracket { breaks, k }
    }

    /// Whether the field has no breaks at all.
    pub fn is_empty(&self) -> bool {
        self.breaks.is_empty()
    }

    /// Lower bound of the interval (m; −∞ below the lowest break).
    pub fn lower_m(&self) -> f64 {
        if self.k == 0 {
            f64::NEG_INFINITY
        } else {
            self.breaks[self.k - 1]
        }
    }

    /// Upper bound of the interval (m; +∞ above the highest break).
    pub fn upper_m(&self) -> f64 {
        self.breaks.get(self.k).copied().unwrap_or(f64::INFINITY)
    }

    /// The interval as a [`Layer`] (its field continued past its bounds).
    pub fn layer(&self) -> Layer {
        Layer {
            lower_m: self.lower_m(),
            upper_m: self.upper_m(),
        }
    }

    /// Move to the neighbouring interval across the upper (`up`) or lower bound.
    pub fn cross(&mut self, up: bool) {
        if up {
            self.k = (self.k + 1).min(self.breaks.len());
        } else {
            self.k = self.k.saturating_sub(1);
        }
    }

    /// The first exit of a step from the interval, if any. `height` gives the height at a
    /// fraction of the step (dense output), `extremum` the fraction at which the height has its
    /// one interior extremum, if the climb changes sign inside the step. `locate(g, a, c)` finds a
    /// root of `g` on [a, c]. A piece that already starts outside (the ray landed on a break a
    /// rounding error to the far side) exits at its start.
    pub fn first_exit(
        &self,
        heights_m: (f64, f64),
        extremum: Option<f64>,
        height: &mut dyn FnMut(f64) -> f64,
        locate: &mut Locate<'_>,
    ) -> Option<Exit> {
        let (lower, upper) = (self.lower_m(), self.upper_m());
        let (h0, h1) = heights_m;
        if extremum.is_none() && h1 > lower && h1 < upper {
            return None;
        }
        let pieces: [(f64, f64); 2] = match extremum {
            Some(tm) => [(0.0, tm), (tm, 1.0)],
            None => [(0.0, 1.0), (1.0, 1.0)],
        };
        for (a, c) in pieces {
            if c <= a {
                continue;
            }
            let ha = if a == 0.0 { h0 } else { height(a) };
            let hc = if c == 1.0 { h1 } else { height(c) };
            let (bound, up, outside) = if hc > ha {
                (upper, true, hc > upper)
            } else {
                (lower, false, hc < lower)
            };
            if !outside {
                continue;
            }
            let already_out = if up { ha >= bound } else { ha <= bound };
            let t = if already_out {
                a
            } else {
                locate(&mut |t| height(t) - bound, a, c)
            };
            return Some(Exit {
                t,
                height_m: bound,
                up,
            });
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bisect(g: &mut dyn FnMut(f64) -> f64, mut a: f64, mut c: f64) -> f64 {
        let ga = g(a);
        for _ in 0..60 {
            let m = 0.5 * (a + c);
            if (g(m) > 0.0) == (ga > 0.0) {
                a = m;
            } else {
                c = m;
            }
        }
        0.5 * (a + c)
    }

    #[test]
    fn bracket_sides_and_crossings() {
        let breaks = [10.0, 20.0, 30.0];
        let b = Bracket::new(&breaks, 20.0, true);
        assert_eq!((b.lower_m(), b.upper_m()), (20.0, 30.0));
        let mut b = Bracket::new(&breaks, 20.0, false);
        assert_eq!((b.lower_m(), b.upper_m()), (10.0, 20.0));
        b.cross(false);
        assert_eq!((b.lower_m(), b.upper_m()), (f64::NEG_INFINITY, 10.0));
        b.cross(false);
        assert_eq!(b.lower_m(), f64::NEG_INFINITY);
        let b = Bracket::new(&breaks, 35.0, true);
        assert_eq!((b.lower_m(), b.upper_m()), (30.0, f64::INFINITY));
    }

    #[test]
    fn first_exit_through_the_top_and_after_an_apex() {
        let breaks = [10.0, 20.0];
        let b = Bracket::new(&breaks, 15.0, true);
        // Rising straight through 20 at t = 0.5.
        let mut h = |t: f64| 15.0 + 10.0 * t;
        let e = b
            .first_exit((15.0, 25.0), None, &mut h, &mut bisect)
            .unwrap();
        assert!((e.t - 0.5).abs() < 1e-12 && e.up && e.height_m == 20.0);
        // Up to an apex at 19 (t = 0.4), then down through 10.
        let mut h = |t: f64| 19.0 - 40.0 * (t - 0.4) * (t - 0.4);
        let h1 = h(1.0);
        assert!(h1 < 10.0);
        let e = b
            .first_exit((h(0.0), h1), Some(0.4), &mut h, &mut bisect)
            .unwrap();
        assert!(!e.up && e.height_m == 10.0 && e.t > 0.4);
        assert!((h(e.t) - 10.0).abs() < 1e-9);
        // Staying inside: no exit.
        let mut h = |t: f64| 15.0 + t;
        assert!(
            b.first_exit((15.0, 16.0), None, &mut h, &mut bisect)
                .is_none()
        );
        // An apex that pokes above 20 exits on the way up.
        let mut h = |t: f64| 15.0 + 24.0 * t * (1.0 - t);
        let e = b
            .first_exit((15.0, 15.0), Some(0.5), &mut h, &mut bisect)
            .unwrap();
        assert!(e.up && e.t < 0.5 && (h(e.t) - 20.0).abs() < 1e-9);
    }

    /// The largest error, per unit jump, of one Dormand–Prince step of length 1 integrating
    /// y' = (t − u)₊^p / p! (a jump of the p-th derivative of the integrand at u), over u.
    fn straddle_error(p: i32) -> f64 {
        let fact = if p == 1 { 1.0 } else { 2.0 };
        (0..=1000)
            .map(|i| {
                let u = i as f64 / 1000.0;
                let mut f = |y: &[f64; 2]| [1.0, (y[0] - u).max(0.0).powi(p) / fact];
                let k1 = f(&[0.0, 0.0]);
                let step = crate::tracer::dopri::Step::attempt(&mut f, &[0.0, 0.0], &k1, 1.0);
                let exact = (1.0 - u).powi(p + 1) / (fact * (p + 1) as f64);
                (step.y1[1] - exact).abs()
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn straddle_kernels_bound_the_steps_error_on_a_jump_and_a_kink() {
        let (jump, kink) = (straddle_error(1), straddle_error(2));
        assert!(
            jump <= STRADDLE_KERNEL && jump > 0.7 * STRADDLE_KERNEL,
            "{jump}"
        );
        assert!(
            kink <= STRADDLE_KINK_KERNEL && kink > 0.7 * STRADDLE_KINK_KERNEL,
            "{kink}"
        );
    }

    #[test]
    fn a_knot_whose_only_jump_is_in_the_third_derivative_is_kept_where_it_matters() {
        let config = TracerConfig::default();
        // A knot of the stress suite's 0.5 m levels at 34 m: curvature continuous to 3e-15 m⁻²,
        // d³n/dh³ jumps by 9e-11 m⁻³.
        let knot = MinorBreak {
            height_m: 34.0,
            curvature_jump_per_m2: 3.3e-15,
            curvature_kink_per_m3: 9e-11,
        };
        let at = |tolerance_m: f64| TracerConfig {
            tolerance_m,
            ..config.clone()
        };
        for tolerance_m in [0.1, 1e-2, 1e-3] {
            let kept = settle(&[], &[knot], &at(tolerance_m), config.error_length_m);
            assert_eq!(kept, vec![34.0], "tolerance {tolerance_m}");
        }
        let smooth = MinorBreak {
            curvature_kink_per_m3: 0.0,
            ..knot
        };
        assert!(settle(&[], &[smooth], &at(1e-2), config.error_length_m).is_empty());
        assert!(settle(&[], &[knot], &at(10.0), config.error_length_m).is_empty());
    }

    fn minor(height_m: f64, curvature_jump_per_m2: f64) -> MinorBreak {
        MinorBreak {
            height_m,
            curvature_jump_per_m2,
            curvature_kink_per_m3: 0.0,
        }
    }

    /// The worst-case direction error of one straddle, as `settle` bounds it.
    fn worst(b: &MinorBreak, c: &TracerConfig) -> f64 {
        let k = c.vertical_step_per_height;
        let cap = ((c.vertical_step_base_m + k * b.height_m) / (1.0 - k)).min(c.max_step_m);
        let jump = STRADDLE_KERNEL * b.curvature_jump_per_m2 * cap * c.max_step_m;
        jump + STRADDLE_KINK_KERNEL * b.curvature_kink_per_m3 * cap * cap * c.max_step_m
    }

    #[test]
    fn settle_keeps_major_breaks_and_drops_only_what_fits_the_budget() {
        let config = TracerConfig::default();
        let minor: Vec<MinorBreak> = (1..=400)
            .map(|i| minor(25.0 * i as f64, 1e-16 * (i % 7 + 1) as f64))
            .chain([minor(10_500.0, 3.5e-14), minor(30.0, 1e-2)])
            .collect();
        let major = [100.0, 11_000.0];
        let at = |tolerance_m: f64| TracerConfig {
            tolerance_m,
            ..config.clone()
        };
        for tolerance_m in [1.0, 1e-3, 1e-5, 1e-7] {
            let per_m = tolerance_m / config.error_length_m;
            let kept = settle(&major, &minor, &at(tolerance_m), config.error_length_m);
            assert!(kept.windows(2).all(|w| w[0] < w[1]), "ascending, distinct");
            assert!(major.iter().all(|b| kept.contains(b)));
            assert!(kept.contains(&30.0), "a 30 K jump's knot is always kept");
            let dropped: f64 = minor
                .iter()
                .filter(|b| !kept.contains(&b.height_m))
                .map(|b| worst(b, &config))
                .sum();
            assert!(
                dropped <= STRADDLE_SHARE * per_m,
                "{dropped:e} at {tolerance_m}"
            );
        }
        let loose = settle(&major, &minor, &at(1.0), config.error_length_m);
        let tight = settle(&major, &minor, &at(1e-7), config.error_length_m);
        assert!(
            loose.iter().all(|b| tight.contains(b)),
            "tighter keeps more"
        );
        assert!(loose.len() < tight.len());
        assert!(!loose.contains(&10_500.0) && tight.contains(&10_500.0));
    }
}
