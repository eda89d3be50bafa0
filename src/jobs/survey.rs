//! Jobs — survey. In: a [`SurveyRequest`] (sounding sources, a date range, the survey options).
//! Out: the rows ([`SurveyRow`]) and the products `survey.csv`, `survey.parquet` (one row per
//! sounding, the same columns), `survey.json` (options, the standard-atmosphere reference, counts
//! of soundings and phenomena), and the plots `monthly.png`, `ducts.png`, `dip.png`.

use std::path::PathBuf;

use serde::Serialize;

use super::{JobError, Product};
use crate::sounding::ReadOptions;
use crate::survey::sources::{DateRange, expand_files};
use crate::survey::{
    Reference, SurveyError, SurveyOptions, SurveyRow, expand_sources, plot, survey, table,
};

/// A validated survey request.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SurveyRequest {
    /// The sounding files, folders and glob patterns, as named.
    pub sources: Vec<PathBuf>,
    /// Which nominal dates to keep.
    pub dates: DateRange,
    /// How each sounding is looked at.
    pub options: SurveyOptions,
    /// Rows name their files relative to this folder (a pipeline's), or as given when `None`.
    #[serde(skip)]
    pub label_base: Option<PathBuf>,
}

/// What [`SurveyRequest::run`] found, before it becomes files.
pub struct SurveyOutcome {
    /// One row per sounding, in source order.
    pub rows: Vec<SurveyRow>,
    /// The standard atmosphere's dip and lowest sun per observer height.
    pub reference: Reference,
}

/// Counts in `survey.json`.
#[derive(Debug, Serialize)]
struct Summary<'a> {
    sources: Vec<String>,
    dates: &'a DateRange,
    options: &'a SurveyOptions,
    reference: &'a Reference,
    soundings: usize,
    usable: usize,
    unusable: Vec<(&'a str, &'a str)>,
    with_inversion: usize,
    with_duct: usize,
    with_surface_duct: usize,
    columns: Vec<String>,
}

impl SurveyRequest {
    /// Check the request (options, dates, at least one source) before any file is read.
    pub fn new(
        sources: Vec<PathBuf>,
        dates: DateRange,
        options: SurveyOptions,
    ) -> Result<Self, JobError> {
        if sources.is_empty() {
            return Err(JobError::Invalid(
                "give at least one sounding source".into(),
            ));
        }
        options.validate()?;
        dates.validate()?;
        Ok(SurveyRequest {
            sources,
            dates,
            options,
            label_base: None,
        })
    }

    /// The same request, its rows naming files relative to `folder`.
    pub fn with_label_base(self, folder: &std::path::Path) -> Self {
        SurveyRequest {
            label_base: Some(folder.to_path_buf()),
            ..self
        }
    }

    /// How rows and `survey.json` name `path`.
    pub fn label(&self, path: &std::path::Path) -> String {
        match &self.label_base {
            Some(base) => crate::input::relative_label(path, base),
            None => path.display().to_string(),
        }
    }

    /// The files the sources name (folders and patterns expanded, sorted).
    pub fn files(&self) -> Result<Vec<PathBuf>, JobError> {
        Ok(expand_files(&self.sources)?)
    }

    /// Read every sounding and survey it; `progress` is set to the number of soundings and
    /// advanced once per sounding.
    pub fn run(&self, progress: &indicatif::ProgressBar) -> Result<SurveyOutcome, JobError> {
        let files = self.files()?;
        let read = ReadOptions::default().strict(self.options.atmosphere.strict);
        let labels: Vec<String> = files.iter().map(|f| self.label(f)).collect();
        let items = expand_sources(&files, &labels, &self.dates, &read);
        progress.set_length(items.len() as u64);
        let reference = Reference::standard(&self.options)?;
        let mut rows = survey(items, &self.options, &reference, progress);
        if self.label_base.is_some() {
            // Reasons name the file as it was opened: name it as the rows do.
            let shown: std::collections::HashMap<&str, String> = labels
                .iter()
                .zip(&files)
                .map(|(l, f)| (l.as_str(), f.display().to_string()))
                .collect();
            for row in &mut rows {
                let file = row.origin.rsplit_once(':').map_or(&*row.origin, |(f, _)| f);
                let opened = shown.get(file).or_else(|| shown.get(row.origin.as_str()));
                if let (Some(opened), Some(reason)) = (opened, row.unusable.as_mut()) {
                    let label = file.to_string();
                    *reason = reason.replace(opened.as_str(), &label);
                }
            }
        }
        Ok(SurveyOutcome { rows, reference })
    }

    /// The products of `outcome`.
    pub fn products(&self, outcome: &SurveyOutcome) -> Result<Vec<Product>, JobError> {
        let rows = &outcome.rows;
        let columns = table::columns(&self.options);
        let plot_err = |name: &str| {
            let name = name.to_string();
            move |message| JobError::from(SurveyError::Plot { name, message })
        };
        let files = self.files()?;
        let summary = Summary {
            sources: files.iter().map(|f| self.label(f)).collect(),
            dates: &self.dates,
            options: &self.options,
            reference: &outcome.reference,
            soundings: rows.len(),
            usable: rows.iter().filter(|r| r.unusable.is_none()).count(),
            unusable: rows
                .iter()
                .filter_map(|r| Some((r.origin.as_str(), r.unusable.as_deref()?)))
                .collect(),
            with_inversion: rows.iter().filter(|r| r.layers.inversion_count > 0).count(),
            with_duct: rows.iter().filter(|r| r.layers.duct_count > 0).count(),
            with_surface_duct: rows.iter().filter(|r| r.layers.surface_duct).count(),
            columns: columns.iter().map(|c| c.name.clone()).collect(),
        };
        let mut json = serde_json::to_vec_pretty(&summary)?;
        json.push(b'\n');
        Ok(vec![
            Product::new("survey.csv", table::to_csv(rows, &columns)?),
            Product::new("survey.parquet", table::to_parquet(rows, &columns)?),
            Product::new("survey.json", json),
            Product::new(
                "monthly.png",
                plot::monthly_png(rows, &self.options).map_err(plot_err("monthly.png"))?,
            ),
            Product::new(
                "ducts.png",
                plot::ducts_png(rows).map_err(plot_err("ducts.png"))?,
            ),
            Product::new(
                "dip.png",
                plot::dip_png(rows, &self.options).map_err(plot_err("dip.png"))?,
            ),
        ])
    }
}
