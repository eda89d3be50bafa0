//! Verification — the accuracy study behind the tracer's tolerance. In: atmospheres (the paper's
//! layered TOMLs, shipped soundings, and the layered stress soundings built here) and the paper
//! scenes. Out: ray heights at target distances and image boundaries, traced at a range of
//! tolerances and compared with a tight reference run; frames of the paper scenes timed on every
//! render path and compared with tight reference renders; for the `bench` command and the tests.
//!
//! * [`stress`] — layered stress soundings as CSV text;
//! * [`accuracy`] — time against error: the `bench accuracy` study, `BENCHMARKS.md` and its plot;
//! * [`image_bounds`] — the apparent elevations of image boundaries against a reference run;
//! * [`frames`] — time per frame of the render paths and image error against the tolerance;
//! * [`frames_report`] — their tables and plot;
//! * [`benchmarks`] — the whole `BENCHMARKS.md`;
//! * [`effects`] — scenes with terrain, haze or the sun taken out, for the effects bench;
//! * [`stats`] — median and 95th percentile.
//! * [`stress_report`] — the stress suite's launch set, Bouguer drift bound, error against
//!   tolerance: the `bench stress` study, `STRESS.md` and its plot.

pub mod accuracy;
pub mod benchmarks;
pub mod effects;
pub mod frames;
pub mod frames_report;
pub mod image_bounds;
pub mod stats;
pub mod stress;
pub mod stress_report;
