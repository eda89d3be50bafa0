//! Stage 4 (trace), break handling: which levels of a piecewise field a step crosses.
//!
//! In: the field's breaks (heights where dn/dh or d²n/dh² jumps, ascending), the ray's current
//! height interval between two neighbouring breaks, and one accepted step (its end heights,
//! climb signs and dense output). Out: the first point of the step at which the ray leaves its
//! interval, so the ray loop can shorten the step to end exactly there. A Runge–Kutta step that
//! straddles a break integrates a right-hand side that is not smooth inside the step and drops
//! from fifth to first or second order; ending steps on breaks keeps the method's order (the
//! same treatment a careful reference integrator gives a discontinuity).

/// A root finder: `locate(g, a, c)` returns a root of `g` on [a, c].
pub(crate) type Locate<'a> = dyn FnMut(&mut dyn FnMut(f64) -> f64, f64, f64) -> f64 + 'a;

/// The open height interval between two neighbouring breaks in which the ray currently is.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bracket<'b> {
    breaks: &'b [f64],
    /// Number of breaks below the interval: it is (breaks[k − 1], breaks[k]).
    k: usize,
}

/// Where a step first leaves its interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Exit {
    /// Fraction of the step (0 < t ≤ 1).
    pub t: f64,
    /// The break height it crosses (m).
    pub height_m: f64,
    /// Whether it crosses upwards.
    pub up: bool,
}

impl<'b> Bracket<'b> {
    /// The interval of a ray at `height_m`; on a break, the side it is heading to.
    pub fn new(breaks: &'b [f64], height_m: f64, climbing: bool) -> Self {
        let k = if climbing {
            breaks.partition_point(|&b| b <= height_m)
        } else {
            breaks.partition_point(|&b| b < height_m)
        };
        Bracket { breaks, k }
    }

    /// Whether the field has no breaks at all.
    pub fn is_empty(&self) -> bool {
        self.breaks.is_empty()
    }

    /// Lower bound of the interval (m; −∞ below the lowest break).
    pub fn lower_m(&self) -> f64 {
        if self.k == 0 {
            f64::NEG_INFINITY
        } else {
            self.breaks[self.k - 1]
        }
    }

    /// Upper bound of the interval (m; +∞ above the highest break).
    pub fn upper_m(&self) -> f64 {
        self.breaks.get(self.k).copied().unwrap_or(f64::INFINITY)
    }

    /// Move to the neighbouring interval across the upper (`up`) or lower bound.
    pub fn cross(&mut self, up: bool) {
        if up {
            self.k = (self.k + 1).min(self.breaks.len());
        } else {
            self.k = self.k.saturating_sub(1);
        }
    }

    /// The first exit of a step from the interval, if any. `height` gives the height at a
    /// fraction of the step (dense output), `extremum` the fraction at which the height has its
    /// one interior extremum, if the climb changes sign inside the step. `locate(g, a, c)` finds a
    /// root of `g` on [a, c]. A piece that already starts outside (the ray landed on a break a
    /// rounding error to the far side) exits at its start.
    pub fn first_exit(
        &self,
        heights_m: (f64, f64),
        extremum: Option<f64>,
        height: &mut dyn FnMut(f64) -> f64,
        locate: &mut Locate<'_>,
    ) -> Option<Exit> {
        let (lower, upper) = (self.lower_m(), self.upper_m());
        let (h0, h1) = heights_m;
        if extremum.is_none() && h1 > lower && h1 < upper {
            return None;
        }
        let pieces: [(f64, f64); 2] = match extremum {
            Some(tm) => [(0.0, tm), (tm, 1.0)],
            None => [(0.0, 1.0), (1.0, 1.0)],
        };
        for (a, c) in pieces {
            if c <= a {
                continue;
            }
            let ha = if a == 0.0 { h0 } else { height(a) };
            let hc = if c == 1.0 { h1 } else { height(c) };
            let (bound, up, outside) = if hc > ha {
                (upper, true, hc > upper)
            } else {
                (lower, false, hc < lower)
            };
            if !outside {
                continue;
            }
            let already_out = if up { ha >= bound } else { ha <= bound };
            let t = if already_out {
                a
            } else {
                locate(&mut |t| height(t) - bound, a, c)
            };
            return Some(Exit {
                t,
                height_m: bound,
                up,
            });
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bisect(g: &mut dyn FnMut(f64) -> f64, mut a: f64, mut c: f64) -> f64 {
        let ga = g(a);
        for _ in 0..60 {
            let m = 0.5 * (a + c);
            if (g(m) > 0.0) == (ga > 0.0) {
                a = m;
            } else {
                c = m;
            }
        }
        0.5 * (a + c)
    }

    #[test]
    fn bracket_sides_and_crossings() {
        let breaks = [10.0, 20.0, 30.0];
        let b = Bracket::new(&breaks, 20.0, true);
        assert_eq!((b.lower_m(), b.upper_m()), (20.0, 30.0));
        let mut b = Bracket::new(&breaks, 20.0, false);
        assert_eq!((b.lower_m(), b.upper_m()), (10.0, 20.0));
        b.cross(false);
        assert_eq!((b.lower_m(), b.upper_m()), (f64::NEG_INFINITY, 10.0));
        b.cross(false);
        assert_eq!(b.lower_m(), f64::NEG_INFINITY);
        let b = Bracket::new(&breaks, 35.0, true);
        assert_eq!((b.lower_m(), b.upper_m()), (30.0, f64::INFINITY));
    }

    #[test]
    fn first_exit_through_the_top_and_after_an_apex() {
        let breaks = [10.0, 20.0];
        let b = Bracket::new(&breaks, 15.0, true);
        // Rising straight through 20 at t = 0.5.
        let mut h = |t: f64| 15.0 + 10.0 * t;
        let e = b
            .first_exit((15.0, 25.0), None, &mut h, &mut bisect)
            .unwrap();
        assert!((e.t - 0.5).abs() < 1e-12 && e.up && e.height_m == 20.0);
        // Up to an apex at 19 (t = 0.4), then down through 10.
        let mut h = |t: f64| 19.0 - 40.0 * (t - 0.4) * (t - 0.4);
        let h1 = h(1.0);
        assert!(h1 < 10.0);
        let e = b
            .first_exit((h(0.0), h1), Some(0.4), &mut h, &mut bisect)
            .unwrap();
        assert!(!e.up && e.height_m == 10.0 && e.t > 0.4);
        assert!((h(e.t) - 10.0).abs() < 1e-9);
        // Staying inside: no exit.
        let mut h = |t: f64| 15.0 + t;
        assert!(
            b.first_exit((15.0, 16.0), None, &mut h, &mut bisect)
                .is_none()
        );
        // An apex that pokes above 20 exits on the way up.
        let mut h = |t: f64| 15.0 + 24.0 * t * (1.0 - t);
        let e = b
            .first_exit((15.0, 15.0), Some(0.5), &mut h, &mut bisect)
            .unwrap();
        assert!(e.up && e.t < 0.5 && (h(e.t) - 20.0).abs() < 1e-9);
    }
}
