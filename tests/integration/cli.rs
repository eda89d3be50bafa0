//! The `ghostship` binary end to end: `profile`, `trace` and `pipeline run` on shipped data, in
//! temporary folders. Expected values come from the input files themselves (surface temperature,
//! layer placement), from straight-line geometry over a sphere, or from properties.

use std::path::Path;

use crate::support::cli::{fails, ghostship, json_file, ok, pipeline_ok, usage_error};
use crate::support::data::{data_file, repo_file, sounding};

fn png_size(path: &Path) -> (u32, u32) {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (img.width(), img.height())
}

/// Rows of profile.csv as (header, rows of numbers).
fn read_profile_csv(path: &Path) -> (String, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().to_string();
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse::<f64>().unwrap()).collect())
        .collect();
    (header, rows)
}

#[test]
fn profile_of_a_sounding_writes_three_files() {
    let dir = tempfile::tempdir().unwrap();
    let input = data_file("Utqiagvik-70026_2026020600_all-levels.csv");
    let out = dir.path().join("utq");
    let r = ok(&[
        "profile",
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(r.stdout.contains("Surface"), "{}", r.stdout);
    assert!(r.stdout.contains("Inversions"), "{}", r.stdout);
    assert!(r.stderr.contains("profile.csv"), "{}", r.stderr);

    let (header, rows) = read_profile_csv(&out.join("profile.csv"));
    assert_eq!(header, ghostship::report::CSV_HEADER);
    let columns = header.split(',').count();
    assert!(rows.iter().all(|r| r.len() == columns));
    // data/README.md: −23.7 °C at the 12 m surface, warming to −14.1 °C by ≈1.1 km.
    let t = header
        .split(',')
        .position(|c| c == "temperature_k")
        .unwrap();
    assert!(
        (rows[0][t] - (273.15 - 23.7)).abs() < 1.0,
        "surface {} K",
        rows[0][t]
    );
    let layers = json_file(&out.join("layers.json"));
    for key in ["surface", "inversions", "ducts", "regimes", "wavelength_nm"] {
        assert!(layers.get(key).is_some(), "layers.json lacks {key}");
    }
    // The README's surface inversion: some inversion starts at the ground.
    let inversions = layers["inversions"].as_array().unwrap();
    assert!(
        inversions.iter().any(|i| i["kind"] == "surface"),
        "{inversions:?}"
    );
    assert_eq!(png_size(&out.join("profile.png")), (1400, 900));
}

#[test]
fn profile_of_a_synthetic_atmosphere_finds_its_layer() {
    let dir = tempfile::tempdir().unwrap();
    let input = data_file("superior_mirage.toml");
    let r = ok(&[
        "profile",
        input.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
        "--format",
        "json",
        "--quiet",
    ]);
    assert!(r.stderr.is_empty(), "--quiet: {}", r.stderr);
    let printed: serde_json::Value = serde_json::from_str(&r.stdout).unwrap();
    let written = json_file(&dir.path().join("layers.json"));
    assert_eq!(printed, written);
    // The TOML: surface 0 °C, 1013.25 hPa; +10 K over 15 m centred at 100 m (96 % of it
    // between 92.5 and 107.5 m).
    let surface = &written["surface"];
    assert!((surface["temperature_k"].as_f64().unwrap() - 273.15).abs() < 1e-6);
    assert!((surface["pressure_hpa"].as_f64().unwrap() - 1013.25).abs() < 1e-6);
    let inv = written["inversions"].as_array().unwrap();
    assert_eq!(inv.len(), 1, "{inv:?}");
    let base = inv[0]["base_agl_m"].as_f64().unwrap();
    let top = inv[0]["top_agl_m"].as_f64().unwrap();
    let delta = inv[0]["delta_t_k"].as_f64().unwrap();
    assert!(
        base > 80.0 && base < 95.0 && top > 105.0 && top < 120.0,
        "{base}–{top}"
    );
    assert!(delta > 9.0 && delta < 10.5, "ΔT {delta}");
    // 0.67 K/m is six times the critical gradient: a duct.
    assert!(!written["ducts"].as_array().unwrap().is_empty());
    let (header, rows) = read_profile_csv(&dir.path().join("profile.csv"));
    assert_eq!(header, ghostship::report::CSV_HEADER);
    assert!((rows[0][1] - 273.15).abs() < 1e-6, "{:?}", rows[0]);
    assert_eq!(png_size(&dir.path().join("profile.png")), (1400, 900));
}

#[test]
fn profile_errors_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    // Garbage.
    let garbage = dir.path().join("garbage.csv");
    std::fs::write(&garbage, b"\x00\x01 this is not a sounding \xff\n").unwrap();
    let r = fails(&[
        "profile",
        garbage.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("garbage.csv"), "{}", r.stderr);
    // A bad number on line 3.
    let bad = dir.path().join("bad.csv");
    std::fs::write(
        &bad,
        "pressure_hpa,height_m,temperature_c,dewpoint_c\n1000,10,-5,-6\n990,100,abc,-7\n980,200,-6,-8\n",
    )
    .unwrap();
    let r = fails(&[
        "profile",
        bad.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("bad.csv"), "{}", r.stderr);
    assert!(r.stderr.contains("line 3"), "{}", r.stderr);
    assert!(r.stderr.contains("temperature_c"), "{}", r.stderr);
    // Missing.
    let missing = dir.path().join("nowhere.csv");
    let r = fails(&["profile", missing.to_str().unwrap()]);
    assert!(r.stderr.contains("nowhere.csv"), "{}", r.stderr);
    // The operating system's reason is given once, not repeated by every layer of the chain.
    assert_eq!(r.stderr.matches("(os error").count(), 1, "{}", r.stderr);
    // A TOML with an unknown field on line 2.
    let toml = dir.path().join("odd.toml");
    std::fs::write(
        &toml,
        "surface_temperature_c = 0.0\nsurface_temprature_k = 3\n",
    )
    .unwrap();
    let r = fails(&[
        "profile",
        toml.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("odd.toml"), "{}", r.stderr);
    assert!(r.stderr.contains("surface_temprature_k"), "{}", r.stderr);
    // Nothing was written for any of them.
    assert!(!dir.path().join("profile.csv").exists());
}

fn trace_json(args: &[&str]) -> serde_json::Value {
    let r = ok(args);
    serde_json::from_str(&r.stdout).unwrap_or_else(|e| panic!("{e}: {}", r.stdout))
}

#[test]
fn trace_reports_json_with_the_expected_keys() {
    let v = trace_json(&[
        "trace",
        "--atmosphere",
        "us1976",
        "--observer-height-m",
        "10",
        "--elevation-deg",
        "-0.2:0.2:0.01",
        "--distance-m",
        "5000,20000",
        "--target-height-m",
        "30",
    ]);
    for key in [
        "observer_height_m",
        "tolerance_m",
        "wavelength_nm",
        "distances_m",
        "target_heights_m",
        "rays",
        "images",
        "horizons",
        "trapped_elevations_deg",
        "notes",
    ] {
        assert!(v.get(key).is_some(), "trace JSON lacks {key}");
    }
    let rays = v["rays"].as_array().unwrap();
    assert_eq!(rays.len(), 41);
    assert_eq!(v["distances_m"], serde_json::json!([5000.0, 20000.0]));
    assert_eq!(rays[0]["heights_m"].as_array().unwrap().len(), 2);
    // Horizons: one per distance, then the sea horizon.
    assert_eq!(v["horizons"].as_array().unwrap().len(), 3);
    // A 30 m target at 5 km is seen (at least one image) in the standard atmosphere.
    assert!(!v["images"].as_array().unwrap().is_empty());
}

#[test]
fn straight_rays_follow_line_sphere_geometry() {
    let h0 = 10.0;
    let distances = [5_000.0, 20_000.0];
    let args = |straight: bool| {
        let mut a = vec![
            "trace",
            "--atmosphere",
            "us1976",
            "--observer-height-m",
            "10",
            "--elevation-deg",
            "-0.1:0.1:0.05",
            "--distance-m",
            "5000,20000",
        ];
        if straight {
            a.push("--straight");
        }
        a.iter().map(|s| s.to_string()).collect::<Vec<_>>()
    };
    let run_json = |straight: bool| {
        let a = args(straight);
        trace_json(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let straight = run_json(true);
    let refracted = run_json(false);
    let r_earth = straight["earth_radius_m"].as_f64().unwrap();
    for (s, c) in straight["rays"]
        .as_array()
        .unwrap()
        .iter()
        .zip(refracted["rays"].as_array().unwrap())
    {
        let a = s["elevation_deg"].as_f64().unwrap().to_radians();
        // Straight line in polar form about Earth's centre: r(θ) = (R + h0)·cos α / cos(α + θ).
        for (j, d) in distances.iter().enumerate() {
            let theta = d / r_earth;
            let exact = (r_earth + h0) * a.cos() / (a + theta).cos() - r_earth;
            match s["heights_m"][j].as_f64() {
                Some(h) => assert!((h - exact).abs() < 0.05, "α {a}: {h} vs {exact}"),
                None => assert!(exact < 0.0, "α {a}, D {d}: ray ended but exact {exact}"),
            }
            // Standard air bends rays towards the ground: lower than straight.
            if let (Some(hs), Some(hc)) = (s["heights_m"][j].as_f64(), c["heights_m"][j].as_f64()) {
                assert!(hc < hs, "α {a}, D {d}: refracted {hc} ≥ straight {hs}");
            }
        }
        if let Some(refr) = s["refraction_deg"].as_f64() {
            assert!(refr.abs() < 1e-9, "straight ray refracted by {refr}°");
        }
    }
}

#[test]
fn trace_csv_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    let plot = dir.path().join("fan.png");
    let input = data_file("superior_mirage.toml");
    let r = ok(&[
        "trace",
        "--atmosphere",
        input.to_str().unwrap(),
        "--observer-height-m",
        "10",
        "--elevation-deg",
        "-0.2:0.3:0.01",
        "--distance-m",
        "10000",
        "--format",
        "csv",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    let mut lines = r.stdout.lines();
    let header = lines.next().unwrap();
    assert!(header.starts_with("elevation_deg,"), "{header}");
    assert!(header.ends_with("height_m_at_10000"), "{header}");
    assert_eq!(lines.count(), 51);
    let (w, h) = png_size(&plot);
    assert!(w > 100 && h > 100);
}

#[test]
fn one_ray_and_short_lists_report_their_rays_and_say_why_there_are_no_images() {
    let base = [
        "trace",
        "--atmosphere",
        "us1976",
        "--observer-height-m",
        "10",
        "--distance-m",
        "5000,20000",
        "--target-height-m",
        "30",
        "--elevation-deg",
    ];
    for (spec, elevations) in [
        ("0.5", vec![0.5]),
        ("-0.1,0.25", vec![-0.1, 0.25]),
        ("0.2:0.2:0.1", vec![0.2]),
    ] {
        let mut args = base.to_vec();
        args.push(spec);
        let v = trace_json(&args);
        let rays = v["rays"].as_array().unwrap();
        let got: Vec<f64> = rays
            .iter()
            .map(|r| r["elevation_deg"].as_f64().unwrap())
            .collect();
        assert_eq!(got, elevations, "{spec}");
        assert_eq!(rays[0]["heights_m"].as_array().unwrap().len(), 2, "{spec}");
        assert!(v["images"].as_array().unwrap().is_empty(), "{spec}");
        assert!(v["horizons"].as_array().unwrap().is_empty(), "{spec}");
        let notes = v["notes"].as_array().unwrap();
        assert_eq!(notes.len(), 1, "{spec}: {notes:?}");
        let note = notes[0].as_str().unwrap();
        assert!(note.contains("at least 3 rays"), "{spec}: {note}");
        // The CSV form and the plot work for one ray too.
        args.extend(["--format", "csv"]);
        let r = ok(&args);
        assert_eq!(r.stdout.lines().count(), 1 + elevations.len(), "{spec}");
    }
    let dir = tempfile::tempdir().unwrap();
    let plot = dir.path().join("one.png");
    let mut args = base.to_vec();
    args.extend(["0.5", "--plot", plot.to_str().unwrap()]);
    ok(&args);
    assert!(png_size(&plot).0 > 100);
    // A listed fan of 3 or more rays is analysed like a range: images and horizons.
    let mut args = base.to_vec();
    args.push("-0.2,-0.1,0,0.05,0.1,0.2");
    let v = trace_json(&args);
    assert_eq!(v["rays"].as_array().unwrap().len(), 6);
    assert_eq!(v["horizons"].as_array().unwrap().len(), 3);
    assert!(!v["images"].as_array().unwrap().is_empty());
    assert!(v["notes"].as_array().unwrap().is_empty());
}

#[test]
fn bad_elevation_specs_are_explained() {
    for (spec, needle) in [
        ("0.5:-0.5:0.01", "TO must not be below FROM"),
        ("0.2,0.1", "strictly ascending order"),
        ("0.1,0.1", "strictly ascending order"),
        ("0.1,x", "not a number of degrees"),
        ("95", "between -90° and 90°"),
        ("-0.5:0.5:0", "STEP must be > 0"),
        ("-0.5:0.5", "FROM:TO:STEP"),
        ("-1:1:0.00001", "at most 100000"),
        ("x:1:0.1", "not a number"),
    ] {
        // A usage error (clap's value parser): status 2, nothing traced.
        let r = usage_error(&[
            "trace",
            "--atmosphere",
            "us1976",
            "--observer-height-m",
            "10",
            "--elevation-deg",
            spec,
        ]);
        assert!(r.stderr.contains(needle), "{spec}: {}", r.stderr);
    }
    let r = fails(&[
        "trace",
        "--atmosphere",
        "us1976",
        "--observer-height-m",
        "50000",
        "--elevation-deg",
        "0:1:0.1",
    ]);
    assert!(r.stderr.contains("observer height"), "{}", r.stderr);
}

#[test]
fn pipeline_run_writes_every_job() {
    let dir = tempfile::tempdir().unwrap();
    let synthetic = data_file("inferior_mirage.toml");
    let sounding = data_file("Danmarkshavn-04320_2026020523_all-levels.csv");
    let pipeline = dir.path().join("small.toml");
    std::fs::write(
        &pipeline,
        format!(
            r#"
[[profile]]
atmosphere = {synthetic:?}
[[profile]]
atmosphere = {sounding:?}
name = "dmh"
[[trace]]
atmosphere = "us1976"
observer_height_m = 5.0
elevation_deg = "-0.1:0.1:0.02"
distances_m = [3000.0]
"#
        ),
    )
    .unwrap();
    let out = dir.path().join("results");
    let r = pipeline_ok(&pipeline, &out, &[]);
    for f in ["profile.csv", "layers.json", "profile.png"] {
        assert!(out.join("inferior_mirage").join(f).is_file(), "{f}");
        assert!(out.join("dmh").join(f).is_file(), "{f}");
    }
    let trace = json_file(&out.join("us1976_transfer/trace.json"));
    assert_eq!(trace["rays"].as_array().unwrap().len(), 11);
    assert!(out.join("us1976_transfer/trace.png").is_file());
    // Quiet by default: a summary row per job, no list of paths (the manifest has them).
    assert!(r.stdout.contains("us1976_transfer"), "{}", r.stdout);
    assert!(!r.stdout.contains("trace.json"), "{}", r.stdout);
    let manifest = json_file(&out.join("manifest.json"));
    assert!(
        manifest["jobs"]["us1976_transfer"]["outputs"]["us1976_transfer/trace.json"]["sha256"]
            .is_string(),
        "{manifest}"
    );
    let r = pipeline_ok(&pipeline, &out, &["--verbose", "--force"]);
    assert!(r.stdout.contains("trace.json"), "{}", r.stdout);

    // A render job whose scene is missing is named, with line and column, before anything runs.
    std::fs::write(&pipeline, "[[render]]\nscene = \"x.toml\"\n").unwrap();
    let r = fails(&["pipeline", "run", pipeline.to_str().unwrap()]);
    assert!(r.stderr.contains("small.toml:2:9"), "{}", r.stderr);
    assert!(r.stderr.contains("x.toml"), "{}", r.stderr);
    // A bad trace job is named.
    std::fs::write(
        &pipeline,
        "[[trace]]\natmosphere = \"us1976\"\nobserver_height_m = 5.0\nelevation_deg = \"1:0:1\"\ndistances_m = [1.0]\n",
    )
    .unwrap();
    let r = fails(&["pipeline", "run", pipeline.to_str().unwrap()]);
    assert!(r.stderr.contains("small.toml:4:17"), "{}", r.stderr);
    assert!(
        r.stderr.contains("TO must not be below FROM"),
        "{}",
        r.stderr
    );
}

#[test]
fn help_mentions_units_and_usage_errors_exit_2() {
    let r = ok(&["profile", "--help"]);
    for needle in ["metres", "nanometres", "--out", "out/profile/"] {
        assert!(r.stdout.contains(needle), "profile --help lacks {needle}");
    }
    let r = ok(&["trace", "--help"]);
    for needle in [
        "degrees",
        "metres",
        "FROM:TO:STEP",
        "--straight",
        "comma-separated",
        "at least 3 rays",
    ] {
        assert!(r.stdout.contains(needle), "trace --help lacks {needle}");
    }
    let r = ok(&["pipeline", "run", "--help"]);
    for needle in [
        "docs/pipeline.md",
        "--shard",
        "--dry-run",
        "--force",
        "--jobs",
    ] {
        assert!(
            r.stdout.contains(needle),
            "pipeline run --help lacks {needle}"
        );
    }
    let r = ok(&["render", "--help"]);
    assert!(
        r.stdout.contains("current folder"),
        "render --help: {}",
        r.stdout
    );
    usage_error(&["trace", "--no-such-option"]);
    usage_error(&["profile"]);
    // Bad values are usage errors too, refused by clap's value parsers before any work.
    let scene = data_file("scenes/fig01_horizon_straight.toml");
    let scene = scene.to_str().unwrap();
    for (args, needle) in [
        (&["render", scene, "--size", "100"][..], "WIDTHxHEIGHT"),
        (&["render", scene, "--size", "0x10"][..], "1 to 16384"),
        (&["render", scene, "-o", "x.jpg"][..], "x.jpg"),
        (&["render", scene, "--exposure", "0"][..], "exposure"),
        (
            &[
                "trace",
                "-a",
                "us1976",
                "--observer-height-m",
                "2",
                "--elevation-deg",
                "1:0:0.1",
            ][..],
            "TO must not be below FROM",
        ),
        (&["pipeline", "run", "p.toml", "--shard", "5/4"][..], "K/N"),
        (&["pipeline", "run", "p.toml", "-j", "0"][..], "≥ 1"),
        (&["pipeline", "merge"][..], "DIR"),
    ] {
        let r = usage_error(args);
        assert!(r.stderr.contains(needle), "{args:?}: {}", r.stderr);
    }
}

#[test]
fn profile_writes_to_out_profile_stem_by_default() {
    let dir = tempfile::tempdir().unwrap();
    let out = ghostship()
        .current_dir(dir.path())
        .args(["profile", "us1976", "--quiet"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let folder = dir.path().join("out").join("profile").join("us1976");
    for f in ["profile.csv", "layers.json", "profile.png"] {
        assert!(folder.join(f).is_file(), "{f} not in {}", folder.display());
    }
    // US1976 at sea level: 288.15 K, 1013.25 hPa, dry (the standard's defining values).
    let (_, rows) = read_profile_csv(&folder.join("profile.csv"));
    assert!((rows[0][1] - 288.15).abs() < 1e-9 && (rows[0][2] - 1013.25).abs() < 1e-9);
    assert_eq!(rows[0][3], 0.0);
}

#[test]
fn sounding_time_chooses_the_sounding() {
    let raw = sounding("raw/USM00070026-data_2010-06-01_excerpt.txt");
    let dir = tempfile::tempdir().unwrap();
    let surface_hpa = |time: Option<(&str, &str)>| {
        let mut args = vec![
            "profile",
            raw.to_str().unwrap(),
            "--format",
            "json",
            "--quiet",
            "--out",
            dir.path().to_str().unwrap(),
        ];
        if let Some((flag, t)) = time {
            args.extend([flag, t]);
        }
        let v: serde_json::Value = serde_json::from_str(&ok(&args).stdout).unwrap();
        v["surface"]["pressure_hpa"].as_f64().unwrap()
    };
    // The raw file's surface records: PRESS 100980 Pa at 00 UTC, 100840 Pa at 12 UTC.
    assert!((surface_hpa(None) - 1009.80).abs() < 1e-6);
    // `--time`, its visible alias and the former name, in either spelling of the time.
    for (flag, t) in [
        ("--time", "2010-06-01 12"),
        ("--time", "2010-06-01T12:00Z"),
        ("--sounding-time", "2010-06-01 12"),
        ("--igra2-time", "2010-06-01 12"),
    ] {
        assert!(
            (surface_hpa(Some((flag, t))) - 1008.40).abs() < 1e-6,
            "{flag} {t}"
        );
    }
    let r = fails(&[
        "profile",
        raw.to_str().unwrap(),
        "--time",
        "2010-06-03 00",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("2010-06-01 12"), "{}", r.stderr);
}

#[test]
fn shipped_soundings_pipeline_runs_and_shows_the_mirages() {
    let pipeline = repo_file("pipelines/soundings.toml");
    let dir = tempfile::tempdir().unwrap();
    pipeline_ok(&pipeline, dir.path(), &["--quiet"]);
    for job in [
        "utqiagvik",
        "danmarkshavn",
        "bjornoya",
        "superior_mirage",
        "inferior_mirage",
        "fata_morgana",
        "novaya_zemlya",
    ] {
        for f in ["profile.csv", "layers.json", "profile.png"] {
            assert!(dir.path().join(job).join(f).is_file(), "{job}/{f}");
        }
    }
    let trace = |name: &str| {
        let job = dir.path().join(format!("{name}_transfer"));
        assert!(job.join("trace.png").is_file());
        json_file(&job.join("trace.json"))
    };
    // Fata Morgana: stacked layers fold the transfer curve, so some image is inverted.
    let fm = trace("fata_morgana");
    assert!(
        fm["images"]
            .as_array()
            .unwrap()
            .iter()
            .any(|i| i["erect"] == false),
        "no inverted image in the Fata Morgana trace"
    );
    // Novaya Zemlya: the critical-gradient ground inversion ducts rays for hundreds of
    // kilometres, but from 100 m none is trapped for ever: Bouguer's invariant shows each ray
    // either meets the sea or climbs out, and the ducted ones escape far away (these rays used
    // to be cut at the 1 000 km trap distance and reported trapped).
    let nz = trace("novaya_zemlya");
    assert!(nz["trapped_elevations_deg"].as_array().unwrap().is_empty());
    let far_escapes = nz["rays"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["termination"] == "escaped" && r["end_distance_m"].as_f64().unwrap() > 500e3)
        .count();
    assert!(far_escapes > 10, "{far_escapes} rays escape beyond 500 km");
    // The other two traces exist and cover every distance.
    for name in ["superior_mirage", "inferior_mirage"] {
        let t = trace(name);
        assert_eq!(t["distances_m"].as_array().unwrap().len(), 5, "{name}");
    }
}

#[test]
fn render_writes_png_and_exr_of_the_requested_size() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("a.png");
    let exr = dir.path().join("sub/a.exr");
    let scene = data_file("scenes/fig08_inferior_mirage.toml");
    let r = ok(&[
        "render",
        scene.to_str().unwrap(),
        "--size",
        "80x40",
        "--spp",
        "1",
        "-o",
        png.to_str().unwrap(),
        "-o",
        exr.to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("a.png"), "{}", r.stderr);
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (80, 40));
    let meta = exr::meta::MetaData::read_from_file(&exr, false).unwrap();
    let size = meta.headers[0].layer_size;
    assert_eq!((size.width(), size.height()), (80, 40));
    // No temporary files are left beside the outputs.
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(names.iter().all(|n| !n.contains(".tmp")), "{names:?}");
}

#[test]
fn render_straight_and_curved_differ_and_bad_input_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let scene = data_file("scenes/fig08_inferior_mirage.toml");
    let curved = dir.path().join("curved.png");
    let straight = dir.path().join("straight.png");
    let args = |out: &Path| {
        vec![
            "render".to_string(),
            scene.to_str().unwrap().to_string(),
            "--size".into(),
            "100x50".into(),
            "--spp".into(),
            "1".into(),
            "-o".into(),
            out.to_str().unwrap().to_string(),
        ]
    };
    let a = args(&curved);
    ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let mut b = args(&straight);
    b.push("--straight".into());
    ok(&b.iter().map(String::as_str).collect::<Vec<_>>());
    assert_ne!(
        std::fs::read(&curved).unwrap(),
        std::fs::read(&straight).unwrap(),
        "the inferior mirage must change the image"
    );

    // Unknown output format, bad spp, bad scene field (with line), missing scene.
    let r = usage_error(&["render", scene.to_str().unwrap(), "-o", "x.jpg"]);
    assert!(r.stderr.contains("x.jpg"), "{}", r.stderr);
    let r = fails(&[
        "render",
        scene.to_str().unwrap(),
        "--spp",
        "3",
        "-o",
        dir.path().join("y.png").to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("square"), "{}", r.stderr);
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[camera]\nheight_m = 10.0\nwidht = 5\n").unwrap();
    let r = fails(&["render", bad.to_str().unwrap()]);
    assert!(r.stderr.contains("bad.toml"), "{}", r.stderr);
    assert!(r.stderr.contains("line 3"), "{}", r.stderr);
    let r = fails(&["render", dir.path().join("none.toml").to_str().unwrap()]);
    assert!(r.stderr.contains("none.toml"), "{}", r.stderr);
}

#[test]
fn pipeline_render_job_writes_every_size_and_format() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = dir.path().join("p.toml");
    let scene = data_file("scenes/fig01_horizon_straight.toml");
    std::fs::write(
        &pipeline,
        format!(
            "name = \"p\"\n[[render]]\nscene = {:?}\nname = \"fig01\"\nsizes = [\"64x32\", \"40x40\"]\nspp = 1\n",
            scene.to_str().unwrap()
        ),
    )
    .unwrap();
    let out = dir.path().join("o");
    pipeline_ok(&pipeline, &out, &[]);
    for (name, w, h) in [("64x32", 64, 32), ("40x40", 40, 40)] {
        let img = image::open(out.join(format!("fig01/{name}.png"))).unwrap();
        assert_eq!((img.width(), img.height()), (w, h));
        assert!(out.join(format!("fig01/{name}.exr")).is_file());
    }
}

#[test]
fn render_scene_chooses_the_igra2_sounding_and_refuses_a_camera_above_the_atmosphere() {
    let raw = sounding("raw/USM00070026-data_2010-06-01_excerpt.txt");
    let dir = tempfile::tempdir().unwrap();
    let scene = |name: &str, camera_height_m: f64, time: Option<&str>| {
        let path = dir.path().join(name);
        let time_line = time.map_or(String::new(), |t| format!("sounding_time = \"{t}\"\n"));
        std::fs::write(
            &path,
            format!(
                "[camera]\nheight_m = {camera_height_m}\nhfov_deg = 1.0\nwidth = 8\nheight = 4\n\
                 [atmosphere]\nsounding = {raw:?}\n{time_line}"
            ),
        )
        .unwrap();
        path
    };
    let out = dir.path().join("x.png");
    let out = out.to_str().unwrap();
    // The file holds 2010-06-01 00 and 12 UTC and 2010-06-02 00 UTC: a time it does not hold is
    // an error that lists the ones it does (the scene's choice reaches the reader).
    let absent = scene("absent.toml", 10.0, Some("2010-06-03 00"));
    let r = fails(&["render", absent.to_str().unwrap(), "-q", "-o", out]);
    assert!(r.stderr.contains("2010-06-01 12"), "{}", r.stderr);
    let present = scene("present.toml", 10.0, Some("2010-06-01 12"));
    ok(&["render", present.to_str().unwrap(), "-q", "-o", out]);
    // A camera above the 40 km top of the traced atmosphere: every ray used to be refused by the
    // tracer and shaded as horizon sky (no sea at all); now it is an error.
    let high = scene("high.toml", 90_000.0, None);
    let r = fails(&["render", high.to_str().unwrap(), "-q", "-o", out]);
    assert!(r.stderr.contains("90000"), "{}", r.stderr);
}

#[test]
fn pipeline_profile_and_trace_jobs_choose_the_igra2_sounding() {
    let raw = sounding("raw/USM00070026-data_2010-06-01_excerpt.txt");
    let dir = tempfile::tempdir().unwrap();
    let pipeline = |name: &str, time: &str| {
        let path = dir.path().join(format!("{name}.toml"));
        std::fs::write(
            &path,
            format!(
                "[[profile]]\natmosphere = {raw:?}\nname = \"p\"\nsounding_time = \"{time}\"\n\
                 [[trace]]\natmosphere = {raw:?}\nname = \"t\"\nsounding_time = \"{time}\"\n\
                 observer_height_m = 10.0\nelevation_deg = \"-0.2:0.2:0.1\"\n\
                 distances_m = [1000.0]\n"
            ),
        )
        .unwrap();
        path
    };
    // A time the file does not hold fails, naming the ones it holds (the job's choice reaches
    // the reader; before, pipelines always took the first sounding).
    let bad = pipeline("bad", "2010-06-03 00");
    let out = dir.path().join("out");
    let r = fails(&[
        "pipeline",
        "run",
        bad.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("2010-06-01 12"), "{}", r.stderr);
    // The 12 UTC sounding: its surface pressure, 1008.40 hPa in the raw file (00 UTC: 1009.80).
    let good = pipeline("good", "2010-06-01 12");
    ok(&[
        "pipeline",
        "run",
        good.to_str().unwrap(),
        "-q",
        "--out",
        out.to_str().unwrap(),
    ]);
    let layers = json_file(&out.join("p").join("layers.json"));
    let p = layers["surface"]["pressure_hpa"].as_f64().unwrap();
    assert!((p - 1008.40).abs() < 1e-6, "{p}");
}

/// The Markdown tables in `text`: each a list of rows (header and rule left out), each row its
/// cells, trimmed.
fn markdown_tables(text: &str) -> Vec<Vec<Vec<String>>> {
    let mut tables = Vec::new();
    let mut current: Vec<&str> = Vec::new();
    for line in text.lines().chain([""]) {
        if line.starts_with('|') {
            current.push(line);
        } else if !current.is_empty() {
            let rows = current
                .iter()
                .skip(2)
                .map(|l| {
                    // Cells split on `|` not escaped as `\|`.
                    let l = l.replace("\\|", "¦");
                    let cells: Vec<String> = l.split('|').map(|c| c.trim().to_string()).collect();
                    cells[1..cells.len() - 1].to_vec()
                })
                .collect();
            tables.push(rows);
            current.clear();
        }
    }
    tables
}

/// The text of the `## {title}` section of `md`, up to the next `## ` heading.
fn md_section<'a>(md: &'a str, title: &str) -> &'a str {
    let start = md
        .find(&format!("\n## {title}"))
        .unwrap_or_else(|| panic!("no section {title}:\n{md}"));
    let rest = &md[start + 1..];
    match rest[3..].find("\n## ") {
        Some(end) => &rest[..end + 3],
        None => rest,
    }
}

fn first_cells(rows: &[Vec<String>]) -> Vec<&str> {
    rows.iter().map(|r| r[0].as_str()).collect()
}

/// The quick run's rays section: one subsection per atmosphere (4 paper, 2 soundings, 6 stress),
/// each with a height-error table and an image-boundary table, a row per tolerance.
fn check_rays_section(md: &str) {
    let rays = md_section(md, "Rays:");
    let cases: Vec<&str> = rays.split("\n### ").skip(1).collect();
    assert_eq!(cases.len(), 12, "{rays}");
    for case in cases {
        let tables = markdown_tables(case);
        assert_eq!(tables.len(), 2, "{case}");
        // tolerance, 4 distances, p95, near-fold/compared, µs, steps, rays/s, steps/s.
        assert!(tables[0].iter().all(|r| r.len() == 11), "{case}");
        // tolerance, re-trace tolerance, images/reference, mismatches, max |Δ|, search ms.
        assert!(tables[1].iter().all(|r| r.len() == 6), "{case}");
        for t in &tables {
            assert_eq!(first_cells(t), ["1", "1e-2", "1e-4"], "{case}");
        }
        for row in &tables[1] {
            assert!(row[2].contains(" / ") && row[3].ends_with(" / 4"), "{case}");
        }
    }
}

/// The quick run's frame-time section: every paper scene at 80×40 and 192×108; the exact path
/// at 192×108 on a proxy; the straight-ray scene without curved paths; the fan tracer's steps
/// reproduced for every curved frame.
fn check_frame_times(md: &str) {
    let frames = md_section(md, "Frames: time per frame");
    let tables = markdown_tables(frames);
    assert_eq!(tables.len(), 3, "{frames}");
    let times = &tables[0];
    assert_eq!(times.len(), 18, "{frames}");
    for row in times {
        assert_eq!(row.len(), 6, "{row:?}");
        let straight_scene = row[0] == "fig01_horizon_straight";
        assert_eq!(row[3] == "–", straight_scene, "{row:?}");
        if row[1] == "192×108" && !straight_scene {
            assert!(row[4].ends_with("(proxy 64×36)"), "{row:?}");
        }
    }
    let fan = &tables[1];
    assert_eq!(fan.len(), 16, "{frames}");
    for row in fan {
        assert_eq!(row.len(), 7, "{row:?}");
        let steps: f64 = row[5].parse().unwrap_or_else(|_| panic!("{row:?}"));
        assert!(steps > 1.0, "{row:?}");
    }
    // Spectral frames: fig13 at both quick sizes, 8 bands, each band at least one more render.
    let spectral = &tables[2];
    assert!(frames.contains("### Spectral frames"), "{frames}");
    assert_eq!(first_cells(spectral), ["fig13_green_flash"; 2], "{frames}");
    for row in spectral {
        assert_eq!(row.len(), 6, "{row:?}");
        assert_eq!(row[2], "8", "{row:?}");
        let num = |c: &str| -> f64 { c.parse().unwrap_or_else(|_| panic!("{row:?}")) };
        let (rgb, spectral) = (num(&row[3]), num(&row[4]));
        assert!(rgb > 0.0 && spectral > rgb, "{row:?}");
    }
}

/// The quick run's image-error section: a table per curved paper scene, a row per tolerance with
/// the fan and exact paths' times, rays and pixel differences.
fn check_image_errors(md: &str) {
    let sweep = md_section(md, "Frames: image error against tolerance");
    assert!(sweep.contains("docs/frame_time_vs_error.png"), "{sweep}");
    let scenes: Vec<&str> = sweep.split("\n### ").skip(1).collect();
    assert_eq!(scenes.len(), 8, "{sweep}");
    for scene in scenes {
        assert!(
            scene.starts_with("fig") && scene.contains("40×20"),
            "{scene}"
        );
        let tables = markdown_tables(scene);
        assert_eq!(tables.len(), 1, "{scene}");
        assert_eq!(first_cells(&tables[0]), ["1", "1e-2", "1e-4"], "{scene}");
        for row in &tables[0] {
            assert_eq!(row.len(), 9, "{row:?}");
            // "changed" cells: a count and its fraction of the 800 pixels.
            let count: usize = row[3].split(' ').next().unwrap().parse().unwrap();
            assert!(count <= 800, "{row:?}");
        }
    }
}

#[test]
fn bench_accuracy_quick_writes_the_tables_and_the_plots() {
    let out = tempfile::tempdir().unwrap();
    let data = crate::support::data::data_dir();
    let r = ok(&[
        "bench",
        "accuracy",
        "--quick",
        "--out",
        out.path().to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("BENCHMARKS.md"), "{}", r.stderr);
    for plot in ["docs/time_vs_error.png", "docs/frame_time_vs_error.png"] {
        assert_eq!(png_size(&out.path().join(plot)), (1400, 900), "{plot}");
    }
    let md = std::fs::read_to_string(out.path().join("BENCHMARKS.md")).unwrap();
    assert!(md.contains("ghostship bench accuracy --quick"), "{md}");
    check_frame_times(&md);
    check_image_errors(&md);
    check_rays_section(&md);
    // --quiet prints nothing on success.
    let q = ok(&[
        "-q",
        "bench",
        "accuracy",
        "--quick",
        "--rays",
        "5",
        "--out",
        out.path().to_str().unwrap(),
        "--data",
        data.to_str().unwrap(),
    ]);
    assert!(q.stderr.is_empty() && q.stdout.is_empty(), "{}", q.stderr);
}

/// Run ghostship with `args`, its stdout a pipe whose reader reads `read` bytes (none: closes it
/// at once) and then goes away, like `ghostship … | head -c 10`; returns the exit status and
/// stderr.
fn with_closed_stdout(args: &[&str], read: usize) -> (std::process::ExitStatus, String) {
    use std::io::Read;
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_ghostship"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("binary starts");
    let mut stdout = child.stdout.take().unwrap();
    let mut head = vec![0u8; read];
    stdout
        .read_exact(&mut head)
        .expect("the first bytes arrive");
    drop(stdout);
    let out = child.wait_with_output().expect("binary ends");
    (
        out.status,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_closed_stdout_pipe_ends_every_command_quietly() {
    let dir = tempfile::tempdir().unwrap();
    // trace: ≈ 1 MB of JSON (and of CSV), far more than a pipe holds, so the writer is still
    // writing when the reader goes after 10 bytes.
    for format in ["json", "csv"] {
        let (status, stderr) = with_closed_stdout(
            &[
                "trace",
                "-a",
                "us1976",
                "--observer-height-m",
                "10",
                "--elevation-deg=-0.5:0.5:0.0005",
                "--format",
                format,
            ],
            10,
        );
        assert_eq!(status.code(), Some(0), "trace {format}: {stderr}");
        assert!(stderr.is_empty(), "trace {format}: {stderr}");
    }
    // The same through a shell pipe into `head -c 10`; the group records ghostship's own status.
    let (status_file, err_file) = (dir.path().join("status"), dir.path().join("err"));
    let out = std::process::Command::new("sh")
        .arg("-c")
        .arg(format!(
            "{{ '{}' trace -a us1976 --observer-height-m 10 --elevation-deg=-0.5:0.5:0.0005 \
             2>'{}'; echo $? >'{}'; }} | head -c 10 >/dev/null",
            env!("CARGO_BIN_EXE_ghostship"),
            err_file.display(),
            status_file.display()
        ))
        .output()
        .unwrap();
    assert!(out.status.success(), "{out:?}");
    assert_eq!(std::fs::read_to_string(&status_file).unwrap().trim(), "0");
    let stderr = std::fs::read_to_string(&err_file).unwrap();
    assert!(stderr.is_empty(), "{stderr}");
    // profile, pipeline run and --help print less than a pipe holds: the reader closes at once,
    // before they print. profile still writes its files.
    let prof = dir.path().join("prof");
    let (status, stderr) = with_closed_stdout(
        &["profile", "us1976", "-q", "--out", prof.to_str().unwrap()],
        0,
    );
    assert_eq!(status.code(), Some(0), "profile: {stderr}");
    assert!(stderr.is_empty(), "profile: {stderr}");
    assert!(prof.join("profile.csv").is_file());
    let pipeline = dir.path().join("p.toml");
    std::fs::write(
        &pipeline,
        "[[trace]]\natmosphere = \"us1976\"\nobserver_height_m = 10\nelevation_deg = \"0:0.2:0.1\"\ndistances_m = [1000.0]\n",
    )
    .unwrap();
    let out_dir = dir.path().join("o");
    let (status, stderr) = with_closed_stdout(
        &[
            "pipeline",
            "run",
            pipeline.to_str().unwrap(),
            "--out",
            out_dir.to_str().unwrap(),
        ],
        0,
    );
    assert_eq!(status.code(), Some(0), "pipeline: {stderr}");
    assert!(stderr.is_empty(), "pipeline: {stderr}");
    assert!(out_dir.join("us1976_transfer/trace.json").is_file());
    for args in [&["--help"][..], &["trace", "--help"][..]] {
        let (status, stderr) = with_closed_stdout(args, 0);
        assert_eq!(status.code(), Some(0), "{args:?}: {stderr}");
        assert!(stderr.is_empty(), "{args:?}: {stderr}");
    }
}

/// The `ghostship` provenance lines of an EXR file.
fn exr_provenance(path: &Path) -> Vec<String> {
    let meta = exr::meta::MetaData::read_from_file(path, false).unwrap();
    match meta.headers[0]
        .own_attributes
        .other
        .get(&exr::meta::attribute::Text::from("ghostship"))
    {
        Some(exr::meta::attribute::AttributeValue::TextVector(v)) => {
            v.iter().map(|t| t.to_string()).collect()
        }
        other => panic!("{}: no provenance attribute: {other:?}", path.display()),
    }
}

#[test]
fn render_tolerance_is_validated_used_and_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let scene = data_file("scenes/fig08_inferior_mirage.toml");
    let render = |tolerance: Option<&str>, stem: &str| {
        let png = dir.path().join(format!("{stem}.png"));
        let exr = dir.path().join(format!("{stem}.exr"));
        let mut args = vec![
            "render".to_string(),
            scene.to_str().unwrap().into(),
            "--size".into(),
            "80x40".into(),
            "--spp".into(),
            "1".into(),
            "-q".into(),
            "-o".into(),
            png.to_str().unwrap().into(),
            "-o".into(),
            exr.to_str().unwrap().into(),
        ];
        if let Some(t) = tolerance {
            args.extend(["--tolerance-m".into(), t.into()]);
        }
        ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
        (image::open(&png).unwrap().to_rgb8(), exr_provenance(&exr))
    };
    let (default_png, default_lines) = render(None, "default");
    let (fine_png, fine_lines) = render(Some("0.01"), "fine");
    let (coarse_png, coarse_lines) = render(Some("1"), "coarse");
    assert!(
        default_lines.contains(&"tracer_tolerance_m=0.001".to_string()),
        "{default_lines:?}"
    );
    assert!(
        fine_lines.contains(&"tracer_tolerance_m=0.01".to_string()),
        "{fine_lines:?}"
    );
    assert!(
        coarse_lines.contains(&"tracer_tolerance_m=1".to_string()),
        "{coarse_lines:?}"
    );
    for img in [&fine_png, &coarse_png] {
        assert_eq!(img.dimensions(), default_png.dimensions());
    }
    // The default 1 mm and the paper's 1 cm agree to far below a pixel here: at most a few edge
    // pixels may move.
    let differing = default_png
        .pixels()
        .zip(fine_png.pixels())
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        differing <= 40,
        "{differing} of 3200 pixels differ between 1 cm and 1 mm"
    );
    for bad in ["0", "-0.01", "nan", "inf", "11", "1e-7"] {
        let r = usage_error(&[
            "render",
            scene.to_str().unwrap(),
            &format!("--tolerance-m={bad}"),
            "-o",
            dir.path().join("bad.png").to_str().unwrap(),
        ]);
        assert!(r.stderr.contains("--tolerance-m"), "{bad}: {}", r.stderr);
        assert!(r.stderr.contains("1e-6 to 10"), "{bad}: {}", r.stderr);
    }
    // The pipeline's render jobs take it too, and record it.
    let pipeline = dir.path().join("p.toml");
    std::fs::write(
        &pipeline,
        format!(
            "[[render]]\nscene = {:?}\nname = \"f\"\nsizes = [\"40x20\"]\nspp = 1\ntolerance_m = 0.05\nformats = [\"exr\"]\n",
            scene.to_str().unwrap()
        ),
    )
    .unwrap();
    let out = dir.path().join("o");
    pipeline_ok(&pipeline, &out, &["-q"]);
    let lines = exr_provenance(&out.join("f/40x20.exr"));
    assert!(
        lines.contains(&"tracer_tolerance_m=0.05".to_string()),
        "{lines:?}"
    );
}

/// A spectral render's EXR records its bands and their centre wavelengths (they replace the
/// scene's single wavelength); an RGB render's records none.
#[test]
fn spectral_exr_records_its_bands() {
    let dir = tempfile::tempdir().unwrap();
    let lines = |scene: &str| {
        let exr = dir.path().join(format!("{scene}.exr"));
        let path = data_file(&format!("scenes/{scene}.toml"));
        ok(&[
            "render",
            path.to_str().unwrap(),
            "--size",
            "16x8",
            "--spp",
            "1",
            "-q",
            "-o",
            exr.to_str().unwrap(),
        ]);
        exr_provenance(&exr)
    };
    let spectral = lines("fig13_green_flash");
    assert!(
        spectral.contains(&"spectral_bands=8".to_string()),
        "{spectral:?}"
    );
    // 8 equal bands over 400–700 nm: 37.5 nm wide, centred from 418.75 nm.
    let want = "spectral_band_centres_nm=418.75,456.25,493.75,531.25,568.75,606.25,643.75,681.25";
    assert!(spectral.contains(&want.to_string()), "{spectral:?}");
    let rgb = lines("fig12_novaya_zemlya");
    assert!(!rgb.iter().any(|l| l.starts_with("spectral")), "{rgb:?}");
}

/// `profile` of a real sounding writes `fitted_layers.toml` and names it in the summary; the file
/// is an atmosphere `profile` accepts, with the sounding's surface height and temperature.
#[test]
fn profile_writes_fitted_layers_that_profile_accepts() {
    let dir = tempfile::tempdir().unwrap();
    let input = sounding("Utqiagvik-70026_2026020600.csv");
    let out = dir.path().join("measured");
    let r = ok(&[
        "profile",
        input.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(r.stdout.contains("Fitted synthetic layers"), "{}", r.stdout);
    let toml = out.join("fitted_layers.toml");
    let again = dir.path().join("synthetic");
    ok(&[
        "profile",
        toml.to_str().unwrap(),
        "--out",
        again.to_str().unwrap(),
    ]);
    let measured = json_file(&out.join("layers.json"));
    let fitted = json_file(&again.join("layers.json"));
    for key in ["height_m", "temperature_k"] {
        let (a, b) = (&measured["surface"][key], &fitted["surface"][key]);
        let (a, b) = (a.as_f64().unwrap(), b.as_f64().unwrap());
        // The fit is least squares, not interpolation: the surface may move by its residual.
        assert!((a - b).abs() < 0.5, "{key}: {a} vs {b}");
    }
}
