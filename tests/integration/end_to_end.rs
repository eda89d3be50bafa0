//! End-to-end physics through the real stages: sounding file or synthetic TOML → profile →
//! Ciddor n(h) table ([`RefractiveAtmosphere`]) → tracer → transfer analysis. Expected values come
//! from /work/shared/notes/references.md (palRefro, the Nautical Almanac dip, the critical
//! gradient) or from properties (the exact field, continuity in elevation).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use ghostship::analysis::{Image, Reach, TransferCurve, find_images};
use ghostship::profile::{AirColumn, FitOptions, Profile, StandardAtmosphere, SyntheticAtmosphere};
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::sounding::{ReadOptions, read_sounding};
use ghostship::tracer::{StratifiedIndex, Termination, Tracer, TracerConfig};
use ghostship::units::ARCMIN_PER_RAD;

const EARTH_RADIUS_M: f64 = 6_371_000.0;

fn repo_file(rel: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    assert!(path.exists(), "missing test input {}", path.display());
    path
}

fn shared_sounding(name: &str) -> PathBuf {
    let path = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/soundings/")).join(name);
    assert!(path.exists(), "missing shared sounding {}", path.display());
    path
}

/// A paper atmosphere from `data/NAME.toml` through Ciddor at 550 nm with the default table.
fn paper(name: &str) -> RefractiveAtmosphere {
    let path = repo_file(&format!("data/{name}.toml"));
    let column = SyntheticAtmosphere::from_file(&path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    RefractiveAtmosphere::new(Arc::new(column), 550.0).expect("paper atmosphere refracts")
}

/// A fitted real sounding through Ciddor at 550 nm.
fn sounding(path: &Path) -> RefractiveAtmosphere {
    let s = read_sounding(path, &ReadOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let profile = Profile::from_sounding(&s, &FitOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    RefractiveAtmosphere::new(Arc::new(profile), 550.0).expect("sounding refracts")
}

/// The exact (untabulated) Ciddor field of an atmosphere, as the tracer sees an index.
struct Exact<'a>(&'a RefractiveAtmosphere);
impl StratifiedIndex for Exact<'_> {
    fn index_and_derivative(&self, height_m: f64) -> (f64, f64) {
        self.0.exact(height_m)
    }
}

fn config(tolerance_m: f64) -> TracerConfig {
    TracerConfig {
        tolerance_m,
        ..TracerConfig::default()
    }
}

fn linspace(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
        .collect()
}

/// Every image of a target [0, H] at each distance, from observer height `h0`, on a fan of
/// `count` rays between `lo_deg` and `hi_deg`.
#[allow(clippy::too_many_arguments)]
fn images_at<S: StratifiedIndex>(
    field: &S,
    h0: f64,
    lo_deg: f64,
    hi_deg: f64,
    count: usize,
    distances_m: &[f64],
    height_m: f64,
) -> Vec<Image> {
    let fan_cfg = TracerConfig {
        stop_after_last_target: true,
        ..config(0.01)
    };
    let tracer = Tracer::new(field, fan_cfg).unwrap();
    let elevations: Vec<f64> = linspace(lo_deg, hi_deg, count)
        .into_iter()
        .map(f64::to_radians)
        .collect();
    let records = tracer.trace_fan(h0, &elevations, distances_m).unwrap();
    let mut out = Vec::new();
    for (j, &d) in distances_m.iter().enumerate() {
        let curve = TransferCurve {
            distance_m: d,
            elevations_rad: elevations.clone(),
            reach: records.iter().map(|r| Reach::from_record(r, j)).collect(),
        };
        out.extend(find_images(&tracer, h0, &curve, height_m));
    }
    out
}

fn print_images(label: &str, images: &[Image]) {
    for im in images {
        eprintln!(
            "{label}: D {:5.1} km, H {:5.1} m: {:+.4}°…{:+.4}° {} (h {:.1}→{:.1} m, mag {:.2})",
            im.distance_m / 1000.0,
            im.height_m,
            im.elevation_min_deg,
            im.elevation_max_deg,
            if im.erect { "erect   " } else { "inverted" },
            im.height_at_min_m,
            im.height_at_max_m,
            im.magnification
        );
    }
}

#[test]
fn explore_scenes() {
    let d: Vec<f64> = (2..=26).map(|k| k as f64 * 1000.0).collect();
    for name in ["superior_mirage", "fata_morgana", "inferior_mirage"] {
        let atm = paper(name);
        for h0 in [1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 40.0, 60.0, 80.0, 100.0, 120.0, 140.0] {
            let images = images_at(&atm, h0, -0.6, 0.6, 1201, &d, 250.0);
            let mut summary = String::new();
            for &dd in &d {
                let at: Vec<&Image> = images.iter().filter(|im| im.distance_m == dd).collect();
                if at.len() > 1 {
                    summary += &format!(" {}km:{}", dd / 1000.0, at.iter().map(|im| if im.erect { 'E' } else { 'I' }).collect::<String>());
                }
            }
            eprintln!("SCAN {name} h0 {h0}:{summary}");
        }
    }
}

/// Lowest elevation whose ray does not reach the ground (bisection on fresh traces).
fn sea_horizon_rad<S: StratifiedIndex>(tracer: &Tracer<'_, S>, h0: f64) -> f64 {
    let hits = |a: f64| tracer.trace(h0, a, &[]).unwrap().termination == Some(Termination::Ground);
    let (mut lo, mut hi) = (-0.02, 0.0);
    assert!(hits(lo) && !hits(hi));
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if hits(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Check 1: US1976 (StandardAtmosphere at 15 °C, 1013.25 hPa) → Ciddor 550 nm dry table → tracer
/// to 80 km reproduces palRefro (references.md §2.1) and the Nautical Almanac dip (§2.2).
#[test]
fn us1976_ciddor_table_matches_palrefro_and_the_almanac_dip() {
    let column = StandardAtmosphere::with_surface(0.0, 288.15, 101_325.0).unwrap();
    let atm = RefractiveAtmosphere::new(Arc::new(column), 550.0).unwrap();
    // Ciddor (450 ppm CO₂) vs the SLALIB optical form A·P/T that palRefro's model uses (§2.6).
    let (ciddor_nm1, _) = atm.exact_refractivity(0.0);
    let l2: f64 = 0.55 * 0.55;
    let a = (287.6155 + 1.62887 / l2 + 0.01360 / (l2 * l2)) * 273.15e-6 / 1013.25;
    let slalib_nm1 = a * 1013.25 / 288.15;
    let ratio = ciddor_nm1 / slalib_nm1;
    eprintln!(
        "surface n−1: Ciddor {ciddor_nm1:.4e}, SLALIB A·P/T {slalib_nm1:.4e}: refraction scales by \
         ≈ {ratio:.5} → expected shift at the horizon ≈ {:+.4}′",
        (ratio - 1.0) * 33.0
    );
    assert!((ciddor_nm1 - 277.838e-6).abs() < 0.002e-6, "{ciddor_nm1}");
    let cfg = TracerConfig {
        top_m: 80_000.0,
        ..config(0.001)
    };
    let tracer = Tracer::new(&atm, cfg).unwrap();
    // palRefro, 15 °C, 1013.25 hPa, 0.55 µm, dry: observed ZD → arcmin.
    let cases = [
        (45.0, 0.953, 0.02),
        (80.0, 5.223, 0.02),
        (85.0, 9.666, 0.02),
        (88.0, 17.789, 0.02),
        (89.0, 23.545, 0.02),
        (89.5, 27.650, 0.02),
        (90.0, 33.000, 0.05),
    ];
    for (zd, expected, tol) in cases {
        let alpha = (90.0_f64 - zd).to_radians();
        let rec = tracer.trace(0.0, alpha, &[]).unwrap();
        assert_eq!(rec.termination, Some(Termination::Escaped), "ZD {zd}");
        let got = rec.refraction_rad.unwrap() * ARCMIN_PER_RAD;
        eprintln!(
            "US1976/Ciddor ZD {zd}: {got:.4}′ (palRefro {expected}′, Δ {:+.4}′), {} steps \
             ({} rejected), invariant drift {:.1e}",
            got - expected,
            rec.steps(),
            rec.rejected_steps,
            rec.invariant_drift
        );
        assert!(
            (got - expected).abs() < tol,
            "ZD {zd}: {got}′ vs {expected}′"
        );
        assert!(rec.invariant_drift < 1e-9, "ZD {zd}: drift {}", rec.invariant_drift);
    }
    // Dip of the sea horizon from 10 m: Nautical Almanac 1.76′·√h (k ≈ 0.164), and the circle of
    // curvature k/R with k from the table's own dn/dh (§2.2: k(ISA) = 0.170).
    let h0 = 10.0;
    let dip = -sea_horizon_rad(&tracer, h0);
    let (n, dn) = atm.index_and_derivative(h0 / 2.0);
    let k = -EARTH_RADIUS_M * dn / n;
    let circle = (2.0 * h0 * (1.0 - k) / EARTH_RADIUS_M).sqrt();
    eprintln!(
        "US1976/Ciddor dip at 10 m: {:.4}′ (circle k = {k:.4}: {:.4}′; Nautical Almanac {:.3}′)",
        dip * ARCMIN_PER_RAD,
        circle * ARCMIN_PER_RAD,
        1.76 * h0.sqrt()
    );
    assert!((k - 0.170).abs() < 0.005, "k {k}");
    assert!(((dip - circle) * ARCMIN_PER_RAD).abs() < 0.005);
    assert!((dip * ARCMIN_PER_RAD - 1.76 * h0.sqrt()).abs() < 0.05);
}

/// Check 2: the paper's claim through data/novaya_zemlya.toml (+0.112 K/m from 0 °C, 1013.25 hPa):
/// a horizontal ray at the surface bends with Earth's curvature to within 1 %. The ray's curvature
/// is measured from its traced heights: relative to the sphere, h(x) = x²·(1/R − κ)/2 + O(x³).
#[test]
fn novaya_zemlya_ground_ray_follows_the_earth() {
    let atm = paper("novaya_zemlya");
    let (n0, dn0) = atm.index_and_derivative(0.0);
    let table_curvature = -dn0 / n0;
    let tracer = Tracer::new(&atm, config(1e-5)).unwrap();
    let distances = [1000.0, 2000.0, 3000.0, 4000.0, 5000.0];
    let rec = tracer.trace(0.0, 0.0, &distances).unwrap();
    eprintln!("NZ ground ray: {:?}, heights {:?}", rec.termination, rec.heights_m);
    // Least squares h = c·x² (the x³ term, from dκ/dh over millimetres, is negligible).
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (h, x) in rec.heights_m.iter().zip(distances) {
        let h = h.expect("ray reaches every distance");
        sxy += h * x * x;
        sxx += x.powi(4);
    }
    let c = sxy / sxx;
    let ray_curvature = 1.0 / EARTH_RADIUS_M - 2.0 * c;
    eprintln!(
        "NZ: ray curvature {:.5}/R, table −(dn/dh)/n at 0 m {:.5}/R",
        ray_curvature * EARTH_RADIUS_M,
        table_curvature * EARTH_RADIUS_M
    );
    assert!((ray_curvature * EARTH_RADIUS_M - 1.0).abs() < 0.01);
    assert!((table_curvature * EARTH_RADIUS_M - 1.0).abs() < 0.01);
    // The tracer's curvature equals the field's (the height error 1e-5 m at 5 km is 1e-6/R).
    assert!(((ray_curvature - table_curvature) * EARTH_RADIUS_M).abs() < 1e-3);
}

/// Largest |Δh| left after bisecting the gap between fan rays `lo` and `hi` 40 times, always
/// keeping the half with the larger jump: a continuous h(D; α) closes the gap (down to the
/// tracer's own noise), a spurious jump does not.
fn residual_jump<S: StratifiedIndex>(tracer: &Tracer<'_, S>, h0: f64, d: f64, lo: (f64, f64), hi: (f64, f64)) -> f64 {
    let probe = |a: f64| match tracer.trace(h0, a, &[d]).unwrap().heights_m[0] {
        Some(h) => h,
        None => f64::NAN,
    };
    let (mut a, mut b) = (lo, hi);
    for _ in 0..40 {
        let m = 0.5 * (a.0 + b.0);
        let hm = probe(m);
        if !hm.is_finite() {
            return 0.0; // the gap holds a ray that ends before D: a band edge, not a jump
        }
        if (hm - a.1).abs() >= (b.1 - hm).abs() {
            b = (m, hm);
        } else {
            a = (m, hm);
        }
    }
    (b.1 - a.1).abs()
}

/// Check 4: real soundings (Bjornoya from data/, Trois-Rivieres from shared/) through the fit
/// and the table: every ray of a fan ends with a reason, Bouguer's invariant holds, h(D; α) is
/// continuous in α; prints µs per ray, the rejected-step ratio and the table's exact cells.
#[test]
fn real_soundings_trace_cleanly_and_continuously() {
    let cases = [
        ("Bjornoya", repo_file("data/Bjornoya-01028_2024022611.csv")),
        ("TroisRivieres", shared_sounding("TroisRivieres-UQAM_2022022222.csv")),
    ];
    let h0 = 10.0;
    let distances: Vec<f64> = (1..=30).map(|k| k as f64 * 1000.0).collect();
    let elevations: Vec<f64> = linspace(-0.5, 0.5, 401)
        .into_iter()
        .map(f64::to_radians)
        .collect();
    for (name, path) in cases {
        let t = Instant::now();
        let atm = sounding(&path);
        let build_s = t.elapsed().as_secs_f64();
        let err = atm.table_max_error();
        let cfg = config(0.01);
        let tol = cfg.tolerance_m;
        let tracer = Tracer::new(&atm, cfg).unwrap();
        let t = Instant::now();
        let mut records = Vec::with_capacity(elevations.len());
        for &a in &elevations {
            records.push(tracer.trace(h0, a, &distances).unwrap());
        }
        let us_per_ray = t.elapsed().as_secs_f64() * 1e6 / elevations.len() as f64;
        let steps: u64 = records.iter().map(|r| r.steps() as u64).sum();
        let rejected: u64 = records.iter().map(|r| r.rejected_steps as u64).sum();
        let drift = records.iter().map(|r| r.invariant_drift).fold(0.0, f64::max);
        eprintln!(
            "{name}: build {build_s:.3} s, table exact cells {} (max |Δn| {:.1e}, |Δdn/dh| {:.1e}), \
             {us_per_ray:.0} µs/ray (1 thread), {:.0} steps/ray, rejected {:.1} %, max drift {drift:.1e}",
            err.exact_cells(),
            err.max_abs_dn(),
            err.max_abs_ddndh_per_m(),
            steps as f64 / records.len() as f64,
            100.0 * rejected as f64 / steps as f64
        );
        for r in &records {
            let reason = r.termination.expect("every ray ends with a reason");
            assert!(
                matches!(
                    reason,
                    Termination::Ground | Termination::Escaped | Termination::TargetsDone
                ),
                "{name}: ray {:.4}° ended with {reason}",
                r.elevation_rad.to_degrees()
            );
            // Position errors of a few tolerances over the path bound the drift by ~tol/R.
            assert!(
                r.invariant_drift < 10.0 * tol / EARTH_RADIUS_M,
                "{name}: ray {:.4}° drift {}",
                r.elevation_rad.to_degrees(),
                r.invariant_drift
            );
        }
        // Continuity: a gap between neighbouring rays much larger than its neighbours' gaps
        // must close under bisection.
        let mut flagged = 0;
        let mut worst: f64 = 0.0;
        for (j, &d) in distances.iter().enumerate() {
            let h: Vec<f64> = records
                .iter()
                .map(|r| r.heights_m[j].unwrap_or(f64::NAN))
                .collect();
            for i in 1..h.len().saturating_sub(2) {
                let gap = (h[i + 1] - h[i]).abs();
                let side = (h[i] - h[i - 1]).abs().max((h[i + 2] - h[i + 1]).abs());
                if !(gap.is_finite() && side.is_finite()) || gap <= 3.0 * side + 5.0 * tol {
                    continue;
                }
                flagged += 1;
                let left = residual_jump(
                    &tracer,
                    h0,
                    d,
                    (elevations[i], h[i]),
                    (elevations[i + 1], h[i + 1]),
                );
                worst = worst.max(left);
                assert!(
                    left < 5.0 * tol,
                    "{name}: D {d} m, α {:.5}°…{:.5}°: gap {gap:.3} m (neighbours {side:.3} m) \
                     leaves {left:.3} m after bisection",
                    elevations[i].to_degrees(),
                    elevations[i + 1].to_degrees()
                );
            }
        }
        eprintln!("{name}: {flagged} steep gaps bisected, worst residual {worst:.2e} m");
    }
}

/// Check 5: the table and the exact Ciddor field give the same ray heights at 26 km for each
/// paper atmosphere.
#[test]
fn table_and_exact_field_agree_at_26_km() {
    let h0 = 10.0;
    let d = [26_000.0];
    let elevations: Vec<f64> = linspace(-0.3, 0.5, 161)
        .into_iter()
        .map(f64::to_radians)
        .collect();
    for name in ["superior_mirage", "inferior_mirage", "fata_morgana", "novaya_zemlya"] {
        let atm = paper(name);
        let exact = Exact(&atm);
        let cfg = config(1e-3);
        let table_tracer = Tracer::new(&atm, cfg.clone()).unwrap();
        let exact_tracer = Tracer::new(&exact, cfg).unwrap();
        let mut worst: f64 = 0.0;
        let mut worst_at = 0.0;
        for &a in &elevations {
            let t = table_tracer.trace(h0, a, &d).unwrap();
            let e = exact_tracer.trace(h0, a, &d).unwrap();
            match (t.heights_m[0], e.heights_m[0]) {
                (Some(ht), Some(he)) => {
                    if (ht - he).abs() > worst {
                        worst = (ht - he).abs();
                        worst_at = a.to_degrees();
                    }
                }
                (None, None) => assert_eq!(t.termination, e.termination, "{name} {a}"),
                other => panic!("{name} α {:.4}°: table/exact {other:?}", a.to_degrees()),
            }
        }
        eprintln!("{name}: table vs exact at 26 km: worst |Δh| {worst:.2e} m at {worst_at:.4}°");
    }
}

#[test]
fn probe_m() {
    for name in ["superior_mirage", "inferior_mirage", "fata_morgana", "novaya_zemlya"] {
        let atm = paper(name);
        let m = |h: f64| (atm.exact_refractivity(h).0 + h / EARTH_RADIUS_M) * 1e6;
        let mut line = String::new();
        for h in [0.0, 2.0, 5.0, 10.0, 15.0, 20.0, 30.0, 50.0, 70.0, 80.0, 90.0, 100.0, 110.0, 120.0, 130.0, 150.0, 200.0] {
            line += &format!(" {h}:{:.3}", m(h) - m(10.0));
        }
        eprintln!("{name} M(h)-M(10):{line}");
        // lowest camera height that sees a duct: min over h0 of whether min_{h>h0} M(h) < M(h0)
    }
}
