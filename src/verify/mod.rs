//! Verification — the accuracy study behind the tracer's tolerance. In: atmospheres (the paper's
//! layered TOMLs, shipped soundings, and the layered stress soundings built here). Out: ray
//! heights at target distances, traced at a range of tolerances and compared with a tight
//! reference run, for the `bench` command and the tests.
//!
//! * [`stress`] — layered stress soundings as CSV text;
//! * [`accuracy`] — time against error: the `bench accuracy` study, `BENCHMARKS.md` and its plot;
//! * [`stress_report`] — the stress suite's launch set, Bouguer drift bound, error against
//!   tolerance: the `bench stress` study, `STRESS.md` and its plot.

pub mod accuracy;
pub mod stress;
pub mod stress_report;
