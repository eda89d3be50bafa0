//! Render — test tracers (unit tests only). In: a map from a ray's launch elevation at the sea
//! surface to its final elevation. Out: a [`RayTracer`] that answers with it and counts its
//! traces, for the sea-level sun's launch search and the sea's sun table.

use std::sync::atomic::{AtomicUsize, Ordering};

use super::ray_model::{FanEnd, FanRay, RayTracer};

/// Rays from the sea whose final elevation is `leave(launch)` (`None`: they do not leave) and
/// whose density paths grow as they flatten, counting the traces.
pub(super) struct Leaving<F> {
    leave: F,
    traces: AtomicUsize,
}

impl<F> Leaving<F> {
    /// Rays that leave at `leave(launch)`.
    pub(super) fn new(leave: F) -> Self {
        Leaving {
            leave,
            traces: AtomicUsize::new(0),
        }
    }

    /// Rays traced so far.
    pub(super) fn traces(&self) -> usize {
        self.traces.load(Ordering::Relaxed)
    }
}

impl<F: Fn(f64) -> Option<f64> + Sync> RayTracer for Leaving<F> {
    fn trace(&self, _h: f64, elevation_rad: f64, _d: &[f64], _sky: bool) -> FanRay {
        self.traces.fetch_add(1, Ordering::Relaxed);
        FanRay {
            elevation_rad,
            heights_m: Vec::new(),
            end: match (self.leave)(elevation_rad) {
                Some(e) => FanEnd::Sky { elevation_rad: e },
                None => FanEnd::Trapped,
            },
            monotone: false,
        }
    }

    fn density_paths_m(&self, _h: f64, e: f64, _s: [f64; 2]) -> Option<[f64; 2]> {
        (self.leave)(e).map(|_| [8e3 / (e + 0.003), 1e3 / (e + 0.01)])
    }
}
