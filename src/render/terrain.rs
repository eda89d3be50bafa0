//! Render — terrain. In: the scene's [`Terrain`] (elevation model, observer, palette), the
//! [`RayTracer`], the frame's azimuth and elevation ranges. Out: a [`TerrainView`] that tells
//! for one sample (apparent elevation, azimuth) whether and where its ray meets the ground, and
//! the ground's colour there.
//!
//! In a stratified atmosphere a ray's height against ground distance, h(d; α), depends only on
//! its apparent elevation α, and it stays on the great circle through the observer along its
//! azimuth. So the view builds, once per frame:
//!
//! * a grid of ground distances dⱼ over the model's land (spacing the model's own, at most
//!   [`MAX_TERRAIN_DISTANCES`] points);
//! * terrain **profiles** z(dⱼ) along azimuths one pixel (or less) apart across the frame
//!   (bilinear in the model; sea, voids and points off the model are no ground);
//! * an [`ElevationFan`] of its own, traced at those distances and refined (by the fan's rules)
//!   wherever rays pass below the highest terrain at a distance.
//!
//! A sample then takes the profile nearest its azimuth and marches its ray (interpolated in the
//! fan between the two neighbouring rays, as for cards) along the grid: the first grid interval
//! where h − z changes sign holds the hit, placed by linear interpolation of h − z. Blocks of
//! [`BLOCK`] intervals where the lower neighbour ray stays above the profile's highest point are
//! skipped whole. A ray that reaches the sea first (its heights end) meets no terrain beyond.
//! The ground distance of the hit orders terrain against cards and the sea.
//!
//! Distances are the renderer's ground distances: arc lengths on the scene's sphere (and for
//! the constant-curvature model, its horizontal coordinate, as for cards).

use rayon::prelude::*;

use super::elevation_fan::{ElevationFan, FanSpec};
use super::ray_model::{FanEnd, RayTracer};
use super::shade::Shader;
use crate::scene::Terrain;
use crate::scene::camera::ViewDirection;

/// Most grid distances per frame.
pub const MAX_TERRAIN_DISTANCES: usize = 2048;
/// Most azimuth profiles per frame.
pub const MAX_TERRAIN_PROFILES: usize = 8192;
/// Grid intervals per skip block.
pub const BLOCK: usize = 16;

/// What [`TerrainView::new`] needs of the frame.
pub(super) struct TerrainFrame {
    pub(super) camera_height_m: f64,
    pub(super) heading_rad: f64,
    pub(super) earth_radius_m: f64,
    /// Azimuth offsets from the heading the frame spans (rad); `None`: all round.
    pub(super) azimuth_span_rad: Option<(f64, f64)>,
    pub(super) elevation_range_rad: (f64, f64),
    pub(super) pixel_rad: f64,
    pub(super) tolerance_px: f64,
    pub(super) max_depth: u32,
    /// Sky brightness (scales the palette).
    pub(super) brightness: f64,
}

/// A terrain hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerrainHit {
    /// Ground distance from the observer (m).
    pub distance_m: f64,
    /// Height of the ground there (m).
    pub height_m: f64,
}

/// Terrain prepared for one frame (see the module docs).
pub(super) struct TerrainView<'a> {
    terrain: &'a Terrain,
    frame: TerrainFrame,
    /// The grid distances (m), ascending.
    pub(super) distances_m: Vec<f64>,
    /// Profiles, `distances_m.len()` per azimuth; −∞ where there is no ground.
    profiles: Vec<f32>,
    /// Highest profile point of each block [bB, (b+1)B] (overlapping by one point).
    block_max: Vec<f32>,
    n_blocks: usize,
    az_start_rad: f64,
    az_inv_step: f64,
    n_profiles: usize,
    /// The terrain fan (None in exact mode: rays are traced per sample).
    fan: Option<ElevationFan>,
    /// Lowest height of each fan ray in each block (−∞ if the ray ends inside it).
    ray_block_min: Vec<f32>,
    /// Samples outside this elevation range (rad) meet no terrain.
    pub(super) may_hit_rad: (f64, f64),
}

/// Lowest height of `heights` in each block (−∞ where one is missing).
fn block_minima(heights: &[Option<f64>], n_blocks: usize) -> impl Iterator<Item = f32> + '_ {
    (0..n_blocks).map(move |b| {
        let end = ((b + 1) * BLOCK + 1).min(heights.len());
        heights[b * BLOCK..end]
            .iter()
            .map(|h| h.map_or(f32::NEG_INFINITY, |h| h as f32))
            .fold(f32::INFINITY, f32::min)
    })
}

impl<'a> TerrainView<'a> {
    /// The view of `terrain` for a frame, its fan traced through `tracer` (`exact`: no fan,
    /// every sample traces its own ray). `None` if the model holds no land in reach.
    pub(super) fn new(
        terrain: &'a Terrain,
        tracer: &dyn RayTracer,
        frame: TerrainFrame,
        exact: bool,
    ) -> Option<Self> {
        let radius = frame.earth_radius_m;
        let (lo, hi) = terrain.land_distance_range_m(radius)?;
        let spacing = terrain.dem.spacing_m(radius).max(1.0);
        let lo = lo.max(spacing);
        let hi = hi.max(lo + spacing);
        let n = (((hi - lo) / spacing).ceil() as usize + 1).clamp(2, MAX_TERRAIN_DISTANCES);
        let step = (hi - lo) / (n - 1) as f64;
        let distances_m: Vec<f64> = (0..n).map(|j| lo + j as f64 * step).collect();

        let (az_lo, az_hi) = match frame.azimuth_span_rad {
            Some((a, b)) => (a - 2.0 * frame.pixel_rad, b + 2.0 * frame.pixel_rad),
            None => (-std::f64::consts::PI, std::f64::consts::PI),
        };
        let n_profiles = (((az_hi - az_lo) / frame.pixel_rad).ceil() as usize + 1)
            .clamp(2, MAX_TERRAIN_PROFILES);
        let az_step = (az_hi - az_lo) / (n_profiles - 1) as f64;
        let profiles: Vec<f32> = (0..n_profiles)
            .into_par_iter()
            .flat_map_iter(|p| {
                let az = frame.heading_rad + az_lo + p as f64 * az_step;
                distances_m.iter().map(move |&d| {
                    terrain
                        .height_along(az, d, radius)
                        .map_or(f32::NEG_INFINITY, |z| z as f32)
                })
            })
            .collect();
        let n_blocks = (n - 1).div_ceil(BLOCK);
        let block_max: Vec<f32> = profiles
            .chunks_exact(n)
            .flat_map(|z| {
                (0..n_blocks).map(move |b| {
                    let end = ((b + 1) * BLOCK + 1).min(n);
                    z[b * BLOCK..end]
                        .iter()
                        .copied()
                        .fold(f32::NEG_INFINITY, f32::max)
                })
            })
            .collect();
        // Highest ground at each distance over all profiles: the fan refines below it.
        let max_top_m: Vec<f64> = (0..n)
            .map(|j| {
                (0..n_profiles)
                    .map(|p| profiles[p * n + j])
                    .fold(f32::NEG_INFINITY, f32::max) as f64
            })
            .collect();
        if max_top_m.iter().all(|z| *z == f64::NEG_INFINITY) {
            return None;
        }
        let mut view = Self {
            terrain,
            distances_m,
            profiles,
            block_max,
            n_blocks,
            az_start_rad: az_lo,
            az_inv_step: 1.0 / az_step,
            n_profiles,
            fan: None,
            ray_block_min: Vec::new(),
            may_hit_rad: frame.elevation_range_rad,
            frame,
        };
        if !exact {
            view.build_fan(tracer, max_top_m);
        }
        Some(view)
    }

    /// Trace the terrain fan, its per-block minima and the elevations that may meet the ground.
    fn build_fan(&mut self, tracer: &dyn RayTracer, max_top_m: Vec<f64>) {
        let f = &self.frame;
        let spec = FanSpec {
            camera_height_m: f.camera_height_m,
            distances_m: self.distances_m.clone(),
            max_top_m,
            need_sky_direction: false,
            sun_band_rad: None,
            elevation_range_rad: f.elevation_range_rad,
            pixel_rad: f.pixel_rad,
            tolerance_px: f.tolerance_px,
            max_depth: f.max_depth,
        };
        let fan = ElevationFan::build(tracer, &spec);
        let n = self.distances_m.len();
        let last = self.distances_m[n - 1];
        let alphas = fan.elevations_rad();
        let mut marked = (usize::MAX, 0usize);
        for i in 0..fan.len() {
            let heights = fan.ray_heights(i);
            self.ray_block_min
                .extend(block_minima(heights, self.n_blocks));
            let low = heights
                .iter()
                .zip(&spec.max_top_m)
                .any(|(h, top)| h.is_some_and(|h| h <= *top));
            let lands_inside = matches!(fan.ray_end(i),
                FanEnd::Ground { distance_m, .. } if distance_m >= spec.distances_m[0] && distance_m <= last);
            if low || lands_inside {
                marked = (marked.0.min(i), marked.1.max(i));
            }
        }
        self.may_hit_rad = if marked.0 == usize::MAX {
            (f64::INFINITY, f64::NEG_INFINITY)
        } else {
            (
                alphas[marked.0.saturating_sub(1)],
                alphas[(marked.1 + 1).min(alphas.len() - 1)],
            )
        };
        self.fan = Some(fan);
    }

    /// Index of the profile nearest azimuth offset `offset_rad` (from the heading); `None`
    /// outside the profiles.
    #[inline]
    fn profile(&self, offset_rad: f64) -> Option<usize> {
        let p = ((offset_rad - self.az_start_rad) * self.az_inv_step + 0.5).floor();
        (p >= 0.0 && p < self.n_profiles as f64).then_some(p as usize)
    }

    /// Where a sample at apparent elevation `alpha` and azimuth offset `offset_rad` meets the
    /// ground, using the terrain fan. `None` in exact mode (see [`Self::hit_traced`]).
    #[inline]
    pub(super) fn hit(&self, alpha: f64, offset_rad: f64) -> Option<TerrainHit> {
        if !(alpha >= self.may_hit_rad.0 && alpha <= self.may_hit_rad.1) {
            return None;
        }
        let fan = self.fan.as_ref()?;
        let p = self.profile(offset_rad)?;
        let (i, t) = fan.interval_fraction(alpha);
        let j1 = (i + 1).min(fan.len() - 1);
        let (ha, hb) = (fan.ray_heights(i), fan.ray_heights(j1));
        let height = |j: usize| match (ha[j], hb[j]) {
            (Some(x), Some(y)) => Some(x + (y - x) * t),
            (x, y) => {
                if t >= 0.5 {
                    y
                } else {
                    x
                }
            }
        };
        let nb = self.n_blocks;
        let (ma, mb) = (
            &self.ray_block_min[i * nb..(i + 1) * nb],
            &self.ray_block_min[j1 * nb..(j1 + 1) * nb],
        );
        let end = if t >= 0.5 {
            fan.ray_end(j1)
        } else {
            fan.ray_end(i)
        };
        self.march(p, height, |b| ma[b].min(mb[b]), end)
    }

    /// As [`Self::hit`] for a ray traced on its own: `heights` at [`Self::distances_m`] and its
    /// end.
    pub(super) fn hit_traced(
        &self,
        offset_rad: f64,
        heights: &[Option<f64>],
        end: FanEnd,
    ) -> Option<TerrainHit> {
        let p = self.profile(offset_rad)?;
        self.march(
            p,
            |j| heights.get(j).copied().flatten(),
            |_| f32::NEG_INFINITY,
            end,
        )
    }

    /// March profile `p` with a ray's heights `height(j)` (block minima `block_min(b)`, which
    /// may be −∞ to force a look) to the first grid interval where the ray meets the ground.
    #[inline]
    fn march(
        &self,
        p: usize,
        height: impl Fn(usize) -> Option<f64>,
        block_min: impl Fn(usize) -> f32,
        end: FanEnd,
    ) -> Option<TerrainHit> {
        let n = self.distances_m.len();
        let z = &self.profiles[p * n..(p + 1) * n];
        let zmax = &self.block_max[p * self.n_blocks..(p + 1) * self.n_blocks];
        let mut prev: Option<(f64, f64)> = None; // (h, z) at the previous grid point
        for (b, &block_top) in zmax.iter().enumerate() {
            if block_min(b) > block_top {
                prev = None; // the block's last point is above ground: restart there
                continue;
            }
            let start = b * BLOCK;
            let stop = ((b + 1) * BLOCK).min(n - 1);
            let first = if prev.is_some() { start + 1 } else { start };
            for (j, &zj) in z.iter().enumerate().take(stop + 1).skip(first) {
                let zj = zj as f64;
                let Some(hj) = height(j) else {
                    return self.landing(prev, j, zj, end);
                };
                if hj <= zj {
                    return Some(self.crossing(prev, j, hj, zj));
                }
                prev = Some((hj, zj));
            }
        }
        None
    }

    /// The hit in grid interval (j − 1, j), given the ray above the ground at j − 1 (`prev`,
    /// when known) and at or below it at j.
    #[inline]
    fn crossing(&self, prev: Option<(f64, f64)>, j: usize, hj: f64, zj: f64) -> TerrainHit {
        let d = &self.distances_m;
        match prev {
            Some((hp, zp)) if zp.is_finite() => {
                let (fp, fj) = (hp - zp, hj - zj);
                let s = (fp / (fp - fj)).clamp(0.0, 1.0);
                TerrainHit {
                    distance_m: d[j - 1] + (d[j] - d[j - 1]) * s,
                    height_m: zp + (zj - zp) * s,
                }
            }
            // The ground starts at j (a coast) or nothing is known before it.
            _ => TerrainHit {
                distance_m: d[j],
                height_m: zj,
            },
        }
    }

    /// A ray whose heights stop at grid point j: if it landed in the sea between j − 1 and j,
    /// it meets ground there only if the ground at the landing point is above the sea.
    fn landing(
        &self,
        prev: Option<(f64, f64)>,
        j: usize,
        zj: f64,
        end: FanEnd,
    ) -> Option<TerrainHit> {
        let FanEnd::Ground { distance_m: ds, .. } = end else {
            return None;
        };
        let (hp, zp) = prev?;
        let d = &self.distances_m;
        if !(ds > d[j - 1] && ds <= d[j] && zp.is_finite() && zj.is_finite()) {
            return None;
        }
        let s = (ds - d[j - 1]) / (d[j] - d[j - 1]);
        let zs = zp + (zj - zp) * s;
        (zs > 0.0)
            .then(|| self.crossing(Some((hp, zp)), j, 0.0, zs.max(0.0)))
            .map(|mut hit| {
                hit.distance_m = hit.distance_m.min(ds);
                hit
            })
    }

    /// Colour (linear RGB) of the ground hit at `hit` by a sample at azimuth offset `offset_rad`.
    pub(super) fn colour(&self, hit: TerrainHit, offset_rad: f64) -> [f64; 3] {
        let t = self.terrain;
        let radius = self.frame.earth_radius_m;
        let az = self.frame.heading_rad + offset_rad;
        let (lat, lon) = t.destination_deg(az, hit.distance_m, radius);
        let lon = t.wrap_lon(lon);
        let (slope, normal) = t
            .dem
            .slope_at(lat, lon, radius)
            .unwrap_or((0.0, [0.0, 0.0, 1.0]));
        // The normal is in the hit point's east/north/up; the light's direction is taken in the
        // same local frame (the model spans a few degrees at most).
        t.palette
            .colour(hit.height_m, slope, normal)
            .map(|c| c * self.frame.brightness)
    }
}

/// Radiance of a sample along `dir` whose ray meets the ground at `hit`: the ground's colour
/// (through the air between, with the sky's aerial perspective) behind the cards nearer than
/// the hit; `heights` (at the card distances `card_distances_m`) are cleared beyond it.
pub(super) fn shade_hit(
    shader: &Shader<'_>,
    view: &TerrainView<'_>,
    dir: &ViewDirection,
    heights: &mut [Option<f64>],
    card_distances_m: &[f64],
    hit: TerrainHit,
) -> [f64; 3] {
    let mut ground = view.colour(hit, dir.azimuth_offset_rad());
    if let Some(aerial) = &shader.aerial {
        let tau = aerial.extinction.chord_optical_depth(
            aerial.earth_radius_m,
            aerial.camera_height_m,
            hit.height_m,
            hit.distance_m,
        );
        ground = aerial.extinction.attenuate(ground, 1.0, tau);
    }
    for (h, &d) in heights.iter_mut().zip(card_distances_m) {
        if d >= hit.distance_m {
            *h = None;
        }
    }
    shader.composite(dir, heights, ground)
}
