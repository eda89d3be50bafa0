//! Stage 4 — trace. In: an index-of-refraction field (an [`IndexField`], or a
//! [`StratifiedIndex`] for horizontally layered air over a sphere) and rays (origin, direction).
//! Out: ray paths and a typed termination for every ray. One tracer serves every scene, the
//! transfer-curve analysis and the renderer.

use glam::DVec3;

/// A refractive-index field in 3-D: n and ∇n at a point (Earth-centred coordinates, metres).
pub trait IndexField: Send + Sync {
    /// Refractive index and its gradient (m⁻¹) at `position_m`.
    fn index_and_gradient(&self, position_m: DVec3) -> (f64, DVec3);
}

/// A horizontally stratified index n(h), h = height above the surface (m), over a sphere.
/// Such a field is spherically symmetric, which the tracer exploits (planar fast path).
pub trait StratifiedIndex: Send + Sync {
    /// n and dn/dh (m⁻¹) at height `height_m` above the surface.
    fn index_and_derivative(&self, height_m: f64) -> (f64, f64);
}
