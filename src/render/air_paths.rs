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
    /// For each of [`GUIDE_PER_RAY`] × rays uniform buckets of elevation from the first: the
    /// index of the first elevation in it (a lookup starts there and steps on: O(1)).
    guide: Vec<u32>,
    guide_inv_width: f64,
}

/// Guide buckets per integrated ray.
const GUIDE_PER_RAY: usize = 4;

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
        (!rays.is_empty()).then(|| Self::with_guide(alphas_rad.to_vec(), rays))
    }

    /// The table of `rays` at the ascending, non-empty `alphas`, with its guide.
    fn with_guide(alphas: Vec<f64>, rays: Vec<RayDensityPaths>) -> Self {
        let span = (alphas[alphas.len() - 1] - alphas[0]).max(1e-300);
        let buckets = (GUIDE_PER_RAY * alphas.len()).min(1 << 22);
        let guide_inv_width = buckets as f64 / span;
        let guide = (0..=buckets)
            .map(|b| {
                let x = alphas[0] + b as f64 / guide_inv_width;
                alphas.partition_point(|&a| a < x) as u32
            })
            .collect();
        AirPaths {
            alphas,
            rays,
            guide,
            guide_inv_width,
        }
    }

    /// The first index whose elevation is not below `alpha` (as `partition_point`), in O(1).
    #[inline]
    fn first_not_below(&self, alpha: f64) -> usize {
        let b = ((alpha - self.alphas[0]) * self.guide_inv_width)
            .max(0.0)
            .min((self.guide.len() - 1) as f64);
        let b = if b.is_nan() { 0 } else { b as i32 as usize };
        // Buckets are ascending; the bucket's start never passes `alpha`'s index: step back
        // over equal-or-greater elevations, then on over smaller ones.
        let mut i = self.guide[b] as usize;
        while i > 0 && self.alphas[i - 1] >= alpha {
            i -= 1;
        }
        while i < self.alphas.len() && self.alphas[i] < alpha {
            i += 1;
        }
        i
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
        let i = self.first_not_below(alpha);
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_guided_lookup_is_the_partition_point() {
        let alphas: Vec<f64> = (0..300)
            .map(|i| -0.01 + 1e-4 * f64::from(i) + 1e-5 * f64::from(i % 7))
            .collect();
        let paths = AirPaths::with_guide(alphas.clone(), Vec::new());
        for k in 0..5000 {
            let x = -0.012 + 0.036 * f64::from(k) / 5000.0;
            assert_eq!(
                paths.first_not_below(x),
                alphas.partition_point(|&a| a < x),
                "{x}"
            );
        }
        for &a in &alphas {
            assert_eq!(paths.first_not_below(a), alphas.partition_point(|&b| b < a));
        }
    }
}
