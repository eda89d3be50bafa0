//! Render — the sun seen from the sea surface, for its glitter. In: the tracer, the sun's true
//! elevation at the camera, the farthest sea point of the frame and the sky's extinction. Out: a
//! table by the sun's true elevation above a sea point's own horizontal of its apparent elevation
//! there (the launch elevation of the ray from the sea that leaves towards it) and the optical
//! depth of that ray.
//!
//! A sea point at ground distance d from the camera has its vertical tilted by d/R, so the sun
//! stands higher (towards it) or lower (away) by up to d/R above its horizontal than above the
//! camera's. Near the surface of a duct the refraction depends strongly on that elevation (fig12:
//! 1.54° for a sun 1.5° below the horizontal, 0.5° for one at 0.2°), so each sea point needs the
//! refraction of its own sun, not the camera foot's with the tilt added.
//!
//! The table is one set of rays launched from the sea surface (height 0) at elevations spanning
//! the frame's true elevations, each with the elevation it leaves the atmosphere at (its true
//! elevation) and its optical depth: a monotone map from launch to true elevation, inverted by
//! cubic interpolation through four neighbouring rays. Rays are added at the middle of every
//! interval whose middle ray the table without it mispredicts by more than
//! [`LAUNCH_TOLERANCE_RAD`] in the launch or [`DEPTH_TOLERANCE`] in the optical depth, so they
//! crowd where the final elevation changes fast (a duct's trapping edge). A ray that does not
//! leave (trapped in a duct, or back on the sea) passes below every sun: a sun below the lowest
//! leaving ray is hidden.

use rayon::prelude::*;

use super::ray_model::{FanEnd, RayTracer};
use crate::scene::sky::Extinction;

/// How far (rad) the interpolated launch of an interval's middle ray may be from its traced
/// launch before the interval is halved; the middle ray is kept either way, so the finished
/// table errs by less (unit-tested against the launch search of the renderer).
pub(super) const LAUNCH_TOLERANCE_RAD: f64 = 1e-7;

/// How far the interpolated optical depth of an interval's middle ray may be from its traced
/// one before the interval is halved (an error δ in the depth scales the glitter by e^−δ).
pub(super) const DEPTH_TOLERANCE: f64 = 1e-4;

/// Optical depth beyond which the sun's light at the sea counts as lost (e^−50 ≈ 2·10⁻²²): a
/// duct's trapping edge is not refined further once the lowest leaving ray's depth exceeds it.
const DARK_DEPTH: f64 = 50.0;

/// Narrowest launch interval (rad) halved: the renderer's launch search's tolerance.
const MIN_WIDTH_RAD: f64 = 5e-9;

/// Launch intervals traced before refinement.
const INITIAL_INTERVALS: usize = 8;

/// Highest launch elevation traced (rad); above its ray's true elevation the refraction is taken
/// as that ray's.
const MAX_LAUNCH_RAD: f64 = 1.5;

/// Most rays in a table (refinement stops there).
const MAX_RAYS: usize = 4096;

/// True elevations beyond the frame's tilts that the table spans (rad), for samples between
/// the traced rays.
const PAD_RAD: f64 = 2e-3;

/// One ray from the sea surface.
#[derive(Debug, Clone, Copy)]
struct SeaRay {
    launch_rad: f64,
    /// Final elevation above the launch point's horizontal (rad); `None`: it does not leave.
    true_rad: Option<f64>,
    /// Optical depth per channel of its path out (+∞ when it does not leave).
    depth: [f64; 3],
}

impl SeaRay {
    fn trace(tracer: &dyn RayTracer, extinction: &Extinction, launch_rad: f64) -> Self {
        let true_rad = match tracer.trace(0.0, launch_rad, &[], true).end {
            FanEnd::Sky { elevation_rad } if elevation_rad.is_finite() => Some(elevation_rad),
            _ => None,
        };
        let depth = true_rad
            .and_then(|_| tracer.density_paths_m(0.0, launch_rad, extinction.scale_heights_m()))
            .map_or([f64::INFINITY; 3], |p| extinction.path_optical_depth(p));
        SeaRay {
            launch_rad,
            true_rad,
            depth,
        }
    }

    /// The least optical depth of its channels.
    fn least_depth(&self) -> f64 {
        self.depth.iter().copied().fold(f64::INFINITY, f64::min)
    }
}

/// The sun's apparent elevation and optical depth at the sea surface, by its true elevation
/// above the sea point's horizontal, over the range a frame's sea points need.
#[derive(Debug, Clone)]
pub(super) struct SeaSunTable {
    /// True elevations of the leaving rays (rad), ascending.
    true_rad: Vec<f64>,
    /// Their launch (apparent) elevations (rad).
    launch_rad: Vec<f64>,
    /// Their optical depths per channel.
    depth: Vec<[f64; 3]>,
    /// Per interval between neighbouring rays: the interpolating cubics (launch, then the
    /// three depths) in the fraction u ∈ [0, 1] of the interval, as monomial coefficients.
    cubics: Vec<[[f64; 4]; 4]>,
    /// 1 / each interval's width in true elevation.
    inv_width: Vec<f64>,
    /// The first interval of each of [`BUCKETS_PER_RAY`] × rays equal buckets of true
    /// elevation over the table (so a lookup walks at most a few intervals).
    buckets: Vec<u32>,
    /// Buckets per radian of true elevation.
    bucket_scale: f64,
    /// Whether a sun below the lowest leaving ray is hidden (that ray is launched level, or
    /// just above rays that do not leave); otherwise below the table the refraction is the
    /// lowest ray's.
    hidden_below: bool,
    /// Whether the traced true elevations rose with the launch everywhere.
    monotonic: bool,
    /// Rays traced to build the table.
    #[cfg_attr(not(test), allow(dead_code))]
    rays: usize,
}

impl SeaSunTable {
    /// Tabulate over true elevations `sun_elevation_rad` ± `max_tilt_rad` (padded).
    pub(super) fn build(
        tracer: &dyn RayTracer,
        sun_elevation_rad: f64,
        max_tilt_rad: f64,
        extinction: &Extinction,
    ) -> Self {
        let tilt = if max_tilt_rad.is_finite() {
            max_tilt_rad.abs()
        } else {
            0.0
        };
        let want = (
            sun_elevation_rad - tilt - PAD_RAD,
            sun_elevation_rad + tilt + PAD_RAD,
        );
        let trace = |a: f64| SeaRay::trace(tracer, extinction, a);
        let (lo, hi) = rayon::join(
            || lowest_ray(&trace, want.0),
            || highest_ray(&trace, want.1),
        );
        let mut rays = vec![lo];
        let width = hi.launch_rad - lo.launch_rad;
        let inner: Vec<SeaRay> = (1..INITIAL_INTERVALS)
            .into_par_iter()
            .map(|i| trace(lo.launch_rad + width * i as f64 / INITIAL_INTERVALS as f64))
            .collect();
        rays.extend(inner);
        rays.push(hi);
        let rays = refine(&trace, rays, want);
        Self::from_rays(&rays)
    }

    /// The table of `rays` (ascending launches).
    fn from_rays(rays: &[SeaRay]) -> Self {
        let first_leaving = rays.iter().position(|r| r.true_rad.is_some());
        let hidden_below = match first_leaving {
            Some(0) => rays[0].launch_rad <= 0.0,
            _ => true,
        };
        let (mut true_rad, mut launch_rad, mut depth) = (Vec::new(), Vec::new(), Vec::new());
        let mut monotonic = true;
        for r in rays {
            let Some(s) = r.true_rad else {
                // A ray above leaving ones that does not leave: the map is not monotone.
                monotonic &= true_rad.is_empty();
                continue;
            };
            // Only rays above every lower one's true elevation (one launch per true elevation).
            if true_rad.last().is_some_and(|&last| s <= last) {
                monotonic = false;
                continue;
            }
            true_rad.push(s);
            launch_rad.push(r.launch_rad);
            depth.push(r.depth);
        }
        let (cubics, inv_width) = cubics(&true_rad, &launch_rad, &depth);
        let (buckets, bucket_scale) = buckets(&true_rad);
        SeaSunTable {
            true_rad,
            launch_rad,
            depth,
            cubics,
            inv_width,
            buckets,
            bucket_scale,
            hidden_below,
            monotonic,
            rays: rays.len(),
        }
    }

    /// How many rays the table traced.
    #[cfg(test)]
    pub(super) fn rays(&self) -> usize {
        self.rays
    }

    /// The apparent elevation (rad) above the sea point's horizontal of a sun at true elevation
    /// `true_rad` above it (where it is below the sea's apparent horizon, the lowest leaving
    /// ray's), and the optical depth per channel of its light there (+∞ where hidden).
    pub(super) fn at(&self, true_rad: f64) -> (f64, [f64; 3]) {
        let n = self.true_rad.len();
        if n == 0 {
            return (0.0, [f64::INFINITY; 3]);
        }
        let (s0, s_last) = (self.true_rad[0], self.true_rad[n - 1]);
        if true_rad.is_nan() || true_rad < s0 {
            let a = self.launch_rad[0];
            return if self.hidden_below || true_rad.is_nan() {
                (a, [f64::INFINITY; 3])
            } else {
                (true_rad + a - s0, self.depth[0])
            };
        }
        if true_rad >= s_last || n == 1 {
            return (
                true_rad + self.launch_rad[n - 1] - s_last,
                self.depth[n - 1],
            );
        }
        let (i, u) = self.cell(true_rad);
        let c = &self.cubics[i];
        let horner = |k: usize| c[k][0] + u * (c[k][1] + u * (c[k][2] + u * c[k][3]));
        (horner(0), [horner(1), horner(2), horner(3)])
    }

    /// The interval of the table holding `true_rad` (strictly inside its span) and the
    /// fraction of the way through it.
    #[inline]
    fn cell(&self, true_rad: f64) -> (usize, f64) {
        let n = self.true_rad.len();
        let b = ((true_rad - self.true_rad[0]) * self.bucket_scale) as usize;
        let mut i = self.buckets[b.min(self.buckets.len() - 1)] as usize;
        while i > 0 && true_rad < self.true_rad[i] {
            i -= 1;
        }
        while i + 2 < n && true_rad >= self.true_rad[i + 1] {
            i += 1;
        }
        (i, (true_rad - self.true_rad[i]) * self.inv_width[i])
    }

    /// The apparent elevation of [`Self::at`] alone (the same value, without the depths).
    pub(super) fn apparent_rad(&self, true_rad: f64) -> f64 {
        let n = self.true_rad.len();
        if n < 2
            || true_rad.is_nan()
            || true_rad < self.true_rad[0]
            || true_rad >= self.true_rad[n - 1]
        {
            return self.at(true_rad).0;
        }
        let (i, u) = self.cell(true_rad);
        let c = &self.cubics[i][0];
        c[0] + u * (c[1] + u * (c[2] + u * c[3]))
    }

    /// The optical depth of [`Self::at`] alone.
    pub(super) fn depth(&self, true_rad: f64) -> [f64; 3] {
        self.at(true_rad).1
    }

    /// Bounds (lo, hi) on the apparent elevation of every true elevation in `true_rad` (lo, hi),
    /// padded for the interpolation's wiggle.
    pub(super) fn apparent_range(&self, true_rad: (f64, f64)) -> (f64, f64) {
        const WIGGLE_RAD: f64 = 1e-6;
        if !self.monotonic {
            let (lo, hi) = self
                .launch_rad
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                });
            let (a, b) = (self.apparent_rad(true_rad.0), self.apparent_rad(true_rad.1));
            return (lo.min(a) - WIGGLE_RAD, hi.max(b) + WIGGLE_RAD);
        }
        (
            self.apparent_rad(true_rad.0) - WIGGLE_RAD,
            self.apparent_rad(true_rad.1) + WIGGLE_RAD,
        )
    }
}

/// Buckets of true elevation per ray of a table.
const BUCKETS_PER_RAY: usize = 4;

/// The cubics of [`interpolate`] on each interval of `xs` (ascending, at least two), in the
/// fraction of the interval (found from its values at u = 0, ⅓, ⅔, 1; an interval next to an
/// infinite depth is infinitely deep), and 1 / the intervals' widths.
fn cubics(xs: &[f64], launch: &[f64], depth: &[[f64; 3]]) -> (Vec<[[f64; 4]; 4]>, Vec<f64>) {
    if xs.len() < 2 {
        return (Vec::new(), Vec::new());
    }
    let fit = |v: [f64; 4]| {
        if !v.iter().all(|x| x.is_finite()) {
            return [f64::INFINITY, 0.0, 0.0, 0.0];
        }
        // The cubic through (0, v0), (⅓, v1), (⅔, v2), (1, v3) in monomial form.
        let c1 = (-11.0 * v[0] + 18.0 * v[1] - 9.0 * v[2] + 2.0 * v[3]) / 2.0;
        let c2 = 9.0 * (2.0 * v[0] - 5.0 * v[1] + 4.0 * v[2] - v[3]) / 2.0;
        let c3 = 27.0 * (-v[0] + 3.0 * v[1] - 3.0 * v[2] + v[3]) / 6.0;
        [v[0], c1, c2, c3]
    };
    xs.windows(2)
        .map(|w| {
            let at = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0].map(|u| {
                // The ends exactly at the rays (the cubic passes through them).
                let s = if u == 1.0 {
                    w[1]
                } else {
                    w[0] + (w[1] - w[0]) * u
                };
                interpolate(xs, launch, depth, s.min(w[1]))
            });
            let mut c = [[0.0; 4]; 4];
            c[0] = fit(at.map(|(a, _)| a));
            for k in 0..3 {
                c[k + 1] = fit(at.map(|(_, d)| d[k]));
            }
            (c, 1.0 / (w[1] - w[0]))
        })
        .unzip()
}

/// The buckets of [`SeaSunTable::buckets`] over `xs` (ascending, at least two) and their
/// number per radian.
fn buckets(xs: &[f64]) -> (Vec<u32>, f64) {
    let n = xs.len();
    if n < 2 {
        return (vec![0], 0.0);
    }
    let count = BUCKETS_PER_RAY * n;
    let scale = count as f64 / (xs[n - 1] - xs[0]);
    let mut i = 0;
    let buckets = (0..count)
        .map(|b| {
            let s = xs[0] + b as f64 / scale;
            while i + 2 < n && s >= xs[i + 1] {
                i += 1;
            }
            i as u32
        })
        .collect();
    (buckets, scale)
}

/// The first (lowest) ray of the table: one that does not leave, is launched level, or leaves
/// at or below `true_lo_rad`.
fn lowest_ray(trace: &(impl Fn(f64) -> SeaRay + Sync), true_lo_rad: f64) -> SeaRay {
    let mut margin = 0.01;
    loop {
        let ray = trace((true_lo_rad - margin).max(0.0));
        if ray.launch_rad <= 0.0 || ray.true_rad.is_none_or(|s| s <= true_lo_rad) {
            return ray;
        }
        margin *= 4.0;
    }
}

/// The last (highest) ray of the table: one that leaves at or above `true_hi_rad`, or the
/// highest traced ([`MAX_LAUNCH_RAD`]).
fn highest_ray(trace: &(impl Fn(f64) -> SeaRay + Sync), true_hi_rad: f64) -> SeaRay {
    let mut margin = 0.03;
    loop {
        let launch = (true_hi_rad + margin).clamp(1e-3, MAX_LAUNCH_RAD);
        let ray = trace(launch);
        if launch >= MAX_LAUNCH_RAD || ray.true_rad.is_some_and(|s| s >= true_hi_rad) {
            return ray;
        }
        margin *= 4.0;
    }
}

/// `rays` (ascending launches, the first and last bracketing the true elevations `want`) with
/// rays added where the table needs them (module docs), ascending.
fn refine(
    trace: &(impl Fn(f64) -> SeaRay + Sync),
    mut rays: Vec<SeaRay>,
    want: (f64, f64),
) -> Vec<SeaRay> {
    // Intervals to test, by their ends' launches.
    let mut open: Vec<(f64, f64)> = rays
        .windows(2)
        .filter(|w| needs_middle(w[0], w[1], want))
        .map(|w| (w[0].launch_rad, w[1].launch_rad))
        .collect();
    while !open.is_empty() && rays.len() < MAX_RAYS {
        let middles: Vec<SeaRay> = open
            .par_iter()
            .map(|&(a, b)| trace(0.5 * (a + b)))
            .collect();
        let table = SeaSunTable::from_rays(&rays);
        let mut next = Vec::new();
        for (&(a, b), m) in open.iter().zip(&middles) {
            if !table.predicts(m) {
                next.push((a, m.launch_rad));
                next.push((m.launch_rad, b));
            }
        }
        rays.extend(middles);
        rays.sort_by(|x, y| x.launch_rad.total_cmp(&y.launch_rad));
        // Halves go on only while they may still matter (and are wide enough).
        open = next
            .into_iter()
            .filter(|&(a, b)| {
                let find = |l: f64| {
                    let i = rays.partition_point(|r| r.launch_rad < l);
                    rays[i.min(rays.len() - 1)]
                };
                needs_middle(find(a), find(b), want)
            })
            .collect();
    }
    rays
}

/// Whether the interval between rays `p` and `q` (ascending launches) needs its middle ray
/// tested: it is wide enough, and it is a trapping edge whose leaving side is neither dark
/// nor below the wanted true elevations, or both leave and the interval meets `want`.
fn needs_middle(p: SeaRay, q: SeaRay, want: (f64, f64)) -> bool {
    if q.launch_rad - p.launch_rad <= MIN_WIDTH_RAD {
        return false;
    }
    match (p.true_rad, q.true_rad) {
        (None, None) => false,
        (None, Some(s)) => s > want.0 && q.least_depth() < DARK_DEPTH,
        (Some(s), None) => s < want.1 && p.least_depth() < DARK_DEPTH,
        (Some(a), Some(b)) => a.min(b) <= want.1 && a.max(b) >= want.0,
    }
}

impl SeaSunTable {
    /// Whether the table predicts ray `m` (traced inside its span) within the tolerances.
    fn predicts(&self, m: &SeaRay) -> bool {
        let Some(s) = m.true_rad else {
            // A ray that does not leave between leaving ones: nothing to interpolate.
            return false;
        };
        let n = self.true_rad.len();
        if n < 2 || s <= self.true_rad[0] || s >= self.true_rad[n - 1] {
            return false;
        }
        let (a, depth) = interpolate(&self.true_rad, &self.launch_rad, &self.depth, s);
        let depth_ok = (0..3)
            .all(|c| m.depth[c] > DARK_DEPTH || (depth[c] - m.depth[c]).abs() <= DEPTH_TOLERANCE);
        (a - m.launch_rad).abs() <= LAUNCH_TOLERANCE_RAD && depth_ok
    }
}

/// The launch and depths at true elevation `s` (inside `xs`, ascending, at least two) by the
/// cubic through the four rays around it (three or two at the ends); depths by linear
/// interpolation next to a ray with an infinite one (then infinite between).
fn interpolate(xs: &[f64], launch: &[f64], depth: &[[f64; 3]], s: f64) -> (f64, [f64; 3]) {
    let n = xs.len();
    let i = xs.partition_point(|&x| x <= s).clamp(1, n - 1) - 1;
    let lo = i.saturating_sub(1);
    let hi = (i + 3).min(n);
    let window = lo..hi;
    let weights = lagrange_weights(&xs[window.clone()], s);
    let a: f64 = window
        .clone()
        .zip(&weights)
        .map(|(j, w)| w * launch[j])
        .sum();
    let finite = window
        .clone()
        .all(|j| depth[j].iter().all(|d| d.is_finite()));
    let d = if finite {
        [0, 1, 2].map(|c| {
            window
                .clone()
                .zip(&weights)
                .map(|(j, w)| w * depth[j][c])
                .sum()
        })
    } else {
        let t = (s - xs[i]) / (xs[i + 1] - xs[i]);
        [0, 1, 2].map(|c| {
            let (p, q) = (depth[i][c], depth[i + 1][c]);
            if p.is_finite() && q.is_finite() {
                p + (q - p) * t
            } else {
                f64::INFINITY
            }
        })
    };
    (a, d)
}

/// The Lagrange weights at `x` of the polynomial through the abscissae `xs` (up to four; the
/// rest are zero).
fn lagrange_weights(xs: &[f64], x: f64) -> [f64; 4] {
    let mut w = [0.0; 4];
    for (j, wj) in w.iter_mut().enumerate().take(xs.len()) {
        *wj = xs
            .iter()
            .enumerate()
            .filter(|&(k, _)| k != j)
            .map(|(_, &xk)| (x - xk) / (xs[j] - xk))
            .product();
    }
    w
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};

    use super::*;
    use crate::render::ray_model::FanRay;
    use crate::render::reflection::sea_level_sun_launch_rad;
    use crate::scene::sky::Sky;

    /// Rays from the sea whose final elevation is `leave(launch)` (`None`: they do not leave)
    /// and whose density paths grow as they flatten, counting the traces.
    struct Leaving<F> {
        leave: F,
        traces: AtomicUsize,
    }

    impl<F: Fn(f64) -> Option<f64> + Sync> RayTracer for Leaving<F> {
        fn trace(&self, _h: f64, elevation_rad: f64, _d: &[f64], _sky: bool) -> FanRay {
            self.traces.fetch_add(1, Ordering::Relaxed);
            FanRay {
                elevation_rad,
                heights_m: Vec::new(),
                end: match (self.leave)(elevation_rad) {
                    Some(e) => FanEnd::Sky { elevation_rad: e },
                    None => FanEnd::Trapped,
                },
                monotone: false,
            }
        }

        fn density_paths_m(&self, _h: f64, e: f64, _s: [f64; 2]) -> Option<[f64; 2]> {
            (self.leave)(e).map(|_| [8e3 / (e + 0.003), 1e3 / (e + 0.01)])
        }
    }

    /// The worst difference (rad) between the table's launch and the renderer's launch search
    /// over `count` true elevations across `sun` ± `tilt`, where the sun's light is not lost.
    fn worst_launch_error(
        tracer: &dyn RayTracer,
        table: &SeaSunTable,
        sun: f64,
        tilt: f64,
        count: usize,
    ) -> f64 {
        let mut worst = 0.0f64;
        for i in 0..=count {
            let s = sun - tilt + 2.0 * tilt * i as f64 / count as f64;
            let (got, depth) = table.at(s);
            if depth[0].is_nan() || depth[0] >= DARK_DEPTH {
                continue;
            }
            let want = sea_level_sun_launch_rad(tracer, s).expect("the sun is lit");
            worst = worst.max((got - want).abs());
        }
        worst
    }

    #[test]
    fn the_table_inverts_the_sea_rays_within_a_tenth_of_a_microradian() {
        let extinction = Sky::default().sun_extinction();
        // Refraction falling from 0.6° at the surface (a strong duct), and a duct that traps
        // every ray launched below 0.2°.
        let smooth = |e: f64| Some(e - 0.0105 * (-e / 0.02).exp());
        let ducted = |e: f64| (e >= 0.0035).then(|| e - 0.0105 * (-e / 0.02).exp());
        for (name, leave) in [
            ("smooth", &smooth as &(dyn Fn(f64) -> Option<f64> + Sync)),
            ("ducted", &ducted),
        ] {
            for (sun_deg, tilt) in [(-0.3, 0.01), (0.5, 0.04), (5.0, 0.02), (20.0, 0.05)] {
                let tracer = Leaving {
                    leave,
                    traces: AtomicUsize::new(0),
                };
                let sun = f64::to_radians(sun_deg);
                let table = SeaSunTable::build(&tracer, sun, tilt, &extinction);
                let rays = tracer.traces.load(Ordering::Relaxed);
                let worst = worst_launch_error(&tracer, &table, sun, tilt, 400);
                eprintln!("{name} {sun_deg}° ± {tilt}: {rays} traces, worst {worst:.2e} rad");
                assert!(worst <= 1e-7, "{name} {sun_deg}°: {worst:e} rad");
                assert!(rays <= 200, "{name} {sun_deg}°: {rays} traces");
            }
        }
    }

    #[test]
    fn fig12s_ducted_sun_table_matches_the_launch_search_across_its_sea() {
        use crate::render::{RenderOptions, prepare_tracer};
        use crate::scene::Scene;
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/data/scenes/fig12_novaya_zemlya.toml"
        );
        let scene = Scene::from_file(std::path::Path::new(path)).expect("scene");
        let loaded = scene.atmosphere.load().expect("atmosphere");
        let refractive = loaded.as_ref().map(|a| &a.refractive);
        let tracer = prepare_tracer(&scene, refractive, &RenderOptions::default()).expect("tracer");
        let sun = scene.sun.expect("sun").elevation_rad;
        // Sea points out to 250 km tilt the sun by up to 0.039 rad.
        let tilt = 250e3 / scene.earth_radius_m;
        let extinction = scene.sky.sun_extinction();
        let table = SeaSunTable::build(tracer.as_ref(), sun, tilt, &extinction);
        let worst = worst_launch_error(tracer.as_ref(), &table, sun, tilt, 200);
        eprintln!("fig12: {} rays, worst {worst:.2e} rad", table.rays());
        assert!(worst <= 1e-7, "{worst:e} rad");
    }
}
