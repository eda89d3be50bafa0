//! End-to-end physics through the real stages: sounding file or synthetic TOML → profile →
//! Ciddor n(h) table ([`RefractiveAtmosphere`]) → tracer → transfer analysis. Expected values come
//! from docs/references.md (palRefro, the Nautical Almanac dip, the critical
//! gradient) or from properties (the exact field, continuity in elevation).

use super::support::data::{self as paths, repo_file};
use super::tracer::{PALREFRO_US1976_550NM, sea_horizon_rad};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use ghostship::analysis::{Image, Reach, TransferCurve, find_images};
use ghostship::profile::{FitOptions, Profile, StandardAtmosphere, SyntheticAtmosphere};
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::sounding::{ReadOptions, read_sounding};
use ghostship::tracer::{RayRecord, StratifiedIndex, Termination, Tracer, TracerConfig};
use ghostship::units::ARCMIN_PER_RAD;

const EARTH_RADIUS_M: f64 = 6_371_000.0;

/// A paper atmosphere from `data/NAME.toml` through Ciddor at 550 nm with the default table.
fn paper(name: &str) -> RefractiveAtmosphere {
    let path = repo_file(&format!("data/{name}.toml"));
    let column =
        SyntheticAtmosphere::from_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
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
    fn breaks_m(&self) -> &[f64] {
        self.0.breaks_m()
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

/// Modified refractivity M(h) = n − 1 + h/R (exact): a ray launched at elevation α from h₀ turns
/// downward only where M falls below M(h₀) − α²/2 (Bouguer's invariant, small angles).
fn modified_refractivity(atm: &RefractiveAtmosphere, h: f64) -> f64 {
    atm.exact_refractivity(h).0 + h / EARTH_RADIUS_M
}

/// One fold of h(D; α) from the independent reference: (α deg, h m).
type Extremum = (f64, f64);

/// The images between two successive extrema of h(D; α) must start and end there. Tolerances:
/// 0.005° in α (a flat extremum's location moves by √(2δh/|h″|) for a height error δh of a
/// centimetre) and 0.05 m in h (the tracer's 1 cm plus the reference's own model differences:
/// constant g, Simpson-integrated pressure).
fn assert_folds(label: &str, images: &[Image], extrema: &[Extremum]) {
    assert_eq!(
        images.len(),
        extrema.len() + 1,
        "{label}: {} images for {} folds",
        images.len(),
        extrema.len()
    );
    for (k, pair) in images.windows(2).enumerate() {
        let (lower, upper) = (&pair[0], &pair[1]);
        assert_ne!(
            lower.erect,
            upper.erect,
            "{label}: images {k}, {} alternate",
            k + 1
        );
        let (alpha, h) = extrema[k];
        assert!(
            (lower.elevation_max_deg - alpha).abs() < 0.005
                && (upper.elevation_min_deg - alpha).abs() < 0.005,
            "{label}: fold {k} at {:.4}° (reference {alpha:.4}°)",
            lower.elevation_max_deg
        );
        assert!(
            (lower.height_at_max_m - h).abs() < 0.05 && (upper.height_at_min_m - h).abs() < 0.05,
            "{label}: fold {k} at {:.3} m (reference {h:.3} m)",
            lower.height_at_max_m
        );
    }
    assert!(images[0].erect, "{label}: the lowest image is erect");
}

const SCENE_TARGET_M: f64 = 250.0;

/// Check 3, camera at 10 m as in the paper's figures, targets [0, 250 m] at 5…26 km. What the
/// three paper atmospheres show from there:
/// * superior_mirage: nothing but one erect image. No ray from 10 m turns down: M above the
///   layer stays above M(10 m) (checked here), so the duct is out of reach from below ~30 m;
/// * fata_morgana: one erect image out to 26 km; the upper layer turns rays with α < 0.17°,
///   but they come back down only beyond ≈ 30 km;
/// * inferior_mirage: no inverted image at ≤ 10 km (the camera is inside the 15 m hot layer, whose
///   rays do not cross before then); from 12 km on an inverted strip appears below the horizon.
///
/// Reference folds: an independent pure-Python RK4 trace (arc-length step 1 m, cross-checked at
/// 0.5 m) of the same TOML atmospheres with dry Ciddor n(h): tests/reference/mirage_folds.py.
#[test]
fn paper_scenes_from_a_10_m_camera() {
    let h0 = 10.0;
    let distances: Vec<f64> = (5..=26).map(|k| k as f64 * 1000.0).collect();
    let superior = paper("superior_mirage");
    let m0 = modified_refractivity(&superior, h0);
    let above: Vec<f64> = (1..=2900)
        .map(|i| modified_refractivity(&superior, h0 + 0.1 * i as f64))
        .collect();
    let duct_floor = above[400..].iter().copied().fold(f64::INFINITY, f64::min);
    eprintln!(
        "superior_mirage: lowest M in 50…300 m is {:.3e} above M(10 m)",
        duct_floor - m0
    );
    assert!(
        above.iter().all(|&m| m > m0),
        "a ray from 10 m could turn in the superior layer"
    );
    for name in ["superior_mirage", "fata_morgana"] {
        let atm = paper(name);
        let images = images_at(&atm, h0, -0.6, 0.6, 1201, &distances, SCENE_TARGET_M);
        print_images(&format!("{name} from 10 m"), &images);
        for &d in &distances {
            let at: Vec<&Image> = images.iter().filter(|im| im.distance_m == d).collect();
            assert!(at.len() == 1 && at[0].erect, "{name} at {d} m: {at:?}");
        }
    }
    let inferior = paper("inferior_mirage");
    let near: Vec<f64> = (1..=10).map(|k| k as f64 * 1000.0).collect();
    let images = images_at(&inferior, h0, -0.6, 0.6, 1201, &near, SCENE_TARGET_M);
    print_images("inferior_mirage from 10 m", &images);
    assert!(
        images.iter().all(|im| im.erect),
        "no inverted image within 10 km"
    );
    let images = images_at(&inferior, h0, -0.6, 0.6, 1201, &[13_000.0], SCENE_TARGET_M);
    print_images("inferior_mirage from 10 m", &images);
    assert_folds(
        "inferior 13 km",
        &images,
        &[(-0.1079, 33.717), (-0.0589, 33.264)],
    );
    assert!(
        images[1].elevation_max_deg < 0.0,
        "the inverted image is below the horizon"
    );
}

/// Check 3 continued: where the superior mirage and the Fata Morgana do form within 26 km: from a
/// camera at 80 m (inside the ducts' reach), targets at 20 km show erect/inverted/erect (superior)
/// and five alternating images (Fata Morgana); the folds match the independent reference.
#[test]
fn paper_mirages_from_an_80_m_camera() {
    let h0 = 80.0;
    let superior = paper("superior_mirage");
    let images = images_at(&superior, h0, -0.6, 0.6, 1201, &[20_000.0], SCENE_TARGET_M);
    print_images("superior_mirage from 80 m", &images);
    assert_folds(
        "superior 20 km",
        &images,
        &[(-0.0118, 97.550), (0.1797, 69.107)],
    );
    let fata = paper("fata_morgana");
    let images = images_at(&fata, h0, -0.6, 0.6, 1201, &[20_000.0], SCENE_TARGET_M);
    print_images("fata_morgana from 80 m", &images);
    assert_folds(
        "fata morgana 20 km",
        &images,
        &[
            (0.0005, 59.215),
            (0.0808, 55.191),
            (0.1291, 118.611),
            (0.2366, 93.772),
        ],
    );
}

/// Check 1: US1976 (StandardAtmosphere at 15 °C, 1013.25 hPa) → Ciddor 550 nm dry table → tracer
/// to 80 km reproduces palRefro (docs/references.md §2.1) and the Nautical Almanac dip (§2.2).
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
    // README's accuracy table: within 0.005′ at 45…89.5°, within 0.01′ at the horizon.
    for (zd, expected) in PALREFRO_US1976_550NM {
        let tol = if zd < 90.0 { 0.005 } else { 0.01 };
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
/// a horizontal ray at the surface bends with Earth's curvature to within 1 %. The ray's
/// curvature κ is measured from its traced heights: relative to the sphere, a ray launched
/// horizontally at h₀ has h(x) − h₀ = x²·(1/R − κ)/2 + O(x³).
///
/// With the full Ciddor formula κ(0) is 1.0019/R, slightly *above* Earth's: the gradient is a
/// little super-critical at the ground (a ray launched horizontally at exactly h = 0 goes into
/// the ground at once), so the ray is launched at 5 cm. The ideal-gas estimate
/// (n − 1 ∝ P/T, as in docs/references.md §2.3) gives 0.9991/R; the 0.28 % difference is the
/// temperature dependence of the compressibility Z in Ciddor's density (second virial term).
#[test]
fn novaya_zemlya_ground_ray_follows_the_earth() {
    let atm = paper("novaya_zemlya");
    let h0 = 0.05;
    let (n0, dn0) = atm.index_and_derivative(0.0);
    let (n_h0, dn_h0) = atm.index_and_derivative(h0);
    let table_curvature = -dn0 / n0;
    let table_curvature_h0 = -dn_h0 / n_h0;
    let air = atm.sample_at(atm.surface_height_m()).air;
    let ideal_curvature = -(n0 - 1.0) / n0
        * (air.dpressure_dh_pa_per_m / air.pressure_pa
            - air.dtemperature_dh_k_per_m / air.temperature_k);
    let tracer = Tracer::new(&atm, config(1e-6)).unwrap();
    let distances = [1000.0, 2000.0, 3000.0, 4000.0, 5000.0];
    let rec = tracer.trace(h0, 0.0, &distances).unwrap();
    // Least squares h − h₀ = c·x² (the x³ term, from dκ/dh over millimetres, is negligible).
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (h, x) in rec.heights_m.iter().zip(distances) {
        let h = h.expect("ray reaches every distance");
        sxy += (h - h0) * x * x;
        sxx += x.powi(4);
    }
    let c = sxy / sxx;
    let ray_curvature = 1.0 / EARTH_RADIUS_M - 2.0 * c;
    eprintln!(
        "NZ: ray from {h0} m: heights {:?}; curvature {:.5}/R; table −(dn/dh)/n {:.5}/R at {h0} m,          {:.5}/R at 0 m; ideal-gas estimate at 0 m {:.5}/R",
        rec.heights_m,
        ray_curvature * EARTH_RADIUS_M,
        table_curvature_h0 * EARTH_RADIUS_M,
        table_curvature * EARTH_RADIUS_M,
        ideal_curvature * EARTH_RADIUS_M
    );
    // The paper's claim.
    assert!((ray_curvature * EARTH_RADIUS_M - 1.0).abs() < 0.01);
    assert!((table_curvature * EARTH_RADIUS_M - 1.0).abs() < 0.01);
    // The tracer bends the ray as the table says (the fit's error is ~1e-6 m / x² ≈ 1e-5/R).
    assert!(((ray_curvature - table_curvature_h0) * EARTH_RADIUS_M).abs() < 1e-4);
    // Independent Ciddor evaluation (dry air, 550 nm, 450 ppm; tests/reference/mirage_folds.py, central
    // difference in h): κ(0)·R = 1.00194.
    assert!((table_curvature * EARTH_RADIUS_M - 1.00194).abs() < 5e-5);
    // Ideal gas: 0.99908 by hand from n − 1 = 2.931467e-4, dlnP/dh = −1.250713e-4 m⁻¹ and
    // dlnT/dh = 0.112/273.15 m⁻¹ (within the references' 0.99959 for 0.1121 K/m and n − 1 ∝ P/T).
    assert!((ideal_curvature * EARTH_RADIUS_M - 0.99908).abs() < 5e-5);
}

/// Largest |Δh| left after bisecting the gap between fan rays `lo` and `hi` 40 times, always
/// keeping the half with the larger jump: a continuous h(D; α) closes the gap (down to the
/// tracer's own noise), a spurious jump does not.
fn residual_jump<S: StratifiedIndex>(
    tracer: &Tracer<'_, S>,
    h0: f64,
    d: f64,
    lo: (f64, f64),
    hi: (f64, f64),
) -> f64 {
    let probe = |a: f64| tracer.trace(h0, a, &[d]).unwrap().heights_m[0].unwrap_or(f64::NAN);
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

/// Check 4: real soundings (Bjornoya from data/, Trois-Rivieres from tests/data/) through the fit
/// and the table: every ray of a fan ends with a reason, Bouguer's invariant holds, h(D; α) is
/// continuous in α; prints µs per ray, the rejected-step ratio and the table's exact cells.
#[test]
fn real_soundings_trace_cleanly_and_continuously() {
    let cases = [
        ("Bjornoya", repo_file("data/Bjornoya-01028_2024022611.csv")),
        (
            "TroisRivieres",
            paths::sounding("TroisRivieres-UQAM_2022022222.csv"),
        ),
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
        // The same fan through the exact (untabulated) field, for comparison only.
        let exact = Exact(&atm);
        let exact_tracer = Tracer::new(&exact, config(tol)).unwrap();
        let t = Instant::now();
        for &a in &elevations {
            exact_tracer.trace(h0, a, &distances).unwrap();
        }
        let exact_us_per_ray = t.elapsed().as_secs_f64() * 1e6 / elevations.len() as f64;
        let steps: u64 = records.iter().map(|r| r.steps() as u64).sum();
        let rejected: u64 = records.iter().map(|r| r.rejected_steps as u64).sum();
        let drift = records
            .iter()
            .map(|r| r.invariant_drift)
            .fold(0.0, f64::max);
        eprintln!(
            "{name}: build {build_s:.3} s, table exact cells {} (max |Δn| {:.1e}, |Δdn/dh| {:.1e}), \
             {us_per_ray:.0} µs/ray (1 thread; exact field {exact_us_per_ray:.0}), {:.0} steps/ray, rejected {:.1} %, max drift {drift:.1e}",
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
            // Each accepted step errs by at most tol in position and tol/L in direction; the
            // relative invariant n·r·cos ψ then moves by ≤ tol/R + tan ψ·tol/L per step (ψ stays
            // below 0.02 rad in this fan out to 30 km), and the errors add at most linearly.
            let bound = r.accepted_steps as f64
                * tol
                * (1.0 / EARTH_RADIUS_M + 0.02 / TracerConfig::default().error_length_m);
            assert!(
                r.invariant_drift <= bound,
                "{name}: ray {:.4}° drift {} > {bound}",
                r.elevation_rad.to_degrees(),
                r.invariant_drift
            );
        }
        // Global accuracy: the tracer bounds each step's error by tol, so a ray's height may be
        // off by up to (steps × tol); compare every 20th ray with a trace at tol/100.
        let fine = Tracer::new(&atm, config(tol / 100.0)).unwrap();
        let mut worst_global: f64 = 0.0;
        for r in records.iter().step_by(20) {
            let f = fine.trace(h0, r.elevation_rad, &distances).unwrap();
            for (a, b) in r.heights_m.iter().zip(&f.heights_m) {
                if let (Some(a), Some(b)) = (a, b) {
                    worst_global = worst_global.max((a - b).abs());
                    assert!(
                        (a - b).abs() <= r.steps() as f64 * tol,
                        "{name}: ray {:.4}°: {a} m vs {b} m at tol/100",
                        r.elevation_rad.to_degrees()
                    );
                }
            }
        }
        eprintln!("{name}: largest height change from tol {tol} to tol/100: {worst_global:.2e} m");
        let (flagged, worst) =
            assert_continuous(name, &tracer, h0, &elevations, &distances, &records);
        eprintln!("{name}: {flagged} steep gaps bisected, worst residual {worst:.2e} m");
    }
}

/// Continuity of h(D; α) over a traced fan: a gap between neighbouring rays much larger than
/// its neighbours' gaps (3× plus 5 tolerances) must close under bisection to below 5 tolerances.
/// Returns the number of gaps bisected and the largest residual.
fn assert_continuous<S: StratifiedIndex>(
    name: &str,
    tracer: &Tracer<'_, S>,
    h0: f64,
    elevations: &[f64],
    distances: &[f64],
    records: &[RayRecord],
) -> (usize, f64) {
    let tol = tracer.config().tolerance_m;
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
                tracer,
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
    (flagged, worst)
}

/// Continuity in elevation through the paper atmospheres at the default tolerance (1 cm), from
/// below the layers (10 m) and between them (80 m).
///
/// Not asserted here, measured while writing this (see the report): with the camera *inside*
/// the Fata Morgana's upper layer (120 m), 1 cm per step leaves up to 9 cm jumps between
/// neighbouring rays at 34 km (11 gaps in 2001 rays over −0.2…+0.2°), because the vertical step
/// limit (2 m + 5 % of the height = 8 m at 120 m) lets a step straddle the 15 m layer; they vanish
/// at 1 mm per step or with the limit held at 2 m. Next to the escape separatrix (α ≈ 0.196°)
/// the remaining noise is amplified to ≈ 10 tolerances at any tolerance.
#[test]
fn paper_fans_are_continuous_in_elevation() {
    let distances: Vec<f64> = (2..=40).step_by(2).map(|k| k as f64 * 1000.0).collect();
    let elevations: Vec<f64> = linspace(-0.4, 0.4, 801)
        .into_iter()
        .map(f64::to_radians)
        .collect();
    let cases = [
        ("superior_mirage", 10.0, 1e-2),
        ("superior_mirage", 80.0, 1e-2),
        ("inferior_mirage", 10.0, 1e-2),
        ("fata_morgana", 10.0, 1e-2),
        // From 80 m the fan crosses a near-fold at 36 km (|∂h/∂α| ≈ 800 × D): there two rays
        // 1e-17 rad apart take different step sequences at 1 cm and land 0.27 m apart (each
        // within the error such a conditioning allows); at 1 mm the jump is 1.2e-4 m.
        ("fata_morgana", 80.0, 1e-3),
    ];
    for (name, h0, tol) in cases {
        let atm = paper(name);
        let tracer = Tracer::new(&atm, config(tol)).unwrap();
        let records = tracer.trace_fan(h0, &elevations, &distances).unwrap();
        for r in &records {
            assert!(
                matches!(
                    r.termination,
                    Some(Termination::Ground | Termination::Escaped | Termination::TargetsDone)
                ),
                "{name} from {h0} m: ray {:.4}° ended with {:?}",
                r.elevation_rad.to_degrees(),
                r.termination
            );
        }
        let label = format!("{name} from {h0} m");
        let (flagged, worst) =
            assert_continuous(&label, &tracer, h0, &elevations, &distances, &records);
        eprintln!(
            "{label} (tol {tol} m): {flagged} steep gaps bisected, worst residual {worst:.2e} m"
        );
    }
}

/// Check 5: the table and the exact Ciddor field give the same ray heights at 26 km for each
/// paper atmosphere (and a real sounding). The tracer runs at 1e-5 m per step so that its own
/// error does not hide the table's: the bound is the table's promise |Δ(dn/dh)| ≤ 1e-11 m⁻¹,
/// i.e. 1e-11·D²/2 = 3.4 mm at 26 km, plus the per-step tolerance summed over both traces.
#[test]
fn table_and_exact_field_agree_at_26_km() {
    let h0 = 10.0;
    let d = 26_000.0;
    let elevations: Vec<f64> = linspace(-0.3, 0.5, 161)
        .into_iter()
        .map(f64::to_radians)
        .collect();
    let cases = [
        ("superior_mirage", paper("superior_mirage")),
        ("inferior_mirage", paper("inferior_mirage")),
        ("fata_morgana", paper("fata_morgana")),
        ("novaya_zemlya", paper("novaya_zemlya")),
        (
            "Bjornoya",
            sounding(&repo_file("data/Bjornoya-01028_2024022611.csv")),
        ),
    ];
    let tol = 1e-5;
    for (name, atm) in &cases {
        let exact = Exact(atm);
        let table_tracer = Tracer::new(atm, config(tol)).unwrap();
        let exact_tracer = Tracer::new(&exact, config(tol)).unwrap();
        let (mut worst, mut worst_at, mut worst_bound) = (0.0_f64, 0.0, 0.0);
        for &a in &elevations {
            let t = table_tracer.trace(h0, a, &[d]).unwrap();
            let e = exact_tracer.trace(h0, a, &[d]).unwrap();
            match (t.heights_m[0], e.heights_m[0]) {
                (Some(ht), Some(he)) => {
                    let bound = 1e-11 * d * d / 2.0 + (t.steps() + e.steps()) as f64 * tol;
                    assert!(
                        (ht - he).abs() <= bound,
                        "{name} α {:.4}°: table {ht} m, exact {he} m (bound {bound:.2e} m)",
                        a.to_degrees()
                    );
                    if (ht - he).abs() > worst {
                        (worst, worst_at, worst_bound) = ((ht - he).abs(), a.to_degrees(), bound);
                    }
                }
                (None, None) => assert_eq!(t.termination, e.termination, "{name} {a}"),
                other => panic!("{name} α {:.4}°: table/exact {other:?}", a.to_degrees()),
            }
        }
        eprintln!(
            "{name}: table vs exact at 26 km: worst |Δh| {worst:.2e} m at {worst_at:.4}° \
             (bound there {worst_bound:.2e} m)"
        );
    }
}
