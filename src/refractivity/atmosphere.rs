//! n(h) and dn/dh of a column of air, exact and tabulated.
//!
//! In: an [`AirColumn`] (T, P, e and their height derivatives by height above mean sea level), a
//! wavelength and a CO₂ content. Out: a [`RefractiveAtmosphere`], which gives n and dn/dh by height
//! above the **surface** — exactly (Ciddor through dual numbers, chain rule, no finite
//! differences) or through a fast table (the [`StratifiedIndex`] implementation the tracer uses).
//!
//! # Accuracy the table must reach, and why
//! A ray's curvature is −(dn/dh)·cos(elevation)/n. An error δ in dn/dh bends a nearly horizontal
//! ray off its path by about δ·L²/2 after a distance L. The tracer's goal is 1 cm over 30 km, so
//! δ ≤ 2·0.01 m / (3·10⁴ m)² ≈ 2·10⁻¹¹ m⁻¹ for an error of one sign along the whole path, and
//! tighter tolerances scale it down: the table's default tolerance is 1·10⁻¹⁴ m⁻¹ for dn/dh and
//! 1·10⁻¹⁴ for n (which does not bend rays but enters the Bouguer invariant; see [`TableSpec`]).
//! Cells whose measured error exceeds it — cells containing a kink of the profile, which a
//! polynomial cannot follow — are evaluated exactly.
//!
//! The table is built lazily, in chunks of cells, where the tracer's lookups land: a frame whose
//! rays stay in the lowest few hundred metres does not pay for the 40 km above. Construction
//! only checks that the air is valid on a 5 m grid over the table's range.

use std::sync::{Arc, OnceLock};

use rayon::prelude::*;

use super::RefractivityError;
use super::ciddor::{CiddorDispersion, DEFAULT_CO2_PPM};
use super::dual::Dual;
use super::table::{GridError, HermiteGrid, Lookup};
use crate::profile::{AirColumn, AirSample, FineZone};
use crate::tracer::{MinorBreak, ScanGrid, StratifiedIndex};

/// Lowest and highest wavelength (nm) the Ciddor formula is fitted for.
pub const WAVELENGTH_RANGE_NM: (f64, f64) = (300.0, 1700.0);
/// Default wavelength (nm): the middle of the visible, as in the paper.
pub const DEFAULT_WAVELENGTH_NM: f64 = 550.0;

/// Layout and tolerances of the lookup table.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TableSpec {
    /// Node spacing of the fine grid near the ground (m).
    pub fine_step_m: f64,
    /// Top of the fine grid (m above the surface); the layers that make mirages live below it.
    pub fine_top_agl_m: f64,
    /// Node spacing of the coarse grid above the fine one (m).
    pub coarse_step_m: f64,
    /// Top of the coarse grid (m above the surface); above it the exact formula is used.
    pub coarse_top_agl_m: f64,
    /// Largest |Δn| accepted in a cell before it falls back to exact evaluation.
    pub tolerance_n: f64,
    /// Largest |Δ(dn/dh)| (m⁻¹) accepted in a cell before it falls back to exact evaluation.
    pub tolerance_dndh_per_m: f64,
    /// Whether whole-column scans (Bouguer's envelope, the regime detector;
    /// [`RefractiveAtmosphere::scan_refractivity`]) read the table too. Off by default, so a
    /// scene builds table cells only where its rays go; on where the rays visit the whole column
    /// anyway (a survey's fan climbs out to the top), which makes the scan cheap table lookups
    /// instead of exact evaluations. The table's error must then stay far below the envelope's
    /// slack on the invariant (1e-10 relative; the tolerances here are absolute in n).
    pub scans_read_table: bool,
}

impl Default for TableSpec {
    /// 0.25 m up to 4 km above the surface, 5 m up to 40 km (the default top of the traced
    /// atmosphere: a frame builds no table it does not use; a trace to a higher top evaluates
    /// the exact formula above), tolerances 1e-14. Why 1e-14: an
    /// error δ in dn/dh bends a ray by δ per metre, which grows to ½·δ·x² in height after x
    /// metres; at 1e-14 that is 3.4 µm at 26 km and 0.2 mm at 200 km, below every tolerance the
    /// tracer offers at the paper's distances (the smooth cells of the quintic table are far
    /// better, ~1e-17; cells that miss the bound evaluate the exact formula).
    fn default() -> Self {
        Self {
            fine_step_m: 0.25,
            fine_top_agl_m: 4_000.0,
            coarse_step_m: 5.0,
            coarse_top_agl_m: 40_000.0,
            tolerance_n: 1e-14,
            tolerance_dndh_per_m: 1e-14,
            scans_read_table: false,
        }
    }
}

/// Measured accuracy of the lookup table (see [`GridError`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TableError {
    /// The fine grid near the ground.
    pub fine: GridError,
    /// The coarse grid above.
    pub coarse: GridError,
}

impl TableError {
    /// Largest |Δn| the table returns at any check point.
    pub fn max_abs_dn(&self) -> f64 {
        self.fine.max_abs_dn.max(self.coarse.max_abs_dn)
    }
    /// Largest |Δ(dn/dh)| (m⁻¹) the table returns at any check point.
    pub fn max_abs_ddndh_per_m(&self) -> f64 {
        self.fine
            .max_abs_ddndh_per_m
            .max(self.coarse.max_abs_ddndh_per_m)
    }
    /// Number of cells that evaluate the exact formula.
    pub fn exact_cells(&self) -> usize {
        self.fine.exact_cells + self.coarse.exact_cells
    }
}

/// The state at one height: air, n − 1 and dn/dh (exact).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefractiveSample {
    /// Height above mean sea level (m).
    pub height_m: f64,
    /// The air there.
    pub air: AirSample,
    /// n − 1.
    pub n_minus_1: f64,
    /// dn/dh (m⁻¹).
    pub dn_dh_per_m: f64,
}

/// A horizontally stratified refractive atmosphere built on an air column.
///
/// Heights are **above the surface** (the column's `surface_height_m`). Heights below the surface
/// are clamped to it (the tracer stops rays at h = 0 anyway). A NaN (or +∞) height returns
/// (NaN, NaN) without panicking and without consulting the column, so the tracer can detect it
/// and terminate the ray.
///
/// The table (see [`TableSpec`]): 0.25 m cells up to 4 km above the surface, 5 m cells up to
/// 40 km, exact above; each cell a quintic Hermite through the exact (n − 1, dn/dh, d²n/dh²) at
/// its ends (C², so the ray equation stays smooth across nodes). When a cell is first built (on
/// the first lookup in its chunk) it is checked against the exact formula at three points;
/// cells off by more than the spec's tolerances (1e-14 in n and in dn/dh per metre) evaluate
/// the exact formula instead. The measured errors are in
/// [`table_max_error`](Self::table_max_error).
///
/// The column's breaks are split into those where dn/dh jumps (see
/// [`breaks_m`](StratifiedIndex::breaks_m)) and the minor ones where only d²n/dh² does, with
/// the sizes of its jumps of d²n/dh² and d³n/dh³ (see
/// [`minor_breaks`](StratifiedIndex::minor_breaks)), so the tracer
/// ends its steps only where that matters at its tolerance.
pub struct RefractiveAtmosphere {
    column: Arc<dyn AirColumn>,
    surface_m: f64,
    wavelength_nm: f64,
    dispersion: CiddorDispersion,
    spec: TableSpec,
    fine: HermiteGrid,
    coarse: HermiteGrid,
    /// The table's measured error, found when first asked for (it builds every cell).
    error: OnceLock<TableError>,
    /// The column's breaks where dn/dh jumps, as heights above the surface (m).
    breaks_agl_m: Vec<f64>,
    /// The column's breaks where dn/dh is continuous (d²n/dh² or d³n/dh³ jumps).
    minor_breaks: Vec<MinorBreak>,
    /// The column's fine zones, as heights above the surface (m).
    fine_zones: Vec<FineZone>,
}

impl std::fmt::Debug for RefractiveAtmosphere {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RefractiveAtmosphere")
            .field("surface_m", &self.surface_m)
            .field("wavelength_nm", &self.wavelength_nm)
            .field("co2_ppm", &self.dispersion.co2_ppm)
            .field("spec", &self.spec)
            .field("error", &self.error.get())
            .finish_non_exhaustive()
    }
}

impl RefractiveAtmosphere {
    /// Build the atmosphere at `wavelength_nm` (300–1700 nm) with 450 ppm CO₂ and the default
    /// table; fails on a wavelength out of range or on air the formula cannot take (non-finite,
    /// T ≤ 0, P ≤ 0, e < 0 or e ≥ P) at any point of a grid of the coarse table step
    /// (5 m by default) over the table's range. The table itself is built lazily.
    pub fn new(column: Arc<dyn AirColumn>, wavelength_nm: f64) -> Result<Self, RefractivityError> {
        Self::build(column, wavelength_nm, DEFAULT_CO2_PPM, TableSpec::default())
    }

    /// As [`new`](Self::new) with the table layout `spec` (validated once, on its grid).
    pub fn with_spec(
        column: Arc<dyn AirColumn>,
        wavelength_nm: f64,
        spec: TableSpec,
    ) -> Result<Self, RefractivityError> {
        Self::build(column, wavelength_nm, DEFAULT_CO2_PPM, spec)
    }

    /// The same atmosphere with another CO₂ content (ppm, 0–10 000); rebuilds the table.
    pub fn with_co2_ppm(self, co2_ppm: f64) -> Result<Self, RefractivityError> {
        Self::build(self.column, self.wavelength_nm, co2_ppm, self.spec)
    }

    /// The same air column, CO₂ content and table layout at another wavelength (nm, 300–1700):
    /// what a spectral render traces each band through (the table is built lazily again).
    pub fn at_wavelength_nm(&self, wavelength_nm: f64) -> Result<Self, RefractivityError> {
        Self::build(
            Arc::clone(&self.column),
            wavelength_nm,
            self.dispersion.co2_ppm,
            self.spec,
        )
    }

    /// The same atmosphere with another table layout; rebuilds the table.
    pub fn with_table_spec(self, spec: TableSpec) -> Result<Self, RefractivityError> {
        Self::build(
            self.column,
            self.wavelength_nm,
            self.dispersion.co2_ppm,
            spec,
        )
    }

    fn build(
        column: Arc<dyn AirColumn>,
        wavelength_nm: f64,
        co2_ppm: f64,
        spec: TableSpec,
    ) -> Result<Self, RefractivityError> {
        let (lo, hi) = WAVELENGTH_RANGE_NM;
        if !(lo..=hi).contains(&wavelength_nm) {
            return Err(RefractivityError::WavelengthOutOfRange { wavelength_nm });
        }
        if !(0.0..=10_000.0).contains(&co2_ppm) {
            return Err(RefractivityError::InvalidCo2 { co2_ppm });
        }
        let spec_ok = spec.fine_step_m > 0.0
            && spec.coarse_step_m > 0.0
            && spec.fine_top_agl_m >= spec.fine_step_m
            && spec.coarse_top_agl_m >= spec.fine_top_agl_m + spec.coarse_step_m
            && spec.tolerance_n >= 0.0
            && spec.tolerance_dndh_per_m >= 0.0
            && (spec.fine_top_agl_m / spec.fine_step_m) < 1e8
            && ((spec.coarse_top_agl_m - spec.fine_top_agl_m) / spec.coarse_step_m) < 1e8;
        if !spec_ok {
            return Err(RefractivityError::InvalidTableSpec(format!("{spec:?}")));
        }
        let surface_m = column.surface_height_m();
        if !surface_m.is_finite() {
            return Err(RefractivityError::NonFinite {
                height_m: surface_m,
            });
        }
        let dispersion = CiddorDispersion::new(wavelength_nm * 1e-9, co2_ppm);
        let exact = |h_agl: f64| -> Result<(f64, f64), RefractivityError> {
            let s = checked_sample(&*column, &dispersion, surface_m + h_agl)?;
            Ok((s.n_minus_1, s.dn_dh_per_m))
        };
        validate_column(&exact, spec.coarse_step_m, spec.coarse_top_agl_m)?;
        let (breaks_agl_m, minor_breaks) = split_breaks(column.breaks_m(), surface_m, &exact)?;
        let mut cuts: Vec<f64> = breaks_agl_m.clone();
        cuts.extend(minor_breaks.iter().map(|b| b.height_m));
        let fine_cells = (spec.fine_top_agl_m / spec.fine_step_m).round() as usize;
        let fine_top = fine_cells as f64 * spec.fine_step_m;
        let fine = HermiteGrid::new(
            0.0,
            spec.fine_step_m,
            fine_cells,
            spec.tolerance_n,
            spec.tolerance_dndh_per_m,
        )
        .with_breaks(cuts.clone());
        let coarse_cells =
            ((spec.coarse_top_agl_m - fine_top) / spec.coarse_step_m).round() as usize;
        let coarse = HermiteGrid::new(
            fine_top,
            spec.coarse_step_m,
            coarse_cells,
            spec.tolerance_n,
            spec.tolerance_dndh_per_m,
        )
        .with_breaks(cuts);
        Ok(Self {
            surface_m,
            wavelength_nm,
            dispersion,
            spec,
            fine,
            coarse,
            error: OnceLock::new(),
            breaks_agl_m,
            minor_breaks,
            fine_zones: column
                .fine_zones_m()
                .into_iter()
                .map(|z| z.lowered(surface_m))
                .collect(),
            column,
        })
    }

    /// Height of the surface above mean sea level (m); table heights are measured from it.
    pub fn surface_height_m(&self) -> f64 {
        self.surface_m
    }

    /// Vacuum wavelength (nm).
    pub fn wavelength_nm(&self) -> f64 {
        self.wavelength_nm
    }

    /// CO₂ content (ppm).
    pub fn co2_ppm(&self) -> f64 {
        self.dispersion.co2_ppm
    }

    /// The air column this atmosphere was built on.
    pub fn column(&self) -> &Arc<dyn AirColumn> {
        &self.column
    }

    /// The table layout in use.
    pub fn table_spec(&self) -> TableSpec {
        self.spec
    }

    /// The Ciddor dispersion terms in use.
    pub fn dispersion(&self) -> &CiddorDispersion {
        &self.dispersion
    }

    /// n and dn/dh (m⁻¹) at `height_agl_m` above the surface, evaluated directly: the Ciddor
    /// formula over dual numbers seeded with (T, dT/dh), (P, dP/dh), (e, de/dh). Below the surface
    /// the surface value is returned; NaN gives (NaN, NaN).
    pub fn exact(&self, height_agl_m: f64) -> (f64, f64) {
        let (nm1, d) = self.exact_refractivity(height_agl_m);
        (1.0 + nm1, d)
    }

    /// Like [`exact`](Self::exact) but returns n − 1 (more significant digits).
    pub fn exact_refractivity(&self, height_agl_m: f64) -> (f64, f64) {
        if height_agl_m.is_nan() || height_agl_m == f64::INFINITY {
            return (f64::NAN, f64::NAN);
        }
        let s = self.sample_at(self.surface_m + height_agl_m.max(0.0));
        (s.n_minus_1, s.dn_dh_per_m)
    }

    /// The air, n − 1 and dn/dh (exact) at `height_m` above **mean sea level** (clamped to the
    /// surface). Invalid air is not checked here; the constructor has checked the table's range
    /// on its coarse grid.
    /// A NaN or +∞ height gives a NaN sample without consulting the column.
    pub fn sample_at(&self, height_m: f64) -> RefractiveSample {
        if height_m.is_nan() || height_m == f64::INFINITY {
            let nan = f64::NAN;
            return RefractiveSample {
                height_m: nan,
                air: AirSample {
                    temperature_k: nan,
                    dtemperature_dh_k_per_m: nan,
                    pressure_pa: nan,
                    dpressure_dh_pa_per_m: nan,
                    vapour_pressure_pa: nan,
                    dvapour_pressure_dh_pa_per_m: nan,
                },
                n_minus_1: nan,
                dn_dh_per_m: nan,
            };
        }
        let h = if height_m < self.surface_m {
            self.surface_m
        } else {
            height_m
        };
        let air = self.column.air_at(h);
        let r = refractivity(&self.dispersion, &air);
        RefractiveSample {
            height_m: h,
            air,
            n_minus_1: r.value,
            dn_dh_per_m: r.deriv,
        }
    }

    /// The measured maximum error of the lookup table against [`exact`](Self::exact), found by
    /// sampling each cell at its quarter, mid and three-quarter points. The table is built
    /// lazily, where lookups need it; this builds all of it (once).
    pub fn table_max_error(&self) -> TableError {
        *self.error.get_or_init(|| {
            let exact = |h| self.checked_refractivity(h);
            TableError {
                fine: self.fine.error(&exact),
                coarse: self.coarse.error(&exact),
            }
        })
    }

    /// (table cells built so far, table cells in all): the table is built where lookups land,
    /// so a frame whose rays stay low builds only the cells it passes through.
    pub fn table_cells_built(&self) -> (usize, usize) {
        let (fine, fine_all) = self.fine.built_cells();
        let (coarse, coarse_all) = self.coarse.built_cells();
        (fine + coarse, fine_all + coarse_all)
    }

    /// (n − 1, dn/dh) at `height_agl_m`, or why the air there is invalid: what builds a
    /// table cell.
    fn checked_refractivity(&self, height_agl_m: f64) -> Result<(f64, f64), RefractivityError> {
        let s = checked_sample(
            &*self.column,
            &self.dispersion,
            self.surface_m + height_agl_m,
        )?;
        Ok((s.n_minus_1, s.dn_dh_per_m))
    }

    /// n − 1 and dn/dh (m⁻¹) at `height_agl_m` for a scan of the whole column (Bouguer's
    /// envelope, the regime detector): exact, so that a scan fills no table cell, or from the
    /// table where the spec says [`scans_read_table`](TableSpec::scans_read_table).
    pub fn scan_refractivity(&self, height_agl_m: f64) -> (f64, f64) {
        if self.spec.scans_read_table {
            self.table_refractivity(height_agl_m)
        } else {
            self.exact_refractivity(height_agl_m)
        }
    }

    /// n − 1 and dn/dh (m⁻¹) from the table (what [`StratifiedIndex`] returns, minus the 1).
    #[inline]
    pub fn table_refractivity(&self, height_agl_m: f64) -> (f64, f64) {
        if height_agl_m.is_nan() || height_agl_m == f64::INFINITY {
            return (f64::NAN, f64::NAN);
        }
        let h = height_agl_m.max(0.0);
        let grid = if h < self.fine.end_m() {
            &self.fine
        } else {
            &self.coarse
        };
        match grid.lookup(h, &|h| self.checked_refractivity(h)) {
            Lookup::Value(v, d) => (v, d),
            Lookup::Exact | Lookup::Outside => self.exact_refractivity(h),
        }
    }
}

impl StratifiedIndex for RefractiveAtmosphere {
    /// n and dn/dh at `height_m` above the surface, from the fast table (exact above its top and
    /// in cells that failed the accuracy check). Clamped below the surface; NaN in → NaN out.
    #[inline]
    fn index_and_derivative(&self, height_m: f64) -> (f64, f64) {
        let (nm1, d) = self.table_refractivity(height_m);
        (1.0 + nm1, d)
    }

    /// n and dn/dh from the exact formula (no table cell is built; see
    /// [`StratifiedIndex::scan_index_and_derivative`]), or from the table when the spec says
    /// [`scans_read_table`](TableSpec::scans_read_table).
    fn scan_index_and_derivative(&self, height_m: f64) -> (f64, f64) {
        let (nm1, d) = self.scan_refractivity(height_m);
        (1.0 + nm1, d)
    }

    /// The table's node spacing, breaks added, where scans read the table
    /// ([`TableSpec::scans_read_table`]): a lookup at a node returns the exact value stored
    /// there, and between nodes the table is one quintic (a cell, or a piece of a cut cell), so
    /// the cells are polynomial ([`ScanGrid::polynomial_cells`]; a cell that evaluates the
    /// exact formula is smooth between the breaks, which are nodes, and its seven samples are
    /// those of a function far closer to its degree-6 interpolant than the envelope's slack).
    /// Otherwise [`ScanGrid::DEFAULT`].
    fn scan_grid(&self) -> ScanGrid {
        if self.spec.scans_read_table {
            ScanGrid {
                fine_step_m: self.spec.fine_step_m,
                fine_top_m: self.spec.fine_top_agl_m,
                coarse_step_m: self.spec.coarse_step_m,
                with_breaks: true,
                polynomial_cells: true,
            }
        } else {
            ScanGrid::DEFAULT
        }
    }

    /// The air column's breaks (heights above the surface; see
    /// [`AirColumn::breaks_m`](crate::profile::AirColumn::breaks_m)).
    fn breaks_m(&self) -> &[f64] {
        &self.breaks_agl_m
    }

    /// The column's breaks where dn/dh is continuous, with their jumps of d²n/dh² and d³n/dh³.
    fn minor_breaks(&self) -> &[MinorBreak] {
        &self.minor_breaks
    }

    /// The air column's fine zones (heights above the surface; see
    /// [`AirColumn::fine_zones_m`](crate::profile::AirColumn::fine_zones_m)).
    fn fine_zones(&self) -> &[FineZone] {
        &self.fine_zones
    }
}

/// Check, before any table cell is built, that the air is valid every `step_m` from the
/// surface to `top_m` (and at the top). Air that is invalid only between two of these points is
/// met later, when a table cell over it is built: that cell falls back to the exact formula,
/// and a ray that meets a non-finite value there ends as non-finite. In height order, so the
/// error names the lowest invalid height.
fn validate_column(
    exact: &(dyn Fn(f64) -> Result<(f64, f64), RefractivityError> + Sync),
    step_m: f64,
    top_m: f64,
) -> Result<(), RefractivityError> {
    let steps = (top_m / step_m).ceil() as usize;
    // In parallel; the error reported is the lowest height's, whatever the thread count.
    let first_bad = (0..=steps)
        .into_par_iter()
        .filter_map(|i| exact((i as f64 * step_m).min(top_m)).err().map(|e| (i, e)))
        .min_by_key(|(i, _)| *i);
    match first_bad {
        Some((_, e)) => Err(e),
        None => Ok(()),
    }
}

/// Half-width (m) of the differences that measure a break's jumps.
const BREAK_PROBE_M: f64 = 1e-3;
/// A break whose dn/dh jumps by more than this (m⁻¹) is a break the tracer always honours;
/// below it, dn/dh is continuous to the precision of the one-sided differences and the level
/// is a minor break, described by its jumps of d²n/dh² and d³n/dh³.
const BREAK_MIN_SLOPE_JUMP_PER_M: f64 = 1e-15;

/// The column's breaks (m above mean sea level) as heights above the surface, split into those
/// where dn/dh jumps and the minor ones where only d²n/dh² or d³n/dh³ does, with those jumps
/// (one-sided first and second differences of the exact dn/dh). Levels where nothing jumps
/// are dropped.
fn split_breaks(
    breaks_msl_m: Vec<f64>,
    surface_m: f64,
    exact: &dyn Fn(f64) -> Result<(f64, f64), RefractivityError>,
) -> Result<(Vec<f64>, Vec<MinorBreak>), RefractivityError> {
    let d = BREAK_PROBE_M;
    let mut major = Vec::new();
    let mut minor = Vec::new();
    for b in crate::profile::normalise_breaks(breaks_msl_m) {
        let h = b - surface_m;
        if h <= 3.0 * d {
            continue;
        }
        let slope = |x: f64| exact(x).map(|v| v.1);
        let (m3, m2, m1) = (slope(h - 3.0 * d)?, slope(h - 2.0 * d)?, slope(h - d)?);
        let (p1, p2, p3) = (slope(h + d)?, slope(h + 2.0 * d)?, slope(h + 3.0 * d)?);
        let slope_jump = ((2.0 * p1 - p2) - (2.0 * m1 - m2)).abs();
        let curvature_jump = ((p2 - p1) - (m1 - m2)).abs() / d;
        let curvature_kink = ((p3 - 2.0 * p2 + p1) - (m1 - 2.0 * m2 + m3)).abs() / (d * d);
        if slope_jump > BREAK_MIN_SLOPE_JUMP_PER_M {
            major.push(h);
        } else if curvature_jump > 0.0 || curvature_kink > 0.0 {
            minor.push(MinorBreak {
                height_m: h,
                curvature_jump_per_m2: curvature_jump,
                curvature_kink_per_m3: curvature_kink,
            });
        }
    }
    Ok((major, minor))
}

/// Ciddor n − 1 as a dual in height.
#[inline]
fn refractivity(dispersion: &CiddorDispersion, air: &AirSample) -> Dual {
    dispersion.refractivity(
        Dual::new(air.temperature_k, air.dtemperature_dh_k_per_m),
        Dual::new(air.pressure_pa, air.dpressure_dh_pa_per_m),
        Dual::new(air.vapour_pressure_pa, air.dvapour_pressure_dh_pa_per_m),
    )
}

/// Sample with validation of the air (used to build the table).
fn checked_sample(
    column: &dyn AirColumn,
    dispersion: &CiddorDispersion,
    height_m: f64,
) -> Result<RefractiveSample, RefractivityError> {
    let air = column.air_at(height_m);
    let finite = [
        air.temperature_k,
        air.dtemperature_dh_k_per_m,
        air.pressure_pa,
        air.dpressure_dh_pa_per_m,
        air.vapour_pressure_pa,
        air.dvapour_pressure_dh_pa_per_m,
    ]
    .iter()
    .all(|v| v.is_finite());
    if !finite
        || air.temperature_k <= 0.0
        || air.pressure_pa <= 0.0
        || air.vapour_pressure_pa < 0.0
        || air.vapour_pressure_pa >= air.pressure_pa
    {
        return Err(RefractivityError::InvalidAir {
            height_m,
            temperature_k: air.temperature_k,
            pressure_pa: air.pressure_pa,
            vapour_pressure_pa: air.vapour_pressure_pa,
        });
    }
    let r = refractivity(dispersion, &air);
    if !r.value.is_finite() || !r.deriv.is_finite() {
        return Err(RefractivityError::NonFinite { height_m });
    }
    Ok(RefractiveSample {
        height_m,
        air,
        n_minus_1: r.value,
        dn_dh_per_m: r.deriv,
    })
}
