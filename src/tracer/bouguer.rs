//! Stage 4 (trace), the fate of a ray from Bouguer's invariant. In a spherically stratified
//! field c = n·r·cos ψ is constant along a ray, and the ray can be at radius r only where
//! g(r) = n(r)·r ≥ c. So whether a ray turns, escapes through the top or meets the ground is
//! decided by the profile g(h) alone: a climbing ray turns below the first height above it where
//! g falls to c, and escapes if there is none; a descending ray likewise turns or meets the
//! ground. A ray with a turning point on both sides oscillates between them for ever: trapped.
//!
//! In: a [`StratifiedIndex`] and the Earth radius. Out: a [`BouguerEnvelope`] — g on the
//! index's [`ScanGrid`](super::ScanGrid) (by default 0.25 m to 4 km above the surface, 5 m
//! above; a sounding surveyed through its table: the table's nodes and every break) with running
//! minima from the ground up and from the top down, and a lower bound of g between nodes — and
//! [`Fate`] queries. The bound between nodes: on a fine grid, how far g can dip below its node
//! values given the end slopes (which assumes g′ nearly linear across a cell); where the grid's
//! cells are polynomial (a table read at its own nodes, 100 m apart for a survey, where g′ can
//! change sign twice inside a cell whose ends both climb), the hull of g's Bernstein
//! coefficients on each cell, and on the part of the ray's own cell beyond it.
//! A fate is only claimed when the grid proves it: "turns" needs a node with g < c; "does not
//! turn" needs g above (or below) the ray to clear c by the bound. Otherwise the answer is
//! [`Fate::Undecided`] and the caller keeps integrating.
//!
//! [`FateWatch`] applies the fates along a ray, as a [`RayHook`]: the one rule by which every
//! caller (the trace report, the renderer) ends rays early. Past its last target a ray that
//! provably oscillates ends [`Termination::Trapped`](super::Termination::Trapped). A ray that
//! provably escapes, once nothing is left for it to meet, climbs out to the top in closed form
//! ([`HookAction::ClimbOut`]: same end, no long integration), or, when the caller does not need
//! its final direction, just ends. A ray whose fate stays undecided runs on to its natural end
//! (ground, top) or the tracer's safety limits (`max_length_m`, `max_steps`).

use rayon::prelude::*;

use super::StratifiedIndex;
use super::ray::{HookAction, RayHook, RayPoint};

/// Relative slack on the invariant (its drift along a traced ray is ~1e-12).
const INVARIANT_SLACK: f64 = 1e-10;

/// What a ray will do, by Bouguer's invariant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fate {
    /// It leaves the top of the atmosphere (after at most one turning point below).
    Escapes,
    /// It reaches the ground (after at most one turning point above).
    MeetsGround,
    /// It has turning points above and below: it oscillates in a duct for ever.
    Trapped,
    /// The grid cannot prove either (the ray grazes a level where g ≈ c).
    Undecided,
}

/// g(h) = n(h)·(R + h) on a grid, with the running minima and dip bounds the fate needs.
#[derive(Debug, Clone)]
pub struct BouguerEnvelope {
    heights_m: Vec<f64>,
    /// min of g over nodes 0..=i.
    min_below: Vec<f64>,
    /// min of g over nodes i.. .
    min_above: Vec<f64>,
    /// The largest dip of g between two nodes at or below i (m).
    dip_below: Vec<f64>,
    /// The largest dip of g between two nodes at or above i (m).
    dip_above: Vec<f64>,
    /// Where the scan's cells are polynomial ([`ScanGrid::polynomial_cells`](super::ScanGrid)):
    /// each cell's hull, which replaces the dip bounds.
    hulls: Option<CellHulls>,
}

/// The Bernstein coefficients of g over each cell of a polynomial scan (m): g lies within
/// their hull, so on any part of a cell it is at least the smallest coefficient of that part
/// (de Casteljau), and on whole cells at least their smallest coefficient.
#[derive(Debug, Clone)]
struct CellHulls {
    coefficients: Vec<[f64; CELL_DEGREE + 1]>,
    /// min of the coefficients of cells i.. .
    lowest_from: Vec<f64>,
    /// min of the coefficients of cells 0..=i.
    lowest_to: Vec<f64>,
}

impl CellHulls {
    /// A lower bound of g over cell `i` from fraction `t` up (`upward`) or down to it.
    fn part(&self, i: usize, t: f64, upward: bool) -> f64 {
        let [left, right] = split(&self.coefficients[i], t.clamp(0.0, 1.0));
        let part = if upward { right } else { left };
        part.iter().copied().fold(f64::INFINITY, f64::min)
    }

    /// A lower bound of g above (`upward`) or below height fraction `t` of cell `i`.
    fn beyond(&self, i: usize, t: f64, upward: bool) -> f64 {
        let rest = if upward {
            self.lowest_from.get(i + 1).copied()
        } else {
            i.checked_sub(1).map(|j| self.lowest_to[j])
        };
        let bound = self.part(i, t, upward).min(rest.unwrap_or(f64::INFINITY));
        // The samples' rounding (g ≈ 6.4e6 m).
        bound - HULL_MARGIN * bound.abs()
    }
}

/// Relative margin on a hull bound for the rounding of the samples it was computed from.
const HULL_MARGIN: f64 = 1e-12;

/// The Bernstein coefficients of the two halves of `b` cut at `t` (de Casteljau).
fn split(b: &[f64; CELL_DEGREE + 1], t: f64) -> [[f64; CELL_DEGREE + 1]; 2] {
    let mut level = *b;
    let (mut left, mut right) = ([0.0; CELL_DEGREE + 1], [0.0; CELL_DEGREE + 1]);
    for r in 0..=CELL_DEGREE {
        left[r] = level[0];
        right[CELL_DEGREE - r] = level[CELL_DEGREE - r];
        for i in 0..CELL_DEGREE - r {
            level[i] = (1.0 - t) * level[i] + t * level[i + 1];
        }
    }
    [left, right]
}

impl BouguerEnvelope {
    /// Scan `index` from the ground to `top_m` over a sphere of `earth_radius_m`, at the nodes
    /// of its [`scan_grid`](StratifiedIndex::scan_grid).
    pub fn new<S: StratifiedIndex + ?Sized>(index: &S, earth_radius_m: f64, top_m: f64) -> Self {
        let heights_m = scan_heights(index, top_m);
        let (g, slope): (Vec<f64>, Vec<f64>) = heights_m
            .par_iter()
            .map(|&h| {
                let (n, dn) = index.scan_index_and_derivative(h);
                let r = earth_radius_m + h;
                (n * r, n + r * dn)
            })
            .unzip();
        let dips: Vec<f64> = (0..heights_m.len())
            .map(|i| {
                if i + 1 >= heights_m.len() {
                    return 0.0;
                }
                let dip = slope_dip(heights_m[i + 1] - heights_m[i], slope[i], slope[i + 1]);
                if dip.is_finite() { dip } else { f64::INFINITY }
            })
            .collect();
        let hulls = index
            .scan_grid()
            .polynomial_cells
            .then(|| CellHulls::new(index, earth_radius_m, &heights_m, &g));
        let nan_safe = |v: f64| if v.is_nan() { f64::NEG_INFINITY } else { v };
        let scan = |values: &[f64], forward: bool, op: fn(f64, f64) -> f64| {
            let mut out = vec![0.0; values.len()];
            let mut acc: Option<f64> = None;
            let idx: Vec<usize> = if forward {
                (0..values.len()).collect()
            } else {
                (0..values.len()).rev().collect()
            };
            for i in idx {
                let v = nan_safe(values[i]);
                acc = Some(acc.map_or(v, |a| op(a, v)));
                out[i] = acc.unwrap_or(v);
            }
            out
        };
        BouguerEnvelope {
            min_below: scan(&g, true, f64::min),
            min_above: scan(&g, false, f64::min),
            dip_below: scan(&dips, true, f64::max),
            dip_above: scan(&dips, false, f64::max),
            heights_m,
            hulls,
        }
    }

    /// The fate of a ray at `height_m`, climbing or not, with invariant `invariant_m`
    /// (n·r·cos ψ, metres).
    pub fn fate(&self, height_m: f64, climbing: bool, invariant_m: f64) -> Fate {
        if !(height_m.is_finite() && invariant_m.is_finite()) {
            return Fate::Undecided;
        }
        let slack = INVARIANT_SLACK * invariant_m.abs();
        let above = self.heights_m.partition_point(|&h| h < height_m);
        let below = above.saturating_sub(1);
        let side = |turns: bool, clear: bool| match (turns, clear) {
            (true, _) => Some(true),
            (false, true) => Some(false),
            _ => None,
        };
        let (clear_above, clear_below) = match &self.hulls {
            Some(hulls) if below + 1 < self.heights_m.len() => {
                let (lo, hi) = (self.heights_m[below], self.heights_m[below + 1]);
                let t = (height_m - lo) / (hi - lo);
                (
                    hulls.beyond(below, t, true) > invariant_m + slack,
                    hulls.beyond(below, t, false) > invariant_m + slack,
                )
            }
            _ => (
                self.min_above
                    .get(above)
                    .is_some_and(|&m| m > invariant_m + slack + self.dip_above[below]),
                self.min_below[below]
                    > invariant_m + slack + self.dip_below[below.min(self.dip_below.len() - 1)],
            ),
        };
        let turns_above = if above >= self.heights_m.len() {
            Some(false)
        } else {
            side(self.min_above[above] < invariant_m - slack, clear_above)
        };
        let turns_below = side(self.min_below[below] < invariant_m - slack, clear_below);
        match (climbing, turns_above, turns_below) {
            (true, Some(false), _) => Fate::Escapes,
            (false, _, Some(false)) => Fate::MeetsGround,
            (_, Some(true), Some(true)) => Fate::Trapped,
            (true, Some(true), Some(false)) => Fate::MeetsGround,
            (false, Some(false), Some(true)) => Fate::Escapes,
            _ => Fate::Undecided,
        }
    }
}

/// How far g can fall below the lower of its node values inside a cell of width `width_m`
/// with end slopes `a` and `b`, from the slopes alone: where the slope keeps its sign (monotone
/// cell), by the curvature, Δ·|g'(b) − g'(a)|/8 (exact if g' is linear across the cell); where
/// it changes sign (a minimum inside), by Δ·(|g'(a)| + |g'(b)|)/2.
fn slope_dip(width_m: f64, a: f64, b: f64) -> f64 {
    if (a > 0.0) == (b > 0.0) {
        width_m * (b - a).abs() / 8.0
    } else {
        width_m * (a.abs() + b.abs()) / 2.0
    }
}

/// Degree of g = n·r over a cell where n is a quintic in h.
const CELL_DEGREE: usize = 6;

/// The inverse of the collocation matrix of the degree-6 Bernstein basis at t = j/6: it turns
/// seven equispaced samples of a polynomial of degree ≤ 6 on [0, 1] into its Bernstein
/// coefficients.
fn bernstein_from_samples() -> &'static [[f64; CELL_DEGREE + 1]; CELL_DEGREE + 1] {
    static INVERSE: std::sync::OnceLock<[[f64; CELL_DEGREE + 1]; CELL_DEGREE + 1]> =
        std::sync::OnceLock::new();
    INVERSE.get_or_init(|| {
        const K: usize = CELL_DEGREE + 1;
        let binomial =
            |n: usize, k: usize| (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64);
        // [M | I] → [I | M⁻¹] by Gauss–Jordan with partial pivoting (M is well conditioned).
        let mut m = [[0.0; 2 * K]; K];
        for (j, row) in m.iter_mut().enumerate() {
            let t = j as f64 / CELL_DEGREE as f64;
            let n = CELL_DEGREE;
            for (i, v) in row[..K].iter_mut().enumerate() {
                *v = binomial(n, i) * t.powi(i as i32) * (1.0 - t).powi((n - i) as i32);
            }
            row[K + j] = 1.0;
        }
        for col in 0..K {
            let pivot = (col..K)
                .max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))
                .unwrap_or(col);
            m.swap(col, pivot);
            let p = m[col][col];
            for v in m[col].iter_mut() {
                *v /= p;
            }
            for r in 0..K {
                if r != col {
                    let f = m[r][col];
                    let pivot_row = m[col];
                    for (v, pv) in m[r].iter_mut().zip(pivot_row) {
                        *v -= f * pv;
                    }
                }
            }
        }
        std::array::from_fn(|r| std::array::from_fn(|c| m[r][K + c]))
    })
}

impl CellHulls {
    /// Each cell's Bernstein coefficients from seven equispaced samples of g (the nodes' `g`
    /// and five scans inside), in parallel (collected in order).
    fn new<S: StratifiedIndex + ?Sized>(
        index: &S,
        earth_radius_m: f64,
        heights_m: &[f64],
        g: &[f64],
    ) -> Self {
        let g_at = |h: f64| index.scan_index_and_derivative(h).0 * (earth_radius_m + h);
        let inverse = bernstein_from_samples();
        let coefficients: Vec<[f64; CELL_DEGREE + 1]> = (0..heights_m.len().saturating_sub(1))
            .into_par_iter()
            .map(|i| {
                let (lo, hi) = (heights_m[i], heights_m[i + 1]);
                let samples: [f64; CELL_DEGREE + 1] = std::array::from_fn(|j| match j {
                    0 => g[i],
                    CELL_DEGREE => g[i + 1],
                    _ => g_at(lo + (hi - lo) * j as f64 / CELL_DEGREE as f64),
                });
                // Relative to the first sample, so that the sums carry the cell's variation
                // rather than 6.4e6 m; a non-finite sample makes the cell's bound −∞.
                std::array::from_fn(|k| {
                    let v = g[i]
                        + inverse[k]
                            .iter()
                            .zip(&samples)
                            .map(|(w, s)| w * (s - g[i]))
                            .sum::<f64>();
                    if v.is_nan() { f64::NEG_INFINITY } else { v }
                })
            })
            .collect();
        let lowest: Vec<f64> = coefficients
            .iter()
            .map(|c| c.iter().copied().fold(f64::INFINITY, f64::min))
            .collect();
        let mut lowest_from = lowest.clone();
        for i in (0..lowest_from.len().saturating_sub(1)).rev() {
            lowest_from[i] = lowest_from[i].min(lowest_from[i + 1]);
        }
        let mut lowest_to = lowest;
        for i in 1..lowest_to.len() {
            lowest_to[i] = lowest_to[i].min(lowest_to[i - 1]);
        }
        CellHulls {
            coefficients,
            lowest_from,
            lowest_to,
        }
    }
}

/// The scan's node heights from the ground to `top_m` (see [`ScanGrid`](super::ScanGrid)).
fn scan_heights<S: StratifiedIndex + ?Sized>(index: &S, top_m: f64) -> Vec<f64> {
    let grid = index.scan_grid();
    let (fine, coarse) = (grid.fine_step_m.max(1e-3), grid.coarse_step_m.max(1e-3));
    let mut heights_m = Vec::new();
    let mut h = 0.0;
    while h < top_m {
        heights_m.push(h);
        h += if h < grid.fine_top_m { fine } else { coarse };
    }
    heights_m.push(top_m);
    if grid.with_breaks {
        let breaks = index.breaks_m().iter().copied();
        let minor = index.minor_breaks().iter().map(|b| b.height_m);
        heights_m.extend(breaks.chain(minor).filter(|&b| b > 0.0 && b < top_m));
        heights_m.sort_by(f64::total_cmp);
        heights_m.dedup();
    }
    heights_m
}

/// The Bouguer fate rule along one ray (a [`RayHook`]); see the module docs.
#[derive(Debug, Clone, Copy)]
pub struct FateWatch<'e> {
    envelope: &'e BouguerEnvelope,
    invariant_m: f64,
    targets_end_m: f64,
    /// Above this height a climbing ray has nothing left to meet (above every object).
    clear_above_m: Option<f64>,
    /// Whether the caller needs an escaping ray's final direction.
    need_direction: bool,
    /// The fate once the envelope has decided it: it does not change along the ray (the
    /// invariant is the launch value, so integration error cannot move it).
    decided: Option<Fate>,
}

impl<'e> FateWatch<'e> {
    /// Watch the ray launched at `elevation_rad` from `observer_height_m` through `index` (the
    /// field `envelope` was built from, over `earth_radius_m`), whose last target is at ground
    /// distance `targets_end_m` (0 without targets). Past it, a ray that provably escapes climbs
    /// out to the top in closed form ([`HookAction::ClimbOut`]).
    pub fn new<S: StratifiedIndex + ?Sized>(
        envelope: &'e BouguerEnvelope,
        index: &S,
        earth_radius_m: f64,
        observer_height_m: f64,
        elevation_rad: f64,
        targets_end_m: f64,
    ) -> Self {
        let (n0, _) = index.index_and_derivative(observer_height_m);
        FateWatch {
            envelope,
            invariant_m: n0 * (earth_radius_m + observer_height_m) * elevation_rad.cos(),
            targets_end_m,
            clear_above_m: None,
            need_direction: true,
            decided: None,
        }
    }

    /// A climbing ray above `height_m` has nothing left to meet (it is above every object): a
    /// ray that provably escapes is finished from there as past its last target.
    pub fn clear_above(self, height_m: f64) -> Self {
        FateWatch {
            clear_above_m: Some(height_m),
            ..self
        }
    }

    /// The caller does not need an escaping ray's final direction: such a ray ends
    /// ([`HookAction::Stop`]) as soon as nothing is left for it to meet, instead of climbing out.
    pub fn without_direction(self) -> Self {
        FateWatch {
            need_direction: false,
            ..self
        }
    }

    /// The ray's invariant n·r·cos ψ (m), from its launch.
    pub fn invariant_m(&self) -> f64 {
        self.invariant_m
    }

    /// The action for a ray now at `point`.
    pub fn action(&mut self, point: &RayPoint) -> HookAction {
        let done = point.distance_m >= self.targets_end_m;
        let climbing = point.elevation_rad > 0.0;
        let clear = self
            .clear_above_m
            .is_some_and(|h| climbing && point.height_m > h);
        if !(done || clear) {
            return HookAction::Continue;
        }
        let fate = match self.decided {
            Some(fate) => fate,
            None => {
                let fate = self
                    .envelope
                    .fate(point.height_m, climbing, self.invariant_m);
                if fate != Fate::Undecided {
                    self.decided = Some(fate);
                }
                fate
            }
        };
        match fate {
            Fate::Trapped if done => HookAction::Trapped,
            // Past the targets, or climbing for good above every object: nothing left to meet.
            Fate::Escapes if !self.need_direction => HookAction::Stop,
            Fate::Escapes if climbing => HookAction::ClimbOut,
            _ => HookAction::Continue,
        }
    }
}

impl RayHook for FateWatch<'_> {
    fn after_step(&mut self, _from: &RayPoint, to: &RayPoint) -> HookAction {
        self.action(to)
    }
}

/// A caller's hook followed by an optional [`FateWatch`] (the watch acts only where the hook
/// lets the ray go on).
pub(crate) struct Watched<'h, 'e, H: RayHook + ?Sized> {
    pub hook: &'h mut H,
    pub watch: Option<FateWatch<'e>>,
}

impl<H: RayHook + ?Sized> RayHook for Watched<'_, '_, H> {
    fn event(&self, point: &RayPoint) -> Option<f64> {
        self.hook.event(point)
    }
    fn after_step(&mut self, from: &RayPoint, to: &RayPoint) -> HookAction {
        match self.hook.after_step(from, to) {
            HookAction::Continue => self
                .watch
                .as_mut()
                .map_or(HookAction::Continue, |w| w.action(to)),
            other => other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tracer::ScanGrid;

    /// n = 1 + a − b·h below `duct_top_m` (a trapping gradient), normal above.
    struct Duct {
        top_m: f64,
    }
    impl StratifiedIndex for Duct {
        fn index_and_derivative(&self, h: f64) -> (f64, f64) {
            let (a, strong, weak) = (3e-4, 4e-7, 4e-8);
            if h < self.top_m {
                (1.0 + a - strong * h, -strong)
            } else {
                (
                    1.0 + a - strong * self.top_m - weak * (h - self.top_m),
                    -weak,
                )
            }
        }
    }

    #[test]
    fn level_ray_in_a_surface_duct_is_trapped_only_if_it_turns_above_the_ground() {
        let r = 6_371_000.0;
        let field = Duct { top_m: 100.0 };
        let env = BouguerEnvelope::new(&field, r, 40_000.0);
        let g = |h: f64| {
            let (n, _) = field.index_and_derivative(h);
            n * (r + h)
        };
        // In the duct, g decreases with height: a level ray at 50 m turns back down at once
        // and meets the ground (no turning point below, g grows downwards).
        assert_eq!(env.fate(50.0, false, g(50.0)), Fate::MeetsGround);
        // Above the duct g grows: a level ray at 500 m with g(500) has no turning point above
        // (it climbs away); below, g dips under it in the duct? g(100) < g(500) → turns below.
        assert_eq!(
            env.fate(500.0, true, g(500.0) * (1.0 - 1e-9)),
            Fate::Escapes
        );
        let c = g(300.0) * (1.0 - 1e-9);
        assert_eq!(
            env.fate(300.0, false, c),
            Fate::Escapes,
            "turns in the duct, then climbs"
        );
        // A ray inside a duct that cannot reach the ground: an elevated duct 1000–1200 m.
        let elevated = ElevatedDuct;
        let env = BouguerEnvelope::new(&elevated, r, 40_000.0);
        let g = |h: f64| {
            let (n, _) = elevated.index_and_derivative(h);
            n * (r + h)
        };
        assert_eq!(
            env.fate(1100.0, true, g(1100.0) * (1.0 - 1e-10)),
            Fate::Trapped
        );
        assert_eq!(
            env.fate(1100.0, false, g(1100.0) * (1.0 - 1e-10)),
            Fate::Trapped
        );
        // Steeper rays (smaller c) leave: up through the top, or down to the ground.
        assert_eq!(
            env.fate(1100.0, true, g(1100.0) * (1.0 - 1e-4)),
            Fate::Escapes
        );
        assert_eq!(
            env.fate(1100.0, false, g(1100.0) * (1.0 - 1e-4)),
            Fate::MeetsGround
        );
        assert_eq!(env.fate(f64::NAN, true, 1.0), Fate::Undecided);
    }

    #[test]
    fn the_watch_ends_trapped_rays_past_their_targets_and_escaping_ones_when_asked() {
        use crate::tracer::{Termination, Tracer, TracerConfig};
        let r = 6_371_000.0;
        let cfg = TracerConfig {
            stop_after_last_target: false,
            tolerance_m: 1e-3,
            ..TracerConfig::default()
        };
        let tracer = Tracer::new(&ElevatedDuct, cfg.clone())
            .unwrap()
            .with_fates();
        // A level ray in the middle of the elevated duct oscillates in it: trapped, but only
        // once it is past its last target (its heights there are still reported).
        let rec = tracer.trace(1100.0, 0.0, &[50_000.0]).unwrap();
        assert_eq!(rec.termination, Some(Termination::Trapped), "{rec:?}");
        assert!(
            rec.heights_m[0].is_some_and(|h| h > 500.0 && h < 1200.0),
            "{rec:?}"
        );
        assert!(rec.end.distance_m >= 50_000.0 && rec.end.distance_m < 60_000.0);
        // A steeper ray climbs out of the top: traced there, with its refraction.
        let up = tracer.trace(1100.0, 0.02, &[50_000.0]).unwrap();
        assert_eq!(up.termination, Some(Termination::Escaped));
        // Without the envelope the trapped ray runs on to a safety limit.
        let plain = Tracer::new(
            &ElevatedDuct,
            TracerConfig {
                max_distance_m: Some(500_000.0),
                ..cfg.clone()
            },
        )
        .unwrap();
        let rec = plain.trace(1100.0, 0.0, &[50_000.0]).unwrap();
        assert_eq!(rec.termination, Some(Termination::MaxDistance));
        // Clear above 1500 m, the watch finishes the steep ray from there in closed form: the
        // same end as the integrated ray, in far fewer steps.
        let envelope = tracer.fates().unwrap();
        let free = Tracer::new(&ElevatedDuct, cfg.clone()).unwrap();
        let integrated = free.trace(1100.0, 0.02, &[50_000.0]).unwrap();
        assert_eq!(integrated.termination, Some(Termination::Escaped));
        let mut watch =
            FateWatch::new(envelope, &ElevatedDuct, r, 1100.0, 0.02, 50_000.0).clear_above(1500.0);
        let mut rec = crate::tracer::RayRecord::default();
        free.trace_into(1100.0, 0.02, &[50_000.0], &mut watch, &mut rec, None)
            .unwrap();
        assert_eq!(rec.termination, Some(Termination::Escaped));
        assert!(
            rec.steps() * 3 < integrated.steps(),
            "{rec:?} {integrated:?}"
        );
        let direction_rad = rec.end_observer_elevation_rad - integrated.end_observer_elevation_rad;
        assert!(direction_rad.abs() < 1e-9, "{direction_rad:e}");
        assert!((rec.end.distance_m - integrated.end.distance_m).abs() < 0.05);
        assert!((rec.end.height_m - integrated.end.height_m).abs() < 1e-6);
        // Not needing the direction, it ends the ray there.
        let mut watch = FateWatch::new(envelope, &ElevatedDuct, r, 1100.0, 0.02, 50_000.0)
            .clear_above(1500.0)
            .without_direction();
        let mut rec = crate::tracer::RayRecord::default();
        plain
            .trace_into(1100.0, 0.02, &[50_000.0], &mut watch, &mut rec, None)
            .unwrap();
        assert_eq!(rec.termination, Some(Termination::LeftRegion));
        assert!(
            rec.end.height_m > 1500.0 && rec.end.height_m < 2000.0,
            "{rec:?}"
        );
    }

    /// g′ ≈ 1 + R·dn/dh = 1.2 everywhere but inside 1000–1100 m, where a cubic n makes
    /// g′ = 1.2 − 6s(1 − s) (s the fraction of the cell): positive at both ends, −0.3 in the
    /// middle, so g rises 14.5 m, falls back to 5.5 m above its value at 1000 m, then rises to
    /// 20 m at 1100 m. Scanned on 100 m cells; `polynomial` says whether the cells are declared
    /// polynomial (they are: n is linear or cubic on each).
    struct BumpCell {
        polynomial: bool,
    }
    const BUMP_R: f64 = 6_371_000.0;
    impl StratifiedIndex for BumpCell {
        fn index_and_derivative(&self, h: f64) -> (f64, f64) {
            let (n0, k) = (1.0 + 3e-4, 1.0 / BUMP_R);
            if h < 1000.0 {
                (n0 + 0.2 * k * h, 0.2 * k)
            } else if h < 1100.0 {
                let s = (h - 1000.0) / 100.0;
                let n =
                    n0 + k * (200.0 + 0.2 * (h - 1000.0) - 100.0 * (3.0 * s * s - 2.0 * s * s * s));
                (n, k * (0.2 - 6.0 * s * (1.0 - s)))
            } else {
                (
                    n0 + k * (200.0 + 20.0 - 100.0 + 0.2 * (h - 1100.0)),
                    0.2 * k,
                )
            }
        }
        fn scan_grid(&self) -> ScanGrid {
            ScanGrid {
                fine_step_m: 100.0,
                fine_top_m: 0.0,
                coarse_step_m: 100.0,
                with_breaks: false,
                polynomial_cells: self.polynomial,
            }
        }
    }

    #[test]
    fn a_dip_inside_a_coarse_cell_whose_ends_climb_is_not_cleared() {
        let g = |h: f64| BumpCell { polynomial: true }.index_and_derivative(h).0 * (BUMP_R + h);
        let (g0, g_ray) = (g(1000.0), g(1030.0));
        // The dip's bottom, 5.5 m above g0, and g at the ray's height, 14 m above.
        let lowest = (0..=500)
            .map(|i| g(1050.0 + 0.1 * f64::from(i)))
            .fold(f64::INFINITY, f64::min);
        assert!(
            lowest > g0 + 5.0 && lowest < g0 + 6.0 && g_ray > g0 + 14.0,
            "{} {}",
            lowest - g0,
            g_ray - g0
        );
        // A climbing ray at 1030 m whose invariant lies between the dip and its own g: it turns
        // at the dip and cannot escape.
        let c = g0 + 10.0;
        let slopes = BouguerEnvelope::new(&BumpCell { polynomial: false }, BUMP_R, 40_000.0);
        let hulls = BouguerEnvelope::new(&BumpCell { polynomial: true }, BUMP_R, 40_000.0);
        // End slopes alone see a cell whose ends both climb at 1.2: no dip, so "escapes".
        assert_eq!(slopes.fate(1030.0, true, c), Fate::Escapes);
        assert_ne!(hulls.fate(1030.0, true, c), Fate::Escapes);
        // Still decided where it is clear: far below the dip, or above the cell.
        assert_eq!(hulls.fate(1030.0, true, g0 - 50.0), Fate::Escapes);
        assert_eq!(hulls.fate(1150.0, true, g(1150.0) - 1.0), Fate::Escapes);
        // Descending from 1090 m with c above the dip: it turns there, so it does not reach the
        // ground without turning, as the hull knows.
        assert_ne!(hulls.fate(1090.0, false, g0 + 5.9), Fate::MeetsGround);
    }

    #[test]
    fn bernstein_split_halves_reproduce_the_polynomial() {
        // Coefficients of an arbitrary sextic; its value at t from the left half at 1 and the
        // right half at 0 (both its value at t).
        let b = [3.0, -1.0, 4.0, 1.5, -5.0, 9.0, 2.0];
        let eval = |c: &[f64; 7], t: f64| {
            (0..7).fold(0.0, |acc, i| {
                let binom = [1.0, 6.0, 15.0, 20.0, 15.0, 6.0, 1.0][i];
                acc + c[i] * binom * t.powi(i as i32) * (1.0 - t).powi(6 - i as i32)
            })
        };
        let [left, right] = split(&b, 0.3);
        assert!(
            (left[6] - eval(&b, 0.3)).abs() < 1e-12 && (right[0] - eval(&b, 0.3)).abs() < 1e-12
        );
        // The left half at u is the whole at 0.3·u; the right half at u the whole at 0.3 + 0.7·u.
        for u in [0.1, 0.5, 0.9] {
            assert!((eval(&left, u) - eval(&b, 0.3 * u)).abs() < 1e-12);
            assert!((eval(&right, u) - eval(&b, 0.3 + 0.7 * u)).abs() < 1e-12);
        }
        // Seven samples of a sextic give its coefficients back.
        let inverse = bernstein_from_samples();
        let samples: [f64; 7] = std::array::from_fn(|j| eval(&b, j as f64 / 6.0));
        for (k, row) in inverse.iter().enumerate() {
            let c: f64 = row.iter().zip(&samples).map(|(w, s)| w * s).sum();
            assert!((c - b[k]).abs() < 1e-11, "{k}: {c} vs {}", b[k]);
        }
    }

    /// A trapping layer between 1000 and 1200 m over normal air.
    struct ElevatedDuct;
    impl StratifiedIndex for ElevatedDuct {
        fn index_and_derivative(&self, h: f64) -> (f64, f64) {
            let (weak, strong) = (4e-8, 4e-7);
            let n0 = 1.0 + 3e-4;
            if h < 1000.0 {
                (n0 - weak * h, -weak)
            } else if h < 1200.0 {
                (n0 - weak * 1000.0 - strong * (h - 1000.0), -strong)
            } else {
                (
                    n0 - weak * 1000.0 - strong * 200.0 - weak * (h - 1200.0),
                    -weak,
                )
            }
        }
    }
}
