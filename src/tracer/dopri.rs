//! Stage 4 (trace), numerical core: one embedded Dormand–Prince 5(4) step with FSAL, its error
//! estimate, the Hairer PI step-size controller and the 4th-order continuous extension (dense
//! output) used to locate events inside a step.
//!
//! In: a right-hand side `f(y)` (autonomous: the ray equation in arc length does not depend on s),
//! a state `y` of `N` reals and a step length. Out: the 5th-order solution, the stage derivatives
//! needed for dense output, and a scaled error.
//!
//! Written by hand rather than taken from a crate (see crates.md §2.1): the available ODE crates
//! (`ode_solvers`, `diffsol`, `russell_ode`) have no event location inside a step, only scalar
//! tolerances (our state mixes positions in metres with unit directions), and they allocate per
//! integration call; the tracer runs millions of short integrations in the renderer's hot loop.
//! The state is a fixed-size array so that every stage lives on the stack.

// The Dormand–Prince 5(4) tableau. The nodes (1/5, 3/10, 4/5, 8/9, 1, 1) are not needed: the
// ray equation in arc length is autonomous.
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
// 5th-order weights (= the last row of A: first same as last).
const B1: f64 = 35.0 / 384.0;
const B3: f64 = 500.0 / 1113.0;
const B4: f64 = 125.0 / 192.0;
const B5: f64 = -2187.0 / 6784.0;
const B6: f64 = 11.0 / 84.0;
// Error weights: 5th-order minus 4th-order weights.
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
// Dense-output weights of the 4th-order continuous extension (Hairer & Wanner's DOPRI5 `contd5`).
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// `y + h·Σ wᵢ kᵢ` for a short list of stages, component by component.
#[inline(always)]
fn combine<const N: usize>(y: &[f64; N], h: f64, terms: &[(f64, &[f64; N])]) -> [f64; N] {
    let mut out = *y;
    for i in 0..N {
        let mut acc = 0.0;
        for (w, k) in terms {
            acc += w * k[i];
        }
        out[i] += h * acc;
    }
    out
}

/// One attempted step: everything needed to accept it, estimate its error and interpolate in it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Step<const N: usize> {
    /// State at the start.
    pub y0: [f64; N],
    /// State at the end (5th order).
    pub y1: [f64; N],
    /// Step length.
    pub h: f64,
    /// Stage derivatives k₁, k₃, k₄, k₅, k₆, k₇ (k₂ is not needed after the step).
    pub k1: [f64; N],
    k3: [f64; N],
    k4: [f64; N],
    k5: [f64; N],
    k6: [f64; N],
    /// f(y1): the first stage of the next step (FSAL).
    pub k7: [f64; N],
    /// The local error estimate (5th minus 4th order), per component.
    pub error: [f64; N],
}

impl<const N: usize> Step<N> {
    /// Take one Dormand–Prince step of length `h` from `y0`, whose derivative is `k1`.
    #[inline]
    #[allow(clippy::needless_range_loop)]
    pub fn attempt(
        f: &mut impl FnMut(&[f64; N]) -> [f64; N],
        y0: &[f64; N],
        k1: &[f64; N],
        h: f64,
    ) -> Self {
        let k2 = f(&combine(y0, h, &[(A21, k1)]));
        let k3 = f(&combine(y0, h, &[(A31, k1), (A32, &k2)]));
        let k4 = f(&combine(y0, h, &[(A41, k1), (A42, &k2), (A43, &k3)]));
        let k5 = f(&combine(
            y0,
            h,
            &[(A51, k1), (A52, &k2), (A53, &k3), (A54, &k4)],
        ));
        let k6 = f(&combine(
            y0,
            h,
            &[(A61, k1), (A62, &k2), (A63, &k3), (A64, &k4), (A65, &k5)],
        ));
        let y1 = combine(
            y0,
            h,
            &[(B1, k1), (B3, &k3), (B4, &k4), (B5, &k5), (B6, &k6)],
        );
        let k7 = f(&y1);
        let mut error = [0.0; N];
        for i in 0..N {
            error[i] =
                h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
        }
        Step {
            y0: *y0,
            y1,
            h,
            k1: *k1,
            k3,
            k4,
            k5,
            k6,
            k7,
            error,
        }
    }

    /// Whether every component of the end state, its derivative and the error is finite.
    pub fn is_finite(&self) -> bool {
        self.y1
            .iter()
            .chain(self.k7.iter())
            .chain(self.error.iter())
            .all(|v| v.is_finite())
    }

    /// The continuous extension of this step.
    #[allow(clippy::needless_range_loop)] // one index walks eight parallel arrays
    pub fn dense(&self) -> Dense<N> {
        let mut c = [[0.0; N]; 5];
        for i in 0..N {
            let dy = self.y1[i] - self.y0[i];
            let bspl = self.h * self.k1[i] - dy;
            c[0][i] = self.y0[i];
            c[1][i] = dy;
            c[2][i] = bspl;
            c[3][i] = dy - self.h * self.k7[i] - bspl;
            c[4][i] = self.h
                * (D1 * self.k1[i]
                    + D3 * self.k3[i]
                    + D4 * self.k4[i]
                    + D5 * self.k5[i]
                    + D6 * self.k6[i]
                    + D7 * self.k7[i]);
        }
        Dense { c }
    }
}

/// The 4th-order interpolant of one accepted step, evaluated at a fraction `t ∈ [0, 1]` of it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Dense<const N: usize> {
    c: [[f64; N]; 5],
}

impl<const N: usize> Dense<N> {
    /// The interpolated state at fraction `t` of the step.
    #[inline]
    pub fn at(&self, t: f64) -> [f64; N] {
        let s = 1.0 - t;
        let mut y = [0.0; N];
        for (i, out) in y.iter_mut().enumerate() {
            let c = &self.c;
            *out = c[0][i] + t * (c[1][i] + s * (c[2][i] + t * (c[3][i] + s * c[4][i])));
        }
        y
    }
}

/// Hairer's PI step-size controller (β = 0.04, safety 0.9, step ratio kept in [0.2, 10]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Controller {
    /// The previous accepted error (at least 1e-4), for the integral part.
    previous_error: f64,
}

const BETA: f64 = 0.04;
const SAFETY: f64 = 0.9;
const MIN_RATIO: f64 = 0.2;
const MAX_RATIO: f64 = 10.0;

impl Controller {
    /// A fresh controller.
    pub fn new() -> Self {
        Controller {
            previous_error: 1e-4,
        }
    }

    /// The next step after accepting a step of length `h` with scaled error `err ≤ 1`.
    pub fn accept(&mut self, h: f64, err: f64) -> f64 {
        let expo = 0.2 - BETA * 0.75;
        let fac11 = err.max(1e-300).powf(expo);
        let fac = fac11 / self.previous_error.powf(BETA);
        let fac = (fac / SAFETY).clamp(1.0 / MAX_RATIO, 1.0 / MIN_RATIO);
        self.previous_error = err.max(1e-4);
        h / fac
    }

    /// The retry step after rejecting a step of length `h` with scaled error `err > 1`.
    pub fn reject(&self, h: f64, err: f64) -> f64 {
        if !err.is_finite() {
            return h * MIN_RATIO;
        }
        let expo = 0.2 - BETA * 0.75;
        let fac11 = err.powf(expo);
        h / (fac11 / SAFETY).min(1.0 / MIN_RATIO)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// y' = y (exp) integrated with fixed steps: 5th order, so halving h cuts the error ~32×.
    #[test]
    fn fifth_order_on_exponential() {
        let mut f = |y: &[f64; 1]| [y[0]];
        let run = |n: usize, f: &mut dyn FnMut(&[f64; 1]) -> [f64; 1]| {
            let h = 1.0 / n as f64;
            let mut y = [1.0];
            let mut k = f(&y);
            let mut g = |y: &[f64; 1]| f(y);
            for _ in 0..n {
                let s = Step::attempt(&mut g, &y, &k, h);
                y = s.y1;
                k = s.k7;
            }
            (y[0] - 1f64.exp()).abs()
        };
        let e1 = run(10, &mut f);
        let e2 = run(20, &mut f);
        let ratio = e1 / e2;
        assert!(ratio > 25.0 && ratio < 40.0, "ratio {ratio}");
    }

    /// The dense output reproduces a cubic exactly (4th-order interpolant) and the end points.
    #[test]
    fn dense_output_matches_solution_inside_step() {
        // y' = (1, 3t², …): state (t, t³), exact solution known.
        let mut f = |y: &[f64; 2]| [1.0, 3.0 * y[0] * y[0]];
        let y0 = [0.5, 0.125];
        let k1 = f(&y0);
        let s = Step::attempt(&mut f, &y0, &k1, 0.4);
        let d = s.dense();
        for i in 0..=10 {
            let t = i as f64 / 10.0;
            let y = d.at(t);
            let x = 0.5 + 0.4 * t;
            assert!((y[0] - x).abs() < 1e-14);
            assert!(
                (y[1] - x * x * x).abs() < 1e-12,
                "t {t}: {} vs {}",
                y[1],
                x * x * x
            );
        }
    }

    #[test]
    fn controller_limits_ratio() {
        let mut c = Controller::new();
        assert!((c.accept(1.0, 0.0) - 10.0).abs() < 1e-12);
        assert!(c.reject(1.0, 1e30) >= 0.2 - 1e-12);
        assert!(c.reject(1.0, f64::NAN) > 0.0);
    }
}
