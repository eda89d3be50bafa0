//! Survey rate: soundings per second of `ghostship survey`'s work (read, fit, layer detectors,
//! one fan per observer height, rows), on a 200-sounding IGRA2 record built from the two complete
//! Utqiagvik soundings of the shipped IGRA2 sample (dated 1901–2000), with the default options
//! (one observer, one distance) and with two observers × three distances; and on one dense
//! (1-s, ~5000-level) Bjørnøya sounding. The thread count is rayon's (all cores unless
//! RAYON_NUM_THREADS says otherwise). Throughput is in soundings.

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
    for year in 1901..=2000 {
        for block in &blocks[..2] {
            out.push_str(&format!("{}{year}{}\n", &block[0][..13], &block[0][17..]));
            for line in &block[1..] {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    let path = dir.join("USM00070026-data.txt");
    std::fs::write(&path, out).expect("write the record");
    (path, 200)
}

fn request(file: &Path, options: SurveyOptions) -> SurveyRequest {
    SurveyRequest::new(vec![file.to_path_buf()], DateRange::default(), options).expect("request")
}

fn bench_survey(c: &mut Criterion) {
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
