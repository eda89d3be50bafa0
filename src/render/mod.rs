//! Stage 5b — render. In: a [`Scene`] and a [`RayTracer`]. Out: a [`Film`] of linear f32 RGBA
//! radiance (unit: the white horizon sky, see [`crate::scene::sky`]).
//!
//! Spherical symmetry makes the ray depend only on its apparent elevation, so the renderer traces
//! one fan of elevations for the whole frame ([`elevation_fan`], refined adaptively where the
//! transfer curve bends sharply; its documentation states the error bound) and shades every pixel
//! sample by interpolating in that fan: per sample, an elevation (a square root and a short
//! arctangent series; the azimuth only when a card or the sun may be met), an O(1) fan lookup, a
//! few comparisons per card in view, and the sky/sea/sun model (shading in `shade`). Per row,
//! cards are tested only in the columns their azimuth range and the row's heights allow.
//!
//! **Flat rows.** With one sample per pixel, a row is cut into a few bands of columns (by their
//! distance from the centre column, on which alone the elevation depends) whose elevations span
//! less than [`FLAT_ROW_FRACTION`] × the fan tolerance (the elevation changes by ≈ α·u²/2 across
//! a row: one band for every row of a narrow mirage frame at 400×200, one to a few at
//! 1920×1080). Each band is shaded at the elevation of its first column: one fan lookup, one sea
//! or sky colour, and per pixel only the card tests in card columns. Rows that would need more
//! than a few bands are shaded pixel by pixel. A band whose ray may show the sun — its disc, or
//! its glitter or mirror image on the sea, which depend on each pixel's azimuth — adds the sun's
//! part column by column: the disc and its mirror image exactly at every column of their chord,
//! the glitter exactly at node columns and interpolated between them within a documented
//! tolerance (`band_sun`).
//!
//! **The sea's reflections** (`reflection`): a reflected ray is a ray from the sea surface, so
//! one *sea fan* traced from height 0 per frame serves every sample (and exact mode too); a flat
//! band whose sea mirrors a card shades that card's columns pixel by pixel (with the sun's part,
//! exact, when the band may show it; on a rough sea, the parts of the slopes that mirror
//! something are found once per band and set of mirrored cards).
//!
//! **Frame plans** (`plan`): everything a frame's rows are shaded from (fan, tables, shader) is
//! built first, then each row is shaded on its own; a sun sweep (`sweep`) shades only the rows
//! that its sun can change and copies the others from its first frame.
//!
//! Exact mode instead calls the tracer for every sample (no fan, no interpolation, no flat rows):
//! it validates the fast path and is the benchmark baseline.
//!
//! Samples: n×n stratified, jittered by a hash of (pixel, sample) — no global random state, so the
//! image is the same whatever the thread count (rows are rendered in parallel, each pixel on its
//! own). With one sample per pixel the pixel centre is used.

mod air_paths;
mod band_sun;
pub mod curved;
pub mod elevation_fan;
mod memo;
mod objects;
mod plan;
pub mod ray_model;
mod reflection;
mod sea_sun;
mod shade;
pub mod spectral;
mod sun;
pub mod sweep;
pub mod sweep_plot;
pub mod terrain;
#[cfg(test)]
mod test_rays;
mod texture_box;

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use crate::scene::camera::{CameraFrame, ViewDirection};
use crate::scene::{Scene, Sun};
use band_sun::{BandColumns, BandSun};
pub use curved::{CurvedRays, ExactRays, PrepareError, prepare_tracer, render_tracer_config};
pub use elevation_fan::{ElevationFan, FanSpec};
pub use memo::MemoRays;
use objects::{RayAlong, SampleRay};
use plan::FramePlan;
pub use ray_model::{ConstantCurvatureRays, FanEnd, FanRay, RayTracer, StraightRays};
use shade::{Shader, ViewCard, wrap_pi};
use terrain::TerrainView;

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
    /// The ray tracer's error tolerance on the ray heights at the target distances (m), within
    /// [`TRACER_TOLERANCE_RANGE_M`]; default [`render_tracer_config`]'s (1 mm). Straight rays
    /// (closed form) do not use it.
    pub tolerance_m: f64,
}

/// The tracer tolerances (m) a render accepts: 1 µm (far below any visible effect, and slow) to
/// 10 m (coarser than a pixel of most frames; only for quick looks).
pub const TRACER_TOLERANCE_RANGE_M: (f64, f64) = (1e-6, 10.0);

/// Check a tracer tolerance (m) against [`TRACER_TOLERANCE_RANGE_M`].
pub fn check_tracer_tolerance(tolerance_m: f64) -> Result<(), RenderError> {
    let (lo, hi) = TRACER_TOLERANCE_RANGE_M;
    if tolerance_m.is_finite() && (lo..=hi).contains(&tolerance_m) {
        Ok(())
    } else {
        Err(RenderError::TracerTolerance(tolerance_m))
    }
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            exact: false,
            samples_per_pixel: None,
            quiet: false,
            tolerance_px: 0.1,
            max_refine_depth: 12,
            tolerance_m: render_tracer_config(crate::units::EARTH_RADIUS_M).tolerance_m,
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
    /// The tracer tolerance is outside [`TRACER_TOLERANCE_RANGE_M`].
    #[error(
        "tracer tolerance must be a finite number of metres from 1e-6 to 10 (default 0.001), got {0}"
    )]
    TracerTolerance(f64),
    /// A sun sweep needs a scene with a `[sun]`.
    #[error("the scene has no [sun]: a sun sweep needs one to move")]
    NoSun,
    /// A sun sweep's true elevation is outside −90°…90°.
    #[error("sun elevations must lie within -90° and 90°, got {:.6}°", .0.to_degrees())]
    SunElevation(f64),
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
    /// Rays whose optical depth towards the sun was integrated along their path (0 without a
    /// sun in view).
    pub sun_rays: usize,
    /// Rays whose paths to the cards and the sea were integrated for the aerial perspective (0
    /// without `visibility_km`, or for straight rays, whose chord is their path).
    pub air_path_rays: usize,
    /// Rays traced from the sea surface for its reflections of the cards (0 without cards beyond
    /// the sea in view, or with `[sea] reflections = false`).
    pub sea_fan_rays: usize,
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

/// Deterministic hash of a 64-bit key → [0, 1) (splitmix64 finaliser).
#[inline]
fn unit_hash(key: u64) -> f64 {
    let mut z = key.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// Directions (azimuth, elevation) through 65 points on each edge of the film (corners
/// included): the frame's border, where both extremes of azimuth and elevation lie (apart from the
/// zenith and nadir).
fn border_directions(
    frame: &CameraFrame,
    width: u32,
    height: u32,
) -> impl Iterator<Item = (f64, f64)> + '_ {
    let (w, h) = (width as f64, height as f64);
    // Along an edge the elevation has at most one interior extreme, at the edge's middle
    // (included: the count is even); the azimuth is monotone. So few points suffice.
    let steps = 64;
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

/// Per-thread buffers for one image row (reused from row to row: no allocation per pixel).
struct RowScratch {
    /// View direction of every sample of the row, pixel by pixel.
    dirs: Vec<ViewDirection>,
    /// Interpolated heights at the card distances.
    heights: Vec<Option<f64>>,
    /// Column ranges [a, b) whose rays may meet a card.
    card_columns: Vec<(usize, usize)>,
    /// The same in a flat row, with the band they belong to.
    band_columns: Vec<(usize, (usize, usize))>,
    /// Interpolated heights at the card distances of each flat band, band after band.
    band_heights: Vec<Option<f64>>,
    /// What the sun adds in each column of a flat row whose band may show it.
    sun_added: Vec<[f64; 3]>,
}

impl RowScratch {
    fn new(samples: usize, distances: usize) -> Self {
        Self {
            dirs: Vec::with_capacity(samples),
            heights: vec![None; distances],
            card_columns: Vec::new(),
            band_columns: Vec::new(),
            band_heights: Vec::new(),
            sun_added: Vec::new(),
        }
    }

    /// Directions of the samples of row `y`: n×n stratified, jittered by a hash of (pixel,
    /// sample); the pixel centres when n = 1.
    fn directions(&mut self, frame: &CameraFrame, y: u32, width: u32, n: u32) {
        if n == 1 {
            frame.row_view_directions(y, width, &mut self.dirs);
            return;
        }
        self.dirs.clear();
        for x in 0..width {
            for s in 0..n * n {
                let key = ((y as u64) << 40) ^ ((x as u64) << 16) ^ s as u64;
                let (sx, sy) = ((s % n) as f64, (s / n) as f64);
                let (jx, jy) = (
                    (sx + unit_hash(2 * key)) / n as f64,
                    (sy + unit_hash(2 * key + 1)) / n as f64,
                );
                self.dirs
                    .push(frame.view_direction(x as f64 + jx, y as f64 + jy));
            }
        }
    }
}

/// Fraction of the fan tolerance ([`RenderOptions::tolerance_px`]) by which the elevations along
/// one image row may differ for the row to be shaded at a single elevation (1 sample per pixel,
/// fan mode). Along a row of a level camera the elevation changes by about α·u²/2 (u the
/// half-width in radians): across a 1° mirage frame at α = 0.3° that is 0.005 px at 400 px wide
/// (every row of the paper frames at 400×200 is one band) but 0.02 px at 1920 (rows of a 1080p
/// frame take one to a few bands). A band shares one ray — one fan lookup, the sea or sky colour once —
/// and only columns that can meet a card (or, for the sun's part, that may show the sun) are
/// shaded pixel by pixel.
/// Features are then misplaced by at most (1 + this) × the fan tolerance.
pub const FLAT_ROW_FRACTION: f64 = 0.1;

/// What [`shade_flat_row`] needs besides the row.
struct FlatRow<'a> {
    frame: &'a CameraFrame,
    fan: &'a ElevationFan,
    shader: &'a Shader<'a>,
    clear_sky_from: f64,
    limit_rad: f64,
    y: u32,
}

/// Most bands a row is cut into by [`flat_bands`]; a row that needs more is shaded pixel by pixel.
pub const MAX_FLAT_BANDS: usize = 8;

/// One band of a flat row: the columns at the same distance from the centre column as the
/// right-half columns [`start`, `end`), shaded at the elevation of column `start`.
struct FlatBand {
    start: usize,
    end: usize,
    alpha: f64,
    background: [f64; 3],
    /// Whether every sample of the band sees only sky (no fan lookup was needed).
    clear_sky: bool,
    /// How the band's ray ended.
    fan_end: FanEnd,
    /// Whether the sea it meets may mirror a card (its card columns then shade the sea's
    /// reflections pixel by pixel).
    reflects: bool,
    /// Whether it may show the sun (its columns then add the sun's part, `band_sun`).
    sun: bool,
    /// Where it may show the sun: per run of [`band_runs`], the columns outside of which the
    /// sun's part is exactly +0 ([`BandColumns::fill_band`]).
    sun_lit: [(usize, usize); 2],
}

/// Cut row `y` into bands of columns, by their distance from the centre column (the elevation
/// depends on nothing else, and changes monotonically with it), whose elevations stay within
/// `limit_rad` of the band's first column. `None` if that takes more than [`MAX_FLAT_BANDS`]
/// or an elevation is not finite. Each band is given by its first right-half column and the
/// elevation (rad) it is shaded at; it runs to the next band's first column.
pub fn flat_bands(
    frame: &CameraFrame,
    y: u32,
    width: u32,
    limit_rad: f64,
) -> Option<Vec<(usize, f64)>> {
    let film_y = y as f64 + 0.5;
    let elevation = |x: usize| frame.view_direction(x as f64 + 0.5, film_y).elevation_rad;
    let width = width as usize;
    let mut bands = Vec::new();
    let mut start = width / 2;
    while start < width {
        if bands.len() == MAX_FLAT_BANDS {
            return None;
        }
        let alpha = elevation(start);
        if !alpha.is_finite() {
            return None;
        }
        // The last column within the limit (monotone: bisect).
        let (mut lo, mut hi) = (start, width);
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if (elevation(mid) - alpha).abs() <= limit_rad {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        bands.push((start, alpha));
        start = lo + 1;
    }
    Some(bands)
}

/// Shade row `y` (1 sample per pixel) band by band ([`flat_bands`]: each band at one elevation,
/// with the sun's part per column where a band may show it), if it can be cut into few enough
/// bands and no band's sea may mirror the terrain; returns whether it did.
fn shade_flat_row(
    ctx: &FlatRow<'_>,
    row: &mut [[f32; 4]],
    scratch: &mut RowScratch,
    non_finite: &AtomicU64,
) -> bool {
    let width = row.len() as u32;
    let film_y = ctx.y as f64 + 0.5;
    let Some(starts) = flat_bands(ctx.frame, ctx.y, width, ctx.limit_rad) else {
        return false;
    };
    let n_dist = scratch.heights.len();
    let RowScratch {
        band_heights,
        band_columns: columns,
        sun_added,
        ..
    } = scratch;
    band_heights.clear();
    band_heights.resize(starts.len() * n_dist, None);
    columns.clear();
    let mut bands = Vec::with_capacity(starts.len());
    for (k, &(start, alpha)) in starts.iter().enumerate() {
        let end = starts.get(k + 1).map_or(width as usize, |b| b.0);
        let heights = &mut band_heights[k * n_dist..(k + 1) * n_dist];
        if alpha >= ctx.clear_sky_from {
            bands.push(FlatBand {
                start,
                end,
                alpha,
                background: ctx.shader.sky_table.at(alpha),
                clear_sky: true,
                fan_end: FanEnd::Lost,
                reflects: false,
                sun: false,
                sun_lit: [(0, 0); 2],
            });
            continue;
        }
        let fan_end = ctx.fan.interpolate(alpha, heights);
        if ctx.shader.may_reflect_terrain(fan_end) {
            return false;
        }
        let dir = ctx
            .frame
            .view_direction_at_elevation(start as f64 + 0.5, film_y, alpha);
        let background = ctx.shader.background_with(&dir, fan_end, false);
        let sun = BandSun::of(ctx.shader, alpha, fan_end);
        let mut sun_lit = [(0, 0); 2];
        if let Some(sun) = sun {
            sun_added.resize(width as usize, [0.0; 3]);
            let run = BandColumns {
                shader: ctx.shader,
                offsets: ctx.shader.azimuths.row(ctx.y),
                sun,
                background,
            };
            sun_lit = run.fill_band((start, end), width as usize, sun_added);
        }
        let mut reflects = false;
        for card in &ctx.shader.cards {
            let mirrored = ctx.shader.may_reflect_card(fan_end, card);
            reflects |= mirrored;
            if mirrored
                || heights[card.distance_index]
                    .is_some_and(|h| !(h < card.base_m || h > card.top_m))
            {
                let range = card_column_range(card, ctx.frame, ctx.y, width);
                columns.push((k, range.unwrap_or((0, width as usize))));
            }
        }
        bands.push(FlatBand {
            start,
            end,
            alpha,
            background,
            clear_sky: false,
            fan_end,
            reflects,
            sun: sun.is_some(),
            sun_lit,
        });
    }
    let sun_added = &sun_added[..];
    shade_bands(
        ctx,
        row,
        &bands,
        band_heights,
        columns,
        sun_added,
        non_finite,
    );
    true
}

/// Fill `row` from its flat bands: the band's background (plus the sun's part, `sun_added`,
/// where the band may show the sun), or the cards over it in the columns (`columns`: band
/// index, column range) where the band's ray meets a card. Band by band, each band's two runs
/// of columns (its right-half columns and their mirror images) at a time.
fn shade_bands(
    ctx: &FlatRow<'_>,
    row: &mut [[f32; 4]],
    bands: &[FlatBand],
    band_heights: &[Option<f64>],
    columns: &[(usize, (usize, usize))],
    sun_added: &[[f64; 3]],
    non_finite: &AtomicU64,
) {
    let width = row.len();
    let n_dist = band_heights.len() / bands.len().max(1);
    let film_y = ctx.y as f64 + 0.5;
    let fallback = ctx.shader.fallback;
    // A rough sea's parts of the slopes, found once per band and set of mirrored cards.
    let mut parts = reflection::PartsCache::default();
    for (k, band) in bands.iter().enumerate() {
        let heights = &band_heights[k * n_dist..(k + 1) * n_dist];
        // The card columns of this band (none over a clear sky).
        let cards = columns
            .iter()
            .filter(|&&(j, _)| j == k && !band.clear_sky)
            .map(|&(_, range)| range);
        let in_card = |x: usize| cards.clone().any(|(a, b)| (a..b).contains(&x));
        let mut composite = |x: usize| {
            let dir = ctx
                .frame
                .view_direction_at_elevation(x as f64 + 0.5, film_y, band.alpha);
            let background = if band.reflects || band.sun {
                ctx.shader
                    .band_background(&dir, band.fan_end, k, &mut parts)
            } else {
                band.background
            };
            ctx.shader.composite(&dir, heights, background)
        };
        let runs = band_runs(band.start, band.end, width);
        for ((a, b), lit) in runs.into_iter().zip(band.sun_lit) {
            if b <= a {
                continue;
            }
            if cards.clone().next().is_none() {
                fill_run(
                    fallback,
                    &mut row[a..b],
                    band,
                    sun_added,
                    (a, lit),
                    non_finite,
                );
                continue;
            }
            let mut x = a;
            while x < b {
                if in_card(x) {
                    row[x] = pixel(finite_or_fallback(composite(x), fallback, non_finite));
                    x += 1;
                    continue;
                }
                let end = (x + 1..b).find(|&e| in_card(e)).unwrap_or(b);
                fill_run(
                    fallback,
                    &mut row[x..end],
                    band,
                    sun_added,
                    (x, lit),
                    non_finite,
                );
                x = end;
            }
        }
    }
}

/// A film pixel of a colour.
#[inline]
fn pixel(c: [f64; 3]) -> [f32; 4] {
    [c[0] as f32, c[1] as f32, c[2] as f32, 1.0]
}

/// `c`, or `fallback` (the shader's fallback colour) when a channel is not finite (counted in
/// `non_finite`, per sample).
#[inline]
fn finite_or_fallback(c: [f64; 3], fallback: [f64; 3], non_finite: &AtomicU64) -> [f64; 3] {
    if c.iter().all(|v| v.is_finite()) {
        c
    } else {
        non_finite.fetch_add(1, Ordering::Relaxed);
        fallback
    }
}

/// Fill `run`, the columns from `first` on of one band of a row that meet no card: the band's
/// background, plus the sun's part per column (`sun_added`) where the band may show the sun,
/// which is +0 outside the columns `lit`: there the pixels are one colour, worked out once.
fn fill_run(
    fallback: [f64; 3],
    run: &mut [[f32; 4]],
    band: &FlatBand,
    sun_added: &[[f64; 3]],
    (first, lit): (usize, (usize, usize)),
    non_finite: &AtomicU64,
) {
    let c = band.background;
    if !band.sun {
        fill_constant(fallback, run, c, non_finite);
        return;
    }
    let end = first + run.len();
    let (lo, hi) = (lit.0.clamp(first, end), lit.1.clamp(first, end));
    let (lo, hi) = if lo < hi { (lo, hi) } else { (end, end) };
    let (before, rest) = run.split_at_mut(lo - first);
    let (lit_run, after) = rest.split_at_mut(hi - lo);
    // The sum with a +0 addition, as the loop below forms it (a −0 channel becomes +0).
    let dark = [c[0] + 0.0, c[1] + 0.0, c[2] + 0.0];
    fill_constant(fallback, before, dark, non_finite);
    fill_constant(fallback, after, dark, non_finite);
    let sums = lit_run.iter_mut().zip(&sun_added[lo..hi]);
    let mut all_finite = true;
    for (px, add) in sums {
        let sum = [c[0] + add[0], c[1] + add[1], c[2] + add[2]];
        // Without a branch per pixel (the loop vectorises); a run with a colour that is not
        // finite is done again below, pixel by pixel. x · 0 is ±0 for a finite x and NaN for
        // any other: one comparison tests the three channels.
        all_finite &= sum[0] * 0.0 + sum[1] * 0.0 + sum[2] * 0.0 == 0.0;
        *px = pixel(sum);
    }
    if !all_finite {
        for (px, add) in lit_run.iter_mut().zip(&sun_added[lo..hi]) {
            let sum = [c[0] + add[0], c[1] + add[1], c[2] + add[2]];
            *px = pixel(finite_or_fallback(sum, fallback, non_finite));
        }
    }
}

/// Fill `run` with colour `c` (`fallback` where it is not finite, counted per pixel).
fn fill_constant(fallback: [f64; 3], run: &mut [[f32; 4]], c: [f64; 3], non_finite: &AtomicU64) {
    if run.is_empty() {
        return;
    }
    run.fill(pixel(finite_or_fallback(c, fallback, non_finite)));
    if !c.iter().all(|v| v.is_finite()) {
        // Counted once above; once per further pixel.
        non_finite.fetch_add(run.len() as u64 - 1, Ordering::Relaxed);
    }
}

/// The two runs of columns of a row `width` wide that a band of right-half columns [`start`,
/// `end`) covers: those, and the left-half columns at the same distance from the centre (the
/// centre column of an odd width is in the first run only).
fn band_runs(start: usize, end: usize, width: usize) -> [(usize, usize); 2] {
    [(start, end), (width - end, (width - start).min(width / 2))]
}

/// Pixel columns [a, b) of row `y` whose samples may see `card`, given that their elevations lie
/// in `alphas` (rad): `None` if the fan's rays at those elevations cannot be within the card's
/// height range at its distance, else [`card_column_range`] (every column when that is
/// unbounded). Samples outside these columns skip the card tests: they would all fail.
fn card_columns_in_row(
    card: &ViewCard<'_>,
    fan: &ElevationFan,
    alphas: (f64, f64),
    frame: &CameraFrame,
    y: u32,
    width: u32,
) -> Option<(usize, usize)> {
    let (h_lo, h_hi) = fan.height_range(alphas.0, alphas.1, card.distance_index)?;
    if h_hi < card.base_m || h_lo > card.top_m {
        return None;
    }
    Some(card_column_range(card, frame, y, width).unwrap_or((0, width as usize)))
}

/// Pixel columns [a, b) of row `y` within `card`'s azimuth range, widened by a pixel for
/// rounding; `None` when the range cannot be bounded (see
/// [`CameraFrame::film_x_range_for_azimuths`]).
fn card_column_range(
    card: &ViewCard<'_>,
    frame: &CameraFrame,
    y: u32,
    width: u32,
) -> Option<(usize, usize)> {
    let (a, b) = frame.film_x_range_for_azimuths(
        card.offset_rad - card.half_width_rad,
        card.offset_rad + card.half_width_rad,
        y as f64,
        (y + 1) as f64,
    )?;
    if !(a.is_finite() && b.is_finite()) {
        return None;
    }
    let first = (a - 1.0).floor().clamp(0.0, width as f64) as usize;
    let end = (b + 1.0).ceil().clamp(0.0, width as f64) as usize;
    Some((first, end))
}

/// Whether a sample of row `y` may meet the terrain: the row's elevations (extreme at the
/// centre column and the edges) reach into the view's elevation range.
fn row_may_meet_terrain(view: &TerrainView<'_>, frame: &CameraFrame, y: u32, width: u32) -> bool {
    let film_y = y as f64 + 0.5;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in [0.5, 0.5 * width as f64, width as f64 - 0.5] {
        let e = frame.view_direction(x, film_y).elevation_rad;
        lo = lo.min(e);
        hi = hi.max(e);
    }
    let pad = 1.0 / frame.focal_px;
    hi + pad >= view.may_hit_rad.0 && lo - pad <= view.may_hit_rad.1
}

/// A camera sample shaded from the fan: the objects its interpolated ray meets (cards only
/// where `may_meet_card`) over the sea or sky; a sample that can meet nothing takes the
/// background alone.
#[inline]
fn shade_fan_sample(
    shader: &Shader<'_>,
    fan: &ElevationFan,
    dir: &ViewDirection,
    may_meet_card: bool,
    heights: &mut [Option<f64>],
) -> [f64; 3] {
    let alpha = dir.elevation_rad;
    let may_meet_terrain = shader.terrain.as_ref().is_some_and(|t| t.may_hit(alpha));
    if !may_meet_card && !may_meet_terrain {
        return shader.background(dir, fan.interpolate_end(alpha));
    }
    let end = fan.interpolate(alpha, heights);
    let ray = SampleRay::new(
        dir,
        RayAlong::Fan {
            alpha,
            card_heights: may_meet_card.then_some(&*heights),
        },
    );
    shader.shade_ray(&ray, || shader.background(dir, end))
}

/// What [`shade_traced_sample`] needs of the frame (exact mode).
struct TracedSample<'a> {
    tracer: &'a dyn RayTracer,
    camera_height_m: f64,
    /// The card distances.
    distances_m: &'a [f64],
    need_sky_direction: bool,
}

/// Exact mode: a camera sample's ray traced on its own to the card distances (and, with
/// terrain, to every one of the terrain's traced distances), and what it meets over the sea or
/// sky.
fn shade_traced_sample(
    shader: &Shader<'_>,
    ctx: &TracedSample<'_>,
    dir: &ViewDirection,
) -> [f64; 3] {
    let alpha = dir.elevation_rad;
    let trace = |distances: &[f64], sky: bool| {
        let mut ray = ctx.tracer.trace(ctx.camera_height_m, alpha, distances, sky);
        ray.heights_m.resize(distances.len(), None);
        ray
    };
    let ray = trace(ctx.distances_m, ctx.need_sky_direction);
    let terrain_ray = shader
        .terrain
        .as_ref()
        .map(|t| trace(&t.traced.traced_m, false));
    let sample = SampleRay::new(
        dir,
        RayAlong::Traced {
            card_heights: &ray.heights_m,
            terrain: terrain_ray.as_ref().map(|r| (&r.heights_m[..], r.end)),
        },
    );
    shader.shade_ray(&sample, || shader.background(dir, ray.end))
}

/// The final elevations (rad) at which rays may show the sun: its disc and two pixels.
fn sun_band_rad(sun: &Sun, pixel_rad: f64) -> (f64, f64) {
    let r = 0.5 * sun.angular_diameter_rad + 2.0 * pixel_rad;
    (sun.elevation_rad - r, sun.elevation_rad + r)
}

/// Rays one pixel apart across `elevations_rad` with their ends (exact mode has no fan to take
/// them from).
fn traced_grid(
    tracer: &dyn RayTracer,
    camera_height_m: f64,
    elevations_rad: (f64, f64),
    pixel_rad: f64,
) -> Vec<(f64, FanEnd)> {
    let (lo, hi) = elevations_rad;
    let count = ((hi - lo) / pixel_rad).ceil().clamp(1.0, 1e6) as usize + 1;
    (0..count)
        .into_par_iter()
        .map(|i| {
            let alpha = lo + (hi - lo) * i as f64 / (count - 1).max(1) as f64;
            (alpha, tracer.trace(camera_height_m, alpha, &[], true).end)
        })
        .collect()
}

/// Render `scene` through `tracer`.
pub fn render_scene(
    scene: &Scene,
    tracer: &dyn RayTracer,
    options: &RenderOptions,
) -> Result<Film, RenderError> {
    let plan = FramePlan::new(scene, tracer, options, None)?;
    let (pixels, non_finite) = plan.shade_all(options.quiet);
    let (width, height) = plan.size();
    Ok(Film {
        width,
        height,
        pixels,
        stats: plan.stats(non_finite),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tracer_tolerance_error_states_the_default_a_render_uses() {
        let message = RenderError::TracerTolerance(0.0).to_string();
        let default = format!("(default {})", RenderOptions::default().tolerance_m);
        assert!(message.contains(&default), "{message}");
    }

    #[test]
    fn tracer_tolerance_default_range_and_refusal() {
        assert_eq!(RenderOptions::default().tolerance_m, 1e-3);
        for ok in [1e-6, 0.01, 10.0] {
            assert!(check_tracer_tolerance(ok).is_ok(), "{ok}");
        }
        for bad in [0.0, -0.01, 9e-7, 10.5, f64::NAN, f64::INFINITY] {
            assert!(
                matches!(
                    check_tracer_tolerance(bad),
                    Err(RenderError::TracerTolerance(_))
                ),
                "{bad}"
            );
        }
    }

    /// A 1.1° frame pitched up 0.3° (the Fata Morgana scene's width), `width` columns and 200
    /// rows wide, with the flat-row limit of its pixels.
    fn wide_frame(width: u32) -> (crate::scene::camera::CameraFrame, f64) {
        let cam = crate::scene::camera::Camera {
            height_m: 10.0,
            heading_rad: 0.3,
            pitch_rad: 0.005,
            hfov_rad: 0.019,
            width,
            height: 200,
            samples_per_pixel: 1,
        };
        let limit_rad = FLAT_ROW_FRACTION * 0.25 * cam.min_pixel_angle_rad();
        (cam.frame(), limit_rad)
    }

    #[test]
    fn flat_bands_cover_the_row_within_the_limit() {
        // A 1.1° frame pitched up 0.3° (the Fata Morgana scene's width), where the elevation
        // changes across a row by more than the limit; odd and even widths (the mirror
        // column of x is width − 1 − x).
        let mut most_bands = 0;
        for width in [1920u32, 1921, 7] {
            let (frame, limit_rad) = wide_frame(width);
            let mut banded_rows = 0;
            for y in [0u32, 40, 100, 199] {
                let Some(bands) = flat_bands(&frame, y, width, limit_rad) else {
                    continue;
                };
                banded_rows += 1;
                most_bands = most_bands.max(bands.len());
                assert_eq!(bands[0].0, width as usize / 2);
                assert!(bands.windows(2).all(|w| w[0].0 < w[1].0));
                let film_y = y as f64 + 0.5;
                let elevation =
                    |x: usize| frame.view_direction(x as f64 + 0.5, film_y).elevation_rad;
                for x in 0..width as usize {
                    let mirrored = x.max(width as usize - 1 - x);
                    let k = bands.iter().rposition(|b| b.0 <= mirrored).unwrap();
                    let off = (elevation(x) - bands[k].1).abs();
                    assert!(
                        off <= limit_rad * (1.0 + 1e-9),
                        "w{width} y{y} x{x}: {off:e}"
                    );
                }
            }
            assert!(banded_rows >= 2, "w{width}: {banded_rows}");
        }
        assert!(most_bands >= 2, "{most_bands}");
    }

    #[test]
    fn a_run_with_a_lit_span_gives_each_pixel_its_sum_and_counts_each_non_finite_one() {
        // Per pixel, as a run was filled before lit spans: the background plus the addition
        // (which is +0 outside the span), the fallback where that is not finite, counted once
        // per pixel. Runs before, across, inside and after the span; empty spans; a −0, a NaN
        // and an infinite background channel; a NaN and an infinite addition.
        let fallback = [0.5, 0.25, 0.125];
        let nan = f64::NAN;
        let backgrounds = [[0.2, -0.0, 0.4], [0.2, nan, 0.4], [f64::INFINITY, 0.1, 0.1]];
        let runs = [(0, 20), (4, 12), (8, 4), (0, 5), (15, 5), (3, 9)];
        for lit in [(6, 14), (20, 20), (0, 0)] {
            // The additions: +0 outside the span.
            let added: Vec<[f64; 3]> = (0..20)
                .map(|x| {
                    let inside = (lit.0..lit.1).contains(&x);
                    if inside {
                        [1e-3 * x as f64, 2e-3, 0.0]
                    } else {
                        [0.0; 3]
                    }
                })
                .collect();
            let (mut with_nan, mut with_inf) = (added.clone(), added.clone());
            if lit.0 < lit.1 {
                with_nan[9] = [nan, 0.0, 0.0];
                with_inf[11] = [0.0, 0.0, f64::NEG_INFINITY];
            }
            for background in backgrounds {
                for sun_added in [&added, &with_nan, &with_inf] {
                    for (first, len) in runs {
                        let band = FlatBand {
                            start: 0,
                            end: 20,
                            alpha: 0.0,
                            background,
                            clear_sky: false,
                            fan_end: FanEnd::Lost,
                            reflects: false,
                            sun: true,
                            sun_lit: [lit, lit],
                        };
                        let non_finite = AtomicU64::new(0);
                        let mut run = vec![[9.0f32; 4]; len];
                        let at = (first, lit);
                        fill_run(fallback, &mut run, &band, sun_added, at, &non_finite);
                        let mut want_bad = 0;
                        for (k, px) in run.iter().enumerate() {
                            let add = sun_added[first + k];
                            let sum = [0, 1, 2].map(|c| background[c] + add[c]);
                            let want = if sum.iter().all(|v| v.is_finite()) {
                                sum
                            } else {
                                want_bad += 1;
                                fallback
                            };
                            let bits = |p: [f32; 4]| p.map(f32::to_bits);
                            let case = format!("{background:?} {lit:?} {first}+{k}");
                            assert_eq!(bits(*px), bits(pixel(want)), "{case}");
                        }
                        let bad = non_finite.load(Ordering::Relaxed);
                        assert_eq!(bad, want_bad, "{background:?} {lit:?} {first}");
                    }
                }
            }
        }
    }

    #[test]
    fn the_bands_runs_cover_every_column_of_a_row_once() {
        for width in [1u32, 2, 7, 8, 400, 401] {
            // Bands as flat_bands cuts them: from the centre column to the right edge.
            let (frame, limit_rad) = wide_frame(width);
            let starts = flat_bands(&frame, 3, width, limit_rad).expect("few bands");
            let w = width as usize;
            let mut covered = vec![0u32; w];
            for (k, &(start, _)) in starts.iter().enumerate() {
                let end = starts.get(k + 1).map_or(w, |b| b.0);
                for (a, b) in band_runs(start, end, w) {
                    (a..b).for_each(|x| covered[x] += 1);
                }
            }
            assert!(covered.iter().all(|&c| c == 1), "w{width}: {covered:?}");
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
