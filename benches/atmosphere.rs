//! Whole-chain cost: building each paper atmosphere (synthetic TOML or fitted sounding → Ciddor
//! n(h); once as construction alone, the table then built lazily, once with the whole table
//! built) and tracing a 400-ray fan (−0.5…+0.5°, observer at 10 m, 1 cm tolerance) through it
//! out to 30 km. Steps per ray and the rejected-step share are printed before each measurement.

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use ghostship::profile::{AirColumn, FitOptions, Profile, SyntheticAtmosphere};
use ghostship::refractivity::RefractiveAtmosphere;
use ghostship::sounding::{ReadOptions, read_sounding};
use ghostship::tracer::{NoHook, RayRecord, Tracer, TracerConfig};

const RAYS: usize = 400;
const OBSERVER_M: f64 = 10.0;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(name)
}

/// The atmospheres: the paper's three scenes and the Novaya Zemlya layer (TOML), and the
/// Bjornoya sounding (fit).
const CASES: [&str; 5] = [
    "superior_mirage.toml",
    "inferior_mirage.toml",
    "fata_morgana.toml",
    "novaya_zemlya.toml",
    "Bjornoya-01028_2024022611.csv",
];

fn column(name: &str) -> Arc<dyn AirColumn> {
    let path = data(name);
    if name.ends_with(".toml") {
        Arc::new(SyntheticAtmosphere::from_file(&path).expect("paper atmosphere"))
    } else {
        let s = read_sounding(&path, &ReadOptions::default()).expect("sounding");
        Arc::new(Profile::from_sounding(&s, &FitOptions::default()).expect("fit"))
    }
}

fn build(name: &str) -> RefractiveAtmosphere {
    RefractiveAtmosphere::new(column(name), 550.0).expect("refractive atmosphere")
}

fn fan() -> Vec<f64> {
    (0..RAYS)
        .map(|i| (-0.5 + i as f64 / (RAYS - 1) as f64).to_radians())
        .collect()
}

fn trace_fan(
    tracer: &Tracer<'_, RefractiveAtmosphere>,
    fan: &[f64],
    record: &mut RayRecord,
) -> (u64, u64) {
    let (mut steps, mut rejected) = (0u64, 0u64);
    for &a in fan {
        tracer
            .trace_into(OBSERVER_M, a, &[30_000.0], &mut NoHook, record, None)
            .expect("valid ray");
        steps += record.steps() as u64;
        rejected += record.rejected_steps as u64;
    }
    (steps, rejected)
}

fn bench_build(c: &mut Criterion) {
    // Construction alone (the table is then built lazily, where lookups land), and construction
    // with the whole table built (what a trace through every height, or `profile`'s table
    // report, pays).
    type Run = fn(&str);
    let cases: [(&str, Run); 2] = [
        ("atmosphere_build", |name| {
            black_box(build(name));
        }),
        ("atmosphere_build_whole_table", |name| {
            black_box(build(name).table_max_error());
        }),
    ];
    for (group_name, run) in cases {
        let mut group = c.benchmark_group(group_name);
        group
            .sample_size(10)
            .measurement_time(Duration::from_secs(3));
        for name in CASES {
            group.bench_with_input(BenchmarkId::from_parameter(name), name, |b, name| {
                b.iter(|| run(name))
            });
        }
        group.finish();
    }
}

fn bench_fan(c: &mut Criterion) {
    let fan = fan();
    let mut group = c.benchmark_group("fan_400_rays_30km");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(5));
    group.throughput(Throughput::Elements(RAYS as u64));
    for name in CASES {
        let atm = build(name);
        let tracer = Tracer::new(&atm, TracerConfig::default()).expect("valid config");
        let mut record = RayRecord::default();
        let (steps, rejected) = trace_fan(&tracer, &fan, &mut record);
        println!(
            "{name}: {:.1} steps/ray, {:.1} % rejected, {} exact table cells",
            steps as f64 / RAYS as f64,
            100.0 * rejected as f64 / steps as f64,
            atm.table_max_error().exact_cells()
        );
        group.bench_function(BenchmarkId::from_parameter(name), |b| {
            b.iter(|| black_box(trace_fan(&tracer, &fan, &mut record)))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_build, bench_fan);
criterion_main!(benches);
