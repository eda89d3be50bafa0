//! Stage 2 — fit: hydrostatic pressure. In: a virtual-temperature function T_v(h, P) and a
//! starting pressure. Out: ln P(h) on a grid, stored as a cubic Hermite whose slopes are the exact
//! hydrostatic d(ln P)/dh = −g₀/(R_d·T_v) at every node, so P(h) and dP/dh = P·d(ln P)/dh are
//! smooth and consistent with each other (what the ray tracer needs).
//!
//! Heights are treated as geopotential with constant standard gravity g₀ (radiosonde heights are
//! geopotential in most formats; the difference to geometric height is below 0.3 % of dP/dh under
//! 20 km). Integration is classical Runge–Kutta (4th order) in ln P; for dry air it reduces to
//! Simpson's rule. Written by hand: a fixed-step RK4 of one scalar equation is a dozen lines, and
//! the Hermite storage reuses the `splines`-based cubic of `monotone.rs`.

use std::sync::{Arc, OnceLock};

use super::monotone::{KnotIndex, MonotoneCubic};
use crate::units::{DRY_AIR_GAS_CONSTANT_J_KG_K, STANDARD_GRAVITY_M_S2};

/// g₀ / R_d (K m⁻¹).
pub(crate) const G_OVER_R: f64 = STANDARD_GRAVITY_M_S2 / DRY_AIR_GAS_CONSTANT_J_KG_K;

/// Virtual temperature (K) of moist air, T / (1 − (e/P)(1 − ε)) (the ingest stage's formula,
/// [`crate::sounding::hypsometric::virtual_temperature_k`]), with `e` clamped to [0, P/2] so a bad
/// input can never divide by zero.
pub(crate) fn virtual_temperature_k(
    temperature_k: f64,
    vapour_pressure_pa: f64,
    pressure_pa: f64,
) -> f64 {
    if pressure_pa.is_nan() || pressure_pa <= 0.0 {
        return temperature_k;
    }
    let e = vapour_pressure_pa.clamp(0.0, 0.5 * pressure_pa);
    crate::sounding::hypsometric::virtual_temperature_k(temperature_k, Some(e), pressure_pa)
}

/// ln P at `h_to` from ln P at `h_from` by RK4 with steps no longer than `max_step_m` (either
/// direction). `tv(h, p)` gives the virtual temperature.
pub(crate) fn integrate_ln_p(
    h_from: f64,
    ln_p_from: f64,
    h_to: f64,
    max_step_m: f64,
    tv: &dyn Fn(f64, f64) -> f64,
) -> f64 {
    let slope = |h: f64, lnp: f64| -G_OVER_R / tv(h, lnp.exp());
    rk4_ln_p(h_from, ln_p_from, h_to, max_step_m, &slope, false)
}

/// [`integrate_ln_p`] given the slope d(ln P)/dh as a function of (h, ln P) directly (dry air
/// needs no pressure, so no `exp` per evaluation; the same values bit for bit). With
/// `pressure_free` (the slope does not depend on ln P) the two mid-step stages, which then
/// evaluate it at the same height, share one evaluation.
fn rk4_ln_p(
    h_from: f64,
    ln_p_from: f64,
    h_to: f64,
    max_step_m: f64,
    f: &dyn Fn(f64, f64) -> f64,
    pressure_free: bool,
) -> f64 {
    let span = h_to - h_from;
    if span == 0.0 || !span.is_finite() {
        return ln_p_from;
    }
    let steps = (span.abs() / max_step_m).ceil().max(1.0) as usize;
    let dh = span / steps as f64;
    let mut lnp = ln_p_from;
    for i in 0..steps {
        let h = h_from + dh * i as f64;
        let k1 = f(h, lnp);
        let k2 = f(h + 0.5 * dh, lnp + 0.5 * dh * k1);
        let k3 = if pressure_free {
            k2
        } else {
            f(h + 0.5 * dh, lnp + 0.5 * dh * k2)
        };
        let k4 = f(h + dh, lnp + dh * k3);
        lnp += dh / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
    lnp
}

/// ln P(h) on a grid from a start height upward, Hermite-interpolated with exact slopes. The
/// grid is integrated in chunks of [`CHUNK_NODES`] nodes, either all at once
/// ([`integrate`](Self::integrate)) or each when a lookup first needs it
/// ([`lazy`](Self::lazy)): the column above a sounding runs to 86 km, and a scene traced to a
/// 40 km top never reads most of it. Both give the same values bit for bit (the same steps in
/// the same order, the same Hermite segments).
#[derive(Clone)]
pub(crate) struct HydrostaticTable {
    /// The node heights.
    nodes: KnotIndex,
    /// ln P at the first node.
    ln_p0: f64,
    /// The virtual temperature, kept for chunks not integrated yet (`None`: all are).
    tv: Option<VirtualTemperature>,
    chunks: Vec<OnceLock<Chunk>>,
}

/// A virtual-temperature function T_v(h, P) a lazy table keeps.
pub(crate) type VirtualTemperature = Arc<dyn Fn(f64, f64) -> f64 + Send + Sync>;

/// Nodes (segments) per chunk.
const CHUNK_NODES: usize = 128;

/// One chunk: the Hermite over its nodes (its last node is the next chunk's first).
#[derive(Debug, Clone)]
struct Chunk {
    curve: MonotoneCubic,
    last_ln_p: f64,
}

impl std::fmt::Debug for HydrostaticTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let built = self.chunks.iter().filter(|c| c.get().is_some()).count();
        f.debug_struct("HydrostaticTable")
            .field("nodes", &self.nodes.knots_m().len())
            .field("chunks", &self.chunks.len())
            .field("integrated", &built)
            .finish()
    }
}

/// The node heights from `h0` to `h_end` for `grid` (see [`HydrostaticTable::integrate`]).
fn grid_heights(h0: f64, h_end: f64, grid: &[(f64, f64)]) -> Vec<f64> {
    let mut heights = vec![h0];
    let mut h = h0;
    for (i, &(up_to, step)) in grid.iter().enumerate() {
        let stop = if i + 1 == grid.len() {
            h_end
        } else {
            up_to.min(h_end)
        };
        let base = h;
        let mut k = 1.0;
        // Regular nodes, leaving a last interval between 0.5 and 1.5 steps.
        while stop - h > 1.5 * step {
            h = base + k * step;
            k += 1.0;
            heights.push(h);
        }
        if stop > h {
            h = stop;
            heights.push(h);
        }
    }
    if heights.len() < 2 {
        heights.push(h0 + grid.last().map_or(1.0, |g| g.1));
    }
    heights
}

/// `grid` (as [`HydrostaticTable::integrate`] takes it) with each height of `nodes` made a node:
/// a pair is cut in two there, so no RK4 step and no Hermite segment straddles a height where
/// the temperature's slope jumps (the US 1976 layer bases above a sounding).
pub(crate) fn grid_with_nodes(grid: &[(f64, f64)], nodes: &[f64]) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(grid.len() + nodes.len());
    let mut below = f64::NEG_INFINITY;
    for &(up_to, step) in grid {
        let mut inside: Vec<f64> = nodes
            .iter()
            .copied()
            .filter(|&h| h > below && h < up_to)
            .collect();
        inside.sort_by(f64::total_cmp);
        out.extend(inside.into_iter().map(|h| (h, step)));
        out.push((up_to, step));
        below = up_to;
    }
    out
}

impl HydrostaticTable {
    /// Integrate upward from `(h0, p0)` to `h_end`. `grid` lists `(up_to_m, step_m)` pairs in
    /// increasing order: nodes are `step_m` apart until `up_to_m`, then the next pair applies
    /// (the last step continues to `h_end`). `tv(h, p)` is the virtual temperature.
    pub(crate) fn integrate(
        h0: f64,
        p0: f64,
        h_end: f64,
        grid: &[(f64, f64)],
        tv: &dyn Fn(f64, f64) -> f64,
    ) -> Self {
        Self::integrate_slope(
            h0,
            p0,
            h_end,
            grid,
            &|h, lnp| -G_OVER_R / tv(h, lnp.exp()),
            false,
        )
    }

    /// [`integrate`](Self::integrate) for dry air, whose virtual temperature is the temperature
    /// `t(h)` whatever the pressure: the same table bit for bit as `integrate` with
    /// `|h, _| t(h)`, without an `exp` per evaluation.
    pub(crate) fn integrate_dry(
        h0: f64,
        p0: f64,
        h_end: f64,
        grid: &[(f64, f64)],
        t: &dyn Fn(f64) -> f64,
    ) -> Self {
        Self::integrate_slope(h0, p0, h_end, grid, &|h, _| -G_OVER_R / t(h), true)
    }

    /// [`integrate`](Self::integrate) with the slope d(ln P)/dh given as a function of
    /// (h, ln P) (`pressure_free`: of h alone; see [`rk4_ln_p`]).
    fn integrate_slope(
        h0: f64,
        p0: f64,
        h_end: f64,
        grid: &[(f64, f64)],
        slope: &dyn Fn(f64, f64) -> f64,
        pressure_free: bool,
    ) -> Self {
        let table = Self::unintegrated(h0, p0, h_end, grid, None);
        let mut ln_p = table.ln_p0;
        for (k, cell) in table.chunks.iter().enumerate() {
            let chunk = table.build(k, ln_p, slope, pressure_free);
            ln_p = chunk.last_ln_p;
            let _ = cell.set(chunk);
        }
        table
    }

    /// As [`integrate`](Self::integrate), each chunk integrated when a lookup first reaches it.
    pub(crate) fn lazy(
        h0: f64,
        p0: f64,
        h_end: f64,
        grid: &[(f64, f64)],
        tv: VirtualTemperature,
    ) -> Self {
        Self::unintegrated(h0, p0, h_end, grid, Some(tv))
    }

    fn unintegrated(
        h0: f64,
        p0: f64,
        h_end: f64,
        grid: &[(f64, f64)],
        tv: Option<VirtualTemperature>,
    ) -> Self {
        let heights = grid_heights(h0, h_end, grid);
        let segments = heights.len() - 1;
        HydrostaticTable {
            nodes: KnotIndex::new(&heights),
            ln_p0: p0.ln(),
            tv,
            chunks: (0..segments.div_ceil(CHUNK_NODES))
                .map(|_| OnceLock::new())
                .collect(),
        }
    }

    /// Chunk `k` from ln P `start` at its first node; `slope(h, ln P)` is d(ln P)/dh
    /// (`pressure_free`: it does not depend on ln P).
    fn build(
        &self,
        k: usize,
        start: f64,
        slope: &dyn Fn(f64, f64) -> f64,
        pressure_free: bool,
    ) -> Chunk {
        let all = self.nodes.knots_m();
        let heights = &all[k * CHUNK_NODES..=((k + 1) * CHUNK_NODES).min(all.len() - 1)];
        let mut ln_p = Vec::with_capacity(heights.len());
        let mut slopes = Vec::with_capacity(heights.len());
        let mut current = start;
        for (i, &hh) in heights.iter().enumerate() {
            if i > 0 {
                let prev = heights[i - 1];
                // Two RK4 sub-steps per node interval.
                current = rk4_ln_p(prev, current, hh, 0.5 * (hh - prev), slope, pressure_free);
            }
            ln_p.push(current);
            slopes.push(slope(hh, current));
        }
        Chunk {
            curve: MonotoneCubic::with_slopes(heights, &ln_p, &slopes),
            last_ln_p: current,
        }
    }

    /// Chunk `k`, integrated now (with those below it) if no lookup has needed it yet.
    fn chunk(&self, k: usize) -> &Chunk {
        if let Some(chunk) = self.chunks[k].get() {
            return chunk;
        }
        let start = if k == 0 {
            self.ln_p0
        } else {
            self.chunk(k - 1).last_ln_p
        };
        self.chunks[k].get_or_init(|| {
            let tv = self.tv.as_deref().expect("an eager table has every chunk");
            self.build(k, start, &|h, lnp| -G_OVER_R / tv(h, lnp.exp()), false)
        })
    }

    /// ln P and d(ln P)/dh at `h` (held at the table's ends outside it).
    pub(crate) fn ln_p_and_slope(&self, h: f64) -> (f64, f64) {
        if h.is_nan() {
            return (f64::NAN, f64::NAN);
        }
        self.chunk(self.nodes.segment(h) / CHUNK_NODES)
            .curve
            .value_slope(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_dry_table_is_the_moist_table_at_zero_humidity_bit_for_bit() {
        // A temperature with a sharp step layer (tanh) over a lapse rate; the moist form at
        // e = 0 (T_v = T / (1 − 0)) against the dry form, which never needs the pressure.
        let t = |h: f64| 270.0 - 0.0065 * h + 3.0 * (1.0 + ((h - 120.0) / 4.0).tanh());
        let grid = [(2_000.0, 0.25), (f64::INFINITY, 10.0)];
        let moist = HydrostaticTable::integrate(3.0, 101_000.0, 20_000.0, &grid, &|h, p| {
            virtual_temperature_k(t(h), 0.0, p)
        });
        let dry = HydrostaticTable::integrate_dry(3.0, 101_000.0, 20_000.0, &grid, &t);
        let mut h = 0.0;
        while h < 20_500.0 {
            let (a, b) = (moist.ln_p_and_slope(h), dry.ln_p_and_slope(h));
            assert_eq!(a.0.to_bits(), b.0.to_bits(), "ln P at {h}");
            assert_eq!(a.1.to_bits(), b.1.to_bits(), "slope at {h}");
            h += 0.37;
        }
    }

    #[test]
    fn tanh_is_exactly_one_beyond_22() {
        // The synthetic layers skip tanh there (synthetic.rs); the same values only if so.
        let mut x = 22.0f64;
        while x < 1e7 {
            assert_eq!(x.tanh(), 1.0, "{x}");
            assert_eq!((-x).tanh(), -1.0, "{x}");
            x = x * 1.001 + 1e-3;
        }
        assert_eq!(22.0f64.next_up().tanh(), 1.0);
    }

    #[test]
    fn isothermal_atmosphere_is_exponential() {
        // Analytic: P = P0·exp(−g h/(R T)) for constant T.
        let t = 250.0;
        let table = HydrostaticTable::integrate(
            0.0,
            100_000.0,
            20_000.0,
            &[(1000.0, 0.5), (f64::INFINITY, 10.0)],
            &|_, _| t,
        );
        for h in [0.0, 0.3, 999.9, 1000.0, 1234.5, 15_000.0, 20_000.0] {
            let (lnp, s) = table.ln_p_and_slope(h);
            let exact = 100_000f64.ln() - G_OVER_R * h / t;
            // Round-off only: ~4000 RK4 additions to ln P ≈ 11.5 (ulp 1.8e-15).
            assert!((lnp - exact).abs() < 1e-10, "{h}: {lnp} {exact}");
            assert!((s + G_OVER_R / t).abs() < 1e-12);
        }
    }

    #[test]
    fn constant_lapse_matches_the_closed_form() {
        // T = T0 + Γh  ⇒  P = P0 (T/T0)^(−g/(RΓ)).
        let (t0, lapse) = (288.15, -0.0065);
        let table = HydrostaticTable::integrate(
            0.0,
            101_325.0,
            11_000.0,
            &[(f64::INFINITY, 10.0)],
            &|h, _| t0 + lapse * h,
        );
        for h in [5.0, 1000.0, 5555.5, 11_000.0] {
            let p = table.ln_p_and_slope(h).0.exp();
            let exact = 101_325.0 * ((t0 + lapse * h) / t0).powf(-G_OVER_R / lapse);
            assert!((p / exact - 1.0).abs() < 1e-10, "{h}: {p} {exact}");
        }
    }

    /// The largest error, as an error in n and in dn/dh (m⁻¹), of `table` against a 0.5 m RK4
    /// integration of `tv` from `(h0, p0)`, every 10 m up to `h_end`. n − 1 ≤ 4.5e-4·P/P₀
    /// (Ciddor at T ≥ 190 K), so an error δ in ln P is at most 4.5e-4·(P/P₀)·δ in n.
    fn index_errors(
        table: &HydrostaticTable,
        (h0, p0, h_end): (f64, f64, f64),
        tv: &dyn Fn(f64, f64) -> f64,
    ) -> (f64, f64) {
        let (mut worst_n, mut worst_dndh) = (0.0f64, 0.0f64);
        let (mut h, mut ln_p) = (h0, p0.ln());
        while h + 10.0 < h_end {
            let to = h + 10.0 - if h == h0 { 3.73 } else { 0.0 };
            ln_p = integrate_ln_p(h, ln_p, to, 0.5, tv);
            h = to;
            let weight = 4.5e-4 * ln_p.exp() / 101_325.0;
            let (got, slope) = table.ln_p_and_slope(h);
            let exact_slope = -G_OVER_R / tv(h, ln_p.exp());
            worst_n = worst_n.max(weight * (got - ln_p).abs());
            worst_dndh = worst_dndh.max(weight * (slope - exact_slope).abs());
        }
        (worst_n, worst_dndh)
    }

    #[test]
    fn a_coarse_grid_with_the_kinks_as_nodes_stays_within_the_tables_bound() {
        // The column above a sounding: US 1976 with a decaying offset and a slope-matching bump
        // (the blend of fit.rs), from a 9 km top to 86 km, kinks at the layer bases. Its error
        // in n and dn/dh must stay below the n(h) table's default bound (1e-14), which a finer
        // grid whose steps straddle the kinks (the former 5 m / 20 m) misses.
        let top_m = 9_000.0;
        let tv = |h: f64, _p: f64| {
            let x = (h - top_m).max(0.0);
            let (t, _) = crate::profile::us1976::us1976_temperature(h);
            t + 4.0 * (-x / 2_000.0).exp() + 0.02 * x * (-x / 200.0).exp()
        };
        let span = (top_m, 30_000.0, 86_000.0);
        let kinks: Vec<f64> = crate::profile::us1976::layer_bases_geometric_m().collect();
        let grid = grid_with_nodes(&[(top_m + 3000.0, 10.0), (f64::INFINITY, 100.0)], &kinks);
        let table = HydrostaticTable::integrate(top_m, 30_000.0, 86_000.0, &grid, &tv);
        let (dn, ddndh) = index_errors(&table, span, &tv);
        assert!(
            dn < 1e-14 && ddndh < 1e-14,
            "with the kinks: {dn:e}, {ddndh:e}"
        );
        let straddling = [(top_m + 3000.0, 5.0), (f64::INFINITY, 20.0)];
        let old = HydrostaticTable::integrate(top_m, 30_000.0, 86_000.0, &straddling, &tv);
        let (dn, ddndh) = index_errors(&old, span, &tv);
        assert!(dn > 1e-14 && ddndh > 1e-14, "straddling: {dn:e}, {ddndh:e}");
    }

    #[test]
    fn hydrostatic_knots_need_no_finer_steps() {
        // One gap between two sounding levels 800 m apart holding a +12 K surface inversion
        // with curvature (a PCHIP-like cubic in height): the fit's step limit must match a
        // 0.5 m integration (itself within 2e-14 of the exact integral) to 1e-11 in ln P.
        let cubic = |h: f64| {
            let u = h / 800.0;
            255.0 + 12.0 * (3.0 * u * u - 2.0 * u * u * u) + 0.8 * u * (1.0 - u) * (0.5 - u)
        };
        let tv = |h: f64, _p: f64| cubic(h);
        let ln_p0 = 101_000f64.ln();
        let coarse = integrate_ln_p(
            0.0,
            ln_p0,
            800.0,
            crate::profile::fit::HYDROSTATIC_STEP_M,
            &tv,
        );
        let fine = integrate_ln_p(0.0, ln_p0, 800.0, 0.5, &tv);
        assert!((coarse - fine).abs() < 1e-11, "{:e}", coarse - fine);
        // Twice the step limit does not: the test can tell.
        let double = integrate_ln_p(
            0.0,
            ln_p0,
            800.0,
            2.0 * crate::profile::fit::HYDROSTATIC_STEP_M,
            &tv,
        );
        assert!((double - fine).abs() > 1e-11, "{:e}", double - fine);
    }

    #[test]
    fn virtual_temperature_is_warmer_for_moist_air() {
        let tv = virtual_temperature_k(280.0, 1000.0, 100_000.0);
        // T_v ≈ T(1 + 0.378 e/P) = 280·1.00378 = 281.06 (first order).
        assert!((tv - 281.06).abs() < 0.01, "{tv}");
        assert_eq!(virtual_temperature_k(280.0, 0.0, 100_000.0), 280.0);
    }
}
