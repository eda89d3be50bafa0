//! Stage 5 (render) — the sun's light along its own curved ray. In: the ray tracer, the camera
//! height, the sky's extinction profile along the sun's rays ([`Sky::sun_extinction`](crate::scene::Sky::sun_extinction)), the sun's
//! band of final elevations, and the apparent elevations of rays already traced with their ends
//! (the elevation fan's rays, or in exact mode a grid one pixel apart). Out: [`SunTransmittance`]
//! — e^(−τ_c) per channel against apparent elevation, τ_c integrated along each ray's own path
//! from the camera to the top ([`RayTracer::density_paths_m`]).
//!
//! Only rays that can show the sun are candidates: those that leave the atmosphere with a final
//! direction inside the sun's band (its disc and two pixels), and their neighbours on either
//! side, so that a sample between two traced rays always has a value on both sides of it. Of
//! those, every eighth is integrated, then the middle one of each interval, until linear
//! interpolation between an interval's ends predicts its middle within 1e-3 of its value (or the
//! interval has no candidate left inside). A sample's transmittance is interpolated linearly in
//! apparent elevation between the two nearest integrated rays (clamped at the ends). A Novaya Zemlya ray that runs 900 km through the lowest
//! air gets the optical depth of that path, which no air-mass formula of the apparent elevation
//! can give.

use rayon::prelude::*;

/// Candidates taken at first: every this many (and the last).
const FIRST_STRIDE: usize = 8;

/// A midpoint whose transmittance linear interpolation between its interval's ends predicts
/// within this share of its value (per channel, plus [`INTERPOLATION_FLOOR`]) closes the
/// interval.
const INTERPOLATION_TOLERANCE: f64 = 1e-3;

/// Absolute floor of that test: a transmittance this small is invisible even at the default sun
/// intensity (1.85e5 × 1e-9 = 2e-4 of the horizon sky).
const INTERPOLATION_FLOOR: f64 = 1e-9;

use super::ray_model::{FanEnd, RayTracer};
use crate::scene::sky::Extinction;

/// Transmittance towards the sun, by apparent elevation at the camera.
#[derive(Debug, Clone)]
pub(super) struct SunTransmittance {
    /// Ascending apparent elevations (rad) of the integrated rays.
    alphas: Vec<f64>,
    /// e^(−τ_c) of each.
    values: Vec<[f64; 3]>,
}

impl SunTransmittance {
    /// Integrate the rays of `traced` (ascending apparent elevations with their ends) that may
    /// show a sun whose disc spans final elevations `band_rad`, and their neighbours. `None` when
    /// no such ray leaves through the top with a path the tracer can integrate.
    pub(super) fn build(
        tracer: &dyn RayTracer,
        camera_height_m: f64,
        extinction: &Extinction,
        band_rad: (f64, f64),
        traced: &[(f64, FanEnd)],
    ) -> Option<Self> {
        let shows_sun = |end: &FanEnd| {
            matches!(end, FanEnd::Sky { elevation_rad }
                if *elevation_rad >= band_rad.0 && *elevation_rad <= band_rad.1)
        };
        let n = traced.len();
        let wanted: Vec<f64> = (0..n)
            .filter(|&i| {
                let lo = i.saturating_sub(1);
                let hi = (i + 1).min(n.saturating_sub(1));
                (lo..=hi).any(|j| shows_sun(&traced[j].1))
            })
            .map(|i| traced[i].0)
            .collect();
        let scale_heights_m = extinction.scale_heights_m();
        let transmittance = |alpha: f64| {
            let paths = tracer.density_paths_m(camera_height_m, alpha, scale_heights_m)?;
            Some(extinction.path_optical_depth(paths).map(|t| (-t).exp()))
        };
        let values = refine(&wanted, transmittance);
        let (alphas, values): (Vec<f64>, Vec<[f64; 3]>) = wanted
            .iter()
            .zip(values)
            .filter_map(|(&a, v)| Some((a, v??)))
            .unzip();
        (!alphas.is_empty()).then_some(SunTransmittance { alphas, values })
    }

    /// Number of integrated rays.
    pub(super) fn len(&self) -> usize {
        self.alphas.len()
    }

    /// e^(−τ_c) at apparent elevation `alpha` (linear between integrated rays, clamped).
    pub(super) fn at(&self, alpha: f64) -> [f64; 3] {
        let i = self.alphas.partition_point(|&a| a < alpha);
        if i == 0 {
            return self.values[0];
        }
        if i == self.alphas.len() {
            return self.values[i - 1];
        }
        let (a0, a1) = (self.alphas[i - 1], self.alphas[i]);
        let t = if a1 > a0 {
            (alpha - a0) / (a1 - a0)
        } else {
            0.0
        };
        let (v0, v1) = (self.values[i - 1], self.values[i]);
        [0, 1, 2].map(|c| v0[c] + (v1[c] - v0[c]) * t)
    }
}

/// `f` at the candidates `alphas` (ascending) where it is needed: at every
/// [`FIRST_STRIDE`]-th, then at the middle candidate of each interval whose ends do not both have
/// a value or whose middle is not predicted by linear interpolation of its ends (then both halves
/// are refined again), until every interval is closed or has no candidate inside. Entries left
/// `None` are not needed: the interpolation of their neighbours stands for them. Each round runs
/// in parallel; the result does not depend on the thread count.
fn refine(
    alphas: &[f64],
    f: impl Fn(f64) -> Option<[f64; 3]> + Sync,
) -> Vec<Option<Option<[f64; 3]>>> {
    let n = alphas.len();
    let mut values: Vec<Option<Option<[f64; 3]>>> = vec![None; n];
    let mut first: Vec<usize> = (0..n).step_by(FIRST_STRIDE).collect();
    if n > 0 && first.last() != Some(&(n - 1)) {
        first.push(n - 1);
    }
    let mut todo = first.clone();
    let mut open: Vec<(usize, usize)> = first.windows(2).map(|w| (w[0], w[1])).collect();
    loop {
        let computed: Vec<Option<[f64; 3]>> = todo.par_iter().map(|&i| f(alphas[i])).collect();
        for (&i, v) in todo.iter().zip(computed) {
            values[i] = Some(v);
        }
        let mut next_open = Vec::new();
        for &(i, j) in open.iter().filter(|&&(i, j)| j > i + 1) {
            let m = (i + j) / 2;
            let Some(vm) = values[m] else {
                next_open.push((i, j));
                continue;
            };
            let closed = match (values[i].flatten(), vm, values[j].flatten()) {
                (Some(a), Some(v), Some(b)) => predicts(alphas, (i, a), (j, b), m, v),
                _ => false,
            };
            if !closed {
                next_open.extend([(i, m), (m, j)]);
            }
        }
        open = next_open;
        // The middles still to compute (intervals are disjoint: no repeats).
        todo = open
            .iter()
            .filter(|&&(i, j)| j > i + 1 && values[(i + j) / 2].is_none())
            .map(|&(i, j)| (i + j) / 2)
            .collect();
        if open.iter().all(|&(i, j)| j <= i + 1) {
            return values;
        }
    }
}

/// Whether linear interpolation between `(i, a)` and `(j, b)` predicts value `v` at `m`.
fn predicts(
    alphas: &[f64],
    (i, a): (usize, [f64; 3]),
    (j, b): (usize, [f64; 3]),
    m: usize,
    v: [f64; 3],
) -> bool {
    let t = (alphas[m] - alphas[i]) / (alphas[j] - alphas[i]);
    (0..3).all(|c| {
        let predicted = a[c] + (b[c] - a[c]) * t;
        (predicted - v[c]).abs() <= INTERPOLATION_TOLERANCE * v[c].abs() + INTERPOLATION_FLOOR
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the renderer would interpolate from the nodes `refine` kept.
    fn kept(alphas: &[f64], values: &[Option<Option<[f64; 3]>>]) -> SunTransmittance {
        let (alphas, values) = alphas
            .iter()
            .zip(values)
            .filter_map(|(&a, v)| Some((a, (*v)??)))
            .unzip();
        SunTransmittance { alphas, values }
    }

    #[test]
    fn refinement_keeps_few_nodes_where_the_transmittance_is_smooth_and_all_at_a_jump() {
        let alphas: Vec<f64> = (0..400).map(|i| f64::from(i) * 1e-5).collect();
        // Optical depths growing to 1, 2 and 3 across the candidates.
        let smooth = |a: f64| Some([(-250.0 * a).exp(), (-500.0 * a).exp(), (-750.0 * a).exp()]);
        let values = refine(&alphas, smooth);
        let used = values.iter().filter(|v| v.is_some()).count();
        assert!(used < alphas.len() / 2, "{used} of {}", alphas.len());
        let table = kept(&alphas, &values);
        for &a in &alphas {
            let (got, want) = (table.at(a), smooth(a).unwrap());
            for c in 0..3 {
                assert!(
                    (got[c] - want[c]).abs() <= 2e-3 * want[c] + 1e-9,
                    "{a}: {got:?} {want:?}"
                );
            }
        }
        // A jump (two families of rays): every candidate near it is computed, and the table
        // reproduces both sides.
        let jump = |a: f64| Some(if a < 2e-3 { [0.5; 3] } else { [0.1; 3] });
        let values = refine(&alphas, jump);
        let table = kept(&alphas, &values);
        assert!(values[199].is_some() && values[200].is_some());
        assert!((table.at(alphas[199])[0] - 0.5).abs() < 1e-12);
        assert!((table.at(alphas[200])[0] - 0.1).abs() < 1e-12);
        // Rays that do not leave through the top: their neighbours are all computed.
        let some_lost = |a: f64| (a > 1e-3).then_some([0.3; 3]);
        let values = refine(&alphas, some_lost);
        assert!(
            values[..=101].iter().all(|v| v.is_some()),
            "around the lost rays"
        );
    }
}
