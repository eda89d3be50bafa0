//! Survey rate: soundings per second of `ghostship survey`'s work (read, fit, layer detectors,
//! one fan per observer height, rows), on a 200-sounding IGRA2 record built from the two complete
//! Utqiagvik soundings of the shipped IGRA2 sample (dated 1901–2000), with the default options
//! (one observer, one distance) and with two observers × three distances; and on one dense
//! (1-s, ~5000-level) Bjørnøya sounding. The thread count is rayon's (all cores unless
//! RAYON_NUM_THREADS says otherwise). Throughput is in soundings.
//!
//! `GHOSTSHIP_BENCH_ARCHIVE=N` (e.g. 30000) first times whole survey runs of an N-sounding
//! record built the same way (the two soundings repeated, years 1901 on), the archive size
//! the survey issue aims at, and prints the median of three runs, soundings per second and ms
//! per sounding; criterion's groups follow.

use std::path::{Path, PathBuf};
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use ghostship::jobs::SurveyRequest;
use ghostship::survey::SurveyOptions;
use ghostship::survey::sources::DateRange;

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The two complete soundings of the IGRA2 sample, each copied once per year 1901–2000.
fn igra2_record(dir: &Path) -> (PathBuf, u64) {
    igra2_record_of(dir, 200)
}

/// `count` soundings (rounded down to even): the two complete soundings of the IGRA2 sample,
/// copied once per day: the first 200 once per year 1901–2000 on their own day (what the
/// criterion groups use), beyond that on day 1–28 of each month from 2001 on.
fn igra2_record_of(dir: &Path, count: u64) -> (PathBuf, u64) {
    let text = std::fs::read_to_string(repo(
        "tests/data/soundings/public/igra2_USM00070026-data.txt",
    ))
    .expect("IGRA2 sample");
    let mut blocks: Vec<Vec<&str>> = Vec::new();
    for line in text.lines() {
        if line.starts_with('#') {
            blocks.push(Vec::new());
        }
        blocks.last_mut().expect("a header first").push(line);
    }
    let mut out = String::new();
    for pair in 0..count / 2 {
        for block in &blocks[..2] {
            let header = block[0];
            if pair < 100 {
                let year = 1901 + pair;
                out.push_str(&format!("{}{year}{}\n", &header[..13], &header[17..]));
            } else {
                let k = pair - 100;
                let (year, month, day) = (2001 + k / 336, 1 + (k / 28) % 12, 1 + k % 28);
                let date = format!("{year} {month:02} {day:02}");
                out.push_str(&format!("{}{date}{}\n", &header[..13], &header[23..]));
            }
            for line in &block[1..] {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    let path = dir.join("USM00070026-data.txt");
    std::fs::write(&path, out).expect("write the record");
    (path, count / 2 * 2)
}

/// With `GHOSTSHIP_BENCH_ARCHIVE=N`: the median of three whole survey runs of an N-sounding
/// record (default options), printed.
fn archive_run() {
    let Some(count) = std::env::var("GHOSTSHIP_BENCH_ARCHIVE")
        .ok()
        .and_then(|v| v.parse::<u64>().ok())
    else {
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let (record, count) = igra2_record_of(dir.path(), count.max(2));
    let r = request(&record, SurveyOptions::default());
    let hidden = indicatif::ProgressBar::hidden();
    let mut seconds: Vec<f64> = (0..3)
        .map(|_| {
            let start = std::time::Instant::now();
            let rows = r.run(&hidden).expect("survey").rows;
            assert_eq!(rows.len() as u64, count);
            start.elapsed().as_secs_f64()
        })
        .collect();
    seconds.sort_by(f64::total_cmp);
    let median = seconds[1];
    println!(
        "survey archive: {count} soundings, {} threads, median of 3 runs {median:.1} s \
         (runs {:.1} / {:.1} / {:.1} s): {:.0} soundings/s, {:.2} ms per sounding",
        rayon::current_num_threads(),
        seconds[0],
        seconds[1],
        seconds[2],
        count as f64 / median,
        1e3 * median / count as f64
    );
}

fn request(file: &Path, options: SurveyOptions) -> SurveyRequest {
    SurveyRequest::new(vec![file.to_path_buf()], DateRange::default(), options).expect("request")
}

fn bench_survey(c: &mut Criterion) {
    archive_run();
    let dir = tempfile::tempdir().expect("temp dir");
    let (record, count) = igra2_record(dir.path());
    let wide = SurveyOptions {
        observer_heights_m: vec![10.0, 50.0],
        distances_m: vec![10_000.0, 20_000.0, 40_000.0],
        ..SurveyOptions::default()
    };
    let hidden = indicatif::ProgressBar::hidden();
    let mut group = c.benchmark_group("survey");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(20));
    group.throughput(Throughput::Elements(count));
    for (name, options) in [
        ("igra2_200_default", SurveyOptions::default()),
        ("igra2_200_2x3", wide),
    ] {
        let r = request(&record, options);
        let rows = r.run(&hidden).expect("survey").rows;
        assert!(rows.iter().all(|row| row.unusable.is_none()), "{name}");
        group.bench_function(name, |b| b.iter(|| r.run(&hidden).expect("survey")));
    }
    group.throughput(Throughput::Elements(1));
    let dense = request(
        &repo("data/Bjornoya-01028_2024022611.csv"),
        SurveyOptions::default(),
    );
    group.bench_function("dense_bjornoya_default", |b| {
        b.iter(|| dense.run(&hidden).expect("survey"))
    });
    group.finish();
}

criterion_group!(benches, bench_survey);
criterion_main!(benches);
