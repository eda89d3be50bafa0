//! Stage 5b — render. In: a [`Scene`] and a [`RayTracer`]. Out: a [`Film`] of linear f32 RGBA
//! radiance (unit: the white horizon sky, see [`crate::scene::sky`]).
//!
//! Spherical symmetry makes the ray depend only on its apparent elevation, so the renderer traces
//! one fan of elevations for the whole frame ([`elevation_fan`], refined adaptively where the
//! transfer curve bends sharply; its documentation states the error bound) and shades every pixel
//! sample by interpolating in that fan: per sample, an elevation (one `atan2`; the azimuth only
//! when a card or the sun may be met), an O(1) fan lookup,
//! a few comparisons per card in view, and the sky/sea/sun model. Exact mode instead calls the
//! tracer for every sample (no fan, no interpolation): it validates the fast path and is the
//! benchmark baseline.
//!
//! Samples: n×n stratified, jittered by a hash of (pixel, sample) — no global random state, so the
//! image is the same whatever the thread count (rows are rendered in parallel, each pixel on its
//! own). With one sample per pixel the pixel centre is used.

pub mod elevation_fan;
pub mod fan;
pub mod traced;

use std::io::IsTerminal;
use std::sync::atomic::{AtomicU64, Ordering};

use indicatif::{ParallelProgressIterator, ProgressBar, ProgressStyle};
use rayon::prelude::*;

use crate::scene::camera::CameraFrame;
use crate::scene::{Scene, Sky, Sun, Texture, samples_per_pixel_root};
pub use elevation_fan::{ElevationFan, FanSpec};
pub use fan::{ConstantCurvatureRays, FanEnd, FanRay, RayTracer, StraightRays};
pub use traced::{CurvedRays, ExactRays, PrepareError, prepare_tracer};

/// How to render.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// Trace every pixel sample itself (no fan).
    pub exact: bool,
    /// Override the scene's samples per pixel (a square number).
    pub samples_per_pixel: Option<u32>,
    /// No progress bar.
    pub quiet: bool,
    /// Fan refinement tolerance: allowed feature misplacement (pixels).
    pub tolerance_px: f64,
    /// Cap on fan bisections per base interval.
    pub max_refine_depth: u32,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            exact: false,
            samples_per_pixel: None,
            quiet: false,
            tolerance_px: 0.1,
            max_refine_depth: 12,
        }
    }
}

/// Rendering failed before it started (bad options).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    /// Samples per pixel must be a square number from 1 to
    /// [`MAX_SAMPLES_PER_PIXEL`](crate::scene::MAX_SAMPLES_PER_PIXEL).
    #[error("samples per pixel must be a square number (1, 4, 9, 16, …, 1024), got {0}")]
    SamplesPerPixel(u32),
    /// The tolerance must be finite and > 0.
    #[error("fan tolerance must be > 0 pixels, got {0}")]
    Tolerance(f64),
}

/// Counters from one render.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RenderStats {
    /// Rays in the elevation fan (0 in exact mode).
    pub fan_rays: usize,
    /// Deepest fan bisection level used.
    pub fan_depth: u32,
    /// Rays traced per sample in exact mode.
    pub sample_rays: u64,
    /// Samples whose shading was not finite and were replaced by the fallback colour (should be 0).
    pub non_finite_samples: u64,
    /// Cards in view.
    pub cards_in_view: usize,
}

/// A rendered image: linear RGBA f32, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Film {
    /// Width (pixels).
    pub width: u32,
    /// Height (pixels).
    pub height: u32,
    /// Linear RGBA (radiance in horizon-sky units; alpha is 1).
    pub pixels: Vec<[f32; 4]>,
    /// Counters.
    pub stats: RenderStats,
}

impl Film {
    /// Pixel at column `x`, row `y`.
    ///
    /// # Panics
    /// If (`x`, `y`) is outside the film.
    pub fn pixel(&self, x: u32, y: u32) -> [f32; 4] {
        self.pixels[(y * self.width + x) as usize]
    }
}

/// A card prepared for shading.
struct ViewCard<'a> {
    distance_index: usize,
    azimuth_rad: f64,
    half_width_rad: f64,
    base_m: f64,
    top_m: f64,
    height_m: f64,
    texture: &'a Texture,
}

/// A smooth function of one angle, tabulated uniformly and interpolated linearly (the sky and the
/// sea are evaluated per sample; a table replaces a `powf` and three `exp` by one lookup).
struct AngleTable {
    start: f64,
    inv_step: f64,
    values: Vec<[f64; 3]>,
}

impl AngleTable {
    /// Largest spacing of the entries (rad): sky and sea vary on scales of a degree near the
    /// horizon; at 90° / 8191 the linear-interpolation error stays below 1e-4 of the value (unit
    /// tests check it). A range wider than 90° gets [`Self::MAX_ENTRIES`] (at most 180° / 8191).
    const MAX_STEP: f64 = std::f64::consts::FRAC_PI_2 / 8191.0;
    /// Fewest entries (a narrow mirage frame needs few; this keeps them finer still).
    const MIN_ENTRIES: usize = 256;
    /// Most entries.
    const MAX_ENTRIES: usize = 8192;

    /// Tabulate `f` on [`lo`, `hi`] (entries computed in parallel, collected in order: the
    /// table does not depend on the thread count).
    fn new(lo: f64, hi: f64, f: impl Fn(f64) -> [f64; 3] + Sync) -> Self {
        let wanted = ((hi - lo) / Self::MAX_STEP).ceil();
        let n = if wanted.is_finite() {
            (wanted as usize + 1).clamp(Self::MIN_ENTRIES, Self::MAX_ENTRIES)
        } else {
            Self::MAX_ENTRIES
        };
        let step = ((hi - lo) / (n - 1) as f64).max(1e-300);
        Self {
            start: lo,
            inv_step: 1.0 / step,
            values: (0..n)
                .into_par_iter()
                .with_min_len(512)
                .map(|i| f(lo + i as f64 * step))
                .collect(),
        }
    }

    #[inline]
    fn at(&self, x: f64) -> [f64; 3] {
        let last = self.values.len() - 1;
        let p = ((x - self.start) * self.inv_step).clamp(0.0, last as f64);
        let p = if p.is_nan() { 0.0 } else { p };
        let i = (p as usize).min(last - 1);
        let t = p - i as f64;
        let (a, b) = (self.values[i], self.values[i + 1]);
        [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * t)
    }
}

/// Everything shading needs, resolved once per frame.
struct Shader<'a> {
    cards: Vec<ViewCard<'a>>,
    sky: Sky,
    sky_table: AngleTable,
    sea_table: AngleTable,
    sun: Option<Sun>,
    fallback: [f64; 3],
}

#[inline]
fn wrap_pi(x: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let y = (x + std::f64::consts::PI).rem_euclid(two_pi) - std::f64::consts::PI;
    if y.is_finite() { y } else { 0.0 }
}

impl Shader<'_> {
    /// Radiance of a sample looking along direction vector `dir` (apparent elevation `alpha`)
    /// along a ray with `heights` at the card distances and end `end`. The azimuth (an `atan2`)
    /// is computed only when a card's height range or the sun's elevation band is met.
    #[inline]
    fn shade(&self, alpha: f64, dir: [f64; 3], heights: &[Option<f64>], end: FanEnd) -> [f64; 3] {
        let mut acc = [0.0f64; 3];
        let mut transmit = 1.0f64;
        let mut azimuth_cache: Option<f64> = None;
        let mut azimuth = || *azimuth_cache.get_or_insert_with(|| CameraFrame::azimuth_of(dir));
        for card in &self.cards {
            let Some(h) = heights[card.distance_index] else {
                continue;
            };
            if h < card.base_m || h > card.top_m {
                continue;
            }
            let mut offset = azimuth() - card.azimuth_rad;
            if offset.abs() > std::f64::consts::PI {
                offset = wrap_pi(offset);
            }
            if offset.abs() > card.half_width_rad {
                continue;
            }
            let u = 0.5 + 0.5 * offset / card.half_width_rad;
            let v = (card.top_m - h) / card.height_m;
            let t = card.texture.sample(u, v);
            for c in 0..3 {
                acc[c] += transmit * t[c] as f64;
            }
            transmit *= 1.0 - t[3] as f64;
            if transmit < 1e-6 {
                return acc;
            }
        }
        let background = match end {
            FanEnd::Ground { grazing_rad, .. } => self.sea_table.at(grazing_rad),
            FanEnd::Sky { elevation_rad } => {
                let mut l = self.sky_table.at(alpha);
                // The elevation test is the disc's own quick reject, done before the azimuth.
                if let Some(sun) = &self.sun
                    && (elevation_rad - sun.elevation_rad).abs() <= 0.5 * sun.angular_diameter_rad
                {
                    let disc = sun.disc(azimuth(), elevation_rad);
                    if disc > 0.0 {
                        let t = self.sky.transmittance(alpha);
                        for c in 0..3 {
                            l[c] += disc * t[c];
                        }
                    }
                }
                l
            }
            FanEnd::Lost => self.fallback,
        };
        for c in 0..3 {
            acc[c] += transmit * background[c];
        }
        acc
    }
}

/// Deterministic hash of a 64-bit key → [0, 1) (splitmix64 finaliser).
#[inline]
fn unit_hash(key: u64) -> f64 {
    let mut z = key.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// Directions (azimuth, elevation) through 257 points on each edge of the film (corners
/// included): the frame's border, where both extremes of azimuth and elevation lie (apart from the
/// zenith and nadir).
fn border_directions(
    frame: &CameraFrame,
    width: u32,
    height: u32,
) -> impl Iterator<Item = (f64, f64)> + '_ {
    let (w, h) = (width as f64, height as f64);
    let steps = 256;
    (0..=steps).flat_map(move |s| {
        let t = s as f64 / steps as f64;
        [(t * w, 0.0), (t * w, h), (0.0, t * h), (w, t * h)].map(|(x, y)| frame.direction(x, y))
    })
}

/// The frame's range of apparent elevations (rad), from its border (plus the zenith or nadir when
/// inside the frame), widened by one pixel.
fn elevation_range(frame: &CameraFrame, width: u32, height: u32, pixel_rad: f64) -> (f64, f64) {
    let (w, h) = (width as f64, height as f64);
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for (_, e) in border_directions(frame, width, height) {
        lo = lo.min(e);
        hi = hi.max(e);
    }
    // An interior extreme exists only at the zenith or nadir: are they inside the frame?
    let inside = |p: Option<(f64, f64)>| {
        p.is_some_and(|(x, y)| (0.0..=w).contains(&x) && (0.0..=h).contains(&y))
    };
    if inside(frame.project([0.0, 0.0, 1.0])) {
        hi = std::f64::consts::FRAC_PI_2;
    }
    if inside(frame.project([0.0, 0.0, -1.0])) {
        lo = -std::f64::consts::FRAC_PI_2;
    }
    let half_pi = std::f64::consts::FRAC_PI_2;
    (
        (lo - pixel_rad).max(-half_pi),
        (hi + pixel_rad).min(half_pi),
    )
}

/// The frame's azimuth span relative to the heading (rad), or `None` if every azimuth is in view
/// (the frame reaches near the zenith or nadir).
fn azimuth_span(frame: &CameraFrame, width: u32, height: u32, heading: f64) -> Option<(f64, f64)> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for (a, e) in border_directions(frame, width, height) {
        if e.abs() > 80f64.to_radians() {
            return None;
        }
        let off = wrap_pi(a - heading);
        lo = lo.min(off);
        hi = hi.max(off);
    }
    Some((lo, hi))
}

/// Provenance for an EXR of `scene` rendered with `options` (scene hash, observer height,
/// wavelength, fan tolerance or "exact", samples per pixel).
pub fn provenance(scene: &Scene, options: &RenderOptions) -> crate::output::exr::ExrMetadata {
    let spp = options
        .samples_per_pixel
        .unwrap_or(scene.camera.samples_per_pixel);
    crate::output::exr::ExrMetadata {
        scene_hash: scene.hash_hex.clone(),
        observer_height_m: scene.camera.height_m,
        wavelength_nm: scene.atmosphere.wavelength_nm,
        tolerance_px: (!options.exact).then_some(options.tolerance_px),
        extra: vec![
            ("samples_per_pixel".into(), spp.to_string()),
            (
                "straight_rays".into(),
                scene.atmosphere.straight.to_string(),
            ),
            ("earth_radius_m".into(), scene.earth_radius_m.to_string()),
        ],
    }
}

/// Render `scene` through `tracer`.
pub fn render_scene(
    scene: &Scene,
    tracer: &dyn RayTracer,
    options: &RenderOptions,
) -> Result<Film, RenderError> {
    let spp = options
        .samples_per_pixel
        .unwrap_or(scene.camera.samples_per_pixel);
    let n = samples_per_pixel_root(spp).ok_or(RenderError::SamplesPerPixel(spp))?;
    if !(options.tolerance_px.is_finite() && options.tolerance_px > 0.0) {
        return Err(RenderError::Tolerance(options.tolerance_px));
    }
    let cam = &scene.camera;
    let frame = cam.frame();
    let pixel_rad = 1.0 / frame.focal_px;
    let (width, height) = (cam.width, cam.height);
    let radius = scene.earth_radius_m;

    // Cards in view (by azimuth), nearest first; the distances the tracer must report.
    let span = azimuth_span(&frame, width, height, cam.heading_rad);
    let mut order: Vec<usize> = (0..scene.cards.len()).collect();
    order.sort_by(|&a, &b| {
        scene.cards[a]
            .distance_m
            .total_cmp(&scene.cards[b].distance_m)
    });
    let mut distances_m: Vec<f64> = Vec::new();
    let mut max_top_m: Vec<f64> = Vec::new();
    let mut cards = Vec::new();
    for i in order {
        let c = &scene.cards[i];
        let ground_radius = radius * (c.distance_m / radius).sin();
        let half_width_rad = if ground_radius > 0.5 * c.width_m {
            (0.5 * c.width_m / ground_radius).min(std::f64::consts::PI)
        } else {
            std::f64::consts::PI
        };
        if let Some((lo, hi)) = span {
            let off = wrap_pi(c.azimuth_rad - cam.heading_rad);
            let pad = half_width_rad + 2.0 * pixel_rad;
            if off + pad < lo || off - pad > hi {
                continue;
            }
        }
        let top_m = c.base_m + c.height_m;
        if distances_m.last() != Some(&c.distance_m) {
            distances_m.push(c.distance_m);
            max_top_m.push(top_m);
        }
        let k = distances_m.len() - 1;
        max_top_m[k] = max_top_m[k].max(top_m);
        cards.push(ViewCard {
            distance_index: k,
            azimuth_rad: c.azimuth_rad,
            half_width_rad,
            base_m: c.base_m,
            top_m,
            height_m: c.height_m,
            texture: &c.texture,
        });
    }
    let elevations = elevation_range(&frame, width, height, pixel_rad);
    let (sky, sea) = (scene.sky, scene.sea);
    // The optical depths once per frame, not once per table entry (same values).
    let depths = sky.optical_depths();
    let need_sky_direction = scene.sun.is_some();
    let mut stats = RenderStats {
        cards_in_view: cards.len(),
        ..RenderStats::default()
    };

    // Samples at or above this elevation see only sky (no sun, above every card): shade them
    // from the sky table alone — the same result as the full path, without the fan lookup.
    let mut clear_sky_from = f64::INFINITY;
    let fan = if options.exact {
        None
    } else {
        let spec = FanSpec {
            camera_height_m: cam.height_m,
            distances_m: distances_m.clone(),
            max_top_m,
            need_sky_direction,
            sun_band_rad: scene.sun.map(|s| {
                let r = 0.5 * s.angular_diameter_rad + 2.0 * pixel_rad;
                (s.elevation_rad - r, s.elevation_rad + r)
            }),
            elevation_range_rad: elevations,
            // The smallest pixel of the frame (its corners, for a wide angle), so the fan's
            // sub-pixel bound holds everywhere, not only at the centre.
            pixel_rad: cam.min_pixel_angle_rad(),
            tolerance_px: options.tolerance_px,
            max_depth: options.max_refine_depth,
        };
        let fan = ElevationFan::build(tracer, &spec);
        if scene.sun.is_none() {
            clear_sky_from = fan.clear_sky_from(&spec.max_top_m);
        }
        stats.fan_rays = fan.len();
        stats.fan_depth = fan.max_depth_reached;
        Some(fan)
    };

    // The sea table spans grazing angles from 0 (where a NaN grazing angle is shaded) to the
    // steepest the frame can show: with a fan, the steepest fan ray (interpolation stays between
    // neighbours); per-sample tracing, 90°.
    let sea_hi = fan
        .as_ref()
        .and_then(ElevationFan::max_grazing_rad)
        .map_or(std::f64::consts::FRAC_PI_2, |g| {
            g.min(std::f64::consts::FRAC_PI_2)
        });
    let shader = Shader {
        cards,
        sky,
        sky_table: AngleTable::new(elevations.0, elevations.1, |e| {
            sky.radiance_with_depths(e, depths)
        }),
        sea_table: AngleTable::new(0.0, sea_hi, |g| {
            sea.radiance_with_sky_depths(g, &sky, depths)
        }),
        sun: scene.sun,
        // A lost (trapped) ray travels in the lowest air: show the horizon sky.
        fallback: scene.sky.radiance(0.0),
    };

    let bar = if options.quiet || !std::io::stderr().is_terminal() {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::new(height as u64);
        if let Ok(style) =
            ProgressStyle::with_template("{spinner} rendering [{bar:40}] {pos}/{len} rows ({eta})")
        {
            bar.set_style(style);
        }
        bar
    };

    let non_finite = AtomicU64::new(0);
    let mut pixels = vec![[0.0f32; 4]; width as usize * height as usize];
    let inv_samples = 1.0 / (n * n) as f64;
    let n_dist = distances_m.len();
    pixels
        .par_chunks_mut(width as usize)
        .enumerate()
        .progress_with(bar.clone())
        .for_each(|(y, row)| {
            let mut heights = vec![None; n_dist];
            for (x, px) in row.iter_mut().enumerate() {
                let mut acc = [0.0f64; 3];
                for s in 0..n * n {
                    let (jx, jy) = if n == 1 {
                        (0.5, 0.5)
                    } else {
                        let key = ((y as u64) << 40) ^ ((x as u64) << 16) ^ s as u64;
                        let (sx, sy) = ((s % n) as f64, (s / n) as f64);
                        (
                            (sx + unit_hash(2 * key)) / n as f64,
                            (sy + unit_hash(2 * key + 1)) / n as f64,
                        )
                    };
                    let dir = frame.direction_vector(x as f64 + jx, y as f64 + jy);
                    let alpha = CameraFrame::elevation_of(dir);
                    let c = match &fan {
                        Some(_) if alpha >= clear_sky_from => shader.sky_table.at(alpha),
                        Some(fan) => {
                            let end = fan.interpolate(alpha, &mut heights);
                            shader.shade(alpha, dir, &heights, end)
                        }
                        None => {
                            let mut ray =
                                tracer.trace(cam.height_m, alpha, &distances_m, need_sky_direction);
                            ray.heights_m.resize(n_dist, None);
                            shader.shade(alpha, dir, &ray.heights_m, ray.end)
                        }
                    };
                    let c = if c.iter().all(|v| v.is_finite()) {
                        c
                    } else {
                        non_finite.fetch_add(1, Ordering::Relaxed);
                        shader.fallback
                    };
                    for i in 0..3 {
                        acc[i] += c[i];
                    }
                }
                *px = [
                    (acc[0] * inv_samples) as f32,
                    (acc[1] * inv_samples) as f32,
                    (acc[2] * inv_samples) as f32,
                    1.0,
                ];
            }
        });
    bar.finish_and_clear();
    stats.non_finite_samples = non_finite.load(Ordering::Relaxed);
    if options.exact {
        stats.sample_rays = width as u64 * height as u64 * (n * n) as u64;
    }
    Ok(Film {
        width,
        height,
        pixels,
        stats,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_pi_wraps() {
        assert!(
            (wrap_pi(3.0 * std::f64::consts::PI - 0.1) - (std::f64::consts::PI - 0.1)).abs()
                < 1e-12
        );
        assert!((wrap_pi(-0.1) + 0.1).abs() < 1e-15);
        assert_eq!(wrap_pi(f64::NAN), 0.0);
    }

    #[test]
    fn angle_table_interpolates_the_sky_closely() {
        let sky = Sky::default();
        let table = AngleTable::new(-0.1, 1.5, |e| sky.radiance(e));
        for i in 0..1000 {
            let e = -0.1 + 1.6 * (i as f64 + 0.37) / 1000.0;
            let (a, b) = (table.at(e), sky.radiance(e));
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() <= 1e-4 * b[c], "{e}: {a:?} {b:?}");
            }
        }
    }

    #[test]
    fn narrow_angle_tables_are_as_close() {
        // A mirage frame's range gets the fewest entries; the error bound still holds.
        let (sky, sea) = (Sky::default(), crate::scene::Sea::default());
        let sky_table = AngleTable::new(-0.004, 0.006, |e| sky.radiance(e));
        let sea_table = AngleTable::new(0.0, 0.004, |g| sea.radiance(g, &sky));
        assert_eq!(sky_table.values.len(), AngleTable::MIN_ENTRIES);
        for i in 0..1000 {
            let x = (i as f64 + 0.37) / 1000.0;
            let (e, g) = (-0.004 + 0.01 * x, 0.004 * x);
            let (a, b) = (sky_table.at(e), sky.radiance(e));
            let (c, d) = (sea_table.at(g), sea.radiance(g, &sky));
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() <= 1e-4 * b[k], "{e}: {a:?} {b:?}");
                assert!((c[k] - d[k]).abs() <= 1e-4 * d[k], "{g}: {c:?} {d:?}");
            }
        }
        // Sea over its full range, at the widest spacing used below 90°.
        let full = AngleTable::new(0.0, std::f64::consts::FRAC_PI_2, |g| sea.radiance(g, &sky));
        for i in 0..1000 {
            let g = std::f64::consts::FRAC_PI_2 * (i as f64 + 0.37) / 1000.0;
            let (c, d) = (full.at(g), sea.radiance(g, &sky));
            for k in 0..3 {
                assert!((c[k] - d[k]).abs() <= 1e-4 * d[k], "{g}: {c:?} {d:?}");
            }
        }
    }

    #[test]
    fn jitter_hash_is_uniform_enough() {
        let n = 10_000;
        let mean: f64 = (0..n).map(|i| unit_hash(i as u64)).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.02, "{mean}");
        assert!((0..n).all(|i| (0.0..1.0).contains(&unit_hash(i as u64))));
    }
}
