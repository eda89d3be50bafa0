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
//! A cell holding one declared break of the profile (a sounding level, a layer edge: dn/dh or
//! d²n/dh² jumps there) is cut in two at the break, with a quintic on each side built from
//! one-sided values at the break, each checked like a whole cell. Without the cut every such
//! cell evaluated the exact formula, and a sounding has a break every few hundred metres: the
//! climb out of escaping rays and every step that lands on a break evaluated the exact formula
//! near each one.
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
    /// Cells cut in two at a break of the profile, a quintic on each side (see the module docs).
    pub cut_cells: usize,
    /// Number of check points (three per cell or piece of a cut cell: quarter, mid and
    /// three-quarter point).
    pub samples: usize,
    /// Largest |Δn| the table returns at the check points (interpolated cells only; exact cells
    /// are exact).
    pub max_abs_dn: f64,
    /// Largest |Δ(dn/dh)| (m⁻¹) the table returns at the check points.
    pub max_abs_ddndh_per_m: f64,
    /// Largest |Δn| of the quintic interpolant (a cut cell: its two pieces) before the exact
    /// fallback was applied.
    pub raw_max_abs_dn: f64,
    /// Largest |Δ(dn/dh)| (m⁻¹) of the quintic interpolant (a cut cell: its pieces) before the
    /// fallback.
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
    /// The profile's breaks (m, grid heights, ascending): a cell holding one is cut there.
    breaks_m: Vec<f64>,
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
    /// Cells cut at a break (their entry in `cells` is NaN, as for an exact cell).
    split: Vec<SplitCell>,
    raw_error: Vec<(f64, f64)>,
}

/// A cell cut in two at a break: a quintic below it and one above it.
#[derive(Debug, Clone)]
struct SplitCell {
    /// Index of the cell in its chunk.
    index: usize,
    /// The break (m, grid height): heights at or above it take the upper piece.
    break_m: f64,
    lower: Piece,
    upper: Piece,
}

/// A quintic Hermite over [start_m, start_m + width].
#[derive(Debug, Clone, Copy)]
struct Piece {
    start_m: f64,
    inv_width: f64,
    coefficients: [f64; 6],
}

impl Piece {
    #[inline]
    fn evaluate(&self, height_m: f64) -> (f64, f64) {
        let t = (height_m - self.start_m) * self.inv_width;
        evaluate(&self.coefficients, t, self.inv_width)
    }
}

/// Distance (m) a break must keep from a cell's nodes to be cut at: the central difference of
/// a node reaches ±[`SECOND_DERIVATIVE_STEP_M`], and a node that sees the break is not used.
const BREAK_CLEARANCE_M: f64 = 2.0 * SECOND_DERIVATIVE_STEP_M;

/// How far (m) from a break its one-sided values are taken (then carried to the break along
/// the slope and curvature): clear of the rounding of heights (~1e-9 m) on the right side.
const ONE_SIDED_OFFSET_M: f64 = 1e-6;

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

/// (n − 1, dn/dh, d²n/dh²) at `h`, the last a central difference.
fn raw_node<E>(exact: &dyn Fn(f64) -> NodeResult<E>, h: f64) -> Result<[f64; 3], E> {
    let (v, d) = exact(h)?;
    let (_, below) = exact(h - SECOND_DERIVATIVE_STEP_M)?;
    let (_, above) = exact(h + SECOND_DERIVATIVE_STEP_M)?;
    Ok([v, d, (above - below) / (2.0 * SECOND_DERIVATIVE_STEP_M)])
}

/// A raw node with its derivatives scaled to a cell of `width_m`.
fn scaled([v, d, second]: [f64; 3], width_m: f64) -> [f64; 3] {
    [v, d * width_m, second * width_m * width_m]
}

/// (n − 1, dn/dh, d²n/dh²) at the break `b` from one side (`side` −1 below, +1 above): the
/// values a little way off it, the second derivative by a one-sided second-order difference,
/// carried back to the break.
fn one_sided_node<E>(
    exact: &dyn Fn(f64) -> NodeResult<E>,
    b: f64,
    side: f64,
) -> Result<[f64; 3], E> {
    let (h, k) = (SECOND_DERIVATIVE_STEP_M, side * ONE_SIDED_OFFSET_M);
    let (v0, d0) = exact(b + k)?;
    let (_, d1) = exact(b + k + side * h)?;
    let (_, d2) = exact(b + k + 2.0 * side * h)?;
    let second = side * (-3.0 * d0 + 4.0 * d1 - d2) / (2.0 * h);
    let slope = d0 - k * second;
    Ok([v0 - k * d0 + 0.5 * k * k * second, slope, second])
}

/// The worst (|Δn|, |Δ(dn/dh)|) of `evaluate_at` against `exact` at a piece's quarter, mid and
/// three-quarter points (NaN if `exact` fails there).
fn check<E>(
    exact: &dyn Fn(f64) -> NodeResult<E>,
    start_m: f64,
    width_m: f64,
    evaluate_at: impl Fn(f64) -> (f64, f64),
) -> (f64, f64) {
    let mut worst = (0.0f64, 0.0f64);
    for frac in [0.25, 0.5, 0.75] {
        let h = start_m + frac * width_m;
        let Ok((n_ex, d_ex)) = exact(h) else {
            return (f64::NAN, f64::NAN);
        };
        let (n_t, d_t) = evaluate_at(h);
        worst.0 = worst.0.max((n_t - n_ex).abs());
        worst.1 = worst.1.max((d_t - d_ex).abs());
    }
    worst
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
            breaks_m: Vec::new(),
            chunks: (0..cells.div_ceil(CHUNK_CELLS))
                .map(|_| OnceLock::new())
                .collect(),
        }
    }

    /// The same grid, cutting each cell that holds one of `breaks_m` (m, grid heights) there.
    pub(crate) fn with_breaks(self, mut breaks_m: Vec<f64>) -> Self {
        breaks_m.retain(|b| b.is_finite());
        breaks_m.sort_by(f64::total_cmp);
        Self { breaks_m, ..self }
    }

    /// The one break cell `[x0, x1]` may be cut at: strictly inside, clear of both nodes, and
    /// alone (no other break within reach of the cell's nodes).
    fn cut_of(&self, x0: f64, x1: f64) -> Option<f64> {
        let lo = self
            .breaks_m
            .partition_point(|&b| b <= x0 - BREAK_CLEARANCE_M);
        let near = &self.breaks_m[lo..];
        let count = near.partition_point(|&b| b < x1 + BREAK_CLEARANCE_M);
        match near[..count] {
            [b] if b > x0 + BREAK_CLEARANCE_M && b < x1 - BREAK_CLEARANCE_M => Some(b),
            _ => None,
        }
    }

    /// Cell `[x0, x1]` cut at `b` from its raw end nodes, with its worst check error (both
    /// pieces); `None` where a one-sided value cannot be evaluated.
    fn split_cell<E>(
        &self,
        exact: &dyn Fn(f64) -> NodeResult<E>,
        (x0, x1, b): (f64, f64, f64),
        (a, z): ([f64; 3], [f64; 3]),
    ) -> Option<(Piece, Piece, (f64, f64))> {
        let below = one_sided_node(exact, b, -1.0).ok()?;
        let above = one_sided_node(exact, b, 1.0).ok()?;
        let piece = |start_m: f64, end_m: f64, p: [f64; 3], q: [f64; 3]| {
            let width = end_m - start_m;
            Piece {
                start_m,
                inv_width: 1.0 / width,
                coefficients: quintic(scaled(p, width), scaled(q, width)),
            }
        };
        let (lower, upper) = (piece(x0, b, a, below), piece(b, x1, above, z));
        let worst_lower = check(exact, x0, b - x0, |h| lower.evaluate(h));
        let worst_upper = check(exact, b, x1 - b, |h| upper.evaluate(h));
        let worst = (
            worst_lower.0.max(worst_upper.0),
            worst_lower.1.max(worst_upper.1),
        );
        Some((lower, upper, worst))
    }

    /// Whether a cell (or cut cell) with check error `worst` and `coefficients` is kept.
    fn passes<'c>(
        &self,
        worst: (f64, f64),
        mut coefficients: impl Iterator<Item = &'c f64>,
    ) -> bool {
        worst.0 <= self.tolerance_n
            && worst.1 <= self.tolerance_dndh
            && worst.0.is_finite()
            && worst.1.is_finite()
            && coefficients.all(|c| c.is_finite())
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
            .map(|i| raw_node(exact, height(i, 0.0)))
            .collect();
        let mut chunk = Chunk {
            cells: [EXACT_CELL; CHUNK_CELLS],
            split: Vec::new(),
            raw_error: vec![(f64::NAN, f64::NAN); count],
        };
        let Ok(nodes) = nodes else {
            return chunk;
        };
        for (k, w) in nodes.windows(2).enumerate() {
            let (x0, x1) = (height(first + k, 0.0), height(first + k + 1, 0.0));
            if let Some(b) = self.cut_of(x0, x1) {
                let Some((lower, upper, worst)) = self.split_cell(exact, (x0, x1, b), (w[0], w[1]))
                else {
                    continue;
                };
                let all = lower.coefficients.iter().chain(&upper.coefficients);
                if self.passes(worst, all) {
                    let (index, break_m) = (k, b);
                    chunk.split.push(SplitCell {
                        index,
                        break_m,
                        lower,
                        upper,
                    });
                }
                chunk.raw_error[k] = worst;
                continue;
            }
            let coefficients = quintic(scaled(w[0], self.step_m), scaled(w[1], self.step_m));
            let worst = check(exact, x0, self.step_m, |h| {
                evaluate(&coefficients, (h - x0) * self.inv_step, self.inv_step)
            });
            if self.passes(worst, coefficients.iter()) {
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
            report.cut_cells += chunk.split.len();
            report.samples += 3 * chunk.split.len();
            for (k, (&(dn, dd), cell)) in chunk.raw_error.iter().zip(&chunk.cells).enumerate() {
                report.raw_max_abs_dn = report.raw_max_abs_dn.max(dn);
                report.raw_max_abs_ddndh_per_m = report.raw_max_abs_ddndh_per_m.max(dd);
                if cell[0].is_nan() && !chunk.split.iter().any(|cut| cut.index == k) {
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
        let chunk = self.chunk(i / CHUNK_CELLS, exact);
        let cell = &chunk.cells[i % CHUNK_CELLS];
        if cell[0].is_nan() {
            return Self::split_lookup(chunk, i % CHUNK_CELLS, height_m);
        }
        let (v, d) = evaluate(cell, u - i as f64, self.inv_step);
        Lookup::Value(v, d)
    }

    /// A cell with no single quintic: one of the chunk's cut cells, or exact.
    #[cold]
    fn split_lookup(chunk: &Chunk, index: usize, height_m: f64) -> Lookup {
        let Some(cut) = chunk.split.iter().find(|c| c.index == index) else {
            return Lookup::Exact;
        };
        let piece = if height_m < cut.break_m {
            &cut.lower
        } else {
            &cut.upper
        };
        let (v, d) = piece.evaluate(height_m);
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

    /// Every height of `heights` is interpolated (not exact) and within `bound` of `f` in n and
    /// dn/dh.
    fn assert_interpolates_within(
        grid: &HermiteGrid,
        f: &dyn Fn(f64) -> NodeResult<()>,
        heights: &[f64],
        bound: f64,
    ) {
        for &h in heights {
            let Lookup::Value(v, d) = grid.lookup(h, f) else {
                panic!("{h} is not interpolated")
            };
            let (ve, de) = f(h).unwrap();
            assert!(
                (v - ve).abs() < bound && (d - de).abs() < bound,
                "{h}: {v} {ve} {d} {de}"
            );
        }
    }

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

    /// A declared break inside a cell cuts it: both sides interpolate to the tolerance, where
    /// the same cell without the break evaluates the exact formula; two breaks in one cell do not
    /// cut it.
    #[test]
    fn a_declared_break_cuts_its_cell() {
        // dn/dh jumps at 10.3 and d²n/dh² is nonzero on both sides (a cubic each side).
        let f = |h: f64| -> NodeResult<()> {
            let x = h - 10.3;
            if x < 0.0 {
                Ok((1e-4 - 2e-8 * x + 1e-9 * x * x * x, -2e-8 + 3e-9 * x * x))
            } else {
                Ok((1e-4 - 5e-8 * x - 2e-9 * x * x, -5e-8 - 4e-9 * x))
            }
        };
        let grid = HermiteGrid::new(0.0, 1.0, 20, 1e-15, 1e-15).with_breaks(vec![10.3]);
        let heights = [10.0, 10.1, 10.299_999, 10.3, 10.300_001, 10.7, 10.999];
        assert_interpolates_within(&grid, &f, &heights, 1e-15);
        let err = grid.error(&f);
        assert_eq!((err.exact_cells, err.cut_cells), (0, 1), "{err:?}");
        assert!(err.max_abs_ddndh_per_m < 1e-15, "{err:?}");
        let unbroken = HermiteGrid::new(0.0, 1.0, 20, 1e-15, 1e-15);
        assert_eq!(unbroken.lookup(10.5, &f), Lookup::Exact);
        let two = HermiteGrid::new(0.0, 1.0, 20, 1e-15, 1e-15).with_breaks(vec![10.3, 10.6]);
        assert_eq!(two.lookup(10.5, &f), Lookup::Exact);
        let at_node = HermiteGrid::new(0.0, 1.0, 20, 1e-15, 1e-15).with_breaks(vec![10.0005]);
        assert_eq!(at_node.error(&f).cut_cells, 0);
    }

    /// Cuts at the edges of the layout: in a chunk's last cell, in the grid's last cell, and a
    /// declared break above the grid that changes nothing.
    #[test]
    fn breaks_cut_cells_at_chunk_and_grid_ends() {
        // dn/dh jumps at 63.4 (cell 63, the first chunk's last) and at 99.6 (cell 99, the
        // grid's last); a cubic between.
        let f = |h: f64| -> NodeResult<()> {
            let kink = |x: f64, k: f64| if x >= 0.0 { (k * x, k) } else { (0.0, 0.0) };
            let (a, da) = kink(h - 63.4, -3e-8);
            let (b, db) = kink(h - 99.6, 5e-8);
            let x = h / 100.0;
            Ok((
                1e-4 - 2e-8 * h + 1e-9 * x * x * x + a + b,
                -2e-8 + 3e-11 * x * x + da + db,
            ))
        };
        let grid =
            HermiteGrid::new(0.0, 1.0, 100, 1e-15, 1e-15).with_breaks(vec![63.4, 99.6, 150.0]);
        let heights = [
            63.0, 63.399_999, 63.4, 63.400_001, 63.999, 64.0, 99.1, 99.6, 99.9, 100.0,
        ];
        assert_interpolates_within(&grid, &f, &heights, 1e-15);
        let err = grid.error(&f);
        assert_eq!((err.exact_cells, err.cut_cells), (0, 2), "{err:?}");
        assert_eq!(grid.lookup(100.5, &f), Lookup::Outside);
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
