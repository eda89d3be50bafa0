//! Shared test support: helpers every integration-test module uses instead of its own copy.
//!
//! * [`cli`] — running the `ghostship` binary and checking its exit status.
//! * [`data`] — paths of the repository's test inputs (shipped soundings, fixtures, scenes).
//! * [`reference`] — an independent ray tracer (not the code under test) for accuracy checks.
//! * [`fans`] — fitted stress soundings, fold slopes and reference heights with error estimates
//!   for fans of rays checked against [`reference`].
#![allow(dead_code)] // each test module uses a different subset

pub mod cli;
pub mod data;
pub mod fans;
pub mod reference;
