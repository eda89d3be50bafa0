//! Render — scene objects. In: one sample's ray — a camera ray interpolated in the frame's fans,
//! a camera ray traced on its own (exact mode), or a ray the sea reflects (from the sea fan) —
//! and the frame's objects: the cards and the terrain. Out: what the ray meets, composed front
//! to back: premultiplied radiance and what is left to see behind.
//!
//! Every object answers through one trait, [`SceneObject`]: [`SceneObject::meet`] says cheaply
//! whether and at what ground distance the ray meets it (cards: the ray's height at the card's
//! distance within its height range, the sample's azimuth within its width; terrain: the march
//! along its profile), and [`SceneObject::shade`] gives its radiance there as seen at the ray's
//! start (through the air between). [`compose`] composes the meets by distance (the nearest
//! first; terrain before a card at the same distance) until nothing shows through, testing and
//! shading only what is visible.

use std::cell::Cell;

use super::ray_model::FanEnd;
use super::reflection::SeaFan;
use super::shade::{Shader, ViewCard};
use super::terrain::TerrainView;
use super::texture_box::ColumnMemo;
use crate::scene::camera::ViewDirection;

/// How a sample's ray is known.
#[derive(Clone, Copy)]
pub(super) enum RayAlong<'a> {
    /// A camera ray interpolated in the frame's fans at apparent elevation `alpha`; its heights
    /// at the card distances (`None`: not interpolated, the sample meets no card).
    Fan {
        alpha: f64,
        card_heights: Option<&'a [Option<f64>]>,
    },
    /// A camera ray traced on its own: its heights at the card distances and, with terrain,
    /// at the terrain's traced distances with its end.
    Traced {
        card_heights: &'a [Option<f64>],
        terrain: Option<(&'a [Option<f64>], FanEnd)>,
    },
    /// A ray the sea reflects at ground distance `from_m`, leaving it at `elevation_rad`: its
    /// heights from the sea fan at ranges beyond `from_m`. It stands for the rays leaving
    /// between the elevations `span_rad` (equal for one ray; on a rough sea, a part of a
    /// sample's slopes that meets the same objects): a card shows its mean over them.
    /// `at_cards`: what it has at each card found beforehand (by the card's index in the
    /// shader; the same as the sea fan gives), or `None` to look it up.
    Reflected {
        fan: &'a SeaFan,
        elevation_rad: f64,
        from_m: f64,
        span_rad: (f64, f64),
        at_cards: Option<&'a [PartAtCard]>,
    },
}

/// A reflected ray at one card, from the sea fan: its heights (m) there, of the ray itself and
/// of the rays at the ends of the span it stands for (`None` where the fan has none), and the
/// card's texture column means over the heights they span as found so far.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct PartAtCard {
    /// The ray's own height.
    pub(super) mid_m: Option<f64>,
    /// The heights of the span's lowest and highest rays.
    pub(super) ends_m: [Option<f64>; 2],
    /// The column means found ([`super::texture_box::TextureColumns::mean_memo`]).
    pub(super) columns: ColumnMemo,
}

impl PartAtCard {
    /// The heights at range `range_m` of the reflected ray at `elevation_rad` and of those at
    /// the ends of `span_rad` ([`SeaFan::height`] each); no column means yet.
    #[inline]
    pub(super) fn of(fan: &SeaFan, elevation_rad: f64, span_rad: (f64, f64), range_m: f64) -> Self {
        Self {
            mid_m: fan.height(elevation_rad, range_m),
            ends_m: [span_rad.0, span_rad.1].map(|e| fan.height(e, range_m)),
            columns: ColumnMemo::default(),
        }
    }
}

/// One sample's ray, with its view direction and its azimuth computed once when needed.
pub(super) struct SampleRay<'a> {
    pub(super) dir: &'a ViewDirection,
    pub(super) along: RayAlong<'a>,
    azimuth: Cell<Option<f64>>,
}

impl<'a> SampleRay<'a> {
    pub(super) fn new(dir: &'a ViewDirection, along: RayAlong<'a>) -> Self {
        Self {
            dir,
            along,
            azimuth: Cell::new(None),
        }
    }

    /// As [`Self::new`] with the azimuth offset already known.
    pub(super) fn with_azimuth(dir: &'a ViewDirection, along: RayAlong<'a>, offset: f64) -> Self {
        Self {
            dir,
            along,
            azimuth: Cell::new(Some(offset)),
        }
    }

    /// The sample's azimuth offset from the camera heading (rad).
    #[inline]
    pub(super) fn azimuth_offset_rad(&self) -> f64 {
        if let Some(a) = self.azimuth.get() {
            return a;
        }
        let a = self.dir.azimuth_offset_rad();
        self.azimuth.set(Some(a));
        a
    }
}

/// Where a ray meets an object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Meet {
    /// Ground distance from the ray's start's observer (the camera; m).
    pub(super) distance_m: f64,
    /// Height of the point met (m).
    pub(super) height_m: f64,
    /// The object's own coordinate there (a card: its horizontal texture coordinate).
    pub(super) u: f64,
    /// Density-weighted path lengths from the camera to the point, where known.
    pub(super) density_paths_m: Option<[f64; 2]>,
}

/// A thing in the scene a ray can meet: a card or the terrain.
pub(super) trait SceneObject: Sync {
    /// The ground distance (m) at which every ray meets the object if it meets it at all (a
    /// card), or `None` (the terrain: where depends on the ray).
    fn fixed_distance_m(&self) -> Option<f64>;

    /// Whether and where `ray` meets the object (no shading).
    fn meet(&self, ray: &SampleRay<'_>) -> Option<Meet>;

    /// The premultiplied radiance of the object at `meet` as seen at the ray's start (the
    /// camera; for a reflected ray, the sea), through the air between, and its coverage.
    fn shade(&self, ray: &SampleRay<'_>, meet: &Meet, shader: &Shader<'_>) -> ([f64; 3], f64);
}

/// `ray`'s meets with the objects, nearest first, composed front to back: the premultiplied
/// radiance and the transmittance left for what lies behind them. `fixed` are objects at fixed
/// ground distances ([`SceneObject::fixed_distance_m`], the cards), in ascending order; `placed`
/// the others (the terrain), whose meets are found first and merged in (before a fixed object
/// at the same distance: the terrain hides a card standing where it is met). Stops shading once
/// less than [`OPAQUE`] shows through, so objects behind an opaque one are not even tested.
#[inline]
pub(super) fn compose<O: SceneObject + Copy>(
    ray: &SampleRay<'_>,
    placed: impl Iterator<Item = O>,
    fixed: impl Iterator<Item = O>,
    shader: &Shader<'_>,
) -> Composed {
    // The placed objects' meets, nearest last (popped first; at equal distances the first
    // object's first): usually none or one, held without allocating.
    let mut pending = Pending::default();
    for obj in placed {
        if let Some(m) = obj.meet(ray) {
            pending.insert(obj, m);
        }
    }
    let mut out = Composed::nothing();
    let add = |out: &mut Composed, obj: O, m: &Meet| out.add(obj.shade(ray, m, shader));
    for obj in fixed {
        let d = obj.fixed_distance_m().unwrap_or(f64::INFINITY);
        while let Some((p, m)) = pending.pop_until(d) {
            if add(&mut out, p, &m) {
                return out;
            }
        }
        if let Some(m) = obj.meet(ray)
            && add(&mut out, obj, &m)
        {
            return out;
        }
    }
    while let Some((p, m)) = pending.pop_until(f64::INFINITY) {
        if add(&mut out, p, &m) {
            return out;
        }
    }
    out
}

/// The placed objects' meets not yet composed: one inline, more on the heap (nearest last).
struct Pending<O> {
    one: Option<(O, Meet)>,
    many: Vec<(O, Meet)>,
}

impl<O> Default for Pending<O> {
    fn default() -> Self {
        Self {
            one: None,
            many: Vec::new(),
        }
    }
}

impl<O: Copy> Pending<O> {
    #[inline]
    fn insert(&mut self, obj: O, m: Meet) {
        if self.many.is_empty() && self.one.is_none() {
            self.one = Some((obj, m));
            return;
        }
        if let Some(first) = self.one.take() {
            self.many.push(first);
        }
        // After the farther meets, before the equally far ones (they came first).
        let at = self
            .many
            .partition_point(|(_, x)| x.distance_m > m.distance_m);
        self.many.insert(at, (obj, m));
    }

    /// The nearest meet, if it is not farther than `d_m`.
    #[inline]
    fn pop_until(&mut self, d_m: f64) -> Option<(O, Meet)> {
        if let Some((_, m)) = &self.one {
            return if m.distance_m <= d_m {
                self.one.take()
            } else {
                None
            };
        }
        if self.many.last()?.1.distance_m <= d_m {
            self.many.pop()
        } else {
            None
        }
    }
}

/// The frame's objects, each through [`SceneObject`] (a closed set, so the compositor's calls
/// are direct, not through a vtable).
#[derive(Clone, Copy)]
pub(super) enum Object<'s, 'a> {
    /// The terrain in view.
    Terrain(&'s TerrainView<'a>),
    /// A card.
    Card(&'s ViewCard<'a>),
}

impl SceneObject for Object<'_, '_> {
    #[inline(always)]
    fn fixed_distance_m(&self) -> Option<f64> {
        match self {
            Object::Terrain(t) => t.fixed_distance_m(),
            Object::Card(c) => c.fixed_distance_m(),
        }
    }

    #[inline(always)]
    fn meet(&self, ray: &SampleRay<'_>) -> Option<Meet> {
        match self {
            Object::Terrain(t) => t.meet(ray),
            Object::Card(c) => c.meet(ray),
        }
    }

    #[inline]
    fn shade(&self, ray: &SampleRay<'_>, meet: &Meet, shader: &Shader<'_>) -> ([f64; 3], f64) {
        match self {
            Object::Terrain(t) => t.shade(ray, meet, shader),
            Object::Card(c) => c.shade(ray, meet, shader),
        }
    }
}

/// Below this transmittance nothing behind shows: composition stops.
pub(super) const OPAQUE: f64 = 1e-6;

/// What [`compose`] found along a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Composed {
    /// Premultiplied radiance of the objects met, front to back.
    pub(super) radiance: [f64; 3],
    /// What is left to see behind them (below [`OPAQUE`]: nothing).
    pub(super) transmittance: f64,
    /// How many of the objects met were shaded (the rest lie behind an opaque one).
    pub(super) meets: usize,
}

impl Composed {
    /// Nothing met yet: no radiance, everything shows through.
    pub(super) fn nothing() -> Self {
        Self {
            radiance: [0.0; 3],
            transmittance: 1.0,
            meets: 0,
        }
    }

    /// Compose an object's premultiplied radiance and coverage behind those so far; returns
    /// whether nothing shows through any more (below [`OPAQUE`]).
    #[inline]
    pub(super) fn add(&mut self, (rgb, alpha): ([f64; 3], f64)) -> bool {
        for (acc, v) in self.radiance.iter_mut().zip(rgb) {
            *acc += self.transmittance * v;
        }
        self.transmittance *= 1.0 - alpha;
        self.meets += 1;
        self.transmittance < OPAQUE
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::shade::AngleTable;

    /// An object met at a fixed distance with a fixed colour and coverage.
    struct Slab {
        distance_m: f64,
        rgb: [f64; 3],
        alpha: f64,
        /// Whether it stands at a fixed distance (like a card) or is placed per ray.
        fixed: bool,
    }

    impl SceneObject for &Slab {
        fn fixed_distance_m(&self) -> Option<f64> {
            self.fixed.then_some(self.distance_m)
        }

        fn meet(&self, _ray: &SampleRay<'_>) -> Option<Meet> {
            Some(Meet {
                distance_m: self.distance_m,
                height_m: 0.0,
                u: 0.0,
                density_paths_m: None,
            })
        }

        fn shade(&self, _: &SampleRay<'_>, _: &Meet, _: &Shader<'_>) -> ([f64; 3], f64) {
            (self.rgb.map(|c| c * self.alpha), self.alpha)
        }
    }

    fn shader() -> Shader<'static> {
        Shader {
            cards: Vec::new(),
            sky_table: std::sync::Arc::new(AngleTable::new(0.0, 1.0, |_| [1.0; 3])),
            sea_table: std::sync::Arc::new(AngleTable::new(0.0, 1.0, |_| [0.0; 3])),
            sun: None,
            sun_transmittance: None,
            sun_path: None,
            heading_rad: 0.0,
            fallback: [1.0; 3],
            aerial: None,
            distances_m: Vec::new(),
            reflection: None,
            terrain: None,
            azimuths: std::sync::Arc::new(crate::scene::camera::FilmAzimuths::new(
                small_camera().frame(),
                4,
                2,
            )),
        }
    }

    /// Front-to-back "over" of `slabs` in the given order, the reference.
    fn over(slabs: &[&Slab]) -> ([f64; 3], f64) {
        let (mut acc, mut t) = ([0.0; 3], 1.0);
        for s in slabs {
            for (a, v) in acc.iter_mut().zip(s.rgb) {
                *a += t * (v * s.alpha);
            }
            t *= 1.0 - s.alpha;
            if t < OPAQUE {
                break;
            }
        }
        (acc, t)
    }

    /// The view through the centre of a small level frame.
    fn centre_view() -> ViewDirection {
        small_camera().frame().view_direction(2.0, 1.0)
    }

    /// A small level camera.
    fn small_camera() -> crate::scene::camera::Camera {
        crate::scene::camera::Camera {
            height_m: 10.0,
            heading_rad: 0.0,
            pitch_rad: 0.0,
            hfov_rad: 0.1,
            width: 4,
            height: 2,
            samples_per_pixel: 1,
        }
    }

    /// A level sample ray from the fan along `dir`, no card heights.
    fn level_fan_ray(dir: &ViewDirection) -> SampleRay<'_> {
        SampleRay::new(
            dir,
            RayAlong::Fan {
                alpha: 0.0,
                card_heights: None,
            },
        )
    }

    #[test]
    fn meets_are_composed_nearest_first_and_stably() {
        let dir = centre_view();
        let ray = level_fan_ray(&dir);
        let shader = shader();
        for count in [1usize, 2, 3, 9, 20] {
            // Distances out of order, with ties (k % 5), translucent.
            let slabs: Vec<Slab> = (0..count)
                .map(|k| Slab {
                    distance_m: 1_000.0 * ((k * 7) % 5) as f64,
                    rgb: [k as f64, 1.0, 0.5],
                    alpha: 0.3,
                    fixed: false,
                })
                .collect();
            let found = compose(&ray, slabs.iter(), std::iter::empty(), &shader);
            let mut sorted: Vec<&Slab> = slabs.iter().collect();
            sorted.sort_by(|a, b| a.distance_m.total_cmp(&b.distance_m)); // stable
            let (acc, t) = over(&sorted);
            assert_eq!(found.meets, count);
            assert_eq!((found.radiance, found.transmittance), (acc, t), "{count}");
        }
        // An opaque slab hides everything behind it, and composition stops there.
        let slabs = [
            Slab {
                distance_m: 5.0,
                rgb: [9.0; 3],
                alpha: 1.0,
                fixed: false,
            },
            Slab {
                distance_m: 2.0,
                rgb: [1.0, 0.0, 0.0],
                alpha: 0.5,
                fixed: false,
            },
            Slab {
                distance_m: 5.0,
                rgb: [7.0; 3],
                alpha: 1.0,
                fixed: false,
            },
        ];
        let found = compose(&ray, slabs.iter(), std::iter::empty(), &shader);
        assert_eq!(found.radiance, [0.5 + 0.5 * 9.0, 4.5, 4.5]);
        assert_eq!(found.transmittance, 0.0);
    }

    #[test]
    fn placed_meets_merge_into_fixed_ones_before_those_equally_far() {
        let dir = centre_view();
        let ray = level_fan_ray(&dir);
        let shader = shader();
        // Fixed slabs in ascending order (ties included), placed ones out of order, some at
        // the fixed ones' distances; all translucent with distinct colours.
        let fixed: Vec<Slab> = [1.0, 2.0, 2.0, 4.0, 6.0]
            .iter()
            .enumerate()
            .map(|(k, &d)| Slab {
                distance_m: 1_000.0 * d,
                rgb: [k as f64, 0.5, 1.0],
                alpha: 0.25,
                fixed: true,
            })
            .collect();
        for placed_km in [vec![], vec![2.0], vec![7.0, 0.5], vec![4.0, 2.0, 4.0, 3.0]] {
            let placed: Vec<Slab> = placed_km
                .iter()
                .enumerate()
                .map(|(k, &d)| Slab {
                    distance_m: 1_000.0 * d,
                    rgb: [0.5, k as f64 + 10.0, 2.0],
                    alpha: 0.4,
                    fixed: false,
                })
                .collect();
            let found = compose(&ray, placed.iter(), fixed.iter(), &shader);
            // The reference: placed ones first, then the fixed, sorted stably by distance.
            let mut sorted: Vec<&Slab> = placed.iter().chain(fixed.iter()).collect();
            sorted.sort_by(|a, b| a.distance_m.total_cmp(&b.distance_m));
            let (acc, t) = over(&sorted);
            assert_eq!(found.meets, sorted.len(), "{placed_km:?}");
            assert_eq!(
                (found.radiance, found.transmittance),
                (acc, t),
                "{placed_km:?}"
            );
        }
    }
}
