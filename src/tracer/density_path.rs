//! Stage 4 (trace), integrals along a ray's curved path. In: a ray traced by [`Tracer`] with a
//! [`DensityPaths`] hook around the caller's hook, and two scale heights H₁, H₂. Out: the
//! density-weighted path lengths D_k = ∫ exp(−h/H_k) ds (m) from the observer to where the ray
//! leaves the atmosphere. An extinction profile β(h) = β₁ e^(−h/H₁) + β₂ e^(−h/H₂) (Rayleigh
//! and aerosol) then has the optical depth τ = β₁·D₁ + β₂·D₂ along that very ray — the
//! renderer's sun, whose light reaches the camera along a path that a Novaya Zemlya duct can
//! stretch to hundreds of kilometres of near-surface air.
//!
//! The integrated part of the path is summed over the accepted steps, each taken with its height
//! linear in path length between its ends (exact for the exponential then; a step's height
//! change is capped by the tracer, `vertical_step_base_m` + 5 % of the height, and its height
//! departs from linear by at most ~ step²/(8R), 8 cm for a 2 km step). The rest — the closed-form climb out to the top
//! that the fate rule takes once a ray provably escapes, or the part of the last step above
//! the last accepted point — comes from the same refraction integral as the climb out
//! (`climb_out::climb_out_density_paths`), from the last accepted point. A caller that traces
//! many rays but needs the paths of few may keep that climb for later ([`PendingClimb`],
//! [`Tracer::density_paths_so_far`], [`Tracer::finish_climb`]).

use super::climb_out::climb_out_density_paths;
use super::{RayHook, RayPoint, RayRecord, StratifiedIndex, Termination, Tracer};
use crate::tracer::HookAction;

/// A [`RayHook`] that sums ∫ exp(−h/H_k) ds over the accepted steps of a ray and passes every
/// call on to `inner`.
#[derive(Debug, Clone)]
pub struct DensityPaths<H> {
    /// The caller's hook (events and early stops are its own).
    pub inner: H,
    scale_heights_m: [f64; 2],
    sums_m: [f64; 2],
    last: Option<RayPoint>,
    /// Ascending ground distances (m) at which the sums so far are wanted, and those sums.
    targets_m: Vec<f64>,
    at_targets_m: Vec<Option<[f64; 2]>>,
    next_target: usize,
}

/// The density-weighted path lengths of one ray (m), from the observer: see [`DensityPaths`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RayDensityPaths {
    /// To each requested ground distance the ray reached, in the order requested.
    pub at_distances_m: Vec<Option<[f64; 2]>>,
    /// To where it met the ground, if it did.
    pub to_ground_m: Option<[f64; 2]>,
}

impl<H> DensityPaths<H> {
    /// Sum over the scale heights `scale_heights_m` (m, > 0) around `inner`.
    pub fn new(inner: H, scale_heights_m: [f64; 2]) -> Self {
        DensityPaths {
            inner,
            scale_heights_m,
            sums_m: [0.0; 2],
            last: None,
            targets_m: Vec::new(),
            at_targets_m: Vec::new(),
            next_target: 0,
        }
    }

    /// Also keep the sums at the ground distances `distances_m` (ascending, m).
    pub fn at_distances(mut self, distances_m: &[f64]) -> Self {
        self.targets_m = distances_m.to_vec();
        self.at_targets_m = vec![None; distances_m.len()];
        self
    }

    /// The sums at every target distance in (from, to], taken on the segment between the two
    /// points (its height linear in ground distance), before `sums_m` moves past it.
    fn note_targets(&mut self, from: &RayPoint, to: &RayPoint) {
        let mut next = self.next_target;
        let span_m = to.distance_m - from.distance_m;
        while next < self.targets_m.len() && self.targets_m[next] <= to.distance_m {
            let target = self.targets_m[next];
            if target >= from.distance_m {
                let f = if span_m > 0.0 {
                    (target - from.distance_m) / span_m
                } else {
                    1.0
                };
                let h = from.height_m + f * (to.height_m - from.height_m);
                let ds = f * (to.arc_length_m - from.arc_length_m);
                let piece = self.segment(from.height_m, h, ds);
                self.at_targets_m[next] = Some([0, 1].map(|k| self.sums_m[k] + piece[k]));
            }
            next += 1;
        }
        self.next_target = next;
    }

    /// ∫ exp(−h/H_k) ds over `ds_m` of path along which h goes linearly from `from_m` to `to_m`.
    fn segment(&self, from_m: f64, to_m: f64, ds_m: f64) -> [f64; 2] {
        self.scale_heights_m.map(|s| {
            let x = (to_m - from_m) / s;
            // (1 − e^(−x)) / x, without cancellation for small x.
            let mean = if x.abs() < 1e-8 {
                1.0 - 0.5 * x
            } else {
                -(-x).exp_m1() / x
            };
            ds_m * (-from_m / s).exp() * mean
        })
    }
}

impl<H: RayHook> RayHook for DensityPaths<H> {
    fn event(&self, point: &RayPoint) -> Option<f64> {
        self.inner.event(point)
    }

    fn after_step(&mut self, from: &RayPoint, to: &RayPoint) -> HookAction {
        if !self.targets_m.is_empty() {
            self.note_targets(from, to);
        }
        let ds = to.arc_length_m - from.arc_length_m;
        let piece = self.segment(from.height_m, to.height_m, ds);
        for (sum, p) in self.sums_m.iter_mut().zip(piece) {
            *sum += p;
        }
        self.last = Some(*to);
        self.inner.after_step(from, to)
    }
}

impl<H> DensityPaths<H> {
    /// What the hook holds for the ray `record` holds (traced from `start`), once its last
    /// partial step — from the last accepted point to where it ended, which the tracer does not
    /// pass to hooks — is added: the sums at the target distances it reached and, if it met the
    /// ground, to the ground.
    pub fn finish(mut self, start: RayPoint, record: &RayRecord) -> RayDensityPaths {
        let last = self.last.unwrap_or(start);
        let end = record.end;
        if end.distance_m >= last.distance_m && end.arc_length_m >= last.arc_length_m {
            if !self.targets_m.is_empty() {
                self.note_targets(&last, &end);
            }
            let ground = record.termination == Some(Termination::Ground);
            let piece = self.segment(
                last.height_m,
                end.height_m,
                end.arc_length_m - last.arc_length_m,
            );
            let total = [0, 1].map(|k| self.sums_m[k] + piece[k]);
            let to_ground_m = (ground && total.iter().all(|v| v.is_finite())).then_some(total);
            // Only where the tracer reported the ray (not past a closed-form climb out).
            for (d, h) in self.at_targets_m.iter_mut().zip(&record.heights_m) {
                if h.is_none() {
                    *d = None;
                }
            }
            return RayDensityPaths {
                at_distances_m: self.at_targets_m,
                to_ground_m,
            };
        }
        RayDensityPaths {
            at_distances_m: self.at_targets_m,
            to_ground_m: None,
        }
    }
}

/// What [`Tracer::density_paths_m`] still has to do for a ray that left through the top: the
/// climb from the last point the hook saw, in closed form ([`Tracer::finish_climb`]). Kept so a
/// caller can trace many rays and integrate the climbs only of those it is asked for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PendingClimb {
    /// The sums up to the last point.
    sums_m: [f64; 2],
    /// Where the climb starts: its height (m) and elevation (rad, > 0).
    height_m: f64,
    elevation_rad: f64,
    scale_heights_m: [f64; 2],
}

/// A ray's density-weighted path lengths, or the climb they still need ([`PendingClimb`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DensityPathsSoFar {
    /// The paths (`None` as [`Tracer::density_paths_m`] gives it).
    Done(Option<[f64; 2]>),
    /// Still to climb.
    Climb(PendingClimb),
}

impl<S: StratifiedIndex + ?Sized> Tracer<'_, S> {
    /// The density-weighted path lengths of the ray that `record` holds, traced from
    /// `observer_height_m` at `elevation_rad` with `hook` (fresh for that trace): `None` unless it
    /// escaped through the top, or when the rest of its climb cannot be integrated.
    pub fn density_paths_m<H>(
        &self,
        observer_height_m: f64,
        elevation_rad: f64,
        hook: &DensityPaths<H>,
        record: &RayRecord,
    ) -> Option<[f64; 2]> {
        match self.density_paths_so_far(observer_height_m, elevation_rad, hook, record) {
            DensityPathsSoFar::Done(paths) => paths,
            DensityPathsSoFar::Climb(climb) => self.finish_climb(&climb),
        }
    }

    /// [`Self::density_paths_m`], but a climb out through the top in closed form left for
    /// [`Self::finish_climb`], which then gives the same values bit for bit.
    pub fn density_paths_so_far<H>(
        &self,
        observer_height_m: f64,
        elevation_rad: f64,
        hook: &DensityPaths<H>,
        record: &RayRecord,
    ) -> DensityPathsSoFar {
        if record.termination != Some(Termination::Escaped) {
            return DensityPathsSoFar::Done(None);
        }
        let start = RayPoint {
            arc_length_m: 0.0,
            distance_m: 0.0,
            height_m: observer_height_m,
            elevation_rad,
        };
        let last = hook.last.unwrap_or(start);
        let rest = if last.height_m >= self.config().top_m {
            [0.0; 2]
        } else if last.elevation_rad > 0.0 {
            return DensityPathsSoFar::Climb(PendingClimb {
                sums_m: hook.sums_m,
                height_m: last.height_m,
                elevation_rad: last.elevation_rad,
                scale_heights_m: hook.scale_heights_m,
            });
        } else {
            // Turned inside the last step and left through the top within it: one segment.
            let ds = record.end.arc_length_m - last.arc_length_m;
            hook.segment(last.height_m, record.end.height_m, ds)
        };
        DensityPathsSoFar::Done(total_paths(hook.sums_m, rest))
    }

    /// The density-weighted path lengths of a ray whose climb `climb` was left to do
    /// ([`Self::density_paths_so_far`] of this tracer): `None` when the climb cannot be
    /// integrated.
    pub fn finish_climb(&self, climb: &PendingClimb) -> Option<[f64; 2]> {
        let cfg = self.config();
        let rest = climb_out_density_paths(
            |h| self.field().index_and_derivative(h),
            &self.breaks_m,
            cfg.earth_radius_m,
            climb.height_m,
            climb.elevation_rad,
            cfg.top_m,
            climb.scale_heights_m,
        )?;
        total_paths(climb.sums_m, rest)
    }
}

/// The sums `sums_m` plus the rest `rest_m`, when both totals are finite.
fn total_paths(sums_m: [f64; 2], rest_m: [f64; 2]) -> Option<[f64; 2]> {
    let total = [sums_m[0] + rest_m[0], sums_m[1] + rest_m[1]];
    total.iter().all(|v| v.is_finite()).then_some(total)
}

/// The density-weighted path lengths (as [`Tracer::density_paths_m`]) of a straight line (n ≡ 1)
/// from `height_m` at `elevation_rad` over a sphere of `radius_m` to `top_m`, in closed-form
/// geometry: `None` if the line meets the sphere or a quadrature fails. A descending line is the
/// climb from its perigee counted twice, less the climb from the start that it does not make.
pub fn straight_density_paths_m(
    radius_m: f64,
    height_m: f64,
    elevation_rad: f64,
    top_m: f64,
    scale_heights_m: [f64; 2],
) -> Option<[f64; 2]> {
    let climb = |h: f64, psi: f64| {
        let vacuum = |_: f64| (1.0, 0.0);
        climb_out_density_paths(vacuum, &[], radius_m, h, psi, top_m, scale_heights_m)
    };
    if elevation_rad > 0.0 {
        return climb(height_m, elevation_rad);
    }
    let perigee_m = (radius_m + height_m) * elevation_rad.cos() - radius_m;
    if perigee_m.is_nan() || perigee_m < 0.0 {
        return None;
    }
    // Level at the perigee; a hair above level keeps the climb's variable well defined.
    let up = climb(perigee_m, PERIGEE_ELEVATION_RAD)?;
    if elevation_rad == 0.0 {
        return Some(up);
    }
    let skipped = climb(height_m, -elevation_rad)?;
    Some([0, 1].map(|k| 2.0 * up[k] - skipped[k]))
}

/// The elevation (rad) a straight line's climb from its perigee starts with.
const PERIGEE_ELEVATION_RAD: f64 = 1e-12;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracer::{NoHook, TracerConfig, UniformIndex};

    /// n ≡ 1 and a vertical ray: D = H (1 − e^(−top/H)) exactly, whichever way the path was
    /// covered (steps, closed-form climb).
    #[test]
    fn a_vertical_ray_in_vacuum_has_the_column_of_each_scale_height() {
        let index = UniformIndex;
        let config = TracerConfig {
            stop_after_last_target: false,
            ..TracerConfig::default()
        };
        let tracer = Tracer::new(&index, config.clone()).unwrap();
        let scales = [8_000.0, 1_000.0];
        let mut hook = DensityPaths::new(NoHook, scales);
        let mut record = RayRecord::default();
        let up = std::f64::consts::FRAC_PI_2 - 1e-9;
        tracer
            .trace_into(0.0, up, &[], &mut hook, &mut record, None)
            .unwrap();
        let paths = tracer.density_paths_m(0.0, up, &hook, &record).unwrap();
        for (d, s) in paths.iter().zip(scales) {
            let exact = s * (1.0 - (-config.top_m / s).exp());
            assert!((d - exact).abs() < 1e-4 * exact, "{d} vs {exact}");
        }
    }

    /// The closed-form straight line against a brute-force midpoint sum along the line
    /// (1 m pieces), for climbing, level and descending lines.
    #[test]
    fn a_straight_line_has_the_density_paths_of_its_geometry() {
        let (radius, top, scales) = (6_371_000.0, 40_000.0, [8_000.0, 1_000.0]);
        for (h0, elevation_deg) in [(2.0, 5.0), (100.0, 0.0), (2_000.0, -1.0), (30.0, 0.2)] {
            let psi = f64::to_radians(elevation_deg);
            let got = straight_density_paths_m(radius, h0, psi, top, scales).unwrap();
            let r0 = radius + h0;
            let (sin, cos) = psi.sin_cos();
            let rt = radius + top;
            let length = (rt * rt - (r0 * cos).powi(2)).sqrt() - r0 * sin;
            let pieces = (length / 1.0).ceil() as usize;
            let ds = length / pieces as f64;
            let mut brute = [0.0; 2];
            for i in 0..pieces {
                let s = (i as f64 + 0.5) * ds;
                let h = (r0 * cos).hypot(r0 * sin + s) - radius;
                for k in 0..2 {
                    brute[k] += (-h / scales[k]).exp() * ds;
                }
            }
            for k in 0..2 {
                let rel = (got[k] - brute[k]).abs() / brute[k];
                assert!(
                    rel < 1e-6,
                    "{h0} m {elevation_deg}°: {} vs {}",
                    got[k],
                    brute[k]
                );
            }
        }
        assert!(straight_density_paths_m(radius, 10.0, -0.01, top, scales).is_none());
    }
}
