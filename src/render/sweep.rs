//! Stage 5c — render the frames of a sweep. In: scenes that share one view of the air (the
//! same atmosphere, camera height, Earth and highest card: one prepared [`RayTracer`]), render
//! options. Out: one [`SweepFrame`] per scene — the [`Film`] that [`render_scene`] gives for it
//! and the facts read from the traced map ([`FrameFacts`]: the sun's apparent band and strips,
//! each card's images), plus, when asked, the frame's transfer curve at a card's distance.
//!
//! **What is shared.** The tracer depends only on what the scenes share, and every ray in a
//! spherically stratified atmosphere depends only on its apparent elevation (and the camera
//! height): moving the sun (in elevation or azimuth), turning the camera, moving a card or
//! changing the sky leaves every ray from the camera the same ray. The frames are rendered
//! through one [`MemoRays`], so each ray (of the elevation fan, of the sun's transmittance, of
//! the sea's reflections and glitter, of the haze, of the facts) is traced once for the whole
//! sweep and looked up by every later frame that asks for it with the same arguments; where the
//! fan's rays carry no card distances (no card in view), its rays to the sky are traced with the
//! density paths of the sun's transmittance along them ([`MemoRays::with_density_paths`]: one
//! trace for both, which the moving sun mostly needs in turn). Each frame still builds its own fan (refined around its own sun, from
//! remembered rays) and shades every row its sun may change; a frame that differs from the
//! first only in its sun holds just those rows over the first frame's film ([`FrameImage`]),
//! and either way it is bit for bit the frame a single render gives. For a sun sweep
//! the union of the frames' fans is the fan widened to the whole sweep, traced once; frames
//! whose fans share no ray (a swept pitch, field of view or card distance) gain nothing but
//! lose nothing either. The first frame is rendered alone (its fan is traced in parallel), then
//! the others in parallel, each frame on its own: the films do not depend on the thread count.
//!
//! **Facts from the traced map.** [`SunFacts`] come from the rays through the pixel centres of
//! one column — the column through the sun's azimuth on the middle row, or the centre column
//! when the sun's azimuth is outside the frame: a row *shows the sun* when its ray leaves the
//! atmosphere in a direction inside the sun's disc (cards, terrain and extinction are not
//! considered: a sun dimmed to nothing still counts). Strips are the maximal runs of
//! consecutive rows that show it. Those rays do not depend on the sun ([`ColumnSky`]), so the
//! frames of a sweep that share the first frame's camera trace each such column once.
//! [`CardFacts`] likewise, along the column through the card's
//! centre (none when that is outside the frame): a row *shows the card* when its ray passes the
//! card's distance between its base and top (nearer cards and terrain not considered); each
//! maximal run of such rows is one image.

use std::borrow::Cow;
use std::sync::{Arc, Mutex, PoisonError};

use rayon::prelude::*;

use super::elevation_fan::ElevationFan;
use super::memo::MemoRays;
use super::plan::{BaseRow, FramePlan};
use super::ray_model::{FanEnd, RayTracer};
use super::shade::wrap_pi;
use super::{Film, RenderError, RenderOptions, RenderStats, render_scene};
use crate::scene::{Card, Scene, Sun, Texture};

/// What the traced map says of the sun in one frame, along the column of [`sun_column`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SunFacts {
    /// Apparent elevation (rad) of the pixel centre of the lowest row that shows the sun.
    pub apparent_low_rad: Option<f64>,
    /// Apparent elevation (rad) of the pixel centre of the highest row that shows the sun.
    pub apparent_high_rad: Option<f64>,
    /// Number of separate runs of rows that show the sun (0 when none does).
    pub strips: usize,
}

/// What the traced map says of one card in one frame, along the column of [`card_column`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CardFacts {
    /// Apparent elevation (rad) of the pixel centre of the lowest row that shows the card.
    pub apparent_low_rad: Option<f64>,
    /// Apparent elevation (rad) of the pixel centre of the highest row that shows the card.
    pub apparent_high_rad: Option<f64>,
    /// Number of separate runs of rows that show the card: its images (0 when none).
    pub images: usize,
}

/// The facts of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameFacts {
    /// The sun's, when the scene has one.
    pub sun: Option<SunFacts>,
    /// Each card's, in scene order; `None` when the card's centre is outside the frame.
    pub cards: Vec<Option<CardFacts>>,
}

/// A frame's transfer curve: where the rays through the centre column pass one ground distance.
#[derive(Debug, Clone, PartialEq)]
pub struct TransferSamples {
    /// The camera height (m).
    pub camera_height_m: f64,
    /// The ground distance (m).
    pub distance_m: f64,
    /// Apparent elevations (rad), from the bottom of the frame to its top.
    pub elevations_rad: Vec<f64>,
    /// Height (m above the surface) of each ray at the distance; `None` when it ended before.
    pub heights_m: Vec<Option<f64>>,
}

/// A frame's image: the film [`render_scene`] gives for the frame's scene, held as the rows
/// the frame shaded over the film of the sweep's first frame (shared, not copied) when it
/// differs from that frame only in its sun, whole otherwise.
#[derive(Debug, Clone)]
pub struct FrameImage(Image);

#[derive(Debug, Clone)]
enum Image {
    Whole(Arc<Film>),
    OnBase {
        base: Arc<Film>,
        /// The rows shaded, ascending, and their pixels one after another.
        rows: Vec<u32>,
        pixels: Vec<[f32; 4]>,
        stats: RenderStats,
    },
}

impl FrameImage {
    /// Width and height (pixels).
    pub fn size(&self) -> (u32, u32) {
        match &self.0 {
            Image::Whole(film) | Image::OnBase { base: film, .. } => (film.width, film.height),
        }
    }

    /// The frame's counters.
    pub fn stats(&self) -> &RenderStats {
        match &self.0 {
            Image::Whole(film) => &film.stats,
            Image::OnBase { stats, .. } => stats,
        }
    }

    /// Row `y`'s pixels.
    ///
    /// # Panics
    /// If `y` is not a row of the image.
    pub fn row(&self, y: u32) -> &[[f32; 4]] {
        let (width, height) = self.size();
        assert!(y < height, "row {y} of {height}");
        let w = width as usize;
        match &self.0 {
            Image::Whole(film) => &film.pixels[y as usize * w..(y as usize + 1) * w],
            Image::OnBase {
                base, rows, pixels, ..
            } => match rows.binary_search(&y) {
                Ok(k) => &pixels[k * w..(k + 1) * w],
                Err(_) => &base.pixels[y as usize * w..(y as usize + 1) * w],
            },
        }
    }

    /// The whole film (borrowed when the frame holds it whole, put together from its rows and
    /// the first frame's otherwise).
    pub fn film(&self) -> Cow<'_, Film> {
        match &self.0 {
            Image::Whole(film) => Cow::Borrowed(film),
            Image::OnBase { base, stats, .. } => {
                let mut pixels = Vec::with_capacity(base.pixels.len());
                for y in 0..base.height {
                    pixels.extend_from_slice(self.row(y));
                }
                Cow::Owned(film_of(base.width, base.height, pixels, *stats))
            }
        }
    }
}

/// One frame of a sweep.
#[derive(Debug, Clone)]
pub struct SweepFrame {
    /// The image: the same as [`render_scene`] of the frame's scene.
    pub image: FrameImage,
    /// The sun and the cards in the traced map.
    pub facts: FrameFacts,
    /// The transfer curve at the farthest card's distance, when asked for and the scene has a
    /// card.
    pub transfer: Option<TransferSamples>,
    /// Rows of the film this frame shaded itself: all of them, unless it differs from the
    /// sweep's first frame only in its sun; then the rows its sun cannot change are taken
    /// from the first frame, which they equal (module docs).
    pub rows_shaded: u32,
}

/// The column whose pixel centre on the middle row is nearest azimuth `azimuth_rad`, when that
/// azimuth lies between the first and last columns' on that row; otherwise `None`.
fn column_at_azimuth(scene: &Scene, azimuth_rad: f64) -> Option<u32> {
    let cam = &scene.camera;
    let frame = cam.frame();
    let y = 0.5 * cam.height as f64;
    let offsets: Vec<f64> = (0..cam.width)
        .map(|x| wrap_pi(frame.direction(x as f64 + 0.5, y).0 - azimuth_rad))
        .collect();
    let (&first, &last) = (offsets.first()?, offsets.last()?);
    if first.min(last) > 0.0 || first.max(last) < 0.0 {
        return None;
    }
    (0..cam.width).min_by(|&a, &b| {
        offsets[a as usize]
            .abs()
            .total_cmp(&offsets[b as usize].abs())
    })
}

/// The column whose facts [`SunFacts`] reports: the one whose pixel centre on the middle row is
/// nearest the sun's azimuth, when that azimuth lies between the first and last columns' on
/// that row; otherwise the centre column.
pub fn sun_column(scene: &Scene, sun: &Sun) -> u32 {
    column_at_azimuth(scene, sun.azimuth_rad).unwrap_or(scene.camera.width / 2)
}

/// The column through `card`'s centre (as [`sun_column`] for its azimuth), or `None` when that
/// is outside the frame.
pub fn card_column(scene: &Scene, card: &Card) -> Option<u32> {
    column_at_azimuth(scene, card.azimuth_rad)
}

/// The apparent elevation and azimuth (rad) of the pixel centres of column `x`, top row first.
fn column_directions(scene: &Scene, x: u32) -> impl Iterator<Item = (f64, f64)> {
    let frame = scene.camera.frame();
    (0..scene.camera.height).map(move |y| {
        let (fx, fy) = (x as f64 + 0.5, y as f64 + 0.5);
        (
            frame.view_direction(fx, fy).elevation_rad,
            frame.direction(fx, fy).0,
        )
    })
}

/// Runs of consecutive `rows` (apparent elevation, whether the row shows the object; top row
/// first) that show it, with the apparent elevations of the lowest and highest such rows.
fn runs(rows: impl IntoIterator<Item = (f64, bool)>) -> (usize, Option<f64>, Option<f64>) {
    let (mut runs, mut low, mut high) = (0, None, None);
    let mut previous = false;
    for (alpha, now) in rows {
        if now {
            high.get_or_insert(alpha);
            low = Some(alpha);
            if !previous {
                runs += 1;
            }
        }
        previous = now;
    }
    (runs, low, high)
}

/// [`runs`] of the rows of column `x` for which `shows(alpha, azimuth)` holds.
fn runs_along(
    scene: &Scene,
    x: u32,
    shows: impl Fn(f64, f64) -> bool,
) -> (usize, Option<f64>, Option<f64>) {
    runs(column_directions(scene, x).map(|(alpha, azimuth)| (alpha, shows(alpha, azimuth))))
}

/// The rays through the pixel centres of one column, top row first: each one's apparent
/// elevation (rad), azimuth (rad) and, when it leaves into the sky, its final elevation (rad).
/// Everything [`SunFacts`] reads of a frame that does not depend on the sun, so the frames of a
/// sun sweep share it ([`render_shared`]).
pub struct ColumnSky {
    rows: Vec<(f64, f64, Option<f64>)>,
}

impl ColumnSky {
    /// Column `x` of `scene`'s camera, its rays traced through `tracer` (need_sky_direction:
    /// their final directions).
    pub fn trace(scene: &Scene, tracer: &dyn RayTracer, x: u32) -> Self {
        Self::trace_beside(scene, tracer, x, None)
    }

    /// [`Self::trace`], but for the rows whose rays `fan` (traced by `tracer` from the same
    /// camera height) shows to end in the sea ([`ElevationFan::surely_sea`]): those are not
    /// traced, and they leave into no sky all the same.
    fn trace_beside(
        scene: &Scene,
        tracer: &dyn RayTracer,
        x: u32,
        fan: Option<&ElevationFan>,
    ) -> Self {
        let height_m = scene.camera.height_m;
        let directions: Vec<(f64, f64)> = column_directions(scene, x).collect();
        let rows = directions
            .into_par_iter()
            .map(|(alpha, azimuth)| {
                if fan.is_some_and(|f| f.surely_sea(alpha)) {
                    return (alpha, azimuth, None);
                }
                let sky = match tracer.trace(height_m, alpha, &[], true).end {
                    FanEnd::Sky { elevation_rad } => Some(elevation_rad),
                    _ => None,
                };
                (alpha, azimuth, sky)
            })
            .collect();
        Self { rows }
    }

    /// The facts of `sun` along this column: a row shows it when its ray leaves in a direction
    /// inside the sun's disc.
    pub fn sun_facts(&self, sun: &Sun) -> SunFacts {
        let radius = 0.5 * sun.angular_diameter_rad;
        let (strips, low, high) = runs(self.rows.iter().map(|&(alpha, azimuth, sky)| {
            let shows = sky.is_some_and(|e| {
                angle_between(azimuth, e, sun.azimuth_rad, sun.elevation_rad) <= radius
            });
            (alpha, shows)
        }));
        SunFacts {
            apparent_low_rad: low,
            apparent_high_rad: high,
            strips,
        }
    }
}

/// The sun's facts in `scene` (which has `sun`) along column `x`, from rays traced through
/// `tracer` (need_sky_direction: their final directions).
pub fn sun_facts(scene: &Scene, sun: &Sun, tracer: &dyn RayTracer, x: u32) -> SunFacts {
    ColumnSky::trace(scene, tracer, x).sun_facts(sun)
}

/// `card`'s facts in `scene` along column `x`, from rays traced through `tracer` to the card's
/// distance.
pub fn card_facts(scene: &Scene, card: &Card, tracer: &dyn RayTracer, x: u32) -> CardFacts {
    let (height_m, top_m) = (scene.camera.height_m, card.base_m + card.height_m);
    let distance = [card.distance_m];
    let (images, low, high) = runs_along(scene, x, |alpha, _| {
        let heights = tracer.heights_at(height_m, alpha, &distance);
        heights[0].is_some_and(|h| h >= card.base_m && h <= top_m)
    });
    CardFacts {
        apparent_low_rad: low,
        apparent_high_rad: high,
        images,
    }
}

/// The card farthest from the observer (the first of equals), if any: the target of the
/// transfer curve.
pub fn farthest_card(scene: &Scene) -> Option<&Card> {
    scene
        .cards
        .iter()
        .reduce(|a, b| if b.distance_m > a.distance_m { b } else { a })
}

/// The facts of `scene` from rays traced through `tracer`.
pub fn frame_facts(scene: &Scene, tracer: &dyn RayTracer) -> FrameFacts {
    frame_facts_with(scene, tracer, &|sun| {
        Arc::new(ColumnSky::trace(scene, tracer, sun_column(scene, sun)))
    })
}

/// [`frame_facts`], the rays of the sun's column ([`sun_column`] of `scene`'s camera) from
/// `column`.
fn frame_facts_with(
    scene: &Scene,
    tracer: &dyn RayTracer,
    column: &dyn Fn(&Sun) -> Arc<ColumnSky>,
) -> FrameFacts {
    let sun = scene.sun.map(|sun| column(&sun).sun_facts(&sun));
    let cards = scene
        .cards
        .iter()
        .map(|card| card_column(scene, card).map(|x| card_facts(scene, card, tracer, x)))
        .collect();
    FrameFacts { sun, cards }
}

/// The sun's columns of a sweep's frames that share the first frame's camera, each traced
/// once ([`ColumnSky`] does not depend on the sun), beside the first frame's fan when it has
/// one ([`ColumnSky::trace_beside`]), found once per sun azimuth ([`sun_column`] depends only
/// on the camera and the azimuth). Two threads may trace the same column at once; they find
/// the same rays, and either copy is kept.
#[derive(Default)]
struct SharedColumns<'f> {
    /// The first frame's fan.
    fan: Option<&'f ElevationFan>,
    /// [`sun_column`] by the bits of the sun's azimuth.
    by_azimuth: Mutex<Vec<(u64, u32)>>,
    columns: Mutex<Vec<(u32, Arc<ColumnSky>)>>,
}

/// The list behind `m`, even if a thread panicked while holding it (it is only ever extended
/// with finished values).
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl SharedColumns<'_> {
    fn get(&self, scene: &Scene, tracer: &dyn RayTracer, sun: &Sun) -> Arc<ColumnSky> {
        let azimuth = sun.azimuth_rad.to_bits();
        let found = lock(&self.by_azimuth)
            .iter()
            .find(|(k, _)| *k == azimuth)
            .map(|&(_, x)| x);
        let x = found.unwrap_or_else(|| {
            let x = sun_column(scene, sun);
            lock(&self.by_azimuth).push((azimuth, x));
            x
        });
        if let Some((_, column)) = lock(&self.columns).iter().find(|(k, _)| *k == x) {
            return Arc::clone(column);
        }
        let column = Arc::new(ColumnSky::trace_beside(scene, tracer, x, self.fan));
        lock(&self.columns).push((x, Arc::clone(&column)));
        column
    }
}

/// Heights at `card`'s distance of the rays through the pixel centres of its column
/// ([`card_column`], the centre column when it is out of view), from the bottom row to the top:
/// the rays [`card_facts`] traces, so through a [`MemoRays`] they are traced once for both.
pub fn transfer_samples(scene: &Scene, tracer: &dyn RayTracer, card: &Card) -> TransferSamples {
    let cam = &scene.camera;
    let frame = cam.frame();
    let x = card_column(scene, card).unwrap_or(cam.width / 2) as f64 + 0.5;
    let elevations_rad: Vec<f64> = (0..cam.height)
        .rev()
        .map(|y| frame.view_direction(x, y as f64 + 0.5).elevation_rad)
        .collect();
    let distance = [card.distance_m];
    let heights_m = elevations_rad
        .iter()
        .map(|&a| tracer.heights_at(cam.height_m, a, &distance)[0])
        .collect();
    TransferSamples {
        camera_height_m: cam.height_m,
        distance_m: card.distance_m,
        elevations_rad,
        heights_m,
    }
}

/// The first frame of a sweep, rendered alone, with what frames that differ from it only in
/// their sun need to take its rows (`None` in exact mode, or when no such frame follows).
struct SweepBase<'a> {
    plan: FramePlan<'a>,
    film: Arc<Film>,
    /// Per row: what the decision to take it reads of it, and its non-finite samples.
    rows: Vec<(BaseRow, u64)>,
}

impl<'a> SweepBase<'a> {
    /// Render `scene` (the film [`render_scene`] gives), keeping per row what
    /// [`render_on_base`] needs when `keep_rows`.
    fn new(
        scene: &'a Scene,
        tracer: &'a dyn RayTracer,
        options: &RenderOptions,
        keep_rows: bool,
    ) -> Result<(Arc<Film>, Option<Self>), RenderError> {
        let plan = FramePlan::new(scene, tracer, options, None)?;
        let reads = plan.sun_reads().filter(|_| keep_rows);
        let (width, height) = plan.size();
        let Some(reads) = reads else {
            let (pixels, non_finite) = plan.shade_all(true);
            let stats = plan.stats(non_finite);
            return Ok((Arc::new(film_of(width, height, pixels, stats)), None));
        };
        let mut pixels = vec![[0.0f32; 4]; width as usize * height as usize];
        let rows: Vec<(BaseRow, u64)> = pixels
            .par_chunks_mut(width as usize)
            .enumerate()
            .map_init(
                || plan.scratch(),
                |scratch, (y, row)| {
                    let y = y as u32;
                    let bad = plan.shade_row(y, row, scratch);
                    let elevations = plan.row_elevations(y, scratch);
                    (plan.base_row(&reads, elevations), bad)
                },
            )
            .collect();
        let stats = plan.stats(rows.iter().map(|r| r.1).sum());
        let film = Arc::new(film_of(width, height, pixels, stats));
        let base = SweepBase {
            plan,
            film: Arc::clone(&film),
            rows,
        };
        Ok((film, Some(base)))
    }
}

fn film_of(width: u32, height: u32, pixels: Vec<[f32; 4]>, stats: RenderStats) -> Film {
    Film {
        width,
        height,
        pixels,
        stats,
    }
}

/// A frame held whole.
fn whole(film: Arc<Film>) -> FrameImage {
    FrameImage(Image::Whole(film))
}

/// Render `scene`, which differs from the base's scene only in its sun: the rows its sun
/// cannot change ([`FramePlan::copies_base_row`]) are the base's, the others are shaded. The
/// image of the film [`render_scene`] gives, and the number of rows shaded.
fn render_on_base<'a>(
    base: &SweepBase<'a>,
    scene: &'a Scene,
    tracer: &'a dyn RayTracer,
    options: &RenderOptions,
) -> Result<(FrameImage, u32), RenderError> {
    let plan = FramePlan::new(scene, tracer, options, Some(&base.plan))?;
    let Some(reads) = plan.sun_reads() else {
        let film = render_scene(scene, tracer, options)?;
        return Ok((whole(Arc::new(film)), scene.camera.height));
    };
    let width = plan.size().0 as usize;
    let mut kept_bad = 0;
    let mut rows = Vec::new();
    for (y, &(decision, base_bad)) in base.rows.iter().enumerate() {
        if plan.copies_base_row(&reads, &base.plan, &decision) {
            kept_bad += base_bad;
        } else {
            rows.push(y as u32);
        }
    }
    // Each shaded row is written whole: none reads what it starts as.
    let mut pixels = vec![[0.0f32; 4]; rows.len() * width];
    let shaded_bad: u64 = pixels
        .par_chunks_mut(width)
        .zip(&rows)
        .map_init(
            || plan.scratch(),
            |scratch, (row, &y)| plan.shade_row(y, row, scratch),
        )
        .sum();
    let shaded = rows.len() as u32;
    let image = FrameImage(Image::OnBase {
        base: Arc::clone(&base.film),
        rows,
        pixels,
        stats: plan.stats(kept_bad + shaded_bad),
    });
    Ok((image, shaded))
}

/// Whether `a` and `b` are the same scene but for their suns (both have one): then a frame of
/// one can be rendered on the other ([`render_on_base`]). `a_record`: `a`'s
/// [`record_without_sun`].
fn differ_only_in_sun(a: &Scene, a_record: &Option<String>, b: &Scene) -> bool {
    if a.sun.is_none() || b.sun.is_none() || a.cards.len() != b.cards.len() {
        return false;
    }
    let same = |x: &Arc<Texture>, y: &Arc<Texture>| Arc::ptr_eq(x, y) || x == y;
    let cards = a
        .cards
        .iter()
        .zip(&b.cards)
        .all(|(x, y)| same(&x.texture, &y.texture));
    let terrain = match (&a.terrain, &b.terrain) {
        (None, None) => true,
        (Some(x), Some(y)) => {
            Arc::ptr_eq(&x.dem, &y.dem)
                && Arc::ptr_eq(&x.gradients, &y.gradients)
                && match (&x.orthophoto, &y.orthophoto) {
                    (None, None) => true,
                    (Some(p), Some(q)) => same(&p.texture, &q.texture),
                    _ => false,
                }
        }
        _ => false,
    };
    // Everything else by its serialised record (exact for numbers), without the sun.
    cards && terrain && a_record.is_some() && *a_record == record_without_sun(b)
}

/// `scene`'s serialised record without its sun ([`differ_only_in_sun`]).
fn record_without_sun(scene: &Scene) -> Option<String> {
    let mut s = scene.clone();
    s.sun = None;
    serde_json::to_string(&s).ok()
}

/// Render every scene of `scenes` through one ray cache over `tracer` (module docs). The
/// scenes must all be renderable by `tracer` (same atmosphere, camera height, Earth radius and
/// highest card or terrain): then each frame's image is the film [`render_scene`] gives with
/// `tracer`. Frames that differ from the first only in their sun hold the rows they shaded over
/// the first frame's film, whose rows their sun cannot change (module docs, [`FrameImage`]).
/// `transfer`: also sample each frame's transfer curve at its farthest card's distance.
pub fn render_shared(
    scenes: &[Scene],
    tracer: &dyn RayTracer,
    options: &RenderOptions,
    transfer: bool,
) -> Result<Vec<SweepFrame>, RenderError> {
    let Some((first, rest)) = scenes.split_first() else {
        return Ok(Vec::new());
    };
    // The sun of a sweep crosses most of the fan's sky rays: trace them with the density
    // paths its transmittance integrates along them (not in exact mode, whose samples' rays
    // never ask for them).
    let scales = first
        .sun
        .filter(|_| !options.exact)
        .map(|_| first.sky.sun_extinction().scale_heights_m());
    let memo = MemoRays::new(tracer).with_density_paths(scales);
    let first_record = record_without_sun(first);
    let on_base: Vec<bool> = rest
        .iter()
        .map(|s| differ_only_in_sun(first, &first_record, s))
        .collect();
    let (film, base) = SweepBase::new(first, &memo, options, on_base.contains(&true))?;
    let columns = SharedColumns {
        fan: base.as_ref().and_then(|b| b.plan.fan()),
        ..SharedColumns::default()
    };
    // `first_camera`: the frame has the first frame's camera (it differs from it only in its
    // sun), so it shares the first frame's sun columns.
    let finish = |scene: &Scene, image: FrameImage, rows_shaded: u32, first_camera: bool| {
        let facts = if first_camera {
            frame_facts_with(scene, &memo, &|sun| columns.get(scene, &memo, sun))
        } else {
            frame_facts(scene, &memo)
        };
        SweepFrame {
            image,
            facts,
            transfer: farthest_card(scene)
                .filter(|_| transfer)
                .map(|card| transfer_samples(scene, &memo, card)),
            rows_shaded,
        }
    };
    let mut frames = vec![finish(first, whole(film), first.camera.height, true)];
    let rest: Vec<SweepFrame> = rest
        .par_iter()
        .zip(&on_base)
        .map(|(scene, &on_base)| {
            let (image, rows) = match &base {
                Some(base) if on_base => render_on_base(base, scene, &memo, options)?,
                _ => (
                    whole(Arc::new(render_scene(scene, &memo, options)?)),
                    scene.camera.height,
                ),
            };
            Ok(finish(scene, image, rows, on_base))
        })
        .collect::<Result<_, RenderError>>()?;
    frames.extend(rest);
    Ok(frames)
}

/// Render `scene` once per true sun elevation in `sun_elevations_rad` through one ray cache
/// ([`render_shared`]). Errors if the scene has no sun, an elevation is outside −90°…90°, or a
/// frame cannot be rendered.
pub fn render_sun_sweep(
    scene: &Scene,
    tracer: &dyn RayTracer,
    options: &RenderOptions,
    sun_elevations_rad: &[f64],
) -> Result<Vec<SweepFrame>, RenderError> {
    let sun = scene.sun.ok_or(RenderError::NoSun)?;
    let half_pi = std::f64::consts::FRAC_PI_2;
    if let Some(&bad) = sun_elevations_rad
        .iter()
        .find(|e| !(e.is_finite() && e.abs() <= half_pi))
    {
        return Err(RenderError::SunElevation(bad));
    }
    let scenes: Vec<Scene> = sun_elevations_rad
        .iter()
        .map(|&elevation_rad| {
            let mut s = scene.clone();
            s.sun = Some(Sun {
                elevation_rad,
                ..sun
            });
            s
        })
        .collect();
    render_shared(&scenes, tracer, options, false)
}

/// Great-circle angle (rad) between two directions given as (azimuth, elevation), by the
/// haversine formula (accurate for the small angles of a sun's disc).
fn angle_between(az1: f64, el1: f64, az2: f64, el2: f64) -> f64 {
    let s_el = (0.5 * (el1 - el2)).sin();
    let s_az = (0.5 * (az1 - az2)).sin();
    let h = s_el * s_el + el1.cos() * el2.cos() * s_az * s_az;
    2.0 * h.sqrt().min(1.0).asin()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn haversine_angle_matches_simple_cases() {
        let d = 1e-3;
        assert!((angle_between(0.0, 0.0, 0.0, d) - d).abs() < 1e-15);
        assert!((angle_between(0.0, 0.0, d, 0.0) - d).abs() < 1e-12);
        // At elevation 60° an azimuth step is shortened by cos 60°.
        let e = 60f64.to_radians();
        assert!((angle_between(0.0, e, d, e) - 0.5 * d).abs() < 1e-9);
    }
}
