//! `ghostship compare` and the `[[compare]]` pipeline job: measured soundings against synthetic
//! layers through one scene.

use std::path::{Path, PathBuf};

use ghostship::profile::{AirColumn, SyntheticAtmosphere};

use crate::support::cli::{fails, json_file, ok, output_tree, pipeline_ok};
use crate::support::data::{data_file, sounding};

/// A piecewise-linear truth: a superior-mirage layer (+10 K over 20 m at 90 m) on the standard
/// lapse rate, written in the same `[[layers]]` form the layer fit writes.
const TRUTH: &str = "description = \"piecewise-linear ghost-ship layer\"\nsurface_temperature_c = 0.0\n\
surface_pressure_hpa = 1013.25\nbackground = -0.0065\n\n[[layers]]\nfrom_m = 90.0\nto_m = 110.0\n\
gradient_k_per_m = 0.5065\n";

/// The ghost-ship scene at a small size, as the tests render it.
fn small(extra: &[&'static str]) -> Vec<&'static str> {
    let mut args = vec!["--size", "160x80", "--spp", "1", "--rays", "401"];
    args.extend_from_slice(extra);
    args
}

fn scene() -> PathBuf {
    data_file("scenes/fig04_superior_mirage.toml")
}

/// `TRUTH` sampled as a dry normalised CSV: every 1 m to 400 m, every 25 m to 12 km.
fn write_truth(dir: &Path) -> (PathBuf, PathBuf) {
    let toml = dir.join("truth.toml");
    std::fs::write(&toml, TRUTH).unwrap();
    let truth = SyntheticAtmosphere::from_file(&toml).unwrap();
    let mut csv = String::from("pressure_hpa,height_m,temperature_c,dewpoint_c\n");
    let heights = (0..400)
        .map(f64::from)
        .chain((16..=480).map(|i| 25.0 * i as f64));
    for h in heights {
        let air = truth.air_at(h);
        csv += &format!(
            "{:.4},{h},{:.5},\n",
            air.pressure_pa / 100.0,
            air.temperature_k - 273.15
        );
    }
    let path = dir.join("truth_sampled.csv");
    std::fs::write(&path, csv).unwrap();
    (path, toml)
}

fn compare(measured: &Path, synthetic: Option<&Path>, out: &Path, extra: &[&'static str]) {
    let mut args = vec!["compare".to_string(), measured.display().to_string()];
    args.extend(synthetic.map(|p| p.display().to_string()));
    args.extend(["--scene".into(), scene().display().to_string()]);
    args.extend(["--out".into(), out.display().to_string()]);
    args.extend(small(extra).iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    ok(&args);
}

#[test]
fn a_real_sounding_gives_every_product_and_images_that_trace_confirms() {
    let dir = tempfile::tempdir().unwrap();
    let measured = sounding("TroisRivieres-UQAM_2022022222.csv");
    compare(&measured, None, dir.path(), &[]);
    for name in [
        "compare.json",
        "measured.png",
        "synthetic.png",
        "side_by_side.png",
        "profiles.png",
        "transfer.png",
        "fitted_layers.toml",
    ] {
        assert!(dir.path().join(name).is_file(), "{name}");
    }
    let side = image::open(dir.path().join("side_by_side.png")).unwrap();
    assert_eq!(side.width(), 3 * 160 + 2 * 6);
    let c = json_file(&dir.path().join("compare.json"));
    // The fitted TOML is an atmosphere `profile` accepts.
    ok(&[
        "profile",
        dir.path().join("fitted_layers.toml").to_str().unwrap(),
        "--out",
        dir.path().join("p").to_str().unwrap(),
    ]);
    // The measured side's images are what `trace` finds with the same fan.
    let fan = &c["fan"];
    let (lo, hi) = (
        fan["elevation_min_deg"].as_f64().unwrap(),
        fan["elevation_max_deg"].as_f64().unwrap(),
    );
    let rays = fan["rays"].as_u64().unwrap() as f64;
    let spec = format!("{lo}:{hi}:{}", (hi - lo) / (rays - 1.0));
    let t = ok(&[
        "trace",
        "-a",
        measured.to_str().unwrap(),
        "--observer-height-m",
        "50",
        "--elevation-deg",
        &spec,
        "--distance-m",
        "26000,60000",
        "--target-height-m",
        "25,40",
        "--tolerance-m",
        &fan["tolerance_m"].as_f64().unwrap().to_string(),
    ]);
    let report: serde_json::Value = serde_json::from_str(&t.stdout).unwrap();
    assert_eq!(report["rays"].as_array().unwrap().len() as f64, rays);
    for target in c["measured"]["targets"].as_array().unwrap() {
        let (d, h) = (target["distance_m"].as_f64(), target["height_m"].as_f64());
        let images: Vec<_> = report["images"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|i| i["distance_m"].as_f64() == d && i["height_m"].as_f64() == h)
            .collect();
        assert_eq!(
            target["count"].as_u64(),
            Some(images.len() as u64),
            "{target}"
        );
        let erect = images
            .iter()
            .filter(|i| i["erect"].as_bool() == Some(true))
            .count();
        assert_eq!(target["erect"].as_u64(), Some(erect as u64), "{target}");
        let lowest = images
            .iter()
            .map(|i| i["elevation_min_deg"].as_f64().unwrap())
            .reduce(f64::min);
        let highest = images
            .iter()
            .map(|i| i["elevation_max_deg"].as_f64().unwrap())
            .reduce(f64::max);
        for (key, edge) in [
            ("elevation_min_deg", lowest),
            ("elevation_max_deg", highest),
        ] {
            match (target[key].as_f64(), edge) {
                (Some(a), Some(b)) => assert!((a - b).abs() < 1e-9, "{key}: {a} {b}"),
                (None, None) => {}
                other => panic!("{key}: {other:?}"),
            }
        }
    }
    // The near ship is seen (so the checks above are not vacuous).
    assert!(
        c["measured"]["targets"][0]["count"].as_u64().unwrap() >= 1,
        "{c}"
    );
    // Trois-Rivières' thin measured ducts (dN/dh spikes at 370–480 m) are smoothed away by the
    // paper-style smooth layers: the comparison says so.
    // The default fit is the paper's form; its strongest layer is the warm nose (−11.6 °C at
    // 416 m to +3.4 °C at 722 m above sea level, README of the test data).
    assert_eq!(c["fit"]["shape"], "smooth");
    let nose = c["fit"]["layers"]
        .as_array()
        .unwrap()
        .iter()
        .max_by(|a, b| {
            let dt = |l: &serde_json::Value| l["delta_t_k"].as_f64().unwrap();
            dt(a).total_cmp(&dt(b))
        })
        .unwrap();
    let (base, top) = (
        nose["base_m"].as_f64().unwrap(),
        nose["top_m"].as_f64().unwrap(),
    );
    assert!(
        base > 300.0 && base < 450.0 && top > 650.0 && top < 800.0,
        "{nose}"
    );
    assert!(nose["delta_t_k"].as_f64().unwrap() > 12.0, "{nose}");
    let measured_ducts = c["measured"]["ducts"].as_array().unwrap().len();
    let synthetic_ducts = c["synthetic"]["ducts"].as_array().unwrap().len();
    assert!(measured_ducts > synthetic_ducts, "{c}");
    let differences = c["differences"].as_array().unwrap();
    assert!(
        differences
            .iter()
            .any(|d| d.as_str().unwrap().starts_with("ducts:")),
        "{differences:?}"
    );
}

#[test]
fn a_sampled_synthetic_atmosphere_round_trips_through_the_fit_and_matches_itself() {
    let dir = tempfile::tempdir().unwrap();
    let (csv, toml) = write_truth(dir.path());
    // Against the truth itself: the sounding sampled every metre shows what the truth shows.
    let own = dir.path().join("own");
    compare(&csv, Some(&toml), &own, &["--smooth-m", "0"]);
    let c = json_file(&own.join("compare.json"));
    assert!(c["fit"].is_null());
    assert!(
        c["image"]["ssim"].as_f64().unwrap() > 0.98,
        "{}",
        c["image"]
    );
    let (m, s) = (&c["measured"]["targets"], &c["synthetic"]["targets"]);
    // The near ship: one erect image through both.
    assert_eq!(m[0]["count"].as_u64(), Some(1), "{m}");
    assert_eq!(s[0]["count"].as_u64(), Some(1), "{s}");
    // The far ship is a ghost ship through both: one inverted image, the same band to 0.001°
    // (the 1 m samples round the layer's corners, which may add a sliver of an erect image a
    // fraction of an arcsecond tall over it, so the erect count is not compared).
    assert_eq!(m[1]["inverted"].as_u64(), Some(1), "{m}");
    assert_eq!(s[1]["inverted"].as_u64(), Some(1), "{s}");
    for key in ["elevation_min_deg", "elevation_max_deg"] {
        let (a, b) = (m[1][key].as_f64().unwrap(), s[1][key].as_f64().unwrap());
        assert!((a - b).abs() < 1e-3, "{key}: {a} {b}");
    }
    // Fitted: the layer comes back (its base and top within 1 m, its ΔT within 0.2 K).
    let fitted = dir.path().join("fitted");
    compare(
        &csv,
        None,
        &fitted,
        &["--smooth-m", "0", "--layers", "linear"],
    );
    let c = json_file(&fitted.join("compare.json"));
    let layers = c["fit"]["layers"].as_array().unwrap();
    let layer = layers
        .iter()
        .max_by(|a, b| {
            let g = |l: &serde_json::Value| l["gradient_k_per_m"].as_f64().unwrap();
            g(a).total_cmp(&g(b))
        })
        .unwrap();
    let base = layer["base_m"].as_f64().unwrap();
    let top = layer["top_m"].as_f64().unwrap();
    assert!(
        (base - 90.0).abs() < 1.0 && (top - 110.0).abs() < 1.0,
        "{layer}"
    );
    let delta = layer["delta_t_k"].as_f64().unwrap();
    assert!((delta - 0.5 * 20.0).abs() < 0.2, "{layer}");
    assert!(c["fit"]["rms_k"].as_f64().unwrap() < 0.05, "{}", c["fit"]);
    let (m, s) = (&c["measured"]["targets"], &c["synthetic"]["targets"]);
    assert_eq!(m[1]["inverted"], s[1]["inverted"], "{m} {s}");
}

#[test]
fn the_fan_spans_the_rendered_field_at_another_aspect_ratio() {
    // fig04: hfov 0.9°, pitch −0.06°, 400×200. Rendered square, the vertical field is 0.9° too.
    let dir = tempfile::tempdir().unwrap();
    let measured = sounding("Bjornoya-01028_2024022611.csv");
    let out = dir.path().to_str().unwrap();
    ok(&[
        "compare",
        measured.to_str().unwrap(),
        "--scene",
        scene().to_str().unwrap(),
        "--out",
        out,
        "--size",
        "60x60",
        "--spp",
        "1",
        "--rays",
        "101",
    ]);
    let c = json_file(&dir.path().join("compare.json"));
    let (lo, hi) = (
        c["fan"]["elevation_min_deg"].as_f64().unwrap(),
        c["fan"]["elevation_max_deg"].as_f64().unwrap(),
    );
    assert!(hi - lo >= 0.9 - 1e-6, "{lo}…{hi}");
    assert!((0.5 * (lo + hi) + 0.06).abs() < 0.01, "{lo}…{hi}");
    let img = image::open(dir.path().join("measured.png")).unwrap();
    assert_eq!((img.width(), img.height()), (60, 60));
}

#[test]
fn compare_output_does_not_depend_on_the_thread_count() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let measured = sounding("pressure_levels/Tiksi-21824_2026020600_all-levels.csv");
    for (dir, threads) in [(&a, "1"), (&b, "2")] {
        let out = dir.path().to_str().unwrap();
        let mut cmd = crate::support::cli::ghostship();
        cmd.env("RAYON_NUM_THREADS", threads)
            .args(["compare", measured.to_str().unwrap(), "--scene"])
            .arg(scene())
            .args(["--out", out])
            .args(small(&[]))
            .assert()
            .success();
    }
    assert_eq!(output_tree(a.path()), output_tree(b.path()));
}

#[test]
fn bad_inputs_are_refused_clearly() {
    let scene = scene();
    let scene = scene.to_str().unwrap();
    let toml = data_file("superior_mirage.toml");
    let csv = sounding("Bjornoya-01028_2024022611.csv");
    let r = fails(&["compare", toml.to_str().unwrap(), "--scene", scene]);
    assert!(r.stderr.contains("must be a sounding file"), "{}", r.stderr);
    let r = fails(&[
        "compare",
        csv.to_str().unwrap(),
        csv.to_str().unwrap(),
        "--scene",
        scene,
    ]);
    assert!(r.stderr.contains(".toml file or us1976"), "{}", r.stderr);
    let r = fails(&["compare", "no/such.csv", "--scene", scene]);
    assert!(r.stderr.contains("no/such.csv"), "{}", r.stderr);
    let r = fails(&["compare", csv.to_str().unwrap(), "--scene", "no/scene.toml"]);
    assert!(r.stderr.contains("no/scene.toml"), "{}", r.stderr);
    let r = fails(&[
        "compare",
        csv.to_str().unwrap(),
        "--scene",
        scene,
        "--rays",
        "2",
    ]);
    assert!(r.stderr.contains("rays must be 3"), "{}", r.stderr);
}

#[test]
fn a_compare_pipeline_job_writes_what_the_command_writes() {
    let dir = tempfile::tempdir().unwrap();
    let measured = sounding("Utqiagvik-70026_2014091012.csv");
    let pipeline = dir.path().join("c.toml");
    std::fs::write(
        &pipeline,
        format!(
            "[[compare]]\natmosphere = {:?}\nscene = {:?}\nsize = \"160x80\"\nspp = 1\nrays = 401\n",
            measured.display().to_string(),
            scene().display().to_string()
        ),
    )
    .unwrap();
    let out = dir.path().join("out");
    pipeline_ok(&pipeline, &out, &["-q"]);
    // Unchanged, it is skipped; another layer form is another job.
    let again = pipeline_ok(&pipeline, &out, &[]);
    assert!(
        again.stdout.contains("0 ran, 1 unchanged"),
        "{}",
        again.stdout
    );
    let text = std::fs::read_to_string(&pipeline).unwrap();
    std::fs::write(&pipeline, format!("{text}layers = \"linear\"\n")).unwrap();
    let linear = pipeline_ok(&pipeline, &out, &["--dry-run"]);
    assert!(linear.stdout.contains("1 would run"), "{}", linear.stdout);
    std::fs::write(&pipeline, text).unwrap();
    let job = out.join("compare_Utqiagvik-70026_2014091012");
    let single = dir.path().join("single");
    compare(&measured, None, &single, &[]);
    for name in [
        "compare.json",
        "side_by_side.png",
        "profiles.png",
        "fitted_layers.toml",
    ] {
        assert_eq!(
            std::fs::read(job.join(name)).unwrap(),
            std::fs::read(single.join(name)).unwrap(),
            "{name}"
        );
    }
    // A synthetic that is a sounding is refused at the key, before any work.
    std::fs::write(
        &pipeline,
        format!(
            "[[compare]]\natmosphere = {:?}\nsynthetic = {:?}\nscene = {:?}\n",
            measured.display().to_string(),
            measured.display().to_string(),
            scene().display().to_string()
        ),
    )
    .unwrap();
    let r = crate::support::cli::pipeline_run(&pipeline, &out, &[]);
    assert_ne!(r.code, Some(0));
    // Reported at the `synthetic` key (line 3), naming the file.
    assert!(r.stderr.contains("c.toml:3:"), "{}", r.stderr);
    assert!(r.stderr.contains("is a sounding"), "{}", r.stderr);
    assert!(
        r.stderr.contains("Utqiagvik-70026_2014091012.csv"),
        "{}",
        r.stderr
    );
}
