//! Shared test support: helpers every integration-test module uses instead of its own copy.
//!
//! * [`data`] — paths of the repository's test inputs (shipped soundings, fixtures, scenes).
//! * [`reference`] — an independent ray tracer (not the code under test) for accuracy checks.
#![allow(dead_code)] // each test module uses a different subset

pub mod data;
pub mod reference;
