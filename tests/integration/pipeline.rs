//! `ghostship pipeline run` and `pipeline merge` end to end, in temporary folders over the
//! repository's own inputs: incremental runs, byte-identical outputs for any `-j` and for shards
//! merged, survival of `kill -9` at random moments, isolation of a corrupt sounding, dry runs,
//! problems reported with line and column, size-limited input reading. Expected outputs are
//! never hard-coded: they are a reference run of the same pipeline.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::support::cli::{
    assert_same_tree, binary, fails, json_file, ok, output_tree, pipeline_ok, pipeline_run,
};
use crate::support::data::{data_dir, data_file, repo_file, sounding, soundings_dir};

/// A small pipeline over shipped inputs (three scenes at 160×80, two profiles, a trace matrix
/// over two observer heights), written into `dir`; about a second of work.
fn small_pipeline(dir: &Path) -> PathBuf {
    let scene = |name: &str| data_file(&format!("scenes/{name}.toml"));
    let text = format!(
        r#"name = "small"
[defaults]
sizes = ["160x80"]
spp = 1
[[render]]
scene = [{:?}, {:?}, {:?}]
[[profile]]
atmosphere = [{:?}, "us1976"]
[[trace]]
atmosphere = {:?}
observer_height_m = [10.0, 50.0]
elevation_deg = "-0.2:0.3:0.005"
distances_m = [10000.0, 30000.0]
"#,
        scene("fig04_superior_mirage"),
        scene("fig08_inferior_mirage"),
        scene("fig10_fata_morgana"),
        data_file("Bjornoya-01028_2024022611.csv"),
        data_file("fata_morgana.toml"),
    );
    let path = dir.join("small.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn job_count(out: &Path) -> usize {
    json_file(&out.join("manifest.json"))["jobs_in_pipeline"]
        .as_array()
        .unwrap()
        .len()
}

#[test]
fn paper_pipeline_skips_when_unchanged_and_is_the_same_for_any_j_and_for_merged_shards() {
    let paper = repo_file("pipelines/paper.toml");
    let dir = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        dir.path().join("a"),
        dir.path().join("b"),
        dir.path().join("c"),
    );
    let start = Instant::now();
    pipeline_ok(&paper, &a, &["-j", "1"]);
    let first = start.elapsed();
    let jobs = job_count(&a);
    let start = Instant::now();
    let again = pipeline_ok(&paper, &a, &[]);
    let second = start.elapsed();
    assert!(
        again
            .stdout
            .contains(&format!("{jobs} job(s): 0 ran, {jobs} unchanged")),
        "{}",
        again.stdout
    );
    assert!(
        second * 10 < first,
        "second run {second:?}, first {first:?}"
    );
    pipeline_ok(&paper, &b, &["-j", "2"]);
    assert_same_tree(&a, &b);
    for k in 1..=4 {
        let r = pipeline_ok(&paper, &c, &["--shard", &format!("{k}/4")]);
        assert!(
            r.stdout.contains(&format!("in shard {k}/4")),
            "{}",
            r.stdout
        );
        assert!(
            !r.stdout.contains(" 0 ran"),
            "shard {k} got no jobs: {}",
            r.stdout
        );
    }
    ok(&["pipeline", "merge", c.to_str().unwrap()]);
    for k in 1..=4 {
        std::fs::remove_file(c.join(format!("manifest-shard-{k}-of-4.json"))).unwrap();
    }
    assert_same_tree(&a, &c);
}

/// A small deterministic generator for the kill moments (the seed is printed on failure).
struct Lcg(u64);

impl Lcg {
    fn below(&mut self, n: u64) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 33) % n.max(1)
    }
}

fn is_temp(name: &str) -> bool {
    name.contains(".ghostship-tmp.") || name.contains(".tmp-")
}

#[test]
fn runs_killed_at_random_moments_resume_to_the_same_bytes_and_leave_no_temp_files() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = small_pipeline(dir.path());
    let reference = dir.path().join("reference");
    pipeline_ok(&pipeline, &reference, &[]);
    // Kills land in the first four fifths of a warm forced run (the first one also fills
    // caches). The machine's load changes while the test runs, so the window adapts: a run that
    // finished before its kill shrinks it by a quarter. The loop goes on until enough runs were
    // really interrupted, which the assertion below checks.
    let start = Instant::now();
    pipeline_ok(&pipeline, &reference, &["--force"]);
    let mut window_ms = (start.elapsed().as_millis() as u64 * 4 / 5).max(1);
    let expected = output_tree(&reference);
    let out = dir.path().join("killed");
    let seed = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as u64;
    let mut rng = Lcg(seed);
    let mut temp_files_seen = 0;
    let mut interrupted = 0;
    let mut attempts = 0;
    const INTERRUPTED: usize = 12;
    const MIN_ATTEMPTS: usize = 20;
    const MAX_ATTEMPTS: usize = 60;
    while (interrupted < INTERRUPTED || attempts < MIN_ATTEMPTS) && attempts < MAX_ATTEMPTS {
        let attempt = attempts;
        attempts += 1;
        // Mostly forced, so that kills also land in runs that rewrite finished outputs; every
        // third run resumes.
        let mut cmd = std::process::Command::new(binary());
        cmd.args([
            "pipeline",
            "run",
            pipeline.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
        ]);
        if attempt % 3 != 0 {
            cmd.arg("--force");
        }
        let mut child = cmd.spawn().unwrap();
        std::thread::sleep(Duration::from_millis(rng.below(window_ms)));
        if child.try_wait().unwrap().is_none() {
            interrupted += 1;
        } else {
            window_ms = (window_ms * 3 / 4).max(1);
        }
        let _ = child.kill(); // SIGKILL
        child.wait().unwrap();
        for (name, bytes) in output_tree(&out) {
            if is_temp(&name) {
                temp_files_seen += 1;
            } else if name.ends_with("manifest.json") {
                assert!(
                    serde_json::from_slice::<serde_json::Value>(&bytes).is_ok(),
                    "seed {seed}, kill {attempt}: {name} is not whole JSON"
                );
            } else {
                assert!(
                    expected.get(&name) == Some(&bytes),
                    "seed {seed}, kill {attempt}: {name} is partial or wrong under its final name"
                );
            }
        }
    }
    assert!(
        interrupted >= INTERRUPTED,
        "seed {seed}: only {interrupted} of {attempts} runs were killed before they finished"
    );
    // A temp file of a dead writer in the older `.<name>.tmp-<pid>` form (pid 0 is never a
    // running process) is removed as well.
    std::fs::create_dir_all(out.join("us1976")).unwrap();
    std::fs::write(out.join("us1976/.layers.json.tmp-0"), b"partial").unwrap();
    let r = pipeline_ok(&pipeline, &out, &[]);
    assert_same_tree(&reference, &out);
    eprintln!(
        "kill test: seed {seed}, {interrupted} of {attempts} runs interrupted, {temp_files_seen} \
         temp file(s) left between kills; last run: {}",
        r.stdout.trim_end()
    );
}

#[test]
fn a_corrupt_sounding_fails_its_job_only_naming_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let batch = dir.path().join("batch");
    std::fs::create_dir(&batch).unwrap();
    for name in [
        "Tiksi-21824_2026020600.csv",
        "SouthPole-89009_2026020600.csv",
        "Boise-72681_2010120912.csv",
    ] {
        std::fs::copy(sounding(name), batch.join(name)).unwrap();
    }
    // Break the temperature of the third data row of Boise's copy.
    let text = std::fs::read_to_string(sounding("Boise-72681_2010120912.csv")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let header = lines
        .iter()
        .position(|l| l.starts_with("pressure_hpa"))
        .unwrap();
    let bad_line = header + 4; // 0-based index of the third data row
    let mut fields: Vec<String> = lines[bad_line].split(',').map(str::to_string).collect();
    fields[2] = "warm".into();
    lines[bad_line] = fields.join(",");
    std::fs::write(
        batch.join("Boise-72681_2010120912.csv"),
        lines.join("\n") + "\n",
    )
    .unwrap();
    let pipeline = dir.path().join("batch.toml");
    std::fs::write(&pipeline, "[[profile]]\natmosphere = \"batch/*.csv\"\n").unwrap();
    let out = dir.path().join("out");
    let r = pipeline_run(&pipeline, &out, &[]);
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    assert!(r.stderr.contains("1 of 3 job(s) failed"), "{}", r.stderr);
    assert!(
        r.stderr.contains("Boise-72681_2010120912.csv"),
        "{}",
        r.stderr
    );
    assert!(
        r.stderr.contains(&format!("line {}", bad_line + 1)),
        "{}",
        r.stderr
    );
    assert!(r.stdout.contains("FAILED"), "{}", r.stdout);
    for good in ["Tiksi-21824_2026020600", "SouthPole-89009_2026020600"] {
        assert!(out.join(good).join("profile.png").is_file(), "{good}");
    }
    let manifest = json_file(&out.join("manifest.json"));
    assert_eq!(
        manifest["jobs"]["Boise-72681_2010120912"]["status"],
        "failed"
    );
    // The next run retries the failed job only (and fails it again).
    let r = pipeline_run(&pipeline, &out, &[]);
    assert!(
        r.stdout.contains("0 ran, 2 unchanged (skipped), 1 failed"),
        "{}",
        r.stdout
    );
}

#[test]
fn dry_run_lists_what_would_run_and_an_edited_input_reruns_its_job() {
    let dir = tempfile::tempdir().unwrap();
    let atmosphere = dir.path().join("layer.toml");
    std::fs::copy(data_file("inferior_mirage.toml"), &atmosphere).unwrap();
    let pipeline = dir.path().join("p.toml");
    std::fs::write(
        &pipeline,
        "[[profile]]\natmosphere = [\"layer.toml\", \"us1976\"]\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    let r = pipeline_ok(&pipeline, &out, &["--dry-run"]);
    assert!(r.stdout.contains("2 would run"), "{}", r.stdout);
    assert!(!out.exists(), "a dry run writes nothing");
    pipeline_ok(&pipeline, &out, &[]);
    let r = pipeline_ok(&pipeline, &out, &["--dry-run"]);
    assert!(
        r.stdout.contains("0 would run, 2 unchanged"),
        "{}",
        r.stdout
    );
    let mut text = std::fs::read_to_string(&atmosphere).unwrap();
    text.push_str("\n# edited\n");
    std::fs::write(&atmosphere, text).unwrap();
    let r = pipeline_ok(&pipeline, &out, &["--dry-run"]);
    assert!(
        r.stdout.contains("1 would run, 1 unchanged"),
        "{}",
        r.stdout
    );
    let row = r.stdout.lines().find(|l| l.starts_with("layer ")).unwrap();
    assert!(row.contains("would run"), "{row}");
    let r = pipeline_ok(&pipeline, &out, &["--dry-run", "--force"]);
    assert!(r.stdout.contains("2 would run"), "{}", r.stdout);
}

#[test]
fn merge_rejects_missing_and_repeated_shards_and_jobs() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = dir.path().join("p.toml");
    std::fs::write(
        &pipeline,
        "[[trace]]\natmosphere = \"us1976\"\nobserver_height_m = [2.0, 5.0, 10.0, 20.0]\nelevation_deg = \"-0.1:0.1:0.05\"\ndistances_m = [2000.0]\n",
    )
    .unwrap();
    let d = dir.path().join("d");
    for k in [1, 2] {
        pipeline_ok(&pipeline, &d, &["--shard", &format!("{k}/3")]);
    }
    let r = fails(&["pipeline", "merge", d.to_str().unwrap()]);
    assert!(r.stderr.contains("3/3 missing"), "{}", r.stderr);
    pipeline_ok(&pipeline, &d, &["--shard", "3/3"]);
    // The same shard in two folders.
    let e = dir.path().join("e");
    std::fs::create_dir(&e).unwrap();
    std::fs::copy(
        d.join("manifest-shard-1-of-3.json"),
        e.join("manifest-shard-1-of-3.json"),
    )
    .unwrap();
    let r = fails(&[
        "pipeline",
        "merge",
        d.to_str().unwrap(),
        e.to_str().unwrap(),
    ]);
    assert!(r.stderr.contains("shard 1/3 appears twice"), "{}", r.stderr);
    // A job in two shards.
    let path = |k: usize| d.join(format!("manifest-shard-{k}-of-3.json"));
    let one = json_file(&path(1));
    let mut two = json_file(&path(2));
    let (name, record) = one["jobs"].as_object().unwrap().iter().next().unwrap();
    two["jobs"][name] = record.clone();
    let saved = std::fs::read(path(2)).unwrap();
    std::fs::write(path(2), serde_json::to_vec_pretty(&two).unwrap()).unwrap();
    let r = fails(&["pipeline", "merge", d.to_str().unwrap()]);
    assert!(
        r.stderr.contains(&format!("job {name:?} appears twice")),
        "{}",
        r.stderr
    );
    std::fs::write(path(2), saved).unwrap();
    ok(&["pipeline", "merge", d.to_str().unwrap()]);
    assert_eq!(job_count(&d), 4);
    assert_eq!(
        json_file(&d.join("manifest.json"))["jobs"]
            .as_object()
            .unwrap()
            .len(),
        4
    );
}

#[test]
fn every_problem_of_a_pipeline_is_reported_with_line_and_column_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let pipeline = dir.path().join("bad.toml");
    std::fs::write(
        &pipeline,
        "[[profile]]\natmosphere = \"missing.csv\"\n[[trace]]\natmosphere = \"us1976\"\nobserver_height_m = \"ten\"\n[[render]]\nscene = \"../nowhere/*.toml\"\nspeed = 3\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    let r = pipeline_run(&pipeline, &out, &[]);
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    for at in ["bad.toml:2:14", "bad.toml:5:21", "bad.toml:8:1"] {
        assert!(r.stderr.contains(at), "{at}: {}", r.stderr);
    }
    for needle in ["missing.csv", "a number or a list", "speed"] {
        assert!(r.stderr.contains(needle), "{needle}: {}", r.stderr);
    }
    assert!(!out.exists(), "nothing ran");
    // A filesystem root is refused as output folder.
    std::fs::write(&pipeline, "[[profile]]\natmosphere = \"us1976\"\n").unwrap();
    for root in ["/", "/tmp/.."] {
        let r = pipeline_run(&pipeline, Path::new(root), &[]);
        assert_eq!(r.code, Some(1), "{}", r.stderr);
        assert!(r.stderr.contains("filesystem root"), "{}", r.stderr);
    }
}

#[test]
fn inputs_are_read_with_a_size_limit() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo.csv");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    let huge = dir.path().join("huge.csv");
    std::fs::File::create(&huge)
        .unwrap()
        .set_len(600 << 20)
        .unwrap(); // sparse
    let mut cases = vec![
        (huge.clone(), "limit"),
        (PathBuf::from("/dev/zero"), "not a regular file"),
    ];
    if made.is_ok_and(|s| s.success()) {
        cases.push((fifo.clone(), "not a regular file"));
    }
    for (input, needle) in &cases {
        let start = Instant::now();
        let r = fails(&[
            "profile",
            input.to_str().unwrap(),
            "--out",
            dir.path().join("o").to_str().unwrap(),
        ]);
        assert!(
            r.stderr.contains(needle),
            "{}: {}",
            input.display(),
            r.stderr
        );
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "{}",
            input.display()
        );
        let r = fails(&["render", input.to_str().unwrap()]);
        assert!(
            r.stderr.contains(needle),
            "{}: {}",
            input.display(),
            r.stderr
        );
        let r = fails(&["pipeline", "run", input.to_str().unwrap(), "--dry-run"]);
        assert!(
            r.stderr.contains(needle),
            "{}: {}",
            input.display(),
            r.stderr
        );
    }
}

#[test]
fn polar_pipeline_runs_every_shipped_sounding() {
    // data/*.csv are byte-identical copies of soundings the polar pipeline runs.
    let csvs = |dir: &Path| -> Vec<PathBuf> {
        let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == "csv"))
            .collect();
        v.sort();
        v
    };
    let tests = soundings_dir();
    let levels = tests.join("pressure_levels");
    let shipped: Vec<Vec<u8>> = csvs(&tests)
        .iter()
        .chain(&csvs(&levels))
        .map(|p| std::fs::read(p).unwrap())
        .collect();
    for copy in csvs(&data_dir()) {
        assert!(
            shipped.contains(&std::fs::read(&copy).unwrap()),
            "{} is not a copy",
            copy.display()
        );
    }
    let r = ok(&[
        "pipeline",
        "run",
        repo_file("pipelines/polar.toml").to_str().unwrap(),
        "--dry-run",
    ]);
    // Every CSV and the IGRA2 excerpt's two complete soundings, each through four jobs.
    let atmospheres = csvs(&tests).len() + csvs(&levels).len() + 2;
    assert!(
        r.stdout.contains(&format!(
            "{} job(s): {} would run",
            4 * atmospheres,
            4 * atmospheres
        )),
        "{}",
        r.stdout
    );
    for p in csvs(&tests).iter().chain(&csvs(&levels)) {
        let stem = p.file_stem().unwrap().to_string_lossy().into_owned();
        for job in [
            stem.clone(),
            format!("{stem}_transfer"),
            format!("ghost_ship_{stem}"),
            format!("compare_{stem}"),
        ] {
            assert!(
                r.stdout.lines().any(|l| l.starts_with(&format!("{job} "))),
                "{job}: {}",
                r.stdout
            );
        }
    }
    // And it runs: every job succeeds (exit 0), each render writes its frame.
    let dir = tempfile::tempdir().unwrap();
    pipeline_ok(
        &repo_file("pipelines/polar.toml"),
        dir.path(),
        &["-j", "2", "-q"],
    );
    let manifest = json_file(&dir.path().join("manifest.json"));
    assert_eq!(manifest["jobs"].as_object().unwrap().len(), 4 * atmospheres);
    for p in csvs(&tests) {
        let stem = p.file_stem().unwrap().to_string_lossy().into_owned();
        let frame = dir.path().join(format!("ghost_ship_{stem}/400x200.png"));
        let img = image::open(&frame).unwrap_or_else(|e| panic!("{}: {e}", frame.display()));
        assert_eq!((img.width(), img.height()), (400, 200));
        // The comparison ran on every real sounding: both sides, both ships, a fit.
        let c = json_file(&dir.path().join(format!("compare_{stem}/compare.json")));
        for side in ["measured", "synthetic"] {
            assert_eq!(c[side]["targets"].as_array().unwrap().len(), 2, "{stem}");
        }
        // A fit in the paper's form (no layers where no inversion is detected) that does at
        // least as well as one straight line.
        assert_eq!(c["fit"]["shape"], "smooth", "{stem}");
        let rms = c["fit"]["rms_k"].as_f64().unwrap();
        assert!(
            rms <= c["fit"]["lapse_only_rms_k"].as_f64().unwrap() + 1e-9,
            "{stem}"
        );
        let ssim = c["image"]["ssim"].as_f64().unwrap();
        assert!(ssim > 0.0 && ssim <= 1.0, "{stem}: {ssim}");
    }
}

#[test]
fn the_example_of_docs_pipeline_md_is_a_valid_pipeline() {
    let doc = std::fs::read_to_string(repo_file("docs/pipeline.md")).unwrap();
    let start = doc.find("```toml\n").expect("an example") + "```toml\n".len();
    let text = &doc[start..start + doc[start..].find("```").unwrap()];
    // Its paths are written relative to pipelines/, like the shipped pipelines.
    let at = repo_file("pipelines").join("example.toml");
    let p = ghostship::pipeline::ResolvedPipeline::from_toml_str(text, &at)
        .unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<&str> = p.jobs.iter().map(|j| j.name.as_str()).collect();
    let soundings = std::fs::read_dir(soundings_dir())
        .unwrap()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "csv"))
        .count();
    // A profile per sounding, 2 atmospheres × 2 heights, 2 scenes × 2 IGRA2 soundings.
    assert_eq!(names.len(), soundings + 4 + 4, "{names:?}");
    for name in [
        "Bjornoya-01028_2024022611_from_10m",
        "superior_mirage_from_50m",
        "fig10_fata_morgana_USM00070026-data_2010-06-01_excerpt_2010060112",
    ] {
        assert!(names.contains(&name), "{name}: {names:?}");
    }
}
