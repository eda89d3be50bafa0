//! Jobs — the library layer behind `profile`, `trace`, `render` and `pipeline run`.
//!
//! In: one typed request per job kind — [`ProfileRequest`], [`TraceJobRequest`],
//! [`RenderRequest`], [`CompareRequest`] — built from command-line flags or from a pipeline file and validated once
//! when it is built. Out: the job's products as named bytes ([`Product`]); nothing here but
//! [`writer`] touches the output folder, and [`manifest`] records what was written.
//!
//! * [`profile`], [`trace`], [`render`], [`sequence`], [`compare`] — request → products, one
//!   module per kind;
//!   [`ensemble`] — the trace job's sensitivity ensemble of a sounding's fit.
//! * [`cache`] — each atmosphere (fitted profile and refractive table) is loaded once per run and
//!   shared by every job that names it.
//! * [`writer`] — atomic writes (temporary file + rename) and removal of dead runs' temp files.
//! * [`manifest`] — `manifest.json`: SHA-256 of every input and output, resolved parameters.
//! * [`run`] — the job loop: skip unchanged jobs, run the rest `-j N` at a time, shards, merge.

pub mod cache;
pub mod compare;
pub mod ensemble;
pub mod manifest;
pub mod profile;
pub mod render;
pub mod run;
pub mod sequence;
pub mod survey;
pub mod trace;
pub mod writer;

use std::sync::Arc;

pub use cache::AtmosphereCache;
pub use compare::CompareRequest;
pub use profile::ProfileRequest;
pub use render::RenderRequest;
pub use sequence::SequenceRequest;
pub use survey::SurveyRequest;
pub use trace::TraceJobRequest;

/// One output of a job: a file name (relative to the job's folder) and its bytes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Product {
    /// File name inside the job's output folder, e.g. `profile.csv`.
    pub name: String,
    /// The file's content.
    pub bytes: Vec<u8>,
}

impl Product {
    /// A product named `name` holding `bytes`.
    pub fn new(name: impl Into<String>, bytes: Vec<u8>) -> Self {
        Product {
            name: name.into(),
            bytes,
        }
    }
}

/// What a job does, with its validated parameters.
#[derive(Debug, Clone)]
pub enum JobRequest {
    /// Layers, n(h) table and plot of one atmosphere.
    Profile(ProfileRequest),
    /// A ray fan and its transfer curves.
    Trace(TraceJobRequest),
    /// A scene rendered at one or more sizes.
    Render(RenderRequest),
    /// A measured sounding against synthetic layers through one scene.
    Compare(Box<CompareRequest>),
    /// Frames of a sweep of the sun or the observer through one scene.
    Sequence(Box<SequenceRequest>),
    /// Every sounding of an archive, one row each.
    Survey(Box<SurveyRequest>),
}

impl JobRequest {
    /// `profile`, `trace`, `render`, `compare`, `sequence` or `survey`.
    pub fn kind(&self) -> &'static str {
        match self {
            JobRequest::Profile(_) => "profile",
            JobRequest::Trace(_) => "trace",
            JobRequest::Render(_) => "render",
            JobRequest::Compare(_) => "compare",
            JobRequest::Sequence(_) => "sequence",
            JobRequest::Survey(_) => "survey",
        }
    }

    /// The atmosphere the job loads (none for straight-ray renders).
    pub fn atmosphere(&self) -> Option<&cache::AtmosphereRequest> {
        match self {
            JobRequest::Profile(r) => Some(&r.atmosphere),
            JobRequest::Trace(r) => Some(&r.atmosphere),
            JobRequest::Render(r) => r.atmosphere.as_ref(),
            JobRequest::Compare(r) => Some(&r.measured),
            JobRequest::Sequence(r) => r.atmosphere(),
            JobRequest::Survey(_) => None,
        }
    }

    /// The files the job reads: atmosphere file, scene file, card images.
    pub fn input_files(&self) -> Vec<std::path::PathBuf> {
        if let JobRequest::Survey(s) = self {
            return s.files().unwrap_or_else(|_| s.sources.clone());
        }
        let mut files: Vec<std::path::PathBuf> = self
            .atmosphere()
            .and_then(|a| a.source.path())
            .map(|p| vec![p.to_path_buf()])
            .unwrap_or_default();
        let render = match self {
            JobRequest::Render(r) => Some(r),
            JobRequest::Compare(c) => {
                let synthetic = c.synthetic.as_ref().and_then(|s| s.source.path());
                files.extend(synthetic.map(|p| p.to_path_buf()));
                Some(&c.render)
            }
            JobRequest::Sequence(s) => {
                let second = s.second_atmosphere();
                files.extend(second.and_then(|a| a.source.path().map(|p| p.to_path_buf())));
                Some(&s.render)
            }
            _ => None,
        };
        if let Some(r) = render {
            files.extend(r.scene.source_path.clone());
            files.extend(r.scene.cards.iter().map(|c| c.image_path.clone()));
        }
        files
    }

    /// The resolved parameters, as the manifest records them.
    pub fn parameters(&self) -> serde_json::Value {
        let value = match self {
            JobRequest::Profile(r) => serde_json::to_value(r),
            JobRequest::Trace(r) => serde_json::to_value(r),
            JobRequest::Render(r) => serde_json::to_value(serde_json::json!({
                "settings": r.settings,
                "atmosphere": r.atmosphere,
                "scene_sha256": r.scene.hash_hex,
            })),
            JobRequest::Sequence(s) => serde_json::to_value(serde_json::json!({
                "settings": s.render.settings,
                "sweep": s.sweep,
                "exr": s.exr,
                "mp4": s.mp4,
                "atmosphere": s.render.atmosphere,
                "second_atmosphere": s.second_atmosphere(),
                "scene_sha256": s.render.scene.hash_hex,
            })),
            // The files themselves are the job's inputs (hashed in the manifest).
            JobRequest::Survey(s) => serde_json::to_value(serde_json::json!({
                "dates": s.dates,
                "options": s.options,
            })),
            JobRequest::Compare(c) => serde_json::to_value(serde_json::json!({
                "settings": c.render.settings,
                "measured": c.measured,
                "synthetic": c.synthetic,
                "rays": c.trace.ray_count(),
                "layers": c.layers,
                "scene_sha256": c.render.scene.hash_hex,
            })),
        };
        value.unwrap_or(serde_json::Value::Null)
    }

    /// The job's products, its atmosphere taken from (or loaded into) `cache`.
    pub fn products(&self, cache: &AtmosphereCache) -> Result<Vec<Product>, JobError> {
        match self {
            JobRequest::Profile(r) => Ok(r.products(&*cache.get(&r.atmosphere)?)?.into_products()),
            JobRequest::Trace(r) => r.products(&*cache.get(&r.atmosphere)?, true),
            JobRequest::Render(r) => r.products(cache),
            JobRequest::Sequence(s) => s.products(cache),
            JobRequest::Survey(s) => s.products(&s.run(&indicatif::ProgressBar::hidden())?),
            JobRequest::Compare(c) => c.products(cache),
        }
    }
}

/// Why a job could not produce its outputs. The message says what failed; the source says where
/// (file, line) and why.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// A request value is out of range.
    #[error("{0}")]
    Invalid(String),
    /// The atmosphere could not be loaded.
    #[error(transparent)]
    Atmosphere(#[from] Arc<crate::atmosphere::AtmosphereError>),
    /// The scene could not be loaded.
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
    /// The trace analysis failed.
    #[error("cannot trace through {atmosphere}")]
    Trace {
        /// The atmosphere traced through.
        atmosphere: String,
        /// Why.
        #[source]
        source: crate::analysis::AnalysisError,
    },
    /// A report or plot could not be made.
    #[error("cannot draw the profile plot of {atmosphere}")]
    Report {
        /// The atmosphere plotted.
        atmosphere: String,
        /// Why.
        #[source]
        source: crate::report::ReportError,
    },
    /// The renderer's tracer could not be prepared.
    #[error("cannot render {scene}")]
    Prepare {
        /// The scene.
        scene: String,
        /// Why.
        #[source]
        source: crate::render::PrepareError,
    },
    /// Rendering failed.
    #[error("cannot render {scene}")]
    Render {
        /// The scene.
        scene: String,
        /// Why.
        #[source]
        source: crate::render::RenderError,
    },
    /// An image could not be encoded.
    #[error(transparent)]
    Film(#[from] crate::output::film::FilmExportError),
    /// A sequence's animated GIF could not be encoded.
    #[error(transparent)]
    Gif(#[from] crate::output::gif::GifError),
    /// A sequence's plot could not be drawn.
    #[error("cannot draw the sequence plot sun.png: {0}")]
    Plot(String),
    /// Measured and synthetic could not be compared (images, figures).
    #[error("cannot compare: {0}")]
    Compare(String),
    /// A survey option is out of range, or its table or plots could not be made.
    #[error(transparent)]
    Survey(#[from] crate::survey::SurveyError),
    /// A file could not be written.
    #[error(transparent)]
    Write(#[from] crate::output::WriteError),
    /// JSON could not be made.
    #[error("cannot serialise JSON")]
    Json(#[from] serde_json::Error),
}

impl From<crate::atmosphere::AtmosphereError> for JobError {
    fn from(e: crate::atmosphere::AtmosphereError) -> Self {
        JobError::Atmosphere(Arc::new(e))
    }
}

/// A SHA-256 as lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}
