//! Render — shading. In: one sample's apparent elevation and direction, and its ray (interpolated
//! from the elevation fan or traced): heights at the card distances and how it ended. Out: linear
//! RGB radiance from the cards it meets (front to back, alpha respected), then the sky, sun or sea
//! behind them (the sea with its reflections of the cards and the sun, `super::reflection`). Tables of sky and sea radiance by angle make each sample a few lookups. With
//! the sky's aerial perspective ([`crate::scene::sky::Extinction`]) a card or the sea is seen
//! through the optical depth of the chord from the camera to the point the ray meets it.

use std::sync::Arc;

use rayon::prelude::*;

use super::air_paths::{AirPaths, Meets};
use super::objects::{Composed, Meet, OPAQUE, Object, RayAlong, SampleRay, SceneObject, compose};
use super::ray_model::FanEnd;
use super::reflection::{Facets, MIN_NODE_SHARE, PartsCache, Spans};
use super::sun::SunTransmittance;
use super::terrain::TerrainView;
use super::texture_box::TextureColumns;
use crate::scene::Texture;
use crate::scene::camera::{FilmAzimuths, ViewDirection};
use crate::scene::sky::{Extinction, SunDisc};

/// The aerial perspective of a frame: extinction and the geometry of the chords.
pub(super) struct AerialShading {
    pub(super) extinction: Extinction,
    pub(super) camera_height_m: f64,
    pub(super) earth_radius_m: f64,
    /// The card distances (m), indexed like a ray's heights.
    pub(super) distances_m: Vec<f64>,
    /// The rays' own paths to the cards and the sea, where the tracer can integrate them.
    pub(super) paths: Option<Arc<AirPaths>>,
}

impl AerialShading {
    /// `radiance` (premultiplied, coverage `alpha`) of what the ray at apparent elevation
    /// `elevation_rad` `meets` at `height_m` and ground distance `distance_m`, as seen from the
    /// camera through the air between: along the ray's own path where [`AirPaths`] has it, else
    /// along the straight chord.
    #[inline]
    fn seen(
        &self,
        radiance: [f64; 3],
        alpha: f64,
        elevation_rad: f64,
        meets: Meets,
        height_m: f64,
        distance_m: f64,
    ) -> [f64; 3] {
        let tau = self.optical_depth(elevation_rad, meets, height_m, distance_m);
        self.extinction.attenuate(radiance, alpha, tau)
    }

    /// The optical depth per channel that [`Self::seen`] attenuates by.
    #[inline]
    fn optical_depth(
        &self,
        elevation_rad: f64,
        meets: Meets,
        height_m: f64,
        distance_m: f64,
    ) -> [f64; 3] {
        let along = self.paths.as_ref().and_then(|p| p.at(elevation_rad, meets));
        match along {
            Some(d) => self.extinction.path_optical_depth(d),
            None => self.extinction.chord_optical_depth(
                self.earth_radius_m,
                self.camera_height_m,
                height_m,
                distance_m,
            ),
        }
    }
}

/// A card prepared for shading.
pub(super) struct ViewCard<'a> {
    /// Its index in the frame's cards (sorted by distance).
    pub(super) index: usize,
    pub(super) distance_index: usize,
    /// Its ground distance (m).
    pub(super) distance_m: f64,
    /// Azimuth of the card centre relative to the camera heading (rad, in (−π, π]).
    pub(super) offset_rad: f64,
    pub(super) half_width_rad: f64,
    pub(super) base_m: f64,
    pub(super) top_m: f64,
    pub(super) height_m: f64,
    pub(super) texture: &'a Texture,
    /// The texture's column integrals, for its mean over the heights a part of a rough sea's
    /// slopes mirrors (`None`: samples only).
    pub(super) columns: Option<Arc<TextureColumns>>,
    /// The haze between the card and a rough sea (with aerial perspective; `None`: none, or
    /// a calm sea, whose one reflected ray takes its own chord to the height it meets).
    pub(super) reflected_haze: Option<ReflectedHaze>,
}

/// The air between a card and the sea that mirrors it on a rough sea: the transmittance per
/// channel of the chord from the sea surface to the card's middle height, by range from the
/// reflection point (tabulated, linear between entries). A part of a pixel's slopes stands for
/// reflected rays across much of the card's height; the chord's optical depth changes with the
/// height it ends at by about the height over twice the aerosol scale height, a few per cent
/// of a faint blurred image.
pub(super) struct ReflectedHaze {
    inv_step: f64,
    values: Vec<[f64; 3]>,
}

impl ReflectedHaze {
    /// Entries over the ranges [0, the card's distance].
    const ENTRIES: usize = 256;

    pub(super) fn new(extinction: &Extinction, earth_radius_m: f64, card: &ViewCard<'_>) -> Self {
        let step = card.distance_m.max(1.0) / (Self::ENTRIES - 1) as f64;
        let mid_m = 0.5 * (card.base_m + card.top_m);
        Self {
            inv_step: 1.0 / step,
            values: (0..Self::ENTRIES)
                .map(|i| {
                    let tau =
                        extinction.chord_optical_depth(earth_radius_m, 0.0, mid_m, i as f64 * step);
                    tau.map(|t| if t.is_finite() { (-t).exp() } else { 0.0 })
                })
                .collect(),
        }
    }

    /// The transmittance at range `range_m` (clamped to the table).
    #[inline]
    fn at(&self, range_m: f64) -> [f64; 3] {
        let last = (self.values.len() - 1) as f64;
        let p = (range_m * self.inv_step).clamp(0.0, last);
        let p = if p.is_nan() { 0.0 } else { p };
        let i = (p as usize).min(self.values.len() - 2);
        let f = p - i as f64;
        let (a, b) = (self.values[i], self.values[i + 1]);
        let mut out = [0.0; 3];
        for c in 0..3 {
            out[c] = a[c] + (b[c] - a[c]) * f;
        }
        out
    }
}

impl ViewCard<'_> {
    /// The sample's azimuth offset from the card's centre, and the card's horizontal texture
    /// coordinate there, if within its width. A camera ray wraps the offset only when it is
    /// beyond ±π, a reflected ray always (as each path always has).
    #[inline]
    pub(super) fn across(&self, azimuth: f64, always_wrap: bool) -> Option<f64> {
        let mut offset = azimuth - self.offset_rad;
        if always_wrap {
            if !in_width(offset, self.half_width_rad) {
                return None;
            }
            offset = wrap_pi(offset);
        } else {
            if offset.abs() > std::f64::consts::PI {
                offset = wrap_pi(offset);
            }
            if offset.abs() > self.half_width_rad {
                return None;
            }
        }
        Some(0.5 + 0.5 * offset / self.half_width_rad)
    }
}

impl ViewCard<'_> {
    /// The card's premultiplied texture where `ray` meets it at `meet`: the sample there, or
    /// for a ray standing for a span of a rough sea's reflected rays, the mean over the heights
    /// they meet (at the span's ends, as the sea fan interpolates them; the card's own edges
    /// where a ray there has ended).
    #[inline]
    fn texel(&self, ray: &SampleRay<'_>, meet: &Meet) -> [f32; 4] {
        let v = |h: f64| (self.top_m - h) / self.height_m;
        match (ray.along, &self.columns) {
            (
                RayAlong::Reflected {
                    fan,
                    from_m,
                    span_rad: (e0, e1),
                    at_cards,
                    ..
                },
                Some(columns),
            ) if e1 > e0 => {
                let ends = |[h0, h1]: [Option<f64>; 2]| (h0.map_or(1.0, v), h1.map_or(0.0, v));
                match at_cards {
                    Some(at) => {
                        let at = &at[self.index];
                        columns.mean_memo(self.texture, meet.u, ends(at.ends_m), &at.columns)
                    }
                    None => {
                        let range_m = self.distance_m - from_m;
                        let (v0, v1) = ends([fan.height(e0, range_m), fan.height(e1, range_m)]);
                        columns.mean(self.texture, meet.u, v0, v1)
                    }
                }
            }
            _ => self.texture.sample(meet.u, v(meet.height_m)),
        }
    }
}

/// Whether azimuth offset `offset` (rad) lies within `half_width` of a card's centre, wrapped
/// into (−π, π] when it is beyond.
#[inline]
fn in_width(mut offset: f64, half_width: f64) -> bool {
    if offset.abs() > std::f64::consts::PI {
        offset = wrap_pi(offset);
    }
    offset.abs() <= half_width
}

impl SceneObject for ViewCard<'_> {
    #[inline(always)]
    fn fixed_distance_m(&self) -> Option<f64> {
        Some(self.distance_m)
    }

    #[inline(always)]
    fn meet(&self, ray: &SampleRay<'_>) -> Option<Meet> {
        let (h, reflected) = match ray.along {
            RayAlong::Fan {
                card_heights: Some(heights),
                ..
            }
            | RayAlong::Traced {
                card_heights: heights,
                ..
            } => (heights[self.distance_index]?, false),
            RayAlong::Fan { .. } => return None,
            RayAlong::Reflected {
                fan,
                elevation_rad,
                from_m,
                at_cards,
                ..
            } => {
                // Beyond the reflection point and in the card's azimuth range first (cheap).
                if self.distance_m <= from_m
                    || !in_width(
                        ray.azimuth_offset_rad() - self.offset_rad,
                        self.half_width_rad,
                    )
                {
                    return None;
                }
                let h = match at_cards {
                    Some(at) => at[self.index].mid_m,
                    None => fan.height(elevation_rad, self.distance_m - from_m),
                };
                (h?, true)
            }
        };
        if h < self.base_m || h > self.top_m {
            return None;
        }
        let u = self.across(ray.azimuth_offset_rad(), reflected)?;
        Some(Meet {
            distance_m: self.distance_m,
            height_m: h,
            u,
            density_paths_m: None,
        })
    }

    #[inline]
    fn shade(&self, ray: &SampleRay<'_>, meet: &Meet, shader: &Shader<'_>) -> ([f64; 3], f64) {
        let t = self.texel(ray, meet);
        let mut rgb = [t[0] as f64, t[1] as f64, t[2] as f64];
        let alpha = t[3] as f64;
        match (ray.along, &shader.aerial, &shader.reflection) {
            (RayAlong::Reflected { from_m, .. }, Some(aerial), Some(_))
                if let Some(haze) = &self.reflected_haze =>
            {
                // A part of a rough sea's slopes: the chord to the card's middle height.
                let t = haze.at(self.distance_m - from_m);
                let path = aerial.extinction.path_radiance;
                for c in 0..3 {
                    rgb[c] = rgb[c] * t[c] + alpha * path[c] * (1.0 - t[c]);
                }
            }
            (RayAlong::Reflected { from_m, .. }, Some(aerial), Some(refl)) => {
                // From the card to the sea (the chord); the sea's own haze is added after.
                let range_m = self.distance_m - from_m;
                let tau = aerial.extinction.chord_optical_depth(
                    refl.earth_radius_m,
                    0.0,
                    meet.height_m,
                    range_m,
                );
                rgb = aerial.extinction.attenuate(rgb, alpha, tau);
            }
            (RayAlong::Reflected { .. }, _, _) => {}
            (_, Some(aerial), _) => {
                let k = self.distance_index;
                let d = aerial.distances_m[k];
                rgb = aerial.seen(
                    rgb,
                    alpha,
                    ray.dir.elevation_rad,
                    Meets::Card(k),
                    meet.height_m,
                    d,
                );
            }
            _ => {}
        }
        (rgb, alpha)
    }
}

/// A smooth function of one angle, tabulated uniformly and interpolated linearly (the sky and the
/// sea are evaluated per sample; a table replaces a `powf` and three `exp` by one lookup).
pub(super) struct AngleTable {
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
    pub(super) fn new(lo: f64, hi: f64, f: impl Fn(f64) -> [f64; 3] + Sync) -> Self {
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
    pub(super) fn at(&self, x: f64) -> [f64; 3] {
        // Index arithmetic in f64 and i32: u64 ↔ f64 conversions are slow on x86-64 without
        // AVX-512, and this runs once per sample. (Tables hold at most 8192 entries.)
        let last = (self.values.len() - 1) as f64;
        let p = ((x - self.start) * self.inv_step).clamp(0.0, last);
        let p = if p.is_nan() { 0.0 } else { p };
        // p ≥ 0, so truncation is the floor (`f64::floor` is a library call on baseline x86-64).
        let cell = (p as i32).min(self.values.len() as i32 - 2);
        let t = p - cell as f64;
        let i = cell as usize;
        let (a, b) = (self.values[i], self.values[i + 1]);
        [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * t)
    }
}

/// Everything shading needs, resolved once per frame.
pub(super) struct Shader<'a> {
    pub(super) cards: Vec<ViewCard<'a>>,
    pub(super) sky_table: Arc<AngleTable>,
    pub(super) sea_table: Arc<AngleTable>,
    pub(super) sun: Option<SunDisc>,
    /// The sky's transmittance towards the sun by apparent elevation (with a sun only).
    pub(super) sun_transmittance: Option<Arc<AngleTable>>,
    /// The transmittance towards the sun along each ray's own path, where the tracer could
    /// integrate it (preferred over `sun_transmittance`, the air-mass fallback).
    pub(super) sun_path: Option<SunTransmittance>,
    /// Camera heading (rad): sample azimuths are offsets from it.
    pub(super) heading_rad: f64,
    pub(super) fallback: [f64; 3],
    /// Aerial perspective towards cards and the sea (`None`: none).
    pub(super) aerial: Option<AerialShading>,
    /// The card distances (m), indexed like a ray's heights.
    pub(super) distances_m: Vec<f64>,
    /// The sea's reflections of the cards and the sun (`None`: the sky reflection alone).
    pub(super) reflection: Option<super::reflection::Reflection>,
    /// The terrain in view, if any.
    pub(super) terrain: Option<Arc<TerrainView<'a>>>,
    /// The azimuth offsets of the film's pixel centres (the sun's columns read them).
    pub(super) azimuths: Arc<FilmAzimuths>,
}

#[inline]
pub(super) fn wrap_pi(x: f64) -> f64 {
    let two_pi = std::f64::consts::TAU;
    let y = (x + std::f64::consts::PI).rem_euclid(two_pi) - std::f64::consts::PI;
    if y.is_finite() { y } else { 0.0 }
}

/// Bounds (lo, hi) on cos φ for every φ between φa and φb (rad, either way round), given as
/// (φa, cos φa) and (φb, cos φb): the ends' cosines, widened to 1 or −1 where the range holds a
/// multiple of 2π or an odd multiple of π; (−1, 1) for a range 2π wide or wider, NaN bounds
/// where an end is not finite.
#[inline]
pub(super) fn cos_range((phi_a, ca): (f64, f64), (phi_b, cb): (f64, f64)) -> (f64, f64) {
    let tau = std::f64::consts::TAU;
    if !(phi_a.is_finite() && phi_b.is_finite()) {
        return (f64::NAN, f64::NAN);
    }
    let (a, b) = (phi_a.min(phi_b), phi_a.max(phi_b));
    if b - a >= tau {
        return (-1.0, 1.0);
    }
    // Whether φ + 2πk lies in [a, b] for some k.
    let holds = |phi: f64| phi + ((a - phi) / tau).ceil() * tau <= b;
    let bottom = if holds(std::f64::consts::PI) {
        -1.0
    } else {
        ca.min(cb)
    };
    let top = if holds(0.0) { 1.0 } else { ca.max(cb) };
    (bottom, top)
}

impl<'a> Shader<'a> {
    /// Ground distance (m) of the cards with distance index `k`.
    #[inline]
    pub(super) fn card_distance_m(&self, k: usize) -> f64 {
        self.distances_m[k]
    }

    /// Whether a ray that ended with `end` may show the sun's glitter or mirror image on the
    /// sea (then the colour depends on the azimuth).
    #[inline]
    pub(super) fn may_meet_glint(&self, end: FanEnd) -> bool {
        match (end, &self.reflection) {
            (
                FanEnd::Ground {
                    grazing_rad,
                    distance_m,
                },
                Some(r),
            ) => r.may_show_sun(grazing_rad, distance_m),
            _ => false,
        }
    }

    /// Whether the sea a ray that ended with `end` may mirror the terrain (on a calm sea, the
    /// reflected ray, on a rough one the lowest of the facets', passes below the highest ground
    /// beyond the first land): then its colour depends on the azimuth.
    #[inline]
    pub(super) fn may_reflect_terrain(&self, end: FanEnd) -> bool {
        let (
            FanEnd::Ground {
                grazing_rad,
                distance_m,
            },
            Some(r),
            Some(terrain),
        ) = (end, &self.reflection, &self.terrain)
        else {
            return false;
        };
        let Some(fan) = &r.fan else {
            return false;
        };
        match &*r.facets {
            Facets::Mirror(table) => table.at(grazing_rad).iter().any(|node| {
                node.weight * node.reflectance >= MIN_NODE_SHARE
                    && terrain.may_be_reflected(fan, node.reflected_elevation_rad, distance_m)
            }),
            Facets::Rough(table) => {
                let span = table.span(grazing_rad);
                terrain.may_be_reflected(fan, span.elevation(0.0), distance_m)
            }
            Facets::None => false,
        }
    }

    /// Whether the sea a ray that ended with `end` mirrors `card` (the reflected rays within the
    /// card's height range at its range have a share that counts, [`MIN_NODE_SHARE`]): then
    /// the colour depends on the azimuth in its columns.
    #[inline]
    pub(super) fn may_reflect_card(&self, end: FanEnd, card: &ViewCard<'_>) -> bool {
        let (
            FanEnd::Ground {
                grazing_rad,
                distance_m,
            },
            Some(r),
        ) = (end, &self.reflection)
        else {
            return false;
        };
        let Some(fan) = &r.fan else {
            return false;
        };
        let range_m = self.card_distance_m(card.distance_index) - distance_m;
        if range_m <= 0.0 {
            return false;
        }
        match &*r.facets {
            Facets::Mirror(table) => table.at(grazing_rad).iter().any(|node| {
                node.weight * node.reflectance >= MIN_NODE_SHARE
                    && fan
                        .height(node.reflected_elevation_rad, range_m)
                        .is_some_and(|h| h >= card.base_m && h <= card.top_m)
            }),
            Facets::Rough(table) => {
                let span = table.span(grazing_rad);
                let mut spans = Spans::new();
                self.card_spans(fan, &span, card, distance_m, &mut spans) >= MIN_NODE_SHARE
            }
            Facets::None => false,
        }
    }

    /// The cards a sample along `dir` meets (`heights` at the card distances), front to back,
    /// over `background`.
    #[inline]
    pub(super) fn composite(
        &self,
        dir: &ViewDirection,
        heights: &[Option<f64>],
        background: [f64; 3],
    ) -> [f64; 3] {
        let ray = SampleRay::new(
            dir,
            RayAlong::Fan {
                alpha: dir.elevation_rad,
                card_heights: Some(heights),
            },
        );
        self.shade_ray(&ray, || background)
    }

    /// What `ray` meets of the frame's objects ([`compose`]): the terrain, placed per ray, and
    /// the cards at their distances (`cards` is sorted by distance).
    #[inline]
    pub(super) fn compose(&self, ray: &SampleRay<'_>) -> Composed {
        compose(
            ray,
            self.terrain.iter().map(|t| Object::Terrain(t)),
            self.cards.iter().map(Object::Card),
            self,
        )
    }

    /// What a camera sample's `ray` meets ([`compose`]) over `background` (computed only when
    /// something shows through).
    #[inline]
    pub(super) fn shade_ray(
        &self,
        ray: &SampleRay<'_>,
        background: impl FnOnce() -> [f64; 3],
    ) -> [f64; 3] {
        let found = self.compose(ray);
        if found.meets == 0 {
            return background();
        }
        let mut acc = found.radiance;
        if found.transmittance >= OPAQUE {
            let background = background();
            for c in 0..3 {
                acc[c] += found.transmittance * background[c];
            }
        }
        acc
    }

    /// Whether a ray that ended with `end` may show the sun (its final direction is within the
    /// disc's elevation band): then the colour depends on the azimuth.
    #[inline]
    pub(super) fn may_meet_sun(&self, end: FanEnd) -> bool {
        match (end, &self.sun) {
            (FanEnd::Sky { elevation_rad }, Some(sun)) => sun.may_meet(elevation_rad),
            _ => false,
        }
    }

    /// Radiance behind every card: the sea, or the sky (with the sun disc where the ray's final
    /// direction meets it), or the fallback for a lost ray. A sample whose ray meets no card is
    /// shaded by this alone (no card adds to it).
    #[inline]
    pub(super) fn background(&self, dir: &ViewDirection, end: FanEnd) -> [f64; 3] {
        self.background_with(dir, end, true)
    }

    /// [`Self::background`]; without `reflections` the sea shows only its tabulated sky
    /// reflection (no mirrored cards, no sun) and the sky no sun: what a flat band shares
    /// across its columns.
    #[inline]
    pub(super) fn background_with(
        &self,
        dir: &ViewDirection,
        end: FanEnd,
        reflections: bool,
    ) -> [f64; 3] {
        let alpha = dir.elevation_rad;
        match end {
            FanEnd::Ground {
                grazing_rad,
                distance_m,
            } => {
                let mut sea = self.sea_table.at(grazing_rad);
                if reflections && self.reflection.is_some() {
                    let extra = self.sea_reflections(dir, grazing_rad, distance_m, true);
                    for c in 0..3 {
                        sea[c] += extra[c];
                    }
                }
                match &self.aerial {
                    Some(aerial) => aerial.seen(sea, 1.0, alpha, Meets::Sea, 0.0, distance_m),
                    None => sea,
                }
            }
            FanEnd::Sky { elevation_rad } => {
                let l = self.sky_table.at(alpha);
                // The elevation test is the disc's own quick reject, done before the azimuth.
                if reflections && self.may_meet_sun(end) {
                    self.with_sun(l, alpha, elevation_rad, dir)
                } else {
                    l
                }
            }
            FanEnd::Trapped | FanEnd::Lost => self.fallback,
        }
    }

    /// [`Self::background`] for a sample of flat band `band`, whose ray ended with `end`: the
    /// same, the rough sea's parts found once per band ([`Self::band_reflections`]).
    pub(super) fn band_background(
        &self,
        dir: &ViewDirection,
        end: FanEnd,
        band: usize,
        cache: &mut PartsCache,
    ) -> [f64; 3] {
        let FanEnd::Ground {
            grazing_rad,
            distance_m,
        } = end
        else {
            return self.background(dir, end);
        };
        let Some(extra) = self.band_reflections(dir, grazing_rad, distance_m, band, cache) else {
            return self.background(dir, end);
        };
        let mut sea = self.sea_table.at(grazing_rad);
        for c in 0..3 {
            sea[c] += extra[c];
        }
        match &self.aerial {
            Some(aerial) => aerial.seen(sea, 1.0, dir.elevation_rad, Meets::Sea, 0.0, distance_m),
            None => sea,
        }
    }

    /// The transmittance per channel of the air from the sea, where the ray at apparent
    /// elevation `alpha` meets it at ground distance `distance_m`, to the camera (1 without
    /// aerial perspective): what the sea's own radiance is attenuated by.
    pub(super) fn sea_transmittance(&self, alpha: f64, distance_m: f64) -> [f64; 3] {
        match &self.aerial {
            Some(aerial) => {
                let tau = aerial.optical_depth(alpha, Meets::Sea, 0.0, distance_m);
                aerial.extinction.attenuate([1.0; 3], 0.0, tau)
            }
            None => [1.0; 3],
        }
    }

    /// The sun's azimuth (rad, clockwise from north), when the scene has a sun.
    pub(super) fn sun_azimuth_rad(&self) -> Option<f64> {
        self.sun.as_ref().map(SunDisc::azimuth_rad)
    }

    /// The transmittance towards the sun of the ray at apparent elevation `alpha` (along its
    /// own path where it was integrated, else by air mass); `None` without a sun.
    #[inline]
    pub(super) fn sun_transmittance_at(&self, alpha: f64) -> Option<[f64; 3]> {
        let table = self.sun_transmittance.as_ref()?;
        Some(match &self.sun_path {
            Some(path) => path.at(alpha),
            None => table.at(alpha),
        })
    }

    /// `sky` plus the sun disc where a sample along `dir` (apparent elevation `alpha`) whose ray
    /// leaves towards `elevation_rad` meets it.
    #[inline]
    pub(super) fn with_sun(
        &self,
        mut sky: [f64; 3],
        alpha: f64,
        elevation_rad: f64,
        dir: &ViewDirection,
    ) -> [f64; 3] {
        let (Some(sun), Some(table)) = (&self.sun, &self.sun_transmittance) else {
            return sky;
        };
        let azimuth = self.heading_rad + dir.azimuth_offset_rad();
        let disc = sun.radiance(azimuth, elevation_rad);
        if disc > 0.0 {
            let t = match &self.sun_path {
                Some(path) => path.at(alpha),
                None => table.at(alpha),
            };
            for c in 0..3 {
                sky[c] += disc * t[c];
            }
        }
        sky
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Sky;

    #[test]
    fn cos_ranges_hold_every_cosine_between_their_ends() {
        let tau = std::f64::consts::TAU;
        let mut widened = [0, 0];
        for i in 0..400 {
            // Ranges anywhere in (−3π, 3π), some across 0, ±π and ±2π, up to 3 rad wide.
            let a = -9.4 + 18.8 * f64::from(i) / 400.0;
            for width in [0.0, 1e-9, 0.01, 0.5, 3.0] {
                for (p, q) in [(a, a + width), (a + width, a)] {
                    let (lo, hi) = cos_range((p, p.cos()), (q, q.cos()));
                    for k in 0..=200 {
                        let c = (a + width * f64::from(k) / 200.0).cos();
                        assert!(lo <= c && c <= hi, "{p}…{q}: {c} outside {lo}…{hi}");
                    }
                    // Widened only where the range holds a top (2πn) or a bottom (2πn + π).
                    let holds = |shift: f64| ((a - shift) / tau).ceil() * tau + shift <= a + width;
                    let (top, bottom) = (holds(0.0), holds(std::f64::consts::PI));
                    if !top {
                        assert_eq!(hi, p.cos().max(q.cos()), "{p}…{q}");
                    }
                    if !bottom {
                        assert_eq!(lo, p.cos().min(q.cos()), "{p}…{q}");
                    }
                    widened[0] += usize::from(top && hi == 1.0);
                    widened[1] += usize::from(bottom && lo == -1.0);
                }
            }
        }
        assert!(widened[0] > 10 && widened[1] > 10, "{widened:?}");
        // A range a full turn wide holds every cosine.
        assert_eq!(
            cos_range((0.3, 0.3f64.cos()), (7.0, 7.0f64.cos())),
            (-1.0, 1.0)
        );
        // No range from a non-finite end.
        for bad in [f64::NAN, f64::INFINITY] {
            let (lo, hi) = cos_range((bad, bad.cos()), (0.1, 0.1f64.cos()));
            assert!(lo.is_nan() && hi.is_nan(), "{bad}");
        }
    }

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
    fn the_sun_transmittance_table_is_as_close() {
        // Wide and narrow frames, across the horizon (where the air mass has its kink and the
        // blue transmittance falls to 3e-4): within 1e-4 of the brightest channel, the red.
        let sky = Sky::default();
        for (lo, hi) in [(-0.1, 1.5), (-0.004, 0.006), (-0.02, 0.01)] {
            let table = AngleTable::new(lo, hi, |e| sky.transmittance(e));
            for i in 0..2000 {
                let e = lo + (hi - lo) * (i as f64 + 0.37) / 2000.0;
                let (a, b) = (table.at(e), sky.transmittance(e));
                let brightest = b.iter().fold(0.0f64, |m, &v| m.max(v));
                for c in 0..3 {
                    assert!((a[c] - b[c]).abs() <= 1e-4 * brightest, "{e}: {a:?} {b:?}");
                }
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
}
