//! Stage 5 (render) — the sun's light along its own curved ray. In: the ray tracer, the camera
//! height, the sky's extinction profile along the sun's rays ([`Sky::sun_extinction`](crate::scene::Sky::sun_extinction)), the sun's
//! band of final elevations, and the apparent elevations of rays already traced with their ends
//! (the elevation fan's rays, or in exact mode a grid one pixel apart). Out: [`SunTransmittance`]
//! — e^(−τ_c) per channel against apparent elevation, τ_c integrated along each ray's own path
//! from the camera to the top ([`RayTracer::density_paths_m`]).
//!
//! Only rays that can show the sun are integrated: those that leave the atmosphere with a final
//! direction inside the sun's band (its disc and two pixels), and their neighbours on either
//! side, so that a sample between two traced rays always has a value on both sides of it. A
//! sample's transmittance is interpolated linearly in apparent elevation between the two nearest
//! integrated rays (clamped at the ends). A Novaya Zemlya ray that runs 900 km through the lowest
//! air gets the optical depth of that path, which no air-mass formula of the apparent elevation
//! can give.

use rayon::prelude::*;

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
        let integrated: Vec<Option<(f64, [f64; 3])>> = wanted
            .par_iter()
            .map(|&alpha| {
                let paths = tracer.density_paths_m(camera_height_m, alpha, scale_heights_m)?;
                let tau = extinction.path_optical_depth(paths);
                Some((alpha, tau.map(|t| (-t).exp())))
            })
            .collect();
        let (alphas, values): (Vec<f64>, Vec<[f64; 3]>) = integrated.into_iter().flatten().unzip();
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
