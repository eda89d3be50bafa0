//! Stage 5 (render) — a ray tracer that remembers. In: any [`RayTracer`]. Out: [`MemoRays`], the
//! same tracer behind a cache keyed by the exact bits of every argument, so that frames sharing
//! a view (a sun sweep: the same camera, atmosphere and cards, only the sun moves) trace each
//! ray once and look it up afterwards.
//!
//! A cached answer is the value the inner tracer returned for exactly the same arguments — or,
//! with [`MemoRays::with_density_paths`], for a sky-fan ray and its density paths, the values of
//! [`RayTracer::trace_to_sky_deferring_density_paths`] and
//! [`RayTracer::finish_density_paths`], which their contract makes those of the two calls —
//! and the tracers are deterministic, so a frame rendered through [`MemoRays`] is bit
//! for bit the frame rendered through the inner tracer, whichever frame or thread traced a ray
//! first. Two
//! threads asking for the same ray at once may both trace it (the lock is not held while
//! tracing); they store the same value.

use std::collections::HashMap;
use std::sync::Mutex;

use super::ray_model::{FanRay, RayTracer};
use crate::tracer::{DensityPathsSoFar, RayDensityPaths};

/// The arguments of one call, by their bits.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Key {
    camera_height: u64,
    elevation: u64,
    distances: Vec<u64>,
    flag: u64,
}

impl Key {
    fn new(camera_height_m: f64, elevation_rad: f64, distances_m: &[f64], flag: u64) -> Self {
        Key {
            camera_height: camera_height_m.to_bits(),
            elevation: elevation_rad.to_bits(),
            distances: distances_m.iter().map(|d| d.to_bits()).collect(),
            flag,
        }
    }
}

/// Both scale heights folded into one key word.
fn scales_key(scale_heights_m: [f64; 2]) -> u64 {
    scale_heights_m[0].to_bits() ^ scale_heights_m[1].to_bits().rotate_left(32)
}

/// The key of [`RayTracer::density_paths_m`]'s arguments.
fn paths_key(camera_height_m: f64, elevation_rad: f64, scale_heights_m: [f64; 2]) -> Key {
    Key::new(
        camera_height_m,
        elevation_rad,
        &scale_heights_m,
        scales_key(scale_heights_m),
    )
}

/// What [`RayTracer::trace_to_sky_with_density_paths`] answers.
type SkyAndPaths = (FanRay, Option<[f64; 2]>);

/// A [`RayTracer`] that answers every call it has seen before from memory.
pub struct MemoRays<'a> {
    inner: &'a dyn RayTracer,
    traces: Mutex<HashMap<Key, FanRay>>,
    /// Keyed with both scale heights (the second in `distances`); a sky-fan ray's climb out
    /// through the top is integrated when its paths are first asked for
    /// ([`Self::with_density_paths`]).
    paths: Mutex<HashMap<Key, DensityPathsSoFar>>,
    /// As `paths`, for [`RayTracer::trace_to_sky_with_density_paths`].
    sky_paths: Mutex<HashMap<Key, SkyAndPaths>>,
    paths_along: Mutex<HashMap<Key, Option<RayDensityPaths>>>,
    heights: Mutex<HashMap<Key, Vec<Option<f64>>>>,
    /// Scale heights for which every sky-fan ray ([`RayTracer::trace`] with the sky direction
    /// and no distances) is traced with its density paths, remembered for
    /// [`RayTracer::density_paths_m`] ([`Self::with_density_paths`]).
    density_scales_m: Option<[f64; 2]>,
}

impl<'a> MemoRays<'a> {
    /// Remember the answers of `inner`.
    pub fn new(inner: &'a dyn RayTracer) -> Self {
        MemoRays {
            inner,
            traces: Mutex::new(HashMap::new()),
            paths: Mutex::new(HashMap::new()),
            sky_paths: Mutex::new(HashMap::new()),
            paths_along: Mutex::new(HashMap::new()),
            heights: Mutex::new(HashMap::new()),
            density_scales_m: None,
        }
    }

    /// Trace every sky-fan ray not yet remembered together with its density paths for the
    /// scale heights `scale_heights_m` ([`RayTracer::trace_to_sky_deferring_density_paths`]:
    /// one trace for both, the same values as the two calls), and remember those paths too,
    /// their climb out through the top integrated only when they are first asked for. Worth it
    /// where many sky rays' paths will be asked for: a sun sweep, whose sun crosses most of
    /// the fan's sky rays in turn. `None`: trace them alone.
    pub fn with_density_paths(mut self, scale_heights_m: Option<[f64; 2]>) -> Self {
        self.density_scales_m = scale_heights_m;
        self
    }

    /// Number of distinct rays traced so far (calls of [`RayTracer::trace`] that were not
    /// answered from memory, less repeats traced at the same time by two threads).
    pub fn traced(&self) -> usize {
        lock(&self.traces).len()
    }
}

/// The map behind `m`, even if a thread panicked while holding it (the map is only ever
/// extended with finished values, so it is never half-written).
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The cached value of `key` in `map`, or `compute()` stored under it.
fn remembered<V: Clone>(map: &Mutex<HashMap<Key, V>>, key: Key, compute: impl FnOnce() -> V) -> V {
    if let Some(v) = lock(map).get(&key) {
        return v.clone();
    }
    let v = compute();
    lock(map).entry(key).or_insert_with(|| v.clone());
    v
}

impl RayTracer for MemoRays<'_> {
    fn trace(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
    ) -> FanRay {
        let key = Key::new(
            camera_height_m,
            elevation_rad,
            distances_m,
            u64::from(need_sky_direction),
        );
        if let Some(scales) = self.density_scales_m
            && distances_m.is_empty()
            && need_sky_direction
        {
            return remembered(&self.traces, key, || {
                let (ray, paths) = self.inner.trace_to_sky_deferring_density_paths(
                    camera_height_m,
                    elevation_rad,
                    scales,
                );
                let key = paths_key(camera_height_m, elevation_rad, scales);
                lock(&self.paths).entry(key).or_insert(paths);
                ray
            });
        }
        remembered(&self.traces, key, || {
            self.inner.trace(
                camera_height_m,
                elevation_rad,
                distances_m,
                need_sky_direction,
            )
        })
    }

    fn trace_with_margin(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
        margin_m: f64,
    ) -> FanRay {
        // Flags 2, 3: not the rays of `trace` (0, 1); the margin keyed after the distances.
        let mut keyed = distances_m.to_vec();
        keyed.push(margin_m);
        let key = Key::new(
            camera_height_m,
            elevation_rad,
            &keyed,
            2 + u64::from(need_sky_direction),
        );
        remembered(&self.traces, key, || {
            self.inner.trace_with_margin(
                camera_height_m,
                elevation_rad,
                distances_m,
                need_sky_direction,
                margin_m,
            )
        })
    }

    fn density_paths_m(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        scale_heights_m: [f64; 2],
    ) -> Option<[f64; 2]> {
        let key = paths_key(camera_height_m, elevation_rad, scale_heights_m);
        let known = lock(&self.paths).get(&key).copied();
        let paths = match known {
            Some(DensityPathsSoFar::Done(paths)) => return paths,
            Some(DensityPathsSoFar::Climb(climb)) => self.inner.finish_density_paths(&climb),
            None => self
                .inner
                .density_paths_m(camera_height_m, elevation_rad, scale_heights_m),
        };
        lock(&self.paths).insert(key, DensityPathsSoFar::Done(paths));
        paths
    }

    fn trace_to_sky_with_density_paths(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        scale_heights_m: [f64; 2],
    ) -> (FanRay, Option<[f64; 2]>) {
        let key = Key::new(
            camera_height_m,
            elevation_rad,
            &scale_heights_m,
            scales_key(scale_heights_m),
        );
        remembered(&self.sky_paths, key, || {
            self.inner.trace_to_sky_with_density_paths(
                camera_height_m,
                elevation_rad,
                scale_heights_m,
            )
        })
    }

    fn density_paths_along(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        scale_heights_m: [f64; 2],
    ) -> Option<RayDensityPaths> {
        let mut args: Vec<f64> = distances_m.to_vec();
        args.extend(scale_heights_m);
        let key = Key::new(
            camera_height_m,
            elevation_rad,
            &args,
            distances_m.len() as u64,
        );
        remembered(&self.paths_along, key, || {
            self.inner.density_paths_along(
                camera_height_m,
                elevation_rad,
                distances_m,
                scale_heights_m,
            )
        })
    }

    fn heights_at(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
    ) -> Vec<Option<f64>> {
        let key = Key::new(camera_height_m, elevation_rad, distances_m, 2);
        remembered(&self.heights, key, || {
            self.inner
                .heights_at(camera_height_m, elevation_rad, distances_m)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::ray_model::ConstantCurvatureRays;
    use crate::units::EARTH_RADIUS_M;

    #[test]
    fn answers_equal_the_inner_tracer_and_repeats_are_not_traced_again() {
        let inner = ConstantCurvatureRays::new(0.13, EARTH_RADIUS_M).unwrap();
        let memo = MemoRays::new(&inner);
        for pass in 0..2 {
            for i in 0..50 {
                let alpha = -0.004 + 1e-4 * f64::from(i);
                let d = [5_000.0, 20_000.0];
                assert_eq!(
                    memo.trace(10.0, alpha, &d, true),
                    inner.trace(10.0, alpha, &d, true)
                );
                assert_eq!(
                    memo.density_paths_m(10.0, alpha, [8_000.0, 1_200.0]),
                    inner.density_paths_m(10.0, alpha, [8_000.0, 1_200.0])
                );
            }
            assert_eq!(memo.traced(), 50, "pass {pass}");
        }
        // Another argument is another ray.
        memo.trace(10.0, 0.0, &[5_000.0], true);
        memo.trace(10.0, 0.0, &[5_000.0], false);
        memo.trace(11.0, 0.0, &[5_000.0], false);
        assert_eq!(memo.traced(), 53);
    }
}
