//! The time-against-error study (`ghostship::verify::accuracy`): on the paper's superior mirage
//! the error at 26 km against the tight self-reference falls as the tolerance is tightened.

use ghostship::verify::accuracy::{AccuracyConfig, BenchCase, measure_case};

use crate::support::data::data_file;

/// Max |Δh| over the fan at 26 km (near-fold rays excluded), for tolerances 1 m … 1e-4 m, must
/// not grow by more than a factor 1.5 (noise: each tolerance takes a different step sequence)
/// from one tolerance to the next ten times tighter, and must end smaller than it started.
#[test]
fn superior_mirage_error_shrinks_with_the_tolerance() {
    let config = AccuracyConfig {
        tolerances_m: vec![1.0, 0.1, 0.01, 1e-3, 1e-4],
        repetitions: 1,
        ..AccuracyConfig::full()
    };
    let case = BenchCase {
        name: "superior_mirage".into(),
        kind: "paper",
        source: ghostship::atmosphere::AtmosphereSource::Synthetic(data_file(
            "superior_mirage.toml",
        )),
        options: Default::default(),
        observer_height_m: 20.0,
    };
    let result = measure_case(&case, &config, &mut || {}).unwrap();
    let errs: Vec<f64> = result
        .rows
        .iter()
        .map(|r| {
            let e = r.errors.last().unwrap();
            assert_eq!(e.distance_m, 26_000.0);
            assert!(e.compared > 50, "{e:?}");
            e.max_m.unwrap()
        })
        .collect();
    for (w, t) in errs.windows(2).zip(&config.tolerances_m[1..]) {
        assert!(w[1] <= 1.5 * w[0], "tolerance {t} m: {errs:?}");
    }
    assert!(errs[errs.len() - 1] < errs[0], "{errs:?}");
}
