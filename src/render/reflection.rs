//! Render — the sea's reflections. In: a ray that met the sea (grazing angle g, ground distance
//! d from the camera, azimuth), the cards, the sky and the sun. Out: the radiance the sea sends
//! back along it beyond the sky reflection already tabulated by grazing angle: the mirror images
//! of the cards and the terrain, and the sun's glitter (calm: its mirror image).
//!
//! In a spherically stratified atmosphere a reflected ray is a ray launched from the sea surface
//! (height 0) at elevation e = the reflected angle, in the same vertical plane, so one **sea
//! fan** ([`SeaFan`]) traced from height 0 once per frame serves every sample: it records each
//! ray's height on a uniform grid of ranges (from the reflection point) and is interpolated
//! bilinearly. A reflected ray from a hit at distance d meets a card at distance D > d at range
//! D − d; the terrain's profile along the sample's azimuth is marched from d on
//! (`super::terrain`). On a calm sea there is one reflected ray; on a rough one the wave facets
//! spread the reflected rays over many elevations, and a sample integrates over them
//! ([`Shader::blur_parts`]): its slopes are cut where each object's image begins and ends and
//! into cells, each part weighted by its exact Fresnel-weighted share from a per-frame table
//! ([`SlopeTable`]) and shaded by one ray (cards averaged over the heights the part spans,
//! `super::texture_box`), so images are smooth blurs, not copies at a few slopes. Card images
//! are seen through the air from the card to the sea (the chord) when the sky has aerial
//! perspective (the renderer then attenuates the whole sea radiance from the sea to the camera).
//! Exact mode uses the same sea fan.

use std::sync::Arc;

use rayon::prelude::*;

use super::objects::{Composed, Meet, PartAtCard, RayAlong, SampleRay, SceneObject};
use super::ray_model::{FanEnd, FanRay, RayTracer};
use super::sea_sun::SeaSunTable;
use super::shade::{AngleTable, Shader, ViewCard, cos_range};
use super::terrain::{TerrainView, piece_density};
use crate::scene::camera::ViewDirection;
use crate::scene::sea::{FacetNode, GlintBound, GlintGeometry, facet_slope_range};
use crate::scene::sky::SunDisc;
use crate::scene::{Sea, Sky, Sun};

/// Facet classes per sample for the cards' mirror images (the sky uses more, in its table).
pub(super) const CARD_FACET_NODES: usize = 8;

/// Facet classes (calm sea) or images (rough sea) whose share of the reflected light (weight ×
/// Fresnel reflectance) is below this are not traced to the cards and the terrain: they change a
/// pixel by less than 1e-3 of the object's radiance, a quarter of an 8-bit step (on a rough sea
/// an image fades in up to twice this, [`fade`]).
pub(super) const MIN_NODE_SHARE: f64 = 1e-3;

/// Most elevations in a sea fan.
const MAX_SEA_FAN_RAYS: usize = 2048;
/// Most ranges on a sea fan's grid (linear interpolation between them errs by about
/// Δr²·κ/8, κ the ray's curvature relative to the surface: millimetres at 250 m steps).
const MAX_SEA_FAN_RANGES: usize = 256;
/// Finest range step (m).
const MIN_RANGE_STEP_M: f64 = 25.0;

/// Rays launched from the sea surface at elevations 0 … `e_hi`, uniformly spaced, with their
/// heights on a uniform grid of ranges and their final sky elevations.
pub(super) struct SeaFan {
    inv_step_e: f64,
    n_e: usize,
    inv_step_r: f64,
    n_r: usize,
    /// Row-major by elevation: height (m) at each range, NaN where the ray had ended.
    heights: Vec<f32>,
    /// Row-major like `heights`: the lowest height of the ray at this range and beyond (+∞
    /// where it had ended: it meets nothing there).
    min_beyond: Vec<f32>,
    /// Row-major like `heights`, when asked for: the density-weighted path lengths [D_R, D_A]
    /// (m) from the sea to each range along the ray's own heights (NaN past its end).
    density: Vec<[f32; 2]>,
    /// Final elevation (rad, relative to the reflection point's horizontal), NaN unless the ray
    /// left into the sky.
    sky_elevation: Vec<f64>,
    /// Elevation spacing of the rays (rad).
    step_e: f64,
    /// Per range cell m (ranges m, m + 1) and block b of rays [bB, (b + 1)B] (B =
    /// [`BOUND_BLOCK`]): the lowest and highest finite height there ([+∞, −∞]: none), so
    /// [`Self::elevations_within`] skips the blocks that cannot meet a height range.
    bounds: Vec<[f32; 2]>,
    n_bounds: usize,
}

/// Fractions of a sea fan's elevation step below this are rounding of an elevation on a ray
/// (computed as (i + t)·step and scaled back by 1/step, it is within a few ulps of i): the
/// neighbour's weight is dropped there, which moves a height by under 1e-12 of the step's.
const ON_RAY: f64 = 1e-12;

/// The sea fan's `n_e` rays (elevations i·`step_e`) traced from the sea to `ranges`: each
/// ray's heights there (f32, NaN where it has none) and its final sky elevation (NaN unless it
/// left into the sky). `top_m`: the highest card or terrain top (m), above which a ray meets
/// nothing.
///
/// The fan interpolates heights between neighbouring rays and ranges, so every cell with a
/// corner at or below `top_m` needs all four corners: a ray stopped as soon as it climbs clear
/// above the cards ([`RayTracer::trace`]) leaves cells without a corner where its neighbour
/// below is still within a card's heights, and the image up to the card's top would be cut
/// off there, by how the stop fell between range nodes (a discontinuity in the camera). So each
/// ray may stop only a margin above `top_m` ([`RayTracer::trace_with_margin`]): the height two
/// neighbouring rays part by at the fan's last range (step × range: h ≈ r·e + r²(1 − k)/2R
/// parts by r·Δe whatever the refraction coefficient k), enough for most rays; then every ray
/// that the cells need further (one range node past where it or a neighbour was last at or
/// below `top_m`, as far as that one's heights go) and that stopped in the sky is traced again
/// without a stop that far (in a duct, say).
fn trace_sea_rays(
    tracer: &dyn RayTracer,
    (n_e, step_e): (usize, f64),
    ranges: &[f64],
    top_m: f64,
    need_sky_direction: bool,
) -> Vec<(Vec<f32>, f64)> {
    let n_r = ranges.len();
    let margin_m = step_e * ranges[n_r - 1];
    let as_f32 = |ray: &FanRay| -> Vec<f32> {
        let mut h: Vec<f32> = ray
            .heights_m
            .iter()
            .map(|h| h.map_or(f32::NAN, |v| v as f32))
            .collect();
        h.resize(n_r, f32::NAN);
        h
    };
    let trace = |i: usize, upto: usize, margin_m: f64| {
        let e = i as f64 * step_e;
        tracer.trace_with_margin(0.0, e, &ranges[..upto], need_sky_direction, margin_m)
    };
    let first: Vec<(Vec<f32>, f64)> = (0..n_e)
        .into_par_iter()
        .map(|i| {
            let ray = trace(i, n_r, margin_m);
            let sky = match ray.end {
                FanEnd::Sky { elevation_rad } => elevation_rad,
                _ => f64::NAN,
            };
            (as_f32(&ray), sky)
        })
        .collect();
    // Leading heights of each ray, and how far the cells it bounds need their rays' heights.
    let count = |h: &[f32]| h.iter().position(|v| v.is_nan()).unwrap_or(n_r);
    let reach: Vec<usize> = first
        .iter()
        .map(|(h, sky)| {
            let below = h.iter().rposition(|&v| f64::from(v) <= top_m);
            let reach = below.map_or(0, |m| m + 2).min(n_r);
            if sky.is_nan() {
                reach.min(count(h))
            } else {
                reach
            }
        })
        .collect();
    first
        .into_par_iter()
        .enumerate()
        .map(|(i, (h, sky))| {
            let need = reach[i.saturating_sub(1)..(i + 2).min(n_e)]
                .iter()
                .copied()
                .max()
                .unwrap_or(0);
            if sky.is_nan() || count(&h) >= need {
                return (h, sky);
            }
            (as_f32(&trace(i, need, f64::INFINITY)), sky)
        })
        .collect()
}

/// Rays per block of [`SeaFan`]'s height bounds.
const BOUND_BLOCK: usize = 8;

impl SeaFan {
    /// Trace the sea fan over elevations [0, `e_hi`] with spacing `step_rad` (at most
    /// [`MAX_SEA_FAN_RAYS`] rays) and ranges [0, `max_range_m`], its rays followed as long as
    /// some cell they bound is at or below `top_m` (the highest card or terrain,
    /// [`trace_sea_rays`]); `None` if there is nothing to cover. `density`: the scale heights
    /// (m) and the sphere's radius (m) to sum each ray's density-weighted path lengths with
    /// ([`Self::density_paths_m`]).
    pub(super) fn build(
        tracer: &dyn RayTracer,
        e_hi: f64,
        step_rad: f64,
        (max_range_m, top_m): (f64, f64),
        need_sky_direction: bool,
        density: Option<([f64; 2], f64)>,
    ) -> Option<Self> {
        if !(e_hi > 0.0 && e_hi.is_finite() && max_range_m > 0.0 && max_range_m.is_finite()) {
            return None;
        }
        let n_e = ((e_hi / step_rad).ceil() as usize + 1).clamp(2, MAX_SEA_FAN_RAYS);
        let n_r =
            ((max_range_m / MIN_RANGE_STEP_M).ceil() as usize + 1).clamp(2, MAX_SEA_FAN_RANGES);
        let step_e = e_hi / (n_e - 1) as f64;
        let step_r = max_range_m / (n_r - 1) as f64;
        let mut ranges: Vec<f64> = (0..n_r).map(|m| m as f64 * step_r).collect();
        ranges[n_r - 1] = max_range_m;
        let rays = trace_sea_rays(tracer, (n_e, step_e), &ranges, top_m, need_sky_direction);
        let mut heights = Vec::with_capacity(n_e * n_r);
        let mut sky_elevation = Vec::with_capacity(n_e);
        for (h, s) in rays {
            heights.extend(h);
            sky_elevation.push(s);
        }
        let density = match density {
            Some((scales_m, radius_m)) => heights
                .par_chunks_exact(n_r)
                .with_min_len(8)
                .flat_map_iter(|row| {
                    let ranges = &ranges;
                    let mut sum = [0.0f64; 2];
                    let mut prev = (0.0, 0.0);
                    row.iter().enumerate().map(move |(m, &h)| {
                        if h.is_nan() || sum[0].is_nan() {
                            sum = [f64::NAN; 2];
                        } else {
                            let at = (ranges[m], f64::from(h));
                            let piece = piece_density(prev, at, radius_m, scales_m);
                            sum = [sum[0] + piece[0], sum[1] + piece[1]];
                            prev = at;
                        }
                        sum.map(|v| v as f32)
                    })
                })
                .collect(),
            None => Vec::new(),
        };
        let mut min_beyond = heights.clone();
        for row in min_beyond.chunks_exact_mut(n_r) {
            let mut low = f32::INFINITY;
            for h in row.iter_mut().rev() {
                if !h.is_nan() {
                    low = low.min(*h);
                }
                *h = low;
            }
        }
        let (bounds, n_bounds) = height_bounds(&heights, n_e, n_r);
        Some(Self {
            inv_step_e: 1.0 / step_e,
            n_e,
            inv_step_r: 1.0 / step_r,
            n_r,
            heights,
            min_beyond,
            density,
            sky_elevation,
            step_e,
            bounds,
            n_bounds,
        })
    }

    /// Rays in the fan.
    pub(super) fn len(&self) -> usize {
        self.n_e
    }

    /// Cell and fraction of `x` (already scaled to grid units) on a grid of `n` nodes.
    #[inline]
    fn cell(x: f64, n: usize) -> Option<(usize, f64)> {
        // n ≤ MAX_SEA_FAN_RAYS: through u32 the casts are exact and cheaper than usize's.
        let last = (n - 1) as u32 as f64;
        if !(x >= 0.0 && x <= last) {
            return None;
        }
        let i = (x as u32).min(n as u32 - 2);
        Some((i as usize, x - f64::from(i)))
    }

    /// The ray launched from the sea at `elevation_rad`, for its heights at many ranges
    /// ([`SeaRay::height`], the same values as [`Self::height`]); `None` outside the fan.
    #[inline]
    pub(super) fn ray(&self, elevation_rad: f64) -> Option<SeaRay<'_>> {
        let (i, t) = Self::cell(elevation_rad * self.inv_step_e, self.n_e)?;
        let rows = i * self.n_r..(i + 2) * self.n_r;
        let (low, high) = self.heights[rows.clone()].split_at(self.n_r);
        let (low_min, high_min) = self.min_beyond[rows].split_at(self.n_r);
        Some(SeaRay {
            low,
            high,
            low_min,
            high_min,
            t,
            inv_step_r: self.inv_step_r,
        })
    }

    /// Height (m) at range `range_m` of the ray launched from the sea at `elevation_rad`:
    /// bilinear in the fan, `None` outside it or where a neighbour had ended.
    #[inline]
    pub(super) fn height(&self, elevation_rad: f64, range_m: f64) -> Option<f64> {
        let (i, t) = Self::cell(elevation_rad * self.inv_step_e, self.n_e)?;
        let (m, u) = Self::cell(range_m * self.inv_step_r, self.n_r)?;
        let at = |i: usize, m: usize| self.heights[i * self.n_r + m] as f64;
        let (a, b) = (at(i, m), at(i, m + 1));
        let (c, d) = (at(i + 1, m), at(i + 1, m + 1));
        let low = a + (b - a) * u;
        let high = c + (d - c) * u;
        let h = Self::between(low, high, t);
        h.is_finite().then_some(h)
    }

    /// `low` + (`high` − `low`)·`t`, but `low` itself for `t` < [`ON_RAY`]: an elevation on a
    /// fan ray up to rounding (as the ends of [`Self::elevations_within`]'s intervals are) has
    /// the ray's own height whether or not the ray above had ended. (NaN · t would make it
    /// vanish there, while the same elevation rounded into the cell below, at t ≈ 1, has it:
    /// rounding would decide whether an image reaches its end.)
    #[inline(always)]
    fn between(low: f64, high: f64, t: f64) -> f64 {
        if t < ON_RAY {
            low
        } else {
            low + (high - low) * t
        }
    }

    /// The density-weighted path lengths [D_R, D_A] (m) from the sea along the ray launched at
    /// `elevation_rad` to range `range_m` (bilinear, as [`Self::height`]); `None` where they
    /// were not summed or a neighbour had ended.
    #[inline]
    pub(super) fn density_paths_m(&self, elevation_rad: f64, range_m: f64) -> Option<[f64; 2]> {
        if self.density.is_empty() {
            return None;
        }
        let (i, t) = Self::cell(elevation_rad * self.inv_step_e, self.n_e)?;
        let (m, u) = Self::cell(range_m * self.inv_step_r, self.n_r)?;
        let at = |i: usize, m: usize| self.density[i * self.n_r + m];
        let (a, b) = (at(i, m), at(i, m + 1));
        let (c, d) = (at(i + 1, m), at(i + 1, m + 1));
        let out = [0, 1].map(|k| {
            let low = f64::from(a[k]) + f64::from(b[k] - a[k]) * u;
            let high = f64::from(c[k]) + f64::from(d[k] - c[k]) * u;
            low + (high - low) * t
        });
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    /// A lower bound (m) on the height, at every range from `range_m` on, of the ray launched
    /// from the sea at `elevation_rad` as [`Self::height`] interpolates it (+∞ outside the fan:
    /// it has no height there).
    #[inline]
    pub(super) fn min_height_beyond(&self, elevation_rad: f64, range_m: f64) -> f64 {
        let Some((i, _)) = Self::cell(elevation_rad * self.inv_step_e, self.n_e) else {
            return f64::INFINITY;
        };
        // (`max` maps a NaN range to 0: every height of the ray bounds it.)
        let x = (range_m * self.inv_step_r).max(0.0);
        if x > (self.n_r - 1) as u32 as f64 {
            return f64::INFINITY;
        }
        // The interpolated height in cell m is a weighted mean of the nodes m, m + 1 of rows
        // i, i + 1, so the nodes' minimum from m on bounds it there and beyond.
        let m = x as u32 as usize;
        let at = |i: usize| self.min_beyond[i * self.n_r + m];
        f64::from(at(i).min(at(i + 1)))
    }

    /// Final elevation (rad, relative to the reflection point's horizontal) of the ray launched
    /// from the sea at `elevation_rad`, where it and its neighbour left into the sky.
    #[inline]
    pub(super) fn sky_elevation(&self, elevation_rad: f64) -> Option<f64> {
        let (i, t) = Self::cell(elevation_rad * self.inv_step_e, self.n_e)?;
        let (a, b) = (self.sky_elevation[i], self.sky_elevation[i + 1]);
        let e = a + (b - a) * t;
        e.is_finite().then_some(e)
    }

    /// The heights (m) of every ray at range `range_m` (the range cell and fraction), as
    /// [`Self::height`] interpolates them; `None` outside the ranges.
    #[inline]
    fn at_range(&self, range_m: f64) -> Option<impl Fn(usize) -> f64 + '_> {
        let (m, u) = Self::cell(range_m * self.inv_step_r, self.n_r)?;
        Some(move |i: usize| {
            let (a, b) = (
                self.heights[i * self.n_r + m] as f64,
                self.heights[i * self.n_r + m + 1] as f64,
            );
            a + (b - a) * u
        })
    }

    /// The launch elevations in [`e_a`, `e_b`] (rad) whose rays are within [`h_lo`, `h_hi`] (m)
    /// at range `range_m`, exactly as [`Self::height`] interpolates them (linear in the
    /// elevation between neighbouring rays): ascending intervals, appended to `out`.
    pub(super) fn elevations_within(
        &self,
        range_m: f64,
        (h_lo, h_hi): (f64, f64),
        (e_a, e_b): (f64, f64),
        out: &mut Spans,
    ) {
        let Some((m, _)) = Self::cell(range_m * self.inv_step_r, self.n_r) else {
            return;
        };
        let Some(height) = self.at_range(range_m) else {
            return;
        };
        if e_b.is_nan() || e_a.is_nan() || e_b < e_a {
            return;
        }
        let last = self.n_e - 1;
        let first = ((e_a * self.inv_step_e).max(0.0) as usize).min(last - 1);
        let end = ((e_b * self.inv_step_e).ceil().max(1.0) as usize).min(last);
        let blocks = &self.bounds[m * self.n_bounds..(m + 1) * self.n_bounds];
        let (b_first, b_last) = (first / BOUND_BLOCK, (end - 1) / BOUND_BLOCK);
        for (b, &[low, high]) in blocks.iter().enumerate().take(b_last + 1).skip(b_first) {
            if f64::from(high) < h_lo || f64::from(low) > h_hi {
                continue;
            }
            let rays = (b * BOUND_BLOCK).max(first)..((b + 1) * BOUND_BLOCK).min(end);
            for i in rays {
                let (h0, h1) = (height(i), height(i + 1));
                if h0.is_nan() || h1.is_nan() {
                    continue;
                }
                let (t0, t1) = if h1 == h0 {
                    if h0 < h_lo || h0 > h_hi {
                        continue;
                    }
                    (0.0, 1.0)
                } else {
                    let (x, y) = ((h_lo - h0) / (h1 - h0), (h_hi - h0) / (h1 - h0));
                    (x.min(y).max(0.0), x.max(y).min(1.0))
                };
                // (i + t)·step: the end of one ray pair's interval (t = 1) is then bit for bit
                // the start of the next one's (t = 0), so the card's intervals join into one
                // ([`Spans::push`]); i·step + t·step can differ from (i + 1)·step by an ulp,
                // leaving a gap that cuts the image into parts at fan rays or not by rounding.
                let i = i as f64;
                let (a, b) = (
                    ((i + t0) * self.step_e).max(e_a),
                    ((i + t1) * self.step_e).min(e_b),
                );
                if a <= b {
                    out.push(a, b);
                }
            }
        }
    }

    /// From launch elevation `elevation_rad`, whose ray is at or below `height_m` at range
    /// `range_m`: the elevation at which the rays above it, walked up the fan, first rise above
    /// `height_m` there (linear between rays), at most `e_max`. A ray that has ended stops the
    /// walk where it is.
    pub(super) fn rise_above(
        &self,
        elevation_rad: f64,
        range_m: f64,
        height_m: f64,
        e_max: f64,
    ) -> f64 {
        let Some(height) = self.at_range(range_m) else {
            return elevation_rad;
        };
        let mut i = ((elevation_rad * self.inv_step_e).max(0.0) as usize).min(self.n_e - 2);
        let mut h0 = height(i);
        loop {
            let h1 = height(i + 1);
            let e1 = (i + 1) as f64 * self.step_e;
            if h0.is_nan() || h1.is_nan() {
                return elevation_rad.min(e_max);
            }
            if h1 > height_m {
                let e = i as f64 * self.step_e + self.step_e * (height_m - h0) / (h1 - h0);
                return e.clamp(elevation_rad, e1).min(e_max);
            }
            if e1 >= e_max || i + 2 >= self.n_e {
                return e1.min(e_max);
            }
            i += 1;
            h0 = h1;
        }
    }
}

/// Most elevation intervals one sample keeps ([`Spans`]).
pub(super) const MAX_SPANS: usize = 24;

/// The elevation intervals (rad) whose reflected rays meet each of a few objects, with the
/// weight each object's image is given ([`fade`]), without allocating: when full, a new
/// interval widens its object's last one to cover it (or is dropped if the object has none).
pub(super) struct Spans {
    items: [(f64, f64); MAX_SPANS],
    /// The object of each interval (an index into `weights`).
    owner: [u8; MAX_SPANS],
    len: usize,
    weights: [f64; MAX_SPANS],
    objects: usize,
    /// Intervals before this index belong to earlier objects: never joined.
    floor: usize,
    /// Whether the current object's intervals are kept.
    accepting: bool,
}

impl Spans {
    pub(super) fn new() -> Self {
        Self {
            items: [(0.0, 0.0); MAX_SPANS],
            owner: [0; MAX_SPANS],
            len: 0,
            weights: [1.0; MAX_SPANS],
            objects: 0,
            floor: 0,
            accepting: false,
        }
    }

    /// Start the intervals of another object (weight 1); returns where they start. Beyond
    /// [`MAX_SPANS`] objects, the next ones' intervals are dropped.
    #[inline]
    pub(super) fn begin(&mut self) -> usize {
        self.floor = self.len;
        if self.objects < MAX_SPANS {
            self.weights[self.objects] = 1.0;
            self.objects += 1;
            self.accepting = true;
        } else {
            self.accepting = false;
        }
        self.len
    }

    /// Add [`a`, `b`] to the current object's intervals, joined to its last one when it starts
    /// where that one ends.
    #[inline]
    pub(super) fn push(&mut self, a: f64, b: f64) {
        if !self.accepting {
            return;
        }
        if self.len > self.floor {
            let last = &mut self.items[self.len - 1];
            if a <= last.1 || self.len == MAX_SPANS {
                *last = (last.0.min(a), last.1.max(b));
                return;
            }
        }
        if self.len < MAX_SPANS {
            self.items[self.len] = (a, b);
            self.owner[self.len] = (self.objects - 1) as u8;
            self.len += 1;
        }
    }

    pub(super) fn len(&self) -> usize {
        self.len
    }

    /// Give the current object's image the weight `weight`; 0 removes its intervals.
    pub(super) fn weigh(&mut self, weight: f64) {
        if !self.accepting {
            return;
        }
        if weight <= 0.0 {
            self.len = self.floor;
            self.objects = self.objects.saturating_sub(1);
        } else if self.objects > 0 {
            self.weights[self.objects - 1] = weight;
        }
    }

    /// The intervals from index `from` on.
    pub(super) fn since(&self, from: usize) -> &[(f64, f64)] {
        &self.items[from.min(self.len)..self.len]
    }

    /// The largest weight of the objects whose intervals hold `e` (0: none).
    #[inline]
    pub(super) fn weight_at(&self, e: f64) -> f64 {
        (0..self.len)
            .filter(|&k| self.items[k].0 <= e && e <= self.items[k].1)
            .map(|k| self.weights[self.owner[k] as usize])
            .fold(0.0, f64::max)
    }
}

/// The weight given to an object's blurred image on a rough sea whose facets send it the share
/// `share` of the reflected light: 0 below [`MIN_NODE_SHARE`] (it is not traced), 1 from twice
/// that, linear between, so an image never appears or vanishes with a jump as the share
/// crosses the threshold (at most it is dimmed by [`MIN_NODE_SHARE`] of its contrast).
#[inline]
pub(super) fn fade(share: f64) -> f64 {
    ((share - MIN_NODE_SHARE) / MIN_NODE_SHARE).clamp(0.0, 1.0)
}

/// [`SeaFan`]'s `bounds` for `heights` (`n_e` rays of `n_r` ranges), and the blocks per range
/// cell.
fn height_bounds(heights: &[f32], n_e: usize, n_r: usize) -> (Vec<[f32; 2]>, usize) {
    let n_blocks = (n_e - 1).div_ceil(BOUND_BLOCK);
    let mut bounds = Vec::with_capacity((n_r - 1) * n_blocks);
    for m in 0..n_r - 1 {
        for b in 0..n_blocks {
            let rays = b * BOUND_BLOCK..((b + 1) * BOUND_BLOCK).min(n_e - 1) + 1;
            let mut out = [f32::INFINITY, f32::NEG_INFINITY];
            for i in rays {
                for h in [heights[i * n_r + m], heights[i * n_r + m + 1]] {
                    if !h.is_nan() {
                        out = [out[0].min(h), out[1].max(h)];
                    }
                }
            }
            bounds.push(out);
        }
    }
    (bounds, n_blocks)
}

/// One ray of a [`SeaFan`]: its two neighbouring fan rays and the fraction between them.
pub(super) struct SeaRay<'f> {
    low: &'f [f32],
    high: &'f [f32],
    /// The two rays' lowest heights from each range on ([`SeaFan`]'s `min_beyond`).
    low_min: &'f [f32],
    high_min: &'f [f32],
    t: f64,
    inv_step_r: f64,
}

impl SeaRay<'_> {
    /// Height (m) at range `range_m`, as [`SeaFan::height`] gives it.
    #[inline(always)]
    pub(super) fn height(&self, range_m: f64) -> Option<f64> {
        let (m, u) = SeaFan::cell(range_m * self.inv_step_r, self.low.len())?;
        let (low, high) = (&self.low[m..m + 2], &self.high[m..m + 2]);
        let (a, b) = (low[0] as f64, low[1] as f64);
        let (c, d) = (high[0] as f64, high[1] as f64);
        let low = a + (b - a) * u;
        let high = c + (d - c) * u;
        let h = SeaFan::between(low, high, self.t);
        h.is_finite().then_some(h)
    }

    /// [`SeaFan::min_height_beyond`] of this ray: a lower bound (m) on its height at every
    /// range from `range_m` on.
    #[inline(always)]
    pub(super) fn min_height_beyond(&self, range_m: f64) -> f64 {
        let x = (range_m * self.inv_step_r).max(0.0);
        if x > (self.low_min.len() - 1) as u32 as f64 {
            return f64::INFINITY;
        }
        let m = x as u32 as usize;
        f64::from(self.low_min[m].min(self.high_min[m]))
    }
}

/// [`Sea::facet_nodes`] with [`CARD_FACET_NODES`] classes, tabulated by grazing angle over
/// [0, `g_hi`] and interpolated linearly (node by node: the classes move continuously with the
/// grazing angle), so a sample pays a lookup, not eight exponentials.
pub(super) struct FacetTable {
    inv_step: f64,
    nodes: Vec<[FacetNode; CARD_FACET_NODES]>,
}

impl FacetTable {
    /// Entries in the table.
    const ENTRIES: usize = 2048;

    pub(super) fn new(sea: &Sea, g_hi: f64) -> Self {
        let g_hi = if g_hi > 0.0 && g_hi.is_finite() {
            g_hi.min(std::f64::consts::FRAC_PI_2)
        } else {
            std::f64::consts::FRAC_PI_2
        };
        let step = g_hi / (Self::ENTRIES - 1) as f64;
        Self {
            inv_step: 1.0 / step,
            nodes: (0..Self::ENTRIES)
                .map(|i| sea.facet_nodes::<CARD_FACET_NODES>(i as f64 * step))
                .collect(),
        }
    }

    /// The facet classes at grazing angle `grazing_rad` (clamped to the table).
    #[inline]
    pub(super) fn at(&self, grazing_rad: f64) -> [FacetNode; CARD_FACET_NODES] {
        let last = (self.nodes.len() - 1) as f64;
        let p = (grazing_rad * self.inv_step).clamp(0.0, last);
        let p = if p.is_nan() { 0.0 } else { p };
        let i = (p as usize).min(self.nodes.len() - 2);
        let t = p - i as f64;
        let (a, b) = (&self.nodes[i], &self.nodes[i + 1]);
        std::array::from_fn(|j| FacetNode {
            reflected_elevation_rad: a[j].reflected_elevation_rad
                + (b[j].reflected_elevation_rad - a[j].reflected_elevation_rad) * t,
            weight: a[j].weight + (b[j].weight - a[j].weight) * t,
            reflectance: a[j].reflectance + (b[j].reflectance - a[j].reflectance) * t,
        })
    }
}

/// Knots per grazing angle of a [`SlopeTable`].
const SLOPE_KNOTS: usize = 64;

/// One knot of a [`SlopeTable`]: the cumulative share and its density (per unit of the span),
/// then the cumulative share-weighted sky radiance and its density, per channel.
type SlopeKnot = [f64; 8];

/// The facets' Fresnel-weighted shares on a rough sea: for grazing angles over [0, `g_hi`], the
/// cumulative share of the reflected light, Σ weight × reflectance, from the lowest slope of
/// [`facet_slope_range`] to each of [`SLOPE_KNOTS`] + 1 knots equally spaced across it (the
/// density [`Sea::facet_density`] normalised to total weight 1 and integrated by trapezoids; in
/// between, the integral of the density linear between knots), and the same for the share
/// times the sky at the reflected rays' elevation. A sample integrates both over any interval
/// of slopes ([`SlopeSpan::share`], [`SlopeSpan::sky`]): exact for every part of a cell,
/// however small, which the midpoint classes of [`Sea::facet_nodes`] are not.
pub(super) struct SlopeTable {
    sigma_along: f64,
    inv_step: f64,
    /// Per grazing angle, the knots.
    knots: Vec<[SlopeKnot; SLOPE_KNOTS + 1]>,
}

impl SlopeTable {
    /// Most grazing angles in the table.
    const MAX_ENTRIES: usize = 512;
    /// Fewest grazing angles in the table.
    const MIN_ENTRIES: usize = 16;
    /// Grazing angles per rms along-ray slope σ′ (the shares change with g on the scale of σ′:
    /// linear interpolation between entries σ′/64 apart errs by some 1e-5 of them).
    const ENTRIES_PER_SIGMA: f64 = 64.0;

    /// The table of `sea` (σ > 0) over grazing angles [0, `g_hi`] (π/2 if not positive), with
    /// the sky radiance `sky` by elevation.
    pub(super) fn new(sea: &Sea, g_hi: f64, sky: &AngleTable) -> Self {
        let g_hi = if g_hi > 0.0 && g_hi.is_finite() {
            g_hi.min(std::f64::consts::FRAC_PI_2)
        } else {
            std::f64::consts::FRAC_PI_2
        };
        let sigma_along = sea.along_ray_slope();
        let wanted = (g_hi / sigma_along * Self::ENTRIES_PER_SIGMA).ceil();
        let entries = if wanted.is_finite() {
            (wanted as usize + 1).clamp(Self::MIN_ENTRIES, Self::MAX_ENTRIES)
        } else {
            Self::MAX_ENTRIES
        };
        let step = g_hi / (entries - 1) as f64;
        Self {
            sigma_along,
            inv_step: 1.0 / step,
            knots: (0..entries)
                .into_par_iter()
                .with_min_len(64)
                .map(|i| Self::entry(sea, i as f64 * step, sigma_along, sky))
                .collect(),
        }
    }

    /// The knots at grazing angle `g`.
    fn entry(
        sea: &Sea,
        g: f64,
        sigma_along: f64,
        sky: &AngleTable,
    ) -> [SlopeKnot; SLOPE_KNOTS + 1] {
        let (lo, hi) = facet_slope_range(g, sigma_along);
        let k_max = SLOPE_KNOTS as f64;
        let half_pi = std::f64::consts::FRAC_PI_2;
        let slope = |k: usize| lo + (hi - lo) * k as f64 / k_max;
        let density: [(f64, f64); SLOPE_KNOTS + 1] =
            std::array::from_fn(|k| sea.facet_density(g, slope(k), sigma_along));
        let total: f64 = density
            .windows(2)
            .map(|w| 0.5 * (w[0].0 + w[1].0))
            .sum::<f64>()
            / k_max;
        let mut out = [[0.0; 8]; SLOPE_KNOTS + 1];
        if total.is_nan() || total <= 0.0 {
            return out;
        }
        let mut sums = [0.0; 4];
        for k in 0..=SLOPE_KNOTS {
            let q = density[k].0 * density[k].1 / total;
            let l = sky.at((g + 2.0 * slope(k)).clamp(0.0, half_pi));
            let dens = [q, q * l[0], q * l[1], q * l[2]];
            if k > 0 {
                let prev = out[k - 1];
                for (c, sum) in sums.iter_mut().enumerate() {
                    *sum += 0.5 * (prev[2 * c + 1] + dens[c]) / k_max;
                }
            }
            for c in 0..4 {
                out[k][2 * c] = sums[c];
                out[k][2 * c + 1] = dens[c];
            }
        }
        out
    }

    /// The slopes seen by a ray meeting the sea at `grazing_rad` (NaN taken as 0).
    #[inline]
    pub(super) fn span(&self, grazing_rad: f64) -> SlopeSpan<'_> {
        let half_pi = std::f64::consts::FRAC_PI_2;
        let g = if grazing_rad.is_finite() {
            grazing_rad.clamp(0.0, half_pi)
        } else {
            0.0
        };
        let (lo, hi) = facet_slope_range(g, self.sigma_along);
        let last = (self.knots.len() - 1) as f64;
        let p = (g * self.inv_step).clamp(0.0, last);
        let i = (p as usize).min(self.knots.len() - 2);
        SlopeSpan {
            g,
            lo,
            width: hi - lo,
            a: &self.knots[i],
            b: &self.knots[i + 1],
            f: p - i as f64,
        }
    }
}

/// The slopes [lo, lo + width] one ray meeting the sea at grazing angle g sees, with its shares
/// ([`SlopeTable`]); positions across the span are t ∈ [0, 1].
pub(super) struct SlopeSpan<'t> {
    g: f64,
    lo: f64,
    width: f64,
    a: &'t [SlopeKnot; SLOPE_KNOTS + 1],
    b: &'t [SlopeKnot; SLOPE_KNOTS + 1],
    f: f64,
}

impl SlopeSpan<'_> {
    /// Elevation (rad) of the reflected ray from the facets at span position `t`: g + 2s,
    /// clamped to [0, π/2] (a ray sent back into the sea is taken to skim it).
    #[inline]
    pub(super) fn elevation(&self, t: f64) -> f64 {
        (self.g + 2.0 * (self.lo + t * self.width)).clamp(0.0, std::f64::consts::FRAC_PI_2)
    }

    /// Span position of the facets that reflect the ray at elevation `e` (rad), unclamped.
    #[inline]
    pub(super) fn position(&self, e: f64) -> f64 {
        (0.5 * (e - self.g) - self.lo) / self.width
    }

    /// Span position below which the reflected rays skim the sea (elevation 0), in [0, 1].
    #[inline]
    pub(super) fn skimming(&self) -> f64 {
        self.position(0.0).clamp(0.0, 1.0)
    }

    /// The knot interval of span position `t` (clamped to [0, 1]) and the position's offset
    /// into it.
    #[inline]
    fn knot(&self, t: f64) -> (usize, f64) {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        let n = SLOPE_KNOTS as f64;
        let x = t * n;
        let k = (x as usize).min(SLOPE_KNOTS - 1);
        (k, (x - k as f64) / n)
    }

    /// Cumulative value `c` (0: the share, 1–3: the share-weighted sky) at offset `tau` into
    /// knot interval `k`: the integral of the density linear across the interval.
    #[inline(always)]
    fn cumulative(&self, k: usize, tau: f64, c: usize) -> f64 {
        let n = SLOPE_KNOTS as f64;
        let at = |knots: &[SlopeKnot; SLOPE_KNOTS + 1]| {
            let (sum, q0, q1) = (
                knots[k][2 * c],
                knots[k][2 * c + 1],
                knots[k + 1][2 * c + 1],
            );
            sum + tau * (q0 + 0.5 * (q1 - q0) * tau * n)
        };
        let (a, b) = (at(self.a), at(self.b));
        a + (b - a) * self.f
    }

    /// The cumulative share (weight × reflectance) of the facets from the span's start to
    /// position `t` (clamped to [0, 1]).
    #[inline]
    pub(super) fn share(&self, t: f64) -> f64 {
        let (k, tau) = self.knot(t);
        self.cumulative(k, tau, 0)
    }

    /// The cumulative share-weighted sky radiance the facets reflect from the span's start to
    /// position `t` (clamped to [0, 1]).
    #[inline]
    pub(super) fn sky(&self, t: f64) -> [f64; 3] {
        let (k, tau) = self.knot(t);
        [
            self.cumulative(k, tau, 1),
            self.cumulative(k, tau, 2),
            self.cumulative(k, tau, 3),
        ]
    }

    /// The span position where the cumulative share reaches `share` (the inverse of
    /// [`Self::share`]: the knot interval by bisection, then the quadratic within it); 1 if it
    /// never does.
    pub(super) fn position_of_share(&self, share: f64) -> f64 {
        let n = SLOPE_KNOTS as f64;
        let at = |k: usize, c: usize| self.a[k][c] + (self.b[k][c] - self.a[k][c]) * self.f;
        if share.is_nan() || share >= at(SLOPE_KNOTS, 0) {
            return 1.0;
        }
        // The last knot at or below the share.
        let (mut lo, mut hi) = (0usize, SLOPE_KNOTS);
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if at(mid, 0) <= share {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let (c0, q0, q1) = (at(lo, 0), at(lo, 1), at(lo + 1, 1));
        // c0 + q0 τ + a τ² = share, a = (q1 − q0) n / 2, for τ in [0, 1/n].
        let (a, rest) = (0.5 * (q1 - q0) * n, share - c0);
        let disc = (q0 * q0 + 4.0 * a * rest).max(0.0);
        let tau = if q0 + disc.sqrt() > 0.0 {
            2.0 * rest / (q0 + disc.sqrt())
        } else {
            0.0
        };
        (lo as f64 + (tau * n).clamp(0.0, 1.0)) / n
    }

    /// The share of the facets whose reflected rays leave between elevations `e0` and `e1`.
    #[inline]
    pub(super) fn share_between(&self, e0: f64, e1: f64) -> f64 {
        let (t0, t1) = if e0 <= 0.0 {
            (0.0, self.position(e1))
        } else {
            (self.position(e0), self.position(e1))
        };
        (self.share(t1) - self.share(t0)).max(0.0)
    }
}

/// The wave facets as the sea's reflections use them: one mirror direction on a calm sea, the
/// integrated slope distribution on a rough one.
pub(super) enum Facets {
    /// σ = 0: one class, the reflected ray at the grazing angle.
    Mirror(FacetTable),
    /// σ > 0, with a sea fan (cards or terrain to mirror).
    Rough(SlopeTable),
    /// σ > 0, nothing to mirror (no sea fan): only the sky's reflection and the glitter.
    None,
}

/// The sun's glitter on a rough sea, resolved once per frame.
pub(super) struct Glint {
    pub(super) sun: Sun,
    /// The sun seen from the sea surface by its true elevation above a sea point's horizontal:
    /// its apparent elevation there and the optical depth of its own curved ray from there.
    pub(super) at_sea: Arc<SeaSunTable>,
    /// Bounds on cos φ over the frame, φ a film point's azimuth from the sun's: a sea point at
    /// ground distance d stands the sun d/R · cos φ higher than the camera's horizontal does.
    pub(super) cos_azimuth: (f64, f64),
    /// Solar irradiance normal to the beam outside the atmosphere, per channel (film units ×
    /// sr); at the sea it is attenuated by the table's optical depth.
    pub(super) irradiance: [f64; 3],
    /// The sun's disc-centre radiance outside the atmosphere (the glint's cap before ρ and the
    /// attenuation).
    pub(super) radiance_cap: [f64; 3],
}

impl Glint {
    /// Bounds (lo, hi) on the sun's true elevation above the horizontal of sea points whose
    /// verticals tilt by `near_rad` … `far_rad` (ground distance / R) towards any azimuth of
    /// the frame.
    fn true_range(&self, near_rad: f64, far_rad: f64) -> (f64, f64) {
        let s = self.sun.elevation_rad;
        let (c0, c1) = self.cos_azimuth;
        let lo = (near_rad * c0).min(far_rad * c0);
        let hi = (near_rad * c1).max(far_rad * c1);
        (s + lo, s + hi)
    }
}

/// Everything the sea's reflections need, per frame.
pub(super) struct Reflection {
    pub(super) sea: Sea,
    pub(super) sky: Sky,
    pub(super) earth_radius_m: f64,
    /// Rays from the sea surface (absent without cards beyond the nearest sea).
    pub(super) fan: Option<Arc<SeaFan>>,
    /// Sky radiance by the reflected rays' elevation.
    pub(super) sky_table: Arc<AngleTable>,
    /// The facets by grazing angle.
    pub(super) facets: Arc<Facets>,
    /// Rough-sea sun glitter (a sun and σ > 0).
    pub(super) glint: Option<Glint>,
    /// The sun, for its mirror image on a mirror sea (σ = 0), and its disc prepared once.
    pub(super) mirror_sun: Option<(Sun, SunDisc)>,
}

/// The launch elevation (rad) at the sea surface of the ray that leaves the atmosphere towards
/// a sun at true elevation `sun_elevation_rad`, to within [`SEA_SUN_LAUNCH_TOLERANCE_RAD`]:
/// a bracketed search on the launch elevation of rays from height 0 over [0, 0.5 rad], where a
/// ray that does not leave (trapped in a surface duct, or back on the sea) counts as passing
/// below the sun. Above the reach of the 0.5 rad ray, the sun's true elevation plus that ray's
/// refraction. `None` when every ray from the sea surface leaves above the sun: the sun's centre
/// is below the sea's apparent horizon.
///
/// The search is regula falsi with the Illinois modification (the final elevation is smooth in
/// the launch elevation wherever rays leave), falling back to bisection where an end of the
/// bracket does not leave or the bracket has not halved in two steps: a handful of rays where
/// bisection alone took 32. The renderer inverts one set of rays from the sea instead
/// ([`super::sea_sun`]); this search is the reference its tests check it against.
#[cfg(test)]
pub(super) fn sea_level_sun_launch_rad(
    tracer: &dyn RayTracer,
    sun_elevation_rad: f64,
) -> Option<f64> {
    let end = |e: f64| match tracer.trace(0.0, e, &[], true).end {
        FanEnd::Sky { elevation_rad } => Some(elevation_rad),
        _ => None,
    };
    let (mut lo, mut hi) = (0.0f64, 0.5f64);
    let top = end(hi)?;
    if top < sun_elevation_rad {
        return Some(sun_elevation_rad + (hi - top));
    }
    let mut f_lo = end(lo).map(|e| e - sun_elevation_rad);
    if f_lo.is_some_and(|f| f > 0.0) {
        return None;
    }
    // f_hi ≥ 0 ≥ f_lo (when the low end leaves): the crossing lies in [lo, hi].
    let mut f_hi = top - sun_elevation_rad;
    // Which end the last step moved (1: high, −1: low), and the bracket's widths one and two
    // steps ago.
    let (mut side, mut widths) = (0i8, [f64::INFINITY; 2]);
    for _ in 0..MAX_LAUNCH_STEPS {
        let width = hi - lo;
        if width <= SEA_SUN_LAUNCH_TOLERANCE_RAD {
            break;
        }
        let mid = match f_lo {
            Some(fl) if f_hi > fl && width < 0.5 * widths[1] => {
                let t = (-fl / (f_hi - fl)).clamp(0.0, 1.0);
                // Strictly inside, so every step shrinks the bracket.
                (lo + width * t).clamp(lo + 1e-3 * width, hi - 1e-3 * width)
            }
            _ => 0.5 * (lo + hi),
        };
        widths = [width, widths[0]];
        match end(mid) {
            Some(e) if e >= sun_elevation_rad => {
                (hi, f_hi) = (mid, e - sun_elevation_rad);
                if side > 0 {
                    f_lo = f_lo.map(|f| 0.5 * f);
                }
                side = 1;
            }
            r => {
                (lo, f_lo) = (mid, r.map(|e| e - sun_elevation_rad));
                if side < 0 {
                    f_hi *= 0.5;
                }
                side = -1;
            }
        }
    }
    Some(0.5 * (lo + hi))
}

/// How closely [`sea_level_sun_launch_rad`] brackets the launch elevation (rad): a thousandth of
/// an arcsecond, far below any pixel.
#[cfg(test)]
pub(super) const SEA_SUN_LAUNCH_TOLERANCE_RAD: f64 = 5e-9;

/// The most rays [`sea_level_sun_launch_rad`] traces after its first two: bisection alone
/// reaches its tolerance from 0.5 rad in 27 halvings, and the search halves the bracket at
/// least once every three steps (a step bisects when the last two did not halve it).
#[cfg(test)]
const MAX_LAUNCH_STEPS: usize = 96;

impl Reflection {
    /// Whether a ray meeting the sea at `grazing_rad`, `distance_m` may show the sun's glitter
    /// or mirror image (then the sea's colour depends on the azimuth).
    pub(super) fn may_show_sun(&self, grazing_rad: f64, distance_m: f64) -> bool {
        let tilt = distance_m / self.earth_radius_m;
        if let Some(g) = &self.glint {
            return g
                .at_sea
                .apparent_range(g.true_range(tilt.abs(), tilt.abs()))
                .is_some_and(|e| self.sea.may_glint(grazing_rad, e));
        }
        match (&self.mirror_sun, &self.fan) {
            (Some((sun, _)), Some(fan)) => fan.sky_elevation(grazing_rad).is_some_and(|e| {
                (e - tilt - sun.elevation_rad).abs()
                    <= 0.5 * sun.angular_diameter_rad + 2.0 * tilt.abs() + 1e-4
            }),
            _ => false,
        }
    }

    /// Whether some ray meeting the sea at a grazing angle in `grazing_rad` (lo, hi) and a
    /// ground distance in `distance_m` (lo, hi) may show the sun: when this is false,
    /// [`Self::may_show_sun`] is false for every such ray. A mirror sea's sun image is not
    /// bounded here: any ray that meets such a sea may show it.
    pub(super) fn may_show_sun_range(
        &self,
        grazing_rad: (f64, f64),
        distance_m: (f64, f64),
    ) -> bool {
        if let Some(g) = &self.glint {
            // The nearest and farthest hits tilt the sun least and most (padded for the
            // rounding of interpolated distances); a NaN distance bounds nothing.
            let (d0, d1) = (distance_m.0.abs(), distance_m.1.abs());
            let r = self.earth_radius_m;
            let near = (d0.min(d1) / r * (1.0 - 1e-9) - 1e-12).max(0.0);
            let far = d0.max(d1) / r * (1.0 + 1e-9) + 1e-12;
            if !far.is_finite() || distance_m.0.is_nan() || distance_m.1.is_nan() {
                return true;
            }
            return g
                .at_sea
                .apparent_range(g.true_range(near, far))
                .is_some_and(|e| self.sea.may_glint_range(grazing_rad, e));
        }
        self.mirror_sun.is_some() && self.fan.is_some()
    }

    /// The sun's glitter (rough sea) or mirror image (mirror sea) along a ray meeting the sea at
    /// `grazing_rad`, `distance_m` towards absolute azimuth `azimuth_rad`.
    pub(super) fn sun(&self, grazing_rad: f64, distance_m: f64, azimuth_rad: f64) -> [f64; 3] {
        self.sun_at(grazing_rad, distance_m).at(self, azimuth_rad)
    }

    /// [`Self::sun`] for rays meeting the sea at `grazing_rad` and `distance_m`, towards any
    /// azimuth ([`SeaSunAt::at`]).
    pub(super) fn sun_at(&self, grazing_rad: f64, distance_m: f64) -> SeaSunAt {
        // The reflection point's vertical is tilted by d/R towards the ray's azimuth.
        let tilt = distance_m / self.earth_radius_m;
        let facet = || self.sea.facet_nodes::<1>(grazing_rad)[0].reflectance;
        if self.glint.is_some() {
            return SeaSunAt::Glint {
                geometry: self.sea.glint_geometry(grazing_rad),
                tilt,
                rho: facet(),
            };
        }
        let (Some(_), Some(fan)) = (&self.mirror_sun, &self.fan) else {
            return SeaSunAt::Nothing;
        };
        match fan.sky_elevation(grazing_rad) {
            Some(end) => SeaSunAt::Mirror {
                elevation_rad: end - tilt,
                reflectance: facet(),
                transmittance: self.sky.transmittance(grazing_rad),
            },
            None => SeaSunAt::Nothing,
        }
    }
}

/// What [`Reflection::sun`] needs of rays meeting the sea at one grazing angle and distance,
/// worked out once for every azimuth (the same values as worked out per ray).
#[derive(Debug, Clone, Copy)]
pub(super) enum SeaSunAt {
    /// No sun on this sea.
    Nothing,
    /// A rough sea's glitter: the facet geometry of the grazing angle, the tilt (rad) of the
    /// reflection point's vertical, and the Fresnel reflectance that caps the glint.
    Glint {
        geometry: GlintGeometry,
        tilt: f64,
        rho: f64,
    },
    /// A mirror sea's image of the disc: the reflected ray's final elevation above the
    /// observer's horizontal (rad), the reflectance and the sky's transmittance at the grazing
    /// angle.
    Mirror {
        elevation_rad: f64,
        reflectance: f64,
        transmittance: [f64; 3],
    },
}

impl SeaSunAt {
    /// A rough sea's glitter towards absolute azimuth `azimuth_rad`: its factor per unit
    /// irradiance from the sun ([`GlintGeometry::per_irradiance`], a smooth function of the
    /// azimuth), and the transmittance per channel of the sun's light to the sea point along its
    /// own curved ray from there (zero where the sun is below the sea's apparent horizon there),
    /// which [`Self::glint_radiance`] turns into radiance. `None` when this is not glitter.
    #[inline]
    pub(super) fn glint_factor_and_transmittance(
        &self,
        refl: &Reflection,
        azimuth_rad: f64,
    ) -> Option<(f64, [f64; 3])> {
        let (SeaSunAt::Glint { geometry, tilt, .. }, Some(g)) = (self, &refl.glint) else {
            return None;
        };
        let phi = g.sun.azimuth_rad - azimuth_rad;
        let (e, depth) = g.at_sea.at(g.sun.elevation_rad + tilt * phi.cos());
        Some((
            geometry.per_irradiance(e, phi),
            depth.map(|tau| (-tau).exp()),
        ))
    }

    /// Bounds on the glitter towards absolute azimuths between `azimuth_rad` (a, b), either way
    /// round and less than π apart ([`GlitterBound`]); `None` when this is not glitter.
    pub(super) fn glint_bound(
        &self,
        refl: &Reflection,
        azimuth_rad: (f64, f64),
    ) -> Option<GlitterBound> {
        let (SeaSunAt::Glint { geometry, tilt, .. }, Some(g)) = (self, &refl.glint) else {
            return None;
        };
        let (irradiance, _) = self.glint_scales(refl)?;
        let sun_azimuth_rad = g.sun.azimuth_rad;
        let phi = |azimuth: f64| {
            let phi = sun_azimuth_rad - azimuth;
            (phi, phi.cos())
        };
        let cos_azimuth = cos_range(phi(azimuth_rad.0), phi(azimuth_rad.1));
        // The true elevations [`Self::glint_factor_and_transmittance`] looks up: s + tilt·cos φ.
        let s = g.sun.elevation_rad;
        let true_rad = (s + tilt * cos_azimuth.0, s + tilt * cos_azimuth.1);
        let t = g.at_sea.transmittance_bound(true_rad);
        let (factor, light) = match g.at_sea.apparent_range(true_rad) {
            Some(apparent) => (
                geometry.bound_over(apparent),
                [0, 1, 2].map(|c| irradiance[c] * t[c]),
            ),
            // Hidden below the sea's horizon at every one of them: +∞ depth, no light.
            None => (geometry.bound_over((0.0, 0.0)), [0.0; 3]),
        };
        Some(GlitterBound {
            sun_azimuth_rad,
            factor,
            light,
        })
    }

    /// The solar irradiance per channel and the Fresnel-reflected disc's radiance per channel
    /// of [`Self::glint_radiance`] (`None` when this is not glitter), for evaluating it many
    /// times.
    #[inline]
    pub(super) fn glint_scales(&self, refl: &Reflection) -> Option<([f64; 3], [f64; 3])> {
        let (SeaSunAt::Glint { rho, .. }, Some(g)) = (self, &refl.glint) else {
            return None;
        };
        Some((g.irradiance, g.radiance_cap.map(|c| rho * c)))
    }

    /// The glitter's radiance for the factor `k` and the transmittance `t` of
    /// [`Self::glint_factor_and_transmittance`]: the sun's irradiance times `k`,
    /// capped by the Fresnel-reflected disc, times `t` (zero where `k` ≤ 0, or when this is not
    /// glitter).
    #[inline]
    pub(super) fn glint_radiance(&self, refl: &Reflection, k: f64, t: [f64; 3]) -> [f64; 3] {
        self.glint_scales(refl)
            .map_or([0.0; 3], |scales| glint_radiance(k, t, scales))
    }

    /// [`Reflection::sun`] towards absolute azimuth `azimuth_rad`.
    pub(super) fn at(&self, refl: &Reflection, azimuth_rad: f64) -> [f64; 3] {
        match *self {
            SeaSunAt::Glint { geometry, tilt, .. } => {
                let Some(g) = &refl.glint else {
                    return [0.0; 3];
                };
                // As glint_factor_and_transmittance.
                let phi = g.sun.azimuth_rad - azimuth_rad;
                let (e, depth) = g.at_sea.at(g.sun.elevation_rad + tilt * phi.cos());
                let k = geometry.per_irradiance(e, phi);
                if k <= 0.0 {
                    return [0.0; 3];
                }
                self.glint_radiance(refl, k, depth.map(|tau| (-tau).exp()))
            }
            SeaSunAt::Mirror {
                elevation_rad,
                reflectance,
                transmittance,
            } => {
                let Some((_, disc)) = &refl.mirror_sun else {
                    return [0.0; 3];
                };
                let disc = disc.radiance(azimuth_rad, elevation_rad);
                if disc <= 0.0 {
                    return [0.0; 3];
                }
                transmittance.map(|t| reflectance * disc * t)
            }
            SeaSunAt::Nothing => [0.0; 3],
        }
    }
}

/// Upper bounds on a rough sea's glitter along rays meeting the sea at one grazing angle and
/// distance, towards the azimuths of a range ([`SeaSunAt::glint_bound`]), and of sub-ranges of
/// it ([`Self::at`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct GlitterBound {
    sun_azimuth_rad: f64,
    /// The factor's bounds over the sun's elevations at the sea points of the whole range.
    factor: GlintBound,
    /// Per channel, the solar irradiance times a bound on its transmittance to the sea.
    light: [f64; 3],
}

impl GlitterBound {
    /// The azimuth φ (rad) of absolute azimuth `azimuth_rad` from the sun's, and cos φ: a
    /// point of the ranges [`Self::at`] takes.
    #[inline]
    pub(super) fn azimuth_from_sun(&self, azimuth_rad: f64) -> (f64, f64) {
        let phi = self.sun_azimuth_rad - azimuth_rad;
        (phi, phi.cos())
    }

    /// Per channel, an upper bound on the glitter's radiance ([`SeaSunAt::glint_radiance`] of
    /// [`SeaSunAt::glint_factor_and_transmittance`]) towards every azimuth between `a` and `b`
    /// ([`Self::azimuth_from_sun`] of two absolute azimuths, either way round, within the range the
    /// bound was made for); NaN or +∞ channels where none is derived.
    #[inline]
    pub(super) fn at(&self, a: (f64, f64), b: (f64, f64)) -> [f64; 3] {
        let k = self.factor.at(cos_range(a, b));
        // The cap, min(k·E, cap), only lowers it.
        self.light.map(|l| k * l)
    }
}

/// [`SeaSunAt::glint_radiance`] with its [`SeaSunAt::glint_scales`].
#[inline]
pub(super) fn glint_radiance(
    k: f64,
    t: [f64; 3],
    (irradiance, cap): ([f64; 3], [f64; 3]),
) -> [f64; 3] {
    if k <= 0.0 {
        return [0.0; 3];
    }
    [0, 1, 2].map(|c| (k * irradiance[c]).min(cap[c]) * t[c])
}

impl Shader<'_> {
    /// What the sea adds along `dir` to its tabulated sky reflection, for a ray that met it at
    /// `grazing_rad` and `distance_m`: the sun's glitter (when `with_sun`) and the mirror images
    /// of the cards and the terrain (composed in depth order, Fresnel-weighted, over the wave
    /// facets, each in front of the sky it hides, which is taken out again).
    pub(super) fn sea_reflections(
        &self,
        dir: &ViewDirection,
        grazing_rad: f64,
        distance_m: f64,
        with_sun: bool,
    ) -> [f64; 3] {
        let mut out = [0.0; 3];
        let Some(refl) = &self.reflection else {
            return out;
        };
        let mut azimuth_cache: Option<f64> = None;
        let mut azimuth = || *azimuth_cache.get_or_insert_with(|| dir.azimuth_offset_rad());
        if with_sun && refl.may_show_sun(grazing_rad, distance_m) {
            out = refl.sun(grazing_rad, distance_m, self.heading_rad + azimuth());
        }
        let Some(fan) = &refl.fan else {
            return out;
        };
        let beyond = |card: &ViewCard<'_>| card.distance_m > distance_m;
        if self.terrain.is_none() && !self.cards.iter().any(beyond) {
            return out;
        }
        let images = match &*refl.facets {
            Facets::Mirror(table) => {
                self.mirror_images(fan, table, dir, grazing_rad, distance_m, &mut azimuth)
            }
            Facets::Rough(table) => {
                self.blurred_images(fan, table, dir, grazing_rad, distance_m, &mut azimuth)
            }
            Facets::None => [0.0; 3],
        };
        for c in 0..3 {
            out[c] += images[c];
        }
        out
    }

    /// [`Self::sea_reflections`] for a sample of flat band `band` (every sample of a band meets
    /// the sea at the same grazing angle and distance) on a rough sea mirroring only cards:
    /// the parts of its slopes ([`Self::blur_parts`]) depend then only on which cards the
    /// sample's azimuth is within, so they are found once per band and set of cards (`cache`)
    /// and only composed per sample; the same result. `None` where that does not hold (a calm
    /// sea, terrain, the sun's glitter, more than 64 cards).
    pub(super) fn band_reflections(
        &self,
        dir: &ViewDirection,
        grazing_rad: f64,
        distance_m: f64,
        band: usize,
        cache: &mut PartsCache,
    ) -> Option<[f64; 3]> {
        let refl = self.reflection.as_ref()?;
        let (Facets::Rough(table), Some(fan)) = (&*refl.facets, &refl.fan) else {
            return None;
        };
        if self.terrain.is_some()
            || self.cards.len() > 64
            || refl.may_show_sun(grazing_rad, distance_m)
        {
            return None;
        }
        let az = dir.azimuth_offset_rad();
        let cards = self
            .cards
            .iter()
            .enumerate()
            .filter(|(_, c)| c.distance_m > distance_m && in_range(c, az))
            .fold(0u64, |mask, (i, _)| mask | 1 << i);
        let at = match cache
            .entries
            .iter()
            .position(|e| e.band == band && e.cards == cards)
        {
            Some(at) => at,
            None => {
                let mut parts = Vec::new();
                self.blur_parts(fan, table, grazing_rad, distance_m, az, |p| parts.push(p));
                let at_cards = self.parts_at_cards(fan, distance_m, &parts);
                let met = self.cards_met(cards, &at_cards);
                cache.entries.push(CachedParts {
                    band,
                    cards,
                    parts,
                    at_cards,
                    met,
                });
                cache.entries.len() - 1
            }
        };
        let entry = &cache.entries[at];
        let n_cards = self.cards.len();
        let mut out = [0.0; 3];
        for (i, (part, &met)) in entry.parts.iter().zip(&entry.met).enumerate() {
            let at = &entry.at_cards[i * n_cards..(i + 1) * n_cards];
            let image = self.band_part(fan, dir, az, distance_m, part, (met, at));
            for c in 0..3 {
                out[c] += image[c];
            }
        }
        Some(out)
    }

    /// `parts`' rays reflected at `distance_m` at each card ([`PartAtCard`]; part by part,
    /// one per card in order): their heights depend on the part, not on the sample's azimuth,
    /// so a band's samples share them, and the cards' column means as its samples find them.
    pub(super) fn parts_at_cards(
        &self,
        fan: &SeaFan,
        distance_m: f64,
        parts: &[BlurPart],
    ) -> Vec<PartAtCard> {
        parts
            .iter()
            .flat_map(|part| {
                self.cards.iter().map(move |card| {
                    let range_m = card.distance_m - distance_m;
                    PartAtCard::of(fan, part.elevation_rad, part.span_rad, range_m)
                })
            })
            .collect()
    }

    /// Which cards each part's ray meets (bit i: card i), part by part, for a band's samples
    /// within the azimuth ranges of the cards `cards` (bit i: card i, beyond the sea point),
    /// given the parts' [`Self::parts_at_cards`]: those whose height range holds the ray's
    /// height there (as [`ViewCard`]'s meet tests it).
    fn cards_met(&self, cards: u64, at_cards: &[PartAtCard]) -> Vec<u64> {
        at_cards
            .chunks(self.cards.len().max(1))
            .map(|at| {
                let meets = |(i, (card, at)): (usize, (&ViewCard<'_>, &PartAtCard))| {
                    let within = at
                        .mid_m
                        .is_some_and(|h| !(h < card.base_m || h > card.top_m));
                    ((cards >> i) & 1 == 1 && within).then_some(1u64 << i)
                };
                self.cards
                    .iter()
                    .zip(at)
                    .enumerate()
                    .filter_map(meets)
                    .fold(0, |m, b| m | b)
            })
            .collect()
    }

    /// [`Self::blur_part`] for a sample of a band whose part's ray meets the cards `met`
    /// ([`Self::cards_met`]) with `at` their [`PartAtCard`]s: those composed in order (the
    /// cards are sorted by distance; no terrain), as [`Self::compose`] would; the same result.
    fn band_part(
        &self,
        fan: &SeaFan,
        dir: &ViewDirection,
        az: f64,
        distance_m: f64,
        part: &BlurPart,
        (met, at): (u64, &[PartAtCard]),
    ) -> [f64; 3] {
        if met == 0 {
            return [0.0; 3];
        }
        let ray = part_ray(fan, dir, az, distance_m, part, Some(at));
        let mut found = Composed::nothing();
        let mut bits = met;
        while bits != 0 {
            let i = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let card = &self.cards[i];
            let (Some(height_m), Some(u)) = (at[i].mid_m, card.across(az, true)) else {
                continue;
            };
            let meet = Meet {
                distance_m: card.distance_m,
                height_m,
                u,
                density_paths_m: None,
            };
            if found.add(card.shade(&ray, &meet, self)) {
                break;
            }
        }
        part_image(part, &found)
    }

    /// The mirror images on a calm sea: the one reflected ray of [`FacetTable`].
    fn mirror_images(
        &self,
        fan: &SeaFan,
        table: &FacetTable,
        dir: &ViewDirection,
        grazing_rad: f64,
        distance_m: f64,
        azimuth: &mut impl FnMut() -> f64,
    ) -> [f64; 3] {
        let mut out = [0.0; 3];
        let Some(refl) = &self.reflection else {
            return out;
        };
        let terrain = self.terrain.as_ref();
        let may_show_terrain =
            |e: f64| terrain.is_some_and(|t| t.may_be_reflected(fan, e, distance_m));
        let nodes = table.at(grazing_rad);
        let counts = |node: &FacetNode| node.weight * node.reflectance >= MIN_NODE_SHARE;
        let terrain_nodes = nodes
            .iter()
            .any(|n| counts(n) && may_show_terrain(n.reflected_elevation_rad));
        let beyond = |card: &ViewCard<'_>| card.distance_m > distance_m;
        if !terrain_nodes && !self.cards.iter().any(beyond) {
            return out;
        }
        let az = azimuth();
        if !terrain_nodes && !self.cards.iter().any(|c| beyond(c) && in_range(c, az)) {
            return out;
        }
        for node in nodes {
            if !counts(&node) {
                continue;
            }
            let e = node.reflected_elevation_rad;
            let ray = SampleRay::with_azimuth(
                dir,
                RayAlong::Reflected {
                    fan,
                    elevation_rad: e,
                    from_m: distance_m,
                    span_rad: (e, e),
                    at_cards: None,
                },
                az,
            );
            let found = self.compose(&ray);
            let covered = 1.0 - found.transmittance;
            if covered == 0.0 {
                continue;
            }
            let sky = refl.sky_table.at(e);
            let wf = node.weight * node.reflectance;
            for c in 0..3 {
                out[c] += wf * (found.radiance[c] - covered * sky[c]);
            }
        }
        out
    }

    /// The blurred images on a rough sea ([`Self::blur_parts`], each part composed at its
    /// middle elevation).
    fn blurred_images(
        &self,
        fan: &SeaFan,
        table: &SlopeTable,
        dir: &ViewDirection,
        grazing_rad: f64,
        distance_m: f64,
        azimuth: &mut impl FnMut() -> f64,
    ) -> [f64; 3] {
        let mut out = [0.0; 3];
        let az = azimuth();
        self.blur_parts(fan, table, grazing_rad, distance_m, az, |part| {
            let image = self.blur_part(fan, dir, az, distance_m, &part, None);
            for c in 0..3 {
                out[c] += image[c];
            }
        });
        out
    }

    /// What one part of a rough sea's slopes adds along `dir` (azimuth offset `az`), reflected
    /// at `distance_m`: the objects its middle ray meets, weighted by the part's share, over the
    /// sky they hide. `at_cards`: the part's [`Self::parts_at_cards`], if found before.
    #[inline]
    pub(super) fn blur_part(
        &self,
        fan: &SeaFan,
        dir: &ViewDirection,
        az: f64,
        distance_m: f64,
        part: &BlurPart,
        at_cards: Option<&[PartAtCard]>,
    ) -> [f64; 3] {
        let ray = part_ray(fan, dir, az, distance_m, part, at_cards);
        part_image(part, &self.compose(&ray))
    }

    /// The parts of the slopes a ray meeting a rough sea at `grazing_rad`, `distance_m` (azimuth
    /// offset `az`) sees that mirror something, passed to `each` in order. The slope span is
    /// cut at the elevations where the objects' images begin and end (each card's heights
    /// through the sea fan, [`Self::card_spans`]; the terrain's highest reflected elevation,
    /// [`terrain_cover`]) and, within images, at the bounds of [`SLOPE_CELLS`] cells; each part
    /// stands for its rays by its middle one (the cards' textures averaged over the heights
    /// its rays span), weighted by its exact Fresnel-weighted share and sky
    /// ([`SlopeSpan::share`], [`SlopeSpan::sky`]). So an image edge moves continuously with
    /// the grazing angle and is spread over the rows the slope distribution spreads it over.
    /// A terrain image with no card mirrored is one part, at the median of its share.
    pub(super) fn blur_parts(
        &self,
        fan: &SeaFan,
        table: &SlopeTable,
        grazing_rad: f64,
        distance_m: f64,
        az: f64,
        mut each: impl FnMut(BlurPart),
    ) {
        let span = table.span(grazing_rad);
        let mirrored = |card: &ViewCard<'_>| card.distance_m > distance_m && in_range(card, az);
        if !self.cards.iter().any(mirrored) {
            // No card's image: no spans, the terrain's alone (as below, without them).
            if let Some((top, weight)) = self.terrain_image(fan, &span, distance_m, az) {
                each(terrain_part(&span, top, weight));
            }
            return;
        }
        let (spans, cover) = self.images(fan, &span, distance_m, az);
        if spans.len() == 0 {
            if let Some((top, weight)) = cover {
                each(terrain_part(&span, top, weight));
            }
            return;
        }
        let weight_at = |e: f64| match cover {
            Some((top, w)) if e <= top => w.max(spans.weight_at(e)),
            _ => spans.weight_at(e),
        };
        let mut breaks = Breaks::new(&span);
        for &(a, b) in spans.since(0) {
            breaks.push(span.position(a));
            breaks.push(span.position(b));
        }
        if let Some((e, _)) = cover {
            breaks.push(span.position(e));
        }
        // The cells' bounds where they cut an image (elsewhere they would cut nothing).
        for c in 1..SLOPE_CELLS {
            let t = c as f64 / SLOPE_CELLS as f64;
            if weight_at(span.elevation(t)) > 0.0 {
                breaks.push(t);
            }
        }
        for (t0, t1) in breaks.parts() {
            let e = span.elevation(0.5 * (t0 + t1));
            let weight = weight_at(e);
            if weight.is_nan() || weight <= 0.0 {
                continue;
            }
            let share = weight * (span.share(t1) - span.share(t0));
            if share.is_nan() || share <= 0.0 {
                continue;
            }
            let (sky0, sky1) = (span.sky(t0), span.sky(t1));
            each(BlurPart {
                elevation_rad: e,
                span_rad: (span.elevation(t0), span.elevation(t1)),
                share,
                sky: [0, 1, 2].map(|c| weight * (sky1[c] - sky0[c])),
            });
        }
    }

    /// The reflected elevations of `span` whose rays from the sea at `distance_m` (azimuth
    /// offset `az`) meet each card, with their weights ([`Self::card_spans`]), and the highest
    /// that meets the terrain with its weight ([`terrain_cover`]).
    fn images(
        &self,
        fan: &SeaFan,
        span: &SlopeSpan<'_>,
        distance_m: f64,
        az: f64,
    ) -> (Spans, Option<(f64, f64)>) {
        let mut spans = Spans::new();
        for card in &self.cards {
            if card.distance_m > distance_m && in_range(card, az) {
                self.card_spans(fan, span, card, distance_m, &mut spans);
            }
        }
        (spans, self.terrain_image(fan, span, distance_m, az))
    }

    /// The terrain's part of [`Self::images`]: its [`terrain_cover`], if the frame has terrain.
    #[inline]
    fn terrain_image(
        &self,
        fan: &SeaFan,
        span: &SlopeSpan<'_>,
        distance_m: f64,
        az: f64,
    ) -> Option<(f64, f64)> {
        self.terrain
            .as_ref()
            .and_then(|t| terrain_cover(t, fan, span, az, distance_m))
    }

    /// Append to `spans` the reflected elevations of `span` whose rays from the sea at
    /// `distance_m` meet `card`'s height range at its range, weighted by [`fade`] of their
    /// share (none below [`MIN_NODE_SHARE`]); returns their share.
    pub(super) fn card_spans(
        &self,
        fan: &SeaFan,
        span: &SlopeSpan<'_>,
        card: &ViewCard<'_>,
        distance_m: f64,
        spans: &mut Spans,
    ) -> f64 {
        let start = spans.begin();
        let (e_lo, e_hi) = (span.elevation(0.0), span.elevation(1.0));
        fan.elevations_within(
            card.distance_m - distance_m,
            (card.base_m, card.top_m),
            (e_lo, e_hi),
            spans,
        );
        let share: f64 = spans
            .since(start)
            .iter()
            .map(|&(a, b)| span.share_between(a, b))
            .sum();
        spans.weigh(fade(share));
        share
    }
}

/// The highest elevation of `span` whose reflected rays from the sea at `distance_m` meet the
/// terrain along azimuth offset `az` (every lower one meets it too, where the sea fan's rays
/// keep their order), and the weight of the terrain's image ([`fade`] of their share; none
/// below [`MIN_NODE_SHARE`]).
fn terrain_cover(
    terrain: &TerrainView<'_>,
    fan: &SeaFan,
    span: &SlopeSpan<'_>,
    az: f64,
    distance_m: f64,
) -> Option<(f64, f64)> {
    let (e_lo, e_hi) = (span.elevation(0.0), span.elevation(1.0));
    if !terrain.may_be_reflected(fan, e_lo, distance_m) {
        return None;
    }
    let top = terrain.reflected_cover(az, fan, distance_m, (e_lo, e_hi))?;
    let weight = fade(span.share_between(e_lo, top));
    (weight > 0.0).then_some((top, weight))
}

/// The parts of a rough sea's slopes found for the samples of one image row's flat bands
/// ([`Shader::band_reflections`]), by band and set of mirrored cards.
#[derive(Default)]
pub(super) struct PartsCache {
    entries: Vec<CachedParts>,
}

struct CachedParts {
    band: usize,
    /// Bit i: card i of the shader is mirrored.
    cards: u64,
    parts: Vec<BlurPart>,
    /// The parts' [`Shader::parts_at_cards`].
    at_cards: Vec<PartAtCard>,
    /// The cards each part's ray meets ([`Shader::cards_met`]).
    met: Vec<u64>,
}

/// One part of a rough sea's slopes that mirrors something ([`Shader::blur_parts`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct BlurPart {
    /// The elevation (rad) of the ray that stands for the part.
    pub(super) elevation_rad: f64,
    /// The elevations its rays span (rad).
    pub(super) span_rad: (f64, f64),
    /// Its Fresnel-weighted share of the reflected light (with its image's weight, [`fade`]).
    pub(super) share: f64,
    /// Its share-weighted sky radiance, per channel (as `share`).
    pub(super) sky: [f64; 3],
}

/// A terrain image with no card mirrored, its reflected rays leaving `span` between its
/// lowest elevation and `top`, with weight `weight`: one part whose ray stands at the median of
/// their shares (the ground's colour is seen once; the share and the sky it hides are exact).
fn terrain_part(span: &SlopeSpan<'_>, top: f64, weight: f64) -> BlurPart {
    let t_top = span.position(top).max(span.skimming());
    let share = span.share(t_top);
    let median = span.position_of_share(0.5 * share).min(t_top);
    BlurPart {
        elevation_rad: span.elevation(median),
        span_rad: (span.elevation(0.0), top),
        share: weight * share,
        sky: span.sky(t_top).map(|v| weight * v),
    }
}

/// The ray that stands for `part` of the slopes of a sample along `dir` (azimuth offset `az`)
/// reflected at `distance_m` ([`Shader::blur_part`]).
#[inline]
fn part_ray<'a>(
    fan: &'a SeaFan,
    dir: &'a ViewDirection,
    az: f64,
    distance_m: f64,
    part: &BlurPart,
    at_cards: Option<&'a [PartAtCard]>,
) -> SampleRay<'a> {
    let along = RayAlong::Reflected {
        fan,
        elevation_rad: part.elevation_rad,
        from_m: distance_m,
        span_rad: part.span_rad,
        at_cards,
    };
    SampleRay::with_azimuth(dir, along, az)
}

/// What `part` adds given what its ray `found`: the objects' radiance weighted by its share,
/// over the sky they hide (nothing where they hide none).
#[inline]
fn part_image(part: &BlurPart, found: &Composed) -> [f64; 3] {
    let covered = 1.0 - found.transmittance;
    if covered == 0.0 {
        return [0.0; 3];
    }
    let mut out = [0.0; 3];
    for (c, v) in out.iter_mut().enumerate() {
        *v = part.share * found.radiance[c] - covered * part.sky[c];
    }
    out
}

/// Whether `card`'s azimuth range holds azimuth offset `az`.
#[inline]
fn in_range(card: &ViewCard<'_>, az: f64) -> bool {
    let mut offset = az - card.offset_rad;
    if offset.abs() > std::f64::consts::PI {
        offset = super::shade::wrap_pi(offset);
    }
    offset.abs() <= card.half_width_rad
}

/// Cells of the slope span on a rough sea, each composed at least once where it meets an object
/// (the midpoint classes of [`Sea::facet_nodes`] with 8 classes were σ′ apart).
pub(super) const SLOPE_CELLS: usize = 8;

/// Most cuts of one sample's slope span.
const MAX_BREAKS: usize = SLOPE_CELLS + 2 * MAX_SPANS + 4;

/// The positions (span positions t) where one sample's slope span is cut: the start of the rays
/// that leave above the sea (below it they all skim it at elevation 0: one part), the objects'
/// edges, and the cells' bounds within images.
struct Breaks {
    items: [f64; MAX_BREAKS],
    len: usize,
    /// Below this every reflected ray skims the sea.
    skim: f64,
}

impl Breaks {
    fn new(span: &SlopeSpan<'_>) -> Self {
        let skim = span.skimming();
        let mut out = Self {
            items: [0.0; MAX_BREAKS],
            len: 0,
            skim,
        };
        out.push(0.0);
        out.push(skim);
        out.push(1.0);
        out
    }

    /// Cut at `t`, if inside the span and above the skimming part.
    #[inline]
    fn push(&mut self, t: f64) {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        if (t > 0.0 && t < self.skim) || self.len == MAX_BREAKS {
            return;
        }
        self.items[self.len] = t;
        self.len += 1;
    }

    /// The parts between the cuts, in order.
    fn parts(&mut self) -> impl Iterator<Item = (f64, f64)> + '_ {
        let items = &mut self.items[..self.len];
        items.sort_unstable_by(f64::total_cmp);
        items
            .windows(2)
            .map(|w| (w[0], w[1]))
            .filter(|(a, b)| b > a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::ray_model::StraightRays;
    use crate::scene::sea::cox_munk_rms_slope_rad;

    fn rough_sea(wind_m_s: f64) -> Sea {
        Sea {
            wave_slope_rad: cox_munk_rms_slope_rad(wind_m_s),
            ..Sea::default()
        }
    }

    /// A sky that changes fast near the horizon, as the real one does.
    fn sky_table() -> AngleTable {
        AngleTable::new(0.0, std::f64::consts::FRAC_PI_2, |e| {
            let f = (-8.0 * e).exp();
            [0.3 + 0.7 * f, 0.4 + 0.6 * f, 0.9 - 0.2 * f]
        })
    }

    #[test]
    fn slope_shares_integrate_the_facet_density() {
        // The midpoint rule with many classes (Sea::facet_nodes) is the reference: the share
        // and the share-weighted sky of any interval of slopes, at grazing angles between the
        // table's entries, within 5e-4 of the reflected light (the 64 knots' trapezoids err by
        // about 2e-4 at most here, under a sky that changes as e⁻⁸ᵉ).
        let sky = sky_table();
        for wind in [0.0, 2.0, 10.0] {
            let sea = rough_sea(wind);
            let table = SlopeTable::new(&sea, 0.3, &sky);
            for g in [0.0, 0.0013, 0.02, 0.1, 0.2917] {
                let span = table.span(g);
                let nodes = sea.facet_nodes::<20000>(g);
                for (t0, t1) in [(0.0, 1.0), (0.0, 0.013), (0.2, 0.45), (0.71, 1.0)] {
                    let (mut share, mut lit) = (0.0, [0.0; 3]);
                    for (i, n) in nodes.iter().enumerate() {
                        let t = (i as f64 + 0.5) / nodes.len() as f64;
                        if (t0..t1).contains(&t) {
                            share += n.weight * n.reflectance;
                            let l = sky.at(n.reflected_elevation_rad);
                            for c in 0..3 {
                                lit[c] += n.weight * n.reflectance * l[c];
                            }
                        }
                    }
                    let got = span.share(t1) - span.share(t0);
                    assert!(
                        (got - share).abs() < 5e-4,
                        "wind {wind} g {g} [{t0}, {t1}]: {got} vs {share}"
                    );
                    let (s0, s1) = (span.sky(t0), span.sky(t1));
                    for c in 0..3 {
                        assert!(
                            (s1[c] - s0[c] - lit[c]).abs() < 5e-4,
                            "{wind} {g} {c} [{t0}, {t1}]: {} vs {}",
                            s1[c] - s0[c],
                            lit[c]
                        );
                    }
                }
                // The inverse: the position where the cumulative share reaches a value.
                for t in [0.0, 0.004, 0.3, 0.5, 0.99] {
                    let back = span.position_of_share(span.share(t));
                    assert!(
                        (span.share(back) - span.share(t)).abs() < 1e-12,
                        "{wind} {g} {t}: {back}"
                    );
                }
                assert_eq!(span.position_of_share(2.0), 1.0);
            }
        }
    }

    #[test]
    fn spans_keep_each_objects_intervals_and_weight() {
        let mut spans = Spans::new();
        spans.begin();
        spans.push(0.1, 0.2);
        spans.push(0.2, 0.3); // joined to the first
        spans.push(0.5, 0.6);
        spans.weigh(0.5);
        let second = spans.begin();
        spans.push(0.25, 0.55); // another object's: not joined
        spans.weigh(1.0);
        spans.begin();
        spans.push(0.9, 0.95);
        spans.weigh(0.0); // dropped
        assert_eq!(spans.since(0), &[(0.1, 0.3), (0.5, 0.6), (0.25, 0.55)][..]);
        assert_eq!(spans.since(second), &[(0.25, 0.55)][..]);
        assert_eq!(spans.weight_at(0.15), 0.5);
        assert_eq!(spans.weight_at(0.27), 1.0);
        assert_eq!(spans.weight_at(0.58), 0.5);
        assert_eq!(spans.weight_at(0.92), 0.0);
        assert_eq!(fade(MIN_NODE_SHARE), 0.0);
        assert_eq!(fade(2.0 * MIN_NODE_SHARE), 1.0);
        assert!((fade(1.5 * MIN_NODE_SHARE) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn elevations_within_a_height_range_are_those_the_fan_interpolates_there() {
        let tracer = StraightRays::new(crate::units::EARTH_RADIUS_M).unwrap();
        let fan = SeaFan::build(&tracer, 0.3, 0.004, (20_000.0, 30.0), false, None).unwrap();
        for (range_m, lo, hi) in [
            (3_000.0, 0.0, 300.0),
            (7_777.0, 20.0, 25.0),
            (150.0, 10.0, 1e4),
        ] {
            let mut spans = Spans::new();
            spans.begin();
            let (e_a, e_b) = (0.0005, 0.29);
            fan.elevations_within(range_m, (lo, hi), (e_a, e_b), &mut spans);
            let inside = |e: f64| spans.since(0).iter().any(|&(a, b)| a <= e && e <= b);
            for i in 0..20_000 {
                let e = e_a + (e_b - e_a) * (i as f64 + 0.5) / 20_000.0;
                let h = fan.height(e, range_m).unwrap();
                let want = (lo..=hi).contains(&h);
                // Within 1e-9 m of an edge either answer will do.
                if (h - lo).abs() > 1e-9 && (h - hi).abs() > 1e-9 {
                    assert_eq!(inside(e), want, "{range_m} [{lo}, {hi}] e {e}: h {h}");
                }
            }
        }
    }
}

/// The search for the sea-level launch towards the sun.
#[cfg(test)]
mod launch_tests {
    use super::*;
    use crate::render::test_rays::Leaving;

    /// The launch whose ray leaves at `sun` by 200 bisection steps (the reference).
    fn bisected(leave: impl Fn(f64) -> Option<f64>, sun: f64) -> f64 {
        let (mut lo, mut hi) = (0.0f64, 0.5f64);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            match leave(mid) {
                Some(e) if e >= sun => hi = mid,
                _ => lo = mid,
            }
        }
        0.5 * (lo + hi)
    }

    #[test]
    fn sea_fan_cells_are_those_of_the_usize_casts() {
        // The u32 casts of `SeaFan::cell` and `min_height_beyond` against usize's, bit for bit,
        // up to the largest fan (and off it).
        let by_usize = |x: f64, n: usize| {
            let last = (n - 1) as f64;
            (x >= 0.0 && x <= last).then(|| {
                let i = (x as usize).min(n - 2);
                (i, x - i as f64)
            })
        };
        for n in [2, 3, 17, MAX_SEA_FAN_RANGES, MAX_SEA_FAN_RAYS] {
            let last = (n - 1) as f64;
            let xs = [
                -1e-300,
                0.0,
                1e-12,
                0.5,
                1.0 - 1e-16,
                1.0,
                last - 0.25,
                last,
                last + 1e-9,
            ];
            for x in xs.into_iter().chain([f64::NAN, f64::INFINITY]) {
                let (a, b) = (SeaFan::cell(x, n), by_usize(x, n));
                assert_eq!(
                    a.map(|(i, u)| (i, u.to_bits())),
                    b.map(|(i, u)| (i, u.to_bits()))
                );
            }
        }
    }

    #[test]
    fn the_sea_level_sun_launch_is_found_within_its_tolerance_in_few_rays() {
        // Refraction falling from 0.6° at the surface (a strong duct) and a duct that traps
        // every ray launched below 0.2°.
        let smooth = |e: f64| Some(e - 0.0105 * (-e / 0.02).exp());
        let ducted = |e: f64| (e >= 0.0035).then(|| e - 0.0105 * (-e / 0.02).exp());
        for sun_deg in [-0.5, -0.1, 0.0, 0.3, 1.0, 5.0, 20.0] {
            let sun = f64::to_radians(sun_deg);
            // Bisection alone traces 32 rays; a trapped low end costs bisection steps until
            // the bracket's low end leaves.
            for (name, limit, leave) in [
                (
                    "smooth",
                    12,
                    &smooth as &(dyn Fn(f64) -> Option<f64> + Sync),
                ),
                ("ducted", 20, &ducted),
            ] {
                let tracer = Leaving::new(leave);
                let want = bisected(leave, sun);
                match sea_level_sun_launch_rad(&tracer, sun) {
                    Some(got) => {
                        assert!(
                            (got - want).abs() <= 0.5 * SEA_SUN_LAUNCH_TOLERANCE_RAD,
                            "{name} {sun_deg}°: {got} vs {want}"
                        );
                        // Where the sun is below every ray that leaves, the launch is the
                        // duct's edge, found by bisection alone.
                        let traces = tracer.traces();
                        let smooth_there = leave(want - 1e-6).is_some();
                        assert!(
                            traces <= limit || !smooth_there,
                            "{name} {sun_deg}°: {traces} rays"
                        );
                    }
                    None => assert!(
                        leave(0.0).is_some_and(|e| e > sun),
                        "{name} {sun_deg}°: none, yet the surface ray leaves below the sun"
                    ),
                }
            }
        }
        // Every ray from the surface leaves above a sun 0.8° below the horizon: hidden.
        let tracer = Leaving::new(smooth);
        assert_eq!(
            sea_level_sun_launch_rad(&tracer, f64::to_radians(-0.8)),
            None
        );
    }
}
