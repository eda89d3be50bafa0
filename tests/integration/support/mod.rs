//! Shared test support: helpers every integration-test module uses instead of its own copy.
//!
//! * [`cli`] — running the `ghostship` binary and checking its exit status.
//! * [`dem`] — synthetic elevation models (GeoTIFF, SRTM .hgt) written from their samples.
//! * [`films`] — comparing renders: channel differences, edges, differing pixels.
//! * [`data`] — paths of the repository's test inputs (shipped soundings, fixtures, scenes).
//! * [`reference`] — an independent ray tracer (not the code under test) for accuracy checks.
//! * [`fans`] — fitted stress soundings, fold slopes and reference heights with error estimates
//!   for fans of rays checked against [`reference`].
//! * [`rough_sea`] — an independent quadrature of a wind-roughened sea's blurred reflections.
#![allow(dead_code)] // each test module uses a different subset

pub mod cli;
pub mod data;
pub mod dem;
pub mod fans;
pub mod films;
pub mod reference;
pub mod rough_sea;

/// Bisects [lo, hi] `iterations` times for the boundary of a predicate that is false at `lo`
/// and true at `hi` (both asserted), returning the last (false, true) bracket.
pub fn bisect(lo: f64, hi: f64, iterations: u32, is_high: impl Fn(f64) -> bool) -> (f64, f64) {
    assert!(!is_high(lo) && is_high(hi), "no boundary in [{lo}, {hi}]");
    let (mut lo, mut hi) = (lo, hi);
    for _ in 0..iterations {
        let mid = 0.5 * (lo + hi);
        if is_high(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    (lo, hi)
}

/// Apparent elevation (rad) from a camera at `camera_m` of the mirror image, on a calm sea, of
/// a point at height `top_m` and ground distance `distance_m`, on a sphere of radius `radius_m`
/// with straight rays: the sea point at angle θ where the camera and the point make equal
/// angles with the surface normal (bisection on θ), seen from the camera.
pub fn mirror_elevation_rad(camera_m: f64, top_m: f64, distance_m: f64, radius_m: f64) -> f64 {
    let r = radius_m;
    let camera = [0.0, r + camera_m];
    let phi = distance_m / r;
    let target = [(r + top_m) * phi.sin(), (r + top_m) * phi.cos()];
    let angle_to_normal = |theta: f64, q: [f64; 2]| {
        let p = [r * theta.sin(), r * theta.cos()];
        let (vx, vy) = (q[0] - p[0], q[1] - p[1]);
        let n = [theta.sin(), theta.cos()];
        ((vx * n[0] + vy * n[1]) / vx.hypot(vy)).acos()
    };
    // The camera's angle to the normal grows with θ, the target's shrinks: one crossing.
    let (lo, hi) = bisect(0.0, phi, 200, |theta| {
        angle_to_normal(theta, camera) > angle_to_normal(theta, target)
    });
    let theta = 0.5 * (lo + hi);
    let p = [r * theta.sin(), r * theta.cos()];
    // Camera horizontal is +x, vertical +y.
    (p[1] - camera[1]).atan2(p[0] - camera[0])
}
