//! Stage 4 (trace), the ray equation in the two coordinate systems the tracer integrates.
//!
//! In: an index field. Out: the right-hand side of d/ds(n dr/ds) = ∇n in arc length s, with state
//! (r, T = n·dr/ds), and the geometric quantities the event logic needs (height above the ground,
//! ground distance from the observer, local elevation, Bouguer's invariant).
//!
//! * [`PlanarSystem`] — spherically symmetric fields ([`StratifiedIndex`]): the ray stays in the
//!   vertical great-circle plane through the observer, so the state is 2-D (x, v, Tx, Ty), the
//!   position being the offset from the observer, who sits on the +y axis of Earth-centred
//!   coordinates. Arc length handles rays that go vertical or turn back, which θ- or
//!   x-parametrised forms cannot. Earth-centred positions of 6.4e6 m would carry ~1e-9 m of f64
//!   rounding, which a layer with a large d²n/dh² turns into force noise; the offsets carry the
//!   rounding of the distance travelled, and the height is summed from them without forming
//!   |r| − R.
//! * [`FieldSystem`] — any 3-D [`IndexField`], over a sphere or a flat Earth. Its positions are
//!   Earth-centred (the field is asked at absolute positions), so it keeps the ~1e-9 m rounding.
//! * [`FieldSystem`] — any 3-D [`IndexField`], over a sphere or a flat Earth.

use glam::{DVec2, DVec3};

use super::breaks::Layer;
use super::{IndexField, StratifiedIndex};
use crate::profile::FineZone;

/// What the event logic needs to know about a state.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Observables {
    /// Height above the ground (m).
    pub height_m: f64,
    /// Ground distance from the observer (m).
    pub distance_m: f64,
    /// Elevation of the direction above the local horizontal (rad).
    pub elevation_rad: f64,
    /// Angle travelled around the Earth's centre (rad); 0 on a flat Earth.
    pub angle_rad: f64,
    /// Bouguer's invariant n·r·cos ψ (sphere) or Snell's n·cos ψ (flat).
    pub invariant: f64,
    /// Refractive index here.
    pub index: f64,
}

/// A ray equation with its geometry.
pub(crate) trait RaySystem<const N: usize> {
    /// d(state)/ds for a step in the height interval `layer` (the field continued past its
    /// bounds, see [`Layer`]). Non-finite components signal a field that failed.
    fn derivative(&self, y: &[f64; N], layer: Layer) -> [f64; N];
    /// Height above the ground (cheap: used for every event test).
    fn height(&self, y: &[f64; N]) -> f64;
    /// Radial (upward) component of the direction T (any positive scale).
    fn climb(&self, y: &[f64; N]) -> f64;
    /// Ground distance from the observer.
    fn distance(&self, y: &[f64; N]) -> f64;
    /// All observables.
    fn observe(&self, y: &[f64; N]) -> Observables;
    /// Scale of the invariant (n·r or n at launch) used to express its drift as a fraction.
    fn invariant_scale(&self, y: &[f64; N]) -> f64;
    /// Heights (m above the ground, ascending) where the field is not smooth.
    fn breaks(&self) -> &[f64];
    /// Height bands (m above the ground) where steps are kept short (see
    /// [`StratifiedIndex::fine_zones`](super::StratifiedIndex::fine_zones)).
    fn fine_zones(&self) -> &[FineZone];
    /// The index and dn/dh at `height_m` above the ground, for a closed-form climb out of a spherically
    /// symmetric field (`climb_out`); `None` where the system has no radial profile (flat
    /// ground). For a 3-D field it is sampled above the observer, so it only means something
    /// when the field is spherically symmetric, as [`HookAction::ClimbOut`] presumes.
    ///
    /// [`HookAction::ClimbOut`]: super::HookAction::ClimbOut
    fn index_at(&self, height_m: f64) -> Option<(f64, f64)>;
    /// Earth radius (m) for the closed-form climb; `None` on flat ground.
    fn radius_m(&self) -> Option<f64>;
}

/// Spherically symmetric field, 2-D state (x, v, Tx, Ty): the position r = (x, R + h₀ + v)
/// about Earth's centre, stored as its offset (x, v) from the observer (at height h₀ on the
/// +y axis). The offset keeps the stage positions of a step to the rounding of kilometres
/// (a few 1e-12 m), not of the Earth's radius (~1e-9 m): in a layer whose d²n/dh² is large
/// (0.02 m⁻² in a 0.1 m, 30 K jump) a 1e-9 m height error is a force error the error estimate
/// sees as noise, which drove steps down to a millimetre.
pub(crate) struct PlanarSystem<'a, S: StratifiedIndex + ?Sized> {
    pub field: &'a S,
    pub radius_m: f64,
    /// The observer's height above the ground (m): the origin of the offsets.
    pub observer_m: f64,
    /// The breaks the ray loop ends its steps on (settled for the tracer's setting).
    pub breaks: &'a [f64],
}

impl<S: StratifiedIndex + ?Sized> PlanarSystem<'_, S> {
    /// The launch state at the observer with direction T (n times the unit direction).
    pub fn launch_state(&self, t: DVec2) -> [f64; 4] {
        [0.0, 0.0, t.x, t.y]
    }
    /// Earth-centred y coordinate of a state.
    #[inline]
    fn centre_y(&self, y: &[f64; 4]) -> f64 {
        self.radius_m + self.observer_m + y[1]
    }
    /// Distance from Earth's centre and height above the ground, the height without the
    /// rounding of |r| (≈ 6.4e6 m): h = (|r|² − R²)/(|r| + R) with |r|² − R² summed from the
    /// offsets, h₀(2R + h₀) + v(2(R + h₀) + v) + x².
    #[inline]
    fn radius_and_height(&self, y: &[f64; 4]) -> (f64, f64) {
        let (x, v) = (y[0], y[1]);
        let (r_e, h0) = (self.radius_m, self.observer_m);
        let cy = self.centre_y(y);
        // |r| ≈ 6.4e6 m: the plain square root cannot overflow or underflow, is within an ulp
        // of `hypot` and several times cheaper; the height does not depend on its rounding.
        let r = (x * x + cy * cy).sqrt();
        let excess = h0 * (2.0 * r_e + h0) + v * (2.0 * (r_e + h0) + v) + x * x;
        (r, excess / (r + r_e))
    }
}

impl<S: StratifiedIndex + ?Sized> RaySystem<4> for PlanarSystem<'_, S> {
    #[inline]
    fn derivative(&self, y: &[f64; 4], layer: Layer) -> [f64; 4] {
        let (len, height) = self.radius_and_height(y);
        let (n, dn) = layer.index_at(height, |h| self.field.index_and_derivative(h));
        let scale = dn / len;
        let inv_n = 1.0 / n;
        [
            y[2] * inv_n,
            y[3] * inv_n,
            y[0] * scale,
            self.centre_y(y) * scale,
        ]
    }
    #[inline]
    fn height(&self, y: &[f64; 4]) -> f64 {
        self.radius_and_height(y).1
    }
    #[inline]
    fn climb(&self, y: &[f64; 4]) -> f64 {
        y[0] * y[2] + self.centre_y(y) * y[3]
    }
    #[inline]
    fn distance(&self, y: &[f64; 4]) -> f64 {
        self.radius_m * y[0].atan2(self.centre_y(y))
    }
    fn observe(&self, y: &[f64; 4]) -> Observables {
        let (r, height_m) = self.radius_and_height(y);
        let cy = self.centre_y(y);
        let angle = y[0].atan2(cy);
        // Radial and tangential (towards increasing θ) components of T.
        let radial = (y[0] * y[2] + cy * y[3]) / r;
        let tangential = (cy * y[2] - y[0] * y[3]) / r;
        let (n, _) = self.field.index_and_derivative(height_m);
        let t_len = radial.hypot(tangential);
        Observables {
            height_m,
            distance_m: self.radius_m * angle,
            elevation_rad: radial.atan2(tangential),
            angle_rad: angle,
            invariant: n * r * tangential / t_len,
            index: n,
        }
    }
    fn invariant_scale(&self, y: &[f64; 4]) -> f64 {
        let (r, height_m) = self.radius_and_height(y);
        let (n, _) = self.field.index_and_derivative(height_m);
        n * r
    }
    fn breaks(&self) -> &[f64] {
        self.breaks
    }
    fn fine_zones(&self) -> &[FineZone] {
        self.field.fine_zones()
    }
    fn index_at(&self, height_m: f64) -> Option<(f64, f64)> {
        Some(self.field.index_and_derivative(height_m))
    }
    fn radius_m(&self) -> Option<f64> {
        Some(self.radius_m)
    }
}

/// The ground under a 3-D field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Ground {
    /// A sphere of this radius (m) centred at the origin; height = |r| − R, ground distance =
    /// R × the angle between r and the observer's position.
    Sphere {
        /// Radius (m).
        radius_m: f64,
    },
    /// The plane z = 0, with the observer above the origin; height = z.
    Flat,
}

/// The height above a sphere of radius `radius_m` of the point `origin_m + offset_m`, whose
/// distance from the centre is `r` (m), without the rounding of r − R: the origin's own height
/// plus (|r|² − |o|²)/(|r| + |o|), the numerator summed from the offset as 2 o·v + v·v.
#[inline]
pub(crate) fn height_near(origin_m: DVec3, offset_m: DVec3, radius_m: f64, r: f64) -> f64 {
    let o = origin_m.length();
    let rise = (2.0 * origin_m.dot(offset_m) + offset_m.length_squared()) / (r + o);
    (o - radius_m) + rise
}

/// Any 3-D field, state (v, T) as two `DVec3`s: the position is `origin_m` + v, kept as the
/// offset v from the observer for the reason given at [`PlanarSystem`].
pub(crate) struct FieldSystem<'a, F: IndexField + ?Sized> {
    pub field: &'a F,
    pub ground: Ground,
    /// The observer (Earth-centred on a sphere): the origin of the offsets.
    pub origin_m: DVec3,
    /// The observer's ground direction (unit; sphere) — distances are measured from it.
    pub start_direction: DVec3,
    /// The breaks the ray loop ends its steps on (settled for the setting).
    pub breaks: &'a [f64],
}

impl<F: IndexField + ?Sized> FieldSystem<'_, F> {
    #[inline]
    fn up(&self, r: DVec3) -> DVec3 {
        match self.ground {
            Ground::Sphere { .. } => r.normalize(),
            Ground::Flat => DVec3::Z,
        }
    }
    /// The offset of a state from the observer.
    #[inline]
    fn offset(y: &[f64; 6]) -> DVec3 {
        DVec3::new(y[0], y[1], y[2])
    }
    /// The position of a state (Earth-centred on a sphere).
    #[inline]
    fn position(&self, y: &[f64; 6]) -> DVec3 {
        self.origin_m + Self::offset(y)
    }

    /// n and ∇n at the point `offset` (at `height_m`) outside `layer`: the layer's continuation
    /// ([`Layer::index_at`]) along the vertical through the point, the field sampled on that
    /// vertical inside the layer; the horizontal part of ∇n is the sample's at the bound.
    #[cold]
    fn continued(&self, offset: DVec3, height_m: f64, layer: Layer) -> (f64, DVec3) {
        let up = self.up(self.origin_m + offset);
        let sample = |h: f64| {
            self.field
                .index_and_gradient_near(self.origin_m, offset + up * (h - height_m))
        };
        let (n, d) = layer.index_at(height_m, |h| {
            let (n, g) = sample(h);
            (n, g.dot(up))
        });
        let (_, edge_g) = sample(layer.nearest_inside(height_m));
        (n, edge_g + up * (d - edge_g.dot(up)))
    }
}

impl<F: IndexField + ?Sized> RaySystem<6> for FieldSystem<'_, F> {
    #[inline]
    fn derivative(&self, y: &[f64; 6], layer: Layer) -> [f64; 6] {
        let offset = Self::offset(y);
        let (n, g) = self.field.index_and_gradient_near(self.origin_m, offset);
        let (n, g) = if layer == Layer::EVERYWHERE {
            (n, g)
        } else {
            let height = self.height(y);
            if layer.contains(height) {
                (n, g)
            } else {
                self.continued(offset, height, layer)
            }
        };
        let inv_n = 1.0 / n;
        [y[3] * inv_n, y[4] * inv_n, y[5] * inv_n, g.x, g.y, g.z]
    }
    #[inline]
    fn height(&self, y: &[f64; 6]) -> f64 {
        let r = self.position(y);
        match self.ground {
            Ground::Sphere { radius_m } => {
                height_near(self.origin_m, Self::offset(y), radius_m, r.length())
            }
            Ground::Flat => r.z,
        }
    }
    #[inline]
    fn climb(&self, y: &[f64; 6]) -> f64 {
        let r = self.position(y);
        self.up(r).dot(DVec3::new(y[3], y[4], y[5]))
    }
    #[inline]
    fn distance(&self, y: &[f64; 6]) -> f64 {
        let r = self.position(y);
        match self.ground {
            Ground::Sphere { radius_m } => {
                radius_m
                    * self
                        .start_direction
                        .cross(r)
                        .length()
                        .atan2(self.start_direction.dot(r))
            }
            Ground::Flat => r.x.hypot(r.y),
        }
    }
    fn observe(&self, y: &[f64; 6]) -> Observables {
        let r = self.position(y);
        let t = DVec3::new(y[3], y[4], y[5]);
        let up = self.up(r);
        let radial = up.dot(t);
        let horizontal = (t - up * radial).length();
        let (n, _) = self
            .field
            .index_and_gradient_near(self.origin_m, Self::offset(y));
        let distance_m = self.distance(y);
        let (angle_rad, invariant) = match self.ground {
            Ground::Sphere { radius_m } => (
                distance_m / radius_m,
                n * r.length() * horizontal / t.length(),
            ),
            Ground::Flat => (0.0, n * horizontal / t.length()),
        };
        Observables {
            height_m: self.height(y),
            distance_m,
            elevation_rad: radial.atan2(horizontal),
            angle_rad,
            invariant,
            index: n,
        }
    }
    fn invariant_scale(&self, y: &[f64; 6]) -> f64 {
        let r = self.position(y);
        let (n, _) = self
            .field
            .index_and_gradient_near(self.origin_m, Self::offset(y));
        match self.ground {
            Ground::Sphere { .. } => n * r.length(),
            Ground::Flat => n,
        }
    }
    fn breaks(&self) -> &[f64] {
        self.breaks
    }
    fn fine_zones(&self) -> &[FineZone] {
        self.field.fine_zones()
    }
    fn index_at(&self, height_m: f64) -> Option<(f64, f64)> {
        match self.ground {
            Ground::Sphere { radius_m } => {
                let at = self.start_direction * (radius_m + height_m);
                let (n, gradient) = self.field.index_and_gradient(at);
                Some((n, gradient.dot(self.start_direction)))
            }
            Ground::Flat => None,
        }
    }
    fn radius_m(&self) -> Option<f64> {
        match self.ground {
            Ground::Sphere { radius_m } => Some(radius_m),
            Ground::Flat => None,
        }
    }
}
