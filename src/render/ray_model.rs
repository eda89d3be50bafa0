//! Stage 5 (render) — the renderer's view of a ray. In: camera height, apparent elevation, the
//! ground distances of the cards in view. Out: a [`FanRay`] — the ray's height above the surface at
//! each of those distances and how it ended ([`FanEnd`]).
//!
//! In a horizontally stratified atmosphere over a sphere every ray stays in the vertical plane
//! through the observer and Earth's centre, and its shape depends only on its apparent elevation α.
//! The renderer therefore asks for rays through the small [`RayTracer`] trait; the curved-ray
//! tracer of `crate::tracer` implements it, and so do the two closed-form models here:
//!
//! * [`StraightRays`] — n ≡ 1: exact line–sphere geometry (the paper's Figure 1 mode);
//! * [`ConstantCurvatureRays`] — every ray bends towards the Earth with the constant curvature
//!   κ = k/R (k: terrestrial refraction coefficient). Relative to the surface, such a ray behaves
//!   like a straight line over an Earth of effective radius R/(1−k); this module *defines* the
//!   model as that exact straight-line geometry, so it is exact (closed form) by construction.
//!   k = 0 gives back [`StraightRays`].
//!
//! Both serve as development back-ends and as test oracles. They are written by hand because they
//! are a few lines of trigonometry that no crate provides in this form.

use crate::tracer::{DensityPathsSoFar, PendingClimb, RayDensityPaths, straight_density_paths_m};

/// What the renderer needs of one ray launched from the camera at apparent elevation α.
#[derive(Debug, Clone, PartialEq)]
pub struct FanRay {
    /// Apparent elevation at the camera (rad, positive up, relative to the observer's horizontal).
    pub elevation_rad: f64,
    /// Height above the surface (m) at each requested ground distance, in the order requested;
    /// `None` where the ray ended (hit the sea, left the atmosphere, or stopped early above
    /// everything) before reaching that distance.
    pub heights_m: Vec<Option<f64>>,
    /// How the ray ended.
    pub end: FanEnd,
    /// The ray kept the sign of its launch elevation until it ended: it climbed the whole way or
    /// descended the whole way, never passing an apogee or perigee. `false` when unknown. In a
    /// spherically stratified atmosphere such rays form monotone families (see
    /// [`ElevationFan`](super::ElevationFan)), which lets the fan skip refining between them.
    pub monotone: bool,
}

/// How a ray ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FanEnd {
    /// Hit the sea at `distance_m` (ground distance from the observer) with `grazing_rad` between
    /// the ray and the local horizontal at that point (≥ 0).
    Ground {
        /// Ground distance of the hit point from the observer (m).
        distance_m: f64,
        /// Angle between the incoming ray and the local horizontal at the hit point (rad, ≥ 0).
        grazing_rad: f64,
    },
    /// Left the atmosphere (or stopped early while above everything and climbing). `elevation_rad`
    /// is the elevation of the final direction relative to the OBSERVER's horizontal: where on the
    /// sky (e.g. the sun) this ray looks. It may be negative: a ray that came up from below the
    /// astronomical horizon (Novaya Zemlya effect).
    Sky {
        /// Elevation of the final direction relative to the observer's horizontal (rad).
        elevation_rad: f64,
    },
    /// Oscillates in a duct for ever (Bouguer's invariant proves it,
    /// [`Termination::Trapped`](crate::tracer::Termination::Trapped)): it never reaches the sea
    /// or the sky. Shaded like [`FanEnd::Lost`], as the horizon-sky fallback.
    Trapped,
    /// Failed: cut short by the tracer's step or length budget, or the field or the state became
    /// non-finite. The renderer shades a documented fallback (never NaN).
    Lost,
}

/// What the renderer needs of a ray tracer: one call per apparent elevation.
///
/// Contract: `heights_m` has one entry per requested distance (the renderer pads or truncates
/// otherwise); non-finite values are tolerated: a NaN height hits no card, a NaN sky direction
/// sees no sun, a NaN grazing angle shades the sea at grazing 0, and any sample whose shading
/// would still not be finite gets the fallback colour and is counted in
/// [`RenderStats::non_finite_samples`](super::RenderStats). No NaN reaches the film.
pub trait RayTracer: Sync {
    /// Trace from camera height `camera_height_m` (above the surface) at apparent elevation
    /// `elevation_rad`. `distances_m` are ascending ground distances (the cards' distances) at
    /// which the ray's height is wanted. `need_sky_direction`: when `false` (no sun in the scene)
    /// the tracer may stop early once the ray is above every card and climbing, reporting
    /// [`FanEnd::Sky`] with its current direction.
    fn trace(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
    ) -> FanRay;

    /// [`Self::trace`], but a ray climbing clear of every card may stop early only once it is
    /// `margin_m` above them (`f64::INFINITY`: followed through every distance it reaches, up
    /// to where it meets the ground or leaves the atmosphere). A fan whose heights are
    /// interpolated between neighbouring rays needs this (the sea fan): a ray stopped just
    /// above the cards has no heights where its neighbour below is still within a card's
    /// height range. Default: [`Self::trace`] (right for a model that never stops early).
    fn trace_with_margin(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
        _margin_m: f64,
    ) -> FanRay {
        self.trace(
            camera_height_m,
            elevation_rad,
            distances_m,
            need_sky_direction,
        )
    }

    /// The density-weighted path lengths ∫ exp(−h/H_k) ds (m) of the ray launched from
    /// `camera_height_m` at `elevation_rad`, from the camera to where it leaves the atmosphere,
    /// for the scale heights `scale_heights_m` (Rayleigh, aerosol): an exponential extinction
    /// profile's optical depth along the ray's own path, which the renderer needs for the sun.
    /// `None` when the ray does not leave through the top, or the model cannot follow its path
    /// (the renderer then uses the sky's air mass). Default: `None`.
    fn density_paths_m(
        &self,
        _camera_height_m: f64,
        _elevation_rad: f64,
        _scale_heights_m: [f64; 2],
    ) -> Option<[f64; 2]> {
        None
    }

    /// [`Self::trace`] with the sky direction and no distances, and [`Self::density_paths_m`]
    /// of the same ray, from one trace where the model can. An implementation must give exactly
    /// the values of the two calls, bit for bit ([`super::MemoRays`] answers the two calls with
    /// them). Default: the two calls.
    fn trace_to_sky_with_density_paths(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        scale_heights_m: [f64; 2],
    ) -> (FanRay, Option<[f64; 2]>) {
        (
            self.trace(camera_height_m, elevation_rad, &[], true),
            self.density_paths_m(camera_height_m, elevation_rad, scale_heights_m),
        )
    }

    /// [`Self::trace_to_sky_with_density_paths`], the density paths' climb out through the top
    /// possibly left for later: [`Self::finish_density_paths`] then gives the paths that call
    /// gives, bit for bit. For a caller that traces many rays and is asked for the paths of few.
    /// Default: the paths at once.
    fn trace_to_sky_deferring_density_paths(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        scale_heights_m: [f64; 2],
    ) -> (FanRay, DensityPathsSoFar) {
        let (ray, paths) =
            self.trace_to_sky_with_density_paths(camera_height_m, elevation_rad, scale_heights_m);
        (ray, DensityPathsSoFar::Done(paths))
    }

    /// The density paths of a ray whose climb out [`Self::trace_to_sky_deferring_density_paths`]
    /// left to do. A tracer that leaves climbs must answer this, and a tracer that passes that
    /// call on must pass this one on too. Default: `None` (never asked of a tracer that leaves
    /// none).
    fn finish_density_paths(&self, _climb: &PendingClimb) -> Option<[f64; 2]> {
        None
    }

    /// The same integrals from the camera to each of the ground distances `distances_m` the ray
    /// reaches and to where it meets the sea, for the aerial perspective towards cards and the
    /// sea. `None` when the model cannot follow the ray's path (the renderer then integrates
    /// along the straight chord, which is exact for straight rays). Default: `None`.
    fn density_paths_along(
        &self,
        _camera_height_m: f64,
        _elevation_rad: f64,
        _distances_m: &[f64],
        _scale_heights_m: [f64; 2],
    ) -> Option<RayDensityPaths> {
        None
    }

    /// Only the ray's heights at `distances_m` (ascending), as [`Self::trace`] reports them;
    /// a tracer may stop the ray once it has passed the last distance. Default: [`Self::trace`]
    /// without the sky direction.
    fn heights_at(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
    ) -> Vec<Option<f64>> {
        self.trace(camera_height_m, elevation_rad, distances_m, false)
            .heights_m
    }
}

/// The parameters of a closed-form ray model were invalid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RayModelError {
    /// The refraction coefficient must be finite and below 1 (k ≥ 1 means rays bend at least as
    /// much as the Earth, which the effective-radius model cannot represent).
    #[error("refraction coefficient k must be finite and < 1, got {0}")]
    Coefficient(f64),
    /// Radii and the atmosphere top must be finite and positive.
    #[error("{name} must be finite and > 0, got {value}")]
    NotPositive {
        /// Which parameter.
        name: &'static str,
        /// Its value.
        value: f64,
    },
}

/// Default top of the atmosphere for the closed-form models (m above the surface).
pub const DEFAULT_ATMOSPHERE_TOP_M: f64 = 40_000.0;

/// Rays in homogeneous air (n ≡ 1): straight lines over a sphere of radius `earth_radius_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StraightRays {
    inner: ConstantCurvatureRays,
}

impl StraightRays {
    /// Straight rays over an Earth of `earth_radius_m`, leaving the atmosphere at
    /// [`DEFAULT_ATMOSPHERE_TOP_M`].
    pub fn new(earth_radius_m: f64) -> Result<Self, RayModelError> {
        Ok(Self {
            inner: ConstantCurvatureRays::new(0.0, earth_radius_m)?,
        })
    }
}

impl RayTracer for StraightRays {
    fn trace(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need: bool,
    ) -> FanRay {
        self.inner
            .trace(camera_height_m, elevation_rad, distances_m, need)
    }

    fn density_paths_m(&self, h: f64, elevation_rad: f64, scales: [f64; 2]) -> Option<[f64; 2]> {
        self.inner.density_paths_m(h, elevation_rad, scales)
    }
}

/// Rays of constant curvature κ = k/R towards the Earth (classic refraction-coefficient model),
/// computed exactly as straight lines over an effective Earth of radius R/(1−k). Ground distances
/// are arc lengths on that effective sphere (the model's horizontal coordinate); the final
/// direction of a sky ray is rotated back into the observer's frame: it has turned down by κ·d
/// over its ground distance d.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConstantCurvatureRays {
    k: f64,
    earth_radius_m: f64,
    effective_radius_m: f64,
    top_m: f64,
}

impl ConstantCurvatureRays {
    /// Refraction coefficient `k` (< 1; 0.13–0.17 in standard air) over `earth_radius_m`, with the
    /// atmosphere top at [`DEFAULT_ATMOSPHERE_TOP_M`].
    pub fn new(k: f64, earth_radius_m: f64) -> Result<Self, RayModelError> {
        Self::with_top(k, earth_radius_m, DEFAULT_ATMOSPHERE_TOP_M)
    }

    /// As [`ConstantCurvatureRays::new`] with an explicit atmosphere top (m above the surface).
    pub fn with_top(k: f64, earth_radius_m: f64, top_m: f64) -> Result<Self, RayModelError> {
        if !k.is_finite() || k >= 1.0 {
            return Err(RayModelError::Coefficient(k));
        }
        for (name, value) in [("earth_radius_m", earth_radius_m), ("top_m", top_m)] {
            if !value.is_finite() || value <= 0.0 {
                return Err(RayModelError::NotPositive { name, value });
            }
        }
        Ok(Self {
            k,
            earth_radius_m,
            effective_radius_m: earth_radius_m / (1.0 - k),
            top_m,
        })
    }

    /// The effective Earth radius R/(1−k) (m).
    pub fn effective_radius_m(&self) -> f64 {
        self.effective_radius_m
    }

    /// The refraction coefficient k.
    pub fn coefficient(&self) -> f64 {
        self.k
    }
}

impl RayTracer for ConstantCurvatureRays {
    fn trace(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        _need_sky_direction: bool,
    ) -> FanRay {
        let lost = |heights_m| FanRay {
            elevation_rad,
            heights_m,
            end: FanEnd::Lost,
            monotone: false,
        };
        if !camera_height_m.is_finite() || camera_height_m < 0.0 || !elevation_rad.is_finite() {
            return lost(vec![None; distances_m.len()]);
        }
        let alpha = elevation_rad.clamp(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
        let re = self.effective_radius_m;
        let r0 = re + camera_height_m;
        // The line r(θ) = p / cos(θ + α), p = r0·cos α (impact parameter), θ the polar angle at
        // Earth's centre from the observer; θ + α is the angle between ray and local horizontal.
        let p = r0 * alpha.cos();
        // Ground hit: only if the ray descends below the tangent (p ≤ R), first crossing.
        let ground_theta = if alpha < 0.0 && p <= re {
            let grazing = (p / re).min(1.0).acos();
            Some((-alpha - grazing, grazing))
        } else {
            None
        };
        let (end_theta, end) = match ground_theta {
            Some((theta, grazing)) => (
                theta,
                FanEnd::Ground {
                    distance_m: theta * re,
                    grazing_rad: grazing,
                },
            ),
            None => {
                let exit = (p / (re + self.top_m)).min(1.0).acos() - alpha;
                let exit = exit.max(0.0);
                // Horizontal direction turns by d/R_eff along the effective sphere and by d/R on
                // the real one: relative to the observer the ray has turned by d·(1/R_eff − 1/R).
                let d = exit * re;
                let final_elevation = alpha + d / re - d / self.earth_radius_m;
                (
                    exit,
                    FanEnd::Sky {
                        elevation_rad: final_elevation,
                    },
                )
            }
        };
        let heights_m = distances_m
            .iter()
            .map(|&d| {
                let theta = d / re;
                if theta.is_nan() || theta < 0.0 || theta > end_theta {
                    return None;
                }
                let c = (theta + alpha).cos();
                if c <= 0.0 {
                    return None;
                }
                // (r0 cos α − R cos(θ+α)) / cos(θ+α): the difference of two ~6.4e6 m numbers
                // keeps nanometre precision in f64.
                Some((p - re * c) / c)
            })
            .collect();
        // A line climbs the whole way when launched upwards; launched downwards it descends the
        // whole way to its first crossing with the sphere, or passes a perigee when it misses.
        let monotone = alpha > 0.0 || (alpha < 0.0 && ground_theta.is_some());
        FanRay {
            elevation_rad,
            heights_m,
            end,
            monotone,
        }
    }

    /// The line's own geometry over the effective sphere (its path length there is the model's
    /// path length; heights above the surface are the same on both spheres).
    fn density_paths_m(&self, h: f64, elevation_rad: f64, scales: [f64; 2]) -> Option<[f64; 2]> {
        let (re, top) = (self.effective_radius_m, self.top_m);
        straight_density_paths_m(re, h, elevation_rad, top, scales)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{ARCMIN_PER_RAD, EARTH_RADIUS_M};

    /// Independent oracle: intersect the ray (as a 2-D Cartesian line) with the vertical line
    /// through the point at polar angle θ on the sphere; returns the height above the surface.
    fn cartesian_height(h0: f64, alpha: f64, d: f64, r: f64) -> f64 {
        let (ox, oy) = (0.0, r + h0);
        let (dx, dy) = (alpha.cos(), alpha.sin());
        let theta = d / r;
        let (ux, uy) = (theta.sin(), theta.cos()); // radial unit vector at θ
        // Solve o + t·d = s·u for s (the radius there).
        let det = dx * uy - dy * ux;
        let t = (ox * uy - oy * ux) / -det;
        let (px, py) = (ox + t * dx, oy + t * dy);
        (px * px + py * py).sqrt() - r
    }

    #[test]
    fn straight_heights_match_cartesian_geometry() {
        let tracer = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let distances = [100.0, 1_000.0, 5_000.0, 10_000.0, 26_000.0];
        for &alpha in &[-0.001, -0.0005, 0.0, 0.0003, 0.002, 0.01] {
            let ray = tracer.trace(10.0, alpha, &distances, true);
            for (d, h) in distances.iter().zip(&ray.heights_m) {
                if let Some(h) = h {
                    let want = cartesian_height(10.0, alpha, *d, EARTH_RADIUS_M);
                    assert!((h - want).abs() < 1e-6, "α={alpha} d={d}: {h} vs {want}");
                }
            }
        }
    }

    #[test]
    fn straight_dip_is_geometric() {
        // Dip of the horizon 1.926′·√h for R = 6371 km (docs/references.md §2.2).
        let tracer = StraightRays::new(EARTH_RADIUS_M).unwrap();
        for &h in &[1.0f64, 10.0, 100.0] {
            let dip = 1.926 / ARCMIN_PER_RAD * h.sqrt();
            let above = tracer.trace(h, -dip * 0.999, &[], true);
            let below = tracer.trace(h, -dip * 1.001, &[], true);
            assert!(matches!(above.end, FanEnd::Sky { .. }), "{h}: {above:?}");
            assert!(matches!(below.end, FanEnd::Ground { .. }), "{h}: {below:?}");
        }
        // Horizon distance √(2Rh): 11.29 km at 10 m.
        let dip = (EARTH_RADIUS_M / (EARTH_RADIUS_M + 10.0)).acos();
        let ray = tracer.trace(10.0, -dip - 1e-12, &[], true);
        match ray.end {
            FanEnd::Ground {
                distance_m,
                grazing_rad,
            } => {
                assert!((distance_m - 11_290.0).abs() < 10.0, "{distance_m}");
                assert!(grazing_rad < 1e-3);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn straight_sky_keeps_direction_and_ground_grazing_is_exact() {
        let tracer = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let ray = tracer.trace(10.0, 0.01, &[1e3], true);
        let FanEnd::Sky { elevation_rad } = ray.end else {
            panic!("{ray:?}")
        };
        assert!((elevation_rad - 0.01).abs() < 1e-15);
        // Steep ray: hits almost below the camera.
        let ray = tracer.trace(10.0, -0.5, &[], true);
        match ray.end {
            FanEnd::Ground {
                distance_m,
                grazing_rad,
            } => {
                let flat = 10.0 / 0.5f64.tan();
                assert!((distance_m - flat).abs() < 1e-3, "{distance_m} vs {flat}");
                // The local horizontal at the hit point is tilted by θ = d/R towards the ray.
                assert!((grazing_rad - (0.5 - distance_m / EARTH_RADIUS_M)).abs() < 1e-9);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn constant_curvature_zero_is_straight_and_dip_shrinks() {
        let straight = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let k0 = ConstantCurvatureRays::new(0.0, EARTH_RADIUS_M).unwrap();
        let d = [500.0, 20_000.0];
        assert_eq!(
            straight.trace(5.0, -0.0007, &d, true),
            k0.trace(5.0, -0.0007, &d, true)
        );
        // With k the dip is the geometric one × √(1−k) to first order (docs/references.md §2.2: the
        // Nautical Almanac's 1.76′√h corresponds to k ≈ 0.164).
        let k = ConstantCurvatureRays::new(0.164, EARTH_RADIUS_M).unwrap();
        let dip = 1.76 / ARCMIN_PER_RAD * 10f64.sqrt();
        assert!(matches!(
            k.trace(10.0, -dip * 0.995, &[], true).end,
            FanEnd::Sky { .. }
        ));
        assert!(matches!(
            k.trace(10.0, -dip * 1.005, &[], true).end,
            FanEnd::Ground { .. }
        ));
    }

    #[test]
    fn constant_curvature_is_a_parabola_for_small_angles() {
        // h(d) ≈ h0 + α·d + d²(1−k)/(2R) (planar limit of a circle of relative curvature (1−k)/R).
        let k = 0.25;
        let t = ConstantCurvatureRays::new(k, EARTH_RADIUS_M).unwrap();
        let d = [2_000.0, 8_000.0];
        let alpha = -0.0004;
        let ray = t.trace(20.0, alpha, &d, true);
        for (d, h) in d.iter().zip(&ray.heights_m) {
            let want = 20.0 + alpha * d + d * d * (1.0 - k) / (2.0 * EARTH_RADIUS_M);
            assert!((h.unwrap() - want).abs() < 1e-3, "{h:?} vs {want}");
        }
        // A sky ray turns down by κ·d over its ground distance d.
        let ray = t.trace(20.0, 0.3, &[], true);
        let FanEnd::Sky { elevation_rad } = ray.end else {
            panic!()
        };
        assert!(elevation_rad < 0.3 && elevation_rad > 0.3 - 0.01);
    }

    #[test]
    fn invalid_models_are_rejected_and_bad_input_is_lost() {
        assert!(ConstantCurvatureRays::new(1.0, EARTH_RADIUS_M).is_err());
        assert!(ConstantCurvatureRays::new(f64::NAN, EARTH_RADIUS_M).is_err());
        assert!(StraightRays::new(-1.0).is_err());
        let t = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let ray = t.trace(10.0, f64::NAN, &[1.0], false);
        assert_eq!(ray.end, FanEnd::Lost);
        assert_eq!(ray.heights_m, vec![None]);
    }
}
