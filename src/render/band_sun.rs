//! Stage 5b (render) — the sun across one flat band of a row. In: the band (its apparent
//! elevation, how its ray ended, its columns), the row, the camera frame and the [`Shader`]. Out:
//! per column, the radiance the sun adds to the band's sun-free colour: its disc, where the
//! band's ray leaves towards it, or its glitter or mirror image on the sea, seen through the air
//! from the sea to the camera.
//!
//! The addition is evaluated exactly (the shading a sample at the band's elevation and the
//! column's azimuth gets) at node columns — the ends of each run of columns, every
//! [`STRIDE`]th column, and the column nearest the sun's azimuth with its neighbours (the disc,
//! its mirror image and the glitter are centred on that azimuth) — and interpolated linearly
//! between them. An interval between two nodes is split at its middle column until linear
//! interpolation predicts the middle within [`TOLERANCE`] of the pixel's radiance there (the
//! band's colour plus the addition, per channel, plus [`FLOOR`]) or the nodes are neighbours. So the sharp edges of the disc and of its mirror image
//! are resolved to single columns (the test fails across them), and inside them, and across the
//! glitter, the addition is within about that tolerance of the exact shading.

use super::ray_model::FanEnd;
use super::reflection::SeaSunAt;
use super::shade::{Shader, wrap_pi};
use crate::scene::camera::CameraFrame;

/// Node spacing (columns) before refinement.
pub const STRIDE: usize = 8;

/// Relative error (per channel) at which linear interpolation closes an interval.
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

    /// The addition towards azimuth offset `azimuth_offset_rad` (from the camera's heading).
    fn at(&self, shader: &Shader<'_>, azimuth_offset_rad: f64) -> [f64; 3] {
        match *self {
            BandSun::Disc {
                elevation_rad,
                transmittance,
            } => shader.sun_disc(elevation_rad, azimuth_offset_rad, transmittance),
            BandSun::Sea { sun, transmittance } => match &shader.reflection {
                Some(refl) => {
                    let sun = sun.at(refl, shader.heading_rad + azimuth_offset_rad);
                    [0, 1, 2].map(|c| sun[c] * transmittance[c])
                }
                None => [0.0; 3],
            },
        }
    }
}

/// The sun's addition along a run of columns of one row of a band.
pub(super) struct BandColumns<'a> {
    pub(super) shader: &'a Shader<'a>,
    pub(super) frame: &'a CameraFrame,
    /// The row's film y of its pixel centres.
    pub(super) film_y: f64,
    /// The band's elevation (rad).
    pub(super) alpha: f64,
    pub(super) sun: BandSun,
    /// The band's sun-free colour, to which the addition is added.
    pub(super) background: [f64; 3],
}

impl BandColumns<'_> {
    fn azimuth_offset(&self, x: usize) -> f64 {
        self.frame
            .view_direction_at_elevation(x as f64 + 0.5, self.film_y, self.alpha)
            .azimuth_offset_rad()
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
    /// distance from the centre column.
    pub(super) fn fill_band(
        &self,
        (start, end): (usize, usize),
        width: usize,
        out: &mut [[f64; 3]],
    ) {
        self.fill((start, end), out);
        self.fill((width - end, (width - start).min(width / 2)), out);
    }

    /// Fill `out[x]` for the columns x of [`a`, `b`) (module docs).
    fn fill(&self, (a, b): (usize, usize), out: &mut [[f64; 3]]) {
        let centre = self.sun_column((a, b));
        let value = |x: usize| self.sun.at(self.shader, self.azimuth_offset(x));
        fill_columns((a, b), centre, self.background, value, out);
    }
}

/// Fill `out[x]` for the columns x of [`a`, `b`) with `value(x)` at the nodes (every
/// [`STRIDE`]th column, the last, and `centre` with its neighbours) and where refinement needs
/// it, linear interpolation between them elsewhere (module docs); `background` is the colour
/// the values are added to.
fn fill_columns(
    (a, b): (usize, usize),
    centre: Option<usize>,
    background: [f64; 3],
    value: impl Fn(usize) -> [f64; 3],
    out: &mut [[f64; 3]],
) {
    if b <= a {
        return;
    }
    let mut nodes: Vec<usize> = (a..b).step_by(STRIDE).collect();
    nodes.push(b - 1);
    if let Some(c) = centre.filter(|c| (a..b).contains(c)) {
        nodes.extend([c.saturating_sub(1).max(a), c, (c + 1).min(b - 1)]);
    }
    nodes.sort_unstable();
    nodes.dedup();
    for &x in &nodes {
        out[x] = value(x);
    }
    let mut open: Vec<(usize, usize)> = nodes.windows(2).map(|w| (w[0], w[1])).collect();
    while let Some((i, j)) = open.pop() {
        if j <= i + 1 {
            continue;
        }
        let m = (i + j) / 2;
        out[m] = value(m);
        if predicts(out, i, j, m, background) {
            interpolate(out, i, m);
            interpolate(out, m, j);
        } else {
            open.extend([(i, m), (m, j)]);
        }
    }
}

/// Whether linear interpolation between columns `i` and `j` of `out` predicts column `m`
/// within [`TOLERANCE`] of the pixel's radiance there (`background` plus the addition), plus
/// [`FLOOR`].
fn predicts(out: &[[f64; 3]], i: usize, j: usize, m: usize, background: [f64; 3]) -> bool {
    let t = (m - i) as f64 / (j - i) as f64;
    let (a, b, v) = (out[i], out[j], out[m]);
    (0..3).all(|c| {
        let predicted = a[c] + (b[c] - a[c]) * t;
        (predicted - v[c]).abs() <= TOLERANCE * (background[c] + v[c]).abs() + FLOOR
    })
}

/// Fill the columns strictly between `i` and `j` of `out` by linear interpolation.
fn interpolate(out: &mut [[f64; 3]], i: usize, j: usize) {
    let (a, b) = (out[i], out[j]);
    for (k, v) in out[i + 1..j].iter_mut().enumerate() {
        let t = (k + 1) as f64 / (j - i) as f64;
        *v = [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * t);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The worst error of `fill_columns` over 400 columns against `exact`, in units of the
    /// tolerance on the pixel's radiance; and how many columns it evaluated.
    fn worst(
        exact: impl Fn(usize) -> [f64; 3],
        centre: usize,
        background: [f64; 3],
    ) -> (f64, usize) {
        let calls = std::cell::Cell::new(0);
        let value = |x: usize| {
            calls.set(calls.get() + 1);
            exact(x)
        };
        let mut out = vec![[f64::NAN; 3]; 400];
        fill_columns((0, 400), Some(centre), background, value, &mut out);
        let mut worst = 0.0f64;
        for (x, got) in out.iter().enumerate() {
            let want = exact(x);
            for c in 0..3 {
                let allowed = TOLERANCE * (background[c] + want[c]).abs() + FLOOR;
                worst = worst.max((got[c] - want[c]).abs() / allowed);
            }
        }
        (worst, calls.get())
    }

    #[test]
    fn glitter_and_disc_profiles_are_filled_within_the_tolerance() {
        let sea = [0.15, 0.19, 0.23];
        // A glitter peak 36 columns wide, 3e4 times the sea at its centre (the strips scene's
        // sun at 0°), and a faint one: the tails are resolved where they still show over the
        // sea, and interpolated where they do not.
        for peak in [5e3, 1e-2] {
            let glitter = |x: usize| {
                let g = peak * (-((x as f64 - 203.0) / 36.0).powi(2)).exp();
                [g, 0.3 * g, 0.01 * g]
            };
            let (err, calls) = worst(glitter, 203, sea);
            assert!(err <= 1.0, "peak {peak}: {err}");
            assert!(calls < 400, "peak {peak}: {calls} columns evaluated");
        }
        // A limb-darkened disc chord with sharp edges between columns 61.5 and 341.5: the
        // edges land on the columns the exact shading puts them, the inside is interpolated.
        let disc = |x: usize| {
            let s = (x as f64 - 201.5) / 140.0;
            if s.abs() >= 1.0 {
                return [0.0; 3];
            }
            let i = 1850.0 * (1.0 - 0.6 * (1.0 - (1.0 - s * s).sqrt()));
            [i, 0.5 * i, 0.1 * i]
        };
        let (err, calls) = worst(disc, 201, [0.3; 3]);
        assert!(err <= 1.0, "disc: {err}");
        assert!(calls < 200, "disc: {calls} columns evaluated");
    }

    #[test]
    fn a_peak_between_the_first_nodes_is_found_at_the_centre_column() {
        // Three columns wide, centred between two nodes 8 apart: only the centre node sees it.
        let spike = |x: usize| {
            if (203..206).contains(&x) {
                [100.0; 3]
            } else {
                [0.0; 3]
            }
        };
        let (err, _) = worst(spike, 204, [0.1; 3]);
        assert!(err <= 1.0, "{err}");
    }
}
