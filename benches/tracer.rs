//! Tracer throughput: rays per second and steps per ray against tolerance, for a fan of 64 rays
//! from a 5 m observer through a sharp elevated inversion (8 K over ≈ 2 m at 10 m, tanh-smoothed,
//! over a standard gradient) out to 30 km. Steps per ray are printed before each measurement.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use ghostship::tracer::{NoHook, RayRecord, StratifiedIndex, Tracer, TracerConfig};

struct SharpInversion;

impl StratifiedIndex for SharpInversion {
    fn index_and_derivative(&self, h: f64) -> (f64, f64) {
        // n − 1 ≈ 2.9e-4 at the ground; an 8 K step ≈ 8e-6 in n over a 1 m half-width.
        let (dn, hc, w) = (8e-6, 10.0, 1.0);
        let t = ((h - hc) / w).tanh();
        let n = 1.000_29 - 2.3e-8 * h - dn * 0.5 * (1.0 + t);
        let dndh = -2.3e-8 - dn * 0.5 * (1.0 - t * t) / w;
        (n, dndh)
    }
}

const RAYS: usize = 64;

fn fan() -> Vec<f64> {
    (0..RAYS)
        .map(|i| (-0.15 + 0.5 * i as f64 / (RAYS - 1) as f64).to_radians())
        .collect()
}

fn trace_fan(tracer: &Tracer<'_, SharpInversion>, fan: &[f64], record: &mut RayRecord) -> u64 {
    let mut steps = 0u64;
    for &a in fan {
        tracer
            .trace_into(
                5.0,
                a,
                &[10_000.0, 20_000.0, 30_000.0],
                &mut NoHook,
                record,
                None,
            )
            .expect("valid ray");
        steps += record.steps() as u64;
    }
    steps
}

fn bench_tolerance(c: &mut Criterion) {
    let fan = fan();
    let mut group = c.benchmark_group("fan_30km_sharp_inversion");
    group.throughput(Throughput::Elements(RAYS as u64));
    for tolerance_m in [1e-3, 1e-2, 1e-1, 1.0] {
        let config = TracerConfig {
            tolerance_m,
            ..TracerConfig::default()
        };
        let tracer = Tracer::new(&SharpInversion, config).expect("valid config");
        let mut record = RayRecord::default();
        let steps = trace_fan(&tracer, &fan, &mut record);
        println!(
            "tolerance {tolerance_m} m: {:.1} steps per ray",
            steps as f64 / RAYS as f64
        );
        group.bench_with_input(
            BenchmarkId::new("tolerance_m", tolerance_m),
            &tolerance_m,
            |b, _| b.iter(|| black_box(trace_fan(&tracer, black_box(&fan), &mut record))),
        );
    }
    group.finish();
}

criterion_group!(benches, bench_tolerance);
criterion_main!(benches);
