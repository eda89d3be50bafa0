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

use std::sync::OnceLock;

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
/// fraction t ∈ [0, 1]), built lazily in chunks of [`CHUNK_CELLS`] cells: a chunk is computed
/// (nodes, coefficients, the per-cell check) the first time a lookup lands in it, so a frame
/// whose rays stay in the lowest few hundred metres pays for those metres only. A chunk is a
/// pure function of its index, so the values do not depend on which thread built it or when.
#[derive(Debug, Clone)]
pub(crate) struct HermiteGrid {
    start_m: f64,
    step_m: f64,
    inv_step: f64,
    cells: usize,
    tolerance_n: f64,
    tolerance_dndh: f64,
    chunks: Vec<OnceLock<Chunk>>,
}

/// Cells per lazily built chunk of a [`HermiteGrid`].
pub(crate) const CHUNK_CELLS: usize = 64;

/// One built chunk: its cells' coefficients (a fixed array, so the hot lookup needs no bounds
/// check; a cell that evaluates the exact formula has NaN coefficients, which is also what a
/// padding cell past the grid's end holds) and the raw check errors (per cell: max |Δn|,
/// max |Δ(dn/dh)|; NaN where a node could not be evaluated).
#[derive(Debug, Clone)]
struct Chunk {
    cells: [[f64; 6]; CHUNK_CELLS],
    raw_error: Vec<(f64, f64)>,
}

/// The coefficients of a cell that evaluates the exact formula.
const EXACT_CELL: [f64; 6] = [f64::NAN; 6];

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
fn node<E>(exact: &dyn Fn(f64) -> NodeResult<E>, h: f64, step_m: f64) -> Result<[f64; 3], E> {
    let (v, d) = exact(h)?;
    let (_, below) = exact(h - SECOND_DERIVATIVE_STEP_M)?;
    let (_, above) = exact(h + SECOND_DERIVATIVE_STEP_M)?;
    let second = (above - below) / (2.0 * SECOND_DERIVATIVE_STEP_M);
    Ok([v, d * step_m, second * step_m * step_m])
}

impl HermiteGrid {
    /// A grid of `cells` cells of `step_m` from `start_m`; nothing is evaluated until a lookup
    /// (or [`error`](Self::error)) needs a chunk. A cell whose interpolation misses
    /// `tolerance_n` or `tolerance_dndh` at its check points evaluates the exact formula.
    pub(crate) fn new(
        start_m: f64,
        step_m: f64,
        cells: usize,
        tolerance_n: f64,
        tolerance_dndh: f64,
    ) -> Self {
        Self {
            start_m,
            step_m,
            inv_step: 1.0 / step_m,
            cells,
            tolerance_n,
            tolerance_dndh,
            chunks: (0..cells.div_ceil(CHUNK_CELLS))
                .map(|_| OnceLock::new())
                .collect(),
        }
    }

    /// Build chunk `c`: the nodes from `exact`, the quintic of each cell, then the
    /// interpolation error at three points per cell (quarter, mid, three-quarter); cells over
    /// a tolerance, and every cell of a chunk where `exact` failed, evaluate exactly.
    #[cold]
    #[inline(never)]
    fn build_chunk<E>(&self, c: usize, exact: &dyn Fn(f64) -> NodeResult<E>) -> Chunk {
        let first = c * CHUNK_CELLS;
        let count = CHUNK_CELLS.min(self.cells - first);
        let height = |i: usize, frac: f64| self.start_m + (i as f64 + frac) * self.step_m;
        let nodes: Result<Vec<[f64; 3]>, E> = (first..=first + count)
            .map(|i| node(exact, height(i, 0.0), self.step_m))
            .collect();
        let mut chunk = Chunk {
            cells: [EXACT_CELL; CHUNK_CELLS],
            raw_error: vec![(f64::NAN, f64::NAN); count],
        };
        let Ok(nodes) = nodes else {
            return chunk;
        };
        for (k, w) in nodes.windows(2).enumerate() {
            let coefficients = quintic(w[0], w[1]);
            let mut worst = (0.0f64, 0.0f64);
            for frac in [0.25, 0.5, 0.75] {
                let Ok((n_ex, d_ex)) = exact(height(first + k, frac)) else {
                    worst = (f64::NAN, f64::NAN);
                    break;
                };
                let (n_t, d_t) = evaluate(&coefficients, frac, self.inv_step);
                worst.0 = worst.0.max((n_t - n_ex).abs());
                worst.1 = worst.1.max((d_t - d_ex).abs());
            }
            let (dn, dd) = worst;
            let interpolated = dn <= self.tolerance_n
                && dd <= self.tolerance_dndh
                && dn.is_finite()
                && dd.is_finite()
                && coefficients.iter().all(|c| c.is_finite());
            if interpolated {
                chunk.cells[k] = coefficients;
            }
            chunk.raw_error[k] = worst;
        }
        chunk
    }

    /// Chunk `c`, built now if no lookup has needed it yet.
    #[inline]
    fn chunk<E>(&self, c: usize, exact: &dyn Fn(f64) -> NodeResult<E>) -> &Chunk {
        self.chunks[c].get_or_init(|| self.build_chunk(c, exact))
    }

    /// The measured accuracy of the whole grid: builds every chunk not yet built (in
    /// parallel) and sums up their checks.
    pub(crate) fn error<E>(&self, exact: &(dyn Fn(f64) -> NodeResult<E> + Sync)) -> GridError {
        (0..self.chunks.len()).into_par_iter().for_each(|c| {
            self.chunk(c, exact);
        });
        let mut report = GridError {
            start_agl_m: self.start_m,
            step_m: self.step_m,
            cells: self.cells,
            samples: 3 * self.cells,
            ..GridError::default()
        };
        for c in 0..self.chunks.len() {
            let chunk = self.chunk(c, exact);
            for (&(dn, dd), cell) in chunk.raw_error.iter().zip(&chunk.cells) {
                report.raw_max_abs_dn = report.raw_max_abs_dn.max(dn);
                report.raw_max_abs_ddndh_per_m = report.raw_max_abs_ddndh_per_m.max(dd);
                if cell[0].is_nan() {
                    report.exact_cells += 1;
                } else {
                    report.max_abs_dn = report.max_abs_dn.max(dn);
                    report.max_abs_ddndh_per_m = report.max_abs_ddndh_per_m.max(dd);
                }
            }
        }
        report
    }

    /// (cells built so far, cells in the grid).
    pub(crate) fn built_cells(&self) -> (usize, usize) {
        let built = self
            .chunks
            .iter()
            .filter_map(|c| c.get())
            .map(|c| c.raw_error.len())
            .sum();
        (built, self.cells)
    }

    /// Top of the grid (m).
    pub(crate) fn end_m(&self) -> f64 {
        self.start_m + self.cells as f64 * self.step_m
    }

    /// Look up `height_m` (which must not be NaN); `exact` builds the chunk it lands in if
    /// none has yet.
    #[inline]
    pub(crate) fn lookup<E>(&self, height_m: f64, exact: &dyn Fn(f64) -> NodeResult<E>) -> Lookup {
        let u = (height_m - self.start_m) * self.inv_step;
        if u.is_nan() || u < 0.0 {
            return Lookup::Outside;
        }
        let cells = self.cells;
        let mut i = u as usize;
        if i >= cells {
            if u > cells as f64 {
                return Lookup::Outside;
            }
            i = cells - 1;
        }
        let cell = &self.chunk(i / CHUNK_CELLS, exact).cells[i % CHUNK_CELLS];
        if cell[0].is_nan() {
            return Lookup::Exact;
        }
        let (v, d) = evaluate(cell, u - i as f64, self.inv_step);
        Lookup::Value(v, d)
    }
}

/// Hermite value and derivative of a cell's quintic at fraction `t` ∈ [0, 1]; `inv_step`
/// turns the derivative into one per metre.
#[inline]
fn evaluate(coefficients: &[f64; 6], t: f64, inv_step: f64) -> (f64, f64) {
    let [c0, c1, c2, c3, c4, c5] = *coefficients;
    let value = c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * c5))));
    let deriv = c1 + t * (2.0 * c2 + t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5)));
    (value, deriv * inv_step)
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
        let grid = HermiteGrid::new(0.0, 0.5, 100, 1e-15, 1e-15);
        assert!(grid.chunks.iter().all(|c| c.get().is_none()));
        assert!(matches!(grid.lookup(13.37, &f), Lookup::Value(..)));
        // 100 cells = two chunks; the lookup at 13.37 m (cell 26) built the first only.
        assert!(grid.chunks[0].get().is_some() && grid.chunks[1].get().is_none());
        let err = grid.error(&f);
        assert_eq!(err.exact_cells, 0);
        assert_eq!(err.cells, 100);
        assert!(
            err.max_abs_dn < 1e-17 && err.max_abs_ddndh_per_m < 1e-17,
            "{err:?}"
        );
        for &h in &[0.0, 0.1, 13.37, 49.99, 50.0] {
            let Lookup::Value(v, d) = grid.lookup(h, &f) else {
                panic!("{h}")
            };
            let (ve, de) = f(h).unwrap();
            assert!((v - ve).abs() < 1e-17 && (d - de).abs() < 1e-17, "{h}");
        }
        assert_eq!(grid.lookup(50.1, &f), Lookup::Outside);
        assert_eq!(grid.lookup(-0.1, &f), Lookup::Outside);
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
        let grid = HermiteGrid::new(0.0, 1.0, 20, 1e-12, 1e-12);
        assert_eq!(grid.lookup(10.5, &f), Lookup::Exact);
        assert!(matches!(grid.lookup(11.5, &f), Lookup::Value(..)));
        let err = grid.error(&f);
        assert_eq!(err.exact_cells, 1, "{err:?}");
        assert!(err.raw_max_abs_ddndh_per_m > 1e-7);
    }

    /// A chunk where the exact formula fails evaluates exactly (and reports NaN-free maxima).
    #[test]
    fn a_failing_chunk_falls_back_to_exact() {
        let f = |h: f64| -> NodeResult<()> {
            if h > 70.0 {
                Err(())
            } else {
                Ok((1e-6 * h, 1e-6))
            }
        };
        let grid = HermiteGrid::new(0.0, 1.0, 100, 1e-12, 1e-12);
        assert!(matches!(grid.lookup(10.0, &f), Lookup::Value(..)));
        assert_eq!(grid.lookup(80.0, &f), Lookup::Exact);
        let err = grid.error(&f);
        assert_eq!(err.exact_cells, 100 - CHUNK_CELLS);
        assert!(err.raw_max_abs_dn.is_finite() && err.max_abs_dn < 1e-12);
    }
}
