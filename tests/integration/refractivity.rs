//! Refractivity stage and `profile` outputs: Ciddor, exact dn/dh, the lookup table, regimes,
//! ducts, critical gradients and the exporters.

use std::sync::Arc;

use ghostship::profile::{AirColumn, AirSample, InversionKind, InversionLayer};
use ghostship::refractivity::columns::{
    LapseRateColumn, SmoothInversionColumn, StandardAtmosphereColumn,
};
use ghostship::refractivity::regimes::AUTOCONVECTIVE_LAPSE_K_PER_M;
use ghostship::refractivity::{
    RefractiveAtmosphere, RefractivityError, RegimeKind, RegimeOptions,
    critical_temperature_gradient_k_per_m, detect_regimes,
};
use ghostship::report::{
    CSV_HEADER, LayersReport, PlotOptions, ProfileGrid, ProfilePlot, layers_json, profile_csv,
    profile_png, summary_text,
};
use ghostship::sounding::{HeightSource, Level};
use ghostship::tracer::StratifiedIndex;
use ghostship::units::EARTH_RADIUS_M;

fn isothermal() -> LapseRateColumn {
    LapseRateColumn {
        surface_height_m: 0.0,
        surface_temperature_k: 253.15,
        surface_pressure_pa: 101_325.0,
        gradient_k_per_m: 0.0,
        vapour_pressure_pa: 0.0,
        isothermal_above_agl_m: f64::INFINITY,
    }
}

fn moist_lapse() -> LapseRateColumn {
    LapseRateColumn {
        surface_height_m: 35.0,
        surface_temperature_k: 283.15,
        surface_pressure_pa: 100_800.0,
        gradient_k_per_m: -0.0065,
        vapour_pressure_pa: 900.0,
        isothermal_above_agl_m: 11_000.0,
    }
}

/// A "15 m" inversion, 263.15 → 273.15 K centred 30 m above the surface (peak ≈ 1.4 K/m).
fn sharp_inversion() -> SmoothInversionColumn {
    SmoothInversionColumn {
        surface_height_m: 12.0,
        surface_pressure_pa: 101_325.0,
        temperature_below_k: 263.15,
        temperature_above_k: 273.15,
        centre_agl_m: 30.0,
        half_width_m: 3.75,
        surface_vapour_pressure_pa: 150.0,
    }
}

fn atmosphere(column: impl AirColumn + 'static) -> RefractiveAtmosphere {
    RefractiveAtmosphere::new(Arc::new(column), 550.0).expect("valid column")
}

/// Deterministic pseudo-random numbers in [0, 1) (SplitMix64), so failures reproduce.
fn uniform(seed: u64, count: usize) -> Vec<f64> {
    let mut state = seed;
    (0..count)
        .map(|_| {
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        })
        .collect()
}

#[test]
fn exact_derivative_matches_central_difference_of_n() {
    let cases: Vec<(&str, RefractiveAtmosphere, Vec<f64>)> = vec![
        (
            "isothermal",
            atmosphere(isothermal()),
            vec![0.5, 100.0, 5_000.0],
        ),
        (
            "moist lapse",
            atmosphere(moist_lapse()),
            vec![0.5, 300.0, 8_000.0],
        ),
        (
            "us1976",
            atmosphere(StandardAtmosphereColumn {
                surface_height_m: 0.0,
            }),
            vec![1.0, 5_000.0, 15_000.0, 25_000.0],
        ),
        (
            "inversion",
            atmosphere(sharp_inversion()),
            vec![5.0, 26.0, 30.0, 33.5, 40.0, 900.0],
        ),
    ];
    for (name, atm, heights) in cases {
        for h in heights {
            let fd = |d: f64| {
                (atm.exact_refractivity(h + d).0 - atm.exact_refractivity(h - d).0) / (2.0 * d)
            };
            // Richardson extrapolation of two central differences cancels the d²·n'''/6 term
            // (up to 4e-12 m⁻¹ in the inversion at d = 1 cm); what remains is d⁴·n⁽⁵⁾/30 (n⁽⁵⁾ ≲
            // 1e-6 m⁻⁵ here → < 1e-15) and rounding of n − 1 (~5e-20 / 5e-3 m ≈ 1e-17).
            let fd = (4.0 * fd(0.005) - fd(0.01)) / 3.0;
            let (_, exact) = atm.exact_refractivity(h);
            let tol = 2e-15 + 1e-9 * exact.abs();
            assert!(
                (fd - exact).abs() < tol,
                "{name} at {h} m: fd {fd:e} exact {exact:e}"
            );
        }
    }
}

#[test]
fn exact_n_is_ciddor_of_the_column_state() {
    let column = moist_lapse();
    let atm = atmosphere(column);
    let air = column.air_at(column.surface_height_m + 250.0);
    let n = ghostship::refractivity::ciddor_refractive_index(
        550e-9,
        air.temperature_k,
        air.pressure_pa,
        air.vapour_pressure_pa,
        450.0,
    );
    assert!((atm.exact(250.0).0 - n).abs() < 1e-15);
    // CO₂ changes n by the published factor only.
    let more = RefractiveAtmosphere::new(Arc::new(column), 550.0)
        .unwrap()
        .with_co2_ppm(550.0)
        .unwrap();
    assert_eq!(more.co2_ppm(), 550.0);
    assert!(more.exact(250.0).0 > n);
}

/// The table against the exact evaluation at random heights (not the construction's check
/// points) for smooth columns, the US1976 column and the sharp inversion.
#[test]
fn table_agrees_with_exact_evaluation() {
    let cases: Vec<(&str, RefractiveAtmosphere, f64)> = vec![
        ("isothermal", atmosphere(isothermal()), 20_000.0),
        ("moist lapse", atmosphere(moist_lapse()), 20_000.0),
        (
            "us1976",
            atmosphere(StandardAtmosphereColumn {
                surface_height_m: 0.0,
            }),
            85_000.0,
        ),
        ("inversion", atmosphere(sharp_inversion()), 20_000.0),
    ];
    for (name, atm, top) in cases {
        let err = atm.table_max_error();
        // At the construction's check points the table is held to 1e-14 in n and dn/dh (cells
        // that miss it use the exact formula): README's accuracy table states that bound.
        assert!(err.max_abs_dn() <= 1e-14, "{name}: {err:?}");
        assert!(err.max_abs_ddndh_per_m() <= 1e-14, "{name}: {err:?}");
        // Below 4 km: no cell needs the exact fallback, except at the sharpest curvature of the
        // inversion (measured: 14 cells, where plain Hermite reaches 1.4e-11 m⁻¹).
        let allowed = if name == "inversion" { 40 } else { 0 };
        assert!(err.fine.exact_cells <= allowed, "{name}: {err:?}");
        let u = uniform(7, 40_000);
        let mut worst = (0.0f64, 0.0f64);
        for (i, x) in u.iter().enumerate() {
            // Half the points in the lowest 100 m (where the inversion is), half up to `top`.
            let h = if i % 2 == 0 { 100.0 * x } else { top * x };
            let (n_t, d_t) = atm.table_refractivity(h);
            let (n_e, d_e) = atm.exact_refractivity(h);
            worst.0 = worst.0.max((n_t - n_e).abs());
            worst.1 = worst.1.max((d_t - d_e).abs());
        }
        assert!(
            worst.0 < 2e-11 && worst.1 < 2e-11,
            "{name}: worst {worst:?}"
        );
        eprintln!(
            "{name}: table {err:?}; random-point worst |Δn| {:e}, |Δdn/dh| {:e}",
            worst.0, worst.1
        );
    }
}

/// The table is built where lookups land (not by Bouguer's envelope), and a cell's values do not depend on when or by which
/// thread it was built: lookups on a fresh atmosphere equal, bit for bit, those on one whose
/// whole table was built in parallel first.
#[test]
fn the_table_is_built_lazily_and_the_same_whatever_the_order() {
    let lazy = atmosphere(sharp_inversion());
    // Bouguer's envelope (which every curved-ray render builds) surveys the whole profile
    // without filling the table.
    let _ = ghostship::tracer::BouguerEnvelope::new(&lazy, EARTH_RADIUS_M, 40_000.0);
    let (built, all) = lazy.table_cells_built();
    assert_eq!(built, 0, "nothing is built before a lookup");
    let _ = lazy.table_refractivity(10.0);
    let (built, _) = lazy.table_cells_built();
    assert!(
        built > 0 && built * 100 < all,
        "{built} of {all} cells after one lookup"
    );
    let eager = atmosphere(sharp_inversion());
    let _ = eager.table_max_error();
    assert_eq!(eager.table_cells_built(), (all, all));
    // Descending, so the lazy table meets its chunks in the opposite order to the eager build.
    let mut heights = uniform(11, 20_000);
    heights.iter_mut().for_each(|x| *x *= 40_000.0);
    heights.sort_by(|a, b| b.total_cmp(a));
    for &h in &heights {
        let (a, b) = (lazy.table_refractivity(h), eager.table_refractivity(h));
        assert!(
            a.0.to_bits() == b.0.to_bits() && a.1.to_bits() == b.1.to_bits(),
            "{h} m: {a:?} vs {b:?}"
        );
    }
    assert_eq!(lazy.table_max_error(), eager.table_max_error());
}

/// US1976 has six lapse-rate changes below 80 km where dn/dh jumps; the cells holding them are
/// cut at the kink, a quintic on each side, so no cell falls back to the exact formula and the
/// table keeps the jump of dn/dh within its bound on both sides.
#[test]
fn us1976_kinks_cut_their_cells() {
    // A table up to 80 km (the default stops at the tracer's 40 km top) holds all six.
    let atm = atmosphere(StandardAtmosphereColumn {
        surface_height_m: 0.0,
    })
    .with_table_spec(ghostship::refractivity::TableSpec {
        coarse_top_agl_m: 80_000.0,
        ..Default::default()
    })
    .expect("valid spec");
    let err = atm.table_max_error();
    assert_eq!(
        (
            err.coarse.cut_cells,
            err.coarse.exact_cells,
            err.fine.exact_cells
        ),
        (6, 0, 0),
        "{err:?}"
    );
    assert!(
        err.max_abs_dn() <= 1e-14 && err.max_abs_ddndh_per_m() <= 1e-14,
        "{err:?}"
    );
    // Each layer base (geopotential → geometric) is a break; the table holds the jump of dn/dh
    // there ((n−1)/T·Δ(dT/dh): 2.9e-9 m⁻¹ at 11 km, 9e-11 at 20 km, ~1e-12 higher up) to its
    // bound on each side.
    let r = ghostship::profile::us1976::US1976_EARTH_RADIUS_M;
    for base in [11_000.0, 20_000.0, 32_000.0, 47_000.0, 51_000.0, 71_000.0] {
        let kink = r * base / (r - base);
        assert!(
            atm.breaks_m().iter().any(|b| (b - kink).abs() < 1e-6),
            "{kink}: {:?}",
            atm.breaks_m()
        );
        for offset_m in [-2.0, -0.01, 0.01, 2.0] {
            let h = kink + offset_m;
            let (table, exact) = (atm.table_refractivity(h), atm.exact_refractivity(h));
            assert!(
                (table.0 - exact.0).abs() <= 1e-14 && (table.1 - exact.1).abs() <= 1e-14,
                "{h} m: {table:?} vs {exact:?}"
            );
        }
    }
}

#[test]
fn stratified_index_clamps_below_surface_and_passes_nan() {
    let atm = atmosphere(moist_lapse());
    let field: &dyn StratifiedIndex = &atm;
    assert_eq!(
        field.index_and_derivative(-5.0),
        field.index_and_derivative(0.0)
    );
    let (n, d) = field.index_and_derivative(f64::NAN);
    assert!(n.is_nan() && d.is_nan());
    // Above the table: exact.
    let (n, d) = field.index_and_derivative(95_000.0);
    assert_eq!((n, d), atm.exact(95_000.0));
    assert!(atm.surface_height_m() == 35.0);
}

#[test]
fn rejects_bad_wavelength_and_unphysical_air() {
    let err = RefractiveAtmosphere::new(Arc::new(isothermal()), 250.0).unwrap_err();
    assert!(matches!(
        err,
        RefractivityError::WavelengthOutOfRange { .. }
    ));
    assert!(RefractiveAtmosphere::new(Arc::new(isothermal()), f64::NAN).is_err());
    struct Broken;
    impl AirColumn for Broken {
        fn surface_height_m(&self) -> f64 {
            0.0
        }
        fn air_at(&self, height_m: f64) -> AirSample {
            AirSample {
                temperature_k: 250.0,
                pressure_pa: 1000.0 - height_m, // negative above 1 km
                dpressure_dh_pa_per_m: -1.0,
                ..AirSample::default()
            }
        }
    }
    let err = RefractiveAtmosphere::new(Arc::new(Broken), 550.0).unwrap_err();
    assert!(matches!(err, RefractivityError::InvalidAir { .. }), "{err}");
}

/// docs/references.md §2.3: 0.1121 K/m at 0 °C and 0.1286 K/m at 15 °C (1013.25 hPa, 550 nm).
#[test]
fn critical_gradient_matches_reference_and_definition() {
    let g0 = critical_temperature_gradient_k_per_m(273.15, 101_325.0, 0.0, 550e-9, EARTH_RADIUS_M);
    let g15 = critical_temperature_gradient_k_per_m(288.15, 101_325.0, 0.0, 550e-9, EARTH_RADIUS_M);
    assert!((g0 - 0.1121).abs() < 1e-4, "{g0}");
    assert!((g15 - 0.1286).abs() < 1e-4, "{g15}");
    // The rest of the table in docs/references.md §2.3 (given to 3–4 digits).
    for (t_c, expected, tol) in [
        (30.0, 0.146, 5e-4),
        (-10.0, 0.1016, 1e-4),
        (-20.0, 0.0915, 1e-4),
        (-30.0, 0.0817, 1e-4),
    ] {
        let g = critical_temperature_gradient_k_per_m(
            t_c + 273.15,
            101_325.0,
            0.0,
            550e-9,
            EARTH_RADIUS_M,
        );
        assert!((g - expected).abs() < tol, "{t_c} °C: {g}");
    }
    // Definition: a hydrostatic layer with that gradient has dn/dh = −1/R at its base (the
    // compressibility term of Ciddor, absent from the P/T model, moves it by < 0.1 %).
    let atm = atmosphere(LapseRateColumn {
        surface_height_m: 0.0,
        surface_temperature_k: 273.15,
        surface_pressure_pa: 101_325.0,
        gradient_k_per_m: g0,
        vapour_pressure_pa: 0.0,
        isothermal_above_agl_m: 1_000.0,
    });
    let (_, d) = atm.exact(0.0);
    // The P/T model neglects Ciddor's compressibility Z, whose temperature term changes
    // d ln(n−1)/dh by (P/T)·|a1|·dT/dh ≈ 371·2.93e-8·0.112 ≈ 1.2e-6 m⁻¹ against
    // |d ln(P/T)/dh| ≈ 5.4e-4 m⁻¹: 0.23 % (+0.06 % from the pressure term), making the ray a
    // little more curved than Earth's.
    let ratio = -d * EARTH_RADIUS_M;
    assert!(ratio > 1.0 && ratio < 1.004, "{ratio}");
}

#[test]
fn standard_and_isothermal_air_have_no_regimes() {
    for atm in [
        atmosphere(isothermal()),
        atmosphere(StandardAtmosphereColumn {
            surface_height_m: 0.0,
        }),
    ] {
        let layers = detect_regimes(&atm, 5_000.0, &RegimeOptions::default());
        assert!(layers.is_empty(), "{layers:?}");
    }
}

#[test]
fn sharp_inversion_gives_trapping_layer_and_duct() {
    let column = sharp_inversion();
    let atm = atmosphere(column);
    let surface = atm.surface_height_m();
    let layers = detect_regimes(&atm, surface + 500.0, &RegimeOptions::default());
    let trapping: Vec<_> = layers
        .iter()
        .filter(|l| l.kind == RegimeKind::Trapping)
        .collect();
    assert_eq!(trapping.len(), 1, "{layers:#?}");
    let t = trapping[0];
    assert!(t.base_agl_m < 30.0 && t.top_agl_m > 30.0, "{t:?}");
    // At the boundaries the exact dN/dh is at the threshold −10⁹/R (linear refinement within a
    // 0.25 m sample: a few N/km).
    let threshold = -1e9 / EARTH_RADIUS_M;
    for h in [t.base_agl_m, t.top_agl_m] {
        let d = atm.exact(h).1 * 1e9;
        assert!((d - threshold).abs() < 5.0, "dN/dh {d} at {h}");
    }
    // Framed by super-refraction below and above.
    let sup = |above: bool| {
        layers.iter().any(|l| {
            l.kind == RegimeKind::SuperRefraction
                && if above {
                    (l.base_agl_m - t.top_agl_m).abs() < 1e-9
                } else {
                    (l.top_agl_m - t.base_agl_m).abs() < 1e-9
                }
        })
    };
    assert!(sup(false) && sup(true), "{layers:#?}");
    // Minimum dN/dh at the peak gradient (30 m) by the P/T model: −(n−1)(dT/dh + g/R_d)/T,
    // within 1 % (the compressibility term of Ciddor is ≈ 0.3 %).
    let peak = atm.sample_at(atm.surface_height_m() + 30.0);
    let model = -peak.n_minus_1 * (peak.air.dtemperature_dh_k_per_m + AUTOCONVECTIVE_LAPSE_K_PER_M)
        / peak.air.temperature_k
        * 1e9;
    assert!(
        (t.min_dndh_per_km / model - 1.0).abs() < 0.01,
        "{} vs {model}",
        t.min_dndh_per_km
    );
    assert!(
        t.max_dtdh_k_per_m > 1.0 && t.max_dtdh_k_per_m < 1.6,
        "{t:?}"
    );
    // The duct: M at its base equals M at the top of the trapping layer, or it reaches the ground.
    let duct = t.duct.as_ref().expect("trapping layer has a duct");
    let m = |h: f64| atm.exact_refractivity(h).0 * 1e6 + h / EARTH_RADIUS_M * 1e6;
    assert!((duct.top_agl_m - t.top_agl_m).abs() < 1e-12);
    assert!(duct.base_agl_m < t.base_agl_m);
    if duct.surface_based {
        assert_eq!(duct.base_agl_m, 0.0);
        assert!(m(0.0) > m(duct.top_agl_m));
    } else {
        assert!(
            (m(duct.base_agl_m) - m(duct.top_agl_m)).abs() < 0.01,
            "{duct:?}"
        );
    }
    // Deficit: M(trapping base) − M(top), to sampling accuracy.
    let deficit = m(t.base_agl_m) - m(t.top_agl_m);
    assert!(
        (duct.m_deficit - deficit).abs() < 0.01,
        "{} vs {deficit}",
        duct.m_deficit
    );
    // The critical gradient reported is the one of the local air (≈ 0.10 K/m at −5 °C).
    assert!(
        t.critical_gradient_k_per_m > 0.09 && t.critical_gradient_k_per_m < 0.11,
        "{t:?}"
    );
}

/// An elevated duct: the same inversion 200 m up in an otherwise standard-lapse column would
/// need a different column; instead a warm-to-cold inversion aloft is represented by raising
/// the centre, and the duct base must then lie above the ground.
#[test]
fn elevated_inversion_gives_elevated_duct() {
    let column = SmoothInversionColumn {
        centre_agl_m: 400.0,
        ..sharp_inversion()
    };
    let atm = atmosphere(column);
    let layers = detect_regimes(
        &atm,
        atm.surface_height_m() + 1_000.0,
        &RegimeOptions::default(),
    );
    let duct = layers.iter().find_map(|l| l.duct.clone()).expect("duct");
    assert!(
        !duct.surface_based && duct.base_agl_m > 0.0 && duct.base_agl_m < 397.0,
        "{duct:?}"
    );
}

/// A temperature drop (T falling 5 K across the layer) makes dn/dh positive; at the edges of
/// the inferior-mirage layer dT/dh is the autoconvective −g/R_d (dry hydrostatic air).
#[test]
fn superadiabatic_layer_is_an_inferior_mirage_layer() {
    let column = SmoothInversionColumn {
        temperature_below_k: 278.15,
        temperature_above_k: 273.15,
        centre_agl_m: 10.0,
        surface_vapour_pressure_pa: 0.0,
        ..sharp_inversion()
    };
    let atm = atmosphere(column);
    let layers = detect_regimes(
        &atm,
        atm.surface_height_m() + 200.0,
        &RegimeOptions::default(),
    );
    let inferior: Vec<_> = layers
        .iter()
        .filter(|l| l.kind == RegimeKind::InferiorMirage)
        .collect();
    assert_eq!(inferior.len(), 1, "{layers:#?}");
    let l = inferior[0];
    assert!(l.base_agl_m < 10.0 && l.top_agl_m > 10.0);
    assert!(l.max_dndh_per_km > 0.0 && l.min_dtdh_k_per_m < -0.5);
    for h in [l.base_agl_m, l.top_agl_m] {
        let s = atm.sample_at(atm.surface_height_m() + h);
        let dtdh = s.air.dtemperature_dh_k_per_m;
        assert!(
            (dtdh + AUTOCONVECTIVE_LAPSE_K_PER_M).abs() < 2e-3,
            "dT/dh {dtdh} at {h}"
        );
    }
}

#[test]
fn profile_csv_has_the_documented_columns_and_grid() {
    let atm = atmosphere(moist_lapse());
    let bytes = profile_csv(&atm, &ProfileGrid::default());
    let text = String::from_utf8(bytes).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "height_m,temperature_k,pressure_hpa,vapour_pressure_hpa,n_minus_1,dn_dh_per_m,dt_dh_k_per_m"
    );
    assert_eq!(CSV_HEADER.split(',').count(), 7);
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap()).collect())
        .collect();
    // 0..2000 by 1 m, 2010..20000 by 10 m, 20100..40000 by 100 m.
    assert_eq!(rows.len(), 2001 + 1800 + 200);
    assert_eq!(rows[0][0], 35.0);
    assert_eq!(rows[1][0], 36.0);
    assert_eq!(rows[2001][0], 35.0 + 2010.0);
    assert_eq!(rows.last().unwrap()[0], 35.0 + 40_000.0);
    for r in &rows {
        assert_eq!(r.len(), 7);
        assert!(r.iter().all(|v| v.is_finite()));
    }
    // Values against the column and the exact path.
    let r = &rows[500];
    let s = atm.sample_at(r[0]);
    assert!((r[1] - s.air.temperature_k).abs() < 1e-4);
    assert!((r[2] - s.air.pressure_pa / 100.0).abs() < 1e-5);
    assert!((r[3] - 9.0).abs() < 1e-9);
    assert!((r[4] / s.n_minus_1 - 1.0).abs() < 1e-9);
    assert!((r[5] / s.dn_dh_per_m - 1.0).abs() < 1e-9);
    assert!((r[6] + 0.0065).abs() < 1e-9);
}

fn inversion_layer(atm: &RefractiveAtmosphere) -> InversionLayer {
    let s = atm.surface_height_m();
    InversionLayer {
        base_m: s + 22.5,
        top_m: s + 37.5,
        base_agl_m: 22.5,
        top_agl_m: 37.5,
        delta_t_k: 9.0,
        max_gradient_k_per_m: 1.33,
        kind: InversionKind::Elevated,
    }
}

#[test]
fn layers_json_has_the_documented_shape() {
    let atm = atmosphere(sharp_inversion());
    let regimes = detect_regimes(
        &atm,
        atm.surface_height_m() + 500.0,
        &RegimeOptions::default(),
    );
    let report = LayersReport::new(&atm, &[inversion_layer(&atm)], &regimes);
    let v: serde_json::Value = serde_json::from_slice(&layers_json(&report)).unwrap();
    let surface = &v["surface"];
    assert_eq!(surface["height_m"], 12.0);
    assert!((surface["temperature_k"].as_f64().unwrap() - 263.15).abs() < 0.01);
    assert!((surface["pressure_hpa"].as_f64().unwrap() - 1013.25).abs() < 1e-9);
    let inv = &v["inversions"][0];
    for key in [
        "base_m",
        "top_m",
        "base_agl_m",
        "top_agl_m",
        "delta_t_k",
        "max_gradient_k_per_m",
    ] {
        assert!(inv[key].is_f64(), "{key}");
    }
    assert_eq!(inv["kind"], "elevated");
    let ducts = v["ducts"].as_array().unwrap();
    assert_eq!(ducts.len(), 1);
    for key in ["base_m", "top_m", "min_dndh_per_km"] {
        assert!(ducts[0][key].is_f64(), "{key}");
    }
    assert!(ducts[0]["min_dndh_per_km"].as_f64().unwrap() < -157.0);
    assert_eq!(v["wavelength_nm"], 550.0);
    assert!(
        v["regimes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|r| r["kind"] == "trapping")
    );
    let text = summary_text(&report);
    for needle in [
        "Surface 12.0 m",
        "Inversions: 1",
        "Ducts: 1",
        "trapping",
        "critical gradient",
    ] {
        assert!(text.contains(needle), "missing {needle:?} in\n{text}");
    }
}

/// Pixels of the inversion shading (light red over white) and of the trapping shading (blue over
/// white) appear exactly when there are such layers; the image has the requested size.
#[test]
fn profile_png_draws_panels_and_shading() {
    let column = sharp_inversion();
    let atm = atmosphere(column);
    let regimes = detect_regimes(
        &atm,
        atm.surface_height_m() + 500.0,
        &RegimeOptions::default(),
    );
    let levels: Vec<Level> = [0.0, 10.0, 20.0, 25.0, 30.0, 35.0, 40.0, 60.0, 100.0, 150.0]
        .iter()
        .enumerate()
        .map(|(i, &h)| Level {
            height_m: atm.surface_height_m() + h,
            pressure_pa: None,
            temperature_k: column.air_at(atm.surface_height_m() + h).temperature_k,
            vapour_pressure_pa: None,
            height_source: HeightSource::Measured,
            line: i + 1,
        })
        .collect();
    let inversions = [inversion_layer(&atm)];
    let options = PlotOptions {
        top_agl_m: 150.0,
        ..PlotOptions::default()
    };
    let plot = ProfilePlot {
        atmosphere: &atm,
        levels: &levels,
        inversions: &inversions,
        regimes: &regimes,
        title: "Synthetic 15 m inversion, 263 → 273 K at 30 m",
    };
    let png = profile_png(&plot, &options).unwrap();
    if let Ok(dir) = std::env::var("GHOSTSHIP_PLOT_DIR") {
        std::fs::write(std::path::Path::new(&dir).join("profile_test.png"), &png).unwrap();
    }
    let img = image::load_from_memory(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (1400, 900));
    let count = |img: &image::RgbImage, target: [u8; 3]| {
        img.pixels()
            .filter(|p| p.0.iter().zip(target).all(|(a, b)| a.abs_diff(b) <= 3))
            .count()
    };
    // 0.25 of (240,120,100) over white = (251,221,216); 0.3 of (70,110,230) over white.
    let inv_pink = [251, 221, 216];
    let trap_blue = [200, 212, 248];
    assert!(count(&img, inv_pink) > 5_000, "inversion shading missing");
    assert!(count(&img, trap_blue) > 5_000, "trapping shading missing");
    let bare = ProfilePlot {
        inversions: &[],
        regimes: &[],
        ..plot
    };
    let img = image::load_from_memory(&profile_png(&bare, &options).unwrap())
        .unwrap()
        .to_rgb8();
    assert_eq!(count(&img, inv_pink), 0);
    assert_eq!(count(&img, trap_blue), 0);
    // Bad options are errors, not panics.
    assert!(
        profile_png(
            &plot,
            &PlotOptions {
                width_px: 10,
                ..options
            }
        )
        .is_err()
    );
    assert!(
        profile_png(
            &plot,
            &PlotOptions {
                top_agl_m: f64::NAN,
                ..options
            }
        )
        .is_err()
    );
}

/// A measured sounding as a column with a kink at every level: T and e linear between levels,
/// P hydrostatic (closed form per linear-T segment) from the measured surface pressure,
/// isothermal above the top. Built here only to exercise the table's exact fallback and the
/// regime detection on real structure (the real fit is the profile stage's job).
struct PiecewiseSounding {
    heights_m: Vec<f64>,
    temperatures_k: Vec<f64>,
    vapour_pa: Vec<f64>,
    /// Pressure at each level (Pa), integrated hydrostatically from the surface.
    pressures_pa: Vec<f64>,
}

const G_OVER_R: f64 =
    ghostship::units::STANDARD_GRAVITY_M_S2 / ghostship::units::DRY_AIR_GAS_CONSTANT_J_KG_K;

/// ∫ dz/T over [0, dz] for T linear from t0 with slope g.
fn inverse_t_integral(t0: f64, g: f64, dz: f64) -> f64 {
    if g.abs() < 1e-12 {
        dz / t0
    } else {
        ((t0 + g * dz) / t0).ln() / g
    }
}

impl PiecewiseSounding {
    fn read(name: &str) -> (Self, Vec<Level>) {
        let path = crate::support::data::sounding(name);
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("cannot read sounding {} ({e})", path.display()));
        let mut s = PiecewiseSounding {
            heights_m: vec![],
            temperatures_k: vec![],
            vapour_pa: vec![],
            pressures_pa: vec![],
        };
        let mut levels = Vec::new();
        let mut surface_pressure = None;
        for (i, line) in text.lines().enumerate() {
            if line.starts_with('#') || line.starts_with("pressure_hpa") {
                continue;
            }
            let f: Vec<&str> = line.split(',').collect();
            let (Ok(h), Ok(t_c)) = (f[1].parse::<f64>(), f[2].parse::<f64>()) else {
                continue;
            };
            if s.heights_m.last().is_some_and(|&last| h <= last) {
                continue;
            }
            if surface_pressure.is_none() {
                surface_pressure = Some(f[0].parse::<f64>().expect("surface pressure") * 100.0);
            }
            let t = t_c + 273.15;
            let e = f[3]
                .parse::<f64>()
                .map(|d| ghostship::units::saturation_vapour_pressure_pa(d + 273.15))
                .unwrap_or(0.0);
            s.heights_m.push(h);
            s.temperatures_k.push(t);
            s.vapour_pa.push(e);
            levels.push(Level {
                height_m: h,
                pressure_pa: None,
                temperature_k: t,
                vapour_pressure_pa: Some(e),
                height_source: HeightSource::Measured,
                line: i + 1,
            });
        }
        let mut p = surface_pressure.expect("no levels");
        s.pressures_pa.push(p);
        for k in 1..s.heights_m.len() {
            let dz = s.heights_m[k] - s.heights_m[k - 1];
            let g = (s.temperatures_k[k] - s.temperatures_k[k - 1]) / dz;
            p *= (-G_OVER_R * inverse_t_integral(s.temperatures_k[k - 1], g, dz)).exp();
            s.pressures_pa.push(p);
        }
        (s, levels)
    }
}

impl AirColumn for PiecewiseSounding {
    fn surface_height_m(&self) -> f64 {
        self.heights_m[0]
    }

    fn air_at(&self, height_m: f64) -> AirSample {
        let n = self.heights_m.len();
        let k = self
            .heights_m
            .partition_point(|&h| h <= height_m)
            .clamp(1, n)
            - 1;
        let (t0, p0, e0) = (
            self.temperatures_k[k],
            self.pressures_pa[k],
            self.vapour_pa[k],
        );
        let dz = height_m - self.heights_m[k];
        let (g, de) = if k + 1 < n {
            let span = self.heights_m[k + 1] - self.heights_m[k];
            (
                (self.temperatures_k[k + 1] - t0) / span,
                (self.vapour_pa[k + 1] - e0) / span,
            )
        } else {
            (0.0, 0.0)
        };
        let t = t0 + g * dz;
        let p = p0 * (-G_OVER_R * inverse_t_integral(t0, g, dz)).exp();
        let e = (e0 + de * dz).min(0.5 * p);
        AirSample {
            temperature_k: t,
            dtemperature_dh_k_per_m: g,
            pressure_pa: p,
            dpressure_dh_pa_per_m: -G_OVER_R * p / t,
            vapour_pressure_pa: e,
            dvapour_pressure_dh_pa_per_m: if e < e0 + de * dz {
                -0.5 * G_OVER_R * p / t
            } else {
                de
            },
        }
    }
}

/// Bjørnøya 2024-02-26 11 UTC (1 s RS41): ~11 m between levels, so dn/dh jumps at every level.
/// The table must still agree with the exact path everywhere (by falling back in those cells),
/// and the detected layers must contain exactly the heights where dN/dh is below −79 N/km.
#[test]
fn real_sounding_with_kinks_table_and_regimes() {
    let (column, levels) = PiecewiseSounding::read("Bjornoya-01028_2024022611.csv");
    let atm = atmosphere(column);
    let err = atm.table_max_error();
    // The construction's 1e-14 at its check points (README's accuracy table), kinks and all.
    assert!(
        err.max_abs_dn() <= 1e-14 && err.max_abs_ddndh_per_m() <= 1e-14,
        "{err:?}"
    );
    assert!(err.fine.exact_cells > 100, "kinks must be caught: {err:?}");
    eprintln!("Bjornoya table: {err:?}");
    for (i, x) in uniform(11, 40_000).iter().enumerate() {
        let h = if i % 2 == 0 {
            1_000.0 * x
        } else {
            30_000.0 * x
        };
        let (n_t, d_t) = atm.table_refractivity(h);
        let (n_e, d_e) = atm.exact_refractivity(h);
        assert!(
            (n_t - n_e).abs() < 2e-11 && (d_t - d_e).abs() < 2e-11,
            "at {h}: {d_t:e} vs {d_e:e}"
        );
    }
    let surface = atm.surface_height_m();
    let layers = detect_regimes(&atm, surface + 1_000.0, &RegimeOptions::default());
    for w in layers.windows(2) {
        assert!(w[0].top_m <= w[1].base_m + 1e-9, "overlap: {w:?}");
    }
    // Independent check on a 0.1 m grid offset from the detection's 0.25 m samples (points
    // within 0.3 m of a layer boundary are skipped: boundaries are interpolated).
    let inside = |h: f64, kinds: &[RegimeKind]| {
        layers
            .iter()
            .any(|l| kinds.contains(&l.kind) && l.base_agl_m <= h && h <= l.top_agl_m)
    };
    let near_edge = |h: f64| {
        layers
            .iter()
            .any(|l| (l.base_agl_m - h).abs() < 0.3 || (l.top_agl_m - h).abs() < 0.3)
    };
    let mut strong = 0;
    for k in 0..9_990 {
        let h = 0.05 + 0.1 * k as f64;
        if near_edge(h) {
            continue;
        }
        let d = atm.exact(h).1 * 1e9;
        let expect_strong = d < -79.0;
        strong += expect_strong as usize;
        assert_eq!(
            inside(h, &[RegimeKind::Trapping, RegimeKind::SuperRefraction]),
            expect_strong,
            "{h} m AGL: dN/dh {d}"
        );
        assert_eq!(
            inside(h, &[RegimeKind::InferiorMirage]),
            d > 0.0,
            "{h} m AGL: dN/dh {d}"
        );
    }
    assert!(
        strong > 0,
        "the 86–172 m inversion should be super-refractive"
    );
    eprintln!("{}", summary_text(&LayersReport::new(&atm, &[], &layers)));
    let png = profile_png(
        &ProfilePlot {
            atmosphere: &atm,
            levels: &levels,
            inversions: &[],
            regimes: &layers,
            title: "Bjørnøya 2024-02-26 11 UTC (levels joined linearly)",
        },
        &PlotOptions {
            top_agl_m: 600.0,
            ..PlotOptions::default()
        },
    )
    .unwrap();
    if let Ok(dir) = std::env::var("GHOSTSHIP_PLOT_DIR") {
        std::fs::write(
            std::path::Path::new(&dir).join("profile_bjornoya.png"),
            &png,
        )
        .unwrap();
    }
}

#[test]
fn wavelength_range_is_inclusive_and_dispersion_is_normal() {
    let column = Arc::new(isothermal());
    assert!(RefractiveAtmosphere::new(column.clone(), 299.0).is_err());
    assert!(RefractiveAtmosphere::new(column.clone(), 1701.0).is_err());
    let blue = RefractiveAtmosphere::new(column.clone(), 300.0).unwrap();
    let red = RefractiveAtmosphere::new(column.clone(), 1700.0).unwrap();
    assert!(blue.exact(0.0).0 > red.exact(0.0).0);
    assert!(
        blue.exact(0.0).1 < red.exact(0.0).1,
        "|dn/dh| larger in the blue"
    );
    let atm = RefractiveAtmosphere::new(column, 550.0).unwrap();
    let (n, d) = atm.index_and_derivative(f64::INFINITY);
    assert!(n.is_nan() && d.is_nan());
    assert!(atm.sample_at(f64::NAN).n_minus_1.is_nan());
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        /// For any smooth hydrostatic lapse-rate column the table matches the exact path at
        /// arbitrary heights, and dn/dh agrees with a Richardson central difference of n.
        #[test]
        fn table_and_derivative_hold_for_any_lapse_column(
            t0 in 220.0f64..310.0,
            gradient in -0.0098f64..0.08,
            e in 0.0f64..1500.0,
            surface in -50.0f64..3000.0,
            p0 in 60_000.0f64..105_000.0,
            h in 0.02f64..3_990.0,
            wavelength in 350.0f64..1000.0,
        ) {
            let column = LapseRateColumn {
                surface_height_m: surface,
                surface_temperature_k: t0,
                surface_pressure_pa: p0,
                gradient_k_per_m: gradient,
                vapour_pressure_pa: e.min(0.9 * ghostship::units::saturation_vapour_pressure_pa(t0)),
                isothermal_above_agl_m: 4_000.0,
            };
            let atm = RefractiveAtmosphere::new(Arc::new(column), wavelength).unwrap();
            let (n_t, d_t) = atm.table_refractivity(h);
            let (n_e, d_e) = atm.exact_refractivity(h);
            prop_assert!((n_t - n_e).abs() < 2e-11 && (d_t - d_e).abs() < 2e-11);
            let fd = |d: f64| (atm.exact_refractivity(h + d).0 - atm.exact_refractivity(h - d).0) / (2.0 * d);
            let richardson = (4.0 * fd(0.005) - fd(0.01)) / 3.0;
            prop_assert!((richardson - d_e).abs() < 2e-15 + 1e-9 * d_e.abs(), "{} vs {}", richardson, d_e);
        }
    }
}
