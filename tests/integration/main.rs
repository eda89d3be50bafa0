//! One integration-test binary (keeps link time low); each file is a module.
mod support;

mod accuracy;
mod aerial;
mod bench_accuracy;
mod cli;
mod compare;
mod docs;
mod end_to_end;
mod fit;
mod images;
mod ingest;
mod ingest_archives;
mod ingest_esc;
mod ingest_netcdf;
mod ingest_temp;
mod layer_fit;
mod pipeline;
mod profile;
mod readme;
mod reference_tracer;
mod refractivity;
mod render;
mod scenes;
mod stress;
mod terrain;
mod tracer;
