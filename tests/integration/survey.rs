//! `ghostship survey`: rows checked against `profile` and `trace` on the same files, a
//! multi-sounding IGRA2 record with a corrupt sounding in the middle, the Parquet table read
//! back by the `parquet` crate's own reader, determinism across thread counts, and clear errors.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use ghostship::survey::SurveyOptions;

use crate::support::cli::{fails, json_file, ok};
use crate::support::data::{public_sounding, sounding};

/// The survey CSV as rows of column → text.
fn read_csv(path: &Path) -> Vec<BTreeMap<String, String>> {
    let mut reader = csv::Reader::from_path(path).unwrap();
    let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            header
                .iter()
                .cloned()
                .zip(r.iter().map(String::from))
                .collect()
        })
        .collect()
}

fn num(row: &BTreeMap<String, String>, key: &str) -> Option<f64> {
    let text = row.get(key).unwrap_or_else(|| panic!("no column {key}"));
    (!text.is_empty()).then(|| text.parse().unwrap())
}

/// `survey-merge PART1 PART2 --out OUT`, which must fail.
fn merge_fails(part1: &Path, part2: &Path, out: &Path) -> crate::support::cli::Run {
    fails(&[
        "survey-merge",
        part1.to_str().unwrap(),
        part2.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ])
}

fn survey(sources: &[&Path], out: &Path, extra: &[&str]) -> Vec<BTreeMap<String, String>> {
    let mut args = vec!["survey", "--quiet", "--out", out.to_str().unwrap()];
    args.extend(sources.iter().map(|p| p.to_str().unwrap()));
    args.extend(extra);
    ok(&args);
    read_csv(&out.join("survey.csv"))
}

/// The survey's fan from `observer_height_m` as a `--elevation-deg` value for `trace`.
fn survey_fan(observer_height_m: f64) -> String {
    let r = SurveyOptions::default().trace_request(observer_height_m);
    let step = SurveyOptions::default().fan_step_deg;
    format!(
        "{:.17}:{:.17}:{step}",
        r.elevation_min_deg, r.elevation_max_deg
    )
}

fn trace_json(path: &Path, observer_height_m: f64, distance_m: f64) -> serde_json::Value {
    let r = ok(&[
        "trace",
        "-a",
        path.to_str().unwrap(),
        "--observer-height-m",
        &observer_height_m.to_string(),
        &format!("--elevation-deg={}", survey_fan(observer_height_m)),
        "--distance-m",
        &distance_m.to_string(),
        "--target-height-m",
        "20",
        "--format",
        "json",
    ]);
    serde_json::from_str(&r.stdout).unwrap()
}

fn layers_json(path: &Path) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    ok(&[
        "profile",
        path.to_str().unwrap(),
        "--layers-top-m",
        "3000",
        "--quiet",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    json_file(&dir.path().join("layers.json"))
}

/// Inversions and ducts of a row against `profile`'s layers.json (which rounds to 0.1 K, 1 m).
fn check_layers(row: &BTreeMap<String, String>, layers: &serde_json::Value, name: &str) {
    let inversions = layers["inversions"].as_array().unwrap();
    assert_eq!(
        num(row, "inversion_count"),
        Some(inversions.len() as f64),
        "{name}"
    );
    let strongest = inversions.iter().max_by(|a, b| {
        let key = |v: &serde_json::Value| v["delta_t_k"].as_f64().unwrap_or(0.0);
        key(a).total_cmp(&key(b))
    });
    match strongest {
        Some(s) => {
            let dt = num(row, "strongest_inversion_dt_k").unwrap();
            assert!(
                (dt - s["delta_t_k"].as_f64().unwrap()).abs() <= 0.051,
                "{name}: {dt}"
            );
            let base = num(row, "strongest_inversion_base_m").unwrap();
            assert!(
                (base - s["base_agl_m"].as_f64().unwrap()).abs() <= 0.51,
                "{name}"
            );
            let top = num(row, "strongest_inversion_top_m").unwrap();
            assert!(
                (top - s["top_agl_m"].as_f64().unwrap()).abs() <= 0.51,
                "{name}"
            );
        }
        None => assert_eq!(num(row, "strongest_inversion_dt_k"), None, "{name}"),
    }
    let ducts = layers["ducts"].as_array().unwrap();
    assert_eq!(num(row, "duct_count"), Some(ducts.len() as f64), "{name}");
    let surface_duct = ducts.iter().any(|d| d["surface_based"].as_bool().unwrap());
    assert_eq!(row["surface_duct"], surface_duct.to_string(), "{name}");
}

/// Horizon dip, lowest sun and images of a row against `trace` with the same fan. The survey's
/// n(h) table is coarser (error bound 1e-12 instead of 1e-14), so angles agree to 1e-5 deg, and
/// counts exactly.
fn check_trace(row: &BTreeMap<String, String>, trace: &serde_json::Value, name: &str) {
    let sea = trace["horizons"].as_array().unwrap().last().unwrap();
    let dip = -sea["elevation_deg"].as_f64().unwrap();
    let survey_dip = num(row, "horizon_dip_deg_h10m").unwrap();
    assert!(
        (dip - survey_dip).abs() < 1e-5,
        "{name}: dip {survey_dip} vs trace {dip}"
    );
    let lowest_sun = trace["rays"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["termination"] == "escaped")
        .map(|r| r["end_elevation_deg"].as_f64().unwrap())
        .reduce(f64::min)
        .unwrap();
    let survey_sun = num(row, "lowest_sun_deg_h10m").unwrap();
    assert!(
        (survey_sun - lowest_sun).abs() < 1e-5,
        "{name}: sun {survey_sun} vs {lowest_sun}"
    );
    let images = trace["images"].as_array().unwrap();
    assert_eq!(
        num(row, "images_h10m_d20000m"),
        Some(images.len() as f64),
        "{name}"
    );
    let inverted = images.iter().any(|i| !i["erect"].as_bool().unwrap());
    assert_eq!(row["inverted_h10m_d20000m"], inverted.to_string(), "{name}");
}

#[test]
fn rows_agree_with_profile_and_trace_on_the_same_files() {
    // Every shipped real sounding (the 14 normalised CSVs), each row against `profile` and
    // `trace` on the same file.
    let mut files: Vec<PathBuf> = std::fs::read_dir(crate::support::data::soundings_dir())
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 14);
    let refs: Vec<&Path> = files.iter().map(PathBuf::as_path).collect();
    let out = tempfile::tempdir().unwrap();
    let rows = survey(&refs, out.path(), &[]);
    assert_eq!(rows.len(), files.len());
    for (row, path) in rows.iter().zip(&files) {
        let name = path.display().to_string();
        assert_eq!(row["origin"], name);
        assert_eq!(row["unusable_reason"], "", "{name}");
        check_layers(row, &layers_json(path), &name);
        check_trace(row, &trace_json(path, 10.0, 20_000.0), &name);
    }
    // The Tiksi surface inversion (+9.6 K over 776 m) is found.
    let tiksi = &rows[files
        .iter()
        .position(|f| f.ends_with("Tiksi-21824_2026020600.csv"))
        .unwrap()];
    assert!(num(tiksi, "strongest_inversion_dt_k").unwrap() > 9.0);
    assert_eq!(tiksi["surface_inversion"], "true");
}

/// The standard atmosphere's horizon dip against the closed form for a uniform gradient near the
/// ground, dip = √(2h(1 − k)/R) with k = −R·dn/dh, which holds to ~1 % for a 10 m observer.
#[test]
fn standard_reference_dip_matches_the_uniform_gradient_formula() {
    use ghostship::refractivity::RefractiveAtmosphere;
    use ghostship::tracer::StratifiedIndex;
    let options = SurveyOptions::default();
    let reference = ghostship::survey::Reference::standard(&options).unwrap();
    let dip = reference.per_observer[0].0.unwrap();
    let column = std::sync::Arc::new(ghostship::profile::StandardAtmosphere::default());
    let atm = RefractiveAtmosphere::new(column, 550.0).unwrap();
    let (_, dn_dh) = atm.index_and_derivative(5.0);
    let r = ghostship::units::EARTH_RADIUS_M;
    let k = -r * dn_dh;
    let expected = (2.0 * 10.0 * (1.0 - k) / r).sqrt().to_degrees();
    assert!(
        (dip / expected - 1.0).abs() < 0.01,
        "dip {dip} vs {expected} (k {k})"
    );
}

/// The header and records of every sounding in an IGRA2 text.
fn igra2_blocks(text: &str) -> Vec<Vec<String>> {
    let mut blocks: Vec<Vec<String>> = Vec::new();
    for line in text.lines() {
        if line.starts_with('#') {
            blocks.push(Vec::new());
        }
        blocks.last_mut().unwrap().push(line.to_string());
    }
    blocks
}

/// `block` with the year of its header replaced.
fn with_year(block: &[String], year: u32) -> Vec<String> {
    let mut b = block.to_vec();
    b[0] = format!("{}{year}{}", &b[0][..13], &b[0][17..]);
    b
}

/// A record built from real soundings: the two complete soundings of the IGRA2 sample file
/// (Utqiagvik 2010-06-01 00 and 12 UTC, from the siphon test suite), then a copy of the first
/// dated 2011 whose fifth record has its temperature field replaced by `abcde`, then copies of
/// both dated 2012. Returns the record's path and the mangled line's number.
fn record_with_corrupt_sounding(dir: &Path) -> (PathBuf, usize) {
    let text = std::fs::read_to_string(public_sounding("igra2_USM00070026-data.txt")).unwrap();
    let blocks = igra2_blocks(&text);
    let (a, b) = (&blocks[0], &blocks[1]);
    let mut corrupt = with_year(a, 2011);
    corrupt[5].replace_range(22..27, "abcde");
    let parts = [
        a.clone(),
        b.clone(),
        corrupt,
        with_year(a, 2012),
        with_year(b, 2012),
    ];
    let bad_line = a.len() + b.len() + 6;
    let lines: Vec<String> = parts.concat();
    let path = dir.join("USM00070026-record.txt");
    std::fs::write(&path, lines.join("\n") + "\n").unwrap();
    (path, bad_line)
}

#[test]
fn igra2_record_with_a_corrupt_sounding_in_the_middle() {
    let dir = tempfile::tempdir().unwrap();
    let (record, bad_line) = record_with_corrupt_sounding(dir.path());
    let out = dir.path().join("out");
    let rows = survey(&[&record], &out, &[]);
    assert_eq!(rows.len(), 5);
    let times: Vec<&str> = rows.iter().map(|r| r["time_utc"].as_str()).collect();
    assert_eq!(
        times,
        [
            "2010-06-01 00",
            "2010-06-01 12",
            "2011-06-01 00",
            "2012-06-01 00",
            "2012-06-01 12"
        ]
    );
    let reason = &rows[2]["unusable_reason"];
    assert!(reason.contains(&format!("line {bad_line}")), "{reason}");
    assert!(reason.contains("TEMP"), "{reason}");
    assert_eq!(rows[2]["inversion_count"], "");
    for k in [0, 1, 3, 4] {
        assert_eq!(rows[k]["unusable_reason"], "", "row {k}");
    }
    // A sounding's facts do not depend on its neighbours: the 2012 copies equal the originals.
    let facts = |r: &BTreeMap<String, String>| {
        let mut r = r.clone();
        for key in ["origin", "time_utc", "month"] {
            r.remove(key);
        }
        r
    };
    assert_eq!(facts(&rows[0]), facts(&rows[3]));
    assert_eq!(facts(&rows[1]), facts(&rows[4]));
    // Each row equals `trace` of that sounding chosen by its time from the same record.
    for k in [0, 1, 3] {
        let r = ok(&[
            "trace",
            "-a",
            record.to_str().unwrap(),
            "--time",
            &rows[k]["time_utc"],
            "--observer-height-m",
            "10",
            &format!("--elevation-deg={}", survey_fan(10.0)),
            "--distance-m",
            "20000",
            "--target-height-m",
            "20",
            "--format",
            "json",
        ]);
        check_trace(
            &rows[k],
            &serde_json::from_str(&r.stdout).unwrap(),
            &format!("row {k}"),
        );
    }
}

#[test]
fn parquet_table_reads_back_with_the_parquet_reader_as_the_csv() {
    use parquet::file::reader::{FileReader, SerializedFileReader};
    use parquet::record::Field;
    let dir = tempfile::tempdir().unwrap();
    let (record, _) = record_with_corrupt_sounding(dir.path());
    let out = dir.path().join("out");
    let extra = [
        "--observer-height-m",
        "10,50",
        "--distance-m",
        "10000,30000",
    ];
    let rows = survey(
        &[&record, &sounding("Tiksi-21824_2026020600.csv")],
        &out,
        &extra,
    );
    let file = std::fs::File::open(out.join("survey.parquet")).unwrap();
    let reader = SerializedFileReader::new(file).unwrap();
    assert_eq!(
        reader.metadata().file_metadata().num_rows(),
        rows.len() as i64
    );
    let mut read = 0;
    for (k, record) in reader.get_row_iter(None).unwrap().enumerate() {
        let record = record.unwrap();
        for (name, field) in record.get_column_iter() {
            let csv = &rows[k][name];
            let same = match field {
                Field::Null => csv.is_empty(),
                Field::Str(s) => s == csv,
                Field::Double(x) => csv.parse::<f64>().unwrap() == *x,
                Field::Long(x) => csv.parse::<i64>().unwrap() == *x,
                Field::Bool(x) => csv.parse::<bool>().unwrap() == *x,
                other => panic!("unexpected Parquet field {other:?} in {name}"),
            };
            assert!(
                same,
                "row {k} column {name}: Parquet {field:?}, CSV {csv:?}"
            );
        }
        read += 1;
    }
    assert_eq!(read, rows.len());
    // 21 sounding columns, 6 per observer height, 6 per (height, distance) case.
    assert_eq!(
        rows[0].len(),
        21 + 2 * 6 + 4 * 6,
        "columns: {:?}",
        rows[0].keys()
    );
}

#[test]
fn survey_outputs_are_identical_whatever_the_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let (record, _) = record_with_corrupt_sounding(dir.path());
    let tiksi = sounding("Tiksi-21824_2026020600.csv");
    let mut trees = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.path().join(format!("out{threads}"));
        crate::support::cli::ghostship()
            .env("RAYON_NUM_THREADS", threads)
            .args(["survey", "--quiet", "--out", out.to_str().unwrap()])
            .args([record.to_str().unwrap(), tiksi.to_str().unwrap()])
            .assert()
            .success();
        trees.push(crate::support::cli::output_tree(&out));
    }
    assert_eq!(trees[0].len(), 6);
    assert_eq!(trees[0], trees[1]);
}

#[test]
fn folders_and_date_ranges_choose_the_soundings() {
    let dir = tempfile::tempdir().unwrap();
    let (record, _) = record_with_corrupt_sounding(dir.path());
    let out = dir.path().join("out");
    let rows = survey(
        &[&record],
        &out,
        &["--from", "2011-01-01", "--to", "2012-06-01"],
    );
    let times: Vec<&str> = rows.iter().map(|r| r["time_utc"].as_str()).collect();
    assert_eq!(times, ["2011-06-01 00", "2012-06-01 00", "2012-06-01 12"]);
    // A folder: its files sorted, README.md skipped.
    let folder = dir.path().join("folder");
    std::fs::create_dir(&folder).unwrap();
    for name in [
        "Tiksi-21824_2026020600.csv",
        "Cherskiy-25123_2026020600.csv",
    ] {
        std::fs::copy(sounding(name), folder.join(name)).unwrap();
    }
    std::fs::write(folder.join("README.md"), "notes\n").unwrap();
    let rows = survey(&[&folder], &dir.path().join("out2"), &[]);
    let origins: Vec<String> = rows.iter().map(|r| r["origin"].clone()).collect();
    assert!(
        origins[0].ends_with("Cherskiy-25123_2026020600.csv"),
        "{origins:?}"
    );
    assert!(
        origins[1].ends_with("Tiksi-21824_2026020600.csv"),
        "{origins:?}"
    );
    assert_eq!(rows.len(), 2);
}

#[test]
fn bad_requests_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    let r = fails(&["survey", "/no/such/archive.txt", "--out", out]);
    assert!(
        r.stderr
            .contains("/no/such/archive.txt: no such file or folder"),
        "{}",
        r.stderr
    );
    let tiksi = sounding("Tiksi-21824_2026020600.csv");
    let t = tiksi.to_str().unwrap();
    let r = fails(&["survey", t, "--from", "2024-13", "--out", out]);
    assert!(r.stderr.contains("is not YYYY-MM-DD"), "{}", r.stderr);
    let r = fails(&["survey", t, "--distance-m", "30000,10000", "--out", out]);
    assert!(r.stderr.contains("strictly ascending"), "{}", r.stderr);
    let pattern = format!("{}/*.nothing", dir.path().display());
    let r = fails(&["survey", &pattern, "--out", out]);
    assert!(r.stderr.contains("no file matches"), "{}", r.stderr);
    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let r = fails(&["survey", empty.to_str().unwrap(), "--out", out]);
    assert!(r.stderr.contains("no sounding file there"), "{}", r.stderr);
}

#[test]
fn a_pipeline_survey_job_writes_what_the_command_writes() {
    let dir = tempfile::tempdir().unwrap();
    let (record, _) = record_with_corrupt_sounding(dir.path());
    let record_name = record.file_name().unwrap().to_str().unwrap().to_string();
    let tiksi = "Tiksi-21824_2026020600.csv";
    std::fs::copy(sounding(tiksi), dir.path().join(tiksi)).unwrap();
    // Rows name files relative to the pipeline's folder: run the command from there.
    let pipeline = dir.path().join("survey.toml");
    std::fs::write(
        &pipeline,
        format!(
            "[defaults]\nsmooth_m = 10.0\n[[survey]]\nname = \"arctic\"\nsources = [{record_name:?}, {tiksi:?}]\n\
             from = \"2011-01-01\"\nobserver_height_m = [10.0, 40.0]\n\
             distances_m = [10000.0, 30000.0]\n"
        ),
    )
    .unwrap();
    let out = dir.path().join("out");
    crate::support::cli::pipeline_ok(&pipeline, &out, &[]);
    crate::support::cli::ghostship()
        .current_dir(dir.path())
        .args(["survey", "--quiet", "--out", "single", &record_name, tiksi])
        .args(["--smooth-m", "10", "--from", "2011-01-01"])
        .args([
            "--observer-height-m",
            "10,40",
            "--distance-m",
            "10000,30000",
        ])
        .assert()
        .success();
    crate::support::cli::assert_same_tree(&out.join("arctic"), &dir.path().join("single"));
    let rows = read_csv(&out.join("arctic/survey.csv"));
    let corrupt = rows
        .iter()
        .find(|r| !r["unusable_reason"].is_empty())
        .unwrap();
    assert!(
        corrupt["unusable_reason"].starts_with(&format!("{record_name}: line ")),
        "{corrupt:?}"
    );
    let manifest = json_file(&out.join("manifest.json"));
    let text = manifest.to_string();
    assert!(
        text.contains("Tiksi-21824_2026020600.csv"),
        "inputs not hashed: {text}"
    );
    // A source that matches nothing is a diagnostic at its line, before any job runs.
    std::fs::write(&pipeline, "[[survey]]\nsources = \"archive/*.nothing\"\n").unwrap();
    let r = crate::support::cli::pipeline_run(&pipeline, &out, &[]);
    assert_ne!(r.code, Some(0));
    assert!(r.stderr.contains("survey.toml:2:"), "{}", r.stderr);
    assert!(r.stderr.contains("no file matches"), "{}", r.stderr);
}

#[test]
fn the_shipped_survey_pipeline_surveys_every_shipped_sounding() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = crate::support::data::repo_file("pipelines/survey.toml");
    crate::support::cli::pipeline_ok(&pipeline, dir.path(), &[]);
    let rows = read_csv(&dir.path().join("shipped/survey.csv"));
    // 14 normalised + 6 pressure-level merges + 3 + 3 IGRA2 launches + 12 Wyoming soundings.
    assert_eq!(rows.len(), 38);
    let unusable: Vec<&str> = rows
        .iter()
        .filter(|r| !r["unusable_reason"].is_empty())
        .map(|r| r["origin"].as_str())
        .collect();
    assert_eq!(
        unusable,
        [
            "../tests/data/soundings/raw/USM00070026-data_2010-06-01_excerpt.txt:318",
            "../tests/data/soundings/raw/USM00070026-drvd_2014-09-10_excerpt.txt:220",
        ]
    );
    assert!(
        rows.iter().all(|r| r["time_utc"].len() == 13),
        "times: {rows:?}"
    );
    // Files are named relative to the pipeline file, in rows and reasons, from any folder.
    let reason = &rows
        .iter()
        .find(|r| !r["unusable_reason"].is_empty())
        .unwrap()["unusable_reason"];
    assert!(
        reason.starts_with("../tests/data/soundings/raw/"),
        "{reason}"
    );
}

/// The pipeline of a split survey (`parts`), its sources beside it.
fn split_pipeline(dir: &Path, parts: usize) -> PathBuf {
    record_with_corrupt_sounding(dir);
    let tiksi = "Tiksi-21824_2026020600.csv";
    std::fs::copy(sounding(tiksi), dir.join(tiksi)).unwrap();
    split_pipeline_keeping_record(dir, parts)
}

/// The pipeline of `split_pipeline` over the sources already in `dir`.
fn split_pipeline_keeping_record(dir: &Path, parts: usize) -> PathBuf {
    let record_name = "USM00070026-record.txt";
    let tiksi = "Tiksi-21824_2026020600.csv";
    let pipeline = dir.join(format!("split{parts}.toml"));
    std::fs::write(
        &pipeline,
        format!(
            "[[survey]]\nname = \"arctic\"\nsources = [{record_name:?}, {tiksi:?}]\nparts = {parts}\n"
        ),
    )
    .unwrap();
    pipeline
}

#[test]
fn a_survey_split_into_parts_and_shards_joins_into_the_unsplit_survey() {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole");
    crate::support::cli::pipeline_ok(&split_pipeline(dir.path(), 1), &whole, &[]);
    // Three parts in one run: the run joins them.
    let parts = dir.path().join("parts");
    let r = crate::support::cli::pipeline_ok(&split_pipeline(dir.path(), 3), &parts, &[]);
    assert!(r.stdout.contains("joined the survey parts"), "{}", r.stdout);
    crate::support::cli::assert_same_tree(&parts.join("arctic"), &whole.join("arctic"));
    let sizes: Vec<usize> = (1..=3)
        .map(|k| read_csv(&parts.join(format!("arctic_part_{k}_of_3/survey.csv"))).len())
        .collect();
    assert_eq!(sizes, [2, 2, 2], "6 soundings in three contiguous parts");
    // The same parts on two "machines" (shards into separate folders), then `pipeline merge`.
    let pipeline = split_pipeline(dir.path(), 3);
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let r = crate::support::cli::pipeline_ok(&pipeline, &a, &["--shard", "1/2"]);
    assert!(
        !r.stdout.contains("joined"),
        "a shard does not join: {}",
        r.stdout
    );
    crate::support::cli::pipeline_ok(&pipeline, &b, &["--shard", "2/2"]);
    let r = ok(&[
        "pipeline",
        "merge",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
    ]);
    assert!(r.stdout.contains("joined the survey parts"), "{}", r.stdout);
    crate::support::cli::assert_same_tree(&a.join("arctic"), &whole.join("arctic"));
    assert_manifest_lists_every_file(&a);
    // The merged manifest, joined survey included, is the one the run in one go wrote.
    assert_eq!(
        json_file(&a.join("manifest.json")),
        json_file(&parts.join("manifest.json"))
    );
    // `ghostship survey --shard` and `survey-merge` do the same by hand; gaps are errors.
    let src = |p: &str| dir.path().join(p).to_str().unwrap().to_string();
    let record = src("USM00070026-record.txt");
    let tiksi = src("Tiksi-21824_2026020600.csv");
    for k in 1..=2 {
        let out = src(&format!("hand{k}"));
        ok(&[
            "survey",
            "--quiet",
            "--shard",
            &format!("{k}/2"),
            "--out",
            &out,
            &record,
            &tiksi,
        ]);
    }
    let joined = src("hand");
    ok(&[
        "survey-merge",
        &src("hand2"),
        &src("hand1"),
        "--out",
        &joined,
    ]);
    let single = src("single");
    ok(&["survey", "--quiet", "--out", &single, &record, &tiksi]);
    crate::support::cli::assert_same_tree(Path::new(&joined), Path::new(&single));
    let r = fails(&["survey-merge", &src("hand1"), "--out", &joined]);
    assert!(r.stderr.contains("part 2/2 is missing"), "{}", r.stderr);
    let r = fails(&[
        "survey-merge",
        &src("hand1"),
        &src("hand1"),
        "--out",
        &joined,
    ]);
    assert!(r.stderr.contains("part 1/2 is given twice"), "{}", r.stderr);
}

#[test]
fn review_edge_cases_are_errors_or_right_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    // A file whose name holds glob characters is surveyed once, as itself, beside its look-alike.
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    for name in ["a1.csv", "a[1].csv"] {
        std::fs::copy(sounding("Tiksi-21824_2026020600.csv"), data.join(name)).unwrap();
    }
    let pipeline = dir.path().join("p.toml");
    std::fs::write(&pipeline, "[[survey]]\nsources = \"data/*.csv\"\n").unwrap();
    let out = dir.path().join("out");
    crate::support::cli::pipeline_ok(&pipeline, &out, &[]);
    let rows = read_csv(&out.join("survey/survey.csv"));
    let origins: Vec<&str> = rows.iter().map(|r| r["origin"].as_str()).collect();
    assert_eq!(origins, ["data/a1.csv", "data/a[1].csv"]);
    // A split survey may not join into another job's folder.
    std::fs::write(
        &pipeline,
        "[[survey]]\nsources = \"data/*.csv\"\nparts = 2\n[[survey]]\nsources = \"data/*.csv\"\nparts = 3\n",
    )
    .unwrap();
    let r = crate::support::cli::pipeline_run(&pipeline, &out, &["--dry-run"]);
    assert_ne!(r.code, Some(0));
    assert!(
        r.stderr.contains("which another job writes too"),
        "{}",
        r.stderr
    );
    // A fan step too fine for the fan limit names the option.
    let t = data.join("a1.csv");
    let o = dir.path().join("o");
    let args = |extra: &[&str]| {
        let mut a = vec!["survey", t.to_str().unwrap(), "--out", o.to_str().unwrap()];
        a.extend_from_slice(extra);
        a.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let a = args(&["--fan-step-deg", "1e-300"]);
    let r = fails(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        r.stderr.contains("fan_step_deg 1e-300 makes a fan of"),
        "{}",
        r.stderr
    );
    // Shard arithmetic does not overflow.
    let a = args(&[
        "--quiet",
        "--shard",
        "9223372036854775807/9223372036854775807",
    ]);
    ok(&a.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(read_csv(&o.join("survey.csv")).len(), 1);
}

/// `record_with_corrupt_sounding`'s record with the temperature of the 2012 copies' third level
/// changed: the same files, soundings and times, other values.
fn change_the_2012_soundings(record: &Path) {
    let text = std::fs::read_to_string(record).unwrap();
    let mut blocks = igra2_blocks(&text);
    for block in blocks.iter_mut().filter(|b| b[0][13..17] == *"2012") {
        block[3].replace_range(22..27, "  -50");
    }
    std::fs::write(record, blocks.concat().join("\n") + "\n").unwrap();
}

/// `ghostship survey --quiet --shard K/N --out OUT SOURCES…`.
fn survey_part(sources: &[&Path], shard: &str, out: &Path) {
    let mut args = vec![
        "survey",
        "--quiet",
        "--shard",
        shard,
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(sources.iter().map(|p| p.to_str().unwrap()));
    ok(&args);
}

#[test]
fn survey_merge_refuses_a_stale_part_of_other_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let (record, _) = record_with_corrupt_sounding(dir.path());
    let (p1, p2) = (dir.path().join("p1"), dir.path().join("p2"));
    survey_part(&[&record], "1/2", &p1);
    survey_part(&[&record], "2/2", &p2);
    // Part.json records each input's size and SHA-256, the request and the program.
    let part = json_file(&p2.join("part.json"));
    let bytes = std::fs::read(&record).unwrap();
    let input = &part["inputs"][0];
    assert_eq!(input["file"], record.to_str().unwrap(), "{input}");
    assert_eq!(input["bytes"], bytes.len(), "{input}");
    assert_eq!(
        input["sha256"],
        ghostship::jobs::sha256_hex(&bytes),
        "{input}"
    );
    assert_eq!(
        part["program"],
        format!("ghostship {}", env!("CARGO_PKG_VERSION"))
    );
    assert_eq!(part["shard"]["count"], 2);
    // The record changes (same soundings, other values); part 1 is surveyed again, the run of
    // part 2 fails before writing, so p2 still holds the part of the old record.
    change_the_2012_soundings(&record);
    survey_part(&[&record], "1/2", &p1);
    let r = fails(&[
        "survey",
        "--shard",
        "2/2",
        "--from",
        "2024-13",
        "--out",
        p2.to_str().unwrap(),
        record.to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("is not YYYY-MM-DD"), "{}", r.stderr);
    let joined = dir.path().join("joined");
    let r = merge_fails(&p1, &p2, &joined);
    for needle in [
        p1.to_str().unwrap(),
        p2.to_str().unwrap(),
        "different inputs",
    ] {
        assert!(r.stderr.contains(needle), "{needle}: {}", r.stderr);
    }
    assert!(!joined.exists(), "a refused merge writes nothing");
    // A part written by another program version is refused too.
    survey_part(&[&record], "2/2", &p2);
    ok(&[
        "survey-merge",
        "-q",
        p1.to_str().unwrap(),
        p2.to_str().unwrap(),
        "--out",
        joined.to_str().unwrap(),
    ]);
    let mut part = json_file(&p2.join("part.json"));
    part["program"] = "ghostship 0.0.0".into();
    std::fs::write(p2.join("part.json"), serde_json::to_vec(&part).unwrap()).unwrap();
    let r = merge_fails(&p1, &p2, &joined);
    assert!(r.stderr.contains("ghostship 0.0.0"), "{}", r.stderr);
}

#[test]
fn a_folder_holds_the_files_of_one_survey_run() {
    let dir = tempfile::tempdir().unwrap();
    let (record, _) = record_with_corrupt_sounding(dir.path());
    let (p1, p2) = (dir.path().join("p1"), dir.path().join("p2"));
    survey_part(&[&record], "1/2", &p1);
    survey_part(&[&record], "2/2", &p2);
    // An unsplit survey into a part's folder leaves no part.json of the earlier run behind.
    survey(&[&record], &p2, &[]);
    assert!(!p2.join("part.json").exists(), "stale part.json kept");
    let r = merge_fails(&p1, &p2, &dir.path().join("j"));
    assert!(r.stderr.contains("part.json"), "{}", r.stderr);
    // The joined survey never goes into a part's folder (it would mix with that part).
    survey_part(&[&record], "2/2", &p2);
    let before = crate::support::cli::output_tree(&p1);
    let r = merge_fails(&p1, &p2, &p1);
    assert!(r.stderr.contains("is one of the parts"), "{}", r.stderr);
    assert!(
        crate::support::cli::output_tree(&p1) == before,
        "the part was changed"
    );
}

/// Every file under `out` but the manifests is listed in `out/manifest.json` (a job's outputs
/// or a joined survey's) with its size and SHA-256.
fn assert_manifest_lists_every_file(out: &Path) {
    let manifest = json_file(&out.join("manifest.json"));
    let mut listed = BTreeMap::new();
    for record in manifest["jobs"].as_object().unwrap().values() {
        listed.extend(record["outputs"].as_object().unwrap().clone());
    }
    for record in manifest["joined"]
        .as_object()
        .into_iter()
        .flat_map(|m| m.values())
    {
        listed.extend(record["outputs"].as_object().unwrap().clone());
    }
    for (rel, bytes) in crate::support::cli::output_tree(out) {
        if rel.starts_with("manifest") {
            continue;
        }
        let record = listed
            .get(&rel)
            .unwrap_or_else(|| panic!("{rel} is not in the manifest: {manifest}"));
        assert_eq!(
            record["sha256"],
            ghostship::jobs::sha256_hex(&bytes),
            "{rel}"
        );
        assert_eq!(record["bytes"], bytes.len(), "{rel}");
    }
}

#[test]
fn a_joined_survey_is_in_the_manifest_and_never_stale() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = split_pipeline(dir.path(), 2);
    let out = dir.path().join("out");
    crate::support::cli::pipeline_ok(&pipeline, &out, &[]);
    assert_manifest_lists_every_file(&out);
    let manifest = json_file(&out.join("manifest.json"));
    assert_eq!(
        manifest["joined"]["arctic"]["parts"],
        serde_json::json!(["arctic_part_1_of_2", "arctic_part_2_of_2"])
    );
    // The same after a second run that skips both parts.
    crate::support::cli::pipeline_ok(&pipeline, &out, &[]);
    assert_manifest_lists_every_file(&out);
    // The record changes and part 2 cannot be written (a folder in the way of its table):
    // the run fails, and the joined survey of the old record is gone rather than kept.
    change_the_2012_soundings(&dir.path().join("USM00070026-record.txt"));
    let blocker = out.join("arctic_part_2_of_2/survey.csv");
    std::fs::remove_file(&blocker).unwrap();
    std::fs::create_dir(&blocker).unwrap();
    std::fs::write(blocker.join("x"), "").unwrap();
    let r = crate::support::cli::pipeline_run(&pipeline, &out, &[]);
    assert_ne!(r.code, Some(0));
    assert!(
        !out.join("arctic/survey.csv").exists(),
        "stale joined survey kept"
    );
    let manifest = json_file(&out.join("manifest.json"));
    assert!(manifest.get("joined").is_none(), "{manifest}");
    // Fixed, the next run joins the parts again, as the unsplit survey of the new record.
    std::fs::remove_dir_all(&blocker).unwrap();
    crate::support::cli::pipeline_ok(&pipeline, &out, &[]);
    assert_manifest_lists_every_file(&out);
    let whole = dir.path().join("whole");
    crate::support::cli::pipeline_ok(&split_pipeline_keeping_record(dir.path(), 1), &whole, &[]);
    crate::support::cli::assert_same_tree(&out.join("arctic"), &whole.join("arctic"));
}

/// The survey's n(h) table (`survey_table()`: 5 m cells to 1 km, 100 m above, cells holding a
/// level cut there) against the exact formula at 4 000 random heights from the surface to the
/// 40 km top, on every shipped real sounding fitted as the survey fits it: within
/// `SURVEY_TABLE_DNDH_PER_M` in n and in dn/dh, the bound README and the docs state.
#[test]
fn the_survey_table_holds_its_bound_against_the_exact_formula() {
    use std::sync::Arc;

    use ghostship::profile::Profile;
    use ghostship::refractivity::RefractiveAtmosphere;
    use ghostship::sounding::{ReadOptions, read_sounding};
    use ghostship::survey::{SURVEY_TABLE_DNDH_PER_M, survey_table};

    let options = SurveyOptions::default();
    let mut files: Vec<PathBuf> = std::fs::read_dir(crate::support::data::soundings_dir())
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    files.sort();
    assert_eq!(files.len(), 14);
    // SplitMix64: deterministic heights, so a failure reproduces.
    let mut state = 0x5EED_u64;
    let mut next = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        (z ^ (z >> 31)) as f64 / u64::MAX as f64
    };
    for path in &files {
        let s = read_sounding(path, &ReadOptions::default()).unwrap();
        let profile = Profile::from_sounding(&s, &options.atmosphere.fit_options()).unwrap();
        let atm = RefractiveAtmosphere::with_spec(Arc::new(profile), 550.0, survey_table())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let (mut worst_n, mut worst_d) = (0.0f64, 0.0f64);
        for _ in 0..4_000 {
            // Half the heights in the lowest kilometre (5 m cells), half above.
            let u = next();
            let h = if u < 0.5 {
                2e3 * u
            } else {
                1e3 + 78e3 * (u - 0.5)
            };
            let (table, exact) = (atm.table_refractivity(h), atm.exact_refractivity(h));
            worst_n = worst_n.max((table.0 - exact.0).abs());
            worst_d = worst_d.max((table.1 - exact.1).abs());
        }
        assert!(
            worst_n <= SURVEY_TABLE_DNDH_PER_M && worst_d <= SURVEY_TABLE_DNDH_PER_M,
            "{}: |Δn| {worst_n:.2e}, |Δdn/dh| {worst_d:.2e} /m",
            path.display()
        );
    }
}
