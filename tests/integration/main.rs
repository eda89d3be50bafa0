//! One integration-test binary (keeps link time low); each file is a module.
mod ingest;
mod refractivity;
mod tracer;
