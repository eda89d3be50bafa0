//! Stage 5 — analysis. In: a stratified refractive atmosphere (`&dyn StratifiedIndex`), an
//! observer height, a fan of apparent elevations and target distances/heights. Out: transfer
//! characteristics h(D; α), every image of each target (erect or inverted, magnification), the
//! apparent horizon, trapped rays, and the `trace` command's report (JSON, CSV, PNG plot).
//!
//! * [`transfer`] — the curve h(D; α) sampled on a fan, image bands and horizons, each refined on
//!   the tracer itself (bisection for level crossings, golden section for extrema).
//! * [`report`] — [`TraceRequest`] → [`TraceReport`] (serialisable), its CSV forms.
//! * [`plot`] — the ray fan and the transfer curves as one PNG.

pub mod plot;
pub mod report;
pub mod transfer;

pub use plot::trace_plot_png;
pub use report::{
    MAX_FAN_RAYS, MIN_ANALYSIS_RAYS, RayReport, TraceReport, TraceRequest, trace_report,
};
pub use transfer::{
    FoldTest, Image, Reach, TransferCurve, apparent_horizon, find_images, find_images_with,
};

/// Why an analysis could not be done.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    /// The tracer rejected its input.
    #[error(transparent)]
    Tracer(#[from] crate::tracer::TracerError),
    /// A request field is out of range.
    #[error("invalid trace request: {0}")]
    InvalidRequest(String),
    /// Writing CSV failed.
    #[error("cannot write CSV: {0}")]
    Csv(#[from] csv::Error),
    /// Drawing or encoding the plot failed.
    #[error("cannot draw plot: {0}")]
    Plot(String),
}
