//! Jobs — the atmosphere cache. In: [`AtmosphereRequest`]s (source and the options that shape
//! it). Out: shared [`LoadedAtmosphere`]s: each distinct request is read, fitted and refracted
//! once per run, however many jobs and image sizes use it, and dropped after its last user
//! (so a batch over thousands of soundings does not hold them all).

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use super::JobError;
use crate::atmosphere::{
    AtmosphereError, AtmosphereOptions, AtmosphereSource, LoadedAtmosphere, load_atmosphere,
};

/// An atmosphere and how to build it: what a job names.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct AtmosphereRequest {
    /// What to load.
    pub source: AtmosphereSource,
    /// How to load it.
    #[serde(flatten)]
    pub options: AtmosphereOptions,
}

impl AtmosphereRequest {
    /// Check the options (wavelength range, smoothing ≥ 0) before any file is read.
    pub fn validate(&self) -> Result<(), JobError> {
        self.options.validate().map_err(JobError::from)
    }

    fn key(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|_| format!("{self:?}"))
    }
}

type Loaded = Result<Arc<LoadedAtmosphere>, Arc<AtmosphereError>>;

struct Slot {
    /// Jobs announced by [`AtmosphereCache::expect`] that have not released it yet.
    users: usize,
    cell: Arc<OnceLock<Loaded>>,
}

/// Loaded atmospheres shared between jobs (and threads).
#[derive(Default)]
pub struct AtmosphereCache {
    slots: Mutex<HashMap<String, Slot>>,
}

impl AtmosphereCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// Announce one more job that will use `request`; the atmosphere is kept until as many
    /// [`release`](Self::release) calls have been made. Atmospheres never announced stay loaded.
    pub fn expect(&self, request: &AtmosphereRequest) {
        self.with_slot(request, |slot| slot.users += 1);
    }

    /// The atmosphere `request` names, loading it on first use (other threads asking for it
    /// meanwhile wait for that load rather than repeating it). A failed load is remembered too.
    pub fn get(&self, request: &AtmosphereRequest) -> Result<Arc<LoadedAtmosphere>, JobError> {
        let cell = self.with_slot(request, |slot| slot.cell.clone());
        cell.get_or_init(|| {
            load_atmosphere(&request.source, &request.options)
                .map(Arc::new)
                .map_err(Arc::new)
        })
        .clone()
        .map_err(JobError::Atmosphere)
    }

    /// One announced job is done with `request`; after the last, the atmosphere is dropped.
    pub fn release(&self, request: &AtmosphereRequest) {
        let mut slots = self.lock();
        let key = request.key();
        if let Some(slot) = slots.get_mut(&key) {
            slot.users = slot.users.saturating_sub(1);
            if slot.users == 0 {
                slots.remove(&key);
            }
        }
    }

    /// `f` on the slot of `request`, created empty if needed.
    fn with_slot<T>(&self, request: &AtmosphereRequest, f: impl FnOnce(&mut Slot) -> T) -> T {
        let mut slots = self.lock();
        let slot = slots.entry(request.key()).or_insert_with(|| Slot {
            users: 0,
            cell: Arc::new(OnceLock::new()),
        });
        f(slot)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, Slot>> {
        // A panic elsewhere cannot leave the map half-updated: every update is one call.
        self.slots.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loads_once_and_drops_after_the_last_user() {
        let cache = AtmosphereCache::new();
        let req = AtmosphereRequest {
            source: AtmosphereSource::Us1976,
            options: AtmosphereOptions::default(),
        };
        cache.expect(&req);
        cache.expect(&req);
        let a = cache.get(&req).unwrap();
        let b = cache.get(&req).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        cache.release(&req);
        assert!(Arc::ptr_eq(&a, &cache.get(&req).unwrap()));
        cache.release(&req);
        assert!(!Arc::ptr_eq(&a, &cache.get(&req).unwrap()));
    }
}
