//! Render — the sun seen from the sea surface, for its glitter. In: the tracer and the sky's
//! extinction. Out: a table by the sun's true elevation above a sea point's own horizontal of its
//! apparent elevation there (the launch elevation of the ray from the sea that leaves towards
//! it) and the optical depth of that ray, for every true elevation a sun can have.
//!
//! A sea point at ground distance d from the camera has its vertical tilted by d/R, so the sun
//! stands higher (towards it) or lower (away) by up to d/R above its horizontal than above the
//! camera's. Near the surface of a duct the refraction depends strongly on that elevation (fig12:
//! 1.54° for a sun 1.5° below the horizontal, 0.5° for one at 0.2°), so each sea point needs the
//! refraction of its own sun, not the camera foot's with the tilt added.
//!
//! The table is one set of rays launched from the sea surface (height 0) from level up to
//! [`MAX_LAUNCH_RAD`], each with the elevation it leaves the atmosphere at (its true elevation)
//! and its optical depth: a map from launch to true elevation, inverted by cubic interpolation
//! through four neighbouring rays (rays whose true elevation falls below a lower ray's are left
//! out). Rays are added at the middle of every interval whose middle ray the table without it
//! mispredicts by more than [`LAUNCH_TOLERANCE_RAD`] in the launch or [`DEPTH_TOLERANCE`] in the
//! optical depth, so they crowd where the final elevation changes fast (a duct's trapping edge).
//! A ray that does not leave (trapped in a duct, or back on the sea) passes below every sun: a
//! sun below the lowest leaving ray is hidden. The table depends on the atmosphere and the sky
//! alone, so the frames of a sweep share it.

use rayon::prelude::*;

use super::ray_model::{FanEnd, RayTracer};
use crate::scene::sky::Extinction;

/// How far (rad) the interpolated launch of an interval's middle ray may be from its traced
/// launch before the interval is halved; the middle ray is kept either way, so the finished
/// table errs by less (unit-tested against the renderer's launch search to 1e-7 rad). 0.2″: the
/// glitter's Cox–Munk factor changes with the sun's elevation on the scale of the wave slopes'
/// spread (0.055 rad on a calm sea), so on any sea whose slopes spread wider than a milliradian
/// this moves it by less than the band fill's tolerance of 1e-3.
pub(super) const LAUNCH_TOLERANCE_RAD: f64 = 1e-6;

/// How far the interpolated optical depth of an interval's middle ray may be from its traced
/// one before the interval is halved: an error δ in the depth scales the glitter by e^−δ, here
/// by at most 0.1 %, the band fill's tolerance.
pub(super) const DEPTH_TOLERANCE: f64 = 1e-3;

/// Optical depth beyond which the sun's light at the sea counts as lost (e^−50 ≈ 2·10⁻²²): a
/// duct's trapping edge is not refined further once the lowest leaving ray's depth exceeds it.
const DARK_DEPTH: f64 = 50.0;

/// Narrowest launch interval (rad) halved: the renderer's launch search's tolerance.
const MIN_WIDTH_RAD: f64 = 5e-9;

/// The lowest launch above level traced before refinement (rad); the first launches double
/// from it up to [`MAX_LAUNCH_RAD`].
const FIRST_LAUNCH_RAD: f64 = 1e-3;

/// Highest launch elevation traced (rad); above its ray's true elevation the refraction is taken
/// as that ray's.
const MAX_LAUNCH_RAD: f64 = 1.5;

/// Most rays in a table (refinement stops there).
const MAX_RAYS: usize = 4096;

/// One ray from the sea surface.
#[derive(Debug, Clone, Copy)]
struct SeaRay {
    launch_rad: f64,
    /// Final elevation above the launch point's horizontal (rad); `None`: it does not leave.
    true_rad: Option<f64>,
    /// Optical depth per channel of its path out (+∞ when it does not leave).
    depth: [f64; 3],
}

impl SeaRay {
    fn trace(tracer: &dyn RayTracer, extinction: &Extinction, launch_rad: f64) -> Self {
        let (ray, paths) =
            tracer.trace_to_sky_with_density_paths(0.0, launch_rad, extinction.scale_heights_m());
        let true_rad = match ray.end {
            FanEnd::Sky { elevation_rad } if elevation_rad.is_finite() => Some(elevation_rad),
            _ => None,
        };
        let depth = paths
            .filter(|_| true_rad.is_some())
            .map_or([f64::INFINITY; 3], |p| extinction.path_optical_depth(p));
        SeaRay {
            launch_rad,
            true_rad,
            depth,
        }
    }

    /// The least optical depth of its channels.
    fn least_depth(&self) -> f64 {
        self.depth.iter().copied().fold(f64::INFINITY, f64::min)
    }
}

/// The sun's apparent elevation and optical depth at the sea surface, by its true elevation
/// above the sea point's horizontal, over the range a frame's sea points need.
#[derive(Debug, Clone)]
pub(super) struct SeaSunTable {
    /// True elevations of the leaving rays (rad), ascending.
    true_rad: Vec<f64>,
    /// Their launch (apparent) elevations (rad).
    launch_rad: Vec<f64>,
    /// Their optical depths per channel.
    depth: Vec<[f64; 3]>,
    /// Per interval between neighbouring rays: the interpolating cubics (launch, then the
    /// three depths) in the fraction u ∈ [0, 1] of the interval, as monomial coefficients.
    cubics: Vec<[[f64; 4]; 4]>,
    /// 1 / each interval's width in true elevation.
    inv_width: Vec<f64>,
    /// The first interval of each of [`BUCKETS_PER_RAY`] × rays equal buckets of true
    /// elevation over the table (so a lookup walks at most a few intervals).
    buckets: Vec<u32>,
    /// Buckets per radian of true elevation.
    bucket_scale: f64,
    /// Whether a sun below the lowest leaving ray is hidden (that ray is launched level, or
    /// just above rays that do not leave); otherwise below the table the refraction is the
    /// lowest ray's.
    hidden_below: bool,
    /// Bounds on each interval's cubics ([`CellBounds`]), and on runs of 2, 4, 8, … intervals:
    /// `bounds[k][i]` bounds intervals i … i + 2^k − 1 (a sparse table, so that the bounds over
    /// any run of intervals are one lookup).
    bounds: Vec<Vec<CellBounds>>,
    /// Rays traced to build the table.
    #[cfg_attr(not(test), allow(dead_code))]
    rays: usize,
}

impl SeaSunTable {
    /// Tabulate every true elevation a sun can have above a sea point's horizontal: rays from
    /// launched level up to [`MAX_LAUNCH_RAD`]. The table depends on the atmosphere and the
    /// sky's extinction alone, not on the sun or the frame, so the frames of a sweep share it
    /// and a single render builds the very same one.
    pub(super) fn build(tracer: &dyn RayTracer, extinction: &Extinction) -> Self {
        let trace = |a: f64| SeaRay::trace(tracer, extinction, a);
        // Launches doubling from a milliradian: the map changes fastest near the horizon.
        let launches: Vec<f64> = std::iter::once(0.0)
            .chain((0..).map(|k| FIRST_LAUNCH_RAD * f64::from(1u32 << k)))
            .take_while(|&a| a < MAX_LAUNCH_RAD)
            .chain(std::iter::once(MAX_LAUNCH_RAD))
            .collect();
        let rays: Vec<SeaRay> = launches.into_par_iter().map(trace).collect();
        Self::from_rays(&refine(&trace, rays))
    }

    /// The table of `rays` (ascending launches).
    fn from_rays(rays: &[SeaRay]) -> Self {
        let first_leaving = rays.iter().position(|r| r.true_rad.is_some());
        let hidden_below = match first_leaving {
            Some(0) => rays[0].launch_rad <= 0.0,
            _ => true,
        };
        let (mut true_rad, mut launch_rad, mut depth) = (Vec::new(), Vec::new(), Vec::new());
        for r in rays {
            let Some(s) = r.true_rad else {
                continue;
            };
            // Only rays above every lower one's true elevation (one launch per true elevation).
            if true_rad.last().is_some_and(|&last| s <= last) {
                continue;
            }
            true_rad.push(s);
            launch_rad.push(r.launch_rad);
            depth.push(r.depth);
        }
        let (cubics, inv_width) = cubics(&true_rad, &launch_rad, &depth);
        let (buckets, bucket_scale) = buckets(&true_rad);
        let bounds = sparse_bounds(cubics.iter().map(CellBounds::of).collect());
        SeaSunTable {
            true_rad,
            launch_rad,
            depth,
            cubics,
            inv_width,
            buckets,
            bucket_scale,
            hidden_below,
            bounds,
            rays: rays.len(),
        }
    }

    /// How many rays the table traced.
    #[cfg(test)]
    pub(super) fn rays(&self) -> usize {
        self.rays
    }

    /// The apparent elevation (rad) above the sea point's horizontal of a sun at true elevation
    /// `true_rad` above it (where it is below the sea's apparent horizon, the lowest leaving
    /// ray's), and the optical depth per channel of its light there (+∞ where hidden).
    pub(super) fn at(&self, true_rad: f64) -> (f64, [f64; 3]) {
        let n = self.true_rad.len();
        if n == 0 {
            return (0.0, [f64::INFINITY; 3]);
        }
        let (s0, s_last) = (self.true_rad[0], self.true_rad[n - 1]);
        if true_rad.is_nan() || true_rad < s0 {
            let a = self.launch_rad[0];
            return if self.hidden_below || true_rad.is_nan() {
                (a, [f64::INFINITY; 3])
            } else {
                (true_rad + a - s0, self.depth[0])
            };
        }
        if true_rad >= s_last || n == 1 {
            return (
                true_rad + self.launch_rad[n - 1] - s_last,
                self.depth[n - 1],
            );
        }
        let (i, u) = self.cell(true_rad);
        let c = &self.cubics[i];
        let horner = |k: usize| c[k][0] + u * (c[k][1] + u * (c[k][2] + u * c[k][3]));
        (horner(0), [horner(1), horner(2), horner(3)])
    }

    /// The interval of the table holding `true_rad` (strictly inside its span) and the
    /// fraction of the way through it.
    #[inline]
    fn cell(&self, true_rad: f64) -> (usize, f64) {
        let n = self.true_rad.len();
        let b = ((true_rad - self.true_rad[0]) * self.bucket_scale) as usize;
        let mut i = self.buckets[b.min(self.buckets.len() - 1)] as usize;
        while i > 0 && true_rad < self.true_rad[i] {
            i -= 1;
        }
        while i + 2 < n && true_rad >= self.true_rad[i + 1] {
            i += 1;
        }
        (i, (true_rad - self.true_rad[i]) * self.inv_width[i])
    }

    /// The apparent elevation of [`Self::at`] alone (the same value, without the depths).
    pub(super) fn apparent_rad(&self, true_rad: f64) -> f64 {
        let n = self.true_rad.len();
        if n < 2
            || true_rad.is_nan()
            || true_rad < self.true_rad[0]
            || true_rad >= self.true_rad[n - 1]
        {
            return self.at(true_rad).0;
        }
        let (i, u) = self.cell(true_rad);
        let c = &self.cubics[i][0];
        c[0] + u * (c[1] + u * (c[2] + u * c[3]))
    }

    /// Bounds (lo, hi) on the apparent elevation [`Self::at`] gives for every true elevation in
    /// `true_rad` (lo, hi), padded for rounding: the ends' values and the bounds of the cubics
    /// of every interval the range meets (whether or not the map is monotone). `None` when the
    /// sun is hidden at every one of them (below the sea's horizon).
    pub(super) fn apparent_range(&self, true_rad: (f64, f64)) -> Option<(f64, f64)> {
        const ROUNDING_RAD: f64 = 1e-9;
        let (lo, hi) = true_rad;
        let hidden = |s: f64| self.true_rad.first().is_none_or(|&s0| s < s0) && self.hidden_below;
        if hidden(hi) && !hi.is_nan() {
            return None;
        }
        let n = self.true_rad.len();
        if n >= 2 && lo > self.true_rad[0] && hi < self.true_rad[n - 1] && lo <= hi {
            // Inside the table: the bounds of the cubics of the intervals met hold the ends.
            let (p, q) = self.launch_bounds_over(self.cell(lo).0, self.cell(hi).0);
            return Some((p - ROUNDING_RAD, q + ROUNDING_RAD));
        }
        let (a, b) = (self.apparent_rad(lo), self.apparent_rad(hi));
        let (mut min, mut max) = (a.min(b), a.max(b));
        if n >= 2 && lo <= hi && hi > self.true_rad[0] && lo < self.true_rad[n - 1] {
            // The table's own ends where the range reaches past them.
            let first = if lo > self.true_rad[0] {
                self.cell(lo).0
            } else {
                0
            };
            let last = if hi < self.true_rad[n - 1] {
                self.cell(hi).0
            } else {
                n - 2
            };
            let (p, q) = self.launch_bounds_over(first, last);
            (min, max) = (min.min(p), max.max(q));
        }
        Some((min - ROUNDING_RAD, max + ROUNDING_RAD))
    }

    /// Per channel, an upper bound on the transmittance e^−τ of the optical depths τ that
    /// [`Self::at`] gives for every true elevation in `true_rad` (lo, hi), padded for rounding:
    /// of the least depth of the intervals the range meets and of the depths it takes beyond
    /// the table's ends. NaN where no bound is derived (a NaN end, or a NaN depth).
    pub(super) fn transmittance_bound(&self, true_rad: (f64, f64)) -> [f64; 3] {
        const ROUNDING: f64 = 1e-9;
        let (lo, hi) = true_rad;
        let n = self.true_rad.len();
        if lo.is_nan() || hi.is_nan() || lo > hi {
            return [f64::NAN; 3];
        }
        if n == 0 {
            return [0.0; 3];
        }
        let (s0, s_last) = (self.true_rad[0], self.true_rad[n - 1]);
        let mut least = [f64::INFINITY; 3];
        let mut take = |d: [f64; 3]| least = least_depths(least, d);
        if lo < s0 && !self.hidden_below {
            take(self.depth[0]);
        }
        if hi >= s_last || n == 1 {
            take(self.depth[n - 1]);
        }
        if n >= 2 && hi >= s0 && lo < s_last {
            let first = if lo > s0 { self.cell(lo).0 } else { 0 };
            let last = if hi < s_last { self.cell(hi).0 } else { n - 2 };
            take(self.bounds_over(first, last).depth_lo);
        }
        least.map(|d| {
            if d == f64::INFINITY {
                0.0
            } else {
                (ROUNDING * (1.0 + d.abs()) - d).exp()
            }
        })
    }

    /// Bounds on the launch cubics of intervals `first` ..= `last`.
    fn launch_bounds_over(&self, first: usize, last: usize) -> (f64, f64) {
        self.bounds_over(first, last).launch
    }

    /// Bounds on the cubics of intervals `first` ..= `last`.
    fn bounds_over(&self, first: usize, last: usize) -> CellBounds {
        let count = last - first + 1;
        let k = (usize::BITS - 1 - count.leading_zeros()) as usize;
        self.bounds[k][first].merge(self.bounds[k][last + 1 - (1 << k)])
    }
}

/// The least and greatest values on u ∈ [0, 1] of the cubic c0 + c1 u + c2 u² + c3 u³.
fn cubic_bounds(c: [f64; 4]) -> (f64, f64) {
    let value = |u: f64| c[0] + u * (c[1] + u * (c[2] + u * c[3]));
    let (mut lo, mut hi) = (value(0.0).min(value(1.0)), value(0.0).max(value(1.0)));
    // Turning points: roots of c1 + 2 c2 u + 3 c3 u² inside (0, 1).
    let (qa, qb, qc) = (3.0 * c[3], 2.0 * c[2], c[1]);
    let roots = if qa == 0.0 {
        [(qb != 0.0).then(|| -qc / qb), None]
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 {
            [None, None]
        } else {
            // The form without cancellation: q = −(qb + sign(qb)·√disc)/2, roots q/qa and qc/q
            // (the textbook form loses the small root when qa is tiny).
            let q = -0.5 * (qb + qb.signum() * disc.sqrt());
            [Some(q / qa), (q != 0.0).then(|| qc / q)]
        }
    };
    for u in roots.into_iter().flatten().filter(|u| *u > 0.0 && *u < 1.0) {
        lo = lo.min(value(u));
        hi = hi.max(value(u));
    }
    (lo, hi)
}

/// Bounds on an interval's cubics, or on a run of intervals'.
#[derive(Debug, Clone, Copy)]
struct CellBounds {
    /// The launch cubic's least and greatest values.
    launch: (f64, f64),
    /// Each depth cubic's least value (NaN where a coefficient is).
    depth_lo: [f64; 3],
}

impl CellBounds {
    /// The bounds of one interval's cubics (launch, then the three depths).
    fn of(cubics: &[[f64; 4]; 4]) -> Self {
        let depth_lo = [1, 2, 3].map(|k| {
            let c = cubics[k];
            if c.iter().any(|v| v.is_nan()) {
                f64::NAN
            } else {
                cubic_bounds(c).0
            }
        });
        CellBounds {
            launch: cubic_bounds(cubics[0]),
            depth_lo,
        }
    }

    /// The bounds of both runs of intervals.
    fn merge(self, other: Self) -> Self {
        let (p, q) = (self.launch, other.launch);
        CellBounds {
            launch: (p.0.min(q.0), p.1.max(q.1)),
            depth_lo: least_depths(self.depth_lo, other.depth_lo),
        }
    }
}

/// The lesser depth of `a` and `b` per channel, NaN where either is.
fn least_depths(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|c| {
        if a[c].is_nan() || b[c].is_nan() {
            f64::NAN
        } else {
            a[c].min(b[c])
        }
    })
}

/// The sparse table of [`SeaSunTable::bounds`] over per-interval `bounds`.
fn sparse_bounds(bounds: Vec<CellBounds>) -> Vec<Vec<CellBounds>> {
    let mut levels = vec![bounds];
    loop {
        let prev = levels.last().expect("one level");
        let span = 1 << (levels.len() - 1);
        if prev.len() <= span {
            return levels;
        }
        let next = (0..prev.len() - span)
            .map(|i| prev[i].merge(prev[i + span]))
            .collect();
        levels.push(next);
    }
}

/// Buckets of true elevation per ray of a table.
const BUCKETS_PER_RAY: usize = 4;

/// The cubics of [`interpolate`] on each interval of `xs` (ascending, at least two), in the
/// fraction of the interval (found from its values at u = 0, ⅓, ⅔, 1; an interval next to an
/// infinite depth is infinitely deep), and 1 / the intervals' widths.
fn cubics(xs: &[f64], launch: &[f64], depth: &[[f64; 3]]) -> (Vec<[[f64; 4]; 4]>, Vec<f64>) {
    if xs.len() < 2 {
        return (Vec::new(), Vec::new());
    }
    let fit = |v: [f64; 4]| {
        if !v.iter().all(|x| x.is_finite()) {
            return [f64::INFINITY, 0.0, 0.0, 0.0];
        }
        // The cubic through (0, v0), (⅓, v1), (⅔, v2), (1, v3) in monomial form.
        let c1 = (-11.0 * v[0] + 18.0 * v[1] - 9.0 * v[2] + 2.0 * v[3]) / 2.0;
        let c2 = 9.0 * (2.0 * v[0] - 5.0 * v[1] + 4.0 * v[2] - v[3]) / 2.0;
        let c3 = 27.0 * (-v[0] + 3.0 * v[1] - 3.0 * v[2] + v[3]) / 6.0;
        [v[0], c1, c2, c3]
    };
    xs.windows(2)
        .map(|w| {
            let at = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0].map(|u| {
                // The ends exactly at the rays (the cubic passes through them).
                let s = if u == 1.0 {
                    w[1]
                } else {
                    w[0] + (w[1] - w[0]) * u
                };
                interpolate(xs, launch, depth, s.min(w[1]))
            });
            let mut c = [[0.0; 4]; 4];
            c[0] = fit(at.map(|(a, _)| a));
            for k in 0..3 {
                c[k + 1] = fit(at.map(|(_, d)| d[k]));
            }
            (c, 1.0 / (w[1] - w[0]))
        })
        .unzip()
}

/// The buckets of [`SeaSunTable::buckets`] over `xs` (ascending, at least two) and their
/// number per radian.
fn buckets(xs: &[f64]) -> (Vec<u32>, f64) {
    let n = xs.len();
    if n < 2 {
        return (vec![0], 0.0);
    }
    let count = BUCKETS_PER_RAY * n;
    let scale = count as f64 / (xs[n - 1] - xs[0]);
    let mut i = 0;
    let buckets = (0..count)
        .map(|b| {
            let s = xs[0] + b as f64 / scale;
            while i + 2 < n && s >= xs[i + 1] {
                i += 1;
            }
            i as u32
        })
        .collect();
    (buckets, scale)
}

/// `rays` (ascending launches) with rays added where the table needs them (module docs),
/// ascending.
fn refine(trace: &(impl Fn(f64) -> SeaRay + Sync), mut rays: Vec<SeaRay>) -> Vec<SeaRay> {
    // Intervals to test, by their ends' launches.
    let mut open: Vec<(f64, f64)> = rays
        .windows(2)
        .filter(|w| needs_middle(w[0], w[1]))
        .map(|w| (w[0].launch_rad, w[1].launch_rad))
        .collect();
    while !open.is_empty() && rays.len() < MAX_RAYS {
        let middles: Vec<SeaRay> = open
            .par_iter()
            .map(|&(a, b)| trace(0.5 * (a + b)))
            .collect();
        let table = SeaSunTable::from_rays(&rays);
        let mut next = Vec::new();
        for (&(a, b), m) in open.iter().zip(&middles) {
            if !table.predicts(m) {
                next.push((a, m.launch_rad));
                next.push((m.launch_rad, b));
            }
        }
        rays.extend(middles);
        rays.sort_by(|x, y| x.launch_rad.total_cmp(&y.launch_rad));
        // Halves go on only while they may still matter (and are wide enough).
        open = next
            .into_iter()
            .filter(|&(a, b)| {
                let find = |l: f64| {
                    let i = rays.partition_point(|r| r.launch_rad < l);
                    rays[i.min(rays.len() - 1)]
                };
                needs_middle(find(a), find(b))
            })
            .collect();
    }
    rays
}

/// Whether the interval between rays `p` and `q` (ascending launches) needs its middle ray
/// tested: it is wide enough, and both leave, or it is a trapping edge whose leaving side is
/// not dark.
fn needs_middle(p: SeaRay, q: SeaRay) -> bool {
    if q.launch_rad - p.launch_rad <= MIN_WIDTH_RAD {
        return false;
    }
    match (p.true_rad, q.true_rad) {
        (None, None) => false,
        (None, Some(_)) => q.least_depth() < DARK_DEPTH,
        (Some(_), None) => p.least_depth() < DARK_DEPTH,
        (Some(_), Some(_)) => true,
    }
}

impl SeaSunTable {
    /// Whether the table predicts ray `m` (traced inside its span) within the tolerances.
    fn predicts(&self, m: &SeaRay) -> bool {
        let Some(s) = m.true_rad else {
            // A ray that does not leave between leaving ones: nothing to interpolate.
            return false;
        };
        let n = self.true_rad.len();
        if n < 2 || s <= self.true_rad[0] || s >= self.true_rad[n - 1] {
            return false;
        }
        let (a, depth) = interpolate(&self.true_rad, &self.launch_rad, &self.depth, s);
        let depth_ok = (0..3)
            .all(|c| m.depth[c] > DARK_DEPTH || (depth[c] - m.depth[c]).abs() <= DEPTH_TOLERANCE);
        (a - m.launch_rad).abs() <= LAUNCH_TOLERANCE_RAD && depth_ok
    }
}

/// The launch and depths at true elevation `s` (inside `xs`, ascending, at least two) by the
/// cubic through the four rays around it (three or two at the ends); depths by linear
/// interpolation next to a ray with an infinite one (then infinite between).
fn interpolate(xs: &[f64], launch: &[f64], depth: &[[f64; 3]], s: f64) -> (f64, [f64; 3]) {
    let n = xs.len();
    let i = xs.partition_point(|&x| x <= s).clamp(1, n - 1) - 1;
    let lo = i.saturating_sub(1);
    let hi = (i + 3).min(n);
    let window = lo..hi;
    let weights = lagrange_weights(&xs[window.clone()], s);
    let a: f64 = window
        .clone()
        .zip(&weights)
        .map(|(j, w)| w * launch[j])
        .sum();
    let finite = window
        .clone()
        .all(|j| depth[j].iter().all(|d| d.is_finite()));
    let d = if finite {
        [0, 1, 2].map(|c| {
            window
                .clone()
                .zip(&weights)
                .map(|(j, w)| w * depth[j][c])
                .sum()
        })
    } else {
        let t = (s - xs[i]) / (xs[i + 1] - xs[i]);
        [0, 1, 2].map(|c| {
            let (p, q) = (depth[i][c], depth[i + 1][c]);
            if p.is_finite() && q.is_finite() {
                p + (q - p) * t
            } else {
                f64::INFINITY
            }
        })
    };
    (a, d)
}

/// The Lagrange weights at `x` of the polynomial through the abscissae `xs` (up to four; the
/// rest are zero).
fn lagrange_weights(xs: &[f64], x: f64) -> [f64; 4] {
    let mut w = [0.0; 4];
    for (j, wj) in w.iter_mut().enumerate().take(xs.len()) {
        *wj = xs
            .iter()
            .enumerate()
            .filter(|&(k, _)| k != j)
            .map(|(_, &xk)| (x - xk) / (xs[j] - xk))
            .product();
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::reflection::sea_level_sun_launch_rad;
    use crate::render::test_rays::Leaving;
    use crate::scene::sky::Sky;

    /// The worst difference (rad) between the table's launch and the renderer's launch search
    /// over `count` true elevations across `sun` ± `tilt`, where the sun's light is not lost.
    fn worst_launch_error(
        tracer: &dyn RayTracer,
        table: &SeaSunTable,
        sun: f64,
        tilt: f64,
        count: usize,
    ) -> f64 {
        let mut worst = 0.0f64;
        for i in 0..=count {
            let s = sun - tilt + 2.0 * tilt * i as f64 / count as f64;
            let (got, depth) = table.at(s);
            if depth[0].is_nan() || depth[0] >= DARK_DEPTH {
                continue;
            }
            let want = sea_level_sun_launch_rad(tracer, s).expect("the sun is lit");
            worst = worst.max((got - want).abs());
        }
        worst
    }

    /// Refraction falling from 0.6° at the surface (a strong duct): a ray launched at e leaves at
    /// e − 0.0105 e^(−e/0.02) rad.
    fn smooth_duct(e: f64) -> Option<f64> {
        Some(e - 0.0105 * (-e / 0.02).exp())
    }

    /// [`smooth_duct`], but trapping every ray launched below 0.2°: a sun below its lowest
    /// leaving ray is hidden.
    fn trapping_duct(e: f64) -> Option<f64> {
        (e >= 0.0035).then(|| smooth_duct(e)).flatten()
    }

    /// Test rays leaving where a map of the launch says ([`Leaving`]).
    type MapRays = Leaving<fn(f64) -> Option<f64>>;

    /// The tables of [`smooth_duct`] and [`trapping_duct`] by name, with their tracers.
    fn duct_tables() -> Vec<(&'static str, MapRays, SeaSunTable)> {
        let extinction = Sky::default().sun_extinction();
        [
            ("smooth", smooth_duct as fn(f64) -> Option<f64>),
            ("ducted", trapping_duct),
        ]
        .into_iter()
        .map(|(name, leave)| {
            let tracer = Leaving::new(leave);
            let table = SeaSunTable::build(&tracer, &extinction);
            (name, tracer, table)
        })
        .collect()
    }

    #[test]
    fn the_table_inverts_the_sea_rays_within_a_tenth_of_a_microradian() {
        for (name, tracer, table) in duct_tables() {
            let rays = tracer.traces();
            eprintln!("{name}: {rays} traces");
            assert!(rays <= 300, "{name}: {rays} traces");
            for (sun_deg, tilt) in [(-0.3, 0.01), (0.5, 0.04), (5.0, 0.02), (20.0, 0.05)] {
                let sun = f64::to_radians(sun_deg);
                let worst = worst_launch_error(&tracer, &table, sun, tilt, 400);
                eprintln!("{name} {sun_deg}° ± {tilt}: worst {worst:.2e} rad");
                assert!(worst <= 1e-7, "{name} {sun_deg}°: {worst:e} rad");
            }
        }
    }

    #[test]
    fn fig12s_ducted_sun_table_matches_the_launch_search_across_its_sea() {
        use crate::render::{RenderOptions, prepare_tracer};
        use crate::scene::Scene;
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/data/scenes/fig12_novaya_zemlya.toml"
        );
        let scene = Scene::from_file(std::path::Path::new(path)).expect("scene");
        let loaded = scene.atmosphere.load().expect("atmosphere");
        let refractive = loaded.as_ref().map(|a| &a.refractive);
        let tracer = prepare_tracer(&scene, refractive, &RenderOptions::default()).expect("tracer");
        let sun = scene.sun.expect("sun").elevation_rad;
        // Sea points out to 250 km tilt the sun by up to 0.039 rad.
        let tilt = 250e3 / scene.earth_radius_m;
        let extinction = scene.sky.sun_extinction();
        let table = SeaSunTable::build(tracer.as_ref(), &extinction);
        let worst = worst_launch_error(tracer.as_ref(), &table, sun, tilt, 200);
        eprintln!("fig12: {} rays, worst {worst:.2e} rad", table.rays());
        assert!(worst <= 1e-7, "{worst:e} rad");
    }

    #[test]
    fn cubic_bounds_hold_the_cubics_turning_points() {
        // A nearly quadratic cubic (c3 tiny): its minimum at u = 0.5 is 0.75.
        let (lo, hi) = cubic_bounds([1.0, -1.0, 1.0, 1e-15]);
        assert!((lo - 0.75).abs() < 1e-12 && hi == 1.0 + 1e-15, "{lo} {hi}");
        // Two turning points inside (0, 1), at ½ ∓ 1/√12, beyond the ends' values.
        let (lo, hi) = cubic_bounds([1.0, -24.0, 72.0, -48.0]);
        let turn = 0.5 - 0.5 / 3f64.sqrt();
        let value = |u: f64| 1.0 - 24.0 * u + 72.0 * u * u - 48.0 * u * u * u;
        assert!((lo - value(turn)).abs() < 1e-12, "{lo}");
        assert!((hi - value(1.0 - turn)).abs() < 1e-12, "{hi}");
        // Monotone: the ends.
        assert_eq!(cubic_bounds([0.0, 1.0, 0.0, 0.0]), (0.0, 1.0));
    }

    #[test]
    fn the_apparent_range_bounds_every_lookup_of_a_folded_map() {
        let extinction = Sky::default().sun_extinction();
        // A map that folds back between launches 0.01 and 0.012 rad (true elevation falling
        // by 2e-4 rad there), as a ray bent back down by a layer aloft would.
        let folded = |e: f64| {
            let fold = if e < 0.01 {
                0.0
            } else if e < 0.012 {
                -1.1 * (e - 0.01)
            } else {
                -0.0022
            };
            Some(e - 0.005 * (-e / 0.02).exp() + fold)
        };
        let tracer = Leaving::new(folded);
        let table = SeaSunTable::build(&tracer, &extinction);
        let mut widest = 0.0f64;
        for i in 0..200 {
            let lo = -0.01 + 0.03 * f64::from(i) / 200.0;
            for width in [0.0, 1e-4, 2e-3, 0.02] {
                let range = table.apparent_range((lo, lo + width));
                for k in 0..=50 {
                    let s = lo + width * f64::from(k) / 50.0;
                    let (e, depth) = table.at(s);
                    match range {
                        Some((a, b)) => assert!(a <= e && e <= b, "{s}: {e} outside {a}…{b}"),
                        None => assert!(depth[0].is_infinite(), "{s}: lit but no range"),
                    }
                }
                let Some((a, b)) = range else { continue };
                // Not the whole table's span: a narrow range gives a narrow bound.
                if width == 1e-4 {
                    widest = widest.max(b - a);
                }
            }
        }
        assert!(widest < 3e-3, "{widest}");
    }

    #[test]
    fn the_transmittance_bound_holds_every_lookup_and_is_tight_over_a_narrow_range() {
        for (name, _, table) in duct_tables() {
            let mut loosest = 0.0f64;
            for i in 0..300 {
                // From below the table (hidden or not) to above its last ray (1.5 rad).
                let lo = -0.02 + 1.6 * (f64::from(i) / 300.0).powi(3);
                for width in [0.0, 1e-6, 1e-4, 0.05] {
                    let bound = table.transmittance_bound((lo, lo + width));
                    for k in 0..=40 {
                        let s = lo + width * f64::from(k) / 40.0;
                        let (_, depth) = table.at(s);
                        for c in 0..3 {
                            let t = (-depth[c]).exp();
                            assert!(t <= bound[c], "{name} {s}: {t} above {}", bound[c]);
                            if width == 1e-6 && t > 1e-30 {
                                loosest = loosest.max(bound[c] / t);
                            }
                        }
                    }
                }
            }
            // Over a microradian the bound is within the least depth of the one or two table
            // intervals met, not the whole table's (the sun at its horizon is dimmed by orders of
            // magnitude more than high up).
            let (_, low) = table.at(0.001);
            let whole = table.transmittance_bound((-1.0, 2.0))[0] / (-low[0]).exp();
            eprintln!("{name}: loosest {loosest}, whole table {whole}");
            assert!(loosest < 3.0 && whole > 100.0, "{name}: {loosest} {whole}");
            assert!(table.transmittance_bound((f64::NAN, 0.0))[0].is_nan());
            assert!(table.transmittance_bound((0.1, 0.0))[0].is_nan());
        }
    }
}
