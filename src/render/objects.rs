//! Render — scene objects. In: one sample's ray — a camera ray interpolated in the frame's fans,
//! a camera ray traced on its own (exact mode), or a ray the sea reflects (from the sea fan) —
//! and the frame's objects: the cards and the terrain. Out: what the ray meets, composed front
//! to back: premultiplied radiance and what is left to see behind.
//!
//! Every object answers through one trait, [`SceneObject`]: [`SceneObject::meet`] says cheaply
//! whether and at what ground distance the ray meets it (cards: the ray's height at the card's
//! distance within its height range, the sample's azimuth within its width; terrain: the march
//! along its profile), and [`SceneObject::shade`] gives its radiance there as seen at the ray's
//! start (through the air between). [`compose`] orders the meets by distance (the nearest first;
//! terrain before a card at the same distance) and composes them until nothing shows through,
//! shading only what is visible.

use std::cell::Cell;

use super::ray_model::FanEnd;
use super::reflection::SeaFan;
use super::shade::Shader;
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
    /// heights from the sea fan at ranges beyond `from_m`.
    Reflected {
        fan: &'a SeaFan,
        elevation_rad: f64,
        from_m: f64,
    },
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
    /// Whether and where `ray` meets the object (no shading).
    fn meet(&self, ray: &SampleRay<'_>) -> Option<Meet>;

    /// The premultiplied radiance of the object at `meet` as seen at the ray's start (the
    /// camera; for a reflected ray, the sea), through the air between, and its coverage.
    fn shade(&self, ray: &SampleRay<'_>, meet: &Meet, shader: &Shader<'_>) -> ([f64; 3], f64);
}

/// Meets held on the stack per sample (more spill to the heap).
const INLINE_MEETS: usize = 8;

/// `ray`'s meets with `objects`, nearest first (stable: at equal distances in `objects`'
/// order), composed front to back: the premultiplied radiance and the transmittance left for
/// what lies behind them. Stops shading once less than [`OPAQUE`] shows through.
pub(super) fn compose<'o>(
    ray: &SampleRay<'_>,
    objects: impl Iterator<Item = &'o dyn SceneObject>,
    shader: &Shader<'_>,
) -> Composed {
    let mut inline: [Option<(&'o dyn SceneObject, Meet)>; INLINE_MEETS] = [None; INLINE_MEETS];
    let mut spill: Vec<(&'o dyn SceneObject, Meet)> = Vec::new();
    let mut n = 0;
    for obj in objects {
        let Some(m) = obj.meet(ray) else {
            continue;
        };
        if n < INLINE_MEETS {
            // After every meet not farther than this one.
            let at = inline[..n]
                .iter()
                .position(|x| x.is_some_and(|(_, x)| x.distance_m > m.distance_m))
                .unwrap_or(n);
            inline.copy_within(at..n, at + 1);
            inline[at] = Some((obj, m));
        } else {
            if spill.is_empty() {
                spill.extend(inline.iter().flatten().copied());
            }
            let at = spill.partition_point(|(_, x)| x.distance_m <= m.distance_m);
            spill.insert(at, (obj, m));
        }
        n += 1;
    }
    let mut out = Composed {
        radiance: [0.0; 3],
        transmittance: 1.0,
        meets: n,
    };
    // Shade one meet over what is in front; whether nothing more shows through.
    let mut shade_one = |obj: &dyn SceneObject, m: &Meet| {
        let (rgb, alpha) = obj.shade(ray, m, shader);
        for c in 0..3 {
            out.radiance[c] += out.transmittance * rgb[c];
        }
        out.transmittance *= 1.0 - alpha;
        out.transmittance < OPAQUE
    };
    if spill.is_empty() {
        for (obj, m) in inline[..n].iter().flatten() {
            if shade_one(*obj, m) {
                break;
            }
        }
    } else {
        for (obj, m) in &spill {
            if shade_one(*obj, m) {
                break;
            }
        }
    }
    out
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
    /// How many objects the ray met.
    pub(super) meets: usize,
}
