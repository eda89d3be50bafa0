//! ghostship — from measured radiosonde soundings to physically accurate images of what an
//! observer sees through a layered atmosphere: superior and inferior mirages, Fata Morgana, the
//! distorted horizon and the Novaya Zemlya sun.
//!
//! The stages, each a module with one input and one output type:
//!
//! ```text
//! sounding file ─ingest→ Sounding ─fit→ Profile ─refract→ refractive atmosphere (n, dn/dh)
//!                                                              │
//! scene file ─parse→ Scene ────────────────────────────────────┤
//!                                                              ▼
//!                                        tracer → paths, transfer curves → renderer → EXR/PNG
//!
//! pipeline file ─resolve→ planned jobs ─jobs→ products (named bytes) → files + manifest.json
//! ```
//!
//! [`jobs`] is the layer the commands and pipelines share: one typed request per job kind, its
//! products as bytes, one writer, the manifest; [`pipeline`] expands and validates pipeline
//! files into those requests; [`input`] reads every input file with a size limit.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod analysis;
pub mod atmosphere;
pub mod compare;
pub mod input;
pub mod jobs;
pub mod output;
pub mod pipeline;
pub mod profile;
pub mod refractivity;
pub mod render;
pub mod report;
pub mod scene;
pub mod solar;
pub mod sounding;
pub mod survey;
pub mod tracer;
pub mod units;
pub mod verify;
