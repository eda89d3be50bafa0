//! Stage 5 (analysis), transfer characteristics: the height h(D; α) at which the ray of apparent
//! elevation α passes ground distance D, and what follows from it.
//!
//! In: a [`Tracer`], an observer height, a sampled fan of elevations. Out: every image of a target
//! occupying heights [0, H] at distance D ([`find_images`]), and the apparent horizon
//! ([`apparent_horizon`]).
//!
//! An image is a maximal interval of α on which 0 ≤ h(D; α) ≤ H and h is monotone: where h has an
//! extremum (a fold) inside the band the picture folds and a new image, of opposite orientation,
//! starts (the Fata Morgana's stacked erect/inverted strips). The fan's heights carry the
//! tracer's error, which differs from ray to ray (at 1 cm per step up to ≈ 0.3 m at 60 km), so
//! the fan only proposes folds and [`FoldTest`] decides, on rays re-traced at a finer tolerance:
//! 1. the fan is split into runs of rays that reach D; in each run every change of direction of
//!    the fan's heights is a candidate and is re-traced;
//! 2. hysteresis over the re-traced candidates (at half the threshold) merges the alternating
//!    wiggles of noise into the branch around them; each surviving extremum is refined by
//!    golden-section search between its fan neighbours;
//! 3. the refined extrema pass the same hysteresis at the full threshold: a fold counts only if
//!    the height moves away from it by more than the threshold on both sides;
//! 4. each monotone branch between folds (or run ends, or the ground/escape rays beside a run)
//!    is clipped to the band: the edges h = 0 and h = H by bisection on re-traced rays.
//!
//! The threshold is set by the noise (ten tracer tolerances, or the re-traced rays' own error
//! bounds if larger), not by the image, so the images found do not depend on the fan's density
//! once it resolves the folds, and a genuine narrow fold (a decimetre-deep Fata Morgana slice)
//! is kept. Folds shallower than the threshold are below the accuracy the tracer was asked for;
//! features narrower than the fan spacing can still be missed: sample densely enough.

use serde::Serialize;

use crate::tracer::{RayRecord, StratifiedIndex, Termination, Tracer, TracerConfig};

/// Where a ray is at ground distance D.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Reach {
    /// It passes D at this height (m).
    Height(f64),
    /// It hit the ground before D.
    GroundBefore,
    /// It left the top of the atmosphere before D.
    EscapedBefore,
    /// It stopped before D for another reason (step limits, non-finite field, ...).
    Unknown,
}

impl Reach {
    /// From a traced record and the index of D among its distances.
    pub fn from_record(record: &RayRecord, index: usize) -> Reach {
        match record.heights_m.get(index).copied().flatten() {
            Some(h) => Reach::Height(h),
            None => match record.termination {
                Some(Termination::Ground) => Reach::GroundBefore,
                Some(Termination::Escaped) => Reach::EscapedBefore,
                _ => Reach::Unknown,
            },
        }
    }

    /// The height as an extended real: −∞ below ground, +∞ above the top, NaN unknown.
    pub fn value(self) -> f64 {
        match self {
            Reach::Height(h) => h,
            Reach::GroundBefore => f64::NEG_INFINITY,
            Reach::EscapedBefore => f64::INFINITY,
            Reach::Unknown => f64::NAN,
        }
    }
}

/// h(D; α) sampled on a fan of ascending elevations.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TransferCurve {
    /// Ground distance D (m).
    pub distance_m: f64,
    /// Apparent elevations (rad), ascending.
    pub elevations_rad: Vec<f64>,
    /// Where each ray is at D.
    pub reach: Vec<Reach>,
}

/// One image of a target [0, H] at distance D: a monotone piece of h(D; α) inside the band.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Image {
    /// Target distance (m).
    pub distance_m: f64,
    /// Target height H (m).
    pub height_m: f64,
    /// Centre of the image's elevation interval (deg).
    pub elevation_deg: f64,
    /// Lowest apparent elevation of the image (deg).
    pub elevation_min_deg: f64,
    /// Highest apparent elevation of the image (deg).
    pub elevation_max_deg: f64,
    /// Erect (h increases with α) or inverted.
    pub erect: bool,
    /// Target height seen at the image's lower edge (m).
    pub height_at_min_m: f64,
    /// Target height seen at the image's upper edge (m).
    pub height_at_max_m: f64,
    /// Mean vertical magnification: D·Δα / |Δh|, the image's angular height relative to the
    /// angular height the covered part of the target would have seen straight at distance D
    /// (1 = no distortion, > 1 stretched, < 1 compressed).
    pub magnification: f64,
}

/// How [`find_images`] tells a fold of h(D; α) from integration noise.
///
/// Neighbouring rays differ by the tracer's error, not only by physics: at the default 1 cm per
/// step a fan's heights at 60 km wiggle by up to ≈ 0.3 m (the step sequence changes from ray to
/// ray), so a dense enough fan shows hundreds of spurious extrema. Candidate folds are therefore
/// re-traced at [`retrace_tolerance_m`](Self::retrace_tolerance_m) (default 1/100 of the
/// tracer's), and a fold counts only if, on those rays, the height moves away from it on both
/// sides by more than max([`threshold_m`](Self::threshold_m), ε₁ + ε₂), ε = steps × re-trace
/// tolerance being a re-traced ray's own error bound.
///
/// Ten tolerances: the fan's rays disagree by that much, so a shallower fold is below the
/// accuracy the tracer was asked for, and the step-count bound alone is no guarantee (at 1e-4 m
/// per step the Danmarkshavn sounding shows 1–2 cm wiggles, 1.5 × that bound, which vanish at
/// 1e-5 m). The threshold is set by the noise, not by the image: a genuine fold a few
/// decimetres deep (a thin Fata Morgana slice) is kept however narrow it is in elevation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FoldTest {
    /// Smallest height reversal that counts as a fold, in units of the tracer's `tolerance_m`
    /// (default 10).
    pub threshold_tolerances: f64,
    /// Added to the threshold (m; default 1e-4), so that it stays above round-off at tiny
    /// tolerances.
    pub floor_m: f64,
    /// Tolerance of the re-traced rays as a fraction of the tracer's (default 0.01); never below
    /// 1e-6 m unless the tracer's own tolerance is.
    pub retrace_ratio: f64,
}

impl Default for FoldTest {
    fn default() -> Self {
        FoldTest {
            threshold_tolerances: 10.0,
            floor_m: 1e-4,
            retrace_ratio: 0.01,
        }
    }
}

impl FoldTest {
    /// The smallest reversal (m) that counts as a fold for a tracer of per-step `tolerance_m`.
    pub fn threshold_m(&self, tolerance_m: f64) -> f64 {
        self.threshold_tolerances * tolerance_m + self.floor_m
    }

    /// The per-step tolerance (m) of the rays that test and refine folds and band edges.
    pub fn retrace_tolerance_m(&self, tolerance_m: f64) -> f64 {
        (tolerance_m * self.retrace_ratio)
            .max(1e-6)
            .min(tolerance_m)
    }
}

/// One evaluated point of h(D; α): the height (±∞ for rays that hit the ground or escape before
/// D, from the fan) and the height's error bound (steps × tolerance; 0 for ±∞).
#[derive(Debug, Clone, Copy)]
struct Point {
    alpha: f64,
    h: f64,
    noise_m: f64,
}

/// Fresh traces to distance D at the re-trace tolerance.
struct Probe<'a, S: StratifiedIndex + ?Sized> {
    tracer: Tracer<'a, S>,
    h0: f64,
    d: f64,
}

impl<'a, S: StratifiedIndex + ?Sized> Probe<'a, S> {
    fn new(tracer: &Tracer<'a, S>, h0: f64, d: f64, test: &FoldTest) -> Option<Self> {
        let cfg = TracerConfig {
            tolerance_m: test.retrace_tolerance_m(tracer.config().tolerance_m),
            stop_after_last_target: true,
            max_distance_m: None,
            ..tracer.config().clone()
        };
        let tracer = Tracer::new(tracer.field(), cfg).ok()?;
        Some(Probe { tracer, h0, d })
    }

    fn at(&self, alpha: f64) -> Point {
        let tol = self.tracer.config().tolerance_m;
        match self.tracer.trace(self.h0, alpha, &[self.d]) {
            Ok(r) => Point {
                alpha,
                h: Reach::from_record(&r, 0).value(),
                noise_m: r.steps() as f64 * tol,
            },
            Err(_) => Point {
                alpha,
                h: f64::NAN,
                noise_m: 0.0,
            },
        }
    }

    fn height(&self, alpha: f64) -> f64 {
        self.at(alpha).h
    }
}

/// Bisection and golden-section searches stop at brackets this narrow (rad).
const RESOLUTION_RAD: f64 = 1e-11;

/// Images narrower than this (rad) are not images but the jump of h(D; α) at a ground or escape
/// edge (rays grazing the ground pass D well above it), which a search resolves only to
/// [`RESOLUTION_RAD`].
const MIN_WIDTH_RAD: f64 = 100.0 * RESOLUTION_RAD;

/// Bisection on `above(α)`; `lo` is false, `hi` is true. Returns the final bracket.
fn bisect(mut lo: f64, mut hi: f64, mut above: impl FnMut(f64) -> bool) -> (f64, f64) {
    for _ in 0..80 {
        if (hi - lo).abs() < RESOLUTION_RAD {
            break;
        }
        let mid = 0.5 * (lo + hi);
        if above(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    (lo, hi)
}

/// Golden-section search for the extremum of `g` in [a, c] (maximum if `max`).
fn golden(mut a: f64, mut c: f64, max: bool, mut g: impl FnMut(f64) -> f64) -> (f64, f64) {
    let sign = if max { -1.0 } else { 1.0 };
    let r = 0.5 * (5f64.sqrt() - 1.0);
    let mut x1 = c - r * (c - a);
    let mut x2 = a + r * (c - a);
    let mut f1 = sign * g(x1);
    let mut f2 = sign * g(x2);
    for _ in 0..100 {
        if (c - a).abs() < RESOLUTION_RAD {
            break;
        }
        if f1 < f2 || f2.is_nan() {
            c = x2;
            x2 = x1;
            f2 = f1;
            x1 = c - r * (c - a);
            f1 = sign * g(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + r * (c - a);
            f2 = sign * g(x2);
        }
    }
    if f1 < f2 {
        (x1, sign * f1)
    } else {
        (x2, sign * f2)
    }
}

/// Whether the heights of `a` and `b` differ by more than the noise: `base` or both points' error
/// bounds, whichever is larger (always for ±∞ against a height).
fn significant(a: &Point, b: &Point, base: f64) -> bool {
    (a.h - b.h).abs() > base.max(a.noise_m + b.noise_m)
}

/// Turning points of the sequence `pts` by hysteresis: indices of the extrema from which the
/// heights move away significantly ([`significant`]) on both sides, and whether each is a
/// maximum. Smaller wiggles merge into the branch around them; the first and last point are
/// never turning points.
fn zigzag(pts: &[Point], base: f64) -> Vec<(usize, bool)> {
    let mut turns = Vec::new();
    let (mut anchor, mut ext, mut dir) = (0, 0, 0.0);
    for (j, p) in pts.iter().enumerate().skip(1) {
        if dir == 0.0 {
            if significant(&pts[anchor], p, base) {
                dir = (p.h - pts[anchor].h).signum();
                ext = j;
            }
        } else if dir * (p.h - pts[ext].h) > 0.0 {
            ext = j;
        } else if significant(&pts[ext], p, base) {
            turns.push((ext, dir > 0.0));
            (anchor, ext, dir) = (ext, j, -dir);
        }
    }
    turns
}

/// A run of fan rays with finite heights at D, `first..=last`, with the neighbouring ray on
/// either side if that one hit the ground or escaped before D (an image edge to bisect).
#[derive(Debug, Clone, Copy)]
struct Segment {
    first: usize,
    last: usize,
    before: Option<usize>,
    after: Option<usize>,
}

/// The runs of finite heights in the fan's values `v`.
fn segments(v: &[f64]) -> Vec<Segment> {
    let infinite = |i: usize| v[i].is_infinite();
    let mut out = Vec::new();
    let mut i = 0;
    while i < v.len() {
        if !v[i].is_finite() {
            i += 1;
            continue;
        }
        let first = i;
        while i + 1 < v.len() && v[i + 1].is_finite() {
            i += 1;
        }
        out.push(Segment {
            first,
            last: i,
            before: (first > 0 && infinite(first - 1)).then(|| first - 1),
            after: (i + 1 < v.len() && infinite(i + 1)).then_some(i + 1),
        });
        i += 1;
    }
    out
}

/// Fan samples where the fan's heights change direction (plateaus count once), inside `seg`.
fn fan_turns(v: &[f64], seg: &Segment) -> Vec<usize> {
    let mut out = Vec::new();
    let (mut last_dir, mut last_at) = (0.0, seg.first);
    for i in seg.first..seg.last {
        let dir = (v[i + 1] - v[i]).signum();
        if v[i + 1] == v[i] {
            continue;
        }
        if last_dir != 0.0 && dir != last_dir {
            out.push(last_at);
        }
        (last_dir, last_at) = (dir, i + 1);
    }
    out
}

/// The ends of the monotone branches of h(D; α) over `seg`: the segment's ends (or the
/// neighbouring ground/escape rays) and every fold between them, refined.
fn branch_nodes<S: StratifiedIndex + ?Sized>(
    probe: &Probe<'_, S>,
    curve: &TransferCurve,
    v: &[f64],
    seg: &Segment,
    base: f64,
) -> Vec<Point> {
    let a = &curve.elevations_rad;
    let outer = |i: usize| Point {
        alpha: a[i],
        h: v[i],
        noise_m: 0.0,
    };
    // Candidates: every turn of the fan, re-traced; (fan index, point).
    let mut pts: Vec<(usize, Point)> = Vec::new();
    pts.extend(seg.before.map(|i| (i, outer(i))));
    pts.push((seg.first, probe.at(a[seg.first])));
    pts.extend(fan_turns(v, seg).into_iter().map(|i| (i, probe.at(a[i]))));
    if seg.last > seg.first {
        pts.push((seg.last, probe.at(a[seg.last])));
    }
    pts.extend(seg.after.map(|i| (i, outer(i))));
    let values: Vec<Point> = pts.iter().map(|p| p.1).collect();
    // Coarse merge at half the threshold (the samples may miss the top of a fold), refine the
    // survivors, then the final test on the refined extrema.
    let mut nodes = vec![values[0]];
    for (t, max) in zigzag(&values, 0.5 * base) {
        nodes.push(refine_fold(probe, a, pts[t].0, max, values[t]));
    }
    nodes.push(values[values.len() - 1]);
    let mut out = vec![nodes[0]];
    out.extend(zigzag(&nodes, base).into_iter().map(|(t, _)| nodes[t]));
    out.push(nodes[nodes.len() - 1]);
    out
}

/// The extremum near fan ray `k` by golden-section search between its neighbours; `sample` (the
/// re-traced ray `k`) if the search finds nothing more extreme.
fn refine_fold<S: StratifiedIndex + ?Sized>(
    probe: &Probe<'_, S>,
    a: &[f64],
    k: usize,
    max: bool,
    sample: Point,
) -> Point {
    let (lo, hi) = (a[k.saturating_sub(1)], a[(k + 1).min(a.len() - 1)]);
    let (alpha, h) = golden(lo, hi, max, |x| probe.height(x));
    let better = if max { h > sample.h } else { h < sample.h };
    if better { probe.at(alpha) } else { sample }
}

/// Where h(D; α) crosses `level` between `lo` (below) and `hi` (above): the re-traced point just
/// inside the band, on the `lo` side if `inside_low`.
fn crossing<S: StratifiedIndex + ?Sized>(
    probe: &Probe<'_, S>,
    lo: &Point,
    hi: &Point,
    level: f64,
    inside_low: bool,
) -> Point {
    let (l, r) = bisect(lo.alpha, hi.alpha, |x| probe.height(x) >= level);
    probe.at(if inside_low { l } else { r })
}

/// The image on the monotone branch from `p` to `q` (ascending α): the part with
/// 0 ≤ h ≤ `height_m`, erect if h rises along the branch.
fn band_image<S: StratifiedIndex + ?Sized>(
    probe: &Probe<'_, S>,
    p: &Point,
    q: &Point,
    height_m: f64,
) -> Option<Image> {
    let rising = q.h > p.h;
    let (lo, hi) = if rising { (p, q) } else { (q, p) };
    if !(hi.h >= 0.0 && lo.h <= height_m) || hi.h == lo.h {
        return None;
    }
    let bottom = if lo.h >= 0.0 {
        *lo
    } else {
        crossing(probe, lo, hi, 0.0, false)
    };
    let top = if hi.h <= height_m {
        *hi
    } else {
        crossing(probe, lo, hi, height_m, true)
    };
    let (first, last) = if bottom.alpha < top.alpha {
        (bottom, top)
    } else {
        (top, bottom)
    };
    let dh = last.h - first.h;
    if last.alpha - first.alpha < MIN_WIDTH_RAD || dh == 0.0 || !dh.is_finite() {
        return None;
    }
    let (amin, amax) = (first.alpha.to_degrees(), last.alpha.to_degrees());
    Some(Image {
        distance_m: probe.d,
        height_m,
        elevation_deg: 0.5 * (amin + amax),
        elevation_min_deg: amin,
        elevation_max_deg: amax,
        erect: rising,
        height_at_min_m: first.h,
        height_at_max_m: last.h,
        magnification: probe.d * (last.alpha - first.alpha) / dh.abs(),
    })
}

/// Every image of a target occupying heights [0, `height_m`] at the curve's distance, refined on
/// `tracer`'s field and settings (at the default [`FoldTest`]'s finer tolerance) from observer
/// height `observer_height_m`.
pub fn find_images<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    observer_height_m: f64,
    curve: &TransferCurve,
    height_m: f64,
) -> Vec<Image> {
    find_images_with(
        tracer,
        observer_height_m,
        curve,
        height_m,
        &FoldTest::default(),
    )
}

/// [`find_images`] with an explicit fold test.
pub fn find_images_with<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    observer_height_m: f64,
    curve: &TransferCurve,
    height_m: f64,
    test: &FoldTest,
) -> Vec<Image> {
    let Some(probe) = Probe::new(tracer, observer_height_m, curve.distance_m, test) else {
        return Vec::new();
    };
    let base = test.threshold_m(tracer.config().tolerance_m);
    let v: Vec<f64> = curve.reach.iter().map(|r| r.value()).collect();
    let mut images = Vec::new();
    for seg in segments(&v) {
        let nodes = branch_nodes(&probe, curve, &v, &seg, base);
        for w in nodes.windows(2) {
            images.extend(band_image(&probe, &w[0], &w[1], height_m));
        }
    }
    images
}

/// The lowest apparent elevation whose ray is not stopped by the ground before ground distance
/// `distance_m` (`None`: before it ends at all — the sea horizon). `clear[i]` says whether the
/// fan ray `elevations_rad[i]` (ascending) qualifies; the lowest qualifying fan ray and the one
/// below it bracket the horizon, which is refined by bisection on fresh traces. `None` if the
/// lowest fan ray already qualifies (the horizon is below the fan) or none does.
pub fn apparent_horizon<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    observer_height_m: f64,
    elevations_rad: &[f64],
    clear: &[bool],
    distance_m: Option<f64>,
) -> Option<f64> {
    let targets: Vec<f64> = distance_m.into_iter().collect();
    let is_clear = |alpha: f64| match tracer.trace(observer_height_m, alpha, &targets) {
        Ok(r) => match distance_m {
            Some(_) => r.heights_m[0].is_some(),
            None => r.termination != Some(Termination::Ground),
        },
        Err(_) => false,
    };
    let first = clear.iter().position(|&c| c)?;
    if first == 0 || first >= elevations_rad.len() {
        return None;
    }
    let (_, hi) = bisect(elevations_rad[first - 1], elevations_rad[first], is_clear);
    Some(hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bisect_brackets_the_switch() {
        let (lo, hi) = bisect(0.0, 1.0, |x| x >= 0.3);
        assert!(lo < 0.3 && hi >= 0.3 && hi - lo < 1e-10);
    }

    #[test]
    fn golden_finds_maximum_and_minimum() {
        let (x, v) = golden(0.0, 2.0, true, |x| -(x - 1.2) * (x - 1.2) + 3.0);
        assert!((x - 1.2).abs() < 1e-5 && (v - 3.0).abs() < 1e-9);
        let (x, _) = golden(0.0, 2.0, false, |x| (x - 0.4) * (x - 0.4));
        assert!((x - 0.4).abs() < 1e-5);
    }

    #[test]
    fn reach_values_order_ground_below_and_escape_above() {
        assert_eq!(Reach::GroundBefore.value(), f64::NEG_INFINITY);
        assert_eq!(Reach::EscapedBefore.value(), f64::INFINITY);
        assert!(Reach::Unknown.value().is_nan());
        assert_eq!(Reach::Height(3.5).value(), 3.5);
    }

    fn points(heights: &[f64]) -> Vec<Point> {
        heights
            .iter()
            .enumerate()
            .map(|(i, &h)| Point {
                alpha: i as f64,
                h,
                noise_m: 0.0,
            })
            .collect()
    }

    #[test]
    fn zigzag_merges_noise_and_keeps_a_shallow_real_fold() {
        // Rising with 3 cm wiggles to a real maximum at index 6, then falling 0.3 m, wiggling.
        let h = [
            0.0, 0.5, 0.47, 0.9, 0.87, 1.2, 1.3, 1.27, 1.29, 1.05, 1.08, 1.0,
        ];
        let turns = zigzag(&points(&h), 0.1);
        assert_eq!(turns, vec![(6, true)]);
        // With a threshold above its depth the same fold is noise.
        assert!(zigzag(&points(&h), 0.35).is_empty());
    }

    #[test]
    fn zigzag_turns_against_ground_and_escape_neighbours() {
        let h = [f64::NEG_INFINITY, 5.0, 3.0, f64::NEG_INFINITY];
        assert_eq!(zigzag(&points(&h), 0.1), vec![(1, true)]);
        let h = [f64::INFINITY, 5.0, 5.05, 9.0, f64::INFINITY];
        assert_eq!(zigzag(&points(&h), 0.1), vec![(1, false)]);
    }

    #[test]
    fn zigzag_needs_both_error_bounds_exceeded() {
        let mut p = points(&[0.0, 1.0, 0.5]);
        assert_eq!(zigzag(&p, 0.1), vec![(1, true)]);
        p[1].noise_m = 0.3;
        p[2].noise_m = 0.3;
        assert!(zigzag(&p, 0.1).is_empty());
    }

    #[test]
    fn fan_turns_count_a_plateau_once() {
        let v = [0.0, 1.0, 2.0, 2.0, 1.0, 0.5, 0.7];
        let seg = Segment {
            first: 0,
            last: v.len() - 1,
            before: None,
            after: None,
        };
        assert_eq!(fan_turns(&v, &seg), vec![2, 5]);
    }

    #[test]
    fn segments_split_at_rays_that_miss_d() {
        let ninf = f64::NEG_INFINITY;
        let v = [ninf, 1.0, 2.0, ninf, f64::NAN, 3.0, 4.0, f64::INFINITY];
        let s = segments(&v);
        assert_eq!(s.len(), 2);
        assert_eq!(
            (s[0].first, s[0].last, s[0].before, s[0].after),
            (1, 2, Some(0), Some(3))
        );
        assert_eq!(
            (s[1].first, s[1].last, s[1].before, s[1].after),
            (5, 6, None, Some(7))
        );
    }

    #[test]
    fn fold_threshold_follows_the_tracer_tolerance() {
        let t = FoldTest::default();
        assert!((t.threshold_m(0.01) - 0.1001).abs() < 1e-12);
        assert!((t.retrace_tolerance_m(0.01) - 1e-4).abs() < 1e-15);
        assert_eq!(t.retrace_tolerance_m(1e-5), 1e-6);
        assert_eq!(t.retrace_tolerance_m(1e-7), 1e-7);
    }

    struct Homogeneous;
    impl StratifiedIndex for Homogeneous {
        fn index_and_derivative(&self, _h: f64) -> (f64, f64) {
            (1.0, 0.0)
        }
    }

    #[test]
    fn straight_rays_see_one_erect_image_with_unit_magnification() {
        let tracer = Tracer::new(&Homogeneous, crate::tracer::TracerConfig::default()).unwrap();
        let elevations: Vec<f64> = (0..51)
            .map(|i| (-0.2 + 0.02 * i as f64).to_radians())
            .collect();
        let records = tracer.trace_fan(3.0, &elevations, &[1_000.0]).unwrap();
        let curve = TransferCurve {
            distance_m: 1_000.0,
            elevations_rad: elevations,
            reach: records.iter().map(|r| Reach::from_record(r, 0)).collect(),
        };
        let images = find_images(&tracer, 3.0, &curve, 5.0);
        assert_eq!(images.len(), 1);
        assert!(images[0].erect);
        assert!((images[0].magnification - 1.0).abs() < 0.01);
        assert!((images[0].height_at_max_m - 5.0).abs() < 1e-6);
    }
}
