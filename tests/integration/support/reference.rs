//! An independent reference ray tracer for spherically stratified air, to check the project's
//! tracer against. It shares no code with `ghostship::tracer` and uses another formulation.
//!
//! # Formulation
//! Polar coordinates about Earth's centre, r = R + h, with the angle θ around the centre as the
//! independent variable and ' = d/dθ. Along a ray, tan ψ = r'/r (ψ = local elevation), and
//! Bouguer's invariant n·r·cos ψ = c gives (r')² = r²(n²r²/c² − 1). Differentiating in θ and
//! using n²r⁴/c² = r² + r'² removes c:
//!
//! ```text
//! h'' = r'' = (r'² + r²)·(dn/dh)/n + 2·r'²/r + r,   h(0) = h₀,  h'(0) = (R + h₀)·tan α,
//! ```
//!
//! a second-order ODE that is regular at apexes and perigees (no square root, no turning-point
//! event). It is integrated in the height u = h (not r, which would cost six digits) and its
//! derivative v = h' (m rad⁻¹) to θ = D/R for each ground distance D. The right-hand side does not
//! depend on θ.
//!
//! # Integrator
//! Butcher's seven-stage, sixth-order explicit Runge–Kutta method (rational coefficients; all 37
//! order conditions up to order six hold exactly, checked with exact fractions). The step is a
//! smooth function of the state, Δθ = 1 / (R/Δx + |v|/Δh): at most Δx of ground distance and
//! at most about Δh of height change per step ([`ReferenceSteps`], default 200 m and 0.2 m), so
//! thin layers are sampled finely however steep the ray (optionally with a smaller Δh for steps
//! that start below a given height, [`FineSteps`], for layers thinner than Δh). Halving the
//! limits halves every step, and the difference of the two runs is the error estimate of
//! [`reference_heights_with_error`].
//!
//! # Breaks
//! A step that straddles a break of the index (a height where dn/dh or d²n/dh² jumps, listed in
//! [`ReferenceIndex::breaks_m`]) would drop to first or second order, so steps end on every break
//! the ray meets. A trial step whose cubic Hermite interpolant (end heights and slopes) leaves the
//! current layer — at its end, or through an apex or perigee inside the step that pokes across a
//! break and back — is confirmed with a Runge–Kutta step to that point and then cut at the first
//! crossing, found by a bracketed Newton iteration on the step length (each iterate a full
//! Runge–Kutta step from the same start; the derivative of its end height is its end slope v) to
//! 1e-13 m (or four rounding units of the break height). The height is set to the break exactly
//! and integration continues in the next layer. Each step evaluates n only inside its own layer,
//! at least 1 nm from its bounds, so a step that starts on a break sees the right side; a stage
//! that overshoots the layer (the last stages of a step ending on a bound do, by up to
//! millimetres) gets the layer's own quadratic continuation from the edge (value, slope and a
//! one-sided difference of dn/dh), not the neighbour's values and not a constant. The ground
//! (h = 0) and the top (`top_m`) are located the same way and end the ray. A level ray launched
//! exactly on a break that bends it down above and up below would slide along the break; the
//! reference then panics rather than loop.
//!
//! # Validity
//! θ grows monotonically along every ray that is not vertical, but v = r·tan ψ grows without
//! bound towards the vertical and the height limit then makes the steps tiny: the formulation is
//! meant for near-horizontal rays (|α| ≲ 10°) and fails for near-vertical ones; it refuses
//! |α| ≥ 60°. n above `top_m` is never used: the reference stops there.
//!
//! # Measured accuracy and cost
//! From tests/integration/reference_tracer.rs, with the default steps, against exact closed
//! forms (largest |Δh| up to 30 km / up to 300 km):
//! * uniform n (straight lines, 0°…10°): 3e-10 m / 1.1e-9 m;
//! * n ∝ 1/r (level rays stay level, others are spirals): 3e-13 m / 1.1e-11 m;
//! * a three-layer piecewise power law n ∝ r^k (dn/dh −1e-7, −4e-7, −0.5e-7 m⁻¹; kinks at 40 and
//!   120 m; 19 rays: ducted, grounded, escaping, launched on a break, and one whose perigees dip
//!   0.05 mm below a break 5801 times): 1.7e-10 m / 4.6e-9 m (4e-11 m / 5e-10 m without that
//!   grazing ray). Without its break list the same rays are off by 5 cm.
//!
//! The asserted bounds are 1e-7 m (30 km) and 1e-6 m (300 km). The step-halving estimate in the
//! modelled atmospheres (paper atmospheres, fitted soundings, US1976; exact Ciddor) stays below
//! 2e-9 m up to 30 km and 1.5e-8 m up to 300 km, and shrinks 2⁶-fold per halving.
//! Cost: 3900–4600 evaluations of n per ray to 30 km (fan −0.5°…+0.5° from 20 m), i.e. a
//! 200-ray fan in ≈ 0.15–0.2 s for a paper atmosphere (≈ 0.2 µs per exact evaluation) and
//! ≈ 0.4 s for the 1-second Bjørnøya sounding (≈ 0.46 µs, 2077 knots), single-threaded.
//! [`reference_heights_with_error`] costs three times as much.
//!
//! [`atmosphere_index`] builds the index of a [`RefractiveAtmosphere`] from its exact (Ciddor)
//! evaluation with the breaks of the column it was built on ([`BreakSource`], which documents
//! where each kind of column has them).

use ghostship::profile::us1976::US1976_EARTH_RADIUS_M;
use ghostship::profile::{
    AirColumn, Background, MODEL_TOP_M, Profile, StandardAtmosphere, SyntheticAtmosphere,
    SyntheticLayer,
};
use ghostship::refractivity::RefractiveAtmosphere;

/// A stratified refractive index for the reference tracer.
pub struct ReferenceIndex<'a> {
    /// n and dn/dh (m⁻¹) at a height above the surface (m).
    pub n_and_dndh: Box<dyn Fn(f64) -> (f64, f64) + Sync + 'a>,
    /// Heights above the surface (m), ascending, where dn/dh or d²n/dh² is discontinuous.
    pub breaks_m: Vec<f64>,
}

impl<'a> ReferenceIndex<'a> {
    /// An index from `n_and_dndh` with the given breaks (sorted here; duplicates removed).
    pub fn new(n_and_dndh: impl Fn(f64) -> (f64, f64) + Sync + 'a, mut breaks_m: Vec<f64>) -> Self {
        assert!(
            breaks_m.iter().all(|b| b.is_finite()),
            "breaks must be finite"
        );
        breaks_m.sort_by(f64::total_cmp);
        breaks_m.dedup_by(|a, b| (*a - *b).abs() < 4.0 * NUDGE_M);
        ReferenceIndex {
            n_and_dndh: Box::new(n_and_dndh),
            breaks_m,
        }
    }
}

/// What the reference found at one requested distance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RefReach {
    /// The ray's height above the surface there (m).
    Height(f64),
    /// The ray reached the ground before this distance.
    GroundBefore,
    /// The ray climbed through the top before this distance.
    EscapedBefore,
}

impl RefReach {
    /// The height, if the ray got there.
    pub fn height_m(self) -> Option<f64> {
        match self {
            RefReach::Height(h) => Some(h),
            _ => None,
        }
    }
}

/// Step limits of the reference: every step is Δθ = 1 / (R/Δx + |v|/Δh).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReferenceSteps {
    /// Δx: the largest ground distance of one step (m).
    pub max_ground_step_m: f64,
    /// Δh: the largest height change of one step (m), approached by steep rays.
    pub max_height_step_m: f64,
    /// A smaller Δh for steps that start low down, where layers may be thinner than
    /// `max_height_step_m`: a step that crosses such a layer whole is cut at its two breaks and
    /// never subdivides it, so halving the steps would not show the error made there.
    pub fine: Option<FineSteps>,
}

/// A smaller height-step limit for the steps that start below a height.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FineSteps {
    /// Steps starting below this height above the surface (m) …
    pub below_m: f64,
    /// … change the height by at most this (m) (the smaller of it and the general limit).
    pub max_height_step_m: f64,
}

impl Default for ReferenceSteps {
    /// 200 m of ground, 0.2 m of height (see the module documentation for the accuracy).
    fn default() -> Self {
        ReferenceSteps {
            max_ground_step_m: 200.0,
            max_height_step_m: 0.2,
            fine: None,
        }
    }
}

impl ReferenceSteps {
    /// Every limit halved (every step exactly half as long).
    pub fn halved(self) -> Self {
        ReferenceSteps {
            max_ground_step_m: 0.5 * self.max_ground_step_m,
            max_height_step_m: 0.5 * self.max_height_step_m,
            fine: self.fine.map(|f| FineSteps {
                max_height_step_m: 0.5 * f.max_height_step_m,
                ..f
            }),
        }
    }
}

/// The density-weighted path lengths ∫ e^(−h/H_k) ds (H = `scales`) of the independent
/// reference tracer's ray from `h0` at `alpha`, from heights every `step_m` of ground (segment
/// lengths from the polar geometry, midpoint weights): to `until_m` of ground, or to its end if
/// it ends before (the top, or the ground, found by extrapolating the last segment to h = 0).
/// Earth radius 6371 km, top 40 km (the renderer's).
pub fn reference_density_paths(
    index: &ReferenceIndex,
    h0: f64,
    alpha: f64,
    until_m: f64,
    step_m: f64,
    scales: [f64; 2],
) -> [f64; 2] {
    let radius = ghostship::units::EARTH_RADIUS_M;
    let top = 40_000.0;
    let n = (until_m / step_m).round() as usize;
    let distances: Vec<f64> = (0..=n).map(|i| i as f64 * step_m).collect();
    let reach = reference_heights(index, radius, top, h0, alpha, &distances);
    let mut points: Vec<(f64, f64)> = std::iter::once((0.0, h0))
        .chain(
            reach
                .iter()
                .zip(&distances)
                .skip(1)
                .map_while(|(r, &d)| r.height_m().map(|h| (d, h))),
        )
        .collect();
    let ended = points.len() <= n;
    if ended && reach[points.len()] == RefReach::GroundBefore {
        let [(d0, h0), (d1, h1)] = [points[points.len() - 2], points[points.len() - 1]];
        points.push((d1 + h1 * (d1 - d0) / (h0 - h1), 0.0));
    }
    let mut paths = [0.0; 2];
    for w in points.windows(2) {
        let ((d0, h0), (d1, h1)) = (w[0], w[1]);
        let mid = 0.5 * (h0 + h1);
        let ds = (h1 - h0).hypot((d1 - d0) * (radius + mid) / radius);
        for k in 0..2 {
            paths[k] += (-mid / scales[k]).exp() * ds;
        }
    }
    paths
}

/// A ray launched at `elevation_rad` from `observer_height_m` (above the surface) over a sphere
/// of `earth_radius_m`, through `index` up to `top_m`: what it does at each ground distance of
/// `distances_m` (ascending, ≥ 0; distance = R·θ), with the default steps.
pub fn reference_heights(
    index: &ReferenceIndex,
    earth_radius_m: f64,
    top_m: f64,
    observer_height_m: f64,
    elevation_rad: f64,
    distances_m: &[f64],
) -> Vec<RefReach> {
    reference_heights_with_steps(
        index,
        earth_radius_m,
        top_m,
        observer_height_m,
        elevation_rad,
        distances_m,
        ReferenceSteps::default(),
    )
}

/// As [`reference_heights`] with the given step limits.
pub fn reference_heights_with_steps(
    index: &ReferenceIndex,
    earth_radius_m: f64,
    top_m: f64,
    observer_height_m: f64,
    elevation_rad: f64,
    distances_m: &[f64],
    steps: ReferenceSteps,
) -> Vec<RefReach> {
    let ray = Ray::new(index, earth_radius_m, top_m, steps);
    ray.trace(observer_height_m, elevation_rad, distances_m)
}

/// As [`reference_heights`], each result with an error estimate (m): |h(steps) − h(steps/2)|
/// between a run with the default steps and one with half those steps (the returned result).
/// For a sixth-order method this is about 63× the error of the returned height; it is +∞ where
/// the two runs disagree on whether the ray got there, 0 where neither did.
pub fn reference_heights_with_error(
    index: &ReferenceIndex,
    earth_radius_m: f64,
    top_m: f64,
    observer_height_m: f64,
    elevation_rad: f64,
    distances_m: &[f64],
) -> Vec<(RefReach, f64)> {
    let (h0, a) = (observer_height_m, elevation_rad);
    let steps = ReferenceSteps::default();
    let coarse = Ray::new(index, earth_radius_m, top_m, steps).trace(h0, a, distances_m);
    let fine = Ray::new(index, earth_radius_m, top_m, steps.halved()).trace(h0, a, distances_m);
    coarse
        .into_iter()
        .zip(fine)
        .map(|(c, f)| (f, reach_difference(c, f)))
        .collect()
}

fn reach_difference(a: RefReach, b: RefReach) -> f64 {
    match (a, b) {
        (RefReach::Height(x), RefReach::Height(y)) => (x - y).abs(),
        (x, y) if x == y => 0.0,
        _ => f64::INFINITY,
    }
}

/// How far inside its layer n is always evaluated (m): far above the rounding of heights up to
/// 100 km (1.5e-11 m), far below any effect on the ray.
const NUDGE_M: f64 = 1e-9;
/// Step of the one-sided difference for d²n/dh² at a layer's edge (m).
const DIFFERENCE_M: f64 = 1e-4;
/// Crossings are located to this height (m).
const CROSSING_TOLERANCE_M: f64 = 1e-13;

/// Butcher's 7-stage, 6th-order explicit Runge–Kutta method: matrix rows and weights (nodes
/// 0, 1/3, 2/3, 1/3, 1/2, 1/2, 1 are the row sums; the ODE is autonomous, so they are not used).
const A: [[f64; 6]; 7] = [
    [0.0; 6],
    [1.0 / 3.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [0.0, 2.0 / 3.0, 0.0, 0.0, 0.0, 0.0],
    [1.0 / 12.0, 1.0 / 3.0, -1.0 / 12.0, 0.0, 0.0, 0.0],
    [-1.0 / 16.0, 9.0 / 8.0, -3.0 / 16.0, -3.0 / 8.0, 0.0, 0.0],
    [0.0, 9.0 / 8.0, -3.0 / 8.0, -3.0 / 4.0, 0.5, 0.0],
    [
        9.0 / 44.0,
        -9.0 / 11.0,
        63.0 / 44.0,
        18.0 / 11.0,
        0.0,
        -16.0 / 11.0,
    ],
];
const B: [f64; 7] = [
    11.0 / 120.0,
    0.0,
    27.0 / 40.0,
    27.0 / 40.0,
    -4.0 / 15.0,
    -4.0 / 15.0,
    11.0 / 120.0,
];

/// The ray's state: angle θ (rad), height u (m) and v = du/dθ (m rad⁻¹).
#[derive(Debug, Clone, Copy)]
struct State {
    theta: f64,
    u: f64,
    v: f64,
}

/// How a march towards a target angle ended.
enum March {
    /// At the target, in this layer.
    Reached(State, usize),
    Ground,
    Escaped,
}

/// One trace: the index, the geometry and the layer bounds [0, breaks…, top].
struct Ray<'i, 'a> {
    index: &'i ReferenceIndex<'a>,
    radius: f64,
    bounds: Vec<f64>,
    inv_ground_step: f64,
    inv_height_step: f64,
    /// Below this height, `inv_fine_height_step` replaces `inv_height_step` (if larger).
    fine_below_m: f64,
    inv_fine_height_step: f64,
}

impl<'i, 'a> Ray<'i, 'a> {
    fn new(index: &'i ReferenceIndex<'a>, radius: f64, top_m: f64, steps: ReferenceSteps) -> Self {
        assert!(
            radius > 0.0 && top_m > 0.0,
            "radius and top must be positive"
        );
        assert!(steps.max_ground_step_m > 0.0 && steps.max_height_step_m > 0.0);
        let fine = steps.fine.unwrap_or(FineSteps {
            below_m: f64::NEG_INFINITY,
            max_height_step_m: steps.max_height_step_m,
        });
        assert!(fine.max_height_step_m > 0.0);
        let inside = |b: &&f64| **b > 4.0 * NUDGE_M && **b < top_m - 4.0 * NUDGE_M;
        let mut bounds = vec![0.0];
        bounds.extend(index.breaks_m.iter().filter(inside));
        bounds.push(top_m);
        // The fields are public: do not rely on `ReferenceIndex::new` having sorted them.
        bounds.sort_by(f64::total_cmp);
        Ray {
            index,
            radius,
            bounds,
            inv_ground_step: radius / steps.max_ground_step_m,
            inv_height_step: 1.0 / steps.max_height_step_m,
            fine_below_m: fine.below_m,
            inv_fine_height_step: 1.0 / fine.max_height_step_m,
        }
    }

    fn trace(&self, h0: f64, elevation: f64, distances_m: &[f64]) -> Vec<RefReach> {
        let top = self.bounds[self.bounds.len() - 1];
        assert!(
            (0.0..top).contains(&h0),
            "observer {h0} m outside [0, {top}) m"
        );
        assert!(
            elevation.abs() < 60f64.to_radians(),
            "elevation out of range"
        );
        assert!(
            distances_m.windows(2).all(|w| w[0] <= w[1]) && distances_m.iter().all(|d| *d >= 0.0)
        );
        let mut state = State {
            theta: 0.0,
            u: h0,
            v: (self.radius + h0) * elevation.tan(),
        };
        let mut layer = self.start_layer(&state);
        let mut out = Vec::with_capacity(distances_m.len());
        for &d in distances_m {
            match self.march(state, layer, d / self.radius) {
                March::Reached(s, l) => {
                    (state, layer) = (s, l);
                    out.push(RefReach::Height(s.u));
                }
                March::Ground => break,
                March::Escaped => {
                    out.resize(distances_m.len(), RefReach::EscapedBefore);
                    return out;
                }
            }
        }
        out.resize(distances_m.len(), RefReach::GroundBefore);
        out
    }

    /// The layer of the start; on a break, the side the ray moves into (for v = 0, up if the
    /// upper side curves it upward).
    fn start_layer(&self, s: &State) -> usize {
        let j = self.bounds.partition_point(|&b| b <= s.u) - 1;
        let on_break = j > 0 && s.u == self.bounds[j];
        let goes_down = s.v < 0.0 || (s.v == 0.0 && self.accel(s.u, 0.0, j) < 0.0);
        if on_break && goes_down { j - 1 } else { j }
    }

    /// u'' in layer `j`.
    fn accel(&self, u: f64, v: f64, j: usize) -> f64 {
        let (n, dndh) = self.index_in_layer(u, j);
        let r = self.radius + u;
        dndh / n * (r * r + v * v) + 2.0 * v * v / r + r
    }

    /// n and dn/dh of layer `j` at `u`, evaluated at least `NUDGE_M` inside the layer. A stage
    /// height beyond the layer (Runge–Kutta stages overshoot the end of a step that ends on a
    /// bound) gets the layer's own quadratic continuation, from n, dn/dh and a one-sided
    /// difference for d²n/dh² at its edge: a constant continuation would err by d²n/dh²·overshoot,
    /// the neighbour's values by the jump.
    fn index_in_layer(&self, u: f64, j: usize) -> (f64, f64) {
        let (lo, hi) = (self.bounds[j] + NUDGE_M, self.bounds[j + 1] - NUDGE_M);
        let edge = u.clamp(lo, hi);
        let (n, dndh) = (self.index.n_and_dndh)(edge);
        let overshoot = u - edge;
        if overshoot == 0.0 {
            return (n, dndh);
        }
        let step = overshoot.signum() * DIFFERENCE_M.min(0.25 * (hi - lo));
        let (_, inner) = (self.index.n_and_dndh)(edge - step);
        let curvature = (dndh - inner) / step;
        (
            n + overshoot * (dndh + 0.5 * curvature * overshoot),
            dndh + curvature * overshoot,
        )
    }

    /// One Runge–Kutta step of length `s` (rad) in layer `j`.
    fn rk_step(&self, y: &State, s: f64, j: usize) -> State {
        let mut ku = [0.0; 7];
        let mut kv = [0.0; 7];
        for i in 0..7 {
            let (mut u, mut v) = (y.u, y.v);
            for m in 0..i {
                u += s * A[i][m] * ku[m];
                v += s * A[i][m] * kv[m];
            }
            ku[i] = v;
            kv[i] = self.accel(u, v, j);
        }
        let (mut u, mut v) = (y.u, y.v);
        for i in 0..7 {
            u += s * B[i] * ku[i];
            v += s * B[i] * kv[i];
        }
        State {
            theta: y.theta + s,
            u,
            v,
        }
    }

    /// The step length the step rule gives at height `u` and slope `v`.
    fn step_rule(&self, u: f64, v: f64) -> f64 {
        let inv_height = if u < self.fine_below_m {
            self.inv_height_step.max(self.inv_fine_height_step)
        } else {
            self.inv_height_step
        };
        1.0 / (self.inv_ground_step + v.abs() * inv_height)
    }

    /// Integrate from `state` in `layer` to angle `target`, crossing breaks on the way.
    fn march(&self, mut state: State, mut layer: usize, target: f64) -> March {
        let mut stalled = 0;
        while state.theta < target {
            let rest = target - state.theta;
            let s = self.step_rule(state.u, state.v).min(rest);
            let trial = self.rk_step(&state, s, layer);
            let Some(bracket) = self.exit_bracket(&state, &trial, s, layer) else {
                state = trial;
                if s == rest {
                    state.theta = target;
                }
                continue;
            };
            let (crossed, bound) = self.locate_crossing(&state, bracket, layer);
            stalled = if crossed.theta > state.theta {
                0
            } else {
                stalled + 1
            };
            assert!(
                stalled < 8,
                "ray trapped on the break at {} m",
                self.bounds[bound]
            );
            state = State {
                u: self.bounds[bound],
                ..crossed
            };
            if bound == 0 {
                return March::Ground;
            }
            if bound == self.bounds.len() - 1 {
                return March::Escaped;
            }
            layer = if bound == layer { layer - 1 } else { layer + 1 };
        }
        March::Reached(state, layer)
    }

    fn outside(&self, u: f64, j: usize) -> bool {
        u < self.bounds[j] || u > self.bounds[j + 1]
    }

    /// If the step `start → end` (length `s`) leaves layer `j`: the step lengths and Runge–Kutta
    /// end points of a bracket of the first exit, one inside the layer and one outside.
    fn exit_bracket(&self, start: &State, end: &State, s: f64, j: usize) -> Option<Bracket> {
        let hermite = Hermite::new(start, end, s);
        let mut inside = *start;
        if let Some(sigma) = hermite.extremum()
            && self.outside(hermite.at(sigma), j)
        {
            let mid = self.rk_step(start, sigma * s, j);
            if self.outside(mid.u, j) {
                return Some(Bracket {
                    inside,
                    outside: mid,
                });
            }
            inside = mid;
        }
        self.outside(end.u, j).then_some(Bracket {
            inside,
            outside: *end,
        })
    }

    /// The state where the ray leaves layer `j` from `start` within `bracket`, and the index of
    /// the bound it crosses there.
    fn locate_crossing(&self, start: &State, bracket: Bracket, j: usize) -> (State, usize) {
        let Bracket { inside, outside } = bracket;
        let bound = if outside.u > self.bounds[j + 1] {
            j + 1
        } else {
            j
        };
        let b = self.bounds[bound];
        let tolerance = CROSSING_TOLERANCE_M + 4.0 * f64::EPSILON * b.abs();
        let (mut lo, mut hi) = (inside.theta - start.theta, outside.theta - start.theta);
        let span = hi;
        // First guess: the secant between the bracket's ends; then Newton, bisecting whenever
        // an iterate would leave the bracket.
        let mut s = lo + (hi - lo) * (b - inside.u) / (outside.u - inside.u);
        let mut y = outside;
        for _ in 0..60 {
            if !(s > lo && s < hi) {
                s = 0.5 * (lo + hi);
            }
            y = self.rk_step(start, s, j);
            let miss = y.u - b;
            if miss.abs() <= tolerance || hi - lo <= 1e-15 * span {
                break;
            }
            if self.outside(y.u, j) {
                hi = s;
            } else {
                lo = s;
            }
            s -= miss / y.v;
        }
        (y, bound)
    }
}

/// Two Runge–Kutta end points from the same start, inside and outside the current layer.
struct Bracket {
    inside: State,
    outside: State,
}

/// The cubic Hermite of height over a step, in σ ∈ [0, 1].
struct Hermite {
    u0: f64,
    d0: f64,
    u1: f64,
    d1: f64,
}

impl Hermite {
    fn new(a: &State, b: &State, s: f64) -> Self {
        Hermite {
            u0: a.u,
            d0: a.v * s,
            u1: b.u,
            d1: b.v * s,
        }
    }

    fn at(&self, t: f64) -> f64 {
        let (t2, t3) = (t * t, t * t * t);
        self.u0 * (2.0 * t3 - 3.0 * t2 + 1.0)
            + self.d0 * (t3 - 2.0 * t2 + t)
            + self.u1 * (3.0 * t2 - 2.0 * t3)
            + self.d1 * (t3 - t2)
    }

    /// The σ in (0, 1) where the slope changes sign, if the end slopes differ in sign.
    fn extremum(&self) -> Option<f64> {
        if self.d0 * self.d1 >= 0.0 {
            return None;
        }
        // p'(σ) = a σ² + b σ + c with one root in (0, 1); bisection is exact enough and safe.
        let slope = |t: f64| {
            6.0 * (self.u0 - self.u1) * (t * t - t)
                + self.d0 * (3.0 * t * t - 4.0 * t + 1.0)
                + self.d1 * (3.0 * t * t - 2.0 * t)
        };
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            if (slope(mid) > 0.0) == (self.d0 > 0.0) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(0.5 * (lo + hi))
    }
}

/// Which air column a [`RefractiveAtmosphere`] was built on, for its breaks (the column itself
/// cannot be recovered from the atmosphere's `Arc<dyn AirColumn>`). Every column also breaks at
/// 86 km ([`MODEL_TOP_M`]), above which its air is held constant.
///
/// Not listed, because their heights are not in the public API: the nodes of the hydrostatic
/// ln P tables (a cubic Hermite with exact slopes, so d²n/dh² jumps by a tiny amount at each):
/// 0.25 m / 10 m apart in a synthetic atmosphere, 5 m / 20 m above a sounding's top. Cutting the
/// steps at them changes a Fata Morgana fan by ≤ 3.4e-10 m at 30 km (measured in the tests).
#[derive(Clone, Copy)]
pub enum BreakSource<'c> {
    /// A fitted sounding: T, ln P and e are PCHIP cubics (C¹) with a knot at every level
    /// ([`Profile::levels`]; smoothing moves values, not knots), so d²n/dh² jumps at each; the
    /// vapour rules switch at the lowest and highest humidity levels (also knots), and the blend
    /// above the top of the data (a knot) carries the kinks of US1976 at its layer bases.
    Profile(&'c Profile),
    /// A synthetic atmosphere: tanh step layers are smooth; constant-gradient layers break at
    /// both bounds; a lapse-rate background at its tropopause, then at the US1976 bases above
    /// it; a US1976 background at its bases.
    Synthetic(&'c SyntheticAtmosphere),
    /// The standard atmosphere (any surface): its layer bases.
    Standard(&'c StandardAtmosphere),
}

impl BreakSource<'_> {
    fn column(&self) -> &dyn AirColumn {
        match *self {
            BreakSource::Profile(p) => p,
            BreakSource::Synthetic(s) => s,
            BreakSource::Standard(s) => s,
        }
    }

    /// Heights above mean sea level (m) where the column's dn/dh or d²n/dh² jumps (unsorted;
    /// may include heights below the surface).
    pub fn breaks_msl_m(&self) -> Vec<f64> {
        let mut out = vec![MODEL_TOP_M];
        match *self {
            BreakSource::Profile(p) => {
                out.extend(p.levels().iter().map(|k| k.height_m));
                out.extend(us1976_bases_m().filter(|&b| b > p.top_of_data_m()));
            }
            BreakSource::Synthetic(s) => out.extend(synthetic_breaks_m(s)),
            BreakSource::Standard(_) => out.extend(us1976_bases_m()),
        }
        out
    }
}

/// Geometric heights (m) of the US1976 layer bases at 11, 20, 32, 47, 51 and 71 km geopotential.
pub fn us1976_bases_m() -> impl Iterator<Item = f64> {
    let r0 = US1976_EARTH_RADIUS_M;
    [11e3, 20e3, 32e3, 47e3, 51e3, 71e3]
        .into_iter()
        .map(move |g: f64| r0 * g / (r0 - g))
}

/// The breaks of a synthetic atmosphere (m above mean sea level): the bounds of its
/// constant-gradient layers, the tropopause of a lapse-rate background and the US1976 bases of
/// the background above it. tanh step layers are smooth.
fn synthetic_breaks_m(s: &SyntheticAtmosphere) -> Vec<f64> {
    let mut out = Vec::new();
    for layer in s.layers() {
        if let SyntheticLayer::Gradient { from_m, to_m, .. } = *layer {
            out.extend([from_m, to_m]);
        }
    }
    let above = match s.background() {
        Background::Lapse { tropopause_m, .. } => {
            out.push(tropopause_m);
            tropopause_m
        }
        Background::Us1976 => s.surface_height_m(),
    };
    out.extend(us1976_bases_m().filter(|&b| b > above));
    out
}

/// The reference index of `atm`: its exact evaluation ([`RefractiveAtmosphere::exact`], the
/// Ciddor formula on the column, not the table) with the breaks of the column it was built on,
/// converted to heights above the surface. Panics if `source` is not that column (compared by
/// their air at a few heights).
pub fn atmosphere_index<'a>(
    atm: &'a RefractiveAtmosphere,
    source: BreakSource<'_>,
) -> ReferenceIndex<'a> {
    let column = source.column();
    for h in [0.0, 37.0, 555.5, 4321.0] {
        let msl = atm.surface_height_m() + h;
        assert!(
            column.air_at(msl) == atm.column().air_at(msl),
            "the break source is not the atmosphere's column"
        );
    }
    let surface = atm.surface_height_m();
    let breaks = source
        .breaks_msl_m()
        .into_iter()
        .map(|b| b - surface)
        .filter(|&b| b > 0.0)
        .collect();
    ReferenceIndex::new(move |h| atm.exact(h), breaks)
}

/// The direction (elevation in rad against the observer's horizontal plane) in which a ray
/// launched upwards at apparent elevation `alpha` ≥ 0 from `h0` (m above the surface) leaves
/// the top `top_m` of the index `n(h)`, over a sphere of `earth_radius_m`: from Bouguer's
/// invariant c = n r cos ψ alone (no ray integration, so independent of both tracers). The
/// angle the ray sweeps about the centre is the refraction integral
/// θ = ∫ c dr / (r √(n²r² − c²)) from r₀ to the top, taken in t with r = r₀ + t² (regular at
/// a horizontal start) by composite Simpson on `intervals` intervals; out of the top into
/// vacuum the ray's elevation is ψ = acos(c / r_t), against the observer's horizontal plane
/// ψ − θ.
pub fn bouguer_escape_elevation(
    n: &dyn Fn(f64) -> f64,
    earth_radius_m: f64,
    top_m: f64,
    h0: f64,
    alpha: f64,
    intervals: usize,
) -> f64 {
    assert!(alpha >= 0.0 && intervals.is_multiple_of(2));
    let r0 = earth_radius_m + h0;
    let c = n(h0) * r0 * alpha.cos();
    let t_top = (top_m - h0).sqrt();
    let g = |t: f64| {
        let r = r0 + t * t;
        let nr = n(r - earth_radius_m) * r;
        let root = ((nr - c) * (nr + c)).max(0.0).sqrt();
        if t == 0.0 {
            // The limit 2c / (r₀ √(d(n²r²)/dr)) of a horizontal start (0 for alpha > 0).
            if root > 0.0 {
                return 0.0;
            }
            let dr = 1e-3;
            let r1 = r0 + dr;
            let nr1 = n(r1 - earth_radius_m) * r1;
            let slope = (nr1 * nr1 - c * c) / dr;
            return 2.0 * c / (r0 * slope.sqrt());
        }
        2.0 * t * c / (r * root)
    };
    let step = t_top / intervals as f64;
    let mut sum = g(0.0) + g(t_top);
    for i in 1..intervals {
        sum += g(i as f64 * step) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    let theta = sum * step / 3.0;
    // Out of the top into vacuum (n = 1): the invariant holds across the boundary.
    let psi_out = (c / (earth_radius_m + top_m)).min(1.0).acos();
    psi_out - theta
}
