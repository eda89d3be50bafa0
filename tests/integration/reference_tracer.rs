//! Checks of the independent reference tracer (`support::reference`) against exact closed-form
//! rays: uniform n (straight lines), n ∝ 1/r (level rays stay level, others are logarithmic
//! spirals) and a three-layer piecewise power law n ∝ r^k (exact rays r^(k+1)·cos((k+1)(θ − θ₀))
//! = const, matched at each boundary), plus its step-halving convergence on real atmospheres
//! and its cost.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use ghostship::profile::us1976::geometric_to_geopotential_m;
use ghostship::profile::{FitOptions, Profile, StandardAtmosphere, SyntheticAtmosphere};
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::sounding::{ReadOptions, read_sounding};

use crate::support::reference::{
    BreakSource, RefReach, ReferenceIndex, ReferenceSteps, atmosphere_index, reference_heights,
    reference_heights_with_error, reference_heights_with_steps, us1976_bases_m,
};

const R: f64 = 6_371_000.0;
/// Distances every exact case is checked at (m).
const DISTANCES_M: [f64; 9] = [0.0, 5e3, 10e3, 20e3, 30e3, 50e3, 100e3, 200e3, 300e3];
/// The accuracy asserted: up to 30 km, and beyond (to 300 km).
const TOLERANCE_30_KM_M: f64 = 1e-7;
const TOLERANCE_300_KM_M: f64 = 1e-6;

fn tolerance(d: f64) -> f64 {
    if d <= 30e3 {
        TOLERANCE_30_KM_M
    } else {
        TOLERANCE_300_KM_M
    }
}

/// Compare reference and exact results; returns the largest height difference (≤ 30 km, beyond).
fn compare(label: &str, got: &[RefReach], want: &[RefReach], distances: &[f64]) -> (f64, f64) {
    let mut worst = (0.0f64, 0.0f64);
    for ((g, w), d) in got.iter().zip(want).zip(distances) {
        match (g, w) {
            (RefReach::Height(a), RefReach::Height(b)) => {
                let e = (a - b).abs();
                assert!(
                    e <= tolerance(*d),
                    "{label} at {d} m: {a} vs exact {b} (Δ {e:.2e} m)"
                );
                if *d <= 30e3 {
                    worst.0 = worst.0.max(e);
                } else {
                    worst.1 = worst.1.max(e);
                }
            }
            _ => assert_eq!(g, w, "{label} at {d} m"),
        }
    }
    worst
}

/// ln cos ψ without cancellation for small ψ.
fn ln_cos(psi: f64) -> f64 {
    let s = (0.5 * psi).sin();
    (-2.0 * s * s).ln_1p()
}

#[test]
fn uniform_index_gives_straight_lines() {
    let index = ReferenceIndex::new(|_| (1.000_29, 0.0), vec![]);
    let top = 100e3;
    let mut worst = (0.0f64, 0.0f64);
    for (h0, deg) in [
        (2.0, 0.0),
        (50.0, -0.1),
        (10.0, 0.3),
        (300.0, 2.0),
        (1.0, 10.0),
    ] {
        let a = f64::to_radians(deg);
        let r0 = R + h0;
        // r = r₀·cos α / cos(θ + α), written as h₀ + r₀·(cos α − cos(θ + α)) / cos(θ + α).
        let exact: Vec<RefReach> = DISTANCES_M
            .iter()
            .map(|d| {
                let t = d / R;
                let num = 2.0 * (0.5 * t + a).sin() * (0.5 * t).sin();
                RefReach::Height(h0 + r0 * num / (t + a).cos())
            })
            .collect();
        let got = reference_heights(&index, R, top, h0, a, &DISTANCES_M);
        let w = compare(
            &format!("uniform {h0} m {deg}°"),
            &got,
            &exact,
            &DISTANCES_M,
        );
        worst = (worst.0.max(w.0), worst.1.max(w.1));
    }
    eprintln!(
        "uniform n: max |Δh| {:.1e} m (≤ 30 km), {:.1e} m (≤ 300 km)",
        worst.0, worst.1
    );
}

#[test]
fn inverse_radius_index_gives_level_rays_and_spirals() {
    // n = n₀·R/r: n·r is constant, so cos ψ is constant along a ray (Bouguer): a level ray
    // keeps its height exactly, any other is the spiral r = r₀·exp(θ·tan α).
    let n0 = 1.000_3;
    let index = ReferenceIndex::new(
        move |h: f64| {
            let r = R + h;
            (n0 * R / r, -n0 * R / (r * r))
        },
        vec![],
    );
    let mut worst = (0.0f64, 0.0f64);
    for (h0, deg) in [
        (0.0, 0.0),
        (25.0, 0.0),
        (1500.0, 0.0),
        (10.0, 0.2),
        (400.0, -0.05),
    ] {
        let a = f64::to_radians(deg);
        let exact: Vec<RefReach> = DISTANCES_M
            .iter()
            .map(|d| RefReach::Height(h0 + (R + h0) * (d / R * a.tan()).exp_m1()))
            .collect();
        let got = reference_heights(&index, R, 50e3, h0, a, &DISTANCES_M);
        let w = compare(&format!("1/r {h0} m {deg}°"), &got, &exact, &DISTANCES_M);
        worst = (worst.0.max(w.0), worst.1.max(w.1));
    }
    eprintln!(
        "n ∝ 1/r: max |Δh| {:.1e} m (≤ 30 km), {:.1e} m (≤ 300 km)",
        worst.0, worst.1
    );
}

/// n = n_j·(r/r_j)^k_j in layer j (base radius r_j): continuous n, dn/dh = k·n/r jumps at the
/// layer boundaries.
struct PowerLayers {
    /// Layer bases above the surface (m); the first is the ground.
    bases_m: [f64; 3],
    k: [f64; 3],
    /// n at each base.
    n_base: [f64; 3],
}

impl PowerLayers {
    /// Layers with the given bases and dn/dh (m⁻¹) at each base, n = `n_ground` at the ground.
    fn new(n_ground: f64, bases_m: [f64; 3], dndh: [f64; 3]) -> Self {
        let mut k = [0.0; 3];
        let mut n_base = [n_ground; 3];
        for j in 0..3 {
            let r = R + bases_m[j];
            k[j] = dndh[j] * r / n_base[j];
            if j < 2 {
                n_base[j + 1] = n_base[j] * ((R + bases_m[j + 1]) / r).powf(k[j]);
            }
        }
        PowerLayers { bases_m, k, n_base }
    }

    fn layer(&self, h: f64) -> usize {
        self.bases_m.iter().rposition(|&b| h >= b).unwrap_or(0)
    }

    fn n_and_dndh(&self, h: f64) -> (f64, f64) {
        let j = self.layer(h);
        let r = R + h;
        let n = self.n_base[j] * (r / (R + self.bases_m[j])).powf(self.k[j]);
        (n, self.k[j] * n / r)
    }

    fn index(&self) -> ReferenceIndex<'_> {
        ReferenceIndex::new(|h| self.n_and_dndh(h), self.bases_m[1..].to_vec())
    }
}

/// A piece of an exact piecewise power-law ray: inside layer `layer` from angle `theta` at
/// height `h` with elevation `psi`, where ψ(θ') = ψ + m·(θ' − θ), m = k + 1, and
/// r(θ') = r·(cos ψ / cos ψ(θ'))^(1/m) (the ray is a straight line in the plane of r^m·e^(imθ),
/// a conformal map, so ψ is unchanged by it).
#[derive(Clone, Copy)]
struct Piece {
    theta: f64,
    h: f64,
    psi: f64,
    layer: usize,
}

/// Counts of what an exact ray did: boundary crossings and apexes/perigees.
#[derive(Default)]
struct Events {
    crossings: usize,
    turns: usize,
}

impl PowerLayers {
    /// The next crossing of the piece's layer bounds (bound index 0 = ground, 3 = `top`):
    /// (Δθ, bound index, ψ there). Through the lower bound ψ < 0, through the upper ψ > 0.
    fn next_crossing(&self, p: &Piece, top: f64) -> Option<(f64, usize, f64)> {
        let bounds = [0.0, self.bases_m[1], self.bases_m[2], top];
        let m = self.k[p.layer] + 1.0;
        let mut best: Option<(f64, usize, f64)> = None;
        for (b, sign) in [(p.layer, -1.0), (p.layer + 1, 1.0)] {
            let hb = bounds[b];
            // cos ψ_b = cos ψ·(r/r_b)^m, as a logarithm.
            let l = ln_cos(p.psi) + m * ((p.h - hb) / (R + hb)).ln_1p();
            if l > 0.0 {
                continue;
            }
            let psi_b = sign * 2.0 * (0.5 * -l.exp_m1()).sqrt().asin();
            let dt = (psi_b - p.psi) / m;
            if dt > 0.0 && best.is_none_or(|x| dt < x.0) {
                best = Some((dt, b, psi_b));
            }
        }
        best
    }

    fn height_in(&self, p: &Piece, theta: f64) -> f64 {
        let m = self.k[p.layer] + 1.0;
        let psi = p.psi + m * (theta - p.theta);
        p.h + (R + p.h) * ((ln_cos(p.psi) - ln_cos(psi)) / m).exp_m1()
    }

    /// The exact ray at `distances_m`, and what it did on the way.
    fn exact(&self, top: f64, h0: f64, alpha: f64, distances_m: &[f64]) -> (Vec<RefReach>, Events) {
        let j = self.layer(h0);
        // On a boundary, a descending ray starts in the layer below it.
        let below = j > 0 && h0 == self.bases_m[j] && alpha < 0.0;
        let mut p = Piece {
            theta: 0.0,
            h: h0,
            psi: alpha,
            layer: if below { j - 1 } else { j },
        };
        let mut ev = Events::default();
        let mut out = Vec::new();
        let mut ended = None;
        for &d in distances_m {
            let target = d / R;
            while ended.is_none() {
                let Some((dt, b, psi_b)) = self.next_crossing(&p, top) else {
                    break;
                };
                if p.theta + dt > target {
                    break;
                }
                let m = self.k[p.layer] + 1.0;
                ev.turns += usize::from(p.psi * psi_b < 0.0 || (p.psi == 0.0 && m != 0.0));
                ev.crossings += 1;
                match b {
                    0 => ended = Some(RefReach::GroundBefore),
                    3 => ended = Some(RefReach::EscapedBefore),
                    _ => {}
                }
                let layer = if psi_b > 0.0 { b } else { b - 1 };
                let h = [0.0, self.bases_m[1], self.bases_m[2], top][b];
                p = Piece {
                    theta: p.theta + dt,
                    h,
                    psi: psi_b,
                    layer: layer.min(2),
                };
            }
            out.push(ended.unwrap_or_else(|| RefReach::Height(self.height_in(&p, target))));
        }
        (out, ev)
    }
}

impl PowerLayers {
    /// Where the exact ray leaves through `top`: (angle travelled, local elevation there);
    /// `None` if it meets the ground first or is still inside after 2 000 crossings.
    fn leave(&self, top: f64, h0: f64, alpha: f64) -> Option<(f64, f64)> {
        let j = self.layer(h0);
        let below = j > 0 && h0 == self.bases_m[j] && alpha < 0.0;
        let mut p = Piece {
            theta: 0.0,
            h: h0,
            psi: alpha,
            layer: if below { j - 1 } else { j },
        };
        for _ in 0..2_000 {
            let (dt, b, psi_b) = self.next_crossing(&p, top)?;
            match b {
                0 => return None,
                3 => return Some((p.theta + dt, psi_b)),
                _ => {}
            }
            p = Piece {
                theta: p.theta + dt,
                h: [0.0, self.bases_m[1], self.bases_m[2], top][b],
                psi: psi_b,
                layer: if psi_b > 0.0 { b } else { b - 1 }.min(2),
            };
        }
        None
    }
}

impl ghostship::tracer::StratifiedIndex for PowerLayers {
    fn index_and_derivative(&self, height_m: f64) -> (f64, f64) {
        self.n_and_dndh(height_m)
    }
    fn breaks_m(&self) -> &[f64] {
        &self.bases_m[1..]
    }
}

/// The tracer's closed-form climb out of escaping rays (Bouguer's invariant and the refraction
/// integral, `HookAction::ClimbOut`) against the exact rays of the piecewise power law: where
/// they leave the top and in which direction, for rays from steep to grazing, launched above
/// the duct or climbing out of it; and the same rays integrated all the way.
#[test]
fn escaping_rays_leave_where_the_exact_power_law_rays_do() {
    use ghostship::tracer::{Termination, Tracer, TracerConfig};
    let layers = PowerLayers::new(1.000_3, [0.0, 40.0, 120.0], [-1e-7, -4e-7, -0.5e-7]);
    let top = 20e3;
    let config = TracerConfig {
        earth_radius_m: R,
        top_m: top,
        ..TracerConfig::default()
    };
    // The direction budget of the tolerance: T over the error length (see the tracer docs).
    let budget_rad = config.tolerance_m / config.error_length_m;
    let closed = Tracer::new(&layers, config.clone()).unwrap().with_fates();
    let integrated = Tracer::new(&layers, config.clone()).unwrap();
    let rays = [
        (5.0, 5.0),
        (30.0, 2.0),
        (100.0, 0.5),
        (100.0, 0.2),
        (121.0, 0.0),
        (300.0, -0.1),
        (2_000.0, 0.001),
        (2_000.0, -0.3),
    ];
    let mut worst = [0.0f64; 4];
    for (h0, deg) in rays {
        let alpha = f64::to_radians(deg);
        let (theta, psi) = layers.leave(top, h0, alpha).expect("the ray escapes");
        let n_top = layers.n_and_dndh(top).0;
        let direction = (n_top * psi.cos()).min(1.0).acos() - theta;
        for (which, tracer) in [(0, &closed), (2, &integrated)] {
            let rec = tracer.trace(h0, alpha, &[]).unwrap();
            assert_eq!(rec.termination, Some(Termination::Escaped), "{h0} {deg}");
            let d_direction = (rec.end_observer_elevation_rad - direction).abs();
            let d_distance = (rec.end.distance_m - R * theta).abs();
            eprintln!(
                "{h0} m {deg}° ({}): {} steps, direction off {d_direction:.1e} rad, exit {d_distance:.1e} m",
                ["closed form", "", "integrated"][which],
                rec.steps()
            );
            worst[which] = worst[which].max(d_direction);
            worst[which + 1] = worst[which + 1].max(d_distance);
        }
    }
    eprintln!("worst: {worst:?}");
    assert!(
        worst[0] <= 0.1 * budget_rad,
        "closed form {:.1e} rad",
        worst[0]
    );
    assert!(
        worst[1] <= 0.1 * budget_rad * R,
        "closed form {:.1e} m",
        worst[1]
    );
}

#[test]
fn piecewise_power_law_matches_the_exact_rays() {
    // Ground to 40 m: dn/dh = −1e-7 (super-refracting, rays still curve less than the Earth);
    // 40–120 m: −4e-7 (ducting, rays curve 2.5× more than the Earth); above: −0.5e-7 (nearly
    // normal). n is continuous, dn/dh jumps at 40 m and 120 m.
    let layers = PowerLayers::new(1.000_3, [0.0, 40.0, 120.0], [-1e-7, -4e-7, -0.5e-7]);
    let index = layers.index();
    let top = 20e3;
    // A level ray in the duct layer whose perigee lies 0.05 mm below its base at 40 m: the
    // excursion into the ground layer lasts ≈ 75 m of ground distance, inside one step.
    let depth = 5e-5;
    let (m_ground, m_duct) = (layers.k[0] + 1.0, layers.k[1] + 1.0);
    let grazing_h0 = 40.0 + m_ground * depth / -m_duct;
    let rays = [
        (10.0, -0.3),      // straight to the ground
        (45.0, 0.0),       // ducted: 9 crossings of 40 m, turning in both layers
        (10.0, 0.0),       // ducted from below: 8 crossings
        (40.0, 0.02),      // launched on a boundary, upward: ducted, 39 crossings
        (40.0, -0.02),     // the same, downward
        (grazing_h0, 0.0), // perigees 0.05 mm below 40 m: 5801 crossings in 300 km
        (60.0, 0.05),      // turns down in the duct, through 40 m to the ground
        (80.0, -0.05),     // down through the duct to the ground
        (119.0, 0.0),      // just under a boundary: turns in the duct, to the ground
        (119.0, 0.01),     // the same, with an apex just under 120 m
        (2.0, 0.2),        // up into the duct, turned back to the ground
        (2.0, 0.1),        // the same
        (150.0, -0.1),     // perigee inside the top layer
        (150.0, -0.2),     // down through both boundaries to the ground
        (120.0, 0.0),      // launched on a boundary into the upper layer
        (100.0, 0.2),      // climbs out of the duct through 120 m
        (100.0, 0.5),      // the same, steeper
        (30.0, 2.0),       // steep, through both boundaries
        (5.0, 5.0),        // escapes through the top (20 km)
    ];
    let (mut worst, mut ducted, mut grounded, mut escaped) = ((0.0f64, 0.0f64), 0, 0, 0);
    for (h0, deg) in rays {
        let a = f64::to_radians(deg);
        let (exact, ev) = layers.exact(top, h0, a, &DISTANCES_M);
        let got = reference_heights(&index, R, top, h0, a, &DISTANCES_M);
        let label = format!("power law {h0} m {deg}°");
        let w = compare(&label, &got, &exact, &DISTANCES_M);
        eprintln!(
            "{label}: {} crossings, {} turns, end {:?}; max |Δh| {:.1e} / {:.1e} m",
            ev.crossings,
            ev.turns,
            exact.last().unwrap(),
            w.0,
            w.1
        );
        worst = (worst.0.max(w.0), worst.1.max(w.1));
        ducted += usize::from(ev.crossings >= 4 && ev.turns >= 4);
        grounded += usize::from(exact.last() == Some(&RefReach::GroundBefore));
        escaped += usize::from(exact.last() == Some(&RefReach::EscapedBefore));
    }
    assert!(
        ducted >= 2 && grounded >= 1 && escaped >= 1,
        "{ducted} {grounded} {escaped}"
    );
    eprintln!(
        "piecewise power law: max |Δh| {:.1e} m (≤ 30 km), {:.1e} m (≤ 300 km)",
        worst.0, worst.1
    );
}

fn repo_file(rel: &str) -> std::path::PathBuf {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    assert!(path.exists(), "missing test input {}", path.display());
    path
}

fn synthetic(name: &str) -> SyntheticAtmosphere {
    SyntheticAtmosphere::from_file(&repo_file(&format!("data/{name}.toml"))).unwrap()
}

fn fitted(name: &str) -> Profile {
    let sounding = read_sounding(&repo_file(&format!("data/{name}")), &ReadOptions::default());
    Profile::from_sounding(&sounding.unwrap(), &FitOptions::default()).unwrap()
}

fn refractive<C: ghostship::profile::AirColumn + Clone + 'static>(c: &C) -> RefractiveAtmosphere {
    RefractiveAtmosphere::new(Arc::new(c.clone()), 550.0).unwrap()
}

/// The step-halving estimates the convergence test asserts: up to 30 km, and beyond (to 300 km).
const ESTIMATE_30_KM_M: f64 = 1e-8;
const ESTIMATE_300_KM_M: f64 = 1e-7;

/// Every kind of atmosphere the reference is meant for, with an observer height for each.
fn atmospheres() -> Vec<(String, RefractiveAtmosphere, f64, Column)> {
    let mut out = Vec::new();
    for (name, h0) in [
        ("fata_morgana", 20.0),
        ("superior_mirage", 20.0),
        ("inferior_mirage", 2.0),
        ("novaya_zemlya", 5.0),
    ] {
        let s = synthetic(name);
        out.push((
            name.to_string(),
            refractive(&s),
            h0,
            Column::Synthetic(Box::new(s)),
        ));
    }
    for name in [
        "Bjornoya-01028_2024022611.csv",
        "Danmarkshavn-04320_2026020523_all-levels.csv",
    ] {
        let p = fitted(name);
        out.push((
            name.to_string(),
            refractive(&p),
            20.0,
            Column::Profile(Box::new(p)),
        ));
    }
    let st = StandardAtmosphere::default();
    out.push((
        "us1976".to_string(),
        refractive(&st),
        20.0,
        Column::Standard(st),
    ));
    out
}

/// An owned column, lent to [`BreakSource`].
enum Column {
    Profile(Box<Profile>),
    Synthetic(Box<SyntheticAtmosphere>),
    Standard(StandardAtmosphere),
}

impl Column {
    fn source(&self) -> BreakSource<'_> {
        match self {
            Column::Profile(p) => BreakSource::Profile(p),
            Column::Synthetic(s) => BreakSource::Synthetic(s),
            Column::Standard(s) => BreakSource::Standard(s),
        }
    }
}

#[test]
fn step_halving_estimates_are_below_the_stated_bounds() {
    // A fan of 12 rays (−0.5° … +1°) to 30 km every kilometre, and two rays to 300 km, in the
    // piecewise power law and in every kind of modelled atmosphere (exact Ciddor evaluation).
    let fan: Vec<f64> = (0..12).map(|i| -0.5 + 1.5 * i as f64 / 11.0).collect();
    let near: Vec<f64> = (1..=30).map(|i| i as f64 * 1000.0).collect();
    let far = [50e3, 100e3, 200e3, 300e3];
    let layers = PowerLayers::new(1.000_3, [0.0, 40.0, 120.0], [-1e-7, -4e-7, -0.5e-7]);
    let check = |name: &str, index: &ReferenceIndex, h0: f64| {
        let (a, _) = worst_estimate(index, h0, &fan, &near);
        let (_, b) = worst_estimate(index, h0, &[0.0, 0.3], &far);
        eprintln!("{name}: step-halving estimate ≤ {a:.1e} m (30 km), ≤ {b:.1e} m (300 km)");
        assert!(
            a <= ESTIMATE_30_KM_M && b <= ESTIMATE_300_KM_M,
            "{name}: {a:e}, {b:e}"
        );
    };
    check("power law", &layers.index(), 20.0);
    for (name, atm, h0, column) in atmospheres() {
        check(&name, &atmosphere_index(&atm, column.source()), h0);
    }
}

/// The largest step-halving estimate over a fan, up to 30 km and beyond.
fn worst_estimate(
    index: &ReferenceIndex,
    h0: f64,
    fan_deg: &[f64],
    distances: &[f64],
) -> (f64, f64) {
    let mut worst = (0.0f64, 0.0f64);
    for &deg in fan_deg {
        let got = reference_heights_with_error(index, R, 20e3, h0, deg.to_radians(), distances);
        for ((_, e), d) in got.iter().zip(distances) {
            let w = if *d <= 30e3 {
                &mut worst.0
            } else {
                &mut worst.1
            };
            *w = w.max(*e);
        }
    }
    worst
}

#[test]
fn convergence_is_sixth_order() {
    // With steps large enough for the truncation error to dominate rounding (1.6 km of ground,
    // 1.6 m of height, then halved twice), successive differences shrink by 2⁶ = 64 through
    // the Fata Morgana's 15 m layers.
    let s = synthetic("fata_morgana");
    let atm = refractive(&s);
    let index = atmosphere_index(&atm, BreakSource::Synthetic(&s));
    let coarse = ReferenceSteps {
        max_ground_step_m: 1600.0,
        max_height_step_m: 1.6,
        fine: None,
    };
    for deg in [0.1, 0.2, 0.3, 0.5] {
        let a = f64::to_radians(deg);
        let h: Vec<f64> = [coarse, coarse.halved(), coarse.halved().halved()]
            .into_iter()
            .map(|st| reference_heights_with_steps(&index, R, 20e3, 20.0, a, &[30e3], st)[0])
            .map(|r| r.height_m().expect("the ray reaches 30 km"))
            .collect();
        let ratio = (h[0] - h[1]) / (h[1] - h[2]);
        eprintln!(
            "{deg}°: differences {:.1e}, {:.1e} m, ratio {ratio:.0}",
            h[0] - h[1],
            h[1] - h[2]
        );
        assert!((32.0..=128.0).contains(&ratio), "{deg}°: ratio {ratio}");
    }
}

#[test]
fn without_its_breaks_the_power_law_is_missed() {
    // The same rays with the boundaries withheld: steps straddle the kinks and the heights are
    // off by far more than the tolerance, so the exact comparison above does test the break
    // handling.
    let layers = PowerLayers::new(1.000_3, [0.0, 40.0, 120.0], [-1e-7, -4e-7, -0.5e-7]);
    let blind = ReferenceIndex::new(|h| layers.n_and_dndh(h), vec![]);
    let mut worst = 0.0f64;
    for (h0, deg) in [(45.0, 0.0), (10.0, 0.0), (100.0, 0.5)] {
        let a = f64::to_radians(deg);
        let (exact, _) = layers.exact(20e3, h0, a, &DISTANCES_M[..5]);
        let got = reference_heights(&blind, R, 20e3, h0, a, &DISTANCES_M[..5]);
        for (g, e) in got.iter().zip(&exact) {
            if let (Some(g), Some(e)) = (g.height_m(), e.height_m()) {
                worst = worst.max((g - e).abs());
            }
        }
    }
    eprintln!("without breaks: max |Δh| {worst:.1e} m up to 30 km");
    assert!(worst > 1e3 * TOLERANCE_30_KM_M, "{worst}");
}

/// dn/dh of `atm` just below and above `b` (m above the surface), and the change over the same
/// distance just above (what a smooth profile would give).
fn jump_at(index: &ReferenceIndex, b: f64) -> (f64, f64) {
    let eps = 1e-4;
    let d = |h: f64| (index.n_and_dndh)(h).1;
    (d(b + eps) - d(b - eps), d(b + 3.0 * eps) - d(b + eps))
}

#[test]
fn break_lists_follow_the_columns() {
    // US1976 layer bases: back at 11, 20, 32, 47, 51, 71 km geopotential, and dn/dh jumps there.
    let bases: Vec<f64> = us1976_bases_m().collect();
    for (b, g) in bases.iter().zip([11e3, 20e3, 32e3, 47e3, 51e3, 71e3]) {
        assert!((geometric_to_geopotential_m(*b) - g).abs() < 1e-8, "{b}");
    }
    let st = StandardAtmosphere::with_surface(120.0, 280.0, 99_000.0).unwrap();
    let atm = refractive(&st);
    let index = atmosphere_index(&atm, BreakSource::Standard(&st));
    let expected: Vec<f64> = bases.iter().chain(&[86e3]).map(|b| b - 120.0).collect();
    assert_eq!(index.breaks_m, expected);
    for &b in &expected[..6] {
        let (jump, smooth) = jump_at(&index, b);
        assert!(
            jump.abs() > 100.0 * smooth.abs(),
            "US1976 at {b} m: {jump:e} vs {smooth:e}"
        );
    }
    // Novaya Zemlya: the gradient layer's top (its base is the ground), the tropopause of the
    // lapse-rate background, the US1976 bases above it and the model top.
    let nz = synthetic("novaya_zemlya");
    let atm = refractive(&nz);
    let index = atmosphere_index(&atm, BreakSource::Synthetic(&nz));
    let mut expected = vec![100.0, 11_000.0];
    expected.extend(bases.iter().filter(|&&b| b > 11_000.0));
    expected.push(86e3);
    assert_eq!(index.breaks_m, expected);
    for &b in &expected[..2] {
        let (jump, smooth) = jump_at(&index, b);
        assert!(
            jump.abs() > 100.0 * smooth.abs(),
            "NZ at {b} m: {jump:e} vs {smooth:e}"
        );
    }
    // Smooth tanh layers add no breaks.
    let fm = synthetic("fata_morgana");
    let atm = refractive(&fm);
    assert_eq!(
        atmosphere_index(&atm, BreakSource::Synthetic(&fm)).breaks_m[0],
        11_000.0
    );
    // A fitted sounding: every knot above the surface, then the US1976 bases above the data.
    let p = fitted("Danmarkshavn-04320_2026020523_all-levels.csv");
    let atm = refractive(&p);
    let index = atmosphere_index(&atm, BreakSource::Profile(&p));
    let surface = atm.surface_height_m();
    let knots: Vec<f64> = p.levels()[1..]
        .iter()
        .map(|k| k.height_m - surface)
        .collect();
    assert_eq!(index.breaks_m[..knots.len()], knots[..]);
    let above: Vec<f64> = index.breaks_m[knots.len()..].to_vec();
    let top = p.top_of_data_m();
    let mut expected: Vec<f64> = bases
        .iter()
        .filter(|&&b| b > top)
        .map(|b| b - surface)
        .collect();
    expected.push(86e3 - surface);
    assert_eq!(above, expected);
    // The knots are real breaks: d²n/dh² jumps at (most of) them.
    let d2 = |h: f64| {
        let e = 1e-3;
        ((index.n_and_dndh)(h + e).1 - (index.n_and_dndh)(h - e).1) / (2.0 * e)
    };
    let kinked = knots
        .windows(3)
        .filter(|w| {
            let (b, gap) = (w[1], (w[2] - w[1]).min(w[1] - w[0]));
            let jump = d2(b + 0.01 * gap) - d2(b - 0.01 * gap);
            let smooth = d2(b + 0.03 * gap) - d2(b + 0.01 * gap);
            jump.abs() > 10.0 * smooth.abs()
        })
        .count();
    eprintln!(
        "Danmarkshavn: d²n/dh² jumps at {kinked} of {} inner knots",
        knots.len() - 2
    );
    assert!(kinked * 2 > knots.len() - 2);
}

#[test]
fn fan_cost() {
    // A 200-ray fan (−0.5° … +0.5° from 20 m) to 30 km through the exact Ciddor evaluation; times
    // are printed, not asserted.
    for (name, atm, _, column) in atmospheres() {
        if !matches!(
            name.as_str(),
            "fata_morgana" | "Bjornoya-01028_2024022611.csv"
        ) {
            continue;
        }
        let index = atmosphere_index(&atm, column.source());
        let calls = AtomicUsize::new(0);
        let counted = ReferenceIndex::new(
            |h| {
                calls.fetch_add(1, Ordering::Relaxed);
                (index.n_and_dndh)(h)
            },
            index.breaks_m.clone(),
        );
        let distances: Vec<f64> = (1..=30).map(|i| i as f64 * 1000.0).collect();
        let start = Instant::now();
        for i in 0..200 {
            let a = f64::to_radians(-0.5 + i as f64 / 199.0);
            reference_heights(&counted, R, 20e3, 20.0, a, &distances);
        }
        let t = start.elapsed();
        let n = calls.load(Ordering::Relaxed);
        eprintln!(
            "{name}: 200 rays to 30 km in {t:.2?} ({:.2?} per ray, {} evaluations of n per ray, \
             {:.2} µs each)",
            t / 200,
            n / 200,
            t.as_secs_f64() * 1e6 / n as f64
        );
    }
}

#[test]
fn hydrostatic_nodes_need_not_be_breaks() {
    // A synthetic atmosphere's pressure is a cubic Hermite in ln P through hydrostatic nodes
    // (0.25 m apart up to 2000 m here, 10 m above, per synthetic.rs), so d²n/dh² jumps slightly
    // at every node. The node heights are not in the public API; adding them as breaks (which
    // cuts every step there) changes the Fata Morgana fan's heights by no more than this.
    let fm = synthetic("fata_morgana");
    let atm = refractive(&fm);
    let index = atmosphere_index(&atm, BreakSource::Synthetic(&fm));
    let mut breaks = index.breaks_m.clone();
    breaks.extend((1..8000).map(|k| k as f64 * 0.25));
    breaks.extend((0..100).map(|k| 2000.0 + k as f64 * 10.0));
    let nodes = ReferenceIndex::new(|h| atm.exact(h), breaks);
    let distances: Vec<f64> = (1..=30).map(|i| i as f64 * 1000.0).collect();
    let mut worst = 0.0f64;
    for i in 0..12 {
        let a = f64::to_radians(-0.3 + 0.8 * i as f64 / 11.0);
        let plain = reference_heights(&index, R, 20e3, 20.0, a, &distances);
        let cut = reference_heights(&nodes, R, 20e3, 20.0, a, &distances);
        for (p, c) in plain.iter().zip(&cut) {
            match (p.height_m(), c.height_m()) {
                (Some(p), Some(c)) => worst = worst.max((p - c).abs()),
                _ => assert_eq!(p, c),
            }
        }
    }
    eprintln!("hydrostatic nodes as breaks: max |Δh| {worst:.1e} m up to 30 km");
    assert!(worst <= ESTIMATE_30_KM_M, "{worst}");
}
