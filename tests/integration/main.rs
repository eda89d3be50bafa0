//! One integration-test binary (keeps link time low); each file is a module.
mod end_to_end;
mod ingest;
mod profile;
mod refractivity;
mod tracer;
