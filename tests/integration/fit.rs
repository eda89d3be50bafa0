//! The temperature fit between levels (issue 10, part 2): PCHIP or linear in ln p, the auto
//! choice by level spacing, and the sensitivity ensemble of `trace --ensemble N`. Checked against
//! the raw numbers of the shipped soundings (read by hand from the CSV files) and independent
//! computations, not against the program's own earlier output.

use std::path::{Path, PathBuf};

use ghostship::atmosphere::{AtmosphereOptions, AtmosphereSource, load_atmosphere};
use ghostship::jobs::TraceJobRequest;
use ghostship::jobs::cache::AtmosphereRequest;
use ghostship::jobs::trace::ElevationSpec;
use ghostship::profile::{AirColumn, FitOptions, Profile, TemperatureFit};
use ghostship::sounding::{Level, ReadOptions, Sounding, read_sounding};
use ghostship::tracer::TracerConfig;

use crate::support::cli::{fails, ghostship, json_file, ok, pipeline_ok, usage_error};
use crate::support::data::{data_file, sounding};

const CHERSKIY: &str = "pressure_levels/Cherskiy-25123_2026020600_all-levels.csv";

fn read(rel: &str) -> Sounding {
    read_sounding(&sounding(rel), &ReadOptions::default()).unwrap()
}

fn fitted(s: &Sounding, fit: TemperatureFit) -> Profile {
    let options = FitOptions {
        temperature_fit: fit,
        ..FitOptions::default()
    };
    Profile::from_sounding(s, &options).unwrap()
}

/// The level of `s` reported at `hpa`.
fn at_hpa(s: &Sounding, hpa: f64) -> &Level {
    s.levels
        .iter()
        .find(|l| l.pressure_pa == Some(hpa * 100.0))
        .unwrap_or_else(|| panic!("no level at {hpa} hPa"))
}

/// Largest dT/dh strictly inside (lo, hi), sampled every 1 cm.
fn max_gradient(p: &Profile, lo: f64, hi: f64) -> f64 {
    let n = ((hi - lo) / 0.01) as usize;
    (1..n)
        .map(|i| {
            p.air_at(lo + (hi - lo) * i as f64 / n as f64)
                .dtemperature_dh_k_per_m
        })
        .fold(f64::MIN, f64::max)
}

#[test]
fn cherskiy_linear_fit_keeps_the_data_gradient_where_pchip_overshoots() {
    // The file: 1002 hPa −34.5 °C (height empty: filled hypsometrically), 1000 hPa −33.7 °C at
    // 165 m.
    let s = read(CHERSKIY);
    let (a, b) = (at_hpa(&s, 1002.0), at_hpa(&s, 1000.0));
    assert!((a.temperature_k - (273.15 - 34.5)).abs() < 1e-9);
    assert!((b.temperature_k - (273.15 - 33.7)).abs() < 1e-9 && b.height_m == 165.0);
    let secant = (b.temperature_k - a.temperature_k) / (b.height_m - a.height_m);
    assert!(secant > 0.05 && secant < 0.07, "{secant}");
    let linear = fitted(&s, TemperatureFit::Linear);
    let pchip = fitted(&s, TemperatureFit::Pchip);
    // Linear in ln p: dT/dh = ΔT/Δln p · d ln P/dh, which moves only with d ln P/dh (≈ 1/T_v,
    // and the pressure fit's cubic) inside the 13 m gap.
    let peak_linear = max_gradient(&linear, a.height_m, b.height_m);
    assert!(
        (peak_linear / secant - 1.0).abs() < 0.01,
        "{peak_linear} vs {secant}"
    );
    // PCHIP concentrates the warming: the 0.081 K/m, well over the secant.
    let peak_pchip = max_gradient(&pchip, a.height_m, b.height_m);
    assert!(peak_pchip > 1.3 * secant, "{peak_pchip} vs {secant}");
    assert!((peak_pchip - 0.081).abs() < 0.001, "{peak_pchip}");
    // Auto takes these significant levels for what they are.
    let auto = fitted(&s, TemperatureFit::Auto);
    assert_eq!(auto.fit_choice().used, TemperatureFit::Linear);
    assert!(auto.fit_choice().significant_levels);
}

#[test]
fn cherskiy_duct_is_an_artefact_of_pchip() {
    let path = sounding(CHERSKIY);
    let duct = |fit: &str| {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().to_str().unwrap();
        let r = ok(&[
            "profile",
            path.to_str().unwrap(),
            "--fit",
            fit,
            "--out",
            out,
            "-q",
        ]);
        (r.stdout, json_file(&dir.path().join("layers.json")))
    };
    let (text, pchip) = duct("pchip");
    let ducts = pchip["ducts"].as_array().unwrap();
    assert_eq!(ducts.len(), 1, "{text}");
    // Between the 1002 hPa level (119 m above the 32 m surface) and 1000 hPa (133 m).
    let (base, top) = (
        ducts[0]["base_agl_m"].as_f64().unwrap(),
        ducts[0]["top_agl_m"].as_f64().unwrap(),
    );
    assert!(
        base > 119.0 && top < 133.5 && top - base < 6.0,
        "{base}–{top}"
    );
    assert!(
        text.contains("Temperature fit: PCHIP (as requested"),
        "{text}"
    );
    let (text, linear) = duct("linear");
    assert_eq!(linear["ducts"].as_array().unwrap().len(), 0, "{text}");
    assert_eq!(linear["input"]["fit"]["used"], "linear");
    // The default is auto, and says why it chose linear.
    let (text, auto) = duct("auto");
    assert_eq!(auto["input"]["fit"]["requested"], "auto");
    assert_eq!(auto["ducts"].as_array().unwrap().len(), 0);
    assert!(
        text.contains("Temperature fit: linear in ln p (auto: median level spacing"),
        "{text}"
    );
    assert!(text.contains("significant levels"), "{text}");
    usage_error(&["profile", path.to_str().unwrap(), "--fit", "cubic"]);
}

#[test]
fn linear_fit_meets_every_level_and_is_linear_in_ln_p_between_them() {
    let s = read(CHERSKIY);
    let p = fitted(&s, TemperatureFit::Linear);
    for level in &s.levels {
        let air = p.air_at(level.height_m);
        assert!(
            (air.temperature_k - level.temperature_k).abs() < 1e-9,
            "{level:?}: {}",
            air.temperature_k
        );
        let measured = level.pressure_pa.unwrap();
        assert!((air.pressure_pa / measured - 1.0).abs() < 1e-9, "{level:?}");
    }
    // By hand from the file: 925 hPa −21.7 °C, 908 hPa −18.9 °C. Halfway in ln p, at
    // √(925·908) = 916.4641 hPa, linear in ln p gives −20.30 °C exactly.
    let p_mid_pa = (925.0f64 * 908.0).sqrt() * 100.0;
    let (lo, hi) = (at_hpa(&s, 925.0).height_m, at_hpa(&s, 908.0).height_m);
    let h_mid = bisect(|h| p.air_at(h).pressure_pa - p_mid_pa, lo, hi);
    let t_mid = p.air_at(h_mid).temperature_k;
    assert!((t_mid - (273.15 - 20.3)).abs() < 1e-6, "{t_mid}");
    // 835 hPa and 750 hPa are both −16.3 °C: isothermal between them, whatever the height.
    let iso = at_hpa(&s, 835.0).height_m + 100.0;
    assert!((p.air_at(iso).temperature_k - (273.15 - 16.3)).abs() < 1e-9);
    // dT/dh jumps at a level (C⁰): at 1000 hPa from ≈0.8 K/13.4 m below to 12 K/556 m above
    // (925 hPa, −21.7 °C, 721 m), and every level is a break the tracer stops on.
    let h = at_hpa(&s, 1000.0).height_m;
    let (below, above) = (p.air_at(h - 1e-6), p.air_at(h + 1e-6));
    assert!(
        (below.dtemperature_dh_k_per_m - 0.06).abs() < 0.002,
        "{below:?}"
    );
    // Linear in ln p, not in height: over those 556 m d ln P/dh ∝ 1/T_v falls by 5 % as the air
    // warms 12 K, so dT/dh starts a few per cent above the height secant.
    let above_secant = 12.0 / (721.0 - 165.0);
    let ratio = above.dtemperature_dh_k_per_m / above_secant;
    assert!(ratio > 1.0 && ratio < 1.05, "{above:?}");
    let breaks = p.breaks_m();
    for level in &s.levels[1..] {
        assert!(
            breaks.iter().any(|b| (b - level.height_m).abs() < 1e-3),
            "{} m is no break",
            level.height_m
        );
    }
}

fn bisect(f: impl Fn(f64) -> f64, mut lo: f64, mut hi: f64) -> f64 {
    let f_lo = f(lo);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if (f(mid) > 0.0) == (f_lo > 0.0) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[test]
fn auto_fits_dense_ascents_with_pchip_and_significant_levels_linearly() {
    // Ny-Ålesund 2024-02-26 (1-s ascent): levels a few metres apart.
    let dense = fitted(
        &read("NyAlesund-01004_2024022611.csv"),
        TemperatureFit::Auto,
    );
    let c = dense.fit_choice();
    assert_eq!(c.used, TemperatureFit::Pchip);
    assert!(c.median_spacing_m.unwrap() < 10.0, "{c:?}");
    // Utqiagvik 2026-02-06 TEMP, all levels: the closest of the shipped significant-level
    // soundings (many levels in its surface inversion), still above the 25 m threshold.
    let s = read("pressure_levels/Utqiagvik-70026_2026020600_all-levels.csv");
    let c = fitted(&s, TemperatureFit::Auto).fit_choice().clone();
    assert_eq!(c.used, TemperatureFit::Linear, "{c:?}");
    // The median spacing, recomputed here from the levels of the lowest 3 km.
    let first = s.levels[0].height_m;
    let inside: Vec<f64> = s
        .levels
        .iter()
        .map(|l| l.height_m)
        .filter(|&h| h <= first + 3000.0)
        .collect();
    let mut gaps: Vec<f64> = inside.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_by(f64::total_cmp);
    let n = gaps.len();
    let median = if n % 2 == 1 {
        gaps[n / 2]
    } else {
        0.5 * (gaps[n / 2 - 1] + gaps[n / 2])
    };
    assert!((c.median_spacing_m.unwrap() - median).abs() < 1e-9);
    assert!(median > 25.0 && median < 60.0, "{median}");
}

#[test]
fn scene_and_pipeline_files_take_fit() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("s.toml");
    let write_scene = |fit: &str| {
        std::fs::write(
            &scene,
            format!(
                "[camera]\nheight_m = 10.0\nhfov_deg = 1.0\nwidth = 4\nheight = 2\n\
                 [atmosphere]\nsounding = {:?}\nfit = {fit}\n",
                sounding(CHERSKIY)
            ),
        )
        .unwrap();
    };
    write_scene("\"pchip\"");
    let s = ghostship::scene::Scene::from_file(&scene).unwrap();
    let (_, options) = s.atmosphere.resolve().unwrap();
    assert_eq!(options.fit, TemperatureFit::Pchip);
    write_scene("\"cubic\"");
    let err = ghostship::scene::Scene::from_file(&scene).unwrap_err();
    let text = format!("{:#}", anyhow::Error::new(err));
    assert!(text.contains("cubic") && text.contains("linear"), "{text}");
    // Pipeline: fit in a [[profile]] job, fit and ensemble in a [[trace]] job.
    let pipeline = dir.path().join("p.toml");
    std::fs::write(
        &pipeline,
        format!(
            "[[profile]]\natmosphere = {path:?}\nfit = \"pchip\"\nname = \"prof\"\n\
             [[trace]]\natmosphere = {path:?}\nobserver_height_m = 10.0\n\
             elevation_deg = \"-0.2:0.3:0.01\"\ndistances_m = [20000.0]\nensemble = 3\n\
             fit = \"linear\"\nname = \"tr\"\n",
            path = sounding(CHERSKIY)
        ),
    )
    .unwrap();
    let out = dir.path().join("out");
    pipeline_ok(&pipeline, &out, &[]);
    let layers = json_file(&out.join("prof/layers.json"));
    assert_eq!(layers["input"]["fit"]["used"], "pchip");
    assert_eq!(layers["ducts"].as_array().unwrap().len(), 1);
    let trace = json_file(&out.join("tr/trace.json"));
    assert_eq!(trace["ensemble"]["members"], 3);
    assert_eq!(trace["ensemble"]["fit"]["used"], "linear");
}

// ---------------------------------------------------------------------------------------------
// The ensemble.

fn trace_args<'a>(atmosphere: &'a str, members: &'a str) -> Vec<&'a str> {
    vec![
        "trace",
        "-a",
        atmosphere,
        "--observer-height-m",
        "10",
        "--elevation-deg=-0.3:0.5:0.002",
        "--distance-m",
        "20000",
        "--target-height-m",
        "20",
        "--ensemble",
        members,
        "-q",
    ]
}

/// `ghostship trace … --ensemble N` with `threads` rayon threads: stdout.
fn trace_with_threads(atmosphere: &str, members: &str, threads: &str) -> String {
    let out = ghostship()
        .args(trace_args(atmosphere, members))
        .env("RAYON_NUM_THREADS", threads)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn width(range: &serde_json::Value) -> f64 {
    range[1].as_f64().unwrap() - range[0].as_f64().unwrap()
}

#[test]
fn cherskiy_ensemble_reports_the_spread_and_is_byte_identical_across_threads() {
    let path = sounding(CHERSKIY);
    let path = path.to_str().unwrap();
    let one = trace_with_threads(path, "12", "1");
    let three = trace_with_threads(path, "12", "3");
    assert_eq!(one, three, "the ensemble depends on the thread count");
    assert_eq!(one, trace_with_threads(path, "12", "3"), "runs differ");
    let v: serde_json::Value = serde_json::from_str(&one).unwrap();
    let e = &v["ensemble"];
    assert_eq!(e["members"], 12);
    // Significant levels: every one of the 27 gaps between the 28 levels is perturbed.
    assert_eq!(e["gaps"], 27);
    assert_eq!(e["perturbed_gaps"], 27);
    assert_eq!(e["member_outcomes"].as_array().unwrap().len(), 12);
    // The linear fit has no duct; a departure of more than ≈0.07 K in the 13 m gap between
    // 1002 and 1000 hPa (half a sine of amplitude a adds πa/13.4 m to its 0.06 K/m) makes one,
    // so most members do: whether a duct is there is not decided by the levels.
    assert_eq!(e["ducts"]["fit_ducts"], 0);
    let with_duct = e["ducts"]["members_with_duct"].as_u64().unwrap();
    assert!((6..=12).contains(&with_duct), "{with_duct}");
    let counted = e["member_outcomes"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|m| !m["ducts"].as_array().unwrap().is_empty())
        .count();
    assert_eq!(counted as u64, with_duct);
    // The sea horizon moves by hundredths of a degree, around the fit's.
    let horizon = &e["sea_horizon"];
    let (lo, hi) = (
        horizon["range_deg"][0].as_f64().unwrap(),
        horizon["range_deg"][1].as_f64().unwrap(),
    );
    assert!(width(&horizon["range_deg"]) > 0.005, "{horizon}");
    let fit = horizon["fit_deg"].as_f64().unwrap();
    assert!(lo < fit && fit < hi && lo > -0.2 && hi < 0.0, "{horizon}");
    // The fit's own outcome is the main report's.
    let main_horizon = v["horizons"].as_array().unwrap().last().unwrap()["elevation_deg"].clone();
    assert_eq!(horizon["fit_deg"], main_horizon);
    // Every member is counted once per target.
    let shares: u64 = e["targets"][0]["image_counts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["members"].as_u64().unwrap())
        .sum();
    assert_eq!(shares, 12);
    let summary: Vec<&str> = e["summary"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_str().unwrap())
        .collect();
    assert!(summary[0].contains("±1 K of the linear-in-ln-p fit in 27 of 27 gaps"));
    assert!(
        summary
            .iter()
            .any(|l| l.contains("images of the 20 m target at 20 km"))
    );
    assert!(
        summary
            .iter()
            .any(|l| l.contains(&format!("duct present in {with_duct}/12 members")))
    );
}

/// A sounding CSV sampled from `atm` every `step_m` from its surface to 12 km (height, T, P).
fn sampled_csv(dir: &Path, atm: &dyn AirColumn, step_m: f64) -> PathBuf {
    let mut text = String::from("height_m,temperature_c,pressure_hpa\n");
    let surface = atm.surface_height_m();
    let mut h = surface;
    while h <= surface + 12_000.0 {
        let air = atm.air_at(h);
        text.push_str(&format!(
            "{h},{:.4},{:.4}\n",
            air.temperature_k - 273.15,
            air.pressure_pa / 100.0
        ));
        h += step_m;
    }
    let path = dir.join(format!("sampled_{step_m}.csv"));
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_densely_sampled_sounding_has_no_spread_a_sparsely_sampled_one_has() {
    // The paper's superior mirage (a warm layer aloft), written out as a sounding.
    let synthetic =
        ghostship::profile::SyntheticAtmosphere::from_file(&data_file("superior_mirage.toml"))
            .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let ensemble = |step_m: f64| {
        let path = sampled_csv(dir.path(), &synthetic, step_m);
        let out = trace_with_threads(path.to_str().unwrap(), "6", "2");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        v["ensemble"].clone()
    };
    // Every 5 m: a dense ascent; its levels are the curve, nothing between them to perturb.
    let dense = ensemble(5.0);
    assert_eq!(dense["fit"]["used"], "pchip");
    assert_eq!(dense["perturbed_gaps"], 0);
    assert_eq!(width(&dense["sea_horizon"]["range_deg"]), 0.0);
    for member in dense["member_outcomes"].as_array().unwrap() {
        assert_eq!(member, &dense["fit_outcome"]);
    }
    // Every 100 m: significant-level spacing; ±1 K between levels moves what is seen.
    let sparse = ensemble(100.0);
    assert_eq!(sparse["fit"]["used"], "linear");
    assert_eq!(sparse["perturbed_gaps"], sparse["gaps"]);
    assert!(
        width(&sparse["sea_horizon"]["range_deg"]) > 1e-3,
        "{sparse}"
    );
}

#[test]
fn model_atmospheres_and_straight_rays_refuse_an_ensemble() {
    let toml = data_file("superior_mirage.toml");
    let r = fails(&trace_args(toml.to_str().unwrap(), "4"));
    assert!(
        r.stderr.contains("ensemble needs a measured sounding"),
        "{}",
        r.stderr
    );
    assert!(
        r.stderr
            .contains("superior_mirage.toml is a synthetic atmosphere")
    );
    let r = fails(&trace_args("us1976", "4"));
    assert!(r.stderr.contains("us1976"), "{}", r.stderr);
    let path = sounding(CHERSKIY);
    let mut args = trace_args(path.to_str().unwrap(), "4");
    args.push("--straight");
    let r = fails(&args);
    assert!(r.stderr.contains("straight"), "{}", r.stderr);
    let r = fails(&trace_args(path.to_str().unwrap(), "501"));
    assert!(r.stderr.contains("at most 500"), "{}", r.stderr);
    // Without --ensemble the report has no ensemble section.
    let mut args = trace_args(path.to_str().unwrap(), "0");
    args.retain(|a| *a != "--ensemble" && *a != "0");
    let v: serde_json::Value = serde_json::from_str(&ok(&args).stdout).unwrap();
    assert!(v.get("ensemble").is_none());
    // The library refuses too, when asked directly, and has no profile to perturb.
    let request = |source: AtmosphereSource| {
        TraceJobRequest::new(
            AtmosphereRequest {
                source,
                options: AtmosphereOptions::default(),
            },
            10.0,
            &ElevationSpec::List(vec![0.0]),
            vec![1000.0],
            vec![20.0],
            TracerConfig::default(),
            false,
        )
        .unwrap()
    };
    assert!(request(AtmosphereSource::Us1976).with_ensemble(4).is_err());
    assert!(request(AtmosphereSource::Us1976).with_ensemble(0).is_ok());
    let atm = load_atmosphere(&AtmosphereSource::Us1976, &AtmosphereOptions::default()).unwrap();
    assert!(atm.profile.is_none());
}
