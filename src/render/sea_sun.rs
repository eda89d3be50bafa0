//! Render — the sun seen from the sea surface, for its glitter. In: the tracer, the sun's true
//! elevation at the camera, the farthest sea point of the frame and the sky's extinction. Out: a
//! table by the sun's true elevation above a sea point's own horizontal of its apparent elevation
//! there (the launch elevation of the ray from the sea that leaves towards it) and the optical
//! depth of that ray.
//!
//! A sea point at ground distance d from the camera has its vertical tilted by d/R, so the sun
//! stands higher (towards it) or lower (away) by up to d/R above its horizontal than above the
//! camera's. Near the surface of a duct the refraction depends strongly on that elevation (fig12:
//! 1.54° for a sun 1.5° below the horizontal, 0.5° for one at 0.2°), so each sea point needs the
//! refraction of its own sun, not the camera foot's with the tilt added.

use rayon::prelude::*;

use super::ray_model::RayTracer;
use super::reflection::sea_level_sun_launch_rad;
use crate::scene::sky::Extinction;

/// Node spacing of the table (rad): linear interpolation between nodes errs in the apparent
/// elevation by about step²/8 times its curvature, micro-radians in a critical duct.
const STEP_RAD: f64 = 1e-3;

/// Most nodes in a table (the step widens beyond).
const MAX_NODES: usize = 512;

/// The sun's apparent elevation and optical depth at the sea surface, by its true elevation
/// above the sea point's horizontal, over the range a frame's sea points need.
#[derive(Debug, Clone)]
pub(super) struct SeaSunTable {
    lo_rad: f64,
    step_rad: f64,
    /// Per node: apparent elevation (rad; 0 where the sun is below the sea's apparent horizon).
    apparent_rad: Vec<f64>,
    /// Per node: optical depth per channel along the sun's ray from the sea (+∞ where hidden).
    depth: Vec<[f64; 3]>,
    /// Whether the apparent elevations never fall from one node to the next.
    monotonic: bool,
    /// Lowest and highest apparent elevation of the table (rad).
    apparent_span_rad: (f64, f64),
}

impl SeaSunTable {
    /// Tabulate over true elevations `sun_elevation_rad` ± `max_tilt_rad` (padded by two steps).
    pub(super) fn build(
        tracer: &dyn RayTracer,
        sun_elevation_rad: f64,
        max_tilt_rad: f64,
        extinction: &Extinction,
    ) -> Self {
        let tilt = if max_tilt_rad.is_finite() {
            max_tilt_rad.abs()
        } else {
            0.0
        };
        let half = tilt + 2.0 * STEP_RAD;
        let nodes = ((2.0 * half / STEP_RAD).ceil() as usize + 1).clamp(2, MAX_NODES);
        let step_rad = 2.0 * half / (nodes - 1) as f64;
        let lo_rad = sun_elevation_rad - half;
        let scales = extinction.scale_heights_m();
        let entries: Vec<(f64, [f64; 3])> = (0..nodes)
            .into_par_iter()
            .map(|i| {
                let s = lo_rad + i as f64 * step_rad;
                let launch = sea_level_sun_launch_rad(tracer, s);
                let depth = launch
                    .and_then(|a| tracer.density_paths_m(0.0, a, scales))
                    .map_or([f64::INFINITY; 3], |p| extinction.path_optical_depth(p));
                (launch.unwrap_or(0.0), depth)
            })
            .collect();
        let (apparent_rad, depth): (Vec<f64>, Vec<[f64; 3]>) = entries.into_iter().unzip();
        let monotonic = apparent_rad.windows(2).all(|w| w[1] >= w[0]);
        let apparent_span_rad = apparent_rad
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        Self {
            lo_rad,
            step_rad,
            apparent_rad,
            depth,
            monotonic,
            apparent_span_rad,
        }
    }

    /// Node and fraction of true elevation `true_rad`, clamped to the table (beyond it, the end
    /// node: only samples farther than every traced ray of the frame by more than the padding).
    fn cell(&self, true_rad: f64) -> (usize, f64) {
        let last = (self.apparent_rad.len() - 1) as f64;
        let x = ((true_rad - self.lo_rad) / self.step_rad).clamp(0.0, last);
        let x = if x.is_nan() { 0.0 } else { x };
        let i = (x as usize).min(self.apparent_rad.len() - 2);
        (i, x - i as f64)
    }

    /// The apparent elevation (rad) above the sea point's horizontal of a sun at true elevation
    /// `true_rad` above it (0 where it is below the sea's apparent horizon), and the optical depth
    /// per channel of its light there.
    pub(super) fn at(&self, true_rad: f64) -> (f64, [f64; 3]) {
        let (i, t) = self.cell(true_rad);
        let lerp = |a: f64, b: f64| {
            if t == 0.0 {
                a
            } else if t == 1.0 {
                b
            } else {
                a + (b - a) * t
            }
        };
        let e = lerp(self.apparent_rad[i], self.apparent_rad[i + 1]);
        let (a, b) = (self.depth[i], self.depth[i + 1]);
        // Next to a node where the sun is hidden (infinite depth), its light is taken as lost.
        let depth = |a: f64, b: f64| {
            if a.is_finite() && b.is_finite() {
                lerp(a, b)
            } else if t == 0.0 {
                a
            } else if t == 1.0 {
                b
            } else {
                f64::INFINITY
            }
        };
        (e, [0, 1, 2].map(|c| depth(a[c], b[c])))
    }

    /// The apparent elevation of [`Self::at`] alone.
    pub(super) fn apparent_rad(&self, true_rad: f64) -> f64 {
        self.at(true_rad).0
    }

    /// The optical depth of [`Self::at`] alone.
    pub(super) fn depth(&self, true_rad: f64) -> [f64; 3] {
        self.at(true_rad).1
    }

    /// Bounds (lo, hi) on the apparent elevation of every true elevation in `true_rad` (lo, hi).
    pub(super) fn apparent_range(&self, true_rad: (f64, f64)) -> (f64, f64) {
        if !self.monotonic {
            return self.apparent_span_rad;
        }
        (self.at(true_rad.0).0, self.at(true_rad.1).0)
    }
}
