//! Stage 5b (render) — the frame plan. In: a [`Scene`], a [`RayTracer`], [`RenderOptions`], and
//! optionally the plan of the same scene under another sun (a sun sweep's base frame). Out: a
//! [`FramePlan`] — the elevation fan, the tables and the [`Shader`] of one frame — that shades
//! any row of the film on its own: [`render_scene`](super::render_scene) shades every row, a sun
//! sweep (`super::sweep`) only the rows its sun can change.
//!
//! **What a plan shares with its base.** The sky, sea and transmittance tables and the terrain
//! view do not depend on the sun or on the fan; the sea fan and the facet table depend on the
//! fan only through its steepest grazing angle, the air paths only through its elevations. A
//! plan built on a base takes each of them from the base when those inputs are the same, bit
//! for bit, instead of building it again: the same values, so the frame is the one a plan built
//! alone gives. The fan (refined around the frame's own sun, from rays a shared ray cache
//! remembers), the sun's disc, its transmittance along the rays and its glitter or mirror image
//! on the sea are the frame's own.
//!
//! **Which rows the sun can change** ([`FramePlan::copies_base_row`]): a row's pixels are a
//! function of the fan's rays that its samples' elevations fall between, of the tables, and of
//! the sun only where a sample's interpolated ray may meet the sun's disc or show its glitter
//! or mirror image on the sea (every other test that a row's shading makes is of the tables and
//! the fan). So a row whose elevations read the same fan rays as the base's, in a plan whose
//! tables are the base's, and that may read the sun in neither frame, shades to the base's
//! pixels. Whether a row may read the sun is bounded per fan interval: an interpolated end lies
//! between the two rays' ends (same kind), or is one of them.

use std::io::IsTerminal;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use indicatif::{ParallelProgressIterator, ProgressBar, ProgressStyle};
use rayon::prelude::*;

use super::air_paths::AirPaths;
use super::elevation_fan::{ElevationFan, FanSpec};
use super::ray_model::{FanEnd, RayTracer};
use super::reflection::{FacetTable, Facets, Glint, Reflection, SeaFan, SlopeTable};
use super::sea_sun::SeaSunTable;
use super::shade::{
    AerialShading, AngleTable, ReflectedHaze, Shader, ViewCard, cos_range, wrap_pi,
};
use super::sun::SunTransmittance;
use super::terrain::{TerrainFrame, TerrainView};
use super::texture_box::TextureColumns;
use super::{
    FLAT_ROW_FRACTION, FlatRow, RenderError, RenderOptions, RenderStats, RowScratch, TracedSample,
    azimuth_span, card_columns_in_row, check_tracer_tolerance, elevation_range,
    row_may_meet_terrain, shade_fan_sample, shade_flat_row, shade_traced_sample, sun_band_rad,
    traced_grid,
};
use crate::scene::camera::{Camera, CameraFrame, FilmAzimuths};
use crate::scene::sky::{Extinction, Sky, SunDisc};
use crate::scene::{Scene, Texture, samples_per_pixel_root};

/// Range (m) of a sea fan traced only for the sun's mirror image (no card in view).
const MIN_SEA_FAN_RANGE_M: f64 = 1.0;

/// Everything one frame's rows are shaded from.
pub(super) struct FramePlan<'a> {
    frame: CameraFrame,
    width: u32,
    height: u32,
    /// Samples per pixel along each axis.
    n: u32,
    /// The elevation fan (`None` in exact mode).
    fan: Option<ElevationFan>,
    shader: Shader<'a>,
    /// Samples at or above this elevation see only sky ([`ElevationFan::clear_sky_from`]).
    clear_sky_from: f64,
    /// A row whose elevations span less than this is shaded at one elevation per band.
    flat_row_limit_rad: f64,
    tracer: &'a dyn RayTracer,
    camera_height_m: f64,
    need_sky_direction: bool,
    /// The sea's sun-independent tables, kept for plans built on this one.
    sea: SeaTables,
    /// Counters (all but the non-finite samples, counted while shading).
    stats: RenderStats,
    /// Whether every input of shading but the sun and the fan is the base's (module docs);
    /// true for a plan built alone.
    shares_base: bool,
    /// The camera, with the frame's azimuth span and elevation range, kept for plans built on
    /// this one.
    view: (Camera, Option<(f64, f64)>, (f64, f64)),
    /// The sky and its extinction along the sun's rays (when the scene has a sun), kept for
    /// plans built on this one.
    sun_extinction: Option<(Sky, Arc<Extinction>)>,
}

/// The sea's tables that do not depend on the sun, and the steepest grazing angle of the fan
/// they were built for.
#[derive(Clone)]
struct SeaTables {
    /// Bits of the fan's steepest grazing angle (`None`: no fan ray met the sea, or exact mode).
    key: Option<u64>,
    /// The sky by the elevation of a reflected ray, over [0, π/2].
    reflected_sky: Arc<AngleTable>,
    /// The sea's radiance by grazing angle.
    sea_table: Arc<AngleTable>,
    /// The sea fan and the facets (`None`: the sea shows no reflections).
    reflection: Option<(Option<Arc<SeaFan>>, Arc<Facets>)>,
}

/// The cards in view (by azimuth), nearest first, and the distances the tracer must report.
struct ViewCards<'a> {
    cards: Vec<ViewCard<'a>>,
    distances_m: Vec<f64>,
    /// Highest card top at each distance (m).
    max_top_m: Vec<f64>,
}

impl<'a> ViewCards<'a> {
    fn new(scene: &'a Scene, span: Option<(f64, f64)>, pixel_rad: f64) -> Self {
        let cam = &scene.camera;
        let radius = scene.earth_radius_m;
        let mut order: Vec<usize> = (0..scene.cards.len()).collect();
        order.sort_by(|&a, &b| {
            scene.cards[a]
                .distance_m
                .total_cmp(&scene.cards[b].distance_m)
        });
        let mut out = ViewCards {
            cards: Vec::new(),
            distances_m: Vec::new(),
            max_top_m: Vec::new(),
        };
        // A rough sea mirrors the cards' textures averaged over heights (once per image).
        let blurred = scene.sea.reflections && scene.sea.wave_slope_rad > 0.0;
        let mut columns = Vec::new();
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
            if out.distances_m.last() != Some(&c.distance_m) {
                out.distances_m.push(c.distance_m);
                out.max_top_m.push(top_m);
            }
            let k = out.distances_m.len() - 1;
            out.max_top_m[k] = out.max_top_m[k].max(top_m);
            out.cards.push(ViewCard {
                index: out.cards.len(),
                distance_index: k,
                distance_m: c.distance_m,
                offset_rad: wrap_pi(c.azimuth_rad - cam.heading_rad),
                half_width_rad,
                base_m: c.base_m,
                top_m,
                height_m: c.height_m,
                texture: &c.texture,
                columns: blurred.then(|| texture_columns(&mut columns, &c.texture)),
                reflected_haze: None,
            });
            if blurred && let Some(extinction) = scene.sky.extinction() {
                let card = out.cards.last_mut().expect("just pushed");
                card.reflected_haze = Some(ReflectedHaze::new(&extinction, radius, card));
            }
        }
        out
    }
}

/// The root n of the samples per pixel (n × n), after checking the options.
fn checked_samples_root(scene: &Scene, options: &RenderOptions) -> Result<u32, RenderError> {
    let spp = options
        .samples_per_pixel
        .unwrap_or(scene.camera.samples_per_pixel);
    let n = samples_per_pixel_root(spp).ok_or(RenderError::SamplesPerPixel(spp))?;
    if !(options.tolerance_px.is_finite() && options.tolerance_px > 0.0) {
        return Err(RenderError::Tolerance(options.tolerance_px));
    }
    check_tracer_tolerance(options.tolerance_m)?;
    Ok(n)
}

/// The terrain in view of `scene`, if it has terrain.
fn terrain_view<'a>(
    scene: &'a Scene,
    tracer: &'a dyn RayTracer,
    options: &RenderOptions,
    span: Option<(f64, f64)>,
    elevations: (f64, f64),
) -> Option<Arc<TerrainView<'a>>> {
    let cam = &scene.camera;
    scene.terrain.as_ref().and_then(|t| {
        let frame = TerrainFrame {
            camera_height_m: cam.height_m,
            heading_rad: cam.heading_rad,
            earth_radius_m: scene.earth_radius_m,
            azimuth_span_rad: span,
            elevation_range_rad: elevations,
            pixel_rad: cam.min_pixel_angle_rad(),
            tolerance_px: options.tolerance_px,
            max_depth: options.max_refine_depth,
            brightness: scene.sky.brightness,
            scale_heights_m: scene.sky.extinction().map(|e| e.scale_heights_m()),
        };
        let mut view = TerrainView::new(t, tracer, frame, options.exact)?;
        if scene.sea.reflections && scene.sea.wave_slope_rad > 0.0 {
            view.prepare_reflections();
        }
        Some(Arc::new(view))
    })
}

/// The lowest elevation from which samples see only sky: the fan's (none with a sun), above
/// every elevation that may meet the terrain.
fn clear_sky_from(
    scene: &Scene,
    fan: &ElevationFan,
    max_top_m: &[f64],
    terrain: Option<&TerrainView<'_>>,
) -> f64 {
    let mut from = if scene.sun.is_none() {
        fan.clear_sky_from(max_top_m)
    } else {
        f64::INFINITY
    };
    if let Some(t) = terrain
        && t.may_hit_rad.0 <= t.may_hit_rad.1
    {
        from = from.max(t.may_hit_rad.1.next_up());
    }
    from
}

/// What [`SeaTables::build`] needs of the frame.
struct SeaReflectionInputs<'a> {
    scene: &'a Scene,
    tracer: &'a dyn RayTracer,
    fan: Option<&'a ElevationFan>,
    elevations: (f64, f64),
    pixel_rad: f64,
    camera_height_m: f64,
    /// The card distances in view (m).
    distances_m: &'a [f64],
    /// The farthest ground distance of the terrain in view (m), if any.
    farthest_terrain_m: Option<f64>,
}

impl SeaTables {
    /// The fan-dependent tables for `inp` (the sea table spans grazing angles from 0, where a
    /// NaN grazing angle is shaded, to the steepest the frame can show: with a fan, the
    /// steepest fan ray, as interpolation stays between neighbours; per-sample tracing, 90°),
    /// with `reflected_sky` (the sky by elevation over [0, π/2]).
    fn build(inp: &SeaReflectionInputs<'_>, reflected_sky: Arc<AngleTable>) -> Self {
        let key = inp.fan.and_then(ElevationFan::max_grazing_rad);
        let sea_hi = key.map_or(std::f64::consts::FRAC_PI_2, |g| {
            g.min(std::f64::consts::FRAC_PI_2)
        });
        let sea = inp.scene.sea;
        let sky = Arc::clone(&reflected_sky);
        let sea_table = AngleTable::new(0.0, sea_hi, |g| sea.radiance_reflecting(g, |e| sky.at(e)));
        let reflection = sea_fan_and_facets(inp, &reflected_sky);
        SeaTables {
            key: key.map(f64::to_bits),
            reflected_sky,
            sea_table: Arc::new(sea_table),
            reflection,
        }
    }
}

/// The steepest grazing angle in the frame: the fan's, or in exact mode that of the frame's
/// lowest ray (Bouguer's invariant n(h)(R + h) cos e fixes cos g = n_c (R + h_c) cos α /
/// (n_0 R): the steepest launch meets the sea steepest).
fn max_grazing_rad(inp: &SeaReflectionInputs<'_>) -> Option<f64> {
    match inp.fan {
        Some(fan) => fan.max_grazing_rad(),
        None => {
            let ray = inp.tracer.trace(
                inp.camera_height_m,
                inp.elevations.0,
                inp.distances_m,
                false,
            );
            match ray.end {
                FanEnd::Ground { grazing_rad, .. } if grazing_rad.is_finite() => Some(grazing_rad),
                _ => None,
            }
        }
    }
}

/// The sea fan (when a card or terrain is in view, over the reflected elevations the frame's
/// grazing angles and the wave facets reach, or for a mirror sea's sun image) and the facets
/// (a rough sea's shares weight `reflected_sky`, the sky by elevation over [0, π/2]). `None`
/// when the scene turns reflections off or the frame shows no sea.
fn sea_fan_and_facets(
    inp: &SeaReflectionInputs<'_>,
    reflected_sky: &AngleTable,
) -> Option<(Option<Arc<SeaFan>>, Arc<Facets>)> {
    let scene = inp.scene;
    let sea = scene.sea;
    if !sea.reflections {
        return None;
    }
    let max_grazing = max_grazing_rad(inp)?;
    let half_pi = std::f64::consts::FRAC_PI_2;
    let sigma_along = sea.wave_slope_rad.tan() * std::f64::consts::FRAC_1_SQRT_2;
    let e_hi = (max_grazing + 8.0 * sigma_along)
        .min(half_pi)
        .max(inp.pixel_rad);
    let mirror = sea.wave_slope_rad == 0.0;
    // Elevation spacing: half a pixel for a mirror (straight rays' heights are linear in the
    // elevation, so interpolation is exact for them); an eighth of the rms facet slope σ′
    // otherwise (a rough sea's images are integrated over reflected elevations spread by ±8σ′,
    // with heights linear between the fan's rays).
    let step_rad = (0.5 * inp.pixel_rad).max(0.125 * sigma_along);
    // Without cards, a mirror sea still needs the fan's sky directions for the sun's image.
    let need_sky = mirror && scene.sun.is_some();
    let max_range_m = match (inp.distances_m.last().copied(), inp.farthest_terrain_m) {
        (Some(a), Some(b)) => Some(a.max(b)),
        (a, b) => a.or(b),
    }
    .or_else(|| need_sky.then_some(MIN_SEA_FAN_RANGE_M));
    // The air along reflected rays to the terrain is summed in the fan (cards take the chord).
    let density = inp
        .farthest_terrain_m
        .and(scene.sky.extinction())
        .map(|e| (e.scale_heights_m(), scene.earth_radius_m));
    let fan = max_range_m
        .and_then(|d| {
            let top_m = super::curved::cards_top_m(scene);
            SeaFan::build(inp.tracer, e_hi, step_rad, (d, top_m), need_sky, density)
        })
        .map(Arc::new);
    let facets = if mirror {
        Facets::Mirror(FacetTable::new(&sea, max_grazing))
    } else if fan.is_some() {
        Facets::Rough(SlopeTable::new(&sea, max_grazing, reflected_sky))
    } else {
        Facets::None
    };
    Some((fan, Arc::new(facets)))
}

/// The column integrals of `texture`, built once per image: `built` holds those built so far.
fn texture_columns(
    built: &mut Vec<(*const Texture, Arc<TextureColumns>)>,
    texture: &Arc<Texture>,
) -> Arc<TextureColumns> {
    let key = Arc::as_ptr(texture);
    if let Some((_, c)) = built.iter().find(|(k, _)| *k == key) {
        return c.clone();
    }
    let c = Arc::new(TextureColumns::new(texture));
    built.push((key, c.clone()));
    c
}

/// The sun's glitter on a rough sea: its light at a sea point comes along its own curved ray
/// from there (a ray skimming a surface duct crosses far more air than any air-mass formula of
/// its elevation gives), at the apparent elevation the sea-level refraction of its true
/// elevation there gives. The table of that refraction depends on the atmosphere and the sky
/// alone. `base`: the glitter of the base frame (the same scene under another sun), if any: its table
/// is taken, and its azimuth bounds when its sun has the same azimuth (they depend only on the
/// camera, the frame's elevations and the sun's azimuth).
fn glint(
    scene: &Scene,
    tracer: &dyn RayTracer,
    base: Option<&Glint>,
    elevations: (f64, f64),
) -> Option<Glint> {
    let sun = scene.sun.filter(|_| scene.sea.wave_slope_rad != 0.0)?;
    let at_sea = base.map_or_else(
        || Arc::new(SeaSunTable::build(tracer, &scene.sky.sun_extinction())),
        |b| Arc::clone(&b.at_sea),
    );
    let cos_azimuth = match base {
        Some(b) if b.sun.azimuth_rad.to_bits() == sun.azimuth_rad.to_bits() => b.cos_azimuth,
        _ => cos_azimuth_range(&scene.camera, sun.azimuth_rad, elevations),
    };
    let r = 0.5 * sun.angular_diameter_rad;
    let solid_angle = std::f64::consts::PI * r * r * (1.0 - sun.limb_darkening / 3.0);
    Some(Glint {
        sun,
        at_sea,
        cos_azimuth,
        irradiance: [sun.intensity * solid_angle; 3],
        radiance_cap: [sun.intensity; 3],
    })
}

/// Bounds on cos φ over the frame of `camera`, φ the azimuth of a film point from the sun's
/// `sun_azimuth_rad`: from film points one pixel apart along the film's edges (a direction's
/// azimuth has no extreme inside a frame that holds neither the zenith nor the nadir; with
/// one, whose frame reaches `elevations`, any azimuth), widened by twice the largest step
/// between neighbouring points.
fn cos_azimuth_range(camera: &Camera, sun_azimuth_rad: f64, elevations: (f64, f64)) -> (f64, f64) {
    const POLE_MARGIN_RAD: f64 = 1e-3;
    let half_pi = std::f64::consts::FRAC_PI_2;
    if !(elevations.0 > -half_pi + POLE_MARGIN_RAD && elevations.1 < half_pi - POLE_MARGIN_RAD) {
        return (-1.0, 1.0);
    }
    let frame = camera.frame();
    let (w, h) = (f64::from(camera.width), f64::from(camera.height));
    let centre = frame.direction(0.5 * w, 0.5 * h).0;
    let offset = |x: f64, y: f64| {
        // φ relative to the centre's, unwrapped into (−π, π] about it.
        wrap_pi(frame.direction(x, y).0 - centre)
    };
    // Around the film's edge: the offsets' bounds and the largest step between neighbours.
    let (w_px, h_px) = (camera.width, camera.height);
    let edge = (0..w_px)
        .map(|x| (f64::from(x), 0.0))
        .chain((0..h_px).map(|y| (w, f64::from(y))))
        .chain((0..w_px).map(|x| (w - f64::from(x), h)))
        .chain((0..h_px).map(|y| (0.0, h - f64::from(y))));
    let (mut lo, mut hi, mut step) = (0.0f64, 0.0f64, 0.0f64);
    let mut last = offset(0.0, 0.0);
    for (x, y) in edge.chain(std::iter::once((0.0, 0.0))) {
        let d = offset(x, y);
        (lo, hi, step) = (lo.min(d), hi.max(d), step.max((d - last).abs()));
        last = d;
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    let pad = 2.0 * step;
    // φ = sun − pixel over [sun − centre − hi − pad, sun − centre − lo + pad].
    let base = sun_azimuth_rad - centre;
    let (a, b) = (base - hi - pad, base - lo + pad);
    cos_range((a, a.cos()), (b, b.cos()))
}

/// The sea's reflections of `scene` from its sun-independent `tables`, with the sun's glitter
/// (`glint`, found beforehand) or mirror image.
fn sea_reflection(scene: &Scene, tables: &SeaTables, glint: Option<Glint>) -> Option<Reflection> {
    let (fan, facets) = tables.reflection.clone()?;
    let mirror = scene.sea.wave_slope_rad == 0.0;
    Some(Reflection {
        sea: scene.sea,
        sky: scene.sky,
        earth_radius_m: scene.earth_radius_m,
        fan,
        sky_table: Arc::clone(&tables.reflected_sky),
        facets,
        glint,
        mirror_sun: scene
            .sun
            .filter(|_| mirror)
            .map(|sun| (sun, SunDisc::new(&sun))),
    })
}

/// What a plan is built from: the scene, its tracer and options, and the frame's geometry.
struct PlanInputs<'a> {
    scene: &'a Scene,
    tracer: &'a dyn RayTracer,
    options: RenderOptions,
    elevations: (f64, f64),
    pixel_rad: f64,
}

impl<'a> PlanInputs<'a> {
    /// The spec of the frame's elevation fan, for the cards in `view`.
    fn fan_spec(&self, view: &ViewCards<'_>) -> FanSpec {
        let cam = &self.scene.camera;
        FanSpec {
            camera_height_m: cam.height_m,
            distances_m: view.distances_m.clone(),
            max_top_m: view.max_top_m.clone(),
            need_sky_direction: self.scene.sun.is_some(),
            sun_band_rad: self.scene.sun.map(|s| sun_band_rad(&s, self.pixel_rad)),
            elevation_range_rad: self.elevations,
            // The smallest pixel of the frame (its corners, for a wide angle), so the fan's
            // sub-pixel bound holds everywhere, not only at the centre.
            pixel_rad: cam.min_pixel_angle_rad(),
            tolerance_px: self.options.tolerance_px,
            max_depth: self.options.max_refine_depth,
        }
    }

    /// The fan (none in exact mode; built on the base's fan when there is one, which the same
    /// tracer traced: [`ElevationFan::build_on`]) and the sky table: the base's table, or built
    /// while the fan is traced (it needs no fan).
    fn fan_and_sky(
        &self,
        spec: &FanSpec,
        base: Option<&FramePlan<'a>>,
    ) -> (Option<ElevationFan>, Arc<AngleTable>) {
        let build_fan = || (!self.options.exact).then(|| ElevationFan::build(self.tracer, spec));
        match base {
            Some(b) => {
                let fan = match &b.fan {
                    Some(f) if !self.options.exact => {
                        Some(ElevationFan::build_on(self.tracer, spec, f))
                    }
                    _ => build_fan(),
                };
                (fan, Arc::clone(&b.shader.sky_table))
            }
            None => {
                let (sky, (lo, hi)) = (self.scene.sky, self.elevations);
                // The optical depths once per frame, not once per table entry (same values).
                let depths = sky.optical_depths();
                rayon::join(build_fan, || {
                    Arc::new(AngleTable::new(lo, hi, |e| {
                        sky.radiance_with_depths(e, depths)
                    }))
                })
            }
        }
    }

    /// The sea's tables for `inp`: the base's when its fan's steepest grazing angle is this
    /// fan's, else built (and then the tables are not the base's: the second value).
    fn sea_tables(
        &self,
        inp: &SeaReflectionInputs<'_>,
        base: Option<&FramePlan<'a>>,
    ) -> (SeaTables, bool) {
        let key = inp
            .fan
            .and_then(ElevationFan::max_grazing_rad)
            .map(f64::to_bits);
        if let Some(b) = base.filter(|b| b.sea.key == key) {
            return (b.sea.clone(), true);
        }
        let reflected_sky = match base {
            Some(b) => Arc::clone(&b.sea.reflected_sky),
            None => {
                let sky = self.scene.sky;
                let depths = sky.optical_depths();
                Arc::new(AngleTable::new(0.0, std::f64::consts::FRAC_PI_2, |e| {
                    sky.radiance_with_depths(e, depths)
                }))
            }
        };
        (SeaTables::build(inp, reflected_sky), base.is_none())
    }

    /// The aerial perspective, its rays' paths integrated at `alphas` (the fan's elevations)
    /// or taken from the base when its fan has the same elevations; with whether the paths
    /// are present exactly when the base's are.
    fn aerial(
        &self,
        view: &ViewCards<'_>,
        alphas: &[f64],
        base: Option<&FramePlan<'a>>,
    ) -> (Option<AerialShading>, bool) {
        let Some(extinction) = self.scene.sky.extinction() else {
            return (None, true);
        };
        let base_paths = base.map(|b| b.shader.aerial.as_ref().and_then(|a| a.paths.clone()));
        let same_rays = base.and_then(|b| b.fan.as_ref()).is_some_and(|f| {
            let bits = |a: &f64| a.to_bits();
            f.elevations_rad()
                .iter()
                .map(bits)
                .eq(alphas.iter().map(bits))
        });
        let cam = &self.scene.camera;
        let paths = match base_paths.clone() {
            Some(paths) if same_rays => paths,
            _ => AirPaths::build(
                self.tracer,
                cam.height_m,
                &view.distances_m,
                extinction.scale_heights_m(),
                alphas,
            )
            .map(Arc::new),
        };
        let shares = base_paths.is_none_or(|b| b.is_some() == paths.is_some());
        let aerial = AerialShading {
            extinction,
            camera_height_m: cam.height_m,
            earth_radius_m: self.scene.earth_radius_m,
            distances_m: view.distances_m.clone(),
            paths,
        };
        (Some(aerial), shares)
    }
}

impl<'a> FramePlan<'a> {
    /// Plan the frame of `scene` through `tracer`. With `base` (a plan of the same scene under
    /// another sun, through the same tracer and options) the sun-independent tables are taken
    /// from it where their inputs are the same (module docs); the plan is the same either way.
    pub(super) fn new(
        scene: &'a Scene,
        tracer: &'a dyn RayTracer,
        options: &RenderOptions,
        base: Option<&FramePlan<'a>>,
    ) -> Result<Self, RenderError> {
        let n = checked_samples_root(scene, options)?;
        let base = base.filter(|_| !options.exact);
        let cam = &scene.camera;
        let frame = cam.frame();
        let pixel_rad = 1.0 / frame.focal_px;
        let (width, height) = (cam.width, cam.height);
        // The frame's border directions: the base's when the camera is the same.
        let (span, elevations) = match base.map(|b| b.view).filter(|v| v.0 == *cam) {
            Some((_, span, elevations)) => (span, elevations),
            None => (
                azimuth_span(&frame, width, height, cam.heading_rad),
                elevation_range(&frame, width, height, pixel_rad),
            ),
        };
        let view = ViewCards::new(scene, span, pixel_rad);
        let inputs = PlanInputs {
            scene,
            tracer,
            options: options.clone(),
            elevations,
            pixel_rad,
        };
        let terrain = match base {
            Some(b) => b.shader.terrain.clone(),
            None => terrain_view(scene, tracer, options, span, inputs.elevations),
        };
        let (fan, sky_table) = inputs.fan_and_sky(&inputs.fan_spec(&view), base);
        let clear_sky_from = fan.as_ref().map_or(f64::INFINITY, |f| {
            clear_sky_from(scene, f, &view.max_top_m, terrain.as_deref())
        });
        let sea_inputs = SeaReflectionInputs {
            scene,
            tracer,
            fan: fan.as_ref(),
            elevations: inputs.elevations,
            pixel_rad,
            camera_height_m: cam.height_m,
            distances_m: &view.distances_m,
            farthest_terrain_m: terrain.as_ref().and_then(|t| t.distances_m.last().copied()),
        };
        // The rays whose paths the sun and the haze integrate: the fan's, or a grid in exact
        // mode.
        let needs_paths = scene.sun.is_some() || scene.sky.aerial.is_some();
        let traced = match &fan {
            Some(fan) if needs_paths => fan.rays_and_ends(),
            None if needs_paths => traced_grid(tracer, cam.height_m, inputs.elevations, pixel_rad),
            _ => Vec::new(),
        };
        // The sun's glitter needs its own rays from the sea, not the sea's tables: found while
        // they are built (or the base frame's, which has the same atmosphere and sky).
        let base_glint = base
            .and_then(|b| b.shader.reflection.as_ref())
            .and_then(|r| r.glint.as_ref());
        let ((sea, same_sea), glint) = rayon::join(
            || inputs.sea_tables(&sea_inputs, base),
            || {
                scene
                    .sea
                    .reflections
                    .then(|| glint(scene, tracer, base_glint, inputs.elevations))
                    .flatten()
            },
        );
        let alphas: Vec<f64> = traced.iter().map(|(a, _)| *a).collect();
        let (aerial, same_aerial) = inputs.aerial(&view, &alphas, base);
        // The sun's extinction: the base's when the sky is the same.
        let sun_extinction = scene.sun.map(|_| {
            let shared = base
                .and_then(|b| b.sun_extinction.as_ref())
                .filter(|(sky, _)| *sky == scene.sky);
            match shared {
                Some((_, e)) => Arc::clone(e),
                None => Arc::new(scene.sky.sun_extinction()),
            }
        });
        let shares_base = base.is_none_or(|b| {
            b.clear_sky_from.to_bits() == clear_sky_from.to_bits() && same_sea && same_aerial
        });
        let mut stats = RenderStats {
            cards_in_view: view.cards.len(),
            fan_rays: fan.as_ref().map_or(0, ElevationFan::len),
            fan_depth: fan.as_ref().map_or(0, |f| f.max_depth_reached),
            air_path_rays: aerial
                .as_ref()
                .and_then(|a| a.paths.as_ref())
                .map_or(0, |p| p.len()),
            ..RenderStats::default()
        };
        let shader = inputs.shader(ShaderParts {
            view,
            terrain,
            sky_table,
            sea: &sea,
            glint,
            aerial,
            traced: &traced,
            sun_extinction: sun_extinction.as_deref(),
            base,
            frame,
        });
        stats.sea_fan_rays = shader
            .reflection
            .as_ref()
            .and_then(|r| r.fan.as_ref())
            .map_or(0, |f| f.len());
        stats.sun_rays = shader.sun_path.as_ref().map_or(0, SunTransmittance::len);
        Ok(FramePlan {
            frame,
            width,
            height,
            n,
            fan,
            shader,
            clear_sky_from,
            flat_row_limit_rad: FLAT_ROW_FRACTION
                * options.tolerance_px
                * cam.min_pixel_angle_rad(),
            tracer,
            camera_height_m: cam.height_m,
            need_sky_direction: scene.sun.is_some(),
            sea,
            stats,
            shares_base,
            view: (*cam, span, elevations),
            sun_extinction: sun_extinction.map(|e| (scene.sky, e)),
        })
    }
}

/// The parts of a frame's [`Shader`] built before it.
struct ShaderParts<'a, 'b> {
    view: ViewCards<'a>,
    terrain: Option<Arc<TerrainView<'a>>>,
    sky_table: Arc<AngleTable>,
    sea: &'b SeaTables,
    /// The sun's glitter on a rough sea ([`glint`]), when the scene has sea reflections.
    glint: Option<Glint>,
    aerial: Option<AerialShading>,
    /// The rays the sun's transmittance is integrated along, with their ends.
    traced: &'b [(f64, FanEnd)],
    /// The sky's extinction along the sun's rays ([`Sky::sun_extinction`]), when the scene has
    /// a sun.
    sun_extinction: Option<&'b Extinction>,
    base: Option<&'b FramePlan<'a>>,
    /// The camera's frame (basis and focal length).
    frame: CameraFrame,
}

impl<'a> PlanInputs<'a> {
    /// The frame's shader from its `parts`, with the sun's own: its disc, its transmittance
    /// along the rays, and its glitter or mirror image on the sea.
    fn shader(&self, parts: ShaderParts<'a, '_>) -> Shader<'a> {
        let (scene, tracer) = (self.scene, self.tracer);
        let (sky, cam) = (scene.sky, &scene.camera);
        let sun_path = scene
            .sun
            .zip(parts.sun_extinction)
            .and_then(|(sun, extinction)| {
                let band = sun_band_rad(&sun, self.pixel_rad);
                SunTransmittance::build(tracer, cam.height_m, extinction, band, parts.traced)
            });
        let (lo, hi) = self.elevations;
        let sun_transmittance = scene.sun.map(|_| {
            parts
                .base
                .and_then(|b| b.shader.sun_transmittance.clone())
                .unwrap_or_else(|| Arc::new(AngleTable::new(lo, hi, |e| sky.transmittance(e))))
        });
        // The film's azimuths: the base frame's when the camera is the same.
        let frame = parts.frame;
        let azimuths = parts
            .base
            .map(|b| &b.shader.azimuths)
            .filter(|a| *a.frame() == frame)
            .map_or_else(
                || Arc::new(FilmAzimuths::new(frame, cam.width, cam.height)),
                Arc::clone,
            );
        Shader {
            azimuths,
            distances_m: parts.view.distances_m,
            reflection: sea_reflection(scene, parts.sea, parts.glint),
            terrain: parts.terrain,
            cards: parts.view.cards,
            sky_table: parts.sky_table,
            sea_table: Arc::clone(&parts.sea.sea_table),
            sun: scene.sun.as_ref().map(SunDisc::new),
            sun_transmittance,
            sun_path,
            heading_rad: cam.heading_rad,
            // A lost (trapped) ray travels in the lowest air: show the horizon sky.
            fallback: sky.radiance(0.0),
            aerial: parts.aerial,
        }
    }
}

impl FramePlan<'_> {
    /// The elevation fan (`None` in exact mode).
    pub(super) fn fan(&self) -> Option<&ElevationFan> {
        self.fan.as_ref()
    }

    /// Film width and height (pixels).
    pub(super) fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The frame's counters, with `non_finite` samples.
    pub(super) fn stats(&self, non_finite: u64) -> RenderStats {
        RenderStats {
            non_finite_samples: non_finite,
            sample_rays: if self.fan.is_none() {
                u64::from(self.width) * u64::from(self.height) * u64::from(self.n * self.n)
            } else {
                0
            },
            ..self.stats
        }
    }

    /// Buffers for shading rows of this frame (one per thread).
    pub(super) fn scratch(&self) -> RowScratch {
        let n_dist = self.shader.distances_m.len();
        RowScratch::new(self.width as usize * (self.n * self.n) as usize, n_dist)
    }

    /// Every row of the film, in parallel (a progress bar unless `quiet` or stderr is not a
    /// terminal): the pixels, and the number of samples whose shading was not finite.
    pub(super) fn shade_all(&self, quiet: bool) -> (Vec<[f32; 4]>, u64) {
        let bar = if quiet || !std::io::stderr().is_terminal() {
            ProgressBar::hidden()
        } else {
            let bar = ProgressBar::new(u64::from(self.height));
            if let Ok(style) = ProgressStyle::with_template(
                "{spinner} rendering [{bar:40}] {pos}/{len} rows ({eta})",
            ) {
                bar.set_style(style);
            }
            bar
        };
        let non_finite = AtomicU64::new(0);
        let mut pixels = vec![[0.0f32; 4]; self.width as usize * self.height as usize];
        pixels
            .par_chunks_mut(self.width as usize)
            .enumerate()
            .progress_with(bar.clone())
            .for_each_init(
                || self.scratch(),
                |scratch, (y, row)| {
                    let bad = self.shade_row(y as u32, row, scratch);
                    non_finite.fetch_add(bad, Ordering::Relaxed);
                },
            );
        bar.finish_and_clear();
        (pixels, non_finite.into_inner())
    }

    /// Shade row `y` into `row` (its `width` pixels): flat bands where it can
    /// ([`shade_flat_row`]), else sample by sample. Returns the number of samples whose shading
    /// was not finite (replaced by the fallback colour).
    pub(super) fn shade_row(&self, y: u32, row: &mut [[f32; 4]], scratch: &mut RowScratch) -> u64 {
        let non_finite = AtomicU64::new(0);
        let (frame, shader, width, n) = (&self.frame, &self.shader, self.width, self.n);
        if let Some(fan) = &self.fan
            && n == 1
            && shader
                .terrain
                .as_ref()
                .is_none_or(|t| !row_may_meet_terrain(t, frame, y, width))
            && shade_flat_row(
                &FlatRow {
                    frame,
                    fan,
                    shader,
                    clear_sky_from: self.clear_sky_from,
                    limit_rad: self.flat_row_limit_rad,
                    y,
                },
                row,
                scratch,
                &non_finite,
            )
        {
            return non_finite.into_inner();
        }
        scratch.directions(frame, y, width, n);
        let RowScratch {
            dirs,
            heights,
            card_columns,
            ..
        } = scratch;
        // Which pixels' rays may meet a card: all of them when tracing per sample; with a fan,
        // those in the column range of a card that the row's rays can reach.
        card_columns.clear();
        match &self.fan {
            None => card_columns.push((0, width as usize)),
            Some(fan) => {
                let (lo, hi) = dirs
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
                        (a.min(d.elevation_rad), b.max(d.elevation_rad))
                    });
                card_columns.extend(
                    shader.cards.iter().filter_map(|card| {
                        card_columns_in_row(card, fan, (lo, hi), frame, y, width)
                    }),
                );
            }
        }
        let traced_sample = TracedSample {
            tracer: self.tracer,
            camera_height_m: self.camera_height_m,
            distances_m: &shader.distances_m,
            need_sky_direction: self.need_sky_direction,
        };
        let samples = (n * n) as usize;
        let inv_samples = 1.0 / samples as f64;
        for (x, px) in row.iter_mut().enumerate() {
            let may_meet_card = card_columns.iter().any(|&(a, b)| (a..b).contains(&x));
            let mut acc = [0.0f64; 3];
            for dir in &dirs[x * samples..(x + 1) * samples] {
                let alpha = dir.elevation_rad;
                let c = match &self.fan {
                    Some(_) if alpha >= self.clear_sky_from => shader.sky_table.at(alpha),
                    Some(fan) => shade_fan_sample(shader, fan, dir, may_meet_card, heights),
                    None => shade_traced_sample(shader, &traced_sample, dir),
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
        non_finite.into_inner()
    }
}

/// Which intervals of a plan's fan hold rays that may read the sun ([`FramePlan::sun_reads`]).
pub(super) struct SunReads {
    /// Intervals below each interval index that may read the sun (cumulative count).
    prefix: Vec<u32>,
}

impl SunReads {
    /// Whether a lookup in the plan's fan of an elevation between those in intervals `i` and
    /// `j` ([`ElevationFan::intervals_of`]) may read the sun.
    fn any(&self, (i, j): (usize, usize)) -> bool {
        let (i, j) = (i.min(j), i.max(j));
        let last = self.prefix.len() - 1;
        self.prefix[(j + 1).min(last)] > self.prefix[i.min(last)]
    }
}

/// What deciding whether to copy a row of a base plan reads of the base, the same for every
/// plan built on it ([`FramePlan::base_row`]).
#[derive(Clone, Copy)]
pub(super) struct BaseRow {
    /// The lowest and highest elevation (rad) the row's lookups read
    /// ([`FramePlan::row_elevations`]).
    elevations: (f64, f64),
    /// The base fan's intervals holding them (`None`: the base has no fan).
    intervals: Option<(usize, usize)>,
    /// Whether the row may read the sun in the base.
    reads_sun: bool,
}

impl FramePlan<'_> {
    /// Bounds on the elevations (rad) at which shading row `y` looks anything up: its
    /// samples' and its flat bands' (−∞ and +∞ when one is not finite). With one sample per
    /// pixel, whose samples and bands are at pixel centres, the camera's bounds on those
    /// ([`CameraFrame::row_elevation_range`]); else the samples' lowest and highest. The same
    /// for every frame of one camera and sample count.
    pub(super) fn row_elevations(&self, y: u32, scratch: &mut RowScratch) -> (f64, f64) {
        if self.n == 1 {
            return self.frame.row_elevation_range(y, self.width);
        }
        scratch.directions(&self.frame, y, self.width, self.n);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut add = |e: f64| {
            if e.is_finite() {
                (lo, hi) = (lo.min(e), hi.max(e));
            } else {
                (lo, hi) = (f64::NEG_INFINITY, f64::INFINITY);
            }
        };
        scratch.dirs.iter().for_each(|d| add(d.elevation_rad));
        (lo, hi)
    }

    /// For each fan interval, whether a ray interpolated in it may read the sun: meet the
    /// disc's band ([`Shader::may_meet_sun`]) or show the sun on the sea
    /// ([`Shader::may_meet_glint`]). `None` without a fan (exact mode).
    pub(super) fn sun_reads(&self) -> Option<SunReads> {
        let fan = self.fan.as_ref()?;
        let last = fan.len() - 1;
        let mut prefix = vec![0];
        let mut count = 0;
        for i in 0..last.max(1) {
            let (a, b) = (fan.ray_end(i), fan.ray_end((i + 1).min(last)));
            count += u32::from(self.ends_may_read_sun(a, b));
            prefix.push(count);
        }
        Some(SunReads { prefix })
    }

    /// Whether a ray interpolated between ends `a` and `b` may read the sun: one of the two
    /// ends when they differ in kind, else an end between them.
    fn ends_may_read_sun(&self, a: FanEnd, b: FanEnd) -> bool {
        let sky = |lo: f64, hi: f64| {
            self.shader
                .sun
                .as_ref()
                .is_some_and(|s| s.may_meet_range(lo, hi))
        };
        let sea = |g: (f64, f64), d: (f64, f64)| {
            self.shader
                .reflection
                .as_ref()
                .is_some_and(|r| r.may_show_sun_range(g, d))
        };
        let end = |e: FanEnd| match e {
            FanEnd::Sky { elevation_rad: x } => sky(x, x),
            FanEnd::Ground {
                distance_m: d,
                grazing_rad: g,
            } => sea((g, g), (d, d)),
            FanEnd::Trapped | FanEnd::Lost => false,
        };
        match (a, b) {
            (FanEnd::Sky { elevation_rad: x }, FanEnd::Sky { elevation_rad: y }) => {
                sky(x.min(y), x.max(y))
            }
            (
                FanEnd::Ground {
                    distance_m: d0,
                    grazing_rad: g0,
                },
                FanEnd::Ground {
                    distance_m: d1,
                    grazing_rad: g1,
                },
            ) => sea((g0.min(g1), g0.max(g1)), (d0.min(d1), d0.max(d1))),
            (a, b) => end(a) || end(b),
        }
    }

    /// What [`Self::copies_base_row`] reads of this plan's row whose lookups span
    /// `elevations` ([`Self::row_elevations`]), with `reads` this plan's
    /// [`Self::sun_reads`].
    pub(super) fn base_row(&self, reads: &SunReads, elevations: (f64, f64)) -> BaseRow {
        let intervals = self
            .fan
            .as_ref()
            .map(|f| f.intervals_of(elevations.0, elevations.1));
        BaseRow {
            elevations,
            intervals,
            reads_sun: intervals.is_none_or(|i| reads.any(i)),
        }
    }

    /// Whether row `y` of this plan shades to the pixels of row `y` of `base` (the plan this
    /// one was built on), with `reads` this plan's [`Self::sun_reads`] and `row` what
    /// [`Self::base_row`] of `base` gives for the row: the tables are the base's, the row
    /// reads the same fan rays in both, and may read the sun in neither (module docs).
    pub(super) fn copies_base_row(
        &self,
        reads: &SunReads,
        base: &FramePlan<'_>,
        row: &BaseRow,
    ) -> bool {
        let (Some(fan), Some(base_fan), Some(theirs)) = (&self.fan, &base.fan, row.intervals)
        else {
            return false;
        };
        if !self.shares_base
            || (self.width, self.height, self.n) != (base.width, base.height, base.n)
            || row.reads_sun
        {
            return false;
        }
        let mine = fan.intervals_of(row.elevations.0, row.elevations.1);
        !reads.any(mine) && fan.same_rays_in(base_fan, mine, theirs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::reflection::PartsCache;
    use crate::render::{RenderOptions, flat_bands};

    /// The frame's elevations, from its film's edges (enough for these pole-free frames).
    fn elevations_of(camera: &Camera) -> (f64, f64) {
        let frame = camera.frame();
        let (w, h) = (f64::from(camera.width), f64::from(camera.height));
        let e = [
            (0.0, 0.0),
            (w, 0.0),
            (0.0, h),
            (w, h),
            (0.5 * w, 0.0),
            (0.5 * w, h),
        ]
        .map(|(x, y)| frame.direction(x, y).1);
        e.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            })
    }

    /// fig01's ships over its wind-roughened sea, `width` × `height` at 1 sample per pixel.
    fn fig01_plan_inputs(width: u32, height: u32) -> (Scene, RenderOptions) {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/data/scenes/fig01_horizon_straight.toml"
        );
        let mut scene = Scene::from_file(std::path::Path::new(path)).expect("scene");
        (scene.camera.width, scene.camera.height) = (width, height);
        let options = RenderOptions {
            samples_per_pixel: Some(1),
            quiet: true,
            ..RenderOptions::default()
        };
        (scene, options)
    }

    #[test]
    fn a_bands_cached_mirror_images_are_each_samples_own() {
        let (scene, options) = fig01_plan_inputs(480, 270);
        let tracer = crate::render::prepare_tracer(&scene, None, &options).expect("tracer");
        let plan = FramePlan::new(&scene, tracer.as_ref(), &options, None).expect("plan");
        let (fan, shader) = (plan.fan.as_ref().expect("fan"), &plan.shader);
        let mut heights = vec![None; shader.distances_m.len()];
        let (mut compared, mut mirrored) = (0, 0);
        for y in 0..plan.height {
            let film_y = f64::from(y) + 0.5;
            let bands = flat_bands(&plan.frame, y, plan.width, plan.flat_row_limit_rad);
            let mut cache = PartsCache::default();
            for (k, &(start, alpha)) in bands.iter().flatten().enumerate() {
                let FanEnd::Ground {
                    grazing_rad,
                    distance_m,
                } = fan.interpolate(alpha, &mut heights)
                else {
                    continue;
                };
                // The band's columns, both halves, left to right as a row is shaded.
                let w = plan.width as usize;
                let end = bands.iter().flatten().nth(k + 1).map_or(w, |b| b.0);
                for x in (w - end..(w - start).min(w / 2)).chain(start..end) {
                    let dir = plan
                        .frame
                        .view_direction_at_elevation(x as f64 + 0.5, film_y, alpha);
                    let Some(got) =
                        shader.band_reflections(&dir, grazing_rad, distance_m, k, &mut cache)
                    else {
                        continue;
                    };
                    let want = shader.sea_reflections(&dir, grazing_rad, distance_m, false);
                    assert_eq!(
                        got.map(f64::to_bits),
                        want.map(f64::to_bits),
                        "row {y} column {x}"
                    );
                    compared += 1;
                    mirrored += usize::from(got.iter().any(|&v| v.abs() > 1e-4));
                }
            }
        }
        assert!(
            compared > 10_000 && mirrored > 1_000,
            "{compared} {mirrored}"
        );
    }

    /// One flat band of a row that may show the sun, as [`BandColumns::fill_band`] filled it.
    struct SunBand<'p> {
        y: u32,
        alpha: f64,
        sun: crate::render::band_sun::BandSun,
        background: [f64; 3],
        /// The band's two runs of columns and, for each, the span outside of which the fill
        /// left +0.
        runs: [((usize, usize), (usize, usize)); 2],
        /// The row's sun additions (only the band's columns are set).
        out: &'p [[f64; 3]],
    }

    /// The strips scene at 400×200, one sample per pixel, with its sun at `sun_deg`: its plan,
    /// and each of its flat bands that may show the sun, filled, passed to `each`.
    fn strips_sun_bands(sun_deg: f64, each: impl FnMut(&FramePlan<'_>, &SunBand<'_>)) {
        sun_bands("fig12b_novaya_zemlya_strips.toml", sun_deg, each);
    }

    /// [`strips_sun_bands`] of the shipped scene `name` (given a sun if it has none).
    fn sun_bands(name: &str, sun_deg: f64, mut each: impl FnMut(&FramePlan<'_>, &SunBand<'_>)) {
        use crate::render::band_sun::{BandColumns, BandSun};
        let dir = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/data/scenes"));
        let path = dir.join(name);
        let mut text = std::fs::read_to_string(&path).expect("scene");
        if !text.contains("[sun]") {
            text.push_str("\n[sun]\nelevation_deg = 0.0\n");
        }
        let mut scene = Scene::from_toml_str(&text, dir, &path).expect("scene");
        (scene.camera.width, scene.camera.height) = (400, 200);
        scene.sun.as_mut().expect("sun").elevation_rad = sun_deg.to_radians();
        let loaded = scene.atmosphere.load().expect("atmosphere");
        let refractive = loaded.as_ref().map(|a| &a.refractive);
        let options = RenderOptions {
            samples_per_pixel: Some(1),
            quiet: true,
            ..RenderOptions::default()
        };
        let tracer = crate::render::prepare_tracer(&scene, refractive, &options).expect("tracer");
        let width = scene.camera.width as usize;
        let plan = FramePlan::new(&scene, tracer.as_ref(), &options, None).expect("plan");
        let (fan, shader) = (plan.fan.as_ref().expect("fan"), &plan.shader);
        let mut heights = vec![None; shader.distances_m.len()];
        let mut out = vec![[f64::NAN; 3]; width];
        for y in 0..plan.height {
            let film_y = f64::from(y) + 0.5;
            let bands = flat_bands(&plan.frame, y, plan.width, plan.flat_row_limit_rad);
            let bands: Vec<(usize, f64)> = bands.into_iter().flatten().collect();
            for (k, &(start, alpha)) in bands.iter().enumerate() {
                let end_of_band = bands.get(k + 1).map_or(width, |b| b.0);
                if alpha >= plan.clear_sky_from {
                    continue;
                }
                let fan_end = fan.interpolate(alpha, &mut heights);
                let Some(sun) = BandSun::of(shader, alpha, fan_end) else {
                    continue;
                };
                let dir = plan
                    .frame
                    .view_direction_at_elevation(start as f64 + 0.5, film_y, alpha);
                let background = shader.background_with(&dir, fan_end, false);
                let columns = BandColumns {
                    shader,
                    offsets: shader.azimuths.row(y),
                    sun,
                    background,
                };
                out.fill([f64::NAN; 3]);
                let spans = columns.fill_band((start, end_of_band), width, &mut out);
                let runs = crate::render::band_runs(start, end_of_band, width);
                let band = SunBand {
                    y,
                    alpha,
                    sun,
                    background,
                    runs: [(runs[0], spans[0]), (runs[1], spans[1])],
                    out: &out,
                };
                each(&plan, &band);
            }
        }
    }

    /// The azimuth (rad) of column `x`'s pixel centre on `band`'s row, as a sample there takes
    /// it.
    fn column_azimuth(plan: &FramePlan<'_>, band: &SunBand<'_>, x: usize) -> f64 {
        let film_y = f64::from(band.y) + 0.5;
        plan.frame
            .view_direction_at_elevation(x as f64 + 0.5, film_y, band.alpha)
            .azimuth_offset_rad()
            + plan.shader.heading_rad
    }

    #[test]
    fn every_column_of_a_disc_band_is_the_samples_own_bit_for_bit() {
        use crate::render::band_sun::BandSun;
        use crate::render::reflection::SeaSunAt;
        // The sun below the sea horizon (its disc in strips) and rising through it, and a mirror
        // sea's image of a sun just above the horizon.
        let cases = [
            ("fig12b_novaya_zemlya_strips.toml", -1.55),
            ("fig12b_novaya_zemlya_strips.toml", -1.0),
            ("fig12b_novaya_zemlya_strips.toml", -0.6),
            ("fig15_calm_sea.toml", -0.2),
        ];
        for (name, sun_deg) in cases {
            let (mut lit, mut compared, mut mirrored) = (0, 0, 0);
            sun_bands(name, sun_deg, |plan, band| {
                let mirror = matches!(
                    band.sun,
                    BandSun::Sea {
                        sun: SeaSunAt::Mirror { .. },
                        ..
                    }
                );
                // The disc's radiance at an azimuth and what weights it, as a sample takes them.
                type Weight = Box<dyn Fn(f64) -> [f64; 3]>;
                let (disc, elevation_rad, weight): (_, f64, Weight) = match band.sun {
                    BandSun::Disc {
                        elevation_rad,
                        transmittance,
                    } => (
                        plan.shader.sun.expect("sun"),
                        elevation_rad,
                        Box::new(move |d: f64| transmittance.map(|t| d * t)),
                    ),
                    BandSun::Sea {
                        sun:
                            SeaSunAt::Mirror {
                                elevation_rad,
                                reflectance,
                                transmittance: sky,
                            },
                        transmittance: air,
                    } => {
                        let refl = plan.shader.reflection.as_ref().expect("sea");
                        let (_, disc) = refl.mirror_sun.expect("mirror sun");
                        let weight = move |d: f64| {
                            let sun = sky.map(|t| reflectance * d * t);
                            [0, 1, 2].map(|c| sun[c] * air[c])
                        };
                        (disc, elevation_rad, Box::new(weight))
                    }
                    BandSun::Sea { .. } => return,
                };
                for ((a, b), (lo, hi)) in band.runs {
                    for x in a..b {
                        let radiance = disc.radiance(column_azimuth(plan, band, x), elevation_rad);
                        let want = if radiance > 0.0 {
                            weight(radiance)
                        } else {
                            [0.0; 3]
                        };
                        let got = band.out[x];
                        let case = format!("{name} {sun_deg}° row {} column {x}", band.y);
                        assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "{case}");
                        if !(lo..hi).contains(&x) {
                            assert_eq!(got, [0.0; 3], "{case} outside {lo}..{hi}");
                        }
                        lit += usize::from(radiance > 0.0);
                        mirrored += usize::from(mirror && radiance > 0.0);
                        compared += 1;
                    }
                }
            });
            eprintln!("{name} {sun_deg}°: {compared} disc columns, {lit} lit, {mirrored} mirrored");
            assert!(
                lit > 2_000 && compared > lit,
                "{name} {sun_deg}°: {lit} of {compared}"
            );
            // The calm sea shows the disc's mirror image (the strips scene's sea is rough).
            assert_eq!(
                mirrored > 1_000,
                name.starts_with("fig15"),
                "{name}: {mirrored}"
            );
        }
    }

    #[test]
    fn the_glitters_dark_tails_and_fits_are_within_the_tolerance_of_each_columns_own() {
        use crate::render::band_sun::{BandSun, FLOOR, NEGLIGIBLE, TOLERANCE};
        use crate::render::reflection::SeaSunAt;
        // Suns low enough for the glitter to fall far below the sea across most of a row, and
        // one high enough for it to cover the whole row.
        for sun_deg in [-1.1, -0.96, -0.6, -0.2, 0.54] {
            let (mut compared, mut dark, mut lit) = (0, 0, 0);
            strips_sun_bands(sun_deg, |plan, band| {
                let BandSun::Sea {
                    sun: sun @ SeaSunAt::Glint { .. },
                    transmittance,
                } = band.sun
                else {
                    return;
                };
                let (refl, background) = (
                    plan.shader.reflection.as_ref().expect("sea"),
                    band.background,
                );
                let y = band.y;
                for ((a, b), (lo, hi)) in band.runs {
                    for (x, &got) in band.out.iter().enumerate().take(b).skip(a) {
                        let want = sun.at(refl, column_azimuth(plan, band, x));
                        let want = [0, 1, 2].map(|c| want[c] * transmittance[c]);
                        let outside = !(lo..hi).contains(&x);
                        if outside {
                            // Dark only where the glitter is below the share of the
                            // tolerance a bound promises, not merely within the tolerance.
                            assert_eq!(got, [0.0; 3], "{sun_deg}° row {y} column {x}");
                            for c in 0..3 {
                                let negligible =
                                    NEGLIGIBLE * (TOLERANCE * background[c].abs() + FLOOR);
                                assert!(
                                    want[c] <= negligible,
                                    "{sun_deg}° row {y} column {x}: {want:?} left dark"
                                );
                            }
                        }
                        for c in 0..3 {
                            let allowed = TOLERANCE * (background[c] + want[c]).abs() + FLOOR;
                            assert!(
                                (got[c] - want[c]).abs() <= allowed,
                                "{sun_deg}° row {y} column {x} ({outside}): {got:?} vs {want:?}"
                            );
                        }
                        compared += 1;
                        dark += usize::from(outside);
                        lit += usize::from(want.iter().any(|&v| v > 1e-3 * background[1]));
                    }
                }
            });
            eprintln!("{sun_deg}°: {compared} columns, {dark} dark, {lit} visibly lit");
            assert!(
                compared >= 10_000 && lit > 500,
                "{sun_deg}°: {compared} {lit}"
            );
            // The tails found: most of a row's columns when the sun is below the horizon (its
            // glitter a narrow streak), none when it is above (the glitter covers every row).
            if sun_deg < -0.5 {
                assert!(dark > compared / 2, "{sun_deg}°: {dark} of {compared}");
            } else if sun_deg < 0.0 {
                assert!(dark > 0, "{sun_deg}°");
            } else {
                assert_eq!((dark, lit), (0, compared), "{sun_deg}°");
            }
        }
    }

    #[test]
    fn the_frames_azimuth_bounds_hold_every_film_point_and_are_narrow() {
        for (heading_deg, pitch_deg, hfov_deg, sun_deg) in [
            (0.0, 0.0, 10.0, 0.0),
            (0.0, -2.0, 10.0, 3.0),
            (10.0, 5.0, 60.0, -170.0),
            (179.0, -30.0, 90.0, -179.0),
            (90.0, 40.0, 120.0, 90.0),
        ] {
            let camera = Camera {
                height_m: 10.0,
                heading_rad: f64::to_radians(heading_deg),
                pitch_rad: f64::to_radians(pitch_deg),
                hfov_rad: f64::to_radians(hfov_deg),
                width: 200,
                height: 100,
                samples_per_pixel: 1,
            };
            let sun = f64::to_radians(sun_deg);
            let (lo, hi) = cos_azimuth_range(&camera, sun, elevations_of(&camera));
            let frame = camera.frame();
            let (mut min, mut max) = (f64::INFINITY, f64::NEG_INFINITY);
            for i in 0..=400 {
                for j in 0..=200 {
                    let (x, y) = (0.5 * f64::from(i), 0.5 * f64::from(j));
                    let c = (sun - frame.direction(x, y).0).cos();
                    assert!(lo <= c && c <= hi, "{heading_deg}°: {c} outside {lo}…{hi}");
                    (min, max) = (min.min(c), max.max(c));
                }
            }
            // Within a few pixels' worth of the film's own bounds.
            let slack = 10.0 * camera.pixel_angle_rad();
            assert!(
                min - lo <= slack && hi - max <= slack,
                "{heading_deg}°: {lo}…{hi} vs {min}…{max}"
            );
        }
    }
}
