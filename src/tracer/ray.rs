//! Stage 4 (trace), the ray loop: adaptive Dormand–Prince integration of one ray with exact
//! event location, typed termination and a per-ray record.
//!
//! In: a ray system (planar or 3-D, see `system`), a launch state, a [`TracerConfig`], sorted
//! ground distances at which the caller wants the ray's height, and an optional [`RayHook`].
//! Out: a [`RayRecord`] (heights at the distances, end point and direction, refraction of escaped
//! rays, step counts, drift of Bouguer's invariant) and optionally the sampled path.
//!
//! Error control bounds the error **at the targets**, not per step. The tolerance T =
//! `tolerance_m` is spread over a path length L (the larger of `error_length_m` and the farthest
//! requested distance): a step of length h is accepted when its estimated error is at most
//! T·h/L ("error per unit step"), counting a position error as itself and a direction error ε
//! as ε·L, the position error it grows into over L. The step errors of a ray then add up to at
//! most T over L (steps under 1 m get the budget of a 1 m step), and the estimate (the embedded 4th-order solution's error) overstates the
//! error of the 5th-order solution that is propagated, which leaves a margin; the tests check
//! the result against an independent reference tracer. Steps also end on every break of the
//! field (see `breaks`), where a step that straddled it would lose the method's order.
//!
//! Events are searched on the step's 4th-order continuous extension: a sign change of the event
//! function between the ends of a step, or — for the ground and the top, which a ray can touch and
//! leave within one step — an extremum of the height inside the step (found as the root of the
//! vertical direction component) that crosses the level. Roots are refined with the Illinois
//! variant of regula falsi to 1e-9 m along the ray.

use std::cell::Cell;
use std::fmt;

use serde::Serialize;

use super::breaks::{Bracket, Exit};
use super::climb_out::climb_out;
use super::dopri::{Controller, Dense, Step};
use super::system::{Observables, RaySystem};
use crate::profile::FineZone;

/// Settings of the tracer. All lengths in metres.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TracerConfig {
    /// Earth radius (m).
    pub earth_radius_m: f64,
    /// Top of the atmosphere above the surface (m); above it n = 1.
    pub top_m: f64,
    /// Error tolerance (m) on the ray's height at the requested distances (the paper used 1 cm
    /// per step); see the module docs for how it is met.
    pub tolerance_m: f64,
    /// Path length over which the error budget `tolerance_m` is spread (m): each step may make
    /// an error of `tolerance_m` × its length / this, and a direction error counts as the
    /// position error it grows into over this length. The length used is the larger of this and
    /// the farthest requested distance. See the module docs.
    pub error_length_m: f64,
    /// Longest step (m). Longer caps (20 km was tried) save steps on long ducted rays but let the
    /// error control's estimate miss at tolerances ≤ 1e-4 m (the stress suite shows it).
    pub max_step_m: f64,
    /// Shortest step (m); a step below it ends the ray with [`Termination::StepUnderflow`].
    pub min_step_m: f64,
    /// First trial step (m); the controller adapts from there.
    pub initial_step_m: f64,
    /// Largest height change per step near the ground (m). A step could otherwise jump over a thin
    /// layer that none of its stages samples; the limit grows with height (next field).
    pub vertical_step_base_m: f64,
    /// Growth of the per-step height limit with height: limit = base + this × h (sounding
    /// resolution also coarsens with height).
    pub vertical_step_per_height: f64,
    /// Longest path along the ray (m).
    pub max_length_m: f64,
    /// Stop when the ground distance reaches this (m), if set: [`Termination::MaxDistance`].
    pub max_distance_m: Option<f64>,
    /// Most steps (accepted + rejected) per ray.
    pub max_steps: u32,
    /// End the ray as soon as it has reached the last requested distance.
    pub stop_after_last_target: bool,
    /// Extra interpolated points per step in recorded paths (0: step ends only).
    pub path_samples_per_step: u32,
}

impl Default for TracerConfig {
    fn default() -> Self {
        TracerConfig {
            earth_radius_m: crate::units::EARTH_RADIUS_M,
            top_m: 40_000.0,
            tolerance_m: 1e-3,
            error_length_m: 30_000.0,
            max_step_m: 2_000.0,
            min_step_m: 1e-7,
            initial_step_m: 1.0,
            vertical_step_base_m: 2.0,
            vertical_step_per_height: 0.05,
            max_length_m: 10_000_000.0,
            max_distance_m: None,
            max_steps: 200_000,
            stop_after_last_target: true,
            path_samples_per_step: 0,
        }
    }
}

/// Invalid tracer input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TracerError {
    /// A configuration value is out of range.
    #[error("invalid tracer setting {name} = {value}: {reason}")]
    InvalidConfig {
        /// The setting.
        name: &'static str,
        /// Its value.
        value: f64,
        /// What is wrong.
        reason: &'static str,
    },
    /// The observer is below the ground or at/above the top of the atmosphere.
    #[error("observer height {height_m} m is outside the atmosphere [0, {top_m}) m")]
    ObserverOutside {
        /// Observer height (m).
        height_m: f64,
        /// Top of the atmosphere (m).
        top_m: f64,
    },
    /// The launch elevation or direction is not finite (or is a zero vector).
    #[error("ray direction is not finite or zero")]
    BadDirection,
    /// The requested distances are not finite, negative or not ascending.
    #[error("target distances must be finite, ≥ 0 and ascending")]
    BadDistances,
}

impl TracerConfig {
    /// Check every setting.
    pub fn validate(&self) -> Result<(), TracerError> {
        let positive: [(&'static str, f64); 8] = [
            ("earth_radius_m", self.earth_radius_m),
            ("top_m", self.top_m),
            ("tolerance_m", self.tolerance_m),
            ("error_length_m", self.error_length_m),
            ("max_step_m", self.max_step_m),
            ("min_step_m", self.min_step_m),
            ("initial_step_m", self.initial_step_m),
            ("vertical_step_base_m", self.vertical_step_base_m),
        ];
        for (name, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(TracerError::InvalidConfig {
                    name,
                    value,
                    reason: "must be finite and > 0",
                });
            }
        }
        if self.max_length_m.is_nan() || self.max_length_m <= 0.0 {
            return Err(TracerError::InvalidConfig {
                name: "max_length_m",
                value: self.max_length_m,
                reason: "must be > 0",
            });
        }
        if !(self.vertical_step_per_height.is_finite() && self.vertical_step_per_height >= 0.0) {
            return Err(TracerError::InvalidConfig {
                name: "vertical_step_per_height",
                value: self.vertical_step_per_height,
                reason: "must be finite and ≥ 0",
            });
        }
        if let Some(d) = self.max_distance_m
            && !(d.is_finite() && d > 0.0)
        {
            return Err(TracerError::InvalidConfig {
                name: "max_distance_m",
                value: d,
                reason: "must be finite and > 0",
            });
        }
        if self.min_step_m > self.max_step_m {
            return Err(TracerError::InvalidConfig {
                name: "min_step_m",
                value: self.min_step_m,
                reason: "must not exceed max_step_m",
            });
        }
        Ok(())
    }
}

/// Why a ray stopped. Every traced ray ends with exactly one of these.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Termination {
    /// Reached the ground (h = 0), which absorbs it.
    Ground,
    /// Left the top of the atmosphere (refracted into vacuum there).
    Escaped,
    /// Reached the last requested ground distance.
    TargetsDone,
    /// Reached `max_distance_m` still inside the atmosphere, its fate undecided (a safety limit).
    MaxDistance,
    /// Travelled `max_length_m` along the path.
    MaxLength,
    /// Used up `max_steps`.
    MaxSteps,
    /// The step size fell below `min_step_m`.
    StepUnderflow,
    /// The field or the state became NaN or infinite.
    NonFinite,
    /// The hook's event function crossed zero (e.g. the ray hit an object surface).
    Event,
    /// The hook asked to stop (e.g. the ray is above every object and climbing).
    LeftRegion,
    /// Past its last target, the ray provably oscillates between two turning points for ever
    /// (Bouguer's invariant, [`super::BouguerEnvelope`]): it is trapped in a duct.
    Trapped,
}

impl Termination {
    /// The snake_case name used in reports.
    pub fn name(self) -> &'static str {
        match self {
            Termination::Ground => "ground",
            Termination::Escaped => "escaped",
            Termination::TargetsDone => "targets_done",
            Termination::MaxDistance => "max_distance",
            Termination::MaxLength => "max_length",
            Termination::MaxSteps => "max_steps",
            Termination::StepUnderflow => "step_underflow",
            Termination::NonFinite => "non_finite",
            Termination::Event => "event",
            Termination::LeftRegion => "left_region",
            Termination::Trapped => "trapped",
        }
    }
}

impl fmt::Display for Termination {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A point on a ray.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct RayPoint {
    /// Path length from the observer (m).
    pub arc_length_m: f64,
    /// Ground distance from the observer, x = R·θ (m).
    pub distance_m: f64,
    /// Height above the ground (m).
    pub height_m: f64,
    /// Elevation of the ray direction above the local horizontal (rad).
    pub elevation_rad: f64,
}

/// The outcome of tracing one ray.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct RayRecord {
    /// Apparent elevation at the observer (rad).
    pub elevation_rad: f64,
    /// Why the ray stopped (`None` only in a record that was never traced).
    pub termination: Option<Termination>,
    /// Height at each requested distance (m); `None` where the ray ended before it.
    pub heights_m: Vec<Option<f64>>,
    /// Local elevation of the ray at each requested distance (rad); `None` as above.
    pub target_elevations_rad: Vec<Option<f64>>,
    /// Where the ray ended.
    pub end: RayPoint,
    /// Elevation of the final direction relative to the observer's horizontal (rad): the local
    /// elevation at the end (after refraction into vacuum for escaped rays) minus the angle θ the
    /// ray travelled around the Earth.
    pub end_observer_elevation_rad: f64,
    /// Astronomical refraction of an escaped ray, apparent minus true elevation (rad).
    pub refraction_rad: Option<f64>,
    /// Accepted steps.
    pub accepted_steps: u32,
    /// Rejected steps (including steps discarded because they straddled a break and were
    /// retaken shorter, to end on it).
    pub rejected_steps: u32,
    /// Breaks of the field (see [`StratifiedIndex::breaks_m`](super::StratifiedIndex::breaks_m))
    /// on which a step was ended.
    pub breaks_landed: u32,
    /// Largest |I − I₀| / (n₀ r₀) along the ray, I = n·r·cos ψ (Bouguer); only meaningful for
    /// spherically symmetric fields (on a flat Earth: Snell's n·cos ψ, relative to n₀).
    pub invariant_drift: f64,
    /// Whether the ray's local elevation left the sign it was launched with (it passed an apogee
    /// or perigee), checked at every accepted step and at the end; always true for a level
    /// launch. A ray that never turned climbed (or descended) the whole way.
    pub turned: bool,
}

impl RayRecord {
    /// Total steps (accepted + rejected).
    pub fn steps(&self) -> u32 {
        self.accepted_steps + self.rejected_steps
    }

    pub(crate) fn reset(&mut self, elevation_rad: f64, targets: usize) {
        self.elevation_rad = elevation_rad;
        self.termination = None;
        self.heights_m.clear();
        self.heights_m.resize(targets, None);
        self.target_elevations_rad.clear();
        self.target_elevations_rad.resize(targets, None);
        self.end = RayPoint::default();
        self.end_observer_elevation_rad = 0.0;
        self.refraction_rad = None;
        self.accepted_steps = 0;
        self.rejected_steps = 0;
        self.breaks_landed = 0;
        self.invariant_drift = 0.0;
        self.turned = elevation_rad.is_nan() || elevation_rad == 0.0;
    }

    /// Note the local elevation `elevation_rad` of a point on the ray.
    #[inline]
    fn note_elevation(&mut self, elevation_rad: f64) {
        let same_sign = (self.elevation_rad > 0.0 && elevation_rad > 0.0)
            || (self.elevation_rad < 0.0 && elevation_rad < 0.0);
        self.turned |= !same_sign;
    }
}

/// What a hook tells the tracer after a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HookAction {
    /// Keep tracing.
    Continue,
    /// Stop here with [`Termination::LeftRegion`].
    Stop,
    /// Stop here with [`Termination::Trapped`].
    Trapped,
    /// The ray provably climbs out through the top without turning again, and nothing below
    /// the top is left for it to meet: finish it in closed form (the refraction integral of a
    /// spherically symmetric field, `climb_out`) and end [`Termination::Escaped`] at the top.
    /// Ignored (the ray is integrated on) when the path is being recorded, on flat ground, or
    /// when the closed form cannot be evaluated. Heights at requested distances beyond this
    /// point are not reported.
    ClimbOut,
}

/// Caller-side control of a ray (the renderer's object surfaces and early stops).
pub trait RayHook {
    /// An event function of the ray state: the ray ends with [`Termination::Event`] where it
    /// changes sign between two points (located on the dense output). `None`: no event.
    fn event(&self, _point: &RayPoint) -> Option<f64> {
        None
    }
    /// Called after every accepted step with its start and end.
    fn after_step(&mut self, _from: &RayPoint, _to: &RayPoint) -> HookAction {
        HookAction::Continue
    }
}

/// The hook that does nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoHook;

impl RayHook for NoHook {}

fn finite<const N: usize>(y: &[f64; N]) -> bool {
    y.iter().all(|v| v.is_finite())
}

fn obs_finite(o: &Observables) -> bool {
    o.height_m.is_finite()
        && o.distance_m.is_finite()
        && o.elevation_rad.is_finite()
        && o.invariant.is_finite()
        && o.index.is_finite()
}

/// Root of `g` on [a, b] with g(a)·g(b) ≤ 0 (Illinois). `scale` converts a fraction to metres.
fn locate(mut g: impl FnMut(f64) -> f64, mut a: f64, mut b: f64, scale: f64) -> f64 {
    let mut ga = g(a);
    let mut gb = g(b);
    if ga == 0.0 {
        return a;
    }
    if gb == 0.0 {
        return b;
    }
    if !(ga.is_finite() && gb.is_finite()) || ga.signum() == gb.signum() {
        return b;
    }
    let mut side = 0i8;
    for _ in 0..200 {
        if (b - a).abs() * scale < 1e-9 {
            break;
        }
        let mut c = (a * gb - b * ga) / (gb - ga);
        if !(c > a.min(b) && c < a.max(b)) {
            c = 0.5 * (a + b);
        }
        let gc = g(c);
        if gc == 0.0 || !gc.is_finite() {
            return c;
        }
        if gc.signum() == gb.signum() {
            b = c;
            gb = gc;
            if side == -1 {
                ga *= 0.5;
            }
            side = -1;
        } else {
            a = c;
            ga = gc;
            if side == 1 {
                gb *= 0.5;
            }
            side = 1;
        }
    }
    // Return the end on the "before the event" side's far boundary: the crossing point.
    if ga.abs() < gb.abs() { a } else { b }
}

fn point(o: &Observables, arc_length_m: f64) -> RayPoint {
    RayPoint {
        arc_length_m,
        distance_m: o.distance_m,
        height_m: o.height_m,
        elevation_rad: o.elevation_rad,
    }
}

/// Fill the end of the record from the final state.
fn finish(
    rec: &mut RayRecord,
    kind: Termination,
    o: &Observables,
    arc_length_m: f64,
    elevation0: f64,
) {
    rec.termination = Some(kind);
    rec.end = point(o, arc_length_m);
    if kind == Termination::Escaped {
        // Snell at the top, spherical form: n·r·cos ψ is conserved across the interface (r equal).
        let cos_out = (o.index * o.elevation_rad.cos()).min(1.0);
        let psi_out = cos_out.acos().copysign(o.elevation_rad);
        rec.end_observer_elevation_rad = psi_out - o.angle_rad;
        rec.refraction_rad = Some(elevation0 - rec.end_observer_elevation_rad);
    } else {
        rec.end_observer_elevation_rad = o.elevation_rad - o.angle_rad;
        rec.refraction_rad = None;
    }
}

/// The path length over which a ray's error budget is spread: the larger of the setting and the
/// farthest target (see the module docs).
pub(crate) fn error_length_m(cfg: &TracerConfig, targets: &[f64]) -> f64 {
    targets
        .last()
        .map_or(cfg.error_length_m, |&d| d.max(cfg.error_length_m))
}

/// Integrate one ray. `y0` is the launch state, `elevation0` the apparent elevation (rad).
#[allow(clippy::too_many_arguments)]
pub(crate) fn integrate<const N: usize, Sys: RaySystem<N>, H: RayHook + ?Sized>(
    sys: &Sys,
    y0: [f64; N],
    elevation0: f64,
    cfg: &TracerConfig,
    targets: &[f64],
    hook: &mut H,
    rec: &mut RayRecord,
    mut path: Option<&mut Vec<RayPoint>>,
) {
    rec.reset(elevation0, targets.len());
    let top = cfg.top_m;
    let half = N / 2;
    let error_length = error_length_m(cfg, targets);
    // Error per unit length: a step of h may err by tolerance·h/L (see the module docs).
    let tolerance_per_m = cfg.tolerance_m / error_length;

    let mut y = y0;
    let mut obs = sys.observe(&y);
    // The interval between breaks the ray is in (on a break: the side it heads to) and, as a
    // `Layer`, the field every stage of a step sees: the interval's own, continued past its
    // bounds. Whenever the bracket moves, the layer follows and the first stage is re-evaluated.
    let mut bracket = Bracket::new(sys.breaks(), obs.height_m, sys.climb(&y) > 0.0);
    let layer = Cell::new(bracket.layer());
    let mut f = |y: &[f64; N]| sys.derivative(y, layer.get());
    let mut k1 = f(&y);
    if !(finite(&y) && finite(&k1) && obs_finite(&obs)) {
        rec.termination = Some(Termination::NonFinite);
        rec.end = RayPoint {
            elevation_rad: elevation0,
            ..RayPoint::default()
        };
        rec.end_observer_elevation_rad = elevation0;
        return;
    }
    let scale = sys.invariant_scale(&y);
    let invariant0 = obs.invariant;
    let mut cur = point(&obs, 0.0);
    if let Some(p) = path.as_deref_mut() {
        p.clear();
        p.push(cur);
    }
    // Targets at the observer's own distance.
    let mut next = 0;
    while next < targets.len() && targets[next] <= obs.distance_m {
        rec.heights_m[next] = Some(obs.height_m);
        rec.target_elevations_rad[next] = Some(obs.elevation_rad);
        next += 1;
    }
    if obs.height_m <= 0.0 && sys.climb(&y) < 0.0 {
        finish(rec, Termination::Ground, &obs, 0.0, elevation0);
        return;
    }
    if obs.height_m >= top && sys.climb(&y) > 0.0 {
        finish(rec, Termination::Escaped, &obs, 0.0, elevation0);
        return;
    }
    if cfg.stop_after_last_target && !targets.is_empty() && next == targets.len() {
        finish(rec, Termination::TargetsDone, &obs, 0.0, elevation0);
        return;
    }
    let mut event_prev = hook.event(&cur);

    let mut s = 0.0;
    let mut h = cfg.initial_step_m.min(cfg.max_step_m);
    let mut controller = Controller::new();
    let mut steps = 0u32;
    let mut aim: Option<Aim> = None;
    // The direction (up?) of the break the last accepted step landed on.
    let mut landed: Option<bool> = None;
    // Whether the step from here was already retaken in the interval its trial step left to.
    let mut relayered = false;
    let rise_share = layer_rise_share(cfg.tolerance_m);
    loop {
        if steps >= cfg.max_steps {
            finish(rec, Termination::MaxSteps, &obs, s, elevation0);
            return;
        }
        steps += 1;
        // Step caps: longest step, height change per step, remaining path length.
        let sin_psi = obs.elevation_rad.sin().abs();
        let vertical_limit = FineZone::limit_rise_m(
            sys.fine_zones(),
            obs.height_m,
            cfg.vertical_step_base_m + cfg.vertical_step_per_height * obs.height_m.max(0.0),
        );
        if sin_psi * cfg.max_step_m > vertical_limit {
            h = h.min(vertical_limit / sin_psi);
        }
        h = h.min(cfg.max_step_m);
        h = h.min(layer_step_cap_m(
            &bracket,
            obs.height_m,
            rise_share,
            sin_psi,
            &k1[half..],
        ));
        if let Some(a) = aim {
            h = a.step_m;
        }
        let remaining = cfg.max_length_m - s;
        if remaining <= cfg.min_step_m {
            finish(rec, Termination::MaxLength, &obs, s, elevation0);
            return;
        }
        h = h.min(remaining);
        if h < cfg.min_step_m {
            finish(rec, Termination::StepUnderflow, &obs, s, elevation0);
            return;
        }
        let step = Step::attempt(&mut f, &y, &k1, h);
        let err = if step.is_finite() {
            let mut e: f64 = 0.0;
            for i in 0..N {
                let w = if i < half { 1.0 } else { error_length };
                e = e.max(step.error[i].abs() * w);
            }
            e / (tolerance_per_m * h.max(MIN_BUDGET_STEP_M))
        } else {
            f64::INFINITY
        };
        // Breaks: a step that crosses one is retaken shorter to end just before it (see
        // `breaks`), whatever its error (a step straddling a jump is inaccurate anyway).
        if step.is_finite() {
            match aim {
                Some(a) if err <= 1.0 => {
                    let o = sys.observe(&step.y1);
                    match a.polish(o.height_m, o.elevation_rad) {
                        Polish::Retake(polished) => {
                            rec.rejected_steps += 1;
                            aim = Some(polished);
                            continue;
                        }
                        // The trial step that aimed here was too long to predict where the ray
                        // goes (it may have reflected off a thin layer that the retaken step
                        // enters): start over with half the aimed length.
                        Polish::Missed => {
                            rec.rejected_steps += 1;
                            aim = None;
                            h = 0.5 * a.step_m;
                            continue;
                        }
                        // The next step starts a hair before the break and moves the bracket on
                        // when it finds the crossing at its start; its first stage is taken past
                        // it.
                        Polish::Landed => {
                            landed = Some(a.exit.up);
                            rec.breaks_landed += 1;
                        }
                    }
                }
                // The aimed step ended on or past its break (the trial step's dense output,
                // which straddled the jump, mispredicted the crossing by more than
                // SHORT_OF_BREAK_M): its last stage saw the other side, hence the error.
                // Retaking it shorter, as a step that passed, ends it before the break; giving
                // up the aim instead shrinks the step until it underflows.
                Some(a) => {
                    let o = sys.observe(&step.y1);
                    if a.overshot(o.height_m)
                        && let Polish::Retake(polished) = a.polish(o.height_m, o.elevation_rad)
                    {
                        rec.rejected_steps += 1;
                        aim = Some(polished);
                        continue;
                    }
                }
                None if !bracket.is_empty() => {
                    let o1 = sys.observe(&step.y1);
                    let before = bracket;
                    let mut aimed = aim_at_break(sys, &mut bracket, &step, &obs, &o1, h, cfg);
                    if bracket.layer() != layer.get() {
                        // (A NaN error does not pass either.)
                        if !matches!(
                            err.partial_cmp(&1.0),
                            Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
                        ) {
                            // A step too inaccurate to pass cannot tell which side of a
                            // break the ray leaves to: it is shrunk below, in its interval.
                            bracket = before;
                            aimed = None;
                        } else if !relayered {
                            // The ray sat on a break and left it into the other interval than
                            // the one its step was taken in: take it again in that one. (Once:
                            // a ray sliding along a break, sent back across it from either
                            // side, keeps the step it has.)
                            relayered = true;
                            layer.set(bracket.layer());
                            k1 = f(&y);
                            rec.rejected_steps += 1;
                            continue;
                        }
                    }
                    if let Some(a) = aimed {
                        rec.rejected_steps += 1;
                        let next_step_m = if err <= 1.0 {
                            controller.accept(h, err)
                        } else {
                            h
                        };
                        aim = Some(Aim { next_step_m, ..a });
                        continue;
                    }
                }
                _ => {}
            }
        }
        if err.is_nan() || err > 1.0 {
            rec.rejected_steps += 1;
            aim = None;
            let shrunk = controller.reject(h, err);
            if !err.is_finite() && shrunk < cfg.min_step_m {
                finish(rec, Termination::NonFinite, &obs, s, elevation0);
                return;
            }
            h = shrunk;
            continue;
        }
        let y1 = step.y1;
        let obs1 = sys.observe(&y1);
        if !obs_finite(&obs1) {
            finish(rec, Termination::NonFinite, &obs, s, elevation0);
            return;
        }
        let mut dense: Option<Dense<N>> = None;
        let get_dense = |dense: &mut Option<Dense<N>>| *dense.get_or_insert_with(|| step.dense());
        rec.accepted_steps += 1;

        // Terminating events: earliest wins.
        let mut end: Option<(f64, Termination)> = None;
        let consider = |end: &mut Option<(f64, Termination)>, t: f64, kind| {
            if end.is_none_or(|(te, _)| t < te) {
                *end = Some((t, kind));
            }
        };
        // Ground.
        let climb0 = sys.climb(&y);
        let climb1 = sys.climb(&y1);
        if obs1.height_m < 0.0 {
            let d = get_dense(&mut dense);
            let t = locate(|t| sys.height(&d.at(t)), 0.0, 1.0, h);
            consider(&mut end, t, Termination::Ground);
        } else if climb0 < 0.0 && climb1 > 0.0 {
            let d = get_dense(&mut dense);
            let tm = locate(|t| sys.climb(&d.at(t)), 0.0, 1.0, h);
            if sys.height(&d.at(tm)) < 0.0 {
                let t = locate(|t| sys.height(&d.at(t)), 0.0, tm, h);
                consider(&mut end, t, Termination::Ground);
            }
        }
        // Top.
        if obs1.height_m > top {
            let d = get_dense(&mut dense);
            let t = locate(|t| sys.height(&d.at(t)) - top, 0.0, 1.0, h);
            consider(&mut end, t, Termination::Escaped);
        } else if climb0 > 0.0 && climb1 < 0.0 {
            let d = get_dense(&mut dense);
            let tm = locate(|t| sys.climb(&d.at(t)), 0.0, 1.0, h);
            if sys.height(&d.at(tm)) > top {
                let t = locate(|t| sys.height(&d.at(t)) - top, 0.0, tm, h);
                consider(&mut end, t, Termination::Escaped);
            }
        }
        if let Some(max_d) = cfg.max_distance_m
            && obs1.distance_m >= max_d
        {
            let d = get_dense(&mut dense);
            let t = locate(|t| sys.distance(&d.at(t)) - max_d, 0.0, 1.0, h);
            consider(&mut end, t, Termination::MaxDistance);
        }
        if s + h >= cfg.max_length_m {
            consider(&mut end, 1.0, Termination::MaxLength);
        }
        // The hook's event function.
        let event1 = hook.event(&point(&obs1, s + h));
        if let (Some(e0), Some(e1)) = (event_prev, event1)
            && e0.signum() != e1.signum()
        {
            let d = get_dense(&mut dense);
            let t = locate(
                |t| {
                    let o = sys.observe(&d.at(t));
                    hook.event(&point(&o, s + t * h)).unwrap_or(e1)
                },
                0.0,
                1.0,
                h,
            );
            consider(&mut end, t, Termination::Event);
        }
        event_prev = event1;
        // Requested distances up to the end of the step (or the terminating event).
        let limit_t = end.map_or(1.0, |(t, _)| t);
        let limit_distance = match end {
            // The event is the distance itself: a target on it must not be lost to the root's
            // rounding.
            Some((_, Termination::MaxDistance)) => cfg.max_distance_m.unwrap_or(f64::INFINITY),
            _ if limit_t >= 1.0 => obs1.distance_m,
            _ => sys.distance(&get_dense(&mut dense).at(limit_t)),
        };
        while next < targets.len() && targets[next] <= limit_distance {
            let d = get_dense(&mut dense);
            let target = targets[next];
            let t = locate(|t| sys.distance(&d.at(t)) - target, 0.0, limit_t, h);
            let o = sys.observe(&d.at(t));
            rec.heights_m[next] = Some(o.height_m);
            rec.target_elevations_rad[next] = Some(o.elevation_rad);
            next += 1;
            if next == targets.len() && cfg.stop_after_last_target {
                end = Some((t, Termination::TargetsDone));
            }
        }
        // Path samples inside the step.
        if let Some(p) = path.as_deref_mut() {
            let last_t = end.map_or(1.0, |(t, _)| t);
            let n = cfg.path_samples_per_step;
            if n > 0 {
                let d = get_dense(&mut dense);
                for j in 1..=n {
                    let t = last_t * j as f64 / (n + 1) as f64;
                    let o = sys.observe(&d.at(t));
                    if obs_finite(&o) {
                        p.push(point(&o, s + t * h));
                    }
                }
            }
        }
        if let Some((t, kind)) = end {
            let o = if t >= 1.0 {
                obs1
            } else {
                let o = sys.observe(&get_dense(&mut dense).at(t));
                if obs_finite(&o) { o } else { obs1 }
            };
            let o = clamp_level(o, kind, top);
            let p = point(&o, s + t * h);
            if let Some(path) = path.as_deref_mut() {
                path.push(p);
            }
            rec.invariant_drift = rec
                .invariant_drift
                .max((o.invariant - invariant0).abs() / scale);
            rec.note_elevation(o.elevation_rad);
            finish(rec, kind, &o, s + t * h, elevation0);
            return;
        }
        rec.invariant_drift = rec
            .invariant_drift
            .max((obs1.invariant - invariant0).abs() / scale);
        rec.note_elevation(obs1.elevation_rad);
        let next_point = point(&obs1, s + h);
        if let Some(p) = path.as_deref_mut() {
            p.push(next_point);
        }
        let action = hook.after_step(&cur, &next_point);
        y = y1;
        // Landed just short of a break: the next step is in the interval beyond it, and its
        // first stage is that interval's field continued back to the landing point.
        if let Some(up) = landed.take() {
            bracket.cross(up);
        }
        relayered = false;
        k1 = if bracket.layer() == layer.get() {
            step.k7
        } else {
            layer.set(bracket.layer());
            f(&y)
        };
        s += h;
        obs = obs1;
        cur = next_point;
        match action {
            HookAction::Continue => {}
            HookAction::Stop => return finish(rec, Termination::LeftRegion, &obs, s, elevation0),
            HookAction::Trapped => return finish(rec, Termination::Trapped, &obs, s, elevation0),
            HookAction::ClimbOut if path.is_none() => {
                let tolerance_rad = CLIMB_OUT_SHARE * tolerance_per_m;
                if let Some((top_obs, length_m)) = climb_to_top(sys, &obs, cfg, tolerance_rad)
                    && s + length_m < cfg.max_length_m
                    && cfg.max_distance_m.is_none_or(|d| top_obs.distance_m < d)
                {
                    rec.note_elevation(top_obs.elevation_rad);
                    return finish(
                        rec,
                        Termination::Escaped,
                        &top_obs,
                        s + length_m,
                        elevation0,
                    );
                }
            }
            HookAction::ClimbOut => {}
        }
        h = match aim.take() {
            Some(a) => a.next_step_m,
            None => controller.accept(h, err),
        };
    }
}

/// Longest step (m) that keeps a ray at `height_m` in the interval between breaks `bracket`
/// (above the ground) within `share` of the interval's thickness of height change: |sin ψ|·s
/// plus the bending, ½·κ·s² with κ at most |∇n| (`gradient`, the second half of the state's
/// derivative) plus the Earth's curvature. A step that crosses a thin interval in one go sees its
/// field vary on the scale of the whole step, where the 5(4) error estimate no longer tracks the
/// error; no cap where the interval is unbounded.
fn layer_step_cap_m(
    bracket: &Bracket<'_>,
    height_m: f64,
    share: f64,
    sin_psi: f64,
    gradient: &[f64],
) -> f64 {
    let lower_m = if height_m >= 0.0 {
        bracket.lower_m().max(0.0)
    } else {
        bracket.lower_m()
    };
    let thickness_m = bracket.upper_m() - lower_m;
    if !thickness_m.is_finite() {
        return f64::INFINITY;
    }
    let rise_m = share * thickness_m;
    let bend = gradient.iter().map(|g| g * g).sum::<f64>().sqrt() + EARTH_CURVATURE_PER_M;
    // Positive root of ½·bend·s² + sin ψ·s = rise, in a form without cancellation.
    2.0 * rise_m / (sin_psi + (sin_psi * sin_psi + 2.0 * bend * rise_m).sqrt())
}

/// Share of an interval's thickness one step may climb or descend at tolerance `tolerance_m`
/// (see [`layer_step_cap_m`]): a quarter at 1 cm and below, growing like the tolerance's sixth
/// root above (a fifth-order step's error grows like the sixth power of its length), at most
/// [`MAX_RISE_SHARE`].
fn layer_rise_share(tolerance_m: f64) -> f64 {
    (0.25 * (tolerance_m / 0.01).powf(1.0 / 6.0)).clamp(0.25, MAX_RISE_SHARE)
}

/// Largest share of its interval's thickness a step may climb or descend (reached near a 10 m
/// tolerance): a step across a whole 0.5 m interval erred 750 times its estimate.
const MAX_RISE_SHARE: f64 = 0.8;

/// An upper bound on the Earth's curvature (1/m) for [`layer_step_cap_m`]: a ray's height
/// above a sphere of radius ≥ 6 000 km bends at most by this beside its own curvature.
const EARTH_CURVATURE_PER_M: f64 = 1.0 / 6.0e6;

/// The share of the error budget per metre (T/L, in radians of direction) that a closed-form
/// climb out may spend on the ray's final direction.
const CLIMB_OUT_SHARE: f64 = 0.1;

/// The state at the top of a ray climbing out from `obs` in closed form, and the path length
/// there; `None` where the system has no radial profile or the closed form fails.
fn climb_to_top<const N: usize, Sys: RaySystem<N>>(
    sys: &Sys,
    obs: &Observables,
    cfg: &TracerConfig,
    tolerance_rad: f64,
) -> Option<(Observables, f64)> {
    let radius_m = sys.radius_m()?;
    let out = climb_out(
        |h| sys.index_at(h).unwrap_or((f64::NAN, f64::NAN)),
        sys.breaks(),
        radius_m,
        obs.height_m,
        obs.elevation_rad,
        cfg.top_m,
        tolerance_rad,
    )?;
    let angle_rad = obs.angle_rad + out.angle_rad;
    let top = Observables {
        height_m: cfg.top_m,
        distance_m: radius_m * angle_rad,
        elevation_rad: out.elevation_top_rad,
        angle_rad,
        invariant: obs.invariant,
        index: out.index_top,
    };
    Some((top, out.arc_length_m))
}

/// Steps shorter than this (m) get the error budget of a step this long. Without the floor, a
/// field with an undeclared jump in dn/dh (its step error falls only like h, as the budget does)
/// would shrink the step to `min_step_m` there; with it such a step settles at a few µm.
const MIN_BUDGET_STEP_M: f64 = 1.0;

/// A step aimed at a break ends this far (m, in height) before it, on the side it comes from:
/// its last stage, which enters the error estimate, then sees the field it integrated. Rounding
/// of heights at Earth's radius is ~1e-9 m.
const SHORT_OF_BREAK_M: f64 = 1e-8;

/// Shortest step (m of path) retaken to end on a break; a crossing closer to the start than this
/// is a ray that already sits on the break (within rounding) and just changes interval.
const MIN_LANDING_STEP_M: f64 = 1e-6;

/// Largest distance (m) from its aim point at which a step aimed at a break counts as landed.
const LANDING_TOLERANCE_M: f64 = 3e-9;

/// Largest miss (m) of an aimed step that can no longer be corrected and still counts as landed
/// (a near-level ray, whose height hardly changes with the step length); a larger miss means
/// the ray did not go where the trial step predicted, and the step is taken again shorter.
const LANDING_SLACK_M: f64 = 1e-6;

/// Retakes of an aimed step (Newton on its length) to bring its end onto the break.
const MAX_POLISH: u8 = 2;

/// A step being retaken so that it ends on a break.
#[derive(Debug, Clone, Copy)]
struct Aim {
    /// Length of the retaken step (m of path).
    step_m: f64,
    /// The break and the direction of the crossing.
    exit: Exit,
    /// Retakes so far.
    polished: u8,
    /// The step to continue with after landing (what the controller proposed for the original).
    next_step_m: f64,
}

/// What an aimed step that passed the error test did.
enum Polish {
    /// It ended on its aim point.
    Landed,
    /// It missed by more than [`LANDING_TOLERANCE_M`]; retake it with this corrected length.
    Retake(Aim),
    /// It missed by more than [`LANDING_SLACK_M`] and cannot be corrected: the ray went
    /// elsewhere than the trial step that aimed it predicted.
    Missed,
}

impl Aim {
    /// Whether a step aimed here ended on the far side of the point it aims at, half way to
    /// the break or beyond.
    fn overshot(&self, height_m: f64) -> bool {
        if self.exit.up {
            height_m > self.exit.height_m - 0.5 * SHORT_OF_BREAK_M
        } else {
            height_m < self.exit.height_m + 0.5 * SHORT_OF_BREAK_M
        }
    }

    /// After the aimed step ended at `height_m` with local elevation `elevation_rad`: landed, a
    /// corrected step (Newton on the step length) if it missed by more than
    /// [`LANDING_TOLERANCE_M`] and the correction is well conditioned, else landed if within
    /// [`LANDING_SLACK_M`] and missed if not.
    fn polish(self, height_m: f64, elevation_rad: f64) -> Polish {
        let aim_m = if self.exit.up {
            self.exit.height_m - SHORT_OF_BREAK_M
        } else {
            self.exit.height_m + SHORT_OF_BREAK_M
        };
        let miss = height_m - aim_m;
        if miss.abs() <= LANDING_TOLERANCE_M {
            return Polish::Landed;
        }
        let climb = elevation_rad.sin();
        let step_m = self.step_m - miss / climb;
        let correctable = self.polished < MAX_POLISH
            && climb.abs() >= 1e-6
            && step_m > MIN_LANDING_STEP_M
            && step_m < 2.0 * self.step_m;
        if correctable {
            Polish::Retake(Aim {
                step_m,
                polished: self.polished + 1,
                ..self
            })
        } else if miss.abs() <= LANDING_SLACK_M {
            Polish::Landed
        } else {
            Polish::Missed
        }
    }
}

/// The aimed retake of `step` if it leaves the ray's interval between breaks far enough from its
/// start; crossings at the start only move `bracket` on.
fn aim_at_break<const N: usize, Sys: RaySystem<N>>(
    sys: &Sys,
    bracket: &mut Bracket<'_>,
    step: &Step<N>,
    obs: &Observables,
    obs1: &Observables,
    h: f64,
    cfg: &TracerConfig,
) -> Option<Aim> {
    let climb0 = sys.climb(&step.y0);
    let climb1 = sys.climb(&step.y1);
    let turns = (climb0 > 0.0) != (climb1 > 0.0);
    if !turns && obs1.height_m > bracket.lower_m() && obs1.height_m < bracket.upper_m() {
        return None;
    }
    let dense = &step.dense();
    let extremum = turns.then(|| locate(|t| sys.climb(&dense.at(t)), 0.0, 1.0, h));
    let mut height = |t: f64| sys.height(&dense.at(t));
    let mut root = |g: &mut dyn FnMut(f64) -> f64, a: f64, c: f64| locate(g, a, c, h);
    for _ in 0..4 {
        let exit = bracket.first_exit(
            (obs.height_m, obs1.height_m),
            extremum,
            &mut height,
            &mut root,
        )?;
        let step_m = exit.t * h;
        // A crossing at the start: the ray sits on the break (within rounding) and leaves it
        // before the step's extremum. A crossing after the extremum is the ray coming back to
        // the break it started on (an apex or perigee in the neighbouring interval): a true
        // crossing, landed on like any other. Taking it for the start would move the bracket
        // to and fro and accept the whole step, straddling every break it meets.
        let starts_on_break = (obs.height_m - exit.height_m).abs() <= 2.0 * SHORT_OF_BREAK_M;
        let at_start = starts_on_break && extremum.is_none_or(|tm| exit.t <= tm);
        if !at_start && step_m > MIN_LANDING_STEP_M.max(cfg.min_step_m) {
            return Some(Aim {
                step_m,
                exit,
                polished: 0,
                next_step_m: h,
            });
        }
        bracket.cross(exit.up);
    }
    None
}

/// Snap the end height of a ground or top event onto its level (the root finder stops within
/// 1e-9 m along the path; the snapped value is what the event means).
fn clamp_level(mut o: Observables, kind: Termination, top: f64) -> Observables {
    match kind {
        Termination::Ground => o.height_m = 0.0,
        Termination::Escaped => o.height_m = top,
        _ => {}
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locate_finds_root() {
        let r = locate(|t| t * t - 0.25, 0.0, 1.0, 1000.0);
        assert!((r - 0.5).abs() < 1e-11);
    }

    #[test]
    fn termination_names_round_trip_serde() {
        for t in [
            Termination::Ground,
            Termination::TargetsDone,
            Termination::LeftRegion,
        ] {
            let j = serde_json::to_string(&t).unwrap();
            assert_eq!(j, format!("\"{}\"", t));
        }
    }

    #[test]
    fn config_validation_rejects_bad_values() {
        let c = TracerConfig {
            tolerance_m: 0.0,
            ..TracerConfig::default()
        };
        assert!(c.validate().is_err());
        let c = TracerConfig {
            top_m: f64::NAN,
            ..TracerConfig::default()
        };
        assert!(c.validate().is_err());
        assert!(TracerConfig::default().validate().is_ok());
    }
}
