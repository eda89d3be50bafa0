//! The fast lookup table behind [`RefractiveAtmosphere`](super::RefractiveAtmosphere)'s
//! `StratifiedIndex` implementation: a uniform grid in height with a cubic Hermite in each cell.
//!
//! In: a function giving the exact (n − 1, dn/dh) at a height. Out: O(1) lookups of
//! (n − 1, dn/dh), where dn/dh is the derivative of the same cubic, so the pair is consistent (the
//! tracer's Bouguer invariant sees a field whose n is exactly the integral of its dn/dh).
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

/// A uniform grid of nodes (n − 1, dn/dh) with a cubic Hermite per cell.
#[derive(Debug, Clone)]
pub(crate) struct HermiteGrid {
    start_m: f64,
    step_m: f64,
    inv_step: f64,
    nodes: Vec<[f64; 2]>,
    exact_cell: Vec<bool>,
}

/// A node function failed (non-finite or invalid air); carries its error.
pub(crate) type NodeResult<E> = Result<(f64, f64), E>;

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
        let nodes: Vec<[f64; 2]> = (0..=cells)
            .into_par_iter()
            .map(|i| exact(start_m + i as f64 * step_m).map(|(a, b)| [a, b]))
            .collect::<Result<_, E>>()?;
        let mut grid = Self {
            start_m,
            step_m,
            inv_step: 1.0 / step_m,
            nodes,
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
        let [y0, m0] = self.nodes[i];
        let [y1, m1] = self.nodes[i + 1];
        let h = self.step_m;
        let d = y1 - y0;
        let a1 = h * m0;
        let c2 = 3.0 * d - h * (2.0 * m0 + m1);
        let c3 = -2.0 * d + h * (m0 + m1);
        let value = y0 + t * (a1 + t * (c2 + t * c3));
        let deriv = (a1 + t * (2.0 * c2 + 3.0 * t * c3)) * self.inv_step;
        (value, deriv)
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

    /// A cubic is reproduced exactly by a cubic Hermite.
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
