//! Tracer and analysis checks against exact solutions and published reference numbers
//! (docs/references.md §1, §2.1, §2.2, §2.3, §2.7).

use ghostship::analysis::{TraceRequest, trace_plot_png, trace_report};
use ghostship::profile::us1976::us1976;
use ghostship::tracer::{
    Ground, IndexField, NoHook, Spherical, StratifiedIndex, Termination, Tracer, TracerConfig,
    straight_ray, trace_field,
};
use ghostship::units::{ARCMIN_PER_RAD, DRY_AIR_GAS_CONSTANT_J_KG_K, STANDARD_GRAVITY_M_S2};
use glam::DVec3;

const R: f64 = 6_371_000.0;

/// n constant.
struct Constant(f64);
impl StratifiedIndex for Constant {
    fn index_and_derivative(&self, _h: f64) -> (f64, f64) {
        (self.0, 0.0)
    }
}

/// n = n₀·R/(R + h): the perfect duct, horizontal rays are circles.
struct InverseRadius(f64);
impl StratifiedIndex for InverseRadius {
    fn index_and_derivative(&self, h: f64) -> (f64, f64) {
        let r = R + h;
        (self.0 * R / r, -self.0 * R / (r * r))
    }
}

/// Dry air with n − 1 = A·P[mb]/T (SLALIB/H&S optical form, docs/references.md §2.6) over US1976.
struct Us1976Field {
    a: f64,
}
impl Us1976Field {
    fn new(wavelength_um: f64) -> Self {
        let l2 = wavelength_um * wavelength_um;
        Us1976Field {
            a: (287.6155 + 1.62887 / l2 + 0.01360 / (l2 * l2)) * 273.15e-6 / 1013.25,
        }
    }
}
impl StratifiedIndex for Us1976Field {
    fn index_and_derivative(&self, h: f64) -> (f64, f64) {
        let air = us1976(h);
        let t = air.temperature_k;
        let p_mb = air.pressure_pa / 100.0;
        // Hydrostatic dP/dz in geometric height: −P g₀/(R_d T) · (r₀/(r₀+z))² (geopotential).
        let ratio = 6_356_766.0 / (6_356_766.0 + h);
        let dp_mb =
            -p_mb * STANDARD_GRAVITY_M_S2 / (DRY_AIR_GAS_CONSTANT_J_KG_K * t) * ratio * ratio;
        let n = 1.0 + self.a * p_mb / t;
        let dn = self.a * (dp_mb / t - p_mb * air.dtemperature_dh_k_per_m / (t * t));
        (n, dn)
    }
}

/// docs/references.md §2.7: T = 273.15 + 0.1121·h, P hydrostatic from 101 325 Pa,
/// n−1 = 7.9012e-7·P/T.
struct CriticalGradient;
impl StratifiedIndex for CriticalGradient {
    fn index_and_derivative(&self, h: f64) -> (f64, f64) {
        let lapse = 0.1121;
        let t0 = 273.15;
        let t = t0 + lapse * h;
        let g_over_r = STANDARD_GRAVITY_M_S2 / DRY_AIR_GAS_CONSTANT_J_KG_K;
        let p = 101_325.0 * (t / t0).powf(-g_over_r / lapse);
        let dp = -p * g_over_r / t;
        let k = 7.9012e-7;
        (1.0 + k * p / t, k * (dp / t - p * lapse / (t * t)))
    }
}

fn config(tolerance_m: f64) -> TracerConfig {
    TracerConfig {
        tolerance_m,
        ..TracerConfig::default()
    }
}

#[test]
fn constant_index_gives_straight_lines() {
    let field = Constant(1.000_3);
    let tracer = Tracer::new(&field, config(0.01)).unwrap();
    let distances: Vec<f64> = (1..=30).map(|k| k as f64 * 1_000.0).collect();
    let mut worst: f64 = 0.0;
    for &alpha_deg in &[-0.1_f64, -0.05, 0.0, 0.02, 0.1, 0.5, 2.0] {
        let alpha = alpha_deg.to_radians();
        let curved = tracer.trace(10.0, alpha, &distances).unwrap();
        let straight = straight_ray(10.0, alpha, R, 40_000.0, &distances).unwrap();
        assert!(curved.termination.is_some());
        for (a, b) in curved.heights_m.iter().zip(&straight.heights_m) {
            match (a, b) {
                (Some(a), Some(b)) => {
                    worst = worst.max((a - b).abs());
                    assert!((a - b).abs() < 1e-4, "α {alpha_deg}: {a} vs {b}")
                }
                (None, None) => {}
                _ => panic!("α {alpha_deg}: curved {a:?} vs straight {b:?}"),
            }
        }
        if straight.termination == Some(Termination::Ground) {
            assert_eq!(curved.termination, Some(Termination::Ground));
            assert!((curved.end.distance_m - straight.end.distance_m).abs() < 0.05);
        }
    }
    eprintln!("constant n: worst height error against straight lines {worst:.2e} m");
}

/// Lowest elevation whose ray does not reach the ground (bisection on the tracer). Shared with
/// the end-to-end checks.
pub(crate) fn sea_horizon_rad<S: StratifiedIndex>(tracer: &Tracer<'_, S>, h0: f64) -> f64 {
    let hits = |a: f64| tracer.trace(h0, a, &[]).unwrap().termination == Some(Termination::Ground);
    // −11.5° is below the sea horizon of any camera up to the 40 km top.
    crate::support::bisect(-0.2, 0.0, 60, |a| !hits(a)).1
}

#[test]
fn constant_index_gives_geometric_dip() {
    let field = Constant(1.000_3);
    let tracer = Tracer::new(&field, config(0.01)).unwrap();
    for (h0, dip_arcmin) in [(10.0, 6.091), (100.0, 19.261), (1.0, 1.926)] {
        let dip = -sea_horizon_rad(&tracer, h0) * ARCMIN_PER_RAD;
        assert!((dip - dip_arcmin).abs() < 0.001, "h0 {h0}: dip {dip}′");
    }
}

#[test]
fn inverse_radius_index_keeps_horizontal_ray_level() {
    let field = InverseRadius(1.000_3);
    let tracer = Tracer::new(&field, config(0.01)).unwrap();
    let distances: Vec<f64> = (1..=20).map(|k| k as f64 * 5_000.0).collect();
    let rec = tracer.trace(25.0, 0.0, &distances).unwrap();
    assert_eq!(rec.termination, Some(Termination::TargetsDone));
    for h in &rec.heights_m {
        let h = h.unwrap();
        assert!((h - 25.0).abs() < 1e-4, "{h}");
    }
    // An inclined ray keeps its local elevation (logarithmic spiral).
    let alpha = 0.3_f64.to_radians();
    let rec = tracer.trace(25.0, alpha, &distances).unwrap();
    for e in &rec.target_elevations_rad {
        assert!((e.unwrap() - alpha).abs() < 1e-8, "{e:?}");
    }
    assert!(rec.invariant_drift < 1e-10, "drift {}", rec.invariant_drift);
}

/// Flat Earth, n² = n₀² + 2g·z: with the optical parameter σ (ds = n dσ) the ray equation is
/// d²r/dσ² = ∇(n²/2) = (0, 0, g), so z(x) = z₀ + tan ψ₀·x + g·x²/(2c²), c = n₀ cos ψ₀.
struct FlatSquareLinear {
    n0: f64,
    g: f64,
}
impl IndexField for FlatSquareLinear {
    fn index_and_gradient(&self, p: DVec3) -> (f64, DVec3) {
        let n = (self.n0 * self.n0 + 2.0 * self.g * p.z).sqrt();
        (n, DVec3::new(0.0, 0.0, self.g / n))
    }
}

#[test]
fn flat_earth_square_linear_index_gives_parabola() {
    let field = FlatSquareLinear {
        n0: 1.000_3,
        g: -4e-7,
    };
    let cfg = TracerConfig {
        tolerance_m: 0.01,
        top_m: 5_000.0,
        ..TracerConfig::default()
    };
    let distances: Vec<f64> = (1..=10).map(|k| k as f64 * 3_000.0).collect();
    let mut worst: f64 = 0.0;
    for psi0_deg in [0.0_f64, 0.5, 1.0, 3.0] {
        let psi0 = psi0_deg.to_radians();
        let z0 = 20.0;
        let dir = DVec3::new(psi0.cos(), 0.0, psi0.sin());
        let rec = trace_field(
            &field,
            Ground::Flat,
            &cfg,
            DVec3::new(0.0, 0.0, z0),
            dir,
            &distances,
            &mut NoHook,
            None,
        )
        .unwrap();
        // c = n(z₀)·cos ψ₀ (Snell's invariant at the launch point).
        let c = field.index_and_gradient(DVec3::new(0.0, 0.0, z0)).0 * psi0.cos();
        for (x, h) in distances.iter().zip(&rec.heights_m) {
            let exact = z0 + psi0.tan() * x + field.g * x * x / (2.0 * c * c);
            match h {
                Some(h) => {
                    worst = worst.max((h - exact).abs());
                }
                None => assert!(
                    exact <= 0.0,
                    "ψ0 {psi0_deg} x {x}: ray ended early, exact {exact}"
                ),
            }
        }
    }
    eprintln!(
        "parabola: worst error {worst:.2e} m at tolerance {} m",
        cfg.tolerance_m
    );
    // The ray is a parabola in the optical parameter, which every Runge–Kutta stage integrates
    // exactly: only rounding is left (README's accuracy table: < 1e-9 m).
    assert!(worst < 0.1 * cfg.tolerance_m, "worst error {worst} m");
    assert!(
        worst < 1e-9,
        "worst error {worst} m: the parabola should be exact to rounding"
    );
}

/// palRefro, 15 °C, 1013.25 hPa, 0.55 µm, dry (docs/references.md §2.1): (observed zenith
/// distance in degrees, refraction in arcmin). Shared with the end-to-end checks, which set their
/// own bounds (README's accuracy table quotes both).
pub(crate) const PALREFRO_US1976_550NM: [(f64, f64); 7] = [
    (45.0, 0.953),
    (80.0, 5.223),
    (85.0, 9.666),
    (88.0, 17.789),
    (89.0, 23.545),
    (89.5, 27.650),
    (90.0, 33.000),
];

/// Allowed error (arcmin) of the tracer through the SLALIB-form US1976 field at each zenith
/// distance of [`PALREFRO_US1976_550NM`], as README's accuracy table states it: 0.005′ to 89°,
/// 0.01′ at 89.5°, 0.02′ at the horizon.
const SLALIB_FIELD_BOUND_ARCMIN: [f64; 7] = [0.005, 0.005, 0.005, 0.005, 0.005, 0.01, 0.02];

#[test]
fn us1976_astronomical_refraction_matches_palrefro() {
    let field = Us1976Field::new(0.55);
    let cfg = TracerConfig {
        tolerance_m: 0.001,
        top_m: 80_000.0,
        ..TracerConfig::default()
    };
    let tracer = Tracer::new(&field, cfg).unwrap();
    for ((zd, expected), tol) in PALREFRO_US1976_550NM
        .into_iter()
        .zip(SLALIB_FIELD_BOUND_ARCMIN)
    {
        let alpha = (90.0_f64 - zd).to_radians();
        let rec = tracer.trace(0.0, alpha, &[]).unwrap();
        assert_eq!(rec.termination, Some(Termination::Escaped), "ZD {zd}");
        let got = rec.refraction_rad.unwrap() * ARCMIN_PER_RAD;
        eprintln!(
            "ZD {zd}: {got:.4}′ (palRefro {expected}′), steps {}, invariant drift {:.1e}",
            rec.steps(),
            rec.invariant_drift
        );
        assert!(
            (got - expected).abs() < tol,
            "ZD {zd}: {got}′ vs {expected}′"
        );
    }
}

#[test]
fn critical_gradient_ray_matches_reference_trace() {
    let cfg = TracerConfig {
        tolerance_m: 1e-4,
        ..TracerConfig::default()
    };
    let tracer = Tracer::new(&CriticalGradient, cfg).unwrap();
    let distances = [10_000.0, 20_000.0, 50_000.0, 100_000.0];
    // docs/references.md §2.7 (DOP853, rtol 1e-12); tolerances are half a unit in the last
    // printed digit.
    let cases: [(f64, [(f64, f64); 4]); 2] = [
        (
            0.0,
            [
                (0.0032, 0.00005),
                (0.0129, 0.00005),
                (0.083, 0.0005),
                (0.362, 0.0005),
            ],
        ),
        (
            10.0,
            [
                (10.077, 0.0005),
                (10.309, 0.0005),
                (11.98, 0.005),
                (18.67, 0.005),
            ],
        ),
    ];
    for (h0, expected) in cases {
        let rec = tracer.trace(h0, 0.0, &distances).unwrap();
        for ((h, (e, tol)), d) in rec.heights_m.iter().zip(expected).zip(distances) {
            let h = h.unwrap();
            eprintln!("h0 {h0}, x {d}: {h:.5} m (reference {e})");
            assert!((h - e).abs() <= tol, "h0 {h0}, x {d}: {h} vs {e}");
        }
    }
}

#[test]
fn planar_and_3d_paths_agree() {
    let field = Us1976Field::new(0.55);
    let cfg = config(0.01);
    let tracer = Tracer::new(&field, cfg.clone()).unwrap();
    let sphere = Spherical {
        index: Us1976Field::new(0.55),
        earth_radius_m: R,
    };
    let distances: Vec<f64> = (1..=10).map(|k| k as f64 * 10_000.0).collect();
    // Observer somewhere off-axis, looking in an arbitrary azimuth.
    let up = DVec3::new(0.3, -0.5, 0.8).normalize();
    let east = up.cross(DVec3::Z).normalize();
    let h0 = 15.0;
    let mut worst: f64 = 0.0;
    for alpha_deg in [-0.05_f64, 0.0, 0.1, 1.0, 10.0] {
        let alpha = alpha_deg.to_radians();
        let planar = tracer.trace(h0, alpha, &distances).unwrap();
        let dir = east * alpha.cos() + up * alpha.sin();
        let full = trace_field(
            &sphere,
            Ground::Sphere { radius_m: R },
            &cfg,
            up * (R + h0),
            dir,
            &distances,
            &mut NoHook,
            None,
        )
        .unwrap();
        assert_eq!(planar.termination, full.termination, "α {alpha_deg}");
        for (a, b) in planar.heights_m.iter().zip(&full.heights_m) {
            match (a, b) {
                (Some(a), Some(b)) => {
                    worst = worst.max((a - b).abs());
                    // README's accuracy table: < 6 mm out to 100 km at the 1 cm tolerance.
                    assert!((a - b).abs() < 0.006, "α {alpha_deg}: {a} vs {b}")
                }
                (None, None) => {}
                _ => panic!("α {alpha_deg}: {a:?} vs {b:?}"),
            }
        }
        assert!((planar.end.distance_m - full.end.distance_m).abs() < 1.0);
    }
    eprintln!("3-D vs planar: worst height difference {worst:.2e} m (tolerance 0.01 m)");
}

#[test]
fn halving_the_tolerance_changes_heights_less_than_the_tolerance() {
    let field = Us1976Field::new(0.55);
    let distances: Vec<f64> = (1..=30).map(|k| k as f64 * 1_000.0).collect();
    for tol in [1.0, 0.1, 0.01, 0.001] {
        let a = Tracer::new(&field, config(tol)).unwrap();
        let b = Tracer::new(&field, config(tol / 2.0)).unwrap();
        for alpha_deg in [-0.08_f64, -0.02, 0.0, 0.05, 0.3, 3.0] {
            let ra = a.trace(20.0, alpha_deg.to_radians(), &distances).unwrap();
            let rb = b.trace(20.0, alpha_deg.to_radians(), &distances).unwrap();
            for (x, y) in ra.heights_m.iter().zip(&rb.heights_m) {
                if let (Some(x), Some(y)) = (x, y) {
                    assert!((x - y).abs() < tol, "tol {tol} α {alpha_deg}: {x} vs {y}");
                }
            }
        }
    }
}

/// A smooth elevated inversion: n drops by `dn` across a layer of half-width `w` at `hc`, over a
/// weak standard gradient. With dn = 1e-5 (≈ 10 K) over a few metres its gradient is ~10× the
/// ducting value 1/R: a duct with a Fata-Morgana-like, non-monotone transfer curve.
struct Inversion {
    dn: f64,
    hc: f64,
    w: f64,
}
impl StratifiedIndex for Inversion {
    fn index_and_derivative(&self, h: f64) -> (f64, f64) {
        let t = ((h - self.hc) / self.w).tanh();
        let n = 1.0003 - 3e-8 * h - self.dn * 0.5 * (1.0 + t);
        let dn = -3e-8 - self.dn * 0.5 * (1.0 - t * t) / self.w;
        (n, dn)
    }
}

const FATA_MORGANA: Inversion = Inversion {
    dn: 1e-5,
    hc: 15.0,
    w: 3.0,
};

fn fata_morgana_request() -> TraceRequest {
    TraceRequest {
        observer_height_m: 10.0,
        elevation_min_deg: -0.2,
        elevation_max_deg: 0.3,
        elevation_count: 401,
        distances_m: vec![20_000.0],
        target_heights_m: vec![30.0],
        ..TraceRequest::default()
    }
}

#[test]
fn fata_morgana_images_are_all_found_and_alternate() {
    let request = fata_morgana_request();
    let report = trace_report(&FATA_MORGANA, &request).unwrap();
    let images = &report.images;
    assert!(images.len() >= 3, "{images:#?}");
    let probe = Tracer::new(&FATA_MORGANA, request.tracer.clone()).unwrap();
    let (d, big_h) = (20_000.0, 30.0);
    let h_at = |deg: f64| probe.trace(10.0, deg.to_radians(), &[d]).unwrap().heights_m[0];
    for pair in images.windows(2) {
        assert!(pair[0].elevation_max_deg <= pair[1].elevation_min_deg + 1e-12);
        assert_ne!(
            pair[0].erect, pair[1].erect,
            "orientation must alternate: {pair:#?}"
        );
    }
    for image in images {
        // Re-trace inside the image: the ray lands on the target, with the stated orientation.
        let width = image.elevation_max_deg - image.elevation_min_deg;
        assert!(width > 0.0);
        let (a1, a2) = (
            image.elevation_min_deg + 0.25 * width,
            image.elevation_min_deg + 0.75 * width,
        );
        let mid = h_at(image.elevation_deg).expect("image ray reaches the target");
        assert!((0.0..=big_h).contains(&mid), "{image:?}: h {mid}");
        let (h1, h2) = (h_at(a1).unwrap(), h_at(a2).unwrap());
        assert_eq!(h2 > h1, image.erect, "{image:?}");
        assert!(image.magnification > 0.0 && image.magnification.is_finite());
    }
    // Brute force: a fan 20× denser finds the same number of in-band monotone pieces.
    let n = 8001;
    let alphas: Vec<f64> = (0..n)
        .map(|i| (-0.2 + 0.5 * i as f64 / (n - 1) as f64).to_radians())
        .collect();
    let fan = probe.trace_fan(10.0, &alphas, &[d]).unwrap();
    let heights: Vec<Option<f64>> = fan.iter().map(|r| r.heights_m[0]).collect();
    let mut pieces = 0;
    let mut prev_in = false;
    let mut prev_dir = 0.0f64;
    for i in 1..n {
        let inside = matches!((heights[i - 1], heights[i]), (Some(a), Some(b)) if (0.0..=big_h).contains(&a) && (0.0..=big_h).contains(&b));
        let dir = match (heights[i - 1], heights[i]) {
            (Some(a), Some(b)) => (b - a).signum(),
            _ => 0.0,
        };
        if inside && (!prev_in || dir != prev_dir) {
            pieces += 1;
        }
        prev_in = inside;
        prev_dir = dir;
    }
    assert_eq!(pieces, images.len(), "brute force {pieces} vs {images:#?}");
    // Rays inside the duct are trapped.
    assert!(!report.trapped_elevations_deg.is_empty());
}

#[test]
fn report_json_has_the_documented_shape() {
    let mut request = fata_morgana_request();
    request.elevation_count = 41;
    let report = trace_report(&FATA_MORGANA, &request).unwrap();
    let json: serde_json::Value = serde_json::from_str(&report.to_json().unwrap()).unwrap();
    for key in [
        "observer_height_m",
        "tolerance_m",
        "wavelength_nm",
        "distances_m",
        "rays",
        "images",
    ] {
        assert!(json.get(key).is_some(), "missing {key}");
    }
    let ray = &json["rays"][0];
    for key in [
        "elevation_deg",
        "termination",
        "heights_m",
        "end_distance_m",
        "refraction_deg",
        "steps",
        "invariant_drift",
    ] {
        assert!(ray.get(key).is_some(), "missing rays[].{key}");
    }
    assert_eq!(ray["termination"], "ground");
    assert!(ray["heights_m"][0].is_null());
    for key in ["distance_m", "height_m", "elevation_deg", "erect"] {
        assert!(
            json["images"][0].get(key).is_some(),
            "missing images[].{key}"
        );
    }
    let csv = String::from_utf8(report.rays_csv().unwrap()).unwrap();
    assert_eq!(csv.lines().count(), 42);
    assert!(csv.lines().next().unwrap().ends_with("height_m_at_20000"));
}

#[test]
fn fan_is_bit_identical_for_any_thread_count() {
    let request = fata_morgana_request();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| trace_report(&FATA_MORGANA, &request).unwrap())
    };
    let one = run(1);
    let three = run(3);
    assert_eq!(one.to_json().unwrap(), three.to_json().unwrap());
    for (a, b) in one.rays.iter().zip(&three.rays) {
        for (x, y) in a.heights_m.iter().zip(&b.heights_m) {
            assert_eq!(x.map(f64::to_bits), y.map(f64::to_bits));
        }
    }
}

#[test]
fn plot_png_is_drawn() {
    let mut request = fata_morgana_request();
    request.elevation_count = 81;
    request.distances_m = vec![10_000.0, 20_000.0];
    let report = trace_report(&FATA_MORGANA, &request).unwrap();
    let png = trace_plot_png(&FATA_MORGANA, &request, &report).unwrap();
    let img = image::load_from_memory(&png).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (1600, 700));
    // Not blank: plenty of coloured (non-grey) pixels from the rays and curves.
    let coloured = img
        .pixels()
        .filter(|p| p[0].abs_diff(p[1]) > 40 || p[1].abs_diff(p[2]) > 40)
        .count();
    assert!(coloured > 2_000, "{coloured}");
    if let Ok(dir) = std::env::var("GHOSTSHIP_PLOT_DIR") {
        std::fs::write(format!("{dir}/fata_morgana_trace.png"), &png).unwrap();
    }
}

/// Piecewise-linear temperature over layers, hydrostatic pressure, n − 1 = 7.9012e-7·P/T.
#[derive(Debug, Clone)]
struct Layered {
    /// (base height, base T, base P, lapse dT/dh) per layer, ascending.
    layers: Vec<(f64, f64, f64, f64)>,
    /// The layer bases above the ground, where dn/dh jumps.
    breaks: Vec<f64>,
}
impl Layered {
    fn new(t0: f64, spec: &[(f64, f64)]) -> Self {
        let g_over_r = STANDARD_GRAVITY_M_S2 / DRY_AIR_GAS_CONSTANT_J_KG_K;
        let (mut h, mut t, mut p) = (0.0, t0, 101_325.0);
        let mut layers = Vec::new();
        for &(thickness, lapse) in spec {
            // Keep T physical: turn the gradient around rather than leave 150…350 K.
            let mut lapse = lapse;
            let t_top = t + lapse * thickness;
            if !(150.0..=350.0).contains(&t_top) {
                lapse = -lapse;
            }
            layers.push((h, t, p, lapse));
            let (t1, p1) = Self::state(t, p, lapse, thickness, g_over_r);
            h += thickness;
            t = t1;
            p = p1;
        }
        layers.push((h, t, p, -0.0065));
        let breaks = layers.iter().map(|l| l.0).filter(|&h| h > 0.0).collect();
        Layered { layers, breaks }
    }
    fn state(t: f64, p: f64, lapse: f64, dh: f64, g_over_r: f64) -> (f64, f64) {
        if lapse.abs() < 1e-12 {
            (t, p * (-g_over_r * dh / t).exp())
        } else {
            let t1 = t + lapse * dh;
            (t1, p * (t1 / t).powf(-g_over_r / lapse))
        }
    }
}
impl StratifiedIndex for Layered {
    fn index_and_derivative(&self, h: f64) -> (f64, f64) {
        let g_over_r = STANDARD_GRAVITY_M_S2 / DRY_AIR_GAS_CONSTANT_J_KG_K;
        let i = self.layers.partition_point(|l| l.0 <= h).saturating_sub(1);
        let (base, t0, p0, lapse) = self.layers[i];
        // Clamp into the column's valid range (T stays > 0 far above the top).
        let dh = (h - base).clamp(-1_000.0, 60_000.0);
        let lapse = if t0 + lapse * dh < 100.0 { 0.0 } else { lapse };
        let (t, p) = Self::state(t0, p0, lapse, dh, g_over_r);
        let k = 7.9012e-7;
        let dp = -p * g_over_r / t;
        (1.0 + k * p / t, k * (dp / t - p * lapse / (t * t)))
    }
    fn breaks_m(&self) -> &[f64] {
        &self.breaks
    }
}

#[test]
fn elevated_duct_carries_a_ray_5000_km() {
    // 30 m of +0.5 K/m (≈ 4× the critical gradient) 100 m above the sea: an elevated duct. A ray
    // launched level in its middle turns down, crosses the inversion's base at ψ ≈ 3.8 mrad and
    // turns up again ≈ 54 m lower in standard air (curvature 0.83/R relative to the ground), so it
    // oscillates between ≈ 46 m and 115 m without touching the (absorbing) sea.
    let field = Layered::new(263.15, &[(100.0, -0.0065), (30.0, 0.5)]);
    let distances: Vec<f64> = (1..=50).map(|k| k as f64 * 100_000.0).collect();
    for tolerance_m in [0.01, 1e-6] {
        let cfg = TracerConfig {
            tolerance_m,
            max_distance_m: Some(5_000_000.0),
            stop_after_last_target: false,
            // The tolerance holds over the whole 5 000 km (error per unit length): 1 µm there
            // takes ~10⁶ steps.
            max_steps: 5_000_000,
            ..TracerConfig::default()
        };
        let tracer = Tracer::new(&field, cfg).unwrap();
        let rec = tracer.trace(115.0, 0.0, &distances).unwrap();
        eprintln!(
            "5000 km duct, tolerance {tolerance_m} m: {} steps ({} rejected), invariant drift {:.2e}",
            rec.steps(),
            rec.rejected_steps,
            rec.invariant_drift
        );
        assert_eq!(rec.termination, Some(Termination::MaxDistance), "{rec:?}");
        assert!((rec.end.distance_m - 5_000_000.0).abs() < 1e-3);
        for h in &rec.heights_m {
            let h = h.unwrap();
            assert!(h > 30.0 && h < 116.0, "left the duct: {h}");
        }
        if tolerance_m < 1e-5 {
            // Bouguer's invariant holds over 5 000 km (and 23 kinks of dn/dh per 1 000 km).
            assert!(rec.invariant_drift < 1e-8, "drift {}", rec.invariant_drift);
        }
    }
}

mod stress {
    use super::*;
    use proptest::prelude::*;

    fn profile() -> impl Strategy<Value = Vec<(f64, f64)>> {
        // Layers 0.1 m … 1 km thick with gradients up to ±50 K/m (less where that would exceed
        // ±40 K across the layer).
        prop::collection::vec(
            (-1.0f64..3.0, -1.0f64..1.0).prop_map(|(log_thickness, g)| {
                let thickness = 10f64.powf(log_thickness);
                let max_gradient = (40.0 / thickness).min(50.0);
                (thickness, g * max_gradient)
            }),
            1..12,
        )
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
        #[test]
        fn every_ray_terminates_with_a_reason(
            spec in profile(),
            t0 in 230.0f64..300.0,
            log_tol in -6.0f64..1.0,
            layer_pick in 0usize..12,
            tilt in -1e-3f64..1e-3,
        ) {
            let field = Layered::new(t0, &spec);
            let tolerance_m = 10f64.powf(log_tol);
            let cfg = TracerConfig {
                tolerance_m,
                max_steps: 50_000,
                max_distance_m: Some(5_000_000.0),
                stop_after_last_target: false,
                ..TracerConfig::default()
            };
            let tracer = Tracer::new(&field, cfg).unwrap();
            // Observer on a layer boundary: the α = 0 ray is tangent to that layer.
            let boundary = field.layers[layer_pick % field.layers.len()].0;
            let h0 = boundary.clamp(0.0, 2_000.0);
            let distances = [1_000.0, 30_000.0, 1_000_000.0];
            for alpha in [0.0, tilt, -tilt.abs() * 0.01, 0.5f64.to_radians(), -0.2f64.to_radians()] {
                let rec = tracer.trace(h0, alpha, &distances).unwrap();
                let t = rec.termination.expect("terminated");
                prop_assert!(rec.steps() <= 50_000);
                prop_assert!(rec.end.height_m.is_finite() && rec.end.distance_m.is_finite());
                prop_assert!(rec.end.elevation_rad.is_finite() && rec.end_observer_elevation_rad.is_finite());
                prop_assert!(rec.invariant_drift.is_finite());
                for h in rec.heights_m.iter().flatten() {
                    prop_assert!(h.is_finite());
                }
                if let Some(r) = rec.refraction_rad {
                    prop_assert!(r.is_finite());
                    prop_assert_eq!(t, Termination::Escaped);
                }
                prop_assert!(rec.end.height_m >= -1e-6, "{t}: {}", rec.end.height_m);
            }
        }
    }
}

#[test]
fn homogeneous_air_gives_one_geometric_image_and_the_geometric_dip() {
    let field = Constant(1.000_3);
    let (h0, d, big_h) = (2.0, 2_000.0, 10.0);
    let request = TraceRequest {
        observer_height_m: h0,
        elevation_min_deg: -0.2,
        elevation_max_deg: 0.5,
        elevation_count: 201,
        distances_m: vec![d],
        target_heights_m: vec![big_h],
        ..TraceRequest::default()
    };
    let report = trace_report(&field, &request).unwrap();
    assert_eq!(report.images.len(), 1, "{:#?}", report.images);
    let image = &report.images[0];
    assert!(image.erect);
    // Exact elevation of the point (D, h) seen from the observer, straight lines over a sphere.
    let seen = |h: f64| {
        let theta = d / R;
        let x = (R + h) * theta.sin();
        let y = (R + h) * theta.cos() - (R + h0);
        y.atan2(x).to_degrees()
    };
    assert!(
        (image.elevation_min_deg - seen(0.0)).abs() < 1e-8,
        "{image:?}"
    );
    assert!(
        (image.elevation_max_deg - seen(big_h)).abs() < 1e-8,
        "{image:?}"
    );
    assert!((image.magnification - 1.0).abs() < 0.01, "{image:?}");
    // Sea horizon: the geometric dip 1.926′·√2 = 2.724′.
    let sea = report.horizons.last().unwrap();
    assert!(sea.distance_m.is_none());
    let dip_arcmin = -sea.elevation_deg.unwrap() * 60.0;
    assert!(
        (dip_arcmin - 1.926 * 2f64.sqrt()).abs() < 0.002,
        "{dip_arcmin}"
    );
    assert!(report.trapped_elevations_deg.is_empty());
}

/// Ends the ray on a vertical wall at a ground distance (an object surface as an event function).
struct Wall {
    distance_m: f64,
}
impl ghostship::tracer::RayHook for Wall {
    fn event(&self, p: &ghostship::tracer::RayPoint) -> Option<f64> {
        Some(p.distance_m - self.distance_m)
    }
}

#[test]
fn hooks_end_rays_on_events_and_early_stops() {
    use ghostship::tracer::{HookAction, RayHook, RayPoint, RayRecord};
    /// Stops a ray once it climbs above 50 m.
    struct Ceiling;
    impl RayHook for Ceiling {
        fn after_step(&mut self, _from: &RayPoint, to: &RayPoint) -> HookAction {
            if to.height_m > 50.0 && to.elevation_rad > 0.0 {
                HookAction::Stop
            } else {
                HookAction::Continue
            }
        }
    }
    let field = Constant(1.0);
    let tracer = Tracer::new(&field, config(0.01)).unwrap();
    let mut record = RayRecord::default();
    let alpha = 0.1_f64.to_radians();
    tracer
        .trace_into(
            5.0,
            alpha,
            &[],
            &mut Wall {
                distance_m: 7_000.0,
            },
            &mut record,
            None,
        )
        .unwrap();
    assert_eq!(record.termination, Some(Termination::Event));
    let exact = straight_ray(5.0, alpha, R, 40_000.0, &[7_000.0])
        .unwrap()
        .heights_m[0]
        .unwrap();
    assert!((record.end.distance_m - 7_000.0).abs() < 1e-6);
    assert!(
        (record.end.height_m - exact).abs() < 1e-4,
        "{} vs {exact}",
        record.end.height_m
    );
    let mut path = Vec::new();
    tracer
        .trace_into(5.0, alpha, &[], &mut Ceiling, &mut record, Some(&mut path))
        .unwrap();
    assert_eq!(record.termination, Some(Termination::LeftRegion));
    assert!(record.end.height_m > 50.0 && record.end.height_m < 50.0 + 2.0 + 0.05 * 50.0 + 1.0);
    assert_eq!(path.last().unwrap().height_m, record.end.height_m);
    assert!(path.windows(2).all(|w| w[1].distance_m > w[0].distance_m));
}

#[test]
fn bad_input_is_a_typed_error() {
    let field = Constant(1.0);
    let tracer = Tracer::new(&field, config(0.01)).unwrap();
    assert!(tracer.trace(-1.0, 0.0, &[]).is_err());
    assert!(tracer.trace(50_000.0, 0.0, &[]).is_err());
    assert!(tracer.trace(1.0, f64::NAN, &[]).is_err());
    assert!(tracer.trace(1.0, 0.0, &[2.0, 1.0]).is_err());
    assert!(Tracer::new(&field, config(-1.0)).is_err());
    // A field that turns NaN above 20 m: the ray stops with NonFinite, no NaN in the record.
    struct Broken;
    impl StratifiedIndex for Broken {
        fn index_and_derivative(&self, h: f64) -> (f64, f64) {
            if h > 20.0 {
                (f64::NAN, f64::NAN)
            } else {
                (1.0003, -2e-8)
            }
        }
    }
    let tracer = Tracer::new(&Broken, config(0.01)).unwrap();
    let rec = tracer
        .trace(10.0, 1.0_f64.to_radians(), &[100_000.0])
        .unwrap();
    assert_eq!(rec.termination, Some(Termination::NonFinite));
    assert!(rec.end.height_m.is_finite() && rec.end.height_m <= 20.0 + 1e-9);
    assert!(rec.heights_m[0].is_none());
}

#[test]
fn us1976_dip_matches_the_refraction_coefficient() {
    let field = Us1976Field::new(0.55);
    let tracer = Tracer::new(&field, config(0.001)).unwrap();
    let h0 = 10.0;
    let dip = -sea_horizon_rad(&tracer, h0);
    // Near the ground the ray is a circle of curvature k/R, k = −R·(dn/dh)/n: then the dip is
    // √(2h(1 − k)/R) (docs/references.md §2.2).
    let (n, dn) = field.index_and_derivative(h0 / 2.0);
    let k = -R * dn / n;
    let expected = (2.0 * h0 * (1.0 - k) / R).sqrt();
    eprintln!(
        "US1976 dip at 10 m: {:.4}′ (circle with k = {k:.4}: {:.4}′; Nautical Almanac 1.76′√h = {:.3}′)",
        dip * ARCMIN_PER_RAD,
        expected * ARCMIN_PER_RAD,
        1.76 * h0.sqrt()
    );
    assert!((k - 0.170).abs() < 0.005, "k {k}");
    assert!(((dip - expected) * ARCMIN_PER_RAD).abs() < 0.005);
    assert!((dip * ARCMIN_PER_RAD - 1.76 * h0.sqrt()).abs() < 0.05);
}

#[test]
fn records_whether_a_ray_turned() {
    // Straight lines over a sphere (n constant): upward rays climb the whole way, downward
    // rays that land descend the whole way, downward rays that miss pass a perigee.
    let field = Constant(1.000_3);
    let tracer = Tracer::new(&field, config(0.01)).unwrap();
    let up = tracer.trace(10.0, 0.001, &[]).unwrap();
    assert!(!up.turned, "{up:?}");
    let down = tracer.trace(10.0, -0.01, &[]).unwrap();
    assert_eq!(down.termination, Some(Termination::Ground));
    assert!(!down.turned);
    let dip = (R / (R + 10.0)).acos();
    let grazing = tracer.trace(10.0, -0.5 * dip, &[]).unwrap();
    assert_eq!(grazing.termination, Some(Termination::Escaped));
    assert!(
        grazing.turned,
        "a ray above the sea horizon passes its perigee"
    );
    // A level launch counts as turned (no sign to keep).
    assert!(tracer.trace(10.0, 0.0, &[]).unwrap().turned);
    // The closed-form straight ray says the same.
    let line = |e: f64| ghostship::tracer::straight_ray(10.0, e, R, 40_000.0, &[]).unwrap();
    assert!(!line(0.001).turned && !line(-0.01).turned);
    assert!(line(-0.5 * dip).turned && line(0.0).turned);
    // In the perfect duct (n ∝ 1/r) a slightly downward ray stays downward (log spiral into
    // the sea); an upward one stays upward.
    let duct = InverseRadius(1.000_3);
    let tracer = Tracer::new(&duct, config(0.01)).unwrap();
    assert!(!tracer.trace(25.0, -1e-4, &[]).unwrap().turned);
    assert!(!tracer.trace(25.0, 1e-4, &[]).unwrap().turned);
    // Stronger than the duct (n ∝ 1/r², n·r falls with height): an upward ray is turned back
    // down (apogee r₀/cos α, 3 m above the camera at α = 1 mrad) and lands.
    struct Trap;
    impl StratifiedIndex for Trap {
        fn index_and_derivative(&self, h: f64) -> (f64, f64) {
            let q = R / (R + h);
            (1.000_3 * q * q, -2.0 * 1.000_3 * q * q / (R + h))
        }
    }
    let tracer = Tracer::new(&Trap, config(0.01)).unwrap();
    let rec = tracer.trace(10.0, 1e-3, &[]).unwrap();
    assert_eq!(rec.termination, Some(Termination::Ground), "{rec:?}");
    assert!(rec.turned);
}

#[test]
fn an_observer_on_a_break_starts_from_the_side_it_heads_to() {
    // The Novaya Zemlya layer ends at 100 m, where dn/dh jumps; an observer exactly there used
    // to take the first stage of a descending ray from the wrong side of the jump, so at 1e-5 m
    // and below every step of near-level downward rays was rejected until the step budget ran
    // out (stuck at distance 0). Both paths, every ray, must now finish in a few hundred steps.
    use ghostship::profile::{AirColumn, SyntheticAtmosphere};
    use ghostship::refractivity::RefractiveAtmosphere;
    use std::sync::Arc;
    let column: Arc<dyn AirColumn> = Arc::new(
        SyntheticAtmosphere::from_file(&crate::support::data::data_file("novaya_zemlya.toml"))
            .unwrap(),
    );
    let atm = RefractiveAtmosphere::new(column, 550.0).unwrap();
    assert!(atm.breaks_m().contains(&100.0), "{:?}", atm.breaks_m());
    let field = Spherical {
        index: &atm,
        earth_radius_m: R,
    };
    for tolerance_m in [1e-4, 1e-5, 1e-6] {
        let cfg = TracerConfig {
            tolerance_m,
            stop_after_last_target: false,
            max_steps: 20_000,
            ..TracerConfig::default()
        };
        let tracer = Tracer::new(&atm, cfg.clone()).unwrap();
        for i in 0..=40 {
            let alpha = (-0.02 + 0.0005 * i as f64).to_radians();
            let rec = tracer.trace(100.0, alpha, &[1_000.0]).unwrap();
            let (sin_a, cos_a) = alpha.sin_cos();
            let exact = trace_field(
                &field,
                Ground::Sphere { radius_m: R },
                &cfg,
                DVec3::new(0.0, 0.0, R + 100.0),
                DVec3::new(cos_a, 0.0, sin_a),
                &[1_000.0],
                &mut NoHook,
                None,
            )
            .unwrap();
            for (path, r) in [("planar", &rec), ("3-D", &exact)] {
                assert!(
                    matches!(
                        r.termination,
                        Some(Termination::Escaped | Termination::Ground)
                    ) && r.steps() < 5_000,
                    "{path}, tolerance {tolerance_m}, α {alpha}: {:?} after {} steps",
                    r.termination,
                    r.steps()
                );
            }
        }
    }
}
