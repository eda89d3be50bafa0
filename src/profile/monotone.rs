//! Stage 2 — fit: the monotone-safe cubic used for every fitted quantity. In: knots (strictly
//! increasing heights, finite values). Out: a C¹ curve through every knot with its analytic
//! derivative, that never leaves the range of the two knots around it (no new extrema, so it
//! never invents an inversion).
//!
//! The curve is PCHIP: a piecewise cubic Hermite with Fritsch–Butland (weighted harmonic mean)
//! tangents inside and SciPy's shape-preserving three-point rule at the ends. It is stored in the
//! `splines` crate as `Interpolation::StrokeBezier` keys, whose Bézier controls are exactly the
//! Hermite tangents: `out_k = y_k + h_k·m_k/3`, `in_{k+1} = y_{k+1} − h_k·m_{k+1}/3` (h_k = the
//! segment's width). `splines` has no derivative, so it is computed here from the same segment's
//! controls, which keeps value and slope consistent. The tangent rule is written by hand because
//! no crate offers PCHIP tangents over `splines` keys. So is the segment search: `splines` finds
//! the segment by a binary search over its 40-byte keys with a `partial_cmp().unwrap()` per probe
//! and then evaluates the Bézier itself; the refractive table's build samples these curves some
//! 10⁵ times per atmosphere, so the curve keeps its knot heights in a plain slice (one
//! `partition_point`) and evaluates the same segment's Bézier controls once for value and slope.

use splines::{Interpolation, Key, Spline};

/// A PCHIP curve through knots, value and slope by height.
#[derive(Debug, Clone)]
pub(crate) struct MonotoneCubic {
    spline: Spline<f64, f64>,
    /// The keys' heights, ascending, with the segment search over them.
    knots: KnotIndex,
    /// (height, value, slope) of the first and last knot, for the ends the spline does not serve.
    first: (f64, f64, f64),
    last: (f64, f64, f64),
}

/// PCHIP tangents (Fritsch–Butland inside, SciPy's three-point shape-preserving rule at the ends).
/// `x` strictly increasing, `x.len() == y.len() >= 2`.
pub(crate) fn pchip_slopes(x: &[f64], y: &[f64]) -> Vec<f64> {
    let n = x.len();
    debug_assert!(n >= 2 && y.len() == n);
    let h: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    let d: Vec<f64> = (0..n - 1).map(|k| (y[k + 1] - y[k]) / h[k]).collect();
    if n == 2 {
        return vec![d[0], d[0]];
    }
    let mut m = vec![0.0; n];
    for k in 1..n - 1 {
        if d[k - 1] * d[k] > 0.0 {
            let w1 = 2.0 * h[k] + h[k - 1];
            let w2 = h[k] + 2.0 * h[k - 1];
            m[k] = (w1 + w2) / (w1 / d[k - 1] + w2 / d[k]);
        }
    }
    m[0] = end_slope(h[0], h[1], d[0], d[1]);
    m[n - 1] = end_slope(h[n - 2], h[n - 3], d[n - 2], d[n - 3]);
    m
}

/// One-sided three-point slope, limited so the end segment keeps the data's shape.
fn end_slope(h0: f64, h1: f64, d0: f64, d1: f64) -> f64 {
    let m = ((2.0 * h0 + h1) * d0 - h0 * d1) / (h0 + h1);
    if sign(m) != sign(d0) {
        0.0
    } else if sign(d0) != sign(d1) && m.abs() > 3.0 * d0.abs() {
        3.0 * d0
    } else {
        m
    }
}

/// −1, 0 or +1 (unlike `f64::signum`, zero maps to zero).
fn sign(v: f64) -> i8 {
    if v > 0.0 {
        1
    } else if v < 0.0 {
        -1
    } else {
        0
    }
}

impl MonotoneCubic {
    /// PCHIP through `(x, y)`. Callers guarantee at least two knots, strictly increasing finite
    /// heights and finite values (checked in debug builds).
    pub(crate) fn new(x: &[f64], y: &[f64]) -> Self {
        let m = pchip_slopes(x, y);
        Self::with_slopes(x, y, &m)
    }

    /// A cubic Hermite through `(x, y)` with the given slopes (used with exact hydrostatic
    /// slopes for ln P).
    pub(crate) fn with_slopes(x: &[f64], y: &[f64], m: &[f64]) -> Self {
        let n = x.len();
        debug_assert!(n >= 2 && y.len() == n && m.len() == n);
        debug_assert!(x.windows(2).all(|w| w[1] > w[0]));
        let keys = (0..n)
            .map(|k| {
                let h_in = if k > 0 { x[k] - x[k - 1] } else { 0.0 };
                let h_out = if k + 1 < n { x[k + 1] - x[k] } else { 0.0 };
                Key::new(
                    x[k],
                    y[k],
                    Interpolation::StrokeBezier(
                        y[k] - h_in * m[k] / 3.0,
                        y[k] + h_out * m[k] / 3.0,
                    ),
                )
            })
            .collect();
        MonotoneCubic {
            spline: Spline::from_vec(keys),
            knots: KnotIndex::new(x),
            first: (x[0], y[0], m[0]),
            last: (x[n - 1], y[n - 1], m[n - 1]),
        }
    }

    /// Value and d/dh at `h`. Outside the knots the end value is held with the end slope reported
    /// (callers handle the outside themselves); a NaN height gives NaN (never a panic: the
    /// `splines` search would panic on NaN, so it is never called with one).
    pub(crate) fn value_slope(&self, h: f64) -> (f64, f64) {
        if h.is_nan() {
            return (f64::NAN, f64::NAN);
        }
        if h <= self.first.0 {
            return (self.first.1, self.first.2);
        }
        if h >= self.last.0 {
            return (self.last.1, self.last.2);
        }
        // first < h < last: the segment [k, k + 1] with knot k ≤ h < knot k + 1.
        let k = self.knots.segment(h);
        let keys = self.spline.keys();
        let (k0, k1) = (&keys[k], &keys[k + 1]);
        let (a, b) = (k0.value, k1.value);
        let u = match k0.interpolation {
            Interpolation::StrokeBezier(_, out) => out,
            _ => a,
        };
        let v = match k1.interpolation {
            Interpolation::StrokeBezier(inp, _) => inp,
            _ => b,
        };
        let width = k1.t - k0.t;
        let s = (h - k0.t) / width;
        let r = 1.0 - s;
        let value = a * r * r * r + 3.0 * s * r * (u * r + v * s) + b * s * s * s;
        let slope = 3.0 * ((u - a) * r * r + 2.0 * (v - u) * r * s + (b - v) * s * s) / width;
        (value, slope)
    }
}

/// Ascending knot heights with an O(1) segment search: a uniform grid of buckets over the
/// knots' span, each holding how many knots lie at or below its lower edge, so a search is a
/// bucket lookup and a binary search over the few knots inside one bucket. The answer is exactly
/// `partition_point`'s (a bucket whose edges rounding put on the wrong side of `h` falls back to
/// the full search). Written by hand: the refractive table's build and the tracer's closed-form
/// climb evaluate the fitted curves very often per sounding, and a binary search over every
/// level per evaluation showed in the survey's profiles.
#[derive(Debug, Clone)]
pub(crate) struct KnotIndex {
    knots_m: Vec<f64>,
    origin_m: f64,
    buckets_per_m: f64,
    /// Knots at or below each bucket's lower edge, and a last entry `knots_m.len()`.
    below: Vec<u32>,
}

/// Buckets per knot of the segment search.
const BUCKETS_PER_KNOT: usize = 4;

impl KnotIndex {
    /// The index of `knots_m` (ascending, finite, at least one).
    pub(crate) fn new(knots_m: &[f64]) -> Self {
        let n = knots_m.len();
        let origin_m = knots_m.first().copied().unwrap_or(0.0);
        let span_m = knots_m.last().copied().unwrap_or(0.0) - origin_m;
        let count = (BUCKETS_PER_KNOT * n).max(1);
        let buckets_per_m = if span_m > 0.0 {
            count as f64 / span_m
        } else {
            0.0
        };
        // The edges rise with b, so the count of knots at or below them only grows: one walk
        // (`partition_point` per edge, for ascending knots).
        let mut at_or_below = 0usize;
        let mut below: Vec<u32> = (0..count)
            .map(|b| {
                let edge_m = origin_m + b as f64 / buckets_per_m.max(f64::MIN_POSITIVE);
                while at_or_below < n && knots_m[at_or_below] <= edge_m {
                    at_or_below += 1;
                }
                at_or_below as u32
            })
            .collect();
        below.push(n as u32);
        KnotIndex {
            knots_m: knots_m.to_vec(),
            origin_m,
            buckets_per_m,
            below,
        }
    }

    /// The knots.
    pub(crate) fn knots_m(&self) -> &[f64] {
        &self.knots_m
    }

    /// Number of knots ≤ `h` (as `partition_point(|&t| t <= h)`); `h` not NaN.
    pub(crate) fn count_at_or_below(&self, h: f64) -> usize {
        let knots = &self.knots_m;
        let buckets = self.below.len() - 1;
        let at = (h - self.origin_m) * self.buckets_per_m;
        if at >= 0.0 && at < buckets as f64 {
            let b = at as usize;
            let (lo, hi) = (self.below[b] as usize, self.below[b + 1] as usize);
            // The bucket's edges bracket h unless rounding moved it across one.
            let lo_ok = lo == 0 || knots[lo - 1] <= h;
            let hi_ok = hi == knots.len() || knots[hi] > h;
            if lo_ok && hi_ok {
                return lo + knots[lo..hi].partition_point(|&t| t <= h);
            }
        }
        knots.partition_point(|&t| t <= h)
    }

    /// The segment [k, k + 1] holding `h`, clamped to the first and last (at least two knots).
    pub(crate) fn segment(&self, h: f64) -> usize {
        self.count_at_or_below(h).clamp(1, self.knots_m.len() - 1) - 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_search_and_evaluation_agree_with_the_splines_crate() {
        let x = [0.0, 1.0, 2.5, 2.75, 7.0, 30.0];
        let y = [3.0, -1.0, 4.0, 4.5, -2.0, 10.0];
        let c = MonotoneCubic::new(&x, &y);
        for i in 0..=3000 {
            let h = 30.0 * i as f64 / 3000.0;
            let (value, _) = c.value_slope(h);
            // The crate's own evaluation, where it serves (inside the knots).
            if let Some(reference) = c.spline.sample(h) {
                assert!(
                    (value - reference).abs() <= 1e-12,
                    "h {h}: {value} vs {reference}"
                );
            }
        }
        // At the knots the curve passes through the data.
        for (&h, &v) in x.iter().zip(&y) {
            assert!((c.value_slope(h).0 - v).abs() <= 1e-12, "knot {h}");
        }
    }

    #[test]
    fn matches_scipy_pchip_tangents() {
        // Expected slopes worked by hand from the published Fritsch–Butland rule and SciPy's
        // documented end rule (not from this code's output). Interior k=1: d0 = 1, d1 = 0.5, h0 = 1, h1 = 2 → w1 = 5, w2 = 4 → m = 9/(5/1 + 4/0.5) = 9/13.
        let x = [0.0, 1.0, 3.0, 4.0];
        let y = [0.0, 1.0, 2.0, 1.0];
        let m = pchip_slopes(&x, &y);
        assert!((m[1] - 9.0 / 13.0).abs() < 1e-15);
        // k=2: d1 = 0.5, d2 = −1: sign change → 0 (the local maximum sits on the knot).
        assert_eq!(m[2], 0.0);
        // start: ((2·1+2)·1 − 1·0.5)/3 = 3.5/3, same sign as d0, d0 and d1 same sign → kept.
        assert!((m[0] - 3.5 / 3.0).abs() < 1e-15);
        // end: h0 = 1 (last), h1 = 2, d0 = −1, d1 = 0.5: ((2+2)(−1) − 0.5)/3 = −1.5; sign flip
        // of d and |m| ≤ 3|d0| → kept.
        assert!((m[3] + 1.5).abs() < 1e-15);
    }

    #[test]
    fn hermite_reproduces_a_cubic_with_exact_slopes() {
        // y = x³ − 2x, y' = 3x² − 2: a cubic Hermite with exact slopes is exact.
        let x: Vec<f64> = (0..6).map(|i| i as f64 * 0.7 - 1.0).collect();
        let y: Vec<f64> = x.iter().map(|t| t * t * t - 2.0 * t).collect();
        let m: Vec<f64> = x.iter().map(|t| 3.0 * t * t - 2.0).collect();
        let c = MonotoneCubic::with_slopes(&x, &y, &m);
        for i in 0..500 {
            let t = -1.0 + 3.5 * i as f64 / 499.0;
            let (v, s) = c.value_slope(t);
            assert!((v - (t * t * t - 2.0 * t)).abs() < 1e-12, "{t}");
            assert!((s - (3.0 * t * t - 2.0)).abs() < 1e-11, "{t}");
        }
    }

    #[test]
    fn nan_and_ends_do_not_panic() {
        let c = MonotoneCubic::new(&[0.0, 1.0], &[2.0, 3.0]);
        assert!(c.value_slope(f64::NAN).0.is_nan());
        assert_eq!(c.value_slope(1.0), (3.0, 1.0));
        assert_eq!(c.value_slope(-5.0), (2.0, 1.0));
        let (v, s) = c.value_slope(0.25);
        assert!((v - 2.25).abs() < 1e-15 && (s - 1.0).abs() < 1e-14);
    }

    #[test]
    fn the_bucket_search_is_partition_point() {
        // Clustered, sparse and repeated-spacing knots, probed on, between and beyond them.
        let mut knots = vec![
            -3.0,
            0.0,
            0.001,
            0.002,
            0.5,
            7.25,
            7.5,
            100.0,
            1e4,
            3e4 + 0.1,
        ];
        knots.extend((0..200).map(|i| 3.1e4 + i as f64 * 1e-3));
        let index = KnotIndex::new(&knots);
        let mut probes = knots.clone();
        probes.extend(knots.iter().map(|k| k + 1e-9));
        probes.extend(knots.iter().map(|k| k - 1e-9));
        probes.extend(knots.iter().map(|&k| f64::from_bits(k.to_bits() + 1)));
        probes.extend((0..20_000).map(|i| -10.0 + i as f64 * 1.6));
        probes.extend([f64::NEG_INFINITY, f64::INFINITY, -1e300, 1e300]);
        for h in probes {
            assert_eq!(
                index.count_at_or_below(h),
                knots.partition_point(|&t| t <= h),
                "h = {h:e}"
            );
        }
        let single = KnotIndex::new(&[5.0]);
        for h in [4.0, 5.0, 6.0] {
            assert_eq!(single.count_at_or_below(h), usize::from(h >= 5.0));
        }
    }
}
