//! Stage 5 (render) — the air between the camera and what a ray meets, along the ray's own
//! curved path. In: the ray tracer, the camera height, the card distances, the scale heights of
//! the aerial perspective's extinction, and the apparent elevations of the rays to integrate
//! (the elevation fan's, or in exact mode a grid one pixel apart). Out: [`AirPaths`] — for each
//! of those rays the density-weighted path lengths D_k = ∫ e^(−h/H_k) ds from the camera to each
//! card distance and to the sea ([`RayTracer::density_paths_along`]), interpolated in apparent
//! elevation per sample.
//!
//! The optical depth towards a card or the sea is then τ_c = β_R,c·D_R + β_A,c·D_A on the path
//! the light really takes, instead of the straight chord between the two end points (which rides
//! below a refracted ray by its sag, up to tens of metres at 50 km). Where the model cannot follow
//! its rays (closed-form straight rays: there the chord is the path) there is no table and the
//! shading integrates along the chord.

use rayon::prelude::*;

use super::ray_model::RayTracer;
use crate::tracer::RayDensityPaths;

/// Density-weighted path lengths by apparent elevation, to the card distances and the sea.
#[derive(Debug, Clone)]
pub(super) struct AirPaths {
    /// Ascending apparent elevations (rad).
    alphas: Vec<f64>,
    /// One [`RayDensityPaths`] per elevation.
    rays: Vec<RayDensityPaths>,
}

/// Where a sample's ray meets something.
#[derive(Debug, Clone, Copy)]
pub(super) enum Meets {
    /// The card distance of this index.
    Card(usize),
    /// The sea.
    Sea,
}

impl AirPaths {
    /// Integrate the rays at the ascending apparent elevations `alphas_rad`; `None` when the
    /// tracer cannot follow them.
    pub(super) fn build(
        tracer: &dyn RayTracer,
        camera_height_m: f64,
        distances_m: &[f64],
        scale_heights_m: [f64; 2],
        alphas_rad: &[f64],
    ) -> Option<Self> {
        let rays: Vec<Option<RayDensityPaths>> = alphas_rad
            .par_iter()
            .map(|&a| tracer.density_paths_along(camera_height_m, a, distances_m, scale_heights_m))
            .collect();
        let rays: Option<Vec<RayDensityPaths>> = rays.into_iter().collect();
        let rays = rays?;
        (!rays.is_empty()).then(|| AirPaths {
            alphas: alphas_rad.to_vec(),
            rays,
        })
    }

    /// Number of integrated rays.
    pub(super) fn len(&self) -> usize {
        self.alphas.len()
    }

    fn value(&self, i: usize, meets: Meets) -> Option<[f64; 2]> {
        let ray = &self.rays[i];
        match meets {
            Meets::Card(k) => ray.at_distances_m.get(k).copied().flatten(),
            Meets::Sea => ray.to_ground_m,
        }
    }

    /// The path lengths for a sample at apparent elevation `alpha` whose ray `meets` a card or
    /// the sea: linear between the two neighbouring integrated rays where both have a value,
    /// else the one that has; `None` if neither does.
    pub(super) fn at(&self, alpha: f64, meets: Meets) -> Option<[f64; 2]> {
        let i = self.alphas.partition_point(|&a| a < alpha);
        let (lo, hi) = (i.saturating_sub(1), i.min(self.alphas.len() - 1));
        match (self.value(lo, meets), self.value(hi, meets)) {
            (Some(a), Some(b)) if hi > lo => {
                let (a0, a1) = (self.alphas[lo], self.alphas[hi]);
                let t = ((alpha - a0) / (a1 - a0)).clamp(0.0, 1.0);
                Some([0, 1].map(|k| a[k] + (b[k] - a[k]) * t))
            }
            (Some(a), _) => Some(a),
            (None, b) => b,
        }
    }
}
