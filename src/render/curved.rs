//! Stage 5 (render) — the real ray tracers behind the renderer's [`RayTracer`] trait. In: a
//! stratified refractive index (a [`RefractiveAtmosphere`] or any
//! [`StratifiedIndex`]), the tracer settings and the highest card top. Out: [`FanRay`]s — heights
//! at the card distances and how each ray ended.
//!
//! * [`CurvedRays`] — the planar fast path of [`Tracer`] (Dormand–Prince in the ray's vertical
//!   plane, dense-output target crossings). The renderer calls it a few thousand times per frame
//!   to build its elevation fan.
//! * [`ExactRays`] — the paper's method: every call integrates the full 3-D ray equation through
//!   the field ([`trace_field`] over [`Spherical`]). Used by the renderer's exact mode (one trace
//!   per pixel sample), to validate the fan and as the benchmark baseline.
//! * [`prepare_tracer`] — picks one of these, or [`StraightRays`], from a scene and options.
//!
//! **Early stops** follow the tracer's one fate rule, [`FateWatch`] (Bouguer's invariant over a
//! [`BouguerEnvelope`] of the field, built once per tracer): past the last card a ray that
//! provably oscillates in a duct ends [`Termination::Trapped`] ([`FanEnd::Trapped`], shaded as the
//! horizon sky). A ray that provably escapes, once nothing is left for it to meet — past the last
//! card, or climbing above every card top without another turning point — climbs out to the top
//! in closed form ([`FanEnd::Sky`] with its final direction), or, without a sun (the direction
//! does not matter), just ends there. Every other ray is traced to the sea or the top, however
//! far: there is no trap distance.

use std::cell::RefCell;

use glam::DVec3;

use super::RenderOptions;
use super::ray_model::{FanEnd, FanRay, RayModelError, RayTracer, StraightRays};
use crate::refractivity::RefractiveAtmosphere;
use crate::scene::Scene;
use crate::tracer::{
    BouguerEnvelope, DensityPaths, DensityPathsSoFar, FateWatch, Ground, PendingClimb,
    RayDensityPaths, RayPoint, RayRecord, Settled, Spherical, StratifiedIndex, Termination, Tracer,
    TracerConfig, TracerError, trace_field,
};

/// The tracer settings the renderer uses: [`TracerConfig::default`] (its tolerance, top at
/// 40 km) over `earth_radius_m`, never stopping at the last card (the renderer needs to know
/// whether the ray ends in the sea or the sky), with no distance limit (see the module docs).
pub fn render_tracer_config(earth_radius_m: f64) -> TracerConfig {
    TracerConfig {
        earth_radius_m,
        stop_after_last_target: false,
        max_distance_m: None,
        ..TracerConfig::default()
    }
}

/// Turn a traced record into the renderer's [`FanRay`] (non-finite values become `None` /
/// [`FanEnd::Lost`]).
fn fan_ray(record: &RayRecord, elevation_rad: f64, n_distances: usize) -> FanRay {
    let mut heights_m: Vec<Option<f64>> = Vec::with_capacity(n_distances);
    heights_m.extend(record.heights_m.iter().map(|h| h.filter(|v| v.is_finite())));
    heights_m.resize(n_distances, None);
    let end = match record.termination {
        Some(Termination::Ground) => {
            let grazing = -record.end.elevation_rad;
            if grazing.is_finite() && record.end.distance_m.is_finite() {
                FanEnd::Ground {
                    distance_m: record.end.distance_m,
                    grazing_rad: grazing.max(0.0),
                }
            } else {
                FanEnd::Lost
            }
        }
        Some(Termination::Escaped | Termination::LeftRegion)
            if record.end_observer_elevation_rad.is_finite() =>
        {
            FanEnd::Sky {
                elevation_rad: record.end_observer_elevation_rad,
            }
        }
        Some(Termination::Trapped) => FanEnd::Trapped,
        _ => FanEnd::Lost,
    };
    FanRay {
        elevation_rad,
        heights_m,
        end,
        monotone: !record.turned,
    }
}

fn lost(elevation_rad: f64, n_distances: usize) -> FanRay {
    FanRay {
        elevation_rad,
        heights_m: vec![None; n_distances],
        end: FanEnd::Lost,
        monotone: false,
    }
}

/// The fate rule shared by both back-ends: what the renderer needs of one ray.
#[derive(Debug, Clone)]
struct Fates {
    envelope: BouguerEnvelope,
    earth_radius_m: f64,
    cards_top_m: f64,
}

impl Fates {
    fn new<S: StratifiedIndex + ?Sized>(
        index: &S,
        config: &TracerConfig,
        cards_top_m: f64,
    ) -> Self {
        Fates {
            envelope: BouguerEnvelope::new(index, config.earth_radius_m, config.top_m),
            earth_radius_m: config.earth_radius_m,
            cards_top_m: cards_top_m.max(0.0),
        }
    }

    /// The watch for one ray: escaping rays climb out in closed form above the cards, or stop
    /// there when the sky direction is not needed.
    fn watch<S: StratifiedIndex + ?Sized>(
        &self,
        index: &S,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
    ) -> FateWatch<'_> {
        self.watch_above(
            index,
            camera_height_m,
            elevation_rad,
            distances_m,
            (need_sky_direction, 0.0),
        )
    }

    /// [`Self::watch`] for a ray that may stop early only `margin_m` above the cards
    /// ([`RayTracer::trace_with_margin`]; +∞: only past the last distance).
    fn watch_above<S: StratifiedIndex + ?Sized>(
        &self,
        index: &S,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        (need_sky_direction, margin_m): (bool, f64),
    ) -> FateWatch<'_> {
        let watch = FateWatch::new(
            &self.envelope,
            index,
            self.earth_radius_m,
            camera_height_m,
            elevation_rad,
            distances_m.last().copied().unwrap_or(0.0),
        )
        .clear_above(self.cards_top_m + margin_m);
        if need_sky_direction {
            watch
        } else {
            watch.without_direction()
        }
    }
}

thread_local! {
    /// Per-thread record reused by [`CurvedRays`]: a trace then allocates only the returned Vec.
    static SCRATCH: RefCell<RayRecord> = RefCell::new(RayRecord::default());
}

/// The curved-ray tracer (planar fast path) as a renderer back-end.
#[derive(Clone)]
pub struct CurvedRays<'a, S: StratifiedIndex + ?Sized> {
    tracer: Tracer<'a, S>,
    /// The same tracer stopping after the last distance asked for ([`RayTracer::heights_at`]).
    stopping: Tracer<'a, S>,
    fates: Fates,
}

impl<'a, S: StratifiedIndex + ?Sized> CurvedRays<'a, S> {
    /// Trace through `index` with `config` (use [`render_tracer_config`] unless testing
    /// something else; `stop_after_last_target` should be false, or rays that pass the last card
    /// end [`FanEnd::Lost`]). `cards_top_m`: the highest card top above the surface (m), 0
    /// without cards.
    pub fn new(index: &'a S, config: TracerConfig, cards_top_m: f64) -> Result<Self, TracerError> {
        let fates = Fates::new(index, &config, cards_top_m);
        let stopping = TracerConfig {
            stop_after_last_target: true,
            ..config.clone()
        };
        Ok(Self {
            tracer: Tracer::new(index, config)?,
            stopping: Tracer::new(index, stopping)?,
            fates,
        })
    }

    /// The underlying tracer.
    pub fn tracer(&self) -> &Tracer<'a, S> {
        &self.tracer
    }
}

impl<S: StratifiedIndex + ?Sized> CurvedRays<'_, S> {
    /// Trace one ray exactly as [`RayTracer::trace`] does, into `record` (its step counts, end
    /// and termination are the renderer's).
    pub fn trace_record_into(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
        record: &mut RayRecord,
    ) -> Result<(), TracerError> {
        let mut watch = self.fates.watch(
            self.tracer.field(),
            camera_height_m,
            elevation_rad,
            distances_m,
            need_sky_direction,
        );
        self.tracer.trace_into(
            camera_height_m,
            elevation_rad,
            distances_m,
            &mut watch,
            record,
            None,
        )
    }
}

/// The density-weighted path lengths of a ray traced by the planar `tracer` with the fate rule
/// `fates` (nothing to meet: an escaping ray climbs out in closed form at once).
fn density_paths_through<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    fates: &Fates,
    camera_height_m: f64,
    elevation_rad: f64,
    scale_heights_m: [f64; 2],
) -> Option<[f64; 2]> {
    let watch = fates.watch(tracer.field(), camera_height_m, elevation_rad, &[], true);
    let mut hook = DensityPaths::new(watch, scale_heights_m);
    let mut record = RayRecord::default();
    tracer
        .trace_into(
            camera_height_m,
            elevation_rad,
            &[],
            &mut hook,
            &mut record,
            None,
        )
        .ok()?;
    tracer.density_paths_m(camera_height_m, elevation_rad, &hook, &record)
}

/// The density-weighted path lengths to the ground distances `distances_m` and the ground of
/// the ray that the renderer's fan traces (as [`CurvedRays::trace_record_into`], without the
/// final sky direction).
fn density_paths_along_through<S: StratifiedIndex + ?Sized>(
    tracer: &Tracer<'_, S>,
    fates: &Fates,
    camera_height_m: f64,
    elevation_rad: f64,
    distances_m: &[f64],
    scale_heights_m: [f64; 2],
) -> Option<RayDensityPaths> {
    let watch = fates.watch(
        tracer.field(),
        camera_height_m,
        elevation_rad,
        distances_m,
        false,
    );
    let mut hook = DensityPaths::new(watch, scale_heights_m).at_distances(distances_m);
    let mut record = RayRecord::default();
    tracer
        .trace_into(
            camera_height_m,
            elevation_rad,
            distances_m,
            &mut hook,
            &mut record,
            None,
        )
        .ok()?;
    let start = RayPoint {
        arc_length_m: 0.0,
        distance_m: 0.0,
        height_m: camera_height_m,
        elevation_rad,
    };
    Some(hook.finish(start, &record))
}

impl<S: StratifiedIndex + ?Sized> RayTracer for CurvedRays<'_, S> {
    fn density_paths_along(
        &self,
        h: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        scales: [f64; 2],
    ) -> Option<RayDensityPaths> {
        density_paths_along_through(
            &self.tracer,
            &self.fates,
            h,
            elevation_rad,
            distances_m,
            scales,
        )
    }

    fn density_paths_m(&self, h: f64, elevation_rad: f64, scales: [f64; 2]) -> Option<[f64; 2]> {
        density_paths_through(&self.tracer, &self.fates, h, elevation_rad, scales)
    }

    fn trace_to_sky_with_density_paths(
        &self,
        h: f64,
        elevation_rad: f64,
        scales: [f64; 2],
    ) -> (FanRay, Option<[f64; 2]>) {
        let (ray, so_far) = self.trace_to_sky_deferring_density_paths(h, elevation_rad, scales);
        let paths = match so_far {
            DensityPathsSoFar::Done(paths) => paths,
            DensityPathsSoFar::Climb(climb) => self.tracer.finish_climb(&climb),
        };
        (ray, paths)
    }

    fn trace_to_sky_deferring_density_paths(
        &self,
        h: f64,
        elevation_rad: f64,
        scales: [f64; 2],
    ) -> (FanRay, DensityPathsSoFar) {
        // The fate rule of `trace` with the sky direction, which `density_paths_m` also
        // follows: one trace gives both.
        let watch = self
            .fates
            .watch(self.tracer.field(), h, elevation_rad, &[], true);
        let mut hook = DensityPaths::new(watch, scales);
        let mut record = RayRecord::default();
        match self
            .tracer
            .trace_into(h, elevation_rad, &[], &mut hook, &mut record, None)
        {
            Ok(()) => (
                fan_ray(&record, elevation_rad, 0),
                self.tracer
                    .density_paths_so_far(h, elevation_rad, &hook, &record),
            ),
            Err(_) => (lost(elevation_rad, 0), DensityPathsSoFar::Done(None)),
        }
    }

    fn finish_density_paths(&self, climb: &PendingClimb) -> Option<[f64; 2]> {
        self.tracer.finish_climb(climb)
    }

    fn trace(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
    ) -> FanRay {
        let run = |record: &mut RayRecord| match self.trace_record_into(
            camera_height_m,
            elevation_rad,
            distances_m,
            need_sky_direction,
            record,
        ) {
            Ok(()) => fan_ray(record, elevation_rad, distances_m.len()),
            Err(_) => lost(elevation_rad, distances_m.len()),
        };
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut record) => run(&mut record),
            // Re-entered on this thread (cannot happen through the renderer): no scratch.
            Err(_) => run(&mut RayRecord::default()),
        })
    }

    fn heights_at(&self, h: f64, elevation_rad: f64, distances_m: &[f64]) -> Vec<Option<f64>> {
        // The fate rule of `trace` without the sky direction (rays above everything stop), on
        // the tracer that also stops past the last distance.
        let mut watch = self
            .fates
            .watch(self.tracer.field(), h, elevation_rad, distances_m, false);
        let mut record = RayRecord::default();
        let traced =
            self.stopping
                .trace_into(h, elevation_rad, distances_m, &mut watch, &mut record, None);
        let mut heights: Vec<Option<f64>> = match traced {
            Ok(()) => record
                .heights_m
                .iter()
                .map(|h| h.filter(|v| v.is_finite()))
                .collect(),
            Err(_) => Vec::new(),
        };
        heights.resize(distances_m.len(), None);
        heights
    }

    fn trace_with_margin(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
        margin_m: f64,
    ) -> FanRay {
        let mut watch = self.fates.watch_above(
            self.tracer.field(),
            camera_height_m,
            elevation_rad,
            distances_m,
            (need_sky_direction, margin_m),
        );
        let mut record = RayRecord::default();
        match self.tracer.trace_into(
            camera_height_m,
            elevation_rad,
            distances_m,
            &mut watch,
            &mut record,
            None,
        ) {
            Ok(()) => fan_ray(&record, elevation_rad, distances_m.len()),
            Err(_) => lost(elevation_rad, distances_m.len()),
        }
    }
}

/// The paper's method as a renderer back-end: every ray integrated in 3-D through the field
/// ∇n = dn/dh · r̂ ([`trace_field`] over [`Spherical`]).
///
/// The ray is launched towards azimuth 0 (the x axis of an Earth-centred frame whose z axis goes
/// through the observer), whatever the pixel's azimuth: the field is spherically symmetric, so a
/// ray launched at another azimuth is this one rotated about the observer's vertical, with the
/// same heights at the same ground distances and the same end (the integrator's error control is
/// rotation-invariant up to rounding; a unit test checks this). The renderer takes the pixel's
/// azimuth into account when it shades (which card the ray meets), so the [`RayTracer`] trait
/// needs no azimuth.
pub struct ExactRays<'a, S: StratifiedIndex + ?Sized> {
    /// The field in 3-D, its minor breaks settled once for `config`.
    field: Settled<Spherical<&'a S>>,
    /// The planar tracer of the same index and settings, for path integrals.
    planar: Tracer<'a, S>,
    config: TracerConfig,
    fates: Fates,
}

impl<'a, S: StratifiedIndex + ?Sized> ExactRays<'a, S> {
    /// As [`CurvedRays::new`].
    pub fn new(index: &'a S, config: TracerConfig, cards_top_m: f64) -> Result<Self, TracerError> {
        config.validate()?;
        let field = Spherical {
            index,
            earth_radius_m: config.earth_radius_m,
        };
        Ok(Self {
            field: Settled::new(field, &config),
            planar: Tracer::new(index, config.clone())?,
            fates: Fates::new(index, &config, cards_top_m),
            config,
        })
    }

    /// Trace one ray in 3-D towards `azimuth_rad` (about the observer's vertical, from the frame's
    /// x axis; any azimuth gives the same ray up to a rotation) and return the full record.
    pub fn trace_record(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        azimuth_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
    ) -> Result<RayRecord, TracerError> {
        self.trace_record_with(
            (camera_height_m, elevation_rad, azimuth_rad),
            distances_m,
            (need_sky_direction, 0.0),
        )
    }

    /// [`Self::trace_record`] from (height, elevation, azimuth); `margin_m`: how far above
    /// the cards a ray climbing clear of them may stop ([`RayTracer::trace_with_margin`]).
    fn trace_record_with(
        &self,
        (camera_height_m, elevation_rad, azimuth_rad): (f64, f64, f64),
        distances_m: &[f64],
        (need_sky_direction, margin_m): (bool, f64),
    ) -> Result<RayRecord, TracerError> {
        let radius = self.config.earth_radius_m;
        let origin = DVec3::new(0.0, 0.0, radius + camera_height_m);
        let (sin_e, cos_e) = elevation_rad.sin_cos();
        let (sin_a, cos_a) = azimuth_rad.sin_cos();
        let direction = DVec3::new(cos_e * cos_a, cos_e * sin_a, sin_e);
        let mut watch = self.fates.watch_above(
            self.field.field.index,
            camera_height_m,
            elevation_rad,
            distances_m,
            (need_sky_direction, margin_m),
        );
        trace_field(
            &self.field,
            Ground::Sphere { radius_m: radius },
            &self.config,
            origin,
            direction,
            distances_m,
            &mut watch,
            None,
        )
    }
}

impl<S: StratifiedIndex + ?Sized> RayTracer for ExactRays<'_, S> {
    fn density_paths_along(
        &self,
        h: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        scales: [f64; 2],
    ) -> Option<RayDensityPaths> {
        density_paths_along_through(
            &self.planar,
            &self.fates,
            h,
            elevation_rad,
            distances_m,
            scales,
        )
    }

    /// Through the planar tracer: in a stratified atmosphere the ray's path does not depend on
    /// how it is integrated (the fan and exact paths agree; see the renderer's tests).
    fn density_paths_m(&self, h: f64, elevation_rad: f64, scales: [f64; 2]) -> Option<[f64; 2]> {
        density_paths_through(&self.planar, &self.fates, h, elevation_rad, scales)
    }

    fn trace(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
    ) -> FanRay {
        match self.trace_record(
            camera_height_m,
            elevation_rad,
            0.0,
            distances_m,
            need_sky_direction,
        ) {
            Ok(record) => fan_ray(&record, elevation_rad, distances_m.len()),
            Err(_) => lost(elevation_rad, distances_m.len()),
        }
    }

    fn trace_with_margin(
        &self,
        camera_height_m: f64,
        elevation_rad: f64,
        distances_m: &[f64],
        need_sky_direction: bool,
        margin_m: f64,
    ) -> FanRay {
        match self.trace_record_with(
            (camera_height_m, elevation_rad, 0.0),
            distances_m,
            (need_sky_direction, margin_m),
        ) {
            Ok(record) => fan_ray(&record, elevation_rad, distances_m.len()),
            Err(_) => lost(elevation_rad, distances_m.len()),
        }
    }
}

/// Why [`prepare_tracer`] could not build a tracer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PrepareError {
    /// Curved rays need a refractive atmosphere (only `straight = true` scenes work without one).
    #[error("the scene uses curved rays but no refractive atmosphere was given")]
    MissingAtmosphere,
    /// The tracer settings were invalid (e.g. the Earth radius).
    #[error(transparent)]
    Tracer(#[from] TracerError),
    /// The straight-ray model rejected the Earth radius.
    #[error(transparent)]
    RayModel(#[from] RayModelError),
    /// A render option is out of range (the tracer tolerance).
    #[error(transparent)]
    Options(#[from] super::RenderError),
    /// The refractive atmosphere could not be rebuilt at a spectral band's wavelength.
    #[error("the refractive atmosphere at a spectral band's wavelength: {0}")]
    Refractivity(#[from] crate::refractivity::RefractivityError),
}

/// Highest card top in `scene` (m above the surface; 0 without cards), or the highest terrain
/// if that is higher (rays climbing above it may stop early).
pub fn cards_top_m(scene: &Scene) -> f64 {
    let cards = scene
        .cards
        .iter()
        .map(|c| c.base_m + c.height_m)
        .fold(0.0, f64::max);
    scene
        .terrain
        .as_ref()
        .map_or(cards, |t| cards.max(t.max_height_m))
}

/// The ray tracer for rendering `scene` with `options`:
///
/// * `scene.atmosphere.straight` → [`StraightRays`] (no atmosphere needed; `atmosphere` ignored);
/// * otherwise, `options.exact` → [`ExactRays`] (3-D per sample), else [`CurvedRays`] (fan);
///   both through `atmosphere` with [`render_tracer_config`]`(scene.earth_radius_m)`, its
///   tolerance set to `options.tolerance_m` (checked by [`check_tracer_tolerance`](super::check_tracer_tolerance)).
///
/// The camera must be inside the traced atmosphere (below its top, 40 km for both back-ends):
/// otherwise every curved ray would be refused by the tracer and shaded as the fallback horizon
/// sky, a silently wrong frame, so it is an error ([`TracerError::ObserverOutside`]).
pub fn prepare_tracer<'a>(
    scene: &Scene,
    atmosphere: Option<&'a RefractiveAtmosphere>,
    options: &RenderOptions,
) -> Result<Box<dyn RayTracer + 'a>, PrepareError> {
    super::check_tracer_tolerance(options.tolerance_m)?;
    let config = TracerConfig {
        tolerance_m: options.tolerance_m,
        ..render_tracer_config(scene.earth_radius_m)
    };
    let camera_height_m = scene.camera.height_m;
    if !(camera_height_m >= 0.0 && camera_height_m < config.top_m) {
        return Err(PrepareError::Tracer(TracerError::ObserverOutside {
            height_m: camera_height_m,
            top_m: config.top_m,
        }));
    }
    if scene.atmosphere.straight {
        return Ok(Box::new(StraightRays::new(scene.earth_radius_m)?));
    }
    let atmosphere = atmosphere.ok_or(PrepareError::MissingAtmosphere)?;
    let top = cards_top_m(scene);
    if options.exact {
        Ok(Box::new(ExactRays::new(atmosphere, config, top)?))
    } else {
        Ok(Box::new(CurvedRays::new(atmosphere, config, top)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::EARTH_RADIUS_M;

    /// n = 1 + a·exp(−h/H) with an optional linear layer of gradient g between `lo` and `hi`.
    struct Layered {
        g: f64,
        lo: f64,
        hi: f64,
    }

    impl StratifiedIndex for Layered {
        fn index_and_derivative(&self, h: f64) -> (f64, f64) {
            let (a, scale) = (2.8e-4, 8_000.0);
            let e = (-h / scale).exp();
            let mut n = 1.0 + a * e;
            let mut dn = -a * e / scale;
            if h > self.lo {
                let top = h.min(self.hi);
                n += self.g * (top - self.lo);
                if h < self.hi {
                    dn += self.g;
                }
            }
            (n, dn)
        }
    }

    fn plain() -> Layered {
        Layered {
            g: 0.0,
            lo: 0.0,
            hi: 0.0,
        }
    }

    fn scene_with_camera_at(height_m: f64, straight: bool) -> Scene {
        let text = format!(
            "[camera]\nheight_m = {height_m}\nhfov_deg = 1.0\nwidth = 4\nheight = 2\n\
             [atmosphere]\nstraight = {straight}\n"
        );
        let path = std::path::Path::new("camera_test.toml");
        Scene::from_toml_str(&text, std::path::Path::new("."), path).expect("valid scene")
    }

    #[test]
    fn one_trace_to_the_sky_gives_the_end_and_paths_of_the_two_calls() {
        // A duct at 0–40 m that traps the lowest rays from the sea, and plain air.
        for field in [
            Layered {
                g: -2e-7,
                lo: 0.0,
                hi: 40.0,
            },
            plain(),
        ] {
            let rays = CurvedRays::new(&field, render_tracer_config(EARTH_RADIUS_M), 0.0).unwrap();
            let scales = [8_000.0, 1_000.0];
            let (mut kinds, mut climbs) = ([0; 2], 0);
            for (h, i) in [0.0, 100.0]
                .into_iter()
                .flat_map(|h| (0..60).map(move |i| (h, i)))
            {
                let e = -0.001 + 0.0005 * f64::from(i) * f64::from(i);
                let (ray, paths) = rays.trace_to_sky_with_density_paths(h, e, scales);
                let end = ray.end;
                let want = (
                    rays.trace(h, e, &[], true),
                    rays.density_paths_m(h, e, scales),
                );
                assert_eq!(
                    format!("{:?}", (ray, paths)),
                    format!("{want:?}"),
                    "{h} {e}"
                );
                // The same with the climb out left for later, then done.
                let (ray, so_far) = rays.trace_to_sky_deferring_density_paths(h, e, scales);
                let paths = match so_far {
                    DensityPathsSoFar::Done(paths) => paths,
                    DensityPathsSoFar::Climb(climb) => {
                        climbs += 1;
                        rays.finish_density_paths(&climb)
                    }
                };
                assert_eq!(
                    format!("{:?}", (ray, paths)),
                    format!("{want:?}"),
                    "{h} {e}"
                );
                kinds[usize::from(matches!(end, FanEnd::Sky { .. }))] += 1;
            }
            assert!(kinds[1] > 10, "{kinds:?}");
            assert!(climbs > 10, "{climbs}");
        }
    }

    #[test]
    fn camera_above_the_atmosphere_top_is_an_error_not_an_all_sky_frame() {
        // The scene format accepts cameras up to 100 km, the tracers stop rays at 40 km: a camera
        // at 90 km looking down used to get a frame of fallback horizon sky with no sea.
        let top = render_tracer_config(EARTH_RADIUS_M).top_m;
        for straight in [false, true] {
            let scene = scene_with_camera_at(90_000.0, straight);
            match prepare_tracer(&scene, None, &RenderOptions::default()) {
                Err(PrepareError::Tracer(TracerError::ObserverOutside { height_m, top_m })) => {
                    assert_eq!((height_m, top_m), (90_000.0, top));
                }
                Err(e) => panic!("straight = {straight}: wrong error {e}"),
                Ok(_) => panic!("straight = {straight}: a camera at 90 km was accepted"),
            }
        }
        // Just below the top it is fine (straight rays need no atmosphere).
        let scene = scene_with_camera_at(top - 1.0, true);
        assert!(prepare_tracer(&scene, None, &RenderOptions::default()).is_ok());
    }

    #[test]
    fn prepare_refuses_a_bad_tracer_tolerance() {
        let scene = scene_with_camera_at(10.0, true);
        let options = RenderOptions {
            tolerance_m: 0.0,
            ..RenderOptions::default()
        };
        assert!(matches!(
            prepare_tracer(&scene, None, &options),
            Err(PrepareError::Options(_))
        ));
    }

    #[test]
    fn early_stop_gives_the_same_heights_and_end_kind() {
        // With a strong duct at 80–120 m (Δn = −4e-5, like +10 K over 15 m), rays from 10 m that
        // rise above the cards (30 m) up to α ≈ 7 mrad are still bent back to the sea; the early stop must not report them as sky.
        let duct = Layered {
            g: -1e-6,
            lo: 80.0,
            hi: 120.0,
        };
        let rays =
            CurvedRays::new(&duct, render_tracer_config(EARTH_RADIUS_M), 30.0).expect("tracer");
        let d = [5_000.0, 15_000.0, 26_000.0];
        let mut grounds = 0;
        for i in 0..200 {
            let alpha = -0.004 + 0.01 * i as f64 / 200.0;
            let full = rays.trace(10.0, alpha, &d, true);
            let quick = rays.trace(10.0, alpha, &d, false);
            assert_eq!(
                std::mem::discriminant(&full.end),
                std::mem::discriminant(&quick.end),
                "α={alpha}: {full:?} vs {quick:?}"
            );
            for (a, b) in full.heights_m.iter().zip(&quick.heights_m) {
                match (a, b) {
                    (Some(x), Some(y)) => assert_eq!(x, y),
                    // The quick ray stopped above every card and climbing: it would be higher.
                    (Some(x), None) => assert!(*x > 30.0, "α={alpha}: {x}"),
                    (None, None) => {}
                    (None, Some(y)) => panic!("α={alpha}: quick has {y}, full none"),
                }
            }
            if let (FanEnd::Ground { distance_m: a, .. }, FanEnd::Ground { distance_m: b, .. }) =
                (full.end, quick.end)
            {
                assert_eq!(a, b);
                if alpha > 0.0 {
                    grounds += 1;
                }
            }
        }
        // The duct really does bring rising rays down (the test exercises the early stop).
        assert!(grounds > 10, "{grounds}");
    }

    #[test]
    fn curved_rays_agree_with_the_exact_3d_rays() {
        let duct = Layered {
            g: -3e-7,
            lo: 80.0,
            hi: 120.0,
        };
        let cfg = render_tracer_config(EARTH_RADIUS_M);
        let fast = CurvedRays::new(&duct, cfg.clone(), 30.0).unwrap();
        let exact = ExactRays::new(&duct, cfg, 30.0).unwrap();
        let d = [5_000.0, 15_000.0, 26_000.0];
        for i in 0..40 {
            let alpha = -0.003 + 0.008 * i as f64 / 40.0;
            let a = fast.trace(10.0, alpha, &d, true);
            let b = exact.trace(10.0, alpha, &d, true);
            assert_eq!(
                std::mem::discriminant(&a.end),
                std::mem::discriminant(&b.end),
                "α={alpha}"
            );
            for (x, y) in a.heights_m.iter().zip(&b.heights_m) {
                if let (Some(x), Some(y)) = (x, y) {
                    // Both integrate to 1 cm per step; allow a few centimetres accumulated.
                    assert!((x - y).abs() < 0.1, "α={alpha}: {x} vs {y}");
                }
            }
            if let (FanEnd::Sky { elevation_rad: x }, FanEnd::Sky { elevation_rad: y }) =
                (a.end, b.end)
            {
                assert!((x - y).abs() < 1e-6, "α={alpha}: {x} vs {y}");
            }
        }
    }

    #[test]
    fn exact_rays_do_not_depend_on_azimuth() {
        let duct = Layered {
            g: -3e-7,
            lo: 80.0,
            hi: 120.0,
        };
        let exact = ExactRays::new(&duct, render_tracer_config(EARTH_RADIUS_M), 30.0).unwrap();
        let d = [5_000.0, 15_000.0];
        for &alpha in &[-0.002, 0.0005, 0.003] {
            let base = exact.trace_record(10.0, alpha, 0.0, &d, true).unwrap();
            for &az in &[0.7, 2.0, -2.9] {
                let r = exact.trace_record(10.0, alpha, az, &d, true).unwrap();
                assert_eq!(r.termination, base.termination);
                for (x, y) in r.heights_m.iter().zip(&base.heights_m) {
                    if let (Some(x), Some(y)) = (x, y) {
                        assert!((x - y).abs() < 1e-3, "α={alpha} az={az}: {x} vs {y}");
                    }
                }
            }
        }
    }

    #[test]
    fn straight_field_matches_closed_form() {
        // n ≡ 1: the tracer must reproduce the straight-ray geometry.
        struct Vacuum;
        impl StratifiedIndex for Vacuum {
            fn index_and_derivative(&self, _h: f64) -> (f64, f64) {
                (1.0, 0.0)
            }
        }
        // Cards up to 100 m: the rays' heights at 1 and 10 km are all below.
        let curved = CurvedRays::new(&Vacuum, render_tracer_config(EARTH_RADIUS_M), 100.0).unwrap();
        let straight = StraightRays::new(EARTH_RADIUS_M).unwrap();
        let d = [1_000.0, 10_000.0];
        for &alpha in &[-0.01, -0.0015, 0.0, 0.002] {
            let a = curved.trace(10.0, alpha, &d, true);
            let b = straight.trace(10.0, alpha, &d, true);
            for (x, y) in a.heights_m.iter().zip(&b.heights_m) {
                match (x, y) {
                    (Some(x), Some(y)) => assert!((x - y).abs() < 0.02, "{alpha}: {x} {y}"),
                    (None, None) => {}
                    _ => panic!("{alpha}: {a:?} {b:?}"),
                }
            }
            match (a.end, b.end) {
                (
                    FanEnd::Ground {
                        distance_m: x,
                        grazing_rad: gx,
                    },
                    FanEnd::Ground {
                        distance_m: y,
                        grazing_rad: gy,
                    },
                ) => {
                    assert!((x - y).abs() < 1.0, "{x} {y}");
                    assert!((gx - gy).abs() < 1e-6, "{gx} {gy}");
                }
                (FanEnd::Sky { elevation_rad: x }, FanEnd::Sky { elevation_rad: y }) => {
                    assert!((x - y).abs() < 1e-7, "{x} {y}")
                }
                other => panic!("{alpha}: {other:?}"),
            }
        }
    }

    #[test]
    fn a_ducted_ray_is_trapped_and_a_ray_out_of_steps_is_lost() {
        // An elevated duct from 20 to 60 m (dn/dh −4e-7, 2.5× the Earth's curvature): n·r peaks
        // at 20 m, and a level ray from 25 m oscillates about it (turning near 8.6 m and at
        // 25 m) for ever.
        let duct = Layered {
            g: -4e-7,
            lo: 20.0,
            hi: 60.0,
        };
        let config = render_tracer_config(EARTH_RADIUS_M);
        for need_sky in [false, true] {
            let rays = CurvedRays::new(&duct, config.clone(), 30.0).unwrap();
            let r = rays.trace(25.0, 0.0, &[5_000.0], need_sky);
            assert_eq!(r.end, FanEnd::Trapped, "{r:?}");
            assert!(r.heights_m[0].is_some_and(|h| h > 8.0 && h < 25.1), "{r:?}");
            let exact = ExactRays::new(&duct, config.clone(), 30.0).unwrap();
            assert_eq!(
                exact.trace(25.0, 0.0, &[5_000.0], need_sky).end,
                FanEnd::Trapped
            );
        }
        // The same ray with a budget of 20 steps is cut short: lost, not trapped.
        let short = TracerConfig {
            max_steps: 20,
            ..config
        };
        let rays = CurvedRays::new(&duct, short, 30.0).unwrap();
        assert_eq!(rays.trace(25.0, 0.0, &[50_000.0], true).end, FanEnd::Lost);
    }

    #[test]
    fn bad_input_is_lost_not_nan() {
        let air = plain();
        let rays = CurvedRays::new(&air, render_tracer_config(EARTH_RADIUS_M), 0.0).unwrap();
        let r = rays.trace(-5.0, 0.0, &[1.0, 2.0], false);
        assert_eq!(r.end, FanEnd::Lost);
        assert_eq!(r.heights_m, vec![None, None]);
        let r = rays.trace(10.0, f64::NAN, &[1.0], true);
        assert_eq!(r.end, FanEnd::Lost);
        let exact = ExactRays::new(&air, render_tracer_config(EARTH_RADIUS_M), 0.0).unwrap();
        assert_eq!(exact.trace(10.0, f64::NAN, &[], true).end, FanEnd::Lost);
    }
}
