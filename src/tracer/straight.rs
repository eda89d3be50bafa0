//! Stage 4 (trace), straight rays: the exact geometry of a ray in air of constant index (n ≡ 1)
//! over a sphere, for the paper's Figure 1 and as an analytic check of the curved tracer.
//!
//! In: observer height, apparent elevation, Earth radius, atmosphere top, ground distances.
//! Out: a [`RayRecord`] with the heights at the distances (line–sphere intersections in closed
//! form, no integration).
//!
//! In polar form about Earth's centre a straight line is r(θ) = K / cos(α + θ), with
//! K = (R + h₀)·cos α, and its local elevation is ψ = α + θ.
//!
//! Also here: [`UniformIndex`], the same air (n ≡ 1) as a [`StratifiedIndex`], for straight-ray
//! geometry through the integrator and every analysis built on it.

use super::StratifiedIndex;
use super::ray::{RayPoint, RayRecord, Termination, TracerError};

/// Trace a straight ray from `observer_height_m` at `elevation_rad` over a sphere of
/// `earth_radius_m`, up to the top `top_m`; heights at `distances_m` (ascending). The ray ends at
/// the ground (if it descends into it) or at the top ([`Termination::Escaped`], refraction 0).
pub fn straight_ray(
    observer_height_m: f64,
    elevation_rad: f64,
    earth_radius_m: f64,
    top_m: f64,
    distances_m: &[f64],
) -> Result<RayRecord, TracerError> {
    if !(observer_height_m >= 0.0 && observer_height_m < top_m) {
        return Err(TracerError::ObserverOutside {
            height_m: observer_height_m,
            top_m,
        });
    }
    if !(elevation_rad.is_finite() && elevation_rad.abs() <= std::f64::consts::FRAC_PI_2) {
        return Err(TracerError::BadDirection);
    }
    if !(earth_radius_m.is_finite() && earth_radius_m > 0.0 && top_m.is_finite()) {
        return Err(TracerError::InvalidConfig {
            name: "earth_radius_m",
            value: earth_radius_m,
            reason: "must be finite and > 0",
        });
    }
    if distances_m.iter().any(|d| !(d.is_finite() && *d >= 0.0))
        || distances_m.windows(2).any(|w| w[1] < w[0])
    {
        return Err(TracerError::BadDistances);
    }
    let r0 = earth_radius_m + observer_height_m;
    let k = r0 * elevation_rad.cos();
    // Angle at which the ray ends: ground (descending and the line dips below R), else the top.
    let (end_angle, termination) = if elevation_rad < 0.0 && k < earth_radius_m {
        // First intersection with r = R, before the tangent point: α + θ = −acos(K/R).
        (
            -(k / earth_radius_m).acos() - elevation_rad,
            Termination::Ground,
        )
    } else {
        (
            (k / (earth_radius_m + top_m)).acos() - elevation_rad,
            Termination::Escaped,
        )
    };
    let mut record = RayRecord::default();
    record.reset(elevation_rad, distances_m.len());
    for (i, d) in distances_m.iter().enumerate() {
        let theta = d / earth_radius_m;
        if theta <= end_angle {
            let psi = elevation_rad + theta;
            record.heights_m[i] = Some(k / psi.cos() - earth_radius_m);
            record.target_elevations_rad[i] = Some(psi);
        }
    }
    let psi_end = elevation_rad + end_angle;
    let r_end = k / psi_end.cos();
    record.termination = Some(termination);
    // A line launched upwards climbs the whole way; launched downwards it descends the whole way
    // to the sea, or passes its perigee and escapes (reset already counts a level launch).
    record.turned |= elevation_rad < 0.0 && termination == Termination::Escaped;
    record.end = RayPoint {
        arc_length_m: r_end * psi_end.sin() - r0 * elevation_rad.sin(),
        distance_m: end_angle * earth_radius_m,
        height_m: if termination == Termination::Ground {
            0.0
        } else {
            top_m
        },
        elevation_rad: psi_end,
    };
    record.end_observer_elevation_rad = elevation_rad;
    record.refraction_rad = (termination == Termination::Escaped).then_some(0.0);
    Ok(record)
}

/// Air of constant refractive index n ≡ 1 (dn/dh = 0): rays through it are straight lines, the
/// paper's Figure 1 geometry. Traced by the same integrator as real air, it reproduces
/// [`straight_ray`] to the tracer's tolerance, so every analysis
/// (images, horizons) works unchanged with refraction switched off.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct UniformIndex;

impl StratifiedIndex for UniformIndex {
    fn index_and_derivative(&self, _height_m: f64) -> (f64, f64) {
        (1.0, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracer::{Tracer, TracerConfig};

    #[test]
    fn uniform_index_traces_straight_rays() {
        // The integrator through n ≡ 1 against the closed-form line–sphere geometry.
        let cfg = TracerConfig::default();
        let tracer = Tracer::new(&UniformIndex, cfg.clone()).unwrap();
        let distances = [5_000.0, 10_000.0, 20_000.0];
        for elevation_deg in [-0.1_f64, 0.0, 0.05, 0.3] {
            let a = elevation_deg.to_radians();
            let traced = tracer.trace(10.0, a, &distances).unwrap();
            let exact = straight_ray(10.0, a, cfg.earth_radius_m, cfg.top_m, &distances).unwrap();
            for (t, e) in traced.heights_m.iter().zip(&exact.heights_m) {
                match (t, e) {
                    (Some(t), Some(e)) => {
                        assert!((t - e).abs() < 0.05, "{elevation_deg}: {t} vs {e}")
                    }
                    (None, None) => {}
                    other => panic!("{elevation_deg}: {other:?}"),
                }
            }
        }
    }

    #[test]
    fn geometric_dip_grazes_the_ground() {
        let r: f64 = 6_371_000.0;
        let h0 = 10.0;
        let dip = (r / (r + h0)).acos();
        // Just above the dip the ray misses the ground, just below it hits.
        let above = straight_ray(h0, -dip + 1e-9, r, 40_000.0, &[]).unwrap();
        let below = straight_ray(h0, -dip - 1e-9, r, 40_000.0, &[]).unwrap();
        assert_eq!(above.termination, Some(Termination::Escaped));
        assert_eq!(below.termination, Some(Termination::Ground));
        // Dip 1.926′·√h (docs/references.md §2.2): 6.091′ at 10 m.
        assert!((dip * crate::units::ARCMIN_PER_RAD - 6.091).abs() < 0.001);
        // Horizon distance √(2Rh) = 11.29 km; the ray just below the dip meets the ground a
        // little before the tangent point (θ = dip − √(2·δ) with δ = 1 − K/R ≈ 1.8e-12 → ~12 m).
        assert!((r * dip / 1000.0 - 11.29).abs() < 0.005);
        let short = r * dip - below.end.distance_m;
        assert!(short > 0.0 && short < 20.0, "{short}");
    }

    #[test]
    fn horizontal_ray_heights_follow_the_sphere() {
        let r = 6_371_000.0;
        let rec = straight_ray(0.0, 0.0, r, 40_000.0, &[10_000.0]).unwrap();
        // Height of a tangent line at x: R/cos(x/R) − R ≈ x²/2R = 7.848 m.
        let h = rec.heights_m[0].unwrap();
        assert!((h - 7.848).abs() < 0.001, "{h}");
    }
}
