//! Verification, image boundaries — part of the `bench accuracy` study. In: a traced fan (its
//! [`RayRecord`]s), the tracer that traced it, the target distances and heights. Out: every image
//! of every target as the library's image finder ([`find_images`]) sees it, and the comparison of
//! two such sets ([`BoundaryComparison`]): how far the apparent elevations of the image
//! boundaries (lower and upper edge) of a run lie from those of a reference run, in arcseconds.
//!
//! Images are matched by their index in the finder's order (ascending elevation per target).
//! A target whose run finds a different number of images than the reference is not compared:
//! it is counted in [`BoundaryComparison::count_mismatches`] instead, so a lost or spurious image
//! shows as a count, not as a shifted match.

use std::time::Instant;

use rayon::prelude::*;

use crate::analysis::{Image, Reach, TransferCurve, find_images};
use crate::tracer::{RayRecord, StratifiedIndex, Tracer};

/// Arcseconds per degree.
pub const ARCSEC_PER_DEG: f64 = 3600.0;

/// The images of one fan: one list per (distance, height) target, distances outer.
#[derive(Debug, Clone, PartialEq)]
pub struct FanImages {
    /// The images of each target, in [`find_images`] order.
    pub targets: Vec<Vec<Image>>,
    /// Wall-clock time of the image search (s, all threads).
    pub seconds: f64,
}

/// Every image of targets [0, H] (H in `heights_m`) standing at every distance (`distances_m`,
/// the distances the fan `records` was traced to, in that order), refined on `tracer` (which
/// re-traces at its [`FoldTest`](crate::analysis::FoldTest) tolerance) from `observer_m`. One
/// target per (distance, height), searched in parallel.
pub fn fan_images<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    observer_m: f64,
    elevations_rad: &[f64],
    records: &[RayRecord],
    distances_m: &[f64],
    heights_m: &[f64],
) -> FanImages {
    let start = Instant::now();
    let jobs: Vec<(usize, f64)> = (0..distances_m.len())
        .flat_map(|k| heights_m.iter().map(move |&h| (k, h)))
        .collect();
    let targets = jobs
        .par_iter()
        .map(|&(k, height)| {
            let curve = TransferCurve {
                distance_m: distances_m[k],
                elevations_rad: elevations_rad.to_vec(),
                reach: records.iter().map(|r| Reach::from_record(r, k)).collect(),
            };
            find_images(tracer, observer_m, &curve, height)
        })
        .collect();
    FanImages {
        targets,
        seconds: start.elapsed().as_secs_f64(),
    }
}

/// How a run's image boundaries compare with a reference's.
#[derive(Debug, Clone, PartialEq)]
pub struct BoundaryComparison {
    /// Targets (distance, height) searched.
    pub targets: usize,
    /// Images the run found, over all targets.
    pub images: usize,
    /// Images the reference found, over all targets.
    pub reference_images: usize,
    /// Targets where the run found a different number of images than the reference (not
    /// compared).
    pub count_mismatches: usize,
    /// Images compared (those of targets whose counts agree).
    pub compared: usize,
    /// Largest |Δ| of a boundary's apparent elevation (lower or upper edge) over the compared
    /// images (arcsec); `None` if none were compared.
    pub max_arcsec: Option<f64>,
}

/// Compare the images of `run` with those of `reference`, target by target (the two must list
/// the same targets in the same order; extra targets on either side count as mismatches).
pub fn compare_boundaries(run: &[Vec<Image>], reference: &[Vec<Image>]) -> BoundaryComparison {
    let mut out = BoundaryComparison {
        targets: run.len().max(reference.len()),
        images: run.iter().map(Vec::len).sum(),
        reference_images: reference.iter().map(Vec::len).sum(),
        count_mismatches: run.len().abs_diff(reference.len()),
        compared: 0,
        max_arcsec: None,
    };
    for (a, b) in run.iter().zip(reference) {
        if a.len() != b.len() {
            out.count_mismatches += 1;
            continue;
        }
        for (x, y) in a.iter().zip(b) {
            let lower = (x.elevation_min_deg - y.elevation_min_deg).abs();
            let upper = (x.elevation_max_deg - y.elevation_max_deg).abs();
            out.compared += 1;
            // A NaN boundary is as bad as can be: keep it visible (`f64::max` would drop it).
            let d = if lower.is_nan() || upper.is_nan() {
                f64::INFINITY
            } else {
                lower.max(upper) * ARCSEC_PER_DEG
            };
            out.max_arcsec = Some(out.max_arcsec.map_or(d, |m: f64| m.max(d)));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(lo_deg: f64, hi_deg: f64) -> Image {
        Image {
            distance_m: 10_000.0,
            height_m: 20.0,
            elevation_deg: 0.5 * (lo_deg + hi_deg),
            elevation_min_deg: lo_deg,
            elevation_max_deg: hi_deg,
            erect: true,
            height_at_min_m: 0.0,
            height_at_max_m: 20.0,
            magnification: 1.0,
        }
    }

    #[test]
    fn boundaries_match_by_index_in_arcseconds() {
        // Two targets; the run moves the upper edge of the second image of target 0 by 2″ and
        // the lower edge of target 1's image by 0.5″.
        let reference = vec![
            vec![image(-0.1, 0.0), image(0.05, 0.1)],
            vec![image(0.2, 0.3)],
        ];
        let run = vec![
            vec![image(-0.1, 0.0), image(0.05, 0.1 + 2.0 / 3600.0)],
            vec![image(0.2 - 0.5 / 3600.0, 0.3)],
        ];
        let c = compare_boundaries(&run, &reference);
        assert_eq!((c.targets, c.images, c.reference_images), (2, 3, 3));
        assert_eq!((c.count_mismatches, c.compared), (0, 3));
        let max = c.max_arcsec.unwrap();
        assert!((max - 2.0).abs() < 1e-9, "{max}");
    }

    #[test]
    fn a_different_image_count_is_a_mismatch_not_a_shifted_match() {
        // The run misses the first image of target 0: matching by index would pair 0.05…0.1 with
        // −0.1…0.0 (540″ off). It must be counted, and target 1 still compared.
        let reference = vec![
            vec![image(-0.1, 0.0), image(0.05, 0.1)],
            vec![image(0.2, 0.3)],
        ];
        let run = vec![vec![image(0.05, 0.1)], vec![image(0.2, 0.3)]];
        let c = compare_boundaries(&run, &reference);
        assert_eq!((c.count_mismatches, c.compared), (1, 1));
        assert_eq!(c.max_arcsec, Some(0.0));
        // Nothing comparable: no maximum at all, rather than 0.
        let c = compare_boundaries(&run[..1], &reference[..1]);
        assert_eq!((c.count_mismatches, c.compared, c.max_arcsec), (1, 0, None));
        // A missing target counts too.
        let c = compare_boundaries(&run[..1], &reference);
        assert_eq!(c.count_mismatches, 2);
    }

    #[test]
    fn a_nan_boundary_is_infinitely_wrong() {
        let c = compare_boundaries(&[vec![image(f64::NAN, 0.1)]], &[vec![image(0.0, 0.1)]]);
        assert_eq!(c.max_arcsec, Some(f64::INFINITY));
    }
}
