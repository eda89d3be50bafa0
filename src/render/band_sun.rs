//! Stage 5b (render) — the sun across one flat band of a row. In: the band (its apparent
//! elevation, how its ray ended, its columns), the row, the camera frame and the [`Shader`]. Out:
//! per column, the radiance the sun adds to the band's sun-free colour: its disc, where the
//! band's ray leaves towards it, or its glitter or mirror image on the sea, seen through the air
//! from the sea to the camera.
//!
//! The disc and a mirror sea's image of it are evaluated exactly at every column of the chord
//! the band's elevation cuts through them — the shading a sample at the band's elevation and the
//! column's azimuth gets, bit for bit: the disc's terms that depend on the elevation alone are
//! worked out once per band ([`DiscChord`]), the columns' azimuths once per row of the film
//! ([`crate::scene::camera::FilmAzimuths`], shared by the frames of a sweep), and the columns on
//! either side of the chord, whose azimuth is outside its half-width, are found by binary search
//! ([`chord_columns`]) and set to +0 without evaluating them (the same 0 the exact shading
//! gives); the caller is told the span outside which the addition is +0, and fills the pixels
//! there with one colour.
//!
//! A rough sea's glitter is smooth but falls by orders of magnitude across a row, which linear
//! interpolation follows only by evaluating most columns: its Cox–Munk factor is interpolated
//! instead by a quadratic in its logarithm (nodes [`SMOOTH_STRIDE`] apart; [`Smooth`]), and so
//! is each channel's transmittance of the sun's light to the column's sea point (slowly varying
//! with the azimuth), with a test that bounds their combined error at every column of an
//! accepted interval, not only at its middle. A low sun's glitter is a narrow streak, and most of
//! a row lies orders of magnitude below the tolerance: where a run's end does, an upper bound on
//! the glitter over the columns from a candidate to that end ([`SeaSunAt::glint_bound`]) finds
//! the tail that is surely below [`NEGLIGIBLE`] of the tolerance, which is left at +0 and not
//! evaluated ([`BandColumns::glitter_lit`]).

use std::cell::RefCell;

use super::ray_model::FanEnd;
use super::reflection::{SeaSunAt, glint_radiance};
use super::shade::{Shader, wrap_pi};
use crate::scene::sky::DiscChord;

/// Node spacing (columns) of the glitter before refinement (it is smooth: [`Smooth`]).
pub const SMOOTH_STRIDE: usize = 256;

/// Share of the fill's tolerance of the background ([`TOLERANCE`] of it plus [`FLOOR`]) below
/// which a bound on the glitter over a run's tail lets it be taken as dark (+0).
pub const NEGLIGIBLE: f64 = 1e-3;

/// How far below [`NEGLIGIBLE`] a run's end must be for its dark tail to be looked for.
const TAIL_SEARCH: f64 = 1e-8;

/// Relative error (per channel of the pixel) within which the glitter's interpolation fills
/// an interval ([`Smooth`]).
pub const TOLERANCE: f64 = 1e-3;

/// Absolute floor of that test, in film units (1 = the horizon sky): far below an 8-bit step.
pub const FLOOR: f64 = 1e-6;

/// What of the sun a flat band may show.
#[derive(Debug, Clone, Copy)]
pub(super) enum BandSun {
    /// The disc, for a ray that leaves at final elevation `elevation_rad` with `transmittance`
    /// towards the sun.
    Disc {
        elevation_rad: f64,
        transmittance: [f64; 3],
    },
    /// The glitter or mirror image on the sea, for a ray that meets it where `sun` says,
    /// seen through the air with `transmittance` per channel.
    Sea {
        sun: SeaSunAt,
        transmittance: [f64; 3],
    },
}

impl BandSun {
    /// The sun's part of a band at apparent elevation `alpha` whose ray ended with `end`, when
    /// it may show any ([`Shader::may_meet_sun`], [`Shader::may_meet_glint`]).
    pub(super) fn of(shader: &Shader<'_>, alpha: f64, end: FanEnd) -> Option<Self> {
        match end {
            FanEnd::Sky { elevation_rad } if shader.may_meet_sun(end) => Some(BandSun::Disc {
                elevation_rad,
                transmittance: shader.sun_transmittance_at(alpha)?,
            }),
            FanEnd::Ground {
                grazing_rad,
                distance_m,
            } if shader.may_meet_glint(end) => Some(BandSun::Sea {
                sun: shader.reflection.as_ref()?.sun_at(grazing_rad, distance_m),
                transmittance: shader.sea_transmittance(alpha, distance_m),
            }),
            _ => None,
        }
    }
}

/// The sun's addition along a run of columns of one row of a band.
pub(super) struct BandColumns<'a> {
    pub(super) shader: &'a Shader<'a>,
    /// The azimuth offsets of the row's pixel centres ([`Shader::azimuths`]).
    pub(super) offsets: &'a [f64],
    pub(super) sun: BandSun,
    /// The band's sun-free colour, to which the addition is added.
    pub(super) background: [f64; 3],
}

impl BandColumns<'_> {
    fn azimuth_offset(&self, x: usize) -> f64 {
        self.offsets[x]
    }

    /// The column of [`a`, `b`) whose azimuth is nearest the sun's, if the sun's azimuth lies
    /// within the run's (azimuth offsets increase along a row).
    fn sun_column(&self, (a, b): (usize, usize)) -> Option<usize> {
        let target = wrap_pi(self.shader.sun_azimuth_rad()? - self.shader.heading_rad);
        if b <= a || self.azimuth_offset(a) > target || self.azimuth_offset(b - 1) < target {
            return None;
        }
        let (mut lo, mut hi) = (a, b - 1);
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if self.azimuth_offset(mid) < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(lo)
    }

    /// Fill `out[x]` for the columns x of the band whose right-half columns are [`start`,
    /// `end`) in a row `width` columns wide: those, and the left-half columns at the same
    /// distance from the centre column ([`super::band_runs`]). Returns, for each of those two runs, the columns
    /// outside of which the addition is exactly zero (+0 in every channel; possibly empty).
    pub(super) fn fill_band(
        &self,
        (start, end): (usize, usize),
        width: usize,
        out: &mut [[f64; 3]],
    ) -> [(usize, usize); 2] {
        SCRATCH.with_borrow_mut(|scratch| {
            super::band_runs(start, end, width).map(|run| self.fill(run, out, scratch))
        })
    }

    /// Fill `out[x]` for the columns x of [`a`, `b`) (module docs); returns the columns of
    /// them outside of which the addition is exactly zero.
    fn fill(
        &self,
        (a, b): (usize, usize),
        out: &mut [[f64; 3]],
        scratch: &mut Scratch,
    ) -> (usize, usize) {
        if let BandSun::Sea {
            sun: sun @ SeaSunAt::Glint { .. },
            transmittance,
        } = self.sun
            && let Some(refl) = &self.shader.reflection
        {
            let heading = self.shader.heading_rad;
            let exact = |x: usize| {
                sun.glint_factor_and_transmittance(refl, heading + self.azimuth_offset(x))
                    .unwrap_or((0.0, [0.0; 3]))
            };
            let radiance = Glitter {
                scales: sun.glint_scales(refl).unwrap_or(([0.0; 3], [0.0; 3])),
                air: transmittance,
            };
            let glitter = Smooth { exact, radiance };
            let centre = self.sun_column((a, b));
            let tails = |ends| self.glitter_lit((a, b), &sun, refl, transmittance, ends);
            return glitter.fill((a, b), centre, self.background, out, scratch, tails);
        }
        let Some((chord, weight)) = self.disc_along() else {
            out[a..b.max(a)].fill([0.0; 3]);
            return (a, a);
        };
        let heading = self.shader.heading_rad;
        // Columns whose azimuth is at least the chord's half-width from the disc centre's are
        // outside the disc ([`DiscChord::half_width_rad`]: offsets within ±π/2 and a target
        // within ±π differ by at most 3π/2, below 2π less a half-width under π/3).
        let target = wrap_pi(chord.azimuth_rad() - heading);
        let half_width = chord.half_width_rad();
        let (lo, hi) = chord_columns((a, b), |x| self.azimuth_offset(x), target, half_width);
        out[a..lo].fill([0.0; 3]);
        out[hi..b].fill([0.0; 3]);
        // Every column between is evaluated exactly (the dark test above is only a shortcut to
        // the 0 the radiance gives beyond the chord).
        let disc = &mut scratch.disc;
        disc.resize(disc.len().max(hi - lo), 0.0);
        chord.radiance_along(heading, &self.offsets[lo..hi], disc);
        for (v, &radiance) in out[lo..hi].iter_mut().zip(disc.iter()) {
            *v = weight.apply(radiance);
        }
        if lo < hi { (lo, hi) } else { (a, a) }
    }

    /// The columns [lo, hi) of [`a`, `b`) (not empty) outside of which the glitter of `sun`,
    /// seen through the air's transmittance `air`, is negligible: a bound on it over the
    /// columns of each tail ([`SeaSunAt::glint_bound`]) is at most [`NEGLIGIBLE`] of the
    /// fill's tolerance of the band's background. Only the ends `ends` says may be dark (left,
    /// right) are looked at. Each end's tail is found by binary search on its first column, the
    /// bound checked over the whole tail found; empty (lo ≥ hi) where the whole run is
    /// negligible.
    fn glitter_lit(
        &self,
        (a, b): (usize, usize),
        sun: &SeaSunAt,
        refl: &super::reflection::Reflection,
        air: [f64; 3],
        [left, right]: [bool; 2],
    ) -> (usize, usize) {
        let heading = self.shader.heading_rad;
        let azimuth = |x: usize| heading + self.azimuth_offset(x);
        let (first, last) = (azimuth(a), azimuth(b - 1));
        let span = (last - first).abs();
        if span.is_nan() || span >= std::f64::consts::PI {
            return (a, b);
        }
        let Some(bound) = sun.glint_bound(refl, (first, last)) else {
            return (a, b);
        };
        let limit: [f64; 3] =
            [0, 1, 2].map(|c| NEGLIGIBLE * (TOLERANCE * self.background[c].abs() + FLOOR) / air[c]);
        let at = |x: usize| bound.azimuth_from_sun(azimuth(x));
        // Every column between two whose azimuths from the sun's are `p` and `q`.
        let dark = |p, q| {
            let v = bound.at(p, q);
            (0..3).all(|c| v[c] <= limit[c])
        };
        let (start, end) = (bound.azimuth_from_sun(first), bound.azimuth_from_sun(last));
        if left && right && dark(start, end) {
            return (a, a);
        }
        // Tails shorter than a quarter of the run are not looked for: the search would cost
        // about what they save.
        let quarter = (b - a) / 4;
        // The first column of the right tail: `hi` dark to the end, `probe` not.
        let hi = if right && dark(at(b - 1 - quarter), end) {
            let (mut probe, mut hi) = (a, b - 1 - quarter);
            while hi > probe + 1 {
                let mid = probe + (hi - probe) / 2;
                if dark(at(mid), end) {
                    hi = mid
                } else {
                    probe = mid
                }
            }
            hi
        } else {
            b
        };
        // The end of the left tail: `lo` − 1 dark from the start, `probe` not.
        let lo = if left && dark(start, at(a + quarter)) {
            if dark(start, at(hi - 1)) {
                return (a, a);
            }
            let (mut lo, mut probe) = (a + quarter, hi - 1);
            while probe > lo + 1 {
                let mid = lo + (probe - lo) / 2;
                if dark(start, at(mid)) {
                    lo = mid
                } else {
                    probe = mid
                }
            }
            lo + 1
        } else {
            a
        };
        (lo, hi)
    }

    /// The disc (or a mirror sea's image of it) along the band's elevation and what weights its
    /// radiance, when the band's sun is one; `None` where neither shows in any column.
    fn disc_along(&self) -> Option<(DiscChord, DiscWeight)> {
        match self.sun {
            BandSun::Disc {
                elevation_rad,
                transmittance,
            } => Some((
                self.shader.sun.as_ref()?.along(elevation_rad)?,
                DiscWeight::Sky(transmittance),
            )),
            BandSun::Sea {
                sun:
                    SeaSunAt::Mirror {
                        elevation_rad,
                        reflectance,
                        transmittance: sky,
                    },
                transmittance,
            } => {
                let (_, disc) = self.shader.reflection.as_ref()?.mirror_sun.as_ref()?;
                Some((
                    disc.along(elevation_rad)?,
                    DiscWeight::Mirror {
                        reflectance,
                        sky,
                        air: transmittance,
                    },
                ))
            }
            BandSun::Sea { .. } => None,
        }
    }
}

/// What a band's disc radiance is weighted by, with the arithmetic of the shading per sample
/// (the sky's disc, [`Shader::with_sun`]; its mirror image, [`SeaSunAt`]).
#[derive(Clone, Copy)]
enum DiscWeight {
    /// The disc itself, through the air's transmittance per channel towards the sun.
    Sky([f64; 3]),
    /// A mirror sea's image of it: its reflectance, the sky's transmittance at the grazing
    /// angle and the air's from the sea to the camera.
    Mirror {
        reflectance: f64,
        sky: [f64; 3],
        air: [f64; 3],
    },
}

impl DiscWeight {
    /// The addition of a disc radiance `disc`.
    #[inline]
    fn apply(&self, disc: f64) -> [f64; 3] {
        match *self {
            DiscWeight::Sky(transmittance) => {
                if disc > 0.0 {
                    transmittance.map(|t| disc * t)
                } else {
                    [0.0; 3]
                }
            }
            DiscWeight::Mirror {
                reflectance,
                sky,
                air,
            } => {
                if disc <= 0.0 {
                    return [0.0; 3];
                }
                let sun = sky.map(|t| reflectance * disc * t);
                [0, 1, 2].map(|c| sun[c] * air[c])
            }
        }
    }
}

/// Work space of [`Smooth::fill`], reused across the bands a thread fills.
#[derive(Default)]
struct Scratch {
    nodes: Vec<usize>,
    open: Vec<(usize, usize)>,
    /// Per column of the row, the exact weights [`Smooth::fill`] evaluated there; an entry
    /// holds for the call whose stamp it bears.
    exact: Vec<Exact>,
    /// The stamp of the latest call of [`Smooth::fill`].
    stamp: u32,
    /// The disc's radiance per column of a chord ([`DiscChord::radiance_along`]).
    disc: Vec<f64>,
}

/// A column's exact weights in a call of [`Smooth::fill`], and once asked for their
/// logarithms.
#[derive(Clone, Copy, Default)]
struct Exact {
    /// The call's stamp ([`Scratch::stamp`]; 0: none).
    stamp: u32,
    weights: Weights,
    /// ln of the factor and of each channel's transmittance, when `logged`.
    logs: [f64; 4],
    logged: bool,
}

impl Exact {
    /// The logarithm of weight `n` (0: the factor, 1 + c: channel c's transmittance); the
    /// first call computes all four (a fit or a test asks for all of them but where they are
    /// zero or equal).
    #[inline]
    fn log(&mut self, n: usize) -> f64 {
        if !self.logged {
            let (k, t) = self.weights;
            self.logs = [k.ln(), t[0].ln(), t[1].ln(), t[2].ln()];
            self.logged = true;
        }
        self.logs[n]
    }
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// The columns [lo, hi) of [`a`, `b`) outside of which a disc's chord (centre azimuth offset
/// `target`, half-width `half_width`) is dark by the test of [`BandColumns::fill`] (an offset
/// within ±π/2 at least the half-width from the target), `offset(x)` giving column x's azimuth
/// offset (increasing along the row): the columns before the first whose offset is past
/// `target − half_width`, and those from the first whose offset reaches `target + half_width`.
/// All of [`a`, `b`) where the test may not hold at the run's ends (an offset beyond ±π/2, an
/// unbounded chord).
fn chord_columns(
    (a, b): (usize, usize),
    offset: impl Fn(usize) -> f64,
    target: f64,
    half_width: f64,
) -> (usize, usize) {
    let within = |x: usize| offset(x).abs() <= std::f64::consts::FRAC_PI_2;
    if b <= a || !half_width.is_finite() || !within(a) || !within(b - 1) {
        return (a, b);
    }
    // The first column of [lo, b) whose offset less the target is `past` (b if none): `past`
    // is false then true along the row.
    let first = |lo: usize, past: &dyn Fn(f64) -> bool| {
        let (mut lo, mut hi) = (lo, b);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if past(offset(mid) - target) {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        lo
    };
    let lo = first(a, &|d| d > -half_width);
    let hi = first(lo, &|d| d >= half_width);
    (lo, hi)
}

/// The node columns of [`a`, `b`) (not empty) into `nodes`: every `stride`th column, the last,
/// and `centre` with its neighbours when it lies in the run; ascending.
fn node_columns(
    (a, b): (usize, usize),
    stride: usize,
    centre: Option<usize>,
    nodes: &mut Vec<usize>,
) {
    nodes.clear();
    nodes.extend((a..b).step_by(stride));
    nodes.push(b - 1);
    if let Some(c) = centre.filter(|c| (a..b).contains(c)) {
        nodes.extend([c.saturating_sub(1).max(a), c, (c + 1).min(b - 1)]);
    }
    nodes.sort_unstable();
    nodes.dedup();
}

/// A positive factor that is smooth in the column and whose logarithm is close to a quadratic
/// over many columns — the glitter's Cox–Munk factor, exp(−tan²β/σ²) times slowly varying
/// terms — with a transmittance per channel that is smooth in the column too (the sun's own
/// attenuation to each column's sea point, the exponential of a slowly varying optical depth),
/// and the radiance they give in a column (which may cap the factor, and is linear in the
/// transmittance).
struct Smooth<E, R> {
    /// A column's exact factor and transmittance.
    exact: E,
    /// The radiance of a factor and a transmittance.
    radiance: R,
}

/// A column's factor and transmittance per channel.
type Weights = (f64, [f64; 3]);

/// The radiance of a factor and a transmittance per channel ([`Smooth`]), and of runs of them.
trait Radiance {
    /// The radiance of factor `k` and transmittance `t`.
    fn of(&self, k: f64, t: [f64; 3]) -> [f64; 3];

    /// Set each `out[n]` to the radiance of the next values of `steps` in turn.
    fn run(&self, steps: &mut Steps4, out: &mut [[f64; 3]]) {
        for v in out {
            let [k, t0, t1, t2] = steps.next();
            *v = self.of(k, [t0, t1, t2]);
        }
    }
}

impl<F: Fn(f64, [f64; 3]) -> [f64; 3]> Radiance for F {
    #[inline]
    fn of(&self, k: f64, t: [f64; 3]) -> [f64; 3] {
        self(k, t)
    }
}

/// The glitter seen through the air: [`glint_radiance`] with `scales`, times the air's
/// transmittance `air` per channel.
struct Glitter {
    scales: ([f64; 3], [f64; 3]),
    air: [f64; 3],
}

impl Radiance for Glitter {
    #[inline]
    fn of(&self, k: f64, t: [f64; 3]) -> [f64; 3] {
        let sun = glint_radiance(k, t, self.scales);
        [0, 1, 2].map(|c| sun[c] * self.air[c])
    }

    /// The same values as [`Self::of`] in turn, the cap taken by a comparison: the same as
    /// `f64::min` wherever the cap is not NaN (a NaN capped value gives the cap).
    fn run(&self, steps: &mut Steps4, out: &mut [[f64; 3]]) {
        let (irradiance, cap) = self.scales;
        if cap.iter().any(|c| c.is_nan()) {
            for v in out {
                let [k, t0, t1, t2] = steps.next();
                *v = self.of(k, [t0, t1, t2]);
            }
            return;
        }
        for v in out {
            let [k, t0, t1, t2] = steps.next();
            if k <= 0.0 {
                *v = [0.0; 3];
                continue;
            }
            let channel = |c: usize, t: f64| {
                let x = k * irradiance[c];
                let capped = if x < cap[c] { x } else { cap[c] };
                capped * t * self.air[c]
            };
            *v = [channel(0, t0), channel(1, t1), channel(2, t2)];
        }
    }
}

impl<E: Fn(usize) -> Weights, R: Radiance> Smooth<E, R> {
    /// Fill `out[x]` for the columns x of [`a`, `b`): the radiance of the exact factor and
    /// transmittance at nodes ([`SMOOTH_STRIDE`] apart, the last column, `centre` and its
    /// neighbours) and at the points refinement evaluates; elsewhere of the factor and each
    /// channel's transmittance interpolated by quadratics in their logarithms through an
    /// interval's ends and middle ([`Fit`]), where [`Self::accepts`] them; other intervals are
    /// halved. The run's two ends are evaluated first; where either's radiance is far below the
    /// tolerance ([`TAIL_SEARCH`] of [`NEGLIGIBLE`] of it), `tails` (told which ends are) gives
    /// the columns [lo, hi) outside of which the glitter is dark: those are set to +0 and the
    /// nodes taken in [lo, hi) alone. Returns the columns outside of which `out` is +0 (empty,
    /// (a, a), where every column is).
    fn fill(
        &self,
        (a, b): (usize, usize),
        centre: Option<usize>,
        background: [f64; 3],
        out: &mut [[f64; 3]],
        scratch: &mut Scratch,
        tails: impl FnOnce([bool; 2]) -> (usize, usize),
    ) -> (usize, usize) {
        if b <= a {
            return (a, a);
        }
        let Scratch {
            nodes,
            open,
            exact: w,
            stamp,
            ..
        } = scratch;
        // The exact factor and transmittance of the columns evaluated so far, those entries of
        // `w` with this call's stamp (a NaN factor is kept as 0, and its radiance as the exact
        // shading gives it).
        *stamp = stamp.wrapping_add(1);
        if *stamp == 0 {
            w.iter_mut().for_each(|e| e.stamp = 0);
            *stamp = 1;
        }
        let stamp = *stamp;
        if w.len() < b {
            w.resize(b, Exact::default());
        }
        let exact = |x: usize, w: &mut [Exact], out: &mut [[f64; 3]]| {
            if w[x].stamp != stamp {
                let (f, t) = (self.exact)(x);
                w[x] = Exact {
                    stamp,
                    weights: (if f.is_nan() { 0.0 } else { f }, t),
                    ..Exact::default()
                };
                out[x] = self.radiance.of(f, t);
            }
        };
        // The run's ends first: where one's exact radiance is far below negligible, `tails` may
        // find columns from it on that are dark, left at +0 (it takes a column as dark only by
        // a bound on it, never below its exact value). An end only just negligible has a short
        // tail, if any, not worth the search: the glitter falls by orders of magnitude across it.
        exact(a, w, out);
        exact(b - 1, w, out);
        let negligible = |x: usize| {
            (0..3).all(|c| {
                out[x][c] <= TAIL_SEARCH * NEGLIGIBLE * (TOLERANCE * background[c].abs() + FLOOR)
            })
        };
        let (lo, hi) = match [negligible(a), negligible(b - 1)] {
            [false, false] => (a, b),
            ends => tails(ends),
        };
        out[a..lo.min(b)].fill([0.0; 3]);
        out[hi.max(lo).max(a)..b].fill([0.0; 3]);
        if lo >= hi {
            return (a, a);
        }
        let (a, b) = (lo, hi);
        node_columns((a, b), SMOOTH_STRIDE, centre, nodes);
        for &x in nodes.iter() {
            exact(x, w, out);
        }
        open.clear();
        open.extend(nodes.windows(2).map(|w| (w[0], w[1])));
        while let Some((i, j)) = open.pop() {
            if j <= i + 1 {
                continue;
            }
            let m = (i + j) / 2;
            let tests =
                [(i + m) / 2, (m + j) / 2].map(|t| (t > i && t < m || t > m && t < j).then_some(t));
            exact(m, w, out);
            for t in tests.into_iter().flatten() {
                exact(t, w, out);
            }
            let points = [(i, w[i].weights), (m, w[m].weights), (j, w[j].weights)];
            let fit = Fit::through(points, |x, n| w[x].log(n));
            match fit.filter(|fit| self.accepts(fit, (i, j), tests, w, background, out)) {
                Some(fit) => {
                    // The interval's columns evaluated exactly keep their radiance: its middle
                    // and test points, no others (an interval holds no other points its
                    // ancestors evaluated: their middles are ends of their halves, their test
                    // points the middles of those halves).
                    let kept = [Some(m), tests[0], tests[1]].map(|x| x.map(|x| (x, out[x])));
                    fit.fill(i, j, &self.radiance, out);
                    for (x, v) in kept.into_iter().flatten() {
                        out[x] = v;
                    }
                }
                None => open.extend([(i, m), (m, j)]),
            }
        }
        (a, b)
    }

    /// Whether `fit`, through the exact factors and transmittances at the ends and middle of
    /// (`i`, `j`), may fill that interval: at the test points `tests` (its quarter points,
    /// evaluated exactly with their radiance in `out`) it predicts the pixel's radiance within
    /// [`TOLERANCE`] of the pixel's radiance there (plus [`FLOOR`]; [`within`]); and its largest
    /// error in the logarithm there, E (the factor's plus the worst channel's transmittance's:
    /// the interpolation error of a quadratic is a cubic in the column, about as large at the
    /// quarter points as anywhere in the interval), taken as 1.5 E anywhere, keeps the radiance
    /// within the same tolerance of the pixel however large the factor and the transmittance
    /// get in the interval (up to the fits' maxima or an exact value, times that error). A
    /// quadratic's error relative to values far below the pixel says nothing about the values
    /// near a peak: without the second test a steep peak at an interval's end was filled from
    /// its tail.
    fn accepts(
        &self,
        fit: &Fit,
        (i, j): (usize, usize),
        tests: [Option<usize>; 2],
        exact: &mut [Exact],
        background: [f64; 3],
        out: &[[f64; 3]],
    ) -> bool {
        let mut log_error = 0.0f64;
        for x in tests.into_iter().flatten() {
            let logs = fit.logs_at(x);
            let got = (logs[0].exp(), [1, 2, 3].map(|n| logs[n].exp()));
            let want = exact[x].weights;
            if !within(self.radiance.of(got.0, got.1), out[x], background) {
                return false;
            }
            let mut error =
                |n: usize, want: f64, got: f64| log_ratio(want, (got, logs[n]), || exact[x].log(n));
            let errors = [
                error(0, want.0, got.0),
                error(1, want.1[0], got.1[0]),
                error(2, want.1[1], got.1[1]),
                error(3, want.1[2], got.1[2]),
            ];
            let [Some(k), Some(t0), Some(t1), Some(t2)] = errors else {
                return false;
            };
            log_error = log_error.max(k + t0.max(t1).max(t2));
        }
        // A factor and a transmittance off by ratios whose product is at most λ give a
        // radiance (linear in both, or capped in the factor) off by at most (λ − 1) v, v the
        // exact radiance: within the tolerance wherever (λ − 1 − TOLERANCE) v ≤ TOLERANCE ·
        // background + FLOOR, so everywhere when it holds at the largest v the interval may
        // hold.
        let growth = (1.5 * log_error).exp();
        let excess = growth - 1.0 - TOLERANCE;
        if excess <= 0.0 {
            return true;
        }
        // The largest values the interval may hold: the fits' maxima, or an exact value.
        let (mut largest, mut clearest) = fit.max_over(i, j);
        for x in [i, (i + j) / 2, j]
            .into_iter()
            .chain(tests.into_iter().flatten())
        {
            let (k, t) = exact[x].weights;
            largest = largest.max(k);
            (0..3).for_each(|c| clearest[c] = clearest[c].max(t[c]));
        }
        let v = self
            .radiance
            .of(largest * growth, clearest.map(|t| t * growth));
        (0..3).all(|c| excess * v[c] <= TOLERANCE * background[c].abs() + FLOOR)
    }
}

/// |ln(`got` / `want`)| (0 when they are equal), `got` given with its logarithm (the exponent
/// it is the exponential of) and `ln_want` giving ln `want`; `None` when they differ and not
/// both are positive.
fn log_ratio(want: f64, (got, ln_got): (f64, f64), ln_want: impl FnOnce() -> f64) -> Option<f64> {
    if want == got {
        return Some(0.0);
    }
    (want > 0.0 && got > 0.0).then(|| (ln_got - ln_want()).abs())
}

/// Quadratics in the logarithms of a column's factor and of each channel of its
/// transmittance, through three columns ([`LogQuadratic`]).
struct Fit {
    factor: LogQuadratic,
    transmittance: [LogQuadratic; 3],
}

impl Fit {
    /// Through `points` (column, weights; columns increasing), `log(x, n)` giving the
    /// logarithm of column x's weight n ([`Exact::log`]): `None` where some but not all
    /// factors, or values of one channel's transmittance, are zero.
    fn through(
        points: [(usize, Weights); 3],
        mut log: impl FnMut(usize, usize) -> f64,
    ) -> Option<Self> {
        let [(x0, w0), (x1, w1), (x2, w2)] = points;
        let mut logs_of = |n: usize| [log(x0, n), log(x1, n), log(x2, n)];
        let factor = LogQuadratic::through([(x0, w0.0), (x1, w1.0), (x2, w2.0)], || logs_of(0))?;
        let mut channel = |c: usize| {
            let values = [(x0, w0.1[c]), (x1, w1.1[c]), (x2, w2.1[c])];
            LogQuadratic::through(values, || logs_of(c + 1))
        };
        let transmittance = [channel(0)?, channel(1)?, channel(2)?];
        Some(Fit {
            factor,
            transmittance,
        })
    }

    /// The logarithms of the weights at column `x` (the factor's, then each channel's):
    /// [`LogQuadratic::log_at`].
    fn logs_at(&self, x: usize) -> [f64; 4] {
        let t = &self.transmittance;
        [
            self.factor.log_at(x),
            t[0].log_at(x),
            t[1].log_at(x),
            t[2].log_at(x),
        ]
    }

    /// The largest factor and transmittance per channel over columns [`i`, `j`]
    /// ([`LogQuadratic::max_over`]).
    fn max_over(&self, i: usize, j: usize) -> Weights {
        let t = &self.transmittance;
        (
            self.factor.max_over(i, j),
            [
                t[0].max_over(i, j),
                t[1].max_over(i, j),
                t[2].max_over(i, j),
            ],
        )
    }

    /// Set `out[x]` to `radiance(factor, transmittance)` for the columns x of (`start`, `end`)
    /// (`start` is the quadratics' first column), by [`LogQuadratic::steps`].
    fn fill(&self, start: usize, end: usize, radiance: &impl Radiance, out: &mut [[f64; 3]]) {
        let [k, t0, t1, t2] = [
            self.factor,
            self.transmittance[0],
            self.transmittance[1],
            self.transmittance[2],
        ]
        .map(|q| q.steps(start));
        let mut steps = Steps4 {
            value: [k.value, t0.value, t1.value, t2.value],
            ratio: [k.ratio, t0.ratio, t1.ratio, t2.ratio],
            growth: [k.growth, t0.growth, t1.growth, t2.growth],
        };
        radiance.run(&mut steps, &mut out[start + 1..end]);
    }
}

/// A quadratic in the logarithm of a factor through three columns (all factors zero: zero),
/// ln k = α + β u + γ u² in the column offset u from the first.
#[derive(Clone, Copy)]
enum LogQuadratic {
    Zero,
    Quadratic {
        /// The first column.
        x0: usize,
        alpha: f64,
        beta: f64,
        gamma: f64,
    },
}

/// The values of a [`LogQuadratic`] at successive columns, by recurrence: each is the
/// previous times a ratio that itself grows by the constant exp(2γ) — three exponentials per
/// interval instead of one per column; the rounding this accumulates over an interval is far
/// below [`TOLERANCE`].
struct Steps {
    value: f64,
    ratio: f64,
    growth: f64,
}

/// Four [`Steps`] side by side (the factor's and the transmittances'), the same values.
struct Steps4 {
    value: [f64; 4],
    ratio: [f64; 4],
    growth: [f64; 4],
}

impl Steps4 {
    /// The values at the next column.
    #[inline]
    fn next(&mut self) -> [f64; 4] {
        let value = self.value;
        for n in 0..4 {
            self.value[n] *= self.ratio[n];
            self.ratio[n] *= self.growth[n];
        }
        value
    }
}

impl LogQuadratic {
    /// Through `points` (column, factor; columns increasing), `logs` giving their logarithms:
    /// `None` where some but not all factors are zero.
    fn through(points: [(usize, f64); 3], logs: impl FnOnce() -> [f64; 3]) -> Option<Self> {
        if points.iter().all(|&(_, k)| k == 0.0) {
            return Some(LogQuadratic::Zero);
        }
        if !points.iter().all(|&(_, k)| k > 0.0 && k.is_finite()) {
            return None;
        }
        let [(x0, _), (x1, _), (x2, _)] = points;
        let (u1, u2) = ((x1 - x0) as f64, (x2 - x0) as f64);
        let [y0, y1, y2] = logs();
        // Newton's divided differences.
        let d1 = (y1 - y0) / u1;
        let gamma = ((y2 - y1) / (u2 - u1) - d1) / u2;
        Some(LogQuadratic::Quadratic {
            x0,
            alpha: y0,
            beta: d1 - gamma * u1,
            gamma,
        })
    }

    /// The largest factor over columns [`i`, `j`] (`i` is the quadratic's first column): at an
    /// end, or at the vertex of a peak between them.
    fn max_over(&self, i: usize, j: usize) -> f64 {
        let LogQuadratic::Quadratic {
            alpha, beta, gamma, ..
        } = *self
        else {
            return 0.0;
        };
        let u_end = (j - i) as f64;
        let mut y = alpha.max(alpha + u_end * (beta + u_end * gamma));
        if gamma < 0.0 {
            let vertex = -beta / (2.0 * gamma);
            if vertex > 0.0 && vertex < u_end {
                y = y.max(alpha + vertex * (beta + vertex * gamma));
            }
        }
        y.exp()
    }

    /// The logarithm of the factor at column `x`, whose exponential is the factor there (−∞
    /// for [`LogQuadratic::Zero`]).
    fn log_at(&self, x: usize) -> f64 {
        let LogQuadratic::Quadratic {
            x0,
            alpha,
            beta,
            gamma,
        } = *self
        else {
            return f64::NEG_INFINITY;
        };
        let u = (x - x0) as f64;
        alpha + u * (beta + u * gamma)
    }

    /// The values at the columns after `start` (the quadratic's first column), in order.
    fn steps(&self, start: usize) -> Steps {
        let LogQuadratic::Quadratic {
            x0,
            alpha,
            beta,
            gamma,
        } = *self
        else {
            return Steps {
                value: 0.0,
                ratio: 0.0,
                growth: 0.0,
            };
        };
        debug_assert_eq!(x0, start);
        Steps {
            value: (alpha + beta + gamma).exp(),
            ratio: (beta + 3.0 * gamma).exp(),
            growth: (2.0 * gamma).exp(),
        }
    }
}

/// Whether `predicted` is within [`TOLERANCE`] of the pixel's radiance (`background` plus the
/// exact `value`), plus [`FLOOR`], in every channel.
fn within(predicted: [f64; 3], value: [f64; 3], background: [f64; 3]) -> bool {
    (0..3).all(|c| {
        (predicted[c] - value[c]).abs() <= TOLERANCE * (background[c] + value[c]).abs() + FLOOR
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chord_columns_hold_every_column_the_dark_test_may_light_and_no_more() {
        let offset = |x: usize| ((x as f64 + 0.5 - 200.0) / 3000.0).atan();
        let cases = [
            (0.0, 0.01),
            (0.05, 0.002),
            (-0.066, 0.001),
            (0.3, 0.01),
            (0.0, 1e-7),
            (0.0, f64::INFINITY),
        ];
        for (target, half_width) in cases {
            let dark = |x: usize| {
                let o = offset(x);
                o.abs() <= std::f64::consts::FRAC_PI_2 && (o - target).abs() >= half_width
            };
            for (a, b) in [(0, 400), (200, 400), (0, 200), (57, 58), (9, 9)] {
                let (lo, hi) = chord_columns((a, b), offset, target, half_width);
                assert!(
                    a <= lo && lo <= hi && hi <= b,
                    "{target} {half_width}: {lo}..{hi}"
                );
                for x in (a..b).filter(|x| !(lo..hi).contains(x)) {
                    assert!(dark(x), "{target} ± {half_width} in {a}..{b}: column {x}");
                }
                if lo < hi && half_width.is_finite() {
                    assert!(
                        !dark(lo) && !dark(hi - 1),
                        "{target} ± {half_width}: {lo}..{hi}"
                    );
                }
            }
        }
        // Offsets beyond ±π/2 at an end of the run: the test may not hold, so all of it.
        let wide = |x: usize| (x as f64 - 200.0) * 0.01;
        assert_eq!(chord_columns((0, 400), wide, 0.0, 0.01), (0, 400));
        // Within them, only column 200 is nearer the target than the half-width (199 and 201
        // are exactly at it: dark).
        assert_eq!(chord_columns((100, 300), wide, 0.0, 0.01), (200, 201));
    }

    /// The worst error of the filled `out` against `exact`, in units of the tolerance on the
    /// pixel's radiance.
    fn worst_error(
        out: &[[f64; 3]],
        exact: impl Fn(usize) -> [f64; 3],
        background: [f64; 3],
    ) -> f64 {
        let mut worst = 0.0f64;
        for (x, got) in out.iter().enumerate() {
            let want = exact(x);
            for c in 0..3 {
                let allowed = TOLERANCE * (background[c] + want[c]).abs() + FLOOR;
                worst = worst.max((got[c] - want[c]).abs() / allowed);
            }
        }
        worst
    }

    /// The worst error of [`Smooth::fill`] over 400 columns for the factor `k` and a capped
    /// radiance, in units of the tolerance; and how many factors it evaluated.
    fn worst_smooth(k: impl Fn(usize) -> f64, centre: usize, background: [f64; 3]) -> (f64, usize) {
        worst_attenuated(k, |_| [1.0; 3], centre, background)
    }

    /// [`worst_smooth`] with the radiance of column x weighted by its transmittance per
    /// channel `weight(x)`.
    fn worst_attenuated(
        k: impl Fn(usize) -> f64,
        weight: impl Fn(usize) -> [f64; 3],
        centre: usize,
        background: [f64; 3],
    ) -> (f64, usize) {
        let calls = std::cell::Cell::new(0);
        let radiance = |k: f64, w: [f64; 3]| {
            if k <= 0.0 {
                return [0.0; 3];
            }
            [
                (k * 2.0).min(900.0) * w[0],
                k * 0.6 * w[1],
                (k * 0.02).min(0.5) * w[2],
            ]
        };
        let glitter = Smooth {
            exact: |x: usize| {
                calls.set(calls.get() + 1);
                (k(x), weight(x))
            },
            radiance,
        };
        let mut out = vec![[f64::NAN; 3]; 400];
        glitter.fill(
            (0, 400),
            Some(centre),
            background,
            &mut out,
            &mut Scratch::default(),
            |_| (0, 400),
        );
        (
            worst_error(&out, |x| radiance(k(x), weight(x)), background),
            calls.get(),
        )
    }

    #[test]
    fn glitter_is_filled_within_the_tolerance_from_few_columns() {
        let sea = [0.15, 0.19, 0.23];
        // The Cox–Munk factor of a sea at 5 m/s (σ² = 0.0175) along a row: the facet slope's
        // tangent grows with the azimuth from the sun's, times a slowly varying Fresnel-like
        // term; peaks from 3e4 times the sea down to far below it, narrow and wide, and one
        // whose right part has the sun below the facets' horizon (factor 0).
        let cox_munk = |x: usize, centre: f64, scale: f64, peak: f64| {
            let t = (x as f64 - centre) / scale;
            let tan2 = t * t * (1.0 + 0.3 * t * t).sqrt();
            peak * (-tan2 / 0.0175).exp() * (1.0 + 0.2 * t.atan())
        };
        for (centre, scale, peak) in [
            (203usize, 270.0, 5e3),
            (203, 270.0, 1e-2),
            (120, 60.0, 5e3),
            (380, 1000.0, 40.0),
            (17, 30.0, 1e4),
            (203, 5.0, 5e3),
        ] {
            let k = |x: usize| cox_munk(x, centre as f64, scale, peak);
            let (err, _) = worst_smooth(k, centre, sea);
            assert!(err <= 1.0, "peak {peak} at {centre}, scale {scale}: {err}");
        }
        // The real factor along rows of 400 columns spanning 0.6° (the strips scene), 10° and
        // 60° of azimuth centred on the sun, over calm and windy seas, grazing and sun
        // elevations from 0.05° to 5°: within the tolerance from at most a quarter of the
        // columns (43–67 of 400 on 2026-12-07; linear interpolation needed twice as many).
        let deg = f64::to_radians;
        for wind in [0.0, 5.0] {
            let sea = crate::scene::Sea {
                wave_slope_rad: crate::scene::sea::cox_munk_rms_slope_rad(wind),
                ..crate::scene::Sea::default()
            };
            for (fov, grazing, sun) in [(0.6, 0.05, 0.1), (10.0, 0.5, 1.0), (60.0, 3.0, 5.0)] {
                let geometry = sea.glint_geometry(deg(grazing));
                let k = |x: usize| {
                    let azimuth = deg(fov * ((x as f64 + 0.5) / 400.0 - 0.5) + 0.37 * fov);
                    geometry.per_irradiance(deg(sun), azimuth)
                };
                let centre = (0..400).min_by(|&a, &b| k(b).total_cmp(&k(a))).unwrap();
                let (err, calls) = worst_smooth(k, centre, [0.15, 0.19, 0.23]);
                let label = format!("wind {wind}, fov {fov}°, grazing {grazing}°, sun {sun}°");
                assert!(err <= 1.0, "{label}: {err}");
                assert!(calls <= 100, "{label}: {calls} columns");
            }
        }
        let cut = |x: usize| {
            if x < 260 {
                cox_munk(x, 200.0, 4.0, 800.0)
            } else {
                0.0
            }
        };
        let (err, _) = worst_smooth(cut, 200, sea);
        assert!(err <= 1.0, "cut: {err}");
        // The sun's own attenuation to each column's sea point, falling by a factor of 3
        // across the row, weights the radiance per column.
        let wide = |x: usize| cox_munk(x, 180.0, 30.0, 3e4);
        let fading = |x: usize| [(-(x as f64) / 360.0).exp(); 3];
        let (err, _) = worst_attenuated(wide, fading, 180, sea);
        assert!(err <= 1.0, "attenuated: {err}");
        // The sun low over the sea's horizon: each channel's optical depth grows with the air
        // mass, 1 / sin of an elevation falling across the row, steeply and differently per
        // channel (the attenuation is interpolated too); and a sun that sets at a column (the
        // transmittance drops to zero there).
        let airmass = |x: usize| 1.0 / (0.004 + 0.02 * (1.0 - x as f64 / 400.0)).sin();
        let low = |x: usize| [0.02, 0.05, 0.11].map(|tau| (-tau * airmass(x)).exp());
        let (err, calls) = worst_attenuated(wide, low, 180, sea);
        assert!(err <= 1.0, "low sun: {err} ({calls} columns)");
        // A broad peak under a sun lower still, whose transmittance a log-quadratic fits
        // worse than the quarter points show: the fill needs the transmittance's error in its
        // bound (without it this errs by 3.5 times the tolerance).
        let lower = |x: usize| {
            let airmass = 1.0 / (0.001 + 0.01 * (1.0 - x as f64 / 400.0)).sin();
            [0.02, 0.04, 0.08].map(|tau| (-tau * airmass).exp())
        };
        let broad = |x: usize| cox_munk(x, 250.0, 300.0, 100.0);
        let (err, _) = worst_attenuated(broad, lower, 250, sea);
        assert!(err <= 1.0, "lower sun: {err}");
        let setting = |x: usize| {
            if x < 310 { low(x) } else { [0.0; 3] }
        };
        let (err, _) = worst_attenuated(|x| cox_munk(x, 300.0, 60.0, 3e4), setting, 300, sea);
        assert!(err <= 1.0, "setting sun: {err}");
    }

    #[test]
    fn tails_found_dark_are_left_at_zero_unevaluated_and_the_rest_filled() {
        let sea = [0.15, 0.19, 0.23];
        // A narrow glitter streak at column 170: far below the tolerance at both ends of the
        // run, and lit around it.
        let k = |x: usize| 5e3 * (-((x as f64 - 170.0) / 12.0).powi(2)).exp();
        let radiance = |k: f64, _: [f64; 3]| [2.0 * k, 0.6 * k, 0.02 * k];
        for (found, span) in [
            ((60, 290), (60, 290)),
            ((0, 400), (0, 400)),
            ((0, 0), (0, 0)),
        ] {
            let (calls, outside) = (std::cell::Cell::new(0), std::cell::Cell::new(0));
            let asked = std::cell::Cell::new(None);
            let glitter = Smooth {
                exact: |x: usize| {
                    calls.set(calls.get() + 1);
                    outside.set(outside.get() + usize::from(!(span.0..span.1).contains(&x)));
                    (k(x), [1.0; 3])
                },
                radiance,
            };
            let mut out = vec![[f64::NAN; 3]; 400];
            let lit = glitter.fill(
                (0, 400),
                Some(170),
                sea,
                &mut out,
                &mut Scratch::default(),
                |ends| {
                    asked.set(Some(ends));
                    found
                },
            );
            // Both ends were far below it, so the search was asked for both tails.
            assert_eq!(asked.get(), Some([true, true]), "{found:?}");
            assert_eq!(lit, span, "{found:?}");
            // Outside the span: +0, and no column evaluated but the run's two ends.
            assert!(
                out[..span.0]
                    .iter()
                    .chain(&out[span.1..])
                    .all(|v| *v == [0.0; 3])
            );
            assert!(outside.get() <= 2, "{found:?}: {} outside", outside.get());
            // Inside: within the tolerance of the exact radiance.
            let inside = &out[span.0..span.1];
            let err = worst_error(inside, |i| radiance(k(span.0 + i), [1.0; 3]), sea);
            assert!(err <= 1.0, "{found:?}: {err}");
            assert!(calls.get() < 60, "{found:?}: {} columns", calls.get());
        }
        // An end that shows: the tails are not looked for.
        let asked = std::cell::Cell::new(false);
        let wide = Smooth {
            exact: |x: usize| {
                (
                    5e3 * (-((x as f64 - 170.0) / 300.0).powi(2)).exp(),
                    [1.0; 3],
                )
            },
            radiance,
        };
        let mut out = vec![[f64::NAN; 3]; 400];
        let lit = wide.fill(
            (0, 400),
            Some(170),
            sea,
            &mut out,
            &mut Scratch::default(),
            |_| {
                asked.set(true);
                (0, 0)
            },
        );
        assert_eq!((lit, asked.get()), ((0, 400), false));
    }
}
