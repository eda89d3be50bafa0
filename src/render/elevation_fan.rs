//! Render — the elevation fan. In: a [`RayTracer`], the camera height, the card distances in view,
//! the frame's elevation range and pixel size. Out: an [`ElevationFan`]: rays sorted by apparent
//! elevation, refined where the transfer curve bends sharply, with O(1) lookup and interpolation.
//!
//! **Refinement and its error bound.** The fan starts with rays spaced two pixels (at the image
//! centre) apart in elevation, and every interval is bisected at least once — so the finished
//! fan is at most one pixel apart — except where the two rays belong to a *monotone family* and
//! miss every card (below). An interval [a, b] between neighbouring rays is bisected — its
//! midpoint m is traced — and it stays *open* (is bisected again in the next round) when any of:
//!
//! * the two ends and the midpoint do not end the same way (sea / sky / lost), or reach a card
//!   distance differently (one has a height there, another not) while one of them is low enough to
//!   hit a card there;
//! * at some card distance D with the heights below the top of the highest card at D, linear
//!   interpolation of the end heights misses the traced midpoint height by more than `tolerance_px`
//!   pixels, converted to elevation through the local slope: |h_m − (h_a + h_b)/2| /
//!   |(h_b − h_a)/(α_b − α_a)| > tolerance_px · pixel angle (a feature at height h_m is drawn at
//!   the wrong elevation by that much);
//! * with a sun in the scene, near the sun's elevation, the same test on the final sky elevation.
//!
//! **Monotone families.** Over a sphere with n = n(r), a ray keeps Bouguer's invariant
//! K = n·r·cos ψ (ψ its local elevation; K = n₀r₀cos α at the camera). Take two rays launched
//! upwards, α₁ < α₂, that never turned down ([`FanRay::monotone`]): at every radius
//! cos ψ = K/(n r) is smaller for ray 2, so ray 2 is steeper everywhere, reaches every radius at
//! a shorter ground distance, and at every ground distance is higher. A ray launched between
//! them has K between theirs, so n r > K₁ > K along ray 1's path: it cannot turn either, and it
//! lies between the two at every distance. The same holds for rays that descend into the sea
//! without turning (the steeper one is lower everywhere and lands first). So when both rays of
//! a base interval are of one such family and pass above the highest card top at every card
//! distance (or, into the sea, land before the same card distances), every ray between them does
//! too: they show the sky at their own apparent elevation (no sun in the scene) or the sea, and
//! the interval is not bisected. It stays two pixels wide; only the sea's grazing angle is
//! interpolated across it (the sea's colour changes smoothly with it).
//!
//! An interval is closed when its midpoint passes, or when it is narrower than
//! `tolerance_px` pixels (then any feature it shows is misplaced by less than that: every elevation
//! inside it lies within `tolerance_px` pixels of both traced rays), or at `max_depth` bisections.
//! So after refinement, wherever the transfer curve is smooth at the scale of the interval, features
//! are placed within `tolerance_px` pixels of where per-sample tracing puts them (the midpoint test
//! estimates the interpolation error of a locally quadratic curve: it is exact for a parabola);
//! at folds and caustics (slope → 0, or changes of how rays end), the error is confined to
//! intervals narrower than `tolerance_px` pixels. A feature of the transfer curve narrower than the
//! base spacing that the midpoint test misses (a wiggle between two samples) can be missed: the
//! spacing after the first bisection is one pixel, so it is smaller than a pixel row (monotone
//! families, which have no such features, keep two pixels). Pixel angle = 1/focal length:
//! off-centre pixels subtend slightly less (cos² of the off-axis angle), so there the bound in
//! pixels is larger by 1/cos² (1.07 at 15° off axis; 1.0003 in a 2° mirage frame; but 4 at 60°,
//! so very wide frames are sampled more coarsely than their edge pixels).

use rayon::prelude::*;

use super::ray_model::{FanEnd, FanRay, RayTracer};

/// What the fan needs to know about the scene to decide where to refine.
#[derive(Debug, Clone)]
pub struct FanSpec {
    /// Camera height above the surface (m).
    pub camera_height_m: f64,
    /// Ascending card distances (m) at which heights are traced.
    pub distances_m: Vec<f64>,
    /// Highest card top at each distance (m above the surface): above it, height errors are
    /// invisible.
    pub max_top_m: Vec<f64>,
    /// Whether a sun is in the scene (final sky directions matter).
    pub need_sky_direction: bool,
    /// Elevation band of the sun disc (rad), when there is one: sky-elevation errors matter there.
    pub sun_band_rad: Option<(f64, f64)>,
    /// Lowest and highest apparent elevation the frame needs (rad).
    pub elevation_range_rad: (f64, f64),
    /// Angle of one pixel (rad).
    pub pixel_rad: f64,
    /// Allowed feature misplacement (pixels).
    pub tolerance_px: f64,
    /// Cap on the number of bisections of a base interval.
    pub max_depth: u32,
}

/// Rays sorted by elevation with a uniform guide table for O(1) lookup.
#[derive(Debug, Clone)]
pub struct ElevationFan {
    alphas: Vec<f64>,
    /// Heights, `distances` per ray, row-major.
    heights: Vec<Option<f64>>,
    ends: Vec<FanEnd>,
    /// Each ray's [`FanRay::monotone`].
    monotone: Vec<bool>,
    n_distances: usize,
    guide: Vec<u32>,
    guide_start: f64,
    guide_inv_width: f64,
    /// Deepest bisection level reached.
    pub max_depth_reached: u32,
    /// How the fan was refined, for fans built on it ([`ElevationFan::build_on`]).
    refinement: Refinement,
}

/// How a fan was refined: its spec, and per base interval where its rays start and how deep
/// it was bisected.
#[derive(Debug, Clone)]
struct Refinement {
    spec: FanSpec,
    /// Index in the fan of each base ray (the first ray of each base interval, and the last).
    base_rays: Vec<usize>,
    /// Deepest bisection level of each base interval.
    depths: Vec<u32>,
}

/// Whether two specs are the same, bit for bit, but for their sun bands.
fn same_but_sun(a: &FanSpec, b: &FanSpec) -> bool {
    let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    a.camera_height_m.to_bits() == b.camera_height_m.to_bits()
        && bits(&a.distances_m) == bits(&b.distances_m)
        && bits(&a.max_top_m) == bits(&b.max_top_m)
        && a.need_sky_direction == b.need_sky_direction
        && a.elevation_range_rad.0.to_bits() == b.elevation_range_rad.0.to_bits()
        && a.elevation_range_rad.1.to_bits() == b.elevation_range_rad.1.to_bits()
        && a.pixel_rad.to_bits() == b.pixel_rad.to_bits()
        && a.tolerance_px.to_bits() == b.tolerance_px.to_bits()
        && a.max_depth == b.max_depth
}

/// The fan's rays as they are collected.
#[derive(Default)]
struct FanParts {
    alphas: Vec<f64>,
    heights: Vec<Option<f64>>,
    ends: Vec<FanEnd>,
    monotone: Vec<bool>,
}

impl FanParts {
    /// Room for `rays` rays of `distances` heights each.
    fn with_capacity(rays: usize, distances: usize) -> Self {
        FanParts {
            alphas: Vec::with_capacity(rays),
            heights: Vec::with_capacity(rays * distances),
            ends: Vec::with_capacity(rays),
            monotone: Vec::with_capacity(rays),
        }
    }

    fn push(&mut self, ray: &FanRay) {
        self.alphas.push(ray.elevation_rad);
        self.heights.extend_from_slice(&ray.heights_m);
        self.ends.push(ray.end);
        self.monotone.push(ray.monotone);
    }

    /// Rays `first..last` of `fan`.
    fn extend_from(&mut self, fan: &ElevationFan, first: usize, last: usize) {
        let d = fan.n_distances;
        self.alphas.extend_from_slice(&fan.alphas[first..last]);
        self.heights
            .extend_from_slice(&fan.heights[first * d..last * d]);
        self.ends.extend_from_slice(&fan.ends[first..last]);
        self.monotone.extend_from_slice(&fan.monotone[first..last]);
    }
}

/// Whether two ends are shaded alike (trapped and lost rays both get the fallback).
fn same_kind(a: &FanEnd, b: &FanEnd) -> bool {
    let kind = |e: &FanEnd| match e {
        FanEnd::Ground { .. } => 0,
        FanEnd::Sky { .. } => 1,
        FanEnd::Trapped | FanEnd::Lost => 2,
    };
    kind(a) == kind(b)
}

/// Whether two ends are the same, bit for bit.
fn same_end(a: &FanEnd, b: &FanEnd) -> bool {
    match (a, b) {
        (
            FanEnd::Ground {
                distance_m: d0,
                grazing_rad: g0,
            },
            FanEnd::Ground {
                distance_m: d1,
                grazing_rad: g1,
            },
        ) => d0.to_bits() == d1.to_bits() && g0.to_bits() == g1.to_bits(),
        (FanEnd::Sky { elevation_rad: e0 }, FanEnd::Sky { elevation_rad: e1 }) => {
            e0.to_bits() == e1.to_bits()
        }
        (FanEnd::Trapped, FanEnd::Trapped) | (FanEnd::Lost, FanEnd::Lost) => true,
        _ => false,
    }
}

/// Does the interval (a, b) with traced midpoint m need more bisection?
fn needs_refinement(spec: &FanSpec, a: &FanRay, m: &FanRay, b: &FanRay) -> bool {
    if !same_kind(&a.end, &m.end) || !same_kind(&m.end, &b.end) {
        return true;
    }
    let dalpha = b.elevation_rad - a.elevation_rad;
    let limit = spec.tolerance_px * spec.pixel_rad;
    let misplaced = |ya: f64, ym: f64, yb: f64| {
        let err = (ym - 0.5 * (ya + yb)).abs();
        let slope = ((yb - ya) / dalpha).abs();
        // err / slope > limit, written without dividing by a vanishing slope.
        err > limit * slope
    };
    for k in 0..spec.distances_m.len() {
        let top = spec.max_top_m[k];
        match (a.heights_m[k], m.heights_m[k], b.heights_m[k]) {
            (Some(ha), Some(hm), Some(hb)) => {
                if ha.min(hm).min(hb) <= top && misplaced(ha, hm, hb) {
                    return true;
                }
            }
            (None, None, None) => {}
            (x, y, z) => {
                if [x, y, z].iter().flatten().any(|&h| h <= top) {
                    return true;
                }
            }
        }
    }
    if let (
        Some((lo, hi)),
        FanEnd::Sky { elevation_rad: ea },
        FanEnd::Sky { elevation_rad: em },
        FanEnd::Sky { elevation_rad: eb },
    ) = (spec.sun_band_rad, a.end, m.end, b.end)
    {
        let (emin, emax) = (ea.min(em).min(eb), ea.max(em).max(eb));
        if emax >= lo && emin <= hi && misplaced(ea, em, eb) {
            return true;
        }
    }
    false
}

/// Whether every ray launched between `a` and `b` (neighbours, α_a < α_b) is shaded exactly as
/// interpolation shades it without a midpoint: both rays belong to a monotone family (both
/// launched upwards and never turned, or both downwards into the sea without turning; see the
/// module docs) and miss every card the same way — passing above the highest card top at each
/// card distance, or (into the sea) all ending before it. Upward rays also need the scene to
/// have no sun: their colour is then the sky at their own apparent elevation, whatever the fan.
fn monotone_and_clear(spec: &FanSpec, a: &FanRay, b: &FanRay) -> bool {
    if !(a.monotone && b.monotone) {
        return false;
    }
    let above_every_top = |r: &FanRay| {
        r.heights_m
            .iter()
            .zip(&spec.max_top_m)
            .all(|(h, top)| h.is_none_or(|h| h > *top))
    };
    let up = a.elevation_rad > 0.0 && b.elevation_rad > 0.0;
    let down = a.elevation_rad < 0.0 && b.elevation_rad < 0.0;
    match (a.end, b.end) {
        (FanEnd::Sky { .. }, FanEnd::Sky { .. }) if up => {
            !spec.need_sky_direction && above_every_top(a) && above_every_top(b)
        }
        (FanEnd::Ground { .. }, FanEnd::Ground { .. }) if down => {
            above_every_top(a)
                && above_every_top(b)
                && a.heights_m
                    .iter()
                    .zip(&b.heights_m)
                    .all(|(x, y)| x.is_some() == y.is_some())
        }
        _ => false,
    }
}

/// Bisect the open interval (`a`, `b`) at bisection level `level` (0 for a base interval):
/// trace its midpoint, push the rays inside it to `inside` in order (left half, midpoint, right
/// half), and return the deepest level reached. The interval is bisected when it is wider than
/// `tolerance_px` pixels and `level` < `max_depth`; its halves are bisected again when the
/// midpoint test ([`needs_refinement`]) fails.
fn refine(
    spec: &FanSpec,
    trace: &(impl Fn(f64) -> FanRay + Sync),
    a: &FanRay,
    b: &FanRay,
    level: u32,
    inside: &mut Vec<FanRay>,
) -> u32 {
    if level >= spec.max_depth
        || b.elevation_rad - a.elevation_rad <= spec.tolerance_px * spec.pixel_rad
    {
        return level;
    }
    let m = trace(0.5 * (a.elevation_rad + b.elevation_rad));
    let mut depth = level + 1;
    if needs_refinement(spec, a, &m, b) {
        depth = depth.max(refine(spec, trace, a, &m, level + 1, inside));
        let at = inside.len();
        inside.push(m);
        // The right half needs the midpoint as its left end: borrow it back from the list.
        let m = inside[at].clone();
        depth = depth.max(refine(spec, trace, &m, b, level + 1, inside));
    } else {
        inside.push(m);
    }
    depth
}

/// The ray of `spec` at `alpha`, traced by `tracer`.
fn traced_for(tracer: &dyn RayTracer, spec: &FanSpec, alpha: f64) -> FanRay {
    let mut ray = tracer.trace(
        spec.camera_height_m,
        alpha,
        &spec.distances_m,
        spec.need_sky_direction,
    );
    // Guard against a tracer that breaks the contract: the fan is indexed by the requested
    // elevation and one height per distance.
    ray.elevation_rad = alpha;
    ray.heights_m.resize(spec.distances_m.len(), None);
    ray
}

impl ElevationFan {
    /// Trace and refine the fan for `spec` (rays traced in parallel, collected in order: the
    /// result does not depend on the number of threads).
    pub fn build(tracer: &dyn RayTracer, spec: &FanSpec) -> Self {
        let (lo, hi) = spec.elevation_range_rad;
        // Base rays two pixels apart: the first round bisects every interval (the midpoint test
        // needs the midpoint), so the finished fan is at most one pixel apart everywhere.
        let step = 2.0 * spec.pixel_rad.max(1e-12);
        let n_base = (((hi - lo) / step).ceil() as usize).max(1) + 1;
        let spacing = (hi - lo) / (n_base - 1) as f64;
        let trace = |alpha: f64| traced_for(tracer, spec, alpha);
        let rays: Vec<FanRay> = (0..n_base)
            .into_par_iter()
            .map(|i| {
                trace(if i + 1 == n_base {
                    hi
                } else {
                    lo + i as f64 * spacing
                })
            })
            .collect();
        // Every base interval is bisected at least once, except between two rays of a monotone
        // family that are clear of every card (module docs). Each base interval is refined on
        // its own (its decisions depend only on its own rays), all in parallel: no round of
        // bisections waits for the slowest ray of the previous one. Collected in order, so the
        // fan does not depend on the number of threads.
        let refined: Vec<(Vec<FanRay>, u32)> = rays
            .par_windows(2)
            .map(|w| {
                let mut inside = Vec::new();
                let depth = if monotone_and_clear(spec, &w[0], &w[1]) {
                    0
                } else {
                    refine(spec, &trace, &w[0], &w[1], 0, &mut inside)
                };
                (inside, depth)
            })
            .collect();
        let mut parts = FanParts::default();
        let mut base_rays = Vec::with_capacity(rays.len());
        let mut depths = Vec::with_capacity(refined.len());
        let mut refined = refined.into_iter();
        for ray in &rays {
            base_rays.push(parts.alphas.len());
            parts.push(ray);
            if let Some((inside, depth)) = refined.next() {
                inside.iter().for_each(|r| parts.push(r));
                depths.push(depth);
            }
        }
        Self::from_parts(parts, spec, base_rays, depths)
    }

    /// [`Self::build`] for `spec`, from the rays of `base`, a fan that `tracer` built for the
    /// same spec but for its sun band (otherwise this is [`Self::build`]): the same fan, bit
    /// for bit. The rays it needs that `base` holds are read from it. A base interval whose
    /// rays' final sky elevations all lie outside both suns' bands is bisected alike for
    /// either band (the sun's test of [`needs_refinement`] applies to neither: every triple
    /// it tests is of those rays), so its rays and depth are taken from `base` whole; the
    /// other base intervals are refined again.
    pub fn build_on(tracer: &dyn RayTracer, spec: &FanSpec, base: &ElevationFan) -> Self {
        let prior = &base.refinement;
        if !same_but_sun(spec, &prior.spec) {
            return Self::build(tracer, spec);
        }
        let bands = [prior.spec.sun_band_rad, spec.sun_band_rad];
        let trace = |alpha: f64| {
            base.ray_at(alpha)
                .unwrap_or_else(|| traced_for(tracer, spec, alpha))
        };
        let last = prior.base_rays.len() - 1;
        // In order on this thread: most intervals are taken whole, the others mostly read
        // rays already traced (the frames of a sweep are rendered in parallel instead).
        let refined: Vec<Option<(Vec<FanRay>, u32)>> = (0..last)
            .map(|k| {
                let (first, end) = (prior.base_rays[k], prior.base_rays[k + 1]);
                if base.clear_of_bands(first, end, bands) {
                    return None;
                }
                let (a, b) = (base.ray(first), base.ray(end));
                let mut inside = Vec::new();
                let depth = if monotone_and_clear(spec, &a, &b) {
                    0
                } else {
                    refine(spec, &trace, &a, &b, 0, &mut inside)
                };
                Some((inside, depth))
            })
            .collect();
        let mut parts = FanParts::with_capacity(base.len(), base.n_distances);
        let mut base_rays = Vec::with_capacity(last + 1);
        let mut depths = Vec::with_capacity(last);
        for (k, own) in refined.iter().enumerate() {
            let (first, end) = (prior.base_rays[k], prior.base_rays[k + 1]);
            base_rays.push(parts.alphas.len());
            match own {
                None => {
                    parts.extend_from(base, first, end);
                    depths.push(prior.depths[k]);
                }
                Some((inside, depth)) => {
                    parts.extend_from(base, first, first + 1);
                    inside.iter().for_each(|r| parts.push(r));
                    depths.push(*depth);
                }
            }
        }
        base_rays.push(parts.alphas.len());
        parts.extend_from(base, prior.base_rays[last], prior.base_rays[last] + 1);
        Self::from_parts(parts, spec, base_rays, depths)
    }

    /// Whether no ray `first..=last` of the fan ends in the sky inside either band (a NaN
    /// final elevation counts as inside), nor do two of them straddle one.
    fn clear_of_bands(&self, first: usize, last: usize, bands: [Option<(f64, f64)>; 2]) -> bool {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for end in &self.ends[first..=last] {
            if let FanEnd::Sky { elevation_rad: e } = *end {
                if e.is_nan() {
                    return false;
                }
                (lo, hi) = (lo.min(e), hi.max(e));
            }
        }
        bands
            .iter()
            .flatten()
            .all(|&(band_lo, band_hi)| !(hi >= band_lo && lo <= band_hi))
    }

    /// Ray `i` as it was traced.
    fn ray(&self, i: usize) -> FanRay {
        FanRay {
            elevation_rad: self.alphas[i],
            heights_m: self.ray_heights(i).to_vec(),
            end: self.ends[i],
            monotone: self.monotone[i],
        }
    }

    /// The fan's ray at exactly `alpha` (bit for bit), if it has one.
    fn ray_at(&self, alpha: f64) -> Option<FanRay> {
        let i = self.alphas.partition_point(|&a| a < alpha);
        (self.alphas.get(i)?.to_bits() == alpha.to_bits()).then(|| self.ray(i))
    }

    /// The fan of the collected `parts`, refined for `spec` with base rays at `base_rays` and
    /// each base interval bisected `depths` deep.
    fn from_parts(
        parts: FanParts,
        spec: &FanSpec,
        base_rays: Vec<usize>,
        depths: Vec<u32>,
    ) -> Self {
        let refinement = Refinement {
            spec: spec.clone(),
            base_rays,
            depths,
        };
        let FanParts {
            alphas,
            heights,
            ends,
            monotone,
        } = parts;
        let n_distances = refinement.spec.distances_m.len();
        let depth = refinement.depths.iter().copied().max().unwrap_or(0);
        let n = alphas.len();
        let start = alphas[0];
        let span = (alphas[n - 1] - start).max(1e-300);
        let buckets = (4 * n).min(1 << 22);
        let inv_width = buckets as f64 / span;
        let mut guide = Vec::with_capacity(buckets + 1);
        let mut i = 0usize;
        for b in 0..=buckets {
            let x = start + b as f64 / inv_width;
            while i + 2 < n && alphas[i + 1] <= x {
                i += 1;
            }
            guide.push(i as u32);
        }
        Self {
            alphas,
            heights,
            ends,
            monotone,
            n_distances,
            guide,
            guide_start: start,
            guide_inv_width: inv_width,
            max_depth_reached: depth,
            refinement,
        }
    }

    /// The lowest fan elevation from which every ray up to the top of the fan ends in the sky and
    /// passes above `max_top_m[k]` (or never reaches) every card distance k: samples at or above
    /// it see only sky, exactly as interpolation would show them. `+∞` if the top ray is not clear.
    pub fn clear_sky_from(&self, max_top_m: &[f64]) -> f64 {
        let d = self.n_distances;
        let clear = |i: usize| {
            matches!(self.ends[i], FanEnd::Sky { .. })
                && self.heights[i * d..(i + 1) * d]
                    .iter()
                    .zip(max_top_m)
                    .all(|(h, top)| h.is_none_or(|h| h > *top))
        };
        let mut from = f64::INFINITY;
        for i in (0..self.alphas.len()).rev() {
            if !clear(i) {
                break;
            }
            from = self.alphas[i];
        }
        from
    }

    /// The steepest finite grazing angle (rad) of the fan's rays that hit the sea, if any: the
    /// largest the fan can interpolate.
    pub fn max_grazing_rad(&self) -> Option<f64> {
        self.ends
            .iter()
            .filter_map(|e| match e {
                FanEnd::Ground { grazing_rad, .. } if grazing_rad.is_finite() => Some(*grazing_rad),
                _ => None,
            })
            .reduce(f64::max)
    }

    /// Whether the ray launched at `alpha` surely ends in the sea: `alpha` lies on or between
    /// two neighbouring rays of the fan launched downwards that descended into the sea without
    /// turning (a monotone family, module docs: every ray between them descends between them
    /// and lands no farther than the shallower one).
    pub fn surely_sea(&self, alpha: f64) -> bool {
        let n = self.alphas.len();
        if n < 2 || !(alpha >= self.alphas[0] && alpha <= self.alphas[n - 1]) {
            return false;
        }
        let down = |k: usize| {
            self.monotone[k]
                && self.alphas[k] < 0.0
                && matches!(self.ends[k], FanEnd::Ground { .. })
        };
        let i = self.interval(alpha);
        down(i) && down(i + 1)
    }

    /// Number of traced rays in the fan.
    pub fn len(&self) -> usize {
        self.alphas.len()
    }

    /// Whether the fan has no rays (never, once built).
    pub fn is_empty(&self) -> bool {
        self.alphas.is_empty()
    }

    /// The traced elevations, ascending.
    pub fn elevations_rad(&self) -> &[f64] {
        &self.alphas
    }

    /// Every ray's apparent elevation with how it ended, ascending.
    pub fn rays_and_ends(&self) -> Vec<(f64, FanEnd)> {
        self.alphas
            .iter()
            .copied()
            .zip(self.ends.iter().copied())
            .collect()
    }

    /// Index i of the interval [αᵢ, αᵢ₊₁] holding `alpha` (clamped to the fan), in O(1): the
    /// one every lookup of `alpha` reads.
    #[inline]
    pub(crate) fn interval(&self, alpha: f64) -> usize {
        let n = self.alphas.len();
        if n < 2 {
            return 0;
        }
        // Clamped in f64 and converted through i32 (the guide has at most 2²² + 1 entries): a
        // u64 conversion costs more on x86-64, and this runs once per sample.
        let b = ((alpha - self.guide_start) * self.guide_inv_width)
            .max(0.0)
            .min((self.guide.len() - 1) as f64);
        let b = b as i32 as usize;
        let mut i = self.guide[b] as usize;
        // The bucket's start is rounded: should it land a node past `alpha`, step back, so
        // the interval depends on the traced elevations alone (not on the guide's width).
        while i > 0 && self.alphas[i] > alpha {
            i -= 1;
        }
        while i + 2 < n && self.alphas[i + 1] <= alpha {
            i += 1;
        }
        i
    }

    /// Whether every lookup of an elevation in [`lo`, `hi`] (rad) — [`Self::interpolate`],
    /// [`Self::interpolate_end`], [`Self::height_range`] — reads the same traced rays, bit for
    /// bit, in this fan as in `other`, and so gives the same answer. Both fans must have been
    /// traced by the same tracer for the same spec but the sun band: the rays one node either
    /// side of the intervals that hold `lo` and `hi` are compared (one more below than the
    /// lookups read, for tables indexed by the fan's elevations with the other bracketing
    /// convention, such as the air paths).
    pub fn same_rays_over(&self, other: &ElevationFan, lo: f64, hi: f64) -> bool {
        self.same_rays_in(other, self.intervals_of(lo, hi), other.intervals_of(lo, hi))
    }

    /// The intervals ([`Self::interval`]) holding `lo` and `hi`.
    pub fn intervals_of(&self, lo: f64, hi: f64) -> (usize, usize) {
        (self.interval(lo), self.interval(hi))
    }

    /// [`Self::same_rays_over`] of the elevations whose intervals are `mine` in this fan and
    /// `theirs` in `other` ([`Self::intervals_of`]).
    pub fn same_rays_in(
        &self,
        other: &ElevationFan,
        mine: (usize, usize),
        theirs: (usize, usize),
    ) -> bool {
        if self.n_distances != other.n_distances || self.len() < 2 || other.len() < 2 {
            return false;
        }
        let window = |fan: &ElevationFan, (lo, hi): (usize, usize)| {
            let first = lo.saturating_sub(1);
            let last = (hi + 1).min(fan.len() - 1);
            (first, last)
        };
        let ((a0, a1), (b0, b1)) = (window(self, mine), window(other, theirs));
        // A window at an end of one fan must be at the same end of the other (lookups clamp
        // there).
        if (a0 == 0) != (b0 == 0)
            || (a1 == self.len() - 1) != (b1 == other.len() - 1)
            || a1 - a0 != b1 - b0
        {
            return false;
        }
        (0..=a1 - a0).all(|k| self.same_ray(a0 + k, other, b0 + k))
    }

    /// Whether ray `i` of this fan and ray `j` of `other` are the same, bit for bit.
    fn same_ray(&self, i: usize, other: &ElevationFan, j: usize) -> bool {
        let d = self.n_distances;
        self.alphas[i].to_bits() == other.alphas[j].to_bits()
            && same_end(&self.ends[i], &other.ends[j])
            && self.heights[i * d..(i + 1) * d]
                .iter()
                .zip(&other.heights[j * d..(j + 1) * d])
                .all(|(a, b)| a.map(f64::to_bits) == b.map(f64::to_bits))
    }

    /// The interval i of the fan holding `alpha` (clamped) and the fraction t ∈ [0, 1] of the
    /// way from ray i to ray i + 1: [`Self::ray_heights`] of both, weighted by t, is what
    /// [`Self::interpolate`] gives. (0, 0) for a fan of one ray.
    #[inline]
    pub fn interval_fraction(&self, alpha: f64) -> (usize, f64) {
        if self.alphas.len() < 2 {
            return (0, 0.0);
        }
        let i = self.interval(alpha);
        let (a0, a1) = (self.alphas[i], self.alphas[i + 1]);
        (i, ((alpha - a0) / (a1 - a0)).clamp(0.0, 1.0))
    }

    /// The traced heights of ray `i` (one per distance).
    ///
    /// # Panics
    /// If `i` ≥ [`Self::len`].
    #[inline]
    pub fn ray_heights(&self, i: usize) -> &[Option<f64>] {
        &self.heights[i * self.n_distances..(i + 1) * self.n_distances]
    }

    /// How ray `i` ended.
    ///
    /// # Panics
    /// If `i` ≥ [`Self::len`].
    pub fn ray_end(&self, i: usize) -> FanEnd {
        self.ends[i]
    }

    /// Interpolate the ray at elevation `alpha` into `heights` (resized to the number of
    /// distances) and return its end. Heights and end values are interpolated linearly where both
    /// neighbours have them; otherwise (a change of how rays end) the nearer ray's value is used.
    #[inline]
    pub fn interpolate(&self, alpha: f64, heights: &mut [Option<f64>]) -> FanEnd {
        let n = self.alphas.len();
        let i = self.interval(alpha);
        if n < 2 {
            heights.copy_from_slice(&self.heights[..self.n_distances]);
            return self.ends[0];
        }
        let (a0, a1) = (self.alphas[i], self.alphas[i + 1]);
        let t = ((alpha - a0) / (a1 - a0)).clamp(0.0, 1.0);
        let near_right = t >= 0.5;
        let d = self.n_distances;
        let (ha, hb) = (
            &self.heights[i * d..(i + 1) * d],
            &self.heights[(i + 1) * d..(i + 2) * d],
        );
        for k in 0..d {
            heights[k] = match (ha[k], hb[k]) {
                (Some(x), Some(y)) => Some(x + (y - x) * t),
                (x, y) => {
                    if near_right {
                        y
                    } else {
                        x
                    }
                }
            };
        }
        self.end_between(i, t)
    }
    /// The end of the ray at elevation `alpha`, interpolated as [`Self::interpolate`] does, without
    /// the heights: all a sample needs when its ray can meet no card.
    #[inline]
    pub fn interpolate_end(&self, alpha: f64) -> FanEnd {
        if self.alphas.len() < 2 {
            return self.ends[0];
        }
        let i = self.interval(alpha);
        let (a0, a1) = (self.alphas[i], self.alphas[i + 1]);
        self.end_between(i, ((alpha - a0) / (a1 - a0)).clamp(0.0, 1.0))
    }

    /// The end at fraction `t` of interval i: ends of the same kind are interpolated linearly;
    /// otherwise (a change of how rays end) the nearer ray's end.
    #[inline]
    fn end_between(&self, i: usize, t: f64) -> FanEnd {
        let near_right = t >= 0.5;
        // Field by field through references: copying the two enums whole made the compiler
        // store them in pieces and reload them at once, a store-forwarding stall per sample.
        match (&self.ends[i], &self.ends[i + 1]) {
            (
                FanEnd::Ground {
                    distance_m: d0,
                    grazing_rad: g0,
                },
                FanEnd::Ground {
                    distance_m: d1,
                    grazing_rad: g1,
                },
            ) => FanEnd::Ground {
                distance_m: d0 + (d1 - d0) * t,
                grazing_rad: g0 + (g1 - g0) * t,
            },
            (FanEnd::Sky { elevation_rad: e0 }, FanEnd::Sky { elevation_rad: e1 }) => FanEnd::Sky {
                elevation_rad: e0 + (e1 - e0) * t,
            },
            (x, y) => {
                if near_right {
                    *y
                } else {
                    *x
                }
            }
        }
    }

    /// Lowest and highest height (m) at card distance `k` that interpolation can give for an
    /// elevation in [`lo`, `hi`]: the extremes over the traced rays of the intervals that hold
    /// them (interpolated heights lie between neighbours, or are one of them). `None` if no such
    /// ray reaches distance k; a NaN height makes the range unbounded (−∞, +∞).
    pub fn height_range(&self, lo: f64, hi: f64, k: usize) -> Option<(f64, f64)> {
        let d = self.n_distances;
        let n = self.alphas.len();
        let (first, last) = if n < 2 {
            (0, 0)
        } else {
            (self.interval(lo), self.interval(hi) + 1)
        };
        let mut range: Option<(f64, f64)> = None;
        for i in first..=last {
            if let Some(h) = self.heights[i * d + k] {
                if h.is_nan() {
                    return Some((f64::NEG_INFINITY, f64::INFINITY));
                }
                range = Some(range.map_or((h, h), |(a, b)| (a.min(h), b.max(h))));
            }
        }
        range
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::ray_model::StraightRays;
    use crate::units::EARTH_RADIUS_M;

    fn spec(distances: Vec<f64>, tops: Vec<f64>) -> FanSpec {
        FanSpec {
            camera_height_m: 10.0,
            distances_m: distances,
            max_top_m: tops,
            need_sky_direction: false,
            sun_band_rad: None,
            elevation_range_rad: (-0.004, 0.002),
            pixel_rad: 2e-5,
            tolerance_px: 0.1,
            max_depth: 10,
        }
    }

    #[test]
    fn lookup_finds_the_right_interval_and_interpolates() {
        let tracer = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let s = spec(vec![5_000.0], vec![30.0]);
        let fan = ElevationFan::build(&tracer, &s);
        let alphas = fan.elevations_rad();
        assert!(alphas.windows(2).all(|w| w[0] < w[1]));
        let mut h = [None];
        for &alpha in &[-0.0015, -0.001234, 0.0, 0.00199] {
            let i = fan.interval(alpha);
            assert!(alphas[i] <= alpha && alpha <= alphas[i + 1], "{alpha}");
            fan.interpolate(alpha, &mut h);
            let exact = tracer.trace(10.0, alpha, &[5_000.0], false).heights_m[0];
            // Straight rays: h(α) at 5 km is almost linear; interpolation error ≪ 1 mm.
            assert!((h[0].unwrap() - exact.unwrap()).abs() < 1e-3);
        }
    }

    #[test]
    fn clear_sky_starts_above_the_card_top() {
        let tracer = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let s = spec(vec![5_000.0], vec![20.0]);
        let fan = ElevationFan::build(&tracer, &s);
        // Straight ray from 10 m reaches 20 m at 5 km when tan α = ((R+20)cos θ − (R+10)) /
        // ((R+20) sin θ), θ = 5 km / R.
        let (r, th) = (EARTH_RADIUS_M, 5_000.0 / EARTH_RADIUS_M);
        let alpha = (((r + 20.0) * th.cos() - (r + 10.0)) / ((r + 20.0) * th.sin())).atan();
        let from = fan.clear_sky_from(&[20.0]);
        assert!(from > alpha && from - alpha <= 2e-5, "{from} vs {alpha}");
        // Nothing is clear when a card reaches above the frame.
        assert_eq!(fan.clear_sky_from(&[1e6]), f64::INFINITY);
    }

    #[test]
    fn the_horizon_is_refined_to_the_tolerance() {
        let tracer = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let s = spec(vec![], vec![]);
        let fan = ElevationFan::build(&tracer, &s);
        // The rays bracketing the ground/sky change are closer than tolerance × pixel.
        let dip = (EARTH_RADIUS_M / (EARTH_RADIUS_M + 10.0)).acos();
        let a = fan.elevations_rad();
        let i = a.partition_point(|&x| x < -dip);
        assert!(a[i] - a[i - 1] <= 0.1 * 2e-5, "{}", a[i] - a[i - 1]);
        // Far below the horizon the rays descend straight into the sea (a monotone family, no
        // card): the base spacing of two pixels is kept.
        assert!((a[1] - a[0] - 4e-5).abs() < 0.01 * 2e-5, "{}", a[1] - a[0]);
        // Just below the horizon, next to the refined change, one pixel or less.
        assert!(
            a[i - 1] - a[i - 2] <= 2e-5 * 1.0001,
            "{}",
            a[i - 1] - a[i - 2]
        );
        // High above it, climbing rays (no card, no sun) keep two pixels as well...
        let n = a.len();
        assert!((a[n - 1] - a[n - 2] - 4e-5).abs() < 0.01 * 2e-5);
        // ...but not when a sun needs their sky directions.
        let sunny = FanSpec {
            need_sky_direction: true,
            sun_band_rad: Some((0.5, 0.6)),
            ..s
        };
        let b = ElevationFan::build(&tracer, &sunny);
        let m = b.elevations_rad().len();
        let top = b.elevations_rad();
        assert!(top[m - 1] - top[m - 2] <= 2e-5 * 1.0001);
    }

    /// Whether two fans are the same, bit for bit.
    fn same_fan(a: &ElevationFan, b: &ElevationFan) -> bool {
        a.len() == b.len()
            && a.max_depth_reached == b.max_depth_reached
            && a.monotone == b.monotone
            && (0..a.len()).all(|i| a.same_ray(i, b, i))
    }

    #[test]
    fn a_fan_built_on_another_suns_fan_is_the_fan_built_alone() {
        // Final elevations that dip and rise like a mirage's (rays near the sun's band are
        // refined for it), leaving below the sea horizon as trapped rays.
        let leave = |a: f64| (a > -0.0035).then(|| -0.02 + 2.0 * a + 3e-4 * (a * 4e4).sin());
        let tracer = crate::render::test_rays::Leaving::new(leave);
        let spec_for = |centre: f64| FanSpec {
            need_sky_direction: true,
            sun_band_rad: Some((centre - 0.004, centre + 0.004)),
            ..spec(vec![], vec![])
        };
        let base = ElevationFan::build(&tracer, &spec_for(-0.03));
        let mut reused = 0;
        for centre in [-0.03, -0.029, -0.026, -0.022, -0.02, -0.017, -0.013, -0.5] {
            let alone = ElevationFan::build(&tracer, &spec_for(centre));
            let before = tracer.traces();
            let on_base = ElevationFan::build_on(&tracer, &spec_for(centre), &base);
            let traced = tracer.traces() - before;
            assert!(same_fan(&alone, &on_base), "sun band at {centre}");
            // Only rays the base does not hold are traced.
            let missing = on_base
                .elevations_rad()
                .iter()
                .filter(|a| base.ray_at(**a).is_none())
                .count();
            assert!(
                traced <= missing,
                "{centre}: {traced} traced, {missing} new"
            );
            reused += on_base.len() - traced;
        }
        assert!(reused > 1000, "{reused}");
        // A spec that differs but in its sun band is built alone.
        let wider = FanSpec {
            elevation_range_rad: (-0.004, 0.003),
            ..spec_for(-0.02)
        };
        let alone = ElevationFan::build(&tracer, &wider);
        assert!(same_fan(
            &alone,
            &ElevationFan::build_on(&tracer, &wider, &base)
        ));
    }

    #[test]
    fn rays_surely_in_the_sea_are_so() {
        let tracer = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let s = FanSpec {
            need_sky_direction: true,
            sun_band_rad: Some((-0.001, 0.0)),
            ..spec(vec![], vec![])
        };
        let fan = ElevationFan::build(&tracer, &s);
        let (mut sure, mut sea) = (0, 0);
        for i in 0..=6000 {
            let alpha = -0.004 + 1e-6 * f64::from(i);
            let ground = matches!(
                tracer.trace(10.0, alpha, &[], true).end,
                FanEnd::Ground { .. }
            );
            if fan.surely_sea(alpha) {
                assert!(ground, "{alpha}");
                sure += 1;
            }
            sea += usize::from(ground);
        }
        // All but the rays next to the horizon, which the fan refines (the dip from 10 m is
        // 1.8 mrad: 2200 of the 6001 rays reach the sea).
        assert!(sure > 2000 && sure <= sea, "{sure} of {sea}");
        assert!(!fan.surely_sea(-0.0041) && !fan.surely_sea(f64::NAN));
    }

    #[test]
    fn rays_that_may_meet_a_card_are_one_pixel_apart() {
        // A card 20 m high at 5 km: rays that reach it below 20 m are not a clear family.
        let tracer = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let s = spec(vec![5_000.0], vec![20.0]);
        let fan = ElevationFan::build(&tracer, &s);
        let a = fan.elevations_rad();
        for w in a.windows(2) {
            let mid = 0.5 * (w[0] + w[1]);
            let ray = tracer.trace(10.0, mid, &[5_000.0], false);
            if ray.heights_m[0].is_some_and(|h| h <= 20.0) {
                assert!(w[1] - w[0] <= 2e-5 * 1.0001, "{mid}: {}", w[1] - w[0]);
            }
        }
    }
}
