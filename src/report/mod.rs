//! Outputs of the `profile` command. In: a [`RefractiveAtmosphere`](crate::refractivity::RefractiveAtmosphere)
//! (which carries its air column), the sounding levels, the inversion layers and the refractive
//! regimes. Out: bytes — `profile.csv`, `layers.json` (also the `--format json` summary),
//! `profile.png` — and a readable text summary. Nothing here touches files; the caller writes the
//! bytes with [`crate::output::write_atomic`].

mod csv;
mod layers;
mod plot;

pub use csv::{CSV_HEADER, GridSegment, ProfileGrid, profile_csv};
pub use layers::{
    DuctReport, InputReport, LayersReport, SurfaceReport, Thresholds, layers_json, summary_json,
    summary_text,
};
pub use plot::{PlotOptions, ProfilePlot, profile_png};

/// An output could not be produced.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReportError {
    /// Plot options are unusable (size, height range).
    #[error("invalid plot options: {0}")]
    InvalidOptions(String),
    /// Drawing the plot failed.
    #[error("cannot draw the profile plot: {0}")]
    Plot(String),
    /// Encoding the PNG failed.
    #[error("cannot encode the profile plot as PNG: {0}")]
    Encode(String),
}
