//! Jobs — survey. In: a [`SurveyRequest`] (sounding sources, a date range, the survey options).
//! Out: the rows ([`SurveyRow`]) and the products `survey.csv`, `survey.parquet` (one row per
//! sounding, the same columns), `survey.json` (options, the input files' sizes and SHA-256, the
//! standard-atmosphere reference, counts of soundings and phenomena), and the plots
//! `monthly.png`, `ducts.png`, `dip.png`.
//!
//! A survey can be split: [`SurveyRequest::with_shard`] surveys the K-th of N contiguous runs of
//! the soundings (all files are read to number them) and adds `part.json` (its rows, exactly,
//! with the program, the request and every input file's size and SHA-256); [`merge_parts`]
//! joins the N parts' `part.json` into the products one unsplit run writes, byte for byte, and
//! refuses parts that do not belong to one survey of the same inputs. [`join_split_surveys`]
//! does that for a pipeline's `<name>_part_K_of_N` jobs and records the joined files in its
//! manifest.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::manifest::{JobStatus, JoinedRecord, Manifest, Shard};
use super::run::PlannedJob;
use super::{JobError, Product};
use crate::sounding::ReadOptions;
use crate::survey::sources::{DateRange, InputFile, expand_files};
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
    /// Which contiguous part of the soundings to survey (`None`: all of them).
    pub shard: Option<Shard>,
}

/// What [`SurveyRequest::run`] found, before it becomes files.
pub struct SurveyOutcome {
    /// How the rows name the source files, in order.
    pub sources: Vec<String>,
    /// Every source file's size and SHA-256, in the same order.
    pub inputs: Vec<InputFile>,
    /// One row per sounding, in source order.
    pub rows: Vec<SurveyRow>,
    /// The standard atmosphere's dip and lowest sun per observer height.
    pub reference: Reference,
    /// The part surveyed and the number of soundings of the whole survey, for a split one.
    pub shard: Option<(Shard, usize)>,
}

/// `part.json`: one part of a split survey, with everything [`merge_parts`] needs, and what
/// it needs to tell whether parts belong together (program, request, inputs).
#[derive(Debug, Serialize, Deserialize)]
struct Part {
    format: String,
    program: String,
    shard: Shard,
    total_soundings: usize,
    sources: Vec<String>,
    inputs: Vec<InputFile>,
    dates: DateRange,
    options: SurveyOptions,
    rows: Vec<SurveyRow>,
}

/// The `format` of `part.json`.
const PART_FORMAT: &str = "ghostship-survey-part-2";

/// Every file a survey writes into its folder: a folder holds those of one run only (a file of
/// an earlier run that this one does not write, such as an old `part.json`, is deleted).
pub const SURVEY_FILES: &[&str] = &[
    "survey.csv",
    "survey.parquet",
    "survey.json",
    "monthly.png",
    "ducts.png",
    "dip.png",
    "part.json",
];

/// Counts in `survey.json`.
#[derive(Debug, Serialize)]
struct Summary<'a> {
    sources: Vec<String>,
    inputs: &'a [InputFile],
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
            shard: None,
        })
    }

    /// The same request surveying only the `shard.index`-th of `shard.count` contiguous runs of
    /// its soundings.
    pub fn with_shard(self, shard: Shard) -> Self {
        SurveyRequest {
            shard: Some(shard),
            ..self
        }
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

    /// Read every sounding and survey it (only the shard's part of them, for a shard);
    /// `progress` is set to the number of soundings surveyed and advanced once per sounding.
    pub fn run(&self, progress: &indicatif::ProgressBar) -> Result<SurveyOutcome, JobError> {
        let files = self.files()?;
        let read = ReadOptions::default().strict(self.options.atmosphere.strict);
        let labels: Vec<String> = files.iter().map(|f| self.label(f)).collect();
        let (mut items, inputs) = expand_sources(&files, &labels, &self.dates, &read);
        let total = items.len();
        if let Some(shard) = self.shard {
            let at = |k: usize| (total as u128 * k as u128 / shard.count as u128) as usize;
            items.truncate(at(shard.index));
            items.drain(..at(shard.index - 1));
        }
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
                // The origin is the file's label, or the label and `:LINE` in a record.
                let whole = row.origin.as_str();
                let stem = whole.rsplit_once(':').map(|(f, _)| f);
                let matched = shown
                    .get_key_value(whole)
                    .or_else(|| stem.and_then(|f| shown.get_key_value(f)));
                if let (Some((label, opened)), Some(reason)) = (matched, row.unusable.as_mut()) {
                    *reason = reason.replace(opened.as_str(), label);
                }
            }
        }
        Ok(SurveyOutcome {
            sources: labels,
            inputs,
            rows,
            reference,
            shard: self.shard.map(|s| (s, total)),
        })
    }

    /// The products of `outcome` (with `part.json` for a part of a split survey).
    pub fn products(&self, outcome: &SurveyOutcome) -> Result<Vec<Product>, JobError> {
        let mut products = products(&self.dates, &self.options, outcome)?;
        if let Some((shard, total_soundings)) = outcome.shard {
            let part = Part {
                format: PART_FORMAT.into(),
                program: super::run::program(),
                shard,
                total_soundings,
                sources: outcome.sources.clone(),
                inputs: outcome.inputs.clone(),
                dates: self.dates.clone(),
                options: self.options.clone(),
                rows: outcome.rows.clone(),
            };
            products.push(Product::new("part.json", serde_json::to_vec(&part)?));
        }
        Ok(products)
    }
}

/// The products of a survey's rows.
fn products(
    dates: &DateRange,
    options: &SurveyOptions,
    outcome: &SurveyOutcome,
) -> Result<Vec<Product>, JobError> {
    let rows = &outcome.rows;
    let columns = table::columns(options);
    let plot_err = |name: &str| {
        let name = name.to_string();
        move |message| JobError::from(SurveyError::Plot { name, message })
    };
    let summary = Summary {
        sources: outcome.sources.clone(),
        inputs: &outcome.inputs,
        dates,
        options,
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
            plot::monthly_png(rows, options).map_err(plot_err("monthly.png"))?,
        ),
        Product::new(
            "ducts.png",
            plot::ducts_png(rows).map_err(plot_err("ducts.png"))?,
        ),
        Product::new(
            "dip.png",
            plot::dip_png(rows, options).map_err(plot_err("dip.png"))?,
        ),
    ])
}

/// Join the parts of a split survey (the folders holding each part's `part.json`, in any order)
/// into the products one unsplit run writes. Every part must be there once, of one survey:
/// written by this program version, of the same sources with the same sizes and SHA-256, dates,
/// options and number of parts, with the rows its share calls for; otherwise the error names
/// the folders and what differs.
pub fn merge_parts(dirs: &[PathBuf]) -> Result<Vec<Product>, JobError> {
    let bad = |m: String| Err(JobError::from(SurveyError::Merge(m)));
    let mut parts = Vec::new();
    for dir in dirs {
        parts.push((dir, read_part(dir)?));
    }
    parts.sort_by_key(|(_, p)| p.shard.index);
    let Some((first_dir, first)) = parts.first() else {
        return bad("no parts given".into());
    };
    let count = first.shard.count;
    for (k, (dir, part)) in parts.iter().enumerate() {
        let differences = differences(first, part);
        if !differences.is_empty() {
            return bad(format!(
                "{} and {} are parts of different surveys: {}",
                first_dir.display(),
                dir.display(),
                differences.join("; ")
            ));
        }
        if part.shard.index == k {
            return bad(format!(
                "part {k}/{count} is given twice ({} and {})",
                parts[k - 1].0.display(),
                dir.display()
            ));
        }
        if part.shard.index != k + 1 {
            return bad(format!("part {}/{count} is missing", k + 1));
        }
        let total = part.total_soundings as u128;
        let at = |k: usize| (total * k as u128 / count as u128) as usize;
        let expected = at(part.shard.index) - at(part.shard.index - 1);
        if part.rows.len() != expected {
            return bad(format!(
                "{}: {} rows, its share of {total} soundings is {expected}",
                dir.join("part.json").display(),
                part.rows.len()
            ));
        }
    }
    if parts.len() > count {
        return bad(format!(
            "{} parts given for a survey split in {count}",
            parts.len()
        ));
    }
    if parts.len() < count {
        return bad(format!("part {}/{count} is missing", parts.len() + 1));
    }
    let (_, first) = &parts[0];
    let (dates, options, sources, inputs) = (
        first.dates.clone(),
        first.options.clone(),
        first.sources.clone(),
        first.inputs.clone(),
    );
    let rows: Vec<SurveyRow> = parts.into_iter().flat_map(|(_, p)| p.rows).collect();
    let outcome = SurveyOutcome {
        sources,
        inputs,
        rows,
        reference: Reference::standard(&options)?,
        shard: None,
    };
    products(&dates, &options, &outcome)
}

/// The `part.json` in `dir`, checked for its format and a shard K/N with 1 ≤ K ≤ N.
fn read_part(dir: &Path) -> Result<Part, JobError> {
    let path = dir.join("part.json");
    let bad = |m: String| JobError::from(SurveyError::Merge(format!("{}: {m}", path.display())));
    let bytes = crate::input::read_limited(&path, crate::input::MAX_SOUNDING_BYTES)
        .map_err(|e| bad(format!("{e} (is {} a survey part?)", dir.display())))?;
    // The format first: an older part.json lacks fields this one needs.
    let format = serde_json::from_slice::<serde_json::Value>(&bytes)
        .ok()
        .and_then(|v| v.get("format")?.as_str().map(String::from));
    if format.as_deref() != Some(PART_FORMAT) {
        return Err(bad(format!(
            "format {format:?}, expected {PART_FORMAT:?} (survey the part again with this program)"
        )));
    }
    let part: Part = serde_json::from_slice(&bytes).map_err(|e| bad(e.to_string()))?;
    let s = part.shard;
    if s.count == 0 || s.index == 0 || s.index > s.count {
        return Err(bad(format!(
            "part {}/{} is not K/N with 1 ≤ K ≤ N",
            s.index, s.count
        )));
    }
    Ok(part)
}

/// What makes `b` a part of another survey than `a` (empty when they belong together).
fn differences(a: &Part, b: &Part) -> Vec<String> {
    let mut found = Vec::new();
    if a.program != b.program {
        found.push(format!("written by {} and by {}", a.program, b.program));
    }
    if a.sources != b.sources {
        found.push(format!(
            "different sources ({} and {} files)",
            a.sources.len(),
            b.sources.len()
        ));
    } else if a.inputs != b.inputs {
        let describe = |i: &InputFile| match (&i.bytes, &i.sha256) {
            (Some(bytes), Some(sha)) => {
                format!("{bytes} bytes, SHA-256 {}…", &sha[..12.min(sha.len())])
            }
            _ => "unreadable".into(),
        };
        let changed: Vec<String> = a
            .inputs
            .iter()
            .zip(&b.inputs)
            .filter(|(x, y)| x != y)
            .map(|(x, y)| format!("{} ({} and {})", x.file, describe(x), describe(y)))
            .collect();
        found.push(format!("different inputs: {}", changed.join(", ")));
    }
    if a.dates != b.dates {
        found.push("different dates".into());
    }
    if a.options != b.options {
        found.push("different options".into());
    }
    if a.shard.count != b.shard.count {
        found.push(format!(
            "split in {} and in {} parts",
            a.shard.count, b.shard.count
        ));
    }
    if a.total_soundings != b.total_soundings {
        found.push(format!(
            "{} and {} soundings in all",
            a.total_soundings, b.total_soundings
        ));
    }
    found
}

/// Whether `dir` holds a part of a split survey.
pub fn is_part(dir: &Path) -> bool {
    dir.join("part.json").is_file()
}

/// The job name of part `shard` of the split survey `name`: `<name>_part_K_of_N`.
pub fn part_name(name: &str, shard: Shard) -> String {
    format!("{name}_part_{}_of_{}", shard.index, shard.count)
}

/// `(name, shard)` of a part's job name (`<name>_part_K_of_N`).
fn parse_part_name(job: &str) -> Option<(&str, Shard)> {
    let (name, rest) = job.rsplit_once("_part_")?;
    let (k, n) = rest.split_once("_of_")?;
    let shard: Shard = format!("{k}/{n}").parse().ok()?;
    Some((name, shard))
}

/// The split surveys among a pipeline's `jobs`: the folder each joins into (`<name>`) → its
/// parts' job names, in part order.
pub fn split_surveys(jobs: &[PlannedJob]) -> std::collections::BTreeMap<String, Vec<String>> {
    let mut groups: std::collections::BTreeMap<String, Vec<(usize, String)>> = Default::default();
    for job in jobs {
        let super::JobRequest::Survey(survey) = &job.request else {
            continue;
        };
        let Some((name, shard)) = parse_part_name(&job.name) else {
            continue;
        };
        if survey.shard == Some(shard) {
            let parts = groups.entry(name.to_string()).or_default();
            parts.push((shard.index, job.name.clone()));
        }
    }
    groups
        .into_iter()
        .map(|(name, mut parts)| {
            parts.sort();
            (name, parts.into_iter().map(|(_, job)| job).collect())
        })
        .collect()
}

/// The split surveys of a merged run's `manifest`, its outputs in `out_dir`: the survey jobs
/// named `<name>_part_K_of_N` whose N parts are all there, each folder holding a part.
pub fn split_surveys_in(
    out_dir: &Path,
    manifest: &Manifest,
) -> std::collections::BTreeMap<String, Vec<String>> {
    let mut groups: std::collections::BTreeMap<(String, usize), Vec<(usize, String)>> =
        Default::default();
    for (job, record) in &manifest.jobs {
        if let (Some((name, shard)), "survey") = (parse_part_name(job), record.kind.as_str()) {
            let parts = groups.entry((name.to_string(), shard.count)).or_default();
            parts.push((shard.index, job.clone()));
        }
    }
    groups
        .into_iter()
        .filter(|((_, count), parts)| parts.len() == *count)
        // A survey merely named like a part (`x_part_1_of_1` without `parts`) is no part.
        .filter(|(_, parts)| parts.iter().all(|(_, job)| is_part(&out_dir.join(job))))
        .map(|((name, _), mut parts)| {
            parts.sort();
            (name, parts.into_iter().map(|(_, job)| job).collect())
        })
        .collect()
}

/// What became of one split survey of a run.
#[derive(Debug, Clone)]
pub struct JoinOutcome {
    /// The folder it joins into.
    pub dir: PathBuf,
    /// Whether its parts were joined there (`Ok(true)`), not joined because the run does not
    /// join it or a part did not succeed (`Ok(false)`: no joined file is left there), or why
    /// they could not be joined.
    pub result: Result<bool, String>,
}

/// For each split survey of `groups` (see [`split_surveys`]), its parts' outputs in `out_dir`:
/// when `join` is set and every part succeeded in `manifest`, join the parts into
/// `<out_dir>/<name>/` and record its files in `manifest.joined`; otherwise delete the joined
/// files an earlier run left there, so that no joined survey of other parts remains.
pub fn join_split_surveys(
    out_dir: &Path,
    groups: &std::collections::BTreeMap<String, Vec<String>>,
    manifest: &mut Manifest,
    join: bool,
) -> Vec<JoinOutcome> {
    let mut outcomes = Vec::new();
    for (name, parts) in groups {
        let dir = out_dir.join(name);
        manifest.joined.remove(name);
        let succeeded = parts.iter().all(|job| {
            manifest
                .jobs
                .get(job)
                .is_some_and(|r| r.status == JobStatus::Ok)
        });
        let joined = if join && succeeded {
            join_parts(out_dir, name, parts).map(|outputs| {
                let record = JoinedRecord {
                    parts: parts.clone(),
                    outputs,
                };
                manifest.joined.insert(name.clone(), record);
                true
            })
        } else {
            Ok(false)
        };
        let result = match joined {
            Ok(true) => Ok(true),
            other => super::writer::remove_products(&dir, SURVEY_FILES)
                .map_err(|e| super::run::error_text(&e))
                .and(other),
        };
        outcomes.push(JoinOutcome { dir, result });
    }
    outcomes
}

/// Join the parts (job folders under `out_dir`) into `<out_dir>/<name>/`; its files' records.
fn join_parts(
    out_dir: &Path,
    name: &str,
    parts: &[String],
) -> Result<std::collections::BTreeMap<String, super::manifest::OutputRecord>, String> {
    let dirs: Vec<PathBuf> = parts.iter().map(|job| out_dir.join(job)).collect();
    let products = merge_parts(&dirs).map_err(|e| super::run::error_text(&e))?;
    super::writer::replace_job_products(out_dir, name, &products, SURVEY_FILES)
        .map_err(|e| super::run::error_text(&e))
}
