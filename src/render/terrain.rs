//! Render — terrain. In: the scene's [`Terrain`] (elevation model, observer, palette), the
//! [`RayTracer`], the frame's azimuth and elevation ranges. Out: a [`TerrainView`] that tells
//! for one sample (apparent elevation, azimuth) whether and where its ray meets the ground, the
//! air along the ray up to there, and the ground's colour.
//!
//! In a stratified atmosphere a ray's height against ground distance, h(d; α), depends only on
//! its apparent elevation α, and it stays on the great circle through the observer along its
//! azimuth. So the view builds, once per frame:
//!
//! * a grid of ground distances dⱼ over the model's land (spacing the model's own, at most
//!   [`MAX_TERRAIN_DISTANCES`] points);
//! * terrain **profiles** z(dⱼ) along azimuths one pixel (or less) apart across the frame
//!   (bilinear in the model; sea, voids and points off the model are no ground);
//! * an [`ElevationFan`] of its own, refined (by the fan's rules) wherever rays pass below the
//!   highest terrain near a distance, traced to the **traced distances** ([`TracedGrid`]):
//!   points at most [`MAX_APPROACH_STEP_M`] apart from the camera to the land, then every
//!   `stride`-th grid distance (and the last). Between traced distances a ray's height is
//!   interpolated linearly. The stride is [`MAX_TRACED_STEP_M`] over the grid spacing; if a
//!   ray that comes below the highest terrain near a traced distance shows there, by the
//!   second difference of its heights at three traced distances, |Δ²h|/8, an interpolation
//!   error above the fan's tolerance at the nearest land (tolerance_px pixels there), the fan
//!   is traced again at stride 1 (every grid distance). Locating the requested distances is
//!   most of a terrain ray's cost, so a coarse stride that passes traces several times fewer.
//!
//! A sample then takes the profile nearest its azimuth and marches its ray (interpolated in the
//! fan between the two neighbouring rays, as for cards) along the grid: the first grid interval
//! where h − z changes sign holds the hit, placed by linear interpolation of h − z. Blocks of
//! [`BLOCK`] intervals where the lower neighbour ray stays above the profile's highest point are
//! skipped whole. A ray that reaches the sea first (its heights end) meets no terrain beyond.
//! The ground distance of the hit orders terrain against cards and the sea.
//!
//! **In the sea.** A ray the sea reflects at ground distance d₀ is a ray launched from the sea
//! surface (`super::reflection::SeaFan`) in the same vertical plane, so it marches the same
//! profile from d₀ on, its height at dⱼ the sea fan's at range dⱼ − d₀. The sea fan's per-ray
//! minima beyond each range reject the rays that stay above the profile's highest ground, and
//! the blocks they stay above, without a look at their points.
//!
//! **The air to the hit.** With the sky's aerial perspective, the density-weighted path
//! lengths D_k = ∫ e^(−h/H_k) ds (H = 8 km and the aerosol scale height) from the camera to
//! every traced distance are summed once per fan ray along its own traced heights (each piece's
//! height linear along it, integrated in closed form; the piece's length from its ground and
//! height steps), and a hit takes them at its distance (linear between traced distances and
//! between the two neighbouring rays). So terrain is seen through the air of the refracted
//! path, as cards are ([`super::air_paths`]). In exact mode every sample's own ray is traced to
//! every grid distance (stride 1) and summed the same way.
//!
//! Distances are the renderer's ground distances: arc lengths on the scene's sphere (and for
//! the constant-curvature model, its horizontal coordinate, as for cards).

use rayon::prelude::*;

use super::elevation_fan::{ElevationFan, FanSpec};
use super::objects::{Meet, RayAlong, SampleRay, SceneObject};
use super::ray_model::{FanEnd, RayTracer};
use super::reflection::{SeaFan, SeaRay};
use super::shade::Shader;
use crate::scene::Terrain;
use crate::scene::terrain::GreatCircle;

/// Most grid distances per frame.
pub const MAX_TERRAIN_DISTANCES: usize = 2048;
/// Most azimuth profiles per frame.
pub const MAX_TERRAIN_PROFILES: usize = 8192;
/// Grid intervals per skip block.
pub const BLOCK: usize = 8;
/// Longest step (m) between the traced distances from the camera to the land (they carry only
/// the air along the way: a ray's sag between them, κd²/8, is centimetres there).
pub const MAX_APPROACH_STEP_M: f64 = 2_000.0;
/// Longest step (m) between traced distances over the land the stride starts from.
pub const MAX_TRACED_STEP_M: f64 = 1_000.0;

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
    /// Scale heights (m) of the aerial perspective's extinction (Rayleigh, aerosol); `None`
    /// without haze (no path integrals).
    pub(super) scale_heights_m: Option<[f64; 2]>,
}

/// A terrain hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerrainHit {
    /// Ground distance from the observer (m).
    pub distance_m: f64,
    /// Height of the ground there (m).
    pub height_m: f64,
    /// The density-weighted path lengths (m) from the camera along the ray to the hit, for the
    /// Rayleigh and aerosol scale heights (`None` without haze, or where unknown).
    pub density_paths_m: Option<[f64; 2]>,
}

/// The distances a terrain ray is traced to, and how the grid distances lie between them.
#[derive(Debug, Clone)]
pub(super) struct TracedGrid {
    /// Ascending: approach points before the land, then grid distances.
    pub(super) traced_m: Vec<f64>,
    /// For each grid distance: the traced interval c (`traced_m[c] ≤ dⱼ ≤ traced_m[c + 1]`, or c
    /// the last) and the fraction of the way through it.
    map: Vec<(usize, f64)>,
    /// The grid distances.
    grid_m: Vec<f64>,
}

impl TracedGrid {
    /// Approach points at most [`MAX_APPROACH_STEP_M`] apart up to the first grid distance, then
    /// every `stride`-th grid distance and the last.
    pub(super) fn new(grid_m: &[f64], stride: usize) -> Self {
        let lo = grid_m[0];
        let steps = (lo / MAX_APPROACH_STEP_M).ceil().max(1.0) as usize;
        let mut traced_m: Vec<f64> = (1..steps).map(|i| lo * i as f64 / steps as f64).collect();
        let first_land = traced_m.len();
        let n = grid_m.len();
        let mut land: Vec<usize> = (0..n).step_by(stride.max(1)).collect();
        if land.last() != Some(&(n - 1)) {
            land.push(n - 1);
        }
        traced_m.extend(land.iter().map(|&j| grid_m[j]));
        let mut map = Vec::with_capacity(n);
        let mut c = 0;
        for (j, &d) in grid_m.iter().enumerate() {
            while c + 1 < land.len() && land[c + 1] <= j {
                c += 1;
            }
            let (a, w) = if c + 1 < land.len() {
                let (j0, j1) = (land[c], land[c + 1]);
                (first_land + c, (d - grid_m[j0]) / (grid_m[j1] - grid_m[j0]))
            } else {
                (first_land + c, 0.0)
            };
            map.push((a, w));
        }
        Self {
            traced_m,
            map,
            grid_m: grid_m.to_vec(),
        }
    }

    /// Height at grid distance j of a ray with `heights` at the traced distances that ended
    /// with `end`: linear between traced distances; between the last traced height and a
    /// landing in the sea, linear down to the landing point; `None` past the ray's end.
    #[inline]
    pub(super) fn height(&self, heights: &[Option<f64>], end: FanEnd, j: usize) -> Option<f64> {
        let (c, w) = self.map[j];
        let h0 = heights[c]?;
        if w == 0.0 {
            return Some(h0);
        }
        match heights[c + 1] {
            Some(h1) => Some(h0 + (h1 - h0) * w),
            None => {
                let FanEnd::Ground { distance_m: ds, .. } = end else {
                    return None;
                };
                let (d0, d) = (self.traced_m[c], self.grid_m[j]);
                (ds > d0 && d <= ds).then(|| h0 * (ds - d) / (ds - d0))
            }
        }
    }

    /// The traced interval holding ground distance `d_m` (the last traced distance at or before
    /// it; 0 before the first).
    #[inline]
    fn interval(&self, d_m: f64) -> usize {
        self.traced_m
            .partition_point(|&t| t <= d_m)
            .saturating_sub(1)
    }
}

/// Density-weighted lengths [D_R, D_A] (m) of the straight piece from (`d0`, `h0`) to (`d1`,
/// `h1`) (ground distance, height) over a sphere of `radius_m`, its height linear along it:
/// L·e^(−h₀/H)·(1 − e^(−Δh/H))/(Δh/H) for each scale height H.
#[inline]
pub(super) fn piece_density(
    (d0, h0): (f64, f64),
    (d1, h1): (f64, f64),
    radius_m: f64,
    scales_m: [f64; 2],
) -> [f64; 2] {
    let dh = h1 - h0;
    let length = ((d1 - d0) * (1.0 + 0.5 * (h0 + h1) / radius_m)).hypot(dh);
    scales_m.map(|scale| {
        let x = dh / scale;
        let mean = if x.abs() < 1e-9 {
            1.0 - 0.5 * x
        } else {
            -(-x).exp_m1() / x
        };
        length * (-h0 / scale).exp() * mean
    })
}

/// Cumulative density-weighted lengths from the camera (`h_cam` at distance 0) to every traced
/// distance of a ray with `heights` (NaN from the first distance it does not reach).
fn cumulative_density(
    traced_m: &[f64],
    heights: &[Option<f64>],
    camera_height_m: f64,
    radius_m: f64,
    scales_m: [f64; 2],
) -> Vec<[f32; 2]> {
    let mut out = Vec::with_capacity(traced_m.len());
    let mut prev = (0.0, camera_height_m);
    let mut sum = [0.0f64; 2];
    for (&d, h) in traced_m.iter().zip(heights) {
        let Some(h) = *h else {
            out.resize(traced_m.len(), [f32::NAN; 2]);
            break;
        };
        let piece = piece_density(prev, (d, h), radius_m, scales_m);
        sum = [sum[0] + piece[0], sum[1] + piece[1]];
        out.push(sum.map(|v| v as f32));
        prev = (d, h);
    }
    out
}

/// Terrain prepared for one frame (see the module docs).
pub(super) struct TerrainView<'a> {
    terrain: &'a Terrain,
    frame: TerrainFrame,
    /// The grid distances (m), ascending.
    pub(super) distances_m: Vec<f64>,
    /// Profiles, `distances_m.len()` per azimuth; −∞ where there is no ground.
    profiles: Vec<f32>,
    /// The model's fractional (row, column) of every profile point, as `profiles` (NaN off
    /// the model): a hit's grid position is interpolated between its grid distances
    /// ([`Self::hit_grid`]).
    grid_rc: Vec<[f64; 2]>,
    /// 1 / the grid distances' spacing (1/m).
    grid_inv_step: f64,
    /// Highest profile point of each block [bB, (b+1)B] (overlapping by one point).
    block_max: Vec<f32>,
    /// Highest point of each profile (−∞: no ground on it).
    profile_max: Vec<f32>,
    n_blocks: usize,
    az_start_rad: f64,
    az_inv_step: f64,
    n_profiles: usize,
    /// The great circle of each profile.
    circles: Vec<GreatCircle>,
    /// The highest ground at each grid distance over all profiles (−∞: none).
    max_top_m: Vec<f64>,
    /// The highest ground in the frame (m).
    max_height_m: f64,
    /// The palette's [`crate::scene::terrain::Palette::ice_tan_below`].
    ice_tan_below: f64,
    /// Where the rays are traced: the fan's (or in exact mode every sample's).
    pub(super) traced: TracedGrid,
    /// The terrain fan (None in exact mode: rays are traced per sample).
    fan: Option<ElevationFan>,
    /// Every fan ray's height at every grid distance ([`TracedGrid::height`]; NaN past its
    /// end), `distances_m.len()` per ray.
    ray_grid_heights: Vec<f32>,
    /// Lowest height of each fan ray in each block (−∞ if the ray ends inside it).
    ray_block_min: Vec<f32>,
    /// Per fan ray, [`cumulative_density`] at every traced distance (empty without haze).
    ray_density: Vec<[f32; 2]>,
    /// Samples outside this elevation range (rad) meet no terrain.
    pub(super) may_hit_rad: (f64, f64),
    /// [`Self::reflection_candidates`] of every profile, one after the other (empty until
    /// [`Self::prepare_reflections`]).
    candidates: Vec<u32>,
    /// Where each profile's candidates start in `candidates` (and where the last ends).
    candidate_start: Vec<usize>,
}

/// [`TerrainView::reflected_cover`]'s ray: the lowest reflected ray not yet known to meet the
/// ground.
struct LowestRay<'f> {
    fan: &'f SeaFan,
    from_m: f64,
    e_hi: f64,
    /// Its elevation (rad).
    e: f64,
    ray: SeaRay<'f>,
    /// The highest elevation known to meet the ground.
    top: Option<f64>,
}

impl LowestRay<'_> {
    /// Raise the ray to clear the ground point at distance `d_m`, height `z_m` (−∞: none), if
    /// it does not; `Some(false)` once it is at `e_hi`, `None` if it leaves the sea fan.
    #[inline]
    fn clear(&mut self, d_m: f64, z_m: f32) -> Option<bool> {
        let (z, range) = (f64::from(z_m), d_m - self.from_m);
        if z == f64::NEG_INFINITY || self.ray.height(range).is_none_or(|h| h > z) {
            return Some(true);
        }
        self.e = self.fan.rise_above(self.e, range, z, self.e_hi);
        self.top = Some(self.e);
        self.ray = self.fan.ray(self.e)?;
        Some(self.e < self.e_hi)
    }
}

/// Lowest height of each block of grid distances for a ray (−∞ where one is missing).
fn block_minima(height: impl Fn(usize) -> Option<f64>, n: usize, n_blocks: usize) -> Vec<f32> {
    (0..n_blocks)
        .map(|b| {
            let end = ((b + 1) * BLOCK + 1).min(n);
            (b * BLOCK..end)
                .map(|j| height(j).map_or(f32::NEG_INFINITY, |h| h as f32))
                .fold(f32::INFINITY, f32::min)
        })
        .collect()
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
        let (profiles, grid_rc) =
            sample_profiles(terrain, &frame, &distances_m, az_lo, az_step, n_profiles);
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
        let profile_max: Vec<f32> = block_max
            .chunks_exact(n_blocks)
            .map(|b| b.iter().copied().fold(f32::NEG_INFINITY, f32::max))
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
            traced: TracedGrid::new(&distances_m, 1),
            grid_inv_step: (n - 1) as f64 / (distances_m[n - 1] - distances_m[0]),
            distances_m,
            profiles,
            grid_rc,
            block_max,
            profile_max,
            n_blocks,
            az_start_rad: az_lo,
            az_inv_step: 1.0 / az_step,
            n_profiles,
            circles: (0..n_profiles)
                .map(|p| terrain.great_circle(frame.heading_rad + az_lo + p as f64 * az_step))
                .collect(),
            max_height_m: max_top_m.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            max_top_m,
            ice_tan_below: terrain.palette.ice_tan_below(),
            fan: None,
            ray_grid_heights: Vec::new(),
            ray_block_min: Vec::new(),
            ray_density: Vec::new(),
            may_hit_rad: frame.elevation_range_rad,
            candidates: Vec::new(),
            candidate_start: vec![0; n_profiles + 1],
            frame,
        };
        if !exact {
            view.build_fan(tracer, spacing);
        }
        Some(view)
    }

    /// Trace the terrain fan at the largest stride whose interpolation passes (module docs),
    /// then its per-block minima, path integrals and the elevations that may meet the ground.
    fn build_fan(&mut self, tracer: &dyn RayTracer, spacing_m: f64) {
        let stride = ((MAX_TRACED_STEP_M / spacing_m) as usize).max(1);
        let mut traced = TracedGrid::new(&self.distances_m, stride);
        let mut fan = ElevationFan::build(tracer, &self.fan_spec(&traced));
        if stride > 1 && !self.interpolates(&traced, &fan) {
            traced = TracedGrid::new(&self.distances_m, 1);
            fan = ElevationFan::build(tracer, &self.fan_spec(&traced));
        }
        let n = self.distances_m.len();
        let mut marked = (usize::MAX, 0usize);
        let (first, last) = (self.distances_m[0], self.distances_m[n - 1]);
        self.ray_grid_heights = (0..fan.len())
            .into_par_iter()
            .flat_map_iter(|i| {
                let (heights, end) = (fan.ray_heights(i), fan.ray_end(i));
                let traced = &traced;
                (0..n).map(move |j| {
                    traced
                        .height(heights, end, j)
                        .map_or(f32::NAN, |h| h as f32)
                })
            })
            .collect();
        for i in 0..fan.len() {
            let grid = &self.ray_grid_heights[i * n..(i + 1) * n];
            let height = |j: usize| Some(f64::from(grid[j])).filter(|h| !h.is_nan());
            let end = fan.ray_end(i);
            self.ray_block_min
                .extend(block_minima(height, n, self.n_blocks));
            let low = (0..n).any(|j| height(j).is_some_and(|h| h <= self.max_top_m[j]));
            let lands_inside = matches!(end,
                FanEnd::Ground { distance_m, .. } if distance_m >= first && distance_m <= last);
            if low || lands_inside {
                marked = (marked.0.min(i), marked.1.max(i));
            }
        }
        if let Some(scales) = self.frame.scale_heights_m {
            let f = &self.frame;
            self.ray_density = (0..fan.len())
                .into_par_iter()
                .flat_map_iter(|i| {
                    let h = fan.ray_heights(i);
                    cumulative_density(
                        &traced.traced_m,
                        h,
                        f.camera_height_m,
                        f.earth_radius_m,
                        scales,
                    )
                })
                .collect();
        }
        let alphas = fan.elevations_rad();
        self.may_hit_rad = if marked.0 == usize::MAX {
            (f64::INFINITY, f64::NEG_INFINITY)
        } else {
            (
                alphas[marked.0.saturating_sub(1)],
                alphas[(marked.1 + 1).min(alphas.len() - 1)],
            )
        };
        self.traced = traced;
        self.fan = Some(fan);
    }

    /// The fan's spec for `traced`: heights matter below the highest ground between a traced
    /// distance's neighbours (none before the land).
    fn fan_spec(&self, traced: &TracedGrid) -> FanSpec {
        let f = &self.frame;
        let t = &traced.traced_m;
        let max_top_m = (0..t.len())
            .map(|c| {
                let (a, b) = (t[c.saturating_sub(1)], t[(c + 1).min(t.len() - 1)]);
                self.distances_m
                    .iter()
                    .zip(&self.max_top_m)
                    .filter(|&(&d, _)| d >= a && d <= b)
                    .map(|(_, &z)| z)
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .collect();
        FanSpec {
            camera_height_m: f.camera_height_m,
            distances_m: t.clone(),
            max_top_m,
            need_sky_direction: false,
            sun_band_rad: None,
            elevation_range_rad: f.elevation_range_rad,
            pixel_rad: f.pixel_rad,
            tolerance_px: f.tolerance_px,
            max_depth: f.max_depth,
        }
    }

    /// Whether linear interpolation between `traced` distances is within the fan's tolerance
    /// for every ray of `fan` where it comes below the highest ground: |Δ²h|/8 at three traced
    /// land distances at most tolerance_px pixels at the nearest land.
    fn interpolates(&self, traced: &TracedGrid, fan: &ElevationFan) -> bool {
        let f = &self.frame;
        let limit_m = f.tolerance_px * f.pixel_rad * self.distances_m[0];
        let first_land = traced.map[0].0;
        let tops = self.fan_spec(traced).max_top_m;
        (0..fan.len()).all(|i| {
            let h = &fan.ray_heights(i)[first_land..];
            (1..h.len().saturating_sub(1)).all(|c| match (h[c - 1], h[c], h[c + 1]) {
                (Some(a), Some(b), Some(d)) if a.min(b).min(d) <= tops[first_land + c] => {
                    (a - 2.0 * b + d).abs() / 8.0 <= limit_m
                }
                _ => true,
            })
        })
    }

    /// Index of the profile nearest azimuth offset `offset_rad` (from the heading); `None`
    /// outside the profiles.
    #[inline]
    fn profile(&self, offset_rad: f64) -> Option<usize> {
        let p = ((offset_rad - self.az_start_rad) * self.az_inv_step + 0.5).floor();
        // (At most MAX_TERRAIN_PROFILES: the u32 casts are exact.)
        (p >= 0.0 && p < self.n_profiles as u32 as f64).then_some(p as u32 as usize)
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
        let n = self.distances_m.len();
        let (ha, hb) = (
            &self.ray_grid_heights[i * n..(i + 1) * n],
            &self.ray_grid_heights[j1 * n..(j1 + 1) * n],
        );
        let (ea, eb) = (fan.ray_end(i), fan.ray_end(j1));
        let tf = t as f32;
        let height = |j: usize| {
            let (x, y) = (ha[j], hb[j]);
            let h = if !(x.is_nan() || y.is_nan()) {
                x + (y - x) * tf
            } else if t >= 0.5 {
                y
            } else {
                x
            };
            (!h.is_nan()).then_some(f64::from(h))
        };
        let nb = self.n_blocks;
        let (ma, mb) = (
            &self.ray_block_min[i * nb..(i + 1) * nb],
            &self.ray_block_min[j1 * nb..(j1 + 1) * nb],
        );
        let end = if t >= 0.5 { eb } else { ea };
        let mut hit = self.march(p, 0, height, |b| ma[b].min(mb[b]), end)?;
        if self.frame.scale_heights_m.is_some() {
            let c = self.traced.interval(hit.distance_m);
            let density = |k: usize| self.density_in(k, fan.ray_heights(k), c, hit);
            hit.density_paths_m = match (density(i), density(j1)) {
                (Some(x), Some(y)) => Some([0, 1].map(|c| x[c] + (y[c] - x[c]) * t)),
                (x, y) => x.or(y),
            };
        }
        Some(hit)
    }

    /// Density-weighted lengths along fan ray `i` (its traced `heights`) to `hit`, in traced
    /// interval `c` ([`TracedGrid::interval`] of its distance): its sum to the traced distance
    /// before the hit, then linear to the next one, or (past its last traced height) the piece
    /// from there to the hit point.
    #[inline]
    fn density_in(
        &self,
        i: usize,
        heights: &[Option<f64>],
        c: usize,
        hit: TerrainHit,
    ) -> Option<[f64; 2]> {
        let m = self.traced.traced_m.len();
        let sums = &self.ray_density[i * m..(i + 1) * m];
        self.interpolated_density(sums, heights, c, hit)
    }

    /// [`Self::density_in`] on the sums `sums` of one ray, the hit in traced interval `c`.
    #[inline]
    fn interpolated_density(
        &self,
        sums: &[[f32; 2]],
        heights: &[Option<f64>],
        c: usize,
        hit: TerrainHit,
    ) -> Option<[f64; 2]> {
        let t = &self.traced.traced_m;
        let s0 = sums[c].map(f64::from);
        if s0[0].is_nan() {
            return None;
        }
        if c + 1 < t.len() && !sums[c + 1][0].is_nan() {
            let s1 = sums[c + 1].map(f64::from);
            let w = ((hit.distance_m - t[c]) / (t[c + 1] - t[c])).clamp(0.0, 1.0);
            return Some([0, 1].map(|k| s0[k] + (s1[k] - s0[k]) * w));
        }
        let scales = self.frame.scale_heights_m?;
        let start = (t[c], heights[c]?);
        let piece = piece_density(
            start,
            (hit.distance_m, hit.height_m),
            self.frame.earth_radius_m,
            scales,
        );
        Some([s0[0] + piece[0], s0[1] + piece[1]])
    }

    /// As [`Self::hit`] for a ray traced on its own: `heights` at [`Self::traced`]'s distances
    /// (stride 1: every grid distance) and its end.
    pub(super) fn hit_traced(
        &self,
        offset_rad: f64,
        heights: &[Option<f64>],
        end: FanEnd,
    ) -> Option<TerrainHit> {
        let p = self.profile(offset_rad)?;
        let tr = &self.traced;
        let mut hit = self.march(
            p,
            0,
            |j| tr.height(heights, end, j),
            |_| f32::NEG_INFINITY,
            end,
        )?;
        if let Some(scales) = self.frame.scale_heights_m {
            let f = &self.frame;
            let sums = cumulative_density(
                &tr.traced_m,
                heights,
                f.camera_height_m,
                f.earth_radius_m,
                scales,
            );
            let c = tr.interval(hit.distance_m);
            hit.density_paths_m = self.interpolated_density(&sums, heights, c, hit);
        }
        Some(hit)
    }

    /// Where a ray the sea reflects at ground distance `from_m` (leaving it at `elevation_rad`,
    /// its heights from the sea fan `fan`) meets the ground along the profile at azimuth offset
    /// `offset_rad`. A ray that stays above the profile's highest point beyond the first land
    /// is rejected at once; blocks are skipped where the ray stays above their highest point.
    #[inline]
    pub(super) fn hit_reflected(
        &self,
        offset_rad: f64,
        fan: &SeaFan,
        elevation_rad: f64,
        from_m: f64,
    ) -> Option<TerrainHit> {
        let d = &self.distances_m;
        if from_m.is_nan() || from_m >= d[d.len() - 1] {
            return None;
        }
        let p = self.profile(offset_rad)?;
        let top = f64::from(self.profile_max[p]);
        if fan.min_height_beyond(elevation_rad, d[0] - from_m) > top {
            return None;
        }
        let from = d.partition_point(|&x| x <= from_m);
        let sea_ray = fan.ray(elevation_rad)?;
        self.march(
            p,
            from,
            |j| sea_ray.height(d[j] - from_m),
            |b| sea_ray.min_height_beyond(d[b * BLOCK] - from_m) as f32,
            FanEnd::Lost,
        )
    }

    /// The highest elevation in [`e_lo`, `e_hi`] (rad) at which a ray the sea reflects at
    /// ground distance `from_m` (its heights from the sea fan `fan`) meets the ground along the
    /// profile at azimuth offset `offset_rad`; `None` if the ray at `e_lo` meets none. Where
    /// the sea fan's rays keep their order (a higher ray is higher at every range) every ray
    /// below it meets the ground too. The lowest ray not yet known to clear the ground is
    /// raised, at each ground point it does not clear, to the ray that just clears that point
    /// ([`SeaFan::rise_above`], exact between the fan's rays), so the answer moves continuously
    /// with `from_m`. Before the profile's first land only its [`Self::reflection_candidates`]
    /// are looked at; from a sea point within the land's distances, every point beyond it
    /// (blocks the ray stays above skipped).
    pub(super) fn reflected_cover(
        &self,
        offset_rad: f64,
        fan: &SeaFan,
        from_m: f64,
        (e_lo, e_hi): (f64, f64),
    ) -> Option<f64> {
        let d = &self.distances_m;
        let n = d.len();
        if from_m.is_nan() || from_m >= d[n - 1] {
            return None;
        }
        let p = self.profile(offset_rad)?;
        if fan.min_height_beyond(e_lo, d[0] - from_m) > f64::from(self.profile_max[p]) {
            return None;
        }
        let z = &self.profiles[p * n..(p + 1) * n];
        let mut low = LowestRay {
            fan,
            from_m,
            e_hi,
            e: e_lo,
            ray: fan.ray(e_lo)?,
            top: None,
        };
        let candidates = &self.candidates[self.candidate_start[p]..self.candidate_start[p + 1]];
        match candidates.first() {
            Some(&first) if d[first as usize] > from_m => {
                for &j in candidates {
                    let j = j as usize;
                    if !low.clear(d[j], z[j])? {
                        break;
                    }
                }
            }
            _ => {
                let zmax = &self.block_max[p * self.n_blocks..(p + 1) * self.n_blocks];
                let from = d.partition_point(|&x| x <= from_m);
                'blocks: for (b, &block_top) in zmax.iter().enumerate().skip(from / BLOCK) {
                    if low.ray.min_height_beyond(d[b * BLOCK] - from_m) as f32 > block_top {
                        continue;
                    }
                    for j in (b * BLOCK).max(from)..=((b + 1) * BLOCK).min(n - 1) {
                        if !low.clear(d[j], z[j])? {
                            break 'blocks;
                        }
                    }
                }
            }
        }
        low.top
    }

    /// Per profile, the ground points that can bound what a reflected ray from the sea before
    /// the profile's first land sees: the vertices of the upper convex hulls of (d, z − d²/2R′)
    /// for R′ = 1, 4/3 and 2 Earth radii. A ray from the sea at distance d₀ that rises as
    /// d²/2R′ over the sea meets ground point (d, z) when it leaves below an elevation that is
    /// the slope from (d₀, −d₀²/2R′) to (d, z − d²/2R′) plus d₀/R′, so the highest such
    /// elevation is reached at a hull vertex; the three radii cover rays bent less and more than
    /// the standard atmosphere's. For other rays (a duct) a point between vertices may bound
    /// the view a little higher: the cover is then a little low, still continuous. Ascending,
    /// the first the profile's first land.
    fn reflection_candidates(&self, p: usize) -> Vec<u32> {
        let n = self.distances_m.len();
        let z = &self.profiles[p * n..(p + 1) * n];
        let land: Vec<usize> = (0..n).filter(|&j| z[j] > f32::NEG_INFINITY).collect();
        let Some(&first) = land.first() else {
            return Vec::new();
        };
        let radius = self.frame.earth_radius_m;
        let mut out = vec![first as u32];
        // The hull's vertices, with their points.
        let mut hull: Vec<(usize, (f64, f64))> = Vec::new();
        for scale in [1.0, 4.0 / 3.0, 2.0] {
            let r = scale * radius;
            let point = |j: usize| {
                let d = self.distances_m[j];
                (d, f64::from(z[j]) - d * d / (2.0 * r))
            };
            hull.clear();
            for &j in &land {
                let c = point(j);
                while hull.len() >= 2 {
                    let (a, b) = (hull[hull.len() - 2].1, hull[hull.len() - 1].1);
                    // Drop b unless a → b → c turns clockwise (b above the chord a–c).
                    if (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0) >= 0.0 {
                        hull.pop();
                    } else {
                        break;
                    }
                }
                hull.push((j, c));
            }
            out.extend(hull.iter().map(|&(j, _)| j as u32));
        }
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Prepare [`Self::reflected_cover`] (the candidates of every profile; a frame whose sea
    /// mirrors the terrain blurred by waves needs them).
    pub(super) fn prepare_reflections(&mut self) {
        let lists: Vec<Vec<u32>> = (0..self.n_profiles)
            .into_par_iter()
            .map(|p| self.reflection_candidates(p))
            .collect();
        self.candidate_start = Vec::with_capacity(lists.len() + 1);
        self.candidate_start.push(0);
        self.candidates.clear();
        for list in lists {
            self.candidates.extend(list);
            self.candidate_start.push(self.candidates.len());
        }
    }

    /// Whether a ray the sea reflects at ground distance `from_m`, leaving it at
    /// `elevation_rad`, may meet the ground anywhere in the frame (it comes below the highest
    /// ground beyond the first land).
    #[inline]
    pub(super) fn may_be_reflected(&self, fan: &SeaFan, elevation_rad: f64, from_m: f64) -> bool {
        let d = &self.distances_m;
        from_m < d[d.len() - 1]
            && fan.min_height_beyond(elevation_rad, d[0] - from_m) <= self.max_height_m
    }

    /// March profile `p` with a ray's heights `height(j)` (block minima `block_min(b)`, which
    /// may be −∞ to force a look) from grid point `from` to the first grid interval where the
    /// ray meets the ground.
    #[inline]
    fn march(
        &self,
        p: usize,
        from: usize,
        height: impl Fn(usize) -> Option<f64>,
        block_min: impl Fn(usize) -> f32,
        end: FanEnd,
    ) -> Option<TerrainHit> {
        let n = self.distances_m.len();
        let z = &self.profiles[p * n..(p + 1) * n];
        let zmax = &self.block_max[p * self.n_blocks..(p + 1) * self.n_blocks];
        let mut prev: Option<(f64, f64)> = None; // (h, z) at the previous grid point
        for (b, &block_top) in zmax.iter().enumerate().skip(from / BLOCK) {
            // A block without ground holds no hit; a ray that ends in it has no height at the
            // next block's first point either, so the march ends there as it would here.
            if block_top == f32::NEG_INFINITY || block_min(b) > block_top {
                prev = None; // the block's last point is above ground: restart there
                continue;
            }
            let start = b * BLOCK;
            let stop = ((b + 1) * BLOCK).min(n - 1);
            let first = if prev.is_some() {
                start + 1
            } else {
                start.max(from)
            };
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
        let (distance_m, height_m) = match prev {
            Some((hp, zp)) if zp.is_finite() => {
                let (fp, fj) = (hp - zp, hj - zj);
                let s = (fp / (fp - fj)).clamp(0.0, 1.0);
                (d[j - 1] + (d[j] - d[j - 1]) * s, zp + (zj - zp) * s)
            }
            // The ground starts at j (a coast) or nothing is known before it.
            _ => (d[j], zj),
        };
        TerrainHit {
            distance_m,
            height_m,
            density_paths_m: None,
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

    /// Colour (linear RGB) of the ground hit at `hit` by a sample at azimuth offset `offset_rad`
    /// (on the great circle of its profile, where the hit was found).
    /// The palette's lit colour, under the orthophoto's where one covers the point (the
    /// photograph's own colours, not relit: it carries the light it was taken in).
    pub(super) fn colour(&self, hit: TerrainHit, offset_rad: f64) -> [f64; 3] {
        let t = self.terrain;
        let p = self.profile(offset_rad);
        if t.orthophoto.is_none() {
            let grid = p.and_then(|p| self.hit_grid(p, hit.distance_m));
            let lit = self.lit_colour(hit.height_m, grid);
            return lit.map(|c| c * self.frame.brightness);
        }
        let radius = self.frame.earth_radius_m;
        let lat_lon = p.map(|p| self.circles[p].lat_lon_deg(hit.distance_m, radius));
        let grid = lat_lon.and_then(|(lat, lon)| t.dem.grid_position(lat, t.wrap_lon(lon)));
        let lit = self.lit_colour(hit.height_m, grid);
        let ground = match (&t.orthophoto, lat_lon) {
            (Some(photo), Some((lat, lon))) => {
                let [r, g, b, a] = photo.rgba_at(lat, lon).map(f64::from);
                let under = 1.0 - a;
                [r + under * lit[0], g + under * lit[1], b + under * lit[2]]
            }
            _ => lit,
        };
        ground.map(|c| c * self.frame.brightness)
    }

    /// The model's fractional (row, column) of the point at ground distance `distance_m` along
    /// profile `p`: linear between the grid positions of the grid distances around it (the
    /// great circle's curvature in latitude and longitude over one grid step moves it by
    /// about a millionth of a cell; the unit tests bound it). `None` off the model.
    #[inline]
    fn hit_grid(&self, p: usize, distance_m: f64) -> Option<(f64, f64)> {
        let n = self.distances_m.len();
        let x =
            ((distance_m - self.distances_m[0]) * self.grid_inv_step).clamp(0.0, (n - 1) as f64);
        // (At most MAX_TERRAIN_DISTANCES: the u32 casts are exact.)
        let j = (x as u32 as usize).min(n - 2);
        let s = x - j as f64;
        let rc = &self.grid_rc[p * n + j..p * n + j + 2];
        let [r, c] = [0, 1].map(|k| rc[0][k] + (rc[1][k] - rc[0][k]) * s);
        (!(r.is_nan() || c.is_nan())).then_some((r, c))
    }

    /// The palette's lit colour of ground at `height_m` at the
    /// model's fractional (row, column) `grid` (flat where unknown).
    #[inline]
    fn lit_colour(&self, height_m: f64, grid: Option<(f64, f64)>) -> [f64; 3] {
        let t = self.terrain;
        let radius = self.frame.earth_radius_m;
        let (tan_slope, normal) = grid
            .and_then(|(r, c)| t.dem.tan_slope_at_grid(&t.gradients, r, c, radius))
            .unwrap_or((0.0, [0.0, 0.0, 1.0]));
        // The palette's albedo (Palette::albedo), the slope's angle taken only near the ice
        // slope.
        let palette = &t.palette;
        let albedo = if palette.is_ice(tan_slope, self.ice_tan_below) {
            palette.ice_rgb
        } else if height_m >= palette.snow_line_m {
            palette.snow_rgb
        } else {
            palette.rock_rgb
        };
        // The normal is in the hit point's east/north/up; the light's direction is taken in the
        // same local frame (the model spans a few degrees at most).
        palette.lit(albedo, normal)
    }
}

/// The profiles z(dⱼ) along `n_profiles` azimuths `az_step` apart from offset `az_lo` (in
/// parallel, collected in order), `distances_m.len()` per azimuth; −∞ where there is no ground.
fn sample_profiles(
    terrain: &Terrain,
    frame: &TerrainFrame,
    distances_m: &[f64],
    az_lo: f64,
    az_step: f64,
    n_profiles: usize,
) -> (Vec<f32>, Vec<[f64; 2]>) {
    let radius = frame.earth_radius_m;
    // The angles along the circles are the same for every profile.
    let angles: Vec<(f64, f64)> = distances_m
        .iter()
        .map(|&d| (d / radius).sin_cos())
        .collect();
    let angles = &angles;
    (0..n_profiles)
        .into_par_iter()
        .flat_map_iter(|p| {
            let circle = terrain.great_circle(frame.heading_rad + az_lo + p as f64 * az_step);
            angles.iter().map(move |&angle| {
                let grid = circle.grid_at_angle(terrain, angle);
                let z = grid
                    .and_then(|(r, c)| terrain.dem.height_at_grid(r, c))
                    .filter(|&z| z > 0.0)
                    .map_or(f32::NEG_INFINITY, |z| z as f32);
                (z, grid.map_or([f64::NAN; 2], |(r, c)| [r, c]))
            })
        })
        .unzip()
}

impl TerrainView<'_> {
    /// Whether a camera sample at apparent elevation `alpha` may meet the terrain (through
    /// the fan; exact mode: always).
    #[inline]
    pub(super) fn may_hit(&self, alpha: f64) -> bool {
        alpha >= self.may_hit_rad.0 && alpha <= self.may_hit_rad.1
    }
}

impl SceneObject for TerrainView<'_> {
    fn fixed_distance_m(&self) -> Option<f64> {
        None
    }

    /// The ground a camera ray meets (through the fan, or along its own traced ray), or a ray
    /// the sea reflects (through the sea fan).
    #[inline]
    fn meet(&self, ray: &SampleRay<'_>) -> Option<Meet> {
        let hit = match ray.along {
            RayAlong::Fan { alpha, .. } => {
                if !self.may_hit(alpha) {
                    return None;
                }
                self.hit(alpha, ray.azimuth_offset_rad())?
            }
            RayAlong::Traced {
                terrain: Some((heights, end)),
                ..
            } => self.hit_traced(ray.azimuth_offset_rad(), heights, end)?,
            RayAlong::Reflected {
                fan,
                elevation_rad,
                from_m,
                ..
            } => self.hit_reflected(ray.azimuth_offset_rad(), fan, elevation_rad, from_m)?,
            RayAlong::Traced { terrain: None, .. } => return None,
        };
        Some(Meet {
            distance_m: hit.distance_m,
            height_m: hit.height_m,
            u: 0.0,
            density_paths_m: hit.density_paths_m,
        })
    }

    /// The ground's colour through the air between (with the sky's aerial perspective: along
    /// the ray's path where the meet carries its path integrals, else the straight chord; for a
    /// ray the sea reflects, along its path from the sea to the ground, summed in the sea fan:
    /// the sea's own haze is added after); opaque.
    fn shade(&self, ray: &SampleRay<'_>, meet: &Meet, shader: &Shader<'_>) -> ([f64; 3], f64) {
        let hit = TerrainHit {
            distance_m: meet.distance_m,
            height_m: meet.height_m,
            density_paths_m: meet.density_paths_m,
        };
        let mut ground = self.colour(hit, ray.azimuth_offset_rad());
        if let RayAlong::Reflected {
            fan,
            elevation_rad,
            from_m,
            ..
        } = ray.along
        {
            if let Some(aerial) = &shader.aerial {
                let range_m = hit.distance_m - from_m;
                let tau = match fan.density_paths_m(elevation_rad, range_m) {
                    Some(d) => aerial.extinction.path_optical_depth(d),
                    None => aerial.extinction.chord_optical_depth(
                        aerial.earth_radius_m,
                        0.0,
                        hit.height_m,
                        range_m,
                    ),
                };
                ground = aerial.extinction.attenuate(ground, 1.0, tau);
            }
        } else if let Some(aerial) = &shader.aerial {
            let tau = match hit.density_paths_m {
                Some(d) => aerial.extinction.path_optical_depth(d),
                None => aerial.extinction.chord_optical_depth(
                    aerial.earth_radius_m,
                    aerial.camera_height_m,
                    hit.height_m,
                    hit.distance_m,
                ),
            };
            ground = aerial.extinction.attenuate(ground, 1.0, tau);
        }
        (ground, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn traced_grid_maps_every_grid_distance_between_traced_ones() {
        let grid: Vec<f64> = (0..23).map(|j| 5_000.0 + 100.0 * j as f64).collect();
        let tg = TracedGrid::new(&grid, 4);
        // Approach points ≤ 2 km apart before 5 km: 1.67 and 3.33 km.
        assert_eq!(tg.traced_m.len(), 2 + 6 + 1);
        assert!((tg.traced_m[0] - 5_000.0 / 3.0).abs() < 1e-9);
        // A ray with heights h = d / 100 at the traced distances: linear everywhere.
        let heights: Vec<Option<f64>> = tg.traced_m.iter().map(|d| Some(d / 100.0)).collect();
        let end = FanEnd::Sky { elevation_rad: 0.0 };
        for (j, d) in grid.iter().enumerate() {
            let h = tg.height(&heights, end, j).unwrap();
            assert!((h - d / 100.0).abs() < 1e-9, "{j}: {h}");
        }
        // Landing in the sea at 6.05 km after its last height at 5.8 km: down to 0 there.
        let mut landed = heights.clone();
        for h in landed.iter_mut().skip(5) {
            *h = None;
        }
        let end = FanEnd::Ground {
            distance_m: 6_050.0,
            grazing_rad: 0.01,
        };
        let at = |j: usize| tg.height(&landed, end, j);
        assert!((at(8).unwrap() - 58.0).abs() < 1e-9);
        assert!((at(10).unwrap() - 58.0 * 50.0 / 250.0).abs() < 1e-9);
        assert_eq!(at(11), None);
    }

    /// A 3″ model of 0.3° × 0.4° south of an observer at 22.45° N, 159.5° W: a ridge of
    /// ripples on a cone (steep and varied slopes), and the view of it looking south over 8°.
    fn ripple_view_terrain() -> Terrain {
        use crate::scene::terrain::{Dem, Palette};
        let (rows, cols) = (361, 481);
        let step = 1.0 / 1200.0;
        let heights: Vec<f32> = (0..rows * cols)
            .map(|i| {
                let (r, c) = ((i / cols) as f64, (i % cols) as f64);
                let cone = 1500.0 - 6.0 * (r - 180.0).hypot(c - 240.0);
                let ripples = 80.0 * (r * 0.37).sin() * (c * 0.23).cos();
                (cone + ripples).max(-1.0) as f32
            })
            .collect();
        let dem = Dem::new(rows, cols, (22.3, -159.7), (step, step), heights).unwrap();
        let mut palette = Palette::default_palette();
        palette.snow_line_m = 900.0;
        Terrain::new("ripples.hgt".into(), dem, (22.45, -159.5), palette, false)
    }

    #[test]
    fn hit_grid_positions_and_colours_are_the_great_circles_within_a_millionth_of_a_cell() {
        let terrain = ripple_view_terrain();
        let radius = 6_371_000.0;
        let tracer = crate::render::ray_model::StraightRays::new(radius).unwrap();
        let half = 4f64.to_radians();
        let frame = TerrainFrame {
            camera_height_m: 80.0,
            heading_rad: std::f64::consts::PI,
            earth_radius_m: radius,
            azimuth_span_rad: Some((-half, half)),
            elevation_range_rad: (-0.01, 0.05),
            pixel_rad: 2.0 * half / 1920.0,
            tolerance_px: 0.25,
            max_depth: 6,
            brightness: 1.0,
            scale_heights_m: None,
        };
        let view = TerrainView::new(&terrain, &tracer, frame, true).expect("land in view");
        let d = &view.distances_m;
        let (first, last) = (d[0], d[d.len() - 1]);
        let (mut worst_cell, mut worst_colour, mut compared) = (0.0f64, 0.0f64, 0usize);
        for p in (0..view.n_profiles).step_by(37) {
            for k in 0..=4000 {
                let distance = first + (last - first) * k as f64 / 4000.0 + 0.123;
                let exact = view.circles[p].grid_at(&terrain, distance, radius);
                let table = view.hit_grid(p, distance.min(last));
                let (Some((r0, c0)), Some((r1, c1))) = (exact, table) else {
                    continue;
                };
                worst_cell = worst_cell.max((r1 - r0).abs()).max((c1 - c0).abs());
                let Some(z) = terrain.dem.height_at_grid(r0, c0) else {
                    continue;
                };
                let (a, b) = (
                    view.lit_colour(z, Some((r0, c0))),
                    view.lit_colour(z, Some((r1, c1))),
                );
                for ch in 0..3 {
                    worst_colour = worst_colour.max((a[ch] - b[ch]).abs() / a[ch]);
                }
                compared += 1;
            }
        }
        assert!(compared > 100_000, "{compared} points compared");
        // The curvature of the great circle in latitude and longitude over one grid step: here
        // 1e-7 of a cell at worst, the colour 6e-9 (relative), so about one f32 rounding of a
        // pixel's radiance at most.
        assert!(
            worst_cell < 1e-6,
            "grid position off by {worst_cell:e} cells"
        );
        assert!(
            worst_colour < 1e-7,
            "colour off by {worst_colour:e} (relative)"
        );
    }

    #[test]
    fn piece_density_is_the_integral_of_the_exponential_profile() {
        // A level piece: length × e^(−h/H); a climbing one against a fine midpoint sum.
        let r = 6.371e6;
        let level = piece_density((0.0, 500.0), (1_000.0, 500.0), r, [8_000.0, 1_000.0]);
        let stretch = 1.0 + 500.0 / r;
        assert!((level[1] - 1_000.0 * stretch * (-0.5f64).exp()).abs() < 1e-9);
        let got = piece_density((0.0, 0.0), (1_000.0, 300.0), r, [8_000.0, 1_000.0]);
        let n = 100_000;
        let length = (1_000.0 * (1.0 + 150.0 / r)).hypot(300.0);
        for (k, scale) in [8_000.0, 1_000.0].into_iter().enumerate() {
            let sum: f64 = (0..n)
                .map(|i| (-(300.0 * (i as f64 + 0.5) / n as f64) / scale).exp())
                .sum::<f64>()
                * length
                / n as f64;
            assert!(
                (got[k] - sum).abs() < 1e-6 * sum,
                "{k}: {} vs {sum}",
                got[k]
            );
        }
    }
}
