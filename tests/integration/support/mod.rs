//! Shared test support: helpers every integration-test module uses instead of its own copy.
//!
//! * [`cli`] — running the `ghostship` binary and checking its exit status.
//! * [`dem`] — synthetic elevation models (GeoTIFF, SRTM .hgt) written from their samples.
//! * [`films`] — comparing renders: channel differences, edges, differing pixels.
//! * [`data`] — paths of the repository's test inputs (shipped soundings, fixtures, scenes).
//! * [`reference`] — an independent ray tracer (not the code under test) for accuracy checks.
//! * [`fans`] — fitted stress soundings, fold slopes and reference heights with error estimates
//!   for fans of rays checked against [`reference`].
#![allow(dead_code)] // each test module uses a different subset

pub mod cli;
pub mod data;
pub mod dem;
pub mod fans;
pub mod films;
pub mod reference;

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
