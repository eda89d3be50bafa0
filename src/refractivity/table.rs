//! The fast lookup table behind [`RefractiveAtmosphere`](super::RefractiveAtmosphere)'s
//! `StratifiedIndex` implementation: a uniform grid in height with a quintic Hermite in each cell.
//!
//! In: a function giving the exact (n − 1, dn/dh) at a height. Out: O(1) lookups of
//! (n − 1, dn/dh), where dn/dh is the derivative of the same polynomial, so the pair is consistent
//! (the tracer's Bouguer invariant sees a field whose n is exactly the integral of its dn/dh).
//!
//! Why quintic: each cell matches n, dn/dh and d²n/dh² at both ends, so the table is C² and the
//! ray equation's right-hand side (which holds dn/dh) stays C¹ across the nodes. A cubic table
//! (C¹) puts a jump of d²n/dh² at every node, 0.25 m apart near the ground, and every integrator
//! step straddles some: that capped the tracer's accuracy at a few 0.1 mm at 26 km whatever its
//! tolerance. d²n/dh² at a node is the central difference of the exact dn/dh over ±1 mm; a node
//! next to a real kink gets a wrong value there, and the cell check below sends those cells to
//! the exact formula.
//!
//! Written by hand: `splines` has no derivative and does an O(log n) search per call, and the
//! tracer's hot loop wants an O(1) index with a per-cell fallback, which no crate offers.

use rayon::prelude::*;

/// Measured accuracy of one uniform grid against the exact evaluation.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct GridError {
    /// Lowest height of the grid (m above the surface).
    pub start_agl_m: f64,
    /// Node spacing (m).
    pub step_m: f64,
    /// Number of cells.
    pub cells: usize,
    /// Cells whose measured Hermite error exceeded the tolerance and which therefore evaluate the
    /// exact formula instead (typically cells containing a kink of the profile: a knot of a C¹ fit
    /// or a lapse-rate change of the standard atmosphere).
    pub exact_cells: usize,
    /// Number of check points (three per cell: quarter, mid and three-quarter point).
    pub samples: usize,
    /// Largest |Δn| the table returns at the check points (interpolated cells only; exact cells
    /// are exact).
    pub max_abs_dn: f64,
    /// Largest |Δ(dn/dh)| (m⁻¹) the table returns at the check points.
    pub max_abs_ddndh_per_m: f64,
    /// Largest |Δn| of the plain Hermite interpolant before the exact fallback was applied.
    pub raw_max_abs_dn: f64,
    /// Largest |Δ(dn/dh)| (m⁻¹) of the plain Hermite interpolant before the fallback.
    pub raw_max_abs_ddndh_per_m: f64,
}

/// The result of a grid lookup.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Lookup {
    /// Interpolated (n − 1, dn/dh).
    Value(f64, f64),
    /// This cell must be evaluated exactly.
    Exact,
    /// The height is not covered by this grid.
    Outside,
}

/// A uniform grid with a quintic Hermite per cell (stored as its six coefficients in the cell
/// fraction t ∈ [0, 1]).
#[derive(Debug, Clone)]
pub(crate) struct HermiteGrid {
    start_m: f64,
    step_m: f64,
    inv_step: f64,
    cells: Vec<[f64; 6]>,
    exact_cell: Vec<bool>,
}

/// Half-width (m) of the central difference of dn/dh that gives d²n/dh² at a node.
const SECOND_DERIVATIVE_STEP_M: f64 = 1e-3;

/// The quintic on [0, 1] with value, slope and second derivative `a` at 0 and `b` at 1 (slopes
/// and second derivatives already scaled to the unit interval).
fn quintic(a: [f64; 3], b: [f64; 3]) -> [f64; 6] {
    let (c0, c1, c2) = (a[0], a[1], 0.5 * a[2]);
    let big_a = b[0] - (c0 + c1 + c2);
    let big_b = b[1] - (c1 + 2.0 * c2);
    let big_c = b[2] - 2.0 * c2;
    [
        c0,
        c1,
        c2,
        10.0 * big_a - 4.0 * big_b + 0.5 * big_c,
        -15.0 * big_a + 7.0 * big_b - big_c,
        6.0 * big_a - 3.0 * big_b + 0.5 * big_c,
    ]
}

/// A node function failed (non-finite or invalid air); carries its error.
pub(crate) type NodeResult<E> = Result<(f64, f64), E>;

/// A node at `h`: (n − 1, slope, second derivative), the slope and second derivative scaled to
/// a cell of `step_m`.
fn node<E>(
    exact: &(dyn Fn(f64) -> NodeResult<E> + Sync),
    h: f64,
    step_m: f64,
) -> Result<[f64; 3], E> {
    let (v, d) = exact(h)?;
    let (_, below) = exact(h - SECOND_DERIVATIVE_STEP_M)?;
    let (_, above) = exact(h + SECOND_DERIVATIVE_STEP_M)?;
    let second = (above - below) / (2.0 * SECOND_DERIVATIVE_STEP_M);
    Ok([v, d * step_m, second * step_m * step_m])
}

impl HermiteGrid {
    /// Build a grid of `cells` cells of `step_m` from `start_m`, evaluating `exact` at every node
    /// (in parallel), then measure the interpolation error at three points per cell and mark the
    /// cells that exceed the tolerances for exact evaluation.
    pub(crate) fn build<E: Send>(
        start_m: f64,
        step_m: f64,
        cells: usize,
        tolerance_n: f64,
        tolerance_dndh: f64,
        exact: &(dyn Fn(f64) -> NodeResult<E> + Sync),
    ) -> Result<(Self, GridError), E> {
        let nodes: Vec<[f64; 3]> = (0..=cells)
            .into_par_iter()
            .map(|i| node(exact, start_m + i as f64 * step_m, step_m))
            .collect::<Result<_, E>>()?;
        let mut grid = Self {
            start_m,
            step_m,
            inv_step: 1.0 / step_m,
            cells: nodes.windows(2).map(|w| quintic(w[0], w[1])).collect(),
            exact_cell: vec![false; cells],
        };
        // Per cell: (raw max dn, raw max d(dn/dh)).
        let errors: Vec<(f64, f64)> = (0..cells)
            .into_par_iter()
            .map(|i| {
                let mut worst = (0.0f64, 0.0f64);
                for frac in [0.25, 0.5, 0.75] {
                    let (n_ex, d_ex) = exact(start_m + (i as f64 + frac) * step_m)?;
                    let (n_t, d_t) = grid.interpolate(i, frac);
                    worst.0 = worst.0.max((n_t - n_ex).abs());
                    worst.1 = worst.1.max((d_t - d_ex).abs());
                }
                Ok(worst)
            })
            .collect::<Result<_, E>>()?;
        let mut report = GridError {
            start_agl_m: start_m,
            step_m,
            cells,
            samples: 3 * cells,
            ..GridError::default()
        };
        for (i, &(dn, dd)) in errors.iter().enumerate() {
            report.raw_max_abs_dn = report.raw_max_abs_dn.max(dn);
            report.raw_max_abs_ddndh_per_m = report.raw_max_abs_ddndh_per_m.max(dd);
            if dn > tolerance_n || dd > tolerance_dndh || !dn.is_finite() || !dd.is_finite() {
                grid.exact_cell[i] = true;
                report.exact_cells += 1;
            } else {
                report.max_abs_dn = report.max_abs_dn.max(dn);
                report.max_abs_ddndh_per_m = report.max_abs_ddndh_per_m.max(dd);
            }
        }
        Ok((grid, report))
    }

    /// Top of the grid (m).
    pub(crate) fn end_m(&self) -> f64 {
        self.start_m + self.exact_cell.len() as f64 * self.step_m
    }

    /// Hermite value and derivative in cell `i` at fraction `t` ∈ [0, 1].
    #[inline]
    fn interpolate(&self, i: usize, t: f64) -> (f64, f64) {
        let [c0, c1, c2, c3, c4, c5] = self.cells[i];
        let value = c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * c5))));
        let deriv = c1 + t * (2.0 * c2 + t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5)));
        (value, deriv * self.inv_step)
    }

    /// Look up `height_m` (which must not be NaN).
    #[inline]
    pub(crate) fn lookup(&self, height_m: f64) -> Lookup {
        let u = (height_m - self.start_m) * self.inv_step;
        if u.is_nan() || u < 0.0 {
            return Lookup::Outside;
        }
        let cells = self.exact_cell.len();
        let mut i = u as usize;
        if i >= cells {
            if u > cells as f64 {
                return Lookup::Outside;
            }
            i = cells - 1;
        }
        if self.exact_cell[i] {
            return Lookup::Exact;
        }
        let (v, d) = self.interpolate(i, u - i as f64);
        Lookup::Value(v, d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cubic is reproduced exactly (to rounding) by the quintic Hermite.
    #[test]
    fn reproduces_a_cubic_exactly() {
        let f = |h: f64| -> NodeResult<()> {
            Ok((
                1e-4 + 2e-6 * h - 3e-8 * h * h + 1e-10 * h * h * h,
                2e-6 - 6e-8 * h + 3e-10 * h * h,
            ))
        };
        let (grid, err) = HermiteGrid::build(0.0, 0.5, 100, 1e-15, 1e-15, &f).unwrap();
        assert_eq!(err.exact_cells, 0);
        assert!(
            err.max_abs_dn < 1e-17 && err.max_abs_ddndh_per_m < 1e-17,
            "{err:?}"
        );
        for &h in &[0.0, 0.1, 13.37, 49.99, 50.0] {
            let Lookup::Value(v, d) = grid.lookup(h) else {
                panic!("{h}")
            };
            let (ve, de) = f(h).unwrap();
            assert!((v - ve).abs() < 1e-17 && (d - de).abs() < 1e-17, "{h}");
        }
        assert_eq!(grid.lookup(50.1), Lookup::Outside);
        assert_eq!(grid.lookup(-0.1), Lookup::Outside);
        assert_eq!(grid.end_m(), 50.0);
    }

    /// A kink (jump in the slope) inside a cell is caught and that cell falls back to exact.
    #[test]
    fn flags_the_cell_with_a_kink() {
        let f = |h: f64| -> NodeResult<()> {
            if h < 10.3 {
                Ok((0.0, 0.0))
            } else {
                Ok((1e-6 * (h - 10.3), 1e-6))
            }
        };
        let (grid, err) = HermiteGrid::build(0.0, 1.0, 20, 1e-12, 1e-12, &f).unwrap();
        assert_eq!(err.exact_cells, 1, "{err:?}");
        assert!(err.raw_max_abs_ddndh_per_m > 1e-7);
        assert_eq!(grid.lookup(10.5), Lookup::Exact);
        assert!(matches!(grid.lookup(11.5), Lookup::Value(..)));
    }
}
