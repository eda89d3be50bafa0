//! Stage 4 — trace. In: an index-of-refraction field (an [`IndexField`], or a
//! [`StratifiedIndex`] for horizontally layered air over a sphere) and rays (origin, direction).
//! Out: ray paths and a typed termination for every ray. One tracer serves every scene, the
//! transfer-curve analysis and the renderer.
//!
//! * [`Tracer`] — the fast path for stratified air: a ray launched at apparent elevation α from
//!   an observer at height h₀ stays in its vertical plane; Dormand–Prince 5(4) in arc length with
//!   dense-output event location ([`RayRecord`], [`Termination`]).
//! * [`trace_field`] — the same integrator for any 3-D [`IndexField`] over a sphere or a flat
//!   Earth; [`Spherical`] turns a stratified index into a 3-D field (∇n = dn/dh · r̂) so the two
//!   paths can be checked against each other.
//! * [`straight_ray`] — exact straight-line geometry (n ≡ 1), the paper's Figure 1.

mod bouguer;
mod breaks;
mod climb_out;
mod density_path;
mod dopri;
mod ray;
mod straight;
mod system;

use std::sync::Arc;

use glam::{DVec2, DVec3};
use rayon::prelude::*;

pub use bouguer::{BouguerEnvelope, Fate, FateWatch};
pub use breaks::MinorBreak;
pub use density_path::{
    DensityPaths, DensityPathsSoFar, PendingClimb, RayDensityPaths, straight_density_paths_m,
};
pub use ray::{
    HookAction, NoHook, RayHook, RayPoint, RayRecord, Termination, TracerConfig, TracerError,
};
pub use straight::{UniformIndex, straight_ray};
pub use system::Ground;

use crate::profile::FineZone;
use system::{FieldSystem, PlanarSystem};

/// A refractive-index field in 3-D: n and ∇n at a point (Earth-centred coordinates, metres).
pub trait IndexField: Send + Sync {
    /// Refractive index and its gradient (m⁻¹) at `position_m`.
    fn index_and_gradient(&self, position_m: DVec3) -> (f64, DVec3);
    /// The same at `origin_m + offset_m`, for the tracer, which keeps a ray's positions as
    /// offsets from its observer: a field whose value depends on the height over a sphere
    /// should take the height from the offset (as [`Spherical`] does) rather than from the
    /// Earth-centred sum, whose ~1e-9 m rounding becomes force noise in strong layers.
    /// Default: evaluates at the sum.
    fn index_and_gradient_near(&self, origin_m: DVec3, offset_m: DVec3) -> (f64, DVec3) {
        self.index_and_gradient(origin_m + offset_m)
    }
    /// Heights above the ground (m, ascending) of the levels where the field is not smooth (see
    /// [`StratifiedIndex::breaks_m`]); the integrator ends its steps on them. Default: none.
    fn breaks_m(&self) -> &[f64] {
        &[]
    }
    /// Levels where dn/dh is continuous but d²n/dh² or d³n/dh³ jumps, with the jumps (see
    /// [`StratifiedIndex::minor_breaks`]). Default: none.
    fn minor_breaks(&self) -> &[MinorBreak] {
        &[]
    }
    /// Height bands above the ground where steps are kept short (see
    /// [`StratifiedIndex::fine_zones`]). Default: none.
    fn fine_zones(&self) -> &[FineZone] {
        &[]
    }
}

/// A horizontally stratified index n(h), h = height above the surface (m), over a sphere.
/// Such a field is spherically symmetric, which the tracer exploits (planar fast path).
pub trait StratifiedIndex: Send + Sync {
    /// n and dn/dh (m⁻¹) at height `height_m` above the surface.
    fn index_and_derivative(&self, height_m: f64) -> (f64, f64);
    /// n and dn/dh at `height_m` for a caller that samples the whole profile once (Bouguer's
    /// envelope): the same field as [`index_and_derivative`](Self::index_and_derivative) to
    /// within the error of any lookup table behind it, but evaluated without filling that table,
    /// so a scene builds table cells only where its rays go. Default: `index_and_derivative`.
    fn scan_index_and_derivative(&self, height_m: f64) -> (f64, f64) {
        self.index_and_derivative(height_m)
    }
    /// The node layout of a whole-column scan (Bouguer's envelope): where a lookup table
    /// stands behind [`scan_index_and_derivative`](Self::scan_index_and_derivative), its own
    /// node spacing, each cell then one polynomial (see [`ScanGrid::polynomial_cells`]).
    /// Default: [`ScanGrid::DEFAULT`].
    fn scan_grid(&self) -> ScanGrid {
        ScanGrid::DEFAULT
    }
    /// Heights above the surface (m, ascending, finite) where dn/dh or d²n/dh² may jump: the
    /// knots of a piecewise fit, the edges of constant-gradient layers, the standard
    /// atmosphere's layer bases. A Runge–Kutta step that straddles such a level drops to first
    /// or second order, so the integrator ends a step exactly on every break a ray crosses and
    /// restarts there. Default: none (a smooth field).
    fn breaks_m(&self) -> &[f64] {
        &[]
    }
    /// Further levels where dn/dh is continuous and only d²n/dh² or d³n/dh³ jumps, each with
    /// the sizes of its jumps (ascending). A step straddling one loses little, so the tracer
    /// ends its steps only on those that could matter at its tolerance (see `breaks::settle`).
    /// Default: none.
    fn minor_breaks(&self) -> &[MinorBreak] {
        &[]
    }
    /// Height bands (m above the surface) where the field changes on a vertical scale shorter
    /// than the tracer's height cap per step and no break marks it; a step that could reach one
    /// changes height by at most its `max_rise_m` (see
    /// [`AirColumn::fine_zones_m`](crate::profile::AirColumn::fine_zones_m)). Default: none.
    fn fine_zones(&self) -> &[FineZone] {
        &[]
    }
}

impl<S: StratifiedIndex + ?Sized> StratifiedIndex for &S {
    fn index_and_derivative(&self, height_m: f64) -> (f64, f64) {
        (**self).index_and_derivative(height_m)
    }
    fn scan_index_and_derivative(&self, height_m: f64) -> (f64, f64) {
        (**self).scan_index_and_derivative(height_m)
    }
    fn scan_grid(&self) -> ScanGrid {
        (**self).scan_grid()
    }
    fn breaks_m(&self) -> &[f64] {
        (**self).breaks_m()
    }
    fn minor_breaks(&self) -> &[MinorBreak] {
        (**self).minor_breaks()
    }
    fn fine_zones(&self) -> &[FineZone] {
        (**self).fine_zones()
    }
}

/// Node spacing of a whole-column scan ([`StratifiedIndex::scan_grid`]): `fine_step_m` up to
/// `fine_top_m` above the surface, `coarse_step_m` above, and — where `with_breaks` — every
/// break of the field a node too, so that no cell straddles a jump of dn/dh. Where
/// `polynomial_cells`, the scanned n(h) is one polynomial of degree ≤ 5 between neighbouring
/// nodes (a quintic table read at its own nodes and breaks).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanGrid {
    /// Node spacing near the ground (m).
    pub fine_step_m: f64,
    /// Top of the fine spacing (m above the surface).
    pub fine_top_m: f64,
    /// Node spacing above it (m).
    pub coarse_step_m: f64,
    /// Whether the field's breaks ([`StratifiedIndex::breaks_m`] and
    /// [`StratifiedIndex::minor_breaks`]) are nodes too.
    pub with_breaks: bool,
    /// Whether n(h) is a polynomial of degree ≤ 5 between neighbouring nodes: Bouguer's
    /// envelope then bounds how far g = n·r dips inside each cell by the Bernstein coefficients
    /// of g (degree ≤ 6, from seven samples), which holds whatever the cell's shape; otherwise
    /// by the end slopes alone, which assumes g' nearly linear across a cell (fine cells).
    pub polynomial_cells: bool,
}

impl ScanGrid {
    /// 0.25 m up to 4 km, 5 m above, breaks not added: fine enough for the thin smooth
    /// (tanh) layers of synthetic atmospheres, which declare no breaks.
    pub const DEFAULT: ScanGrid = ScanGrid {
        fine_step_m: 0.25,
        fine_top_m: 4_000.0,
        coarse_step_m: 5.0,
        with_breaks: false,
        polynomial_cells: false,
    };
}

/// A stratified index seen as a 3-D field about Earth's centre: ∇n = dn/dh · r̂.
#[derive(Debug, Clone, Copy)]
pub struct Spherical<S> {
    /// The stratified index.
    pub index: S,
    /// Earth radius (m): h = |r| − R.
    pub earth_radius_m: f64,
}

impl<S: StratifiedIndex> IndexField for Spherical<S> {
    fn index_and_gradient(&self, position_m: DVec3) -> (f64, DVec3) {
        let r = position_m.length();
        let (n, dn) = self.index.index_and_derivative(r - self.earth_radius_m);
        (n, position_m * (dn / r))
    }
    fn index_and_gradient_near(&self, origin_m: DVec3, offset_m: DVec3) -> (f64, DVec3) {
        let position_m = origin_m + offset_m;
        let r = position_m.length();
        let height_m = system::height_near(origin_m, offset_m, self.earth_radius_m, r);
        let (n, dn) = self.index.index_and_derivative(height_m);
        (n, position_m * (dn / r))
    }
    fn breaks_m(&self) -> &[f64] {
        self.index.breaks_m()
    }
    fn minor_breaks(&self) -> &[MinorBreak] {
        self.index.minor_breaks()
    }
    fn fine_zones(&self) -> &[FineZone] {
        self.index.fine_zones()
    }
}

/// A 3-D field with its breaks settled once for one tracer setting (the minor breaks that matter
/// at its tolerance over its `error_length_m` promoted to breaks, the rest dropped), for callers
/// that trace many rays with [`trace_field`], which otherwise settles them on every call. Rays
/// to targets beyond `error_length_m` get the breaks settled for `error_length_m`.
#[derive(Debug, Clone)]
pub struct Settled<F> {
    /// The field.
    pub field: F,
    breaks_m: Vec<f64>,
}

impl<F: IndexField> Settled<F> {
    /// `field` with its breaks settled for `config`.
    pub fn new(field: F, config: &TracerConfig) -> Self {
        let breaks_m = breaks::settle(
            field.breaks_m(),
            field.minor_breaks(),
            config,
            config.error_length_m,
        );
        Settled { field, breaks_m }
    }
}

impl<F: IndexField> IndexField for Settled<F> {
    fn index_and_gradient(&self, position_m: DVec3) -> (f64, DVec3) {
        self.field.index_and_gradient(position_m)
    }
    fn index_and_gradient_near(&self, origin_m: DVec3, offset_m: DVec3) -> (f64, DVec3) {
        self.field.index_and_gradient_near(origin_m, offset_m)
    }
    fn breaks_m(&self) -> &[f64] {
        &self.breaks_m
    }
    fn fine_zones(&self) -> &[FineZone] {
        self.field.fine_zones()
    }
}

/// The ray tracer for a stratified atmosphere (planar fast path). Cheap to build and `Sync`:
/// share one across threads. Per-ray scratch lives on the stack; [`Tracer::trace_into`] reuses
/// the caller's record and path buffers so a tight loop allocates nothing.
#[derive(Clone)]
pub struct Tracer<'a, S: StratifiedIndex + ?Sized> {
    field: &'a S,
    config: TracerConfig,
    fates: Option<Arc<BouguerEnvelope>>,
    /// The breaks the ray loop ends steps on, settled for rays whose error length is
    /// `config.error_length_m` (see `breaks::settle`); shared by clones.
    breaks_m: Arc<[f64]>,
}

impl<'a, S: StratifiedIndex + ?Sized> Tracer<'a, S> {
    /// A tracer through `field` with `config` (validated).
    pub fn new(field: &'a S, config: TracerConfig) -> Result<Self, TracerError> {
        config.validate()?;
        let breaks_m = breaks::settle(
            field.breaks_m(),
            field.minor_breaks(),
            &config,
            config.error_length_m,
        )
        .into();
        Ok(Tracer {
            field,
            config,
            fates: None,
            breaks_m,
        })
    }

    /// The same tracer, ending every ray that provably oscillates past its last target with
    /// [`Termination::Trapped`] ([`FateWatch`] over a [`BouguerEnvelope`] of the field, built
    /// here once and shared by clones).
    pub fn with_fates(self) -> Self {
        let envelope =
            BouguerEnvelope::new(self.field, self.config.earth_radius_m, self.config.top_m);
        Tracer {
            fates: Some(Arc::new(envelope)),
            ..self
        }
    }

    /// The fate envelope, if [`Self::with_fates`] built one.
    pub fn fates(&self) -> Option<&BouguerEnvelope> {
        self.fates.as_deref()
    }

    /// The settings.
    pub fn config(&self) -> &TracerConfig {
        &self.config
    }

    /// The field.
    pub fn field(&self) -> &'a S {
        self.field
    }

    fn check(
        &self,
        observer_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
    ) -> Result<(), TracerError> {
        if !(observer_height_m >= 0.0 && observer_height_m < self.config.top_m) {
            return Err(TracerError::ObserverOutside {
                height_m: observer_height_m,
                top_m: self.config.top_m,
            });
        }
        if !elevation_rad.is_finite() {
            return Err(TracerError::BadDirection);
        }
        check_distances(distances_m)
    }

    /// Trace one ray launched at `elevation_rad` above the horizontal from `observer_height_m`,
    /// reporting its height at each of `distances_m` (ascending ground distances).
    pub fn trace(
        &self,
        observer_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
    ) -> Result<RayRecord, TracerError> {
        let mut record = RayRecord::default();
        self.trace_into(
            observer_height_m,
            elevation_rad,
            distances_m,
            &mut NoHook,
            &mut record,
            None,
        )?;
        Ok(record)
    }

    /// Trace one ray into `record` (its buffers are reused), with a `hook`, optionally recording
    /// the path into `path` (cleared first).
    pub fn trace_into<H: RayHook + ?Sized>(
        &self,
        observer_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        hook: &mut H,
        record: &mut RayRecord,
        path: Option<&mut Vec<RayPoint>>,
    ) -> Result<(), TracerError> {
        self.check(observer_height_m, elevation_rad, distances_m)?;
        // Targets beyond the error length shrink the budget per metre: settle again for them.
        let error_length_m = ray::error_length_m(&self.config, distances_m);
        let farther: Vec<f64>;
        let breaks: &[f64] = if error_length_m > self.config.error_length_m
            && !self.field.minor_breaks().is_empty()
        {
            farther = breaks::settle(
                self.field.breaks_m(),
                self.field.minor_breaks(),
                &self.config,
                error_length_m,
            );
            &farther
        } else {
            &self.breaks_m
        };
        let sys = PlanarSystem {
            field: self.field,
            radius_m: self.config.earth_radius_m,
            observer_m: observer_height_m,
            breaks,
        };
        let (n0, _) = self.field.index_and_derivative(observer_height_m);
        let mut hook = bouguer::Watched {
            hook,
            watch: self.fates.as_deref().map(|envelope| {
                FateWatch::new(
                    envelope,
                    self.field,
                    self.config.earth_radius_m,
                    observer_height_m,
                    elevation_rad,
                    distances_m.last().copied().unwrap_or(0.0),
                )
            }),
        };
        let (sin_a, cos_a) = elevation_rad.sin_cos();
        let state = sys.launch_state(DVec2::new(n0 * cos_a, n0 * sin_a));
        ray::integrate(
            &sys,
            state,
            elevation_rad,
            &self.config,
            distances_m,
            &mut hook,
            record,
            path,
        );
        Ok(())
    }

    /// Trace a fan of elevations in parallel (rayon). Each ray depends only on its own inputs, so
    /// the result is bit-identical for any thread count.
    pub fn trace_fan(
        &self,
        observer_height_m: f64,
        elevations_rad: &[f64],
        distances_m: &[f64],
    ) -> Result<Vec<RayRecord>, TracerError> {
        for &e in elevations_rad {
            self.check(observer_height_m, e, distances_m)?;
        }
        elevations_rad
            .par_iter()
            .map(|&e| self.trace(observer_height_m, e, distances_m))
            .collect()
    }
}

fn check_distances(distances_m: &[f64]) -> Result<(), TracerError> {
    if distances_m.iter().any(|d| !(d.is_finite() && *d >= 0.0))
        || distances_m.windows(2).any(|w| w[1] < w[0])
    {
        return Err(TracerError::BadDistances);
    }
    Ok(())
}

/// Trace one ray through any 3-D field (the general path). `origin_m` is the observer
/// (Earth-centred for [`Ground::Sphere`], above z = 0 for [`Ground::Flat`]); ground distances are
/// measured from the observer's ground point. The record's `elevation_rad` is the launch
/// direction's elevation above the local horizontal; `config.earth_radius_m` is ignored (the
/// ground says).
#[allow(clippy::too_many_arguments)] // field, geometry, settings, ray, targets, hook, path: all distinct
pub fn trace_field<F: IndexField + ?Sized>(
    field: &F,
    ground: Ground,
    config: &TracerConfig,
    origin_m: DVec3,
    direction: DVec3,
    distances_m: &[f64],
    hook: &mut dyn RayHook,
    path: Option<&mut Vec<RayPoint>>,
) -> Result<RayRecord, TracerError> {
    config.validate()?;
    check_distances(distances_m)?;
    let dir = direction.normalize_or_zero();
    if !origin_m.is_finite() || dir == DVec3::ZERO || !dir.is_finite() {
        return Err(TracerError::BadDirection);
    }
    let (up, height) = match ground {
        Ground::Sphere { radius_m } => (origin_m.normalize(), origin_m.length() - radius_m),
        Ground::Flat => (DVec3::Z, origin_m.z),
    };
    if !(height >= 0.0 && height < config.top_m) {
        return Err(TracerError::ObserverOutside {
            height_m: height,
            top_m: config.top_m,
        });
    }
    let settled: Vec<f64>;
    let breaks: &[f64] = if field.minor_breaks().is_empty() {
        field.breaks_m()
    } else {
        let error_length_m = ray::error_length_m(config, distances_m);
        settled = breaks::settle(
            field.breaks_m(),
            field.minor_breaks(),
            config,
            error_length_m,
        );
        &settled
    };
    let sys = FieldSystem {
        field,
        ground,
        origin_m,
        breaks,
        start_direction: match ground {
            Ground::Sphere { .. } => up,
            Ground::Flat => DVec3::ZERO,
        },
    };
    let (n0, _) = field.index_and_gradient(origin_m);
    let t = dir * n0;
    let elevation = dir.dot(up).clamp(-1.0, 1.0).asin();
    let mut record = RayRecord::default();
    let state = [0.0, 0.0, 0.0, t.x, t.y, t.z];
    ray::integrate(
        &sys,
        state,
        elevation,
        config,
        distances_m,
        hook,
        &mut record,
        path,
    );
    Ok(record)
}
