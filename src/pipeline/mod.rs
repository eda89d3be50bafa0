//! Pipeline — batch runs. In: a pipeline file (TOML; the format is documented in
//! `docs/pipeline.md`). Out: a [`ResolvedPipeline`]: every job expanded (globs, IGRA2 time
//! ranges, atmospheres × scenes × observer heights), validated and planned (inputs hashed) for
//! [`crate::jobs::run`]. Every problem — TOML syntax, unknown keys, wrong types, missing files,
//! impossible values — is reported with file, line and column, all of them before any work.
//!
//! ```toml
//! name = "paper"                         # optional; default: the file stem
//! [defaults]                             # optional; any job key, for every job that has it
//! sizes = ["400x200"]
//! [[profile]]
//! atmosphere = "../data/*.csv"           # a file, a glob, a synthetic *.toml or us1976
//! [[trace]]
//! atmosphere = "../data/superior_mirage.toml"
//! observer_height_m = [10.0, 50.0]       # one job per height
//! elevation_deg = "-0.3:0.5:0.002"
//! distances_m = [5000.0, 15000.0, 26000.0]
//! [[render]]
//! scene = "../data/scenes/fig04_superior_mirage.toml"
//! atmosphere = ["../data/*.csv"]         # optional: one job per atmosphere instead of the scene's
//! name = "ghost_ship_{stem}"
//! [[sequence]]                           # frames of a sweep (one of the two keys)
//! scene = "../data/scenes/fig12b_novaya_zemlya_strips.toml"
//! sun_elevation_deg = "-3:1:0.04"        # or observer_height_m = "5:120:5"
//! [[compare]]                            # measured against synthetic layers (fitted if absent)
//! atmosphere = "../data/*.csv"           # the measured soundings, one job each
//! scene = "../data/scenes/fig04_superior_mirage.toml"
//! [[survey]]                             # every sounding of an archive, one table
//! sources = ["../data/soundings/*.csv"]
//! ```

mod expand;
mod tables;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use toml::de::{DeTable, DeValue};

pub use expand::{TimeSelection, glob_files, relative_label};
pub use tables::{COMPARE_KEYS, PROFILE_KEYS, RENDER_KEYS, SEQUENCE_KEYS, SURVEY_KEYS, TRACE_KEYS};

use crate::jobs::run::PlannedJob;
use tables::{NamedJob, Problem, Table};

/// One problem in a pipeline file, at a 1-based line and column.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    /// 1-based line.
    pub line: usize,
    /// 1-based column (in characters).
    pub column: usize,
    /// What is wrong.
    pub message: String,
}

/// A pipeline file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The file could not be read.
    #[error("cannot read pipeline {path}")]
    Read {
        /// The pipeline file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The file has problems; every one is listed as `file:line:column: message`.
    #[error("invalid pipeline: {}", list(path, problems))]
    Invalid {
        /// The pipeline file.
        path: PathBuf,
        /// Every problem found, in file order.
        problems: Vec<Diagnostic>,
    },
}

fn list(path: &Path, problems: &[Diagnostic]) -> String {
    let lines: Vec<String> = problems
        .iter()
        .map(|d| format!("{}:{}:{}: {}", path.display(), d.line, d.column, d.message))
        .collect();
    if lines.len() == 1 {
        lines[0].clone()
    } else {
        format!("{} problems\n  {}", lines.len(), lines.join("\n  "))
    }
}

/// A validated pipeline, every job planned.
#[derive(Debug, Clone)]
pub struct ResolvedPipeline {
    /// Pipeline name (the default output folder is `out/<name>`).
    pub name: String,
    /// The pipeline file.
    pub source: PathBuf,
    /// SHA-256 of the pipeline file.
    pub sha256: String,
    /// Every job, in file order (profile, trace, render, then compare tables).
    pub jobs: Vec<PlannedJob>,
}

impl ResolvedPipeline {
    /// Read, expand, validate and plan a pipeline file.
    pub fn from_file(path: &Path) -> Result<Self, PipelineError> {
        let text = crate::input::read_limited_text(path, crate::input::MAX_TOML_BYTES).map_err(
            |source| PipelineError::Read {
                path: path.to_path_buf(),
                source,
            },
        )?;
        Self::from_toml_str(&text, path)
    }

    /// The same from the file's text; `path` is where it came from (relative paths in the file
    /// are resolved against its folder).
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Self, PipelineError> {
        let folder = path.parent().unwrap_or(Path::new("")).to_path_buf();
        let mut problems: Vec<Problem> = Vec::new();
        let (doc, errors) = DeTable::parse_recoverable(text);
        for e in &errors {
            problems.push((e.span().unwrap_or(0..0), e.message().to_string()));
        }
        let (name, named) = if errors.is_empty() {
            read_document(doc.get_ref(), path, &folder, &mut problems)
        } else {
            (String::new(), Vec::new())
        };
        let jobs = if problems.is_empty() {
            plan(named, &folder, &mut problems)
        } else {
            Vec::new()
        };
        if !problems.is_empty() {
            return Err(PipelineError::Invalid {
                path: path.to_path_buf(),
                problems: diagnostics(text, problems),
            });
        }
        Ok(ResolvedPipeline {
            name,
            source: path.to_path_buf(),
            sha256: crate::jobs::sha256_hex(text.as_bytes()),
            jobs,
        })
    }
}

/// The named jobs of a parsed document, with their spans; problems are collected.
fn read_document(
    doc: &DeTable,
    path: &Path,
    folder: &Path,
    problems: &mut Vec<Problem>,
) -> (String, Vec<(std::ops::Range<usize>, NamedJob)>) {
    let mut name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "pipeline".into());
    let mut defaults = DeTable::new();
    let mut named = Vec::new();
    for (key, value) in doc.iter() {
        match (key.get_ref().as_ref(), value.get_ref()) {
            ("name", DeValue::String(s)) => {
                name = s.to_string();
                if let Err(e) = check_name(&name) {
                    problems.push((value.span(), format!("name: {e}")));
                }
            }
            ("defaults", DeValue::Table(t)) => {
                defaults = t.clone();
                check_default_keys(t, problems);
            }
            ("profile" | "trace" | "render" | "sequence" | "compare" | "survey", DeValue::Array(_)) => {}
            (k @ ("name" | "defaults" | "profile" | "trace" | "render" | "sequence" | "compare" | "survey"), v) => problems.push((
                value.span(),
                format!("{k}: unexpected {} here", v.type_str()),
            )),
            (k, _) => problems.push((
                key.span(),
                format!(
                    "unknown key `{k}` (expected name, defaults, [[profile]], [[trace]], [[render]], [[sequence]], [[compare]] or [[survey]])"
                ),
            )),
        }
    }
    for (kind, keys) in [
        ("profile", PROFILE_KEYS),
        ("trace", TRACE_KEYS),
        ("render", RENDER_KEYS),
        ("sequence", SEQUENCE_KEYS),
        ("compare", COMPARE_KEYS),
        ("survey", SURVEY_KEYS),
    ] {
        let Some(DeValue::Array(items)) = doc.get(kind).map(|v| v.get_ref()) else {
            continue;
        };
        for (k, item) in items.iter().enumerate() {
            let DeValue::Table(own) = item.get_ref() else {
                problems.push((item.span(), format!("{kind}: expected a table")));
                continue;
            };
            let table = TableRef {
                kind,
                ordinal: k + 1,
                keys,
                own,
                span: item.span(),
            };
            let jobs = job_table(&table, &defaults, folder, problems);
            named.extend(jobs.into_iter().map(|j| (item.span(), j)));
        }
    }
    if named.is_empty() && problems.is_empty() {
        problems.push((
            0..0,
            "no jobs: add at least one [[profile]], [[trace]], [[render]], [[sequence]], [[compare]] or [[survey]] table"
                .into(),
        ));
    }
    (name, named)
}

fn check_default_keys(defaults: &DeTable, problems: &mut Vec<Problem>) {
    for key in defaults.keys() {
        let k: &str = key.get_ref();
        let known = [
            PROFILE_KEYS,
            TRACE_KEYS,
            RENDER_KEYS,
            SEQUENCE_KEYS,
            COMPARE_KEYS,
            SURVEY_KEYS,
        ]
        .iter()
        .any(|keys| keys.contains(&k));
        if !known || k == "name" {
            problems.push((key.span(), format!("unknown key `{k}` in [defaults]")));
        }
    }
}

/// One `[[kind]]` table of the file, as written.
struct TableRef<'a, 'i> {
    /// `profile`, `trace`, …
    kind: &'a str,
    /// Its place among the file's tables of its kind (1-based).
    ordinal: usize,
    /// The keys its kind accepts.
    keys: &'a [&'a str],
    /// Its own keys.
    own: &'a DeTable<'i>,
    /// Its span.
    span: std::ops::Range<usize>,
}

/// One job table: its own keys checked, the defaults it accepts merged in, expanded to jobs.
/// Problems with its values name the table (`[[survey]] arctic`, by its `name`, or
/// `[[trace]] #2`, by its place among the tables of its kind).
fn job_table(
    table_ref: &TableRef,
    defaults: &DeTable,
    folder: &Path,
    problems: &mut Vec<Problem>,
) -> Vec<NamedJob> {
    let TableRef {
        kind,
        ordinal,
        keys,
        own,
        ..
    } = *table_ref;
    let span = table_ref.span.clone();
    let mut merged = DeTable::new();
    for (k, v) in defaults.iter() {
        if keys.contains(&k.get_ref().as_ref()) {
            merged.insert(k.clone(), v.clone());
        }
    }
    let mut own_keys = Vec::new();
    let mut unknown = false;
    for (k, v) in own.iter() {
        let name: &str = k.get_ref();
        if !keys.contains(&name) {
            unknown = true;
            problems.push((
                k.span(),
                format!(
                    "unknown key `{name}` in [[{kind}]] (expected one of: {})",
                    keys.join(", ")
                ),
            ));
        }
        own_keys.push(name.to_string());
        merged.insert(k.clone(), v.clone());
    }
    if unknown {
        return Vec::new();
    }
    let mut table = Table {
        table: &merged,
        span,
        folder,
        problems: Vec::new(),
    };
    let jobs = match kind {
        "profile" => tables::profile_jobs(&mut table),
        "trace" => tables::trace_jobs(&mut table),
        "compare" => tables::compare_jobs(&mut table),
        "sequence" => tables::sequence_jobs(&mut table),
        "survey" => tables::survey_jobs(&mut table),
        _ => tables::render_jobs(&mut table, &own_keys),
    };
    let label = match merged.get("name").map(|v| v.get_ref()) {
        Some(DeValue::String(name)) => format!("[[{kind}]] {name}"),
        _ => format!("[[{kind}]] #{ordinal}"),
    };
    problems.extend(
        table
            .problems
            .drain(..)
            .map(|(at, message)| (at, format!("{label}: {message}"))),
    );
    for (name, _) in &jobs {
        if let Err(e) = check_name(name) {
            let at = merged.get("name").map_or(table.span.clone(), |v| v.span());
            problems.push((at, format!("job name: {e}")));
        }
    }
    jobs
}

/// A split survey's joined folder `<name>/` must be no job's folder and no other split survey's.
fn check_joined_surveys(named: &[(std::ops::Range<usize>, NamedJob)], problems: &mut Vec<Problem>) {
    let names: BTreeSet<&str> = named.iter().map(|(_, (n, _))| n.as_str()).collect();
    let mut joined: BTreeMap<String, usize> = BTreeMap::new();
    for (span, (name, request)) in named {
        let crate::jobs::JobRequest::Survey(survey) = request else {
            continue;
        };
        let Some(shard) = survey.shard else {
            continue;
        };
        let suffix = format!("_part_{}_of_{}", shard.index, shard.count);
        let Some(base) = name.strip_suffix(&suffix) else {
            continue;
        };
        let clash = names.contains(base)
            || joined
                .insert(base.to_string(), shard.count)
                .is_some_and(|count| count != shard.count);
        if clash && shard.index == 1 {
            problems.push((
                span.clone(),
                format!("the split survey {base:?} joins into {base}/, which another job writes too; give one of them another `name`"),
            ));
        }
    }
}

/// Check names are unique, hash every job's inputs and plan it.
fn plan(
    named: Vec<(std::ops::Range<usize>, NamedJob)>,
    folder: &Path,
    problems: &mut Vec<Problem>,
) -> Vec<PlannedJob> {
    let mut seen = BTreeSet::new();
    let mut jobs = Vec::new();
    check_joined_surveys(&named, problems);
    for (span, (name, request)) in named {
        if !seen.insert(name.clone()) {
            problems.push((
                span,
                format!("two jobs are named {name:?}; give one of them another `name` (placeholders: {{stem}}, {{scene}}, {{height}})"),
            ));
            continue;
        }
        let mut inputs = BTreeMap::new();
        for file in request.input_files() {
            match crate::input::read_limited(&file, crate::input::MAX_SOUNDING_BYTES) {
                Ok(bytes) => {
                    inputs.insert(
                        relative_label(&file, folder),
                        crate::jobs::sha256_hex(&bytes),
                    );
                }
                Err(e) => problems.push((span.clone(), format!("{}: {e}", file.display()))),
            }
        }
        let mut parameters = request.parameters();
        relabel_paths(&mut parameters, folder);
        jobs.push(PlannedJob::new(name, request, parameters, inputs));
    }
    jobs
}

/// Replace every string of `value` that names an existing file by its label relative to
/// `folder`, so the recorded parameters do not depend on the working directory.
fn relabel_paths(value: &mut serde_json::Value, folder: &Path) {
    match value {
        serde_json::Value::String(s) if s.contains(['/', '\\']) && Path::new(s).is_file() => {
            *s = relative_label(Path::new(s), folder);
        }
        serde_json::Value::Array(items) => items.iter_mut().for_each(|v| relabel_paths(v, folder)),
        serde_json::Value::Object(map) => map.values_mut().for_each(|v| relabel_paths(v, folder)),
        _ => {}
    }
}

/// Byte spans → 1-based lines and columns, sorted.
fn diagnostics(text: &str, problems: Vec<Problem>) -> Vec<Diagnostic> {
    let mut out: Vec<Diagnostic> = problems
        .into_iter()
        .map(|(span, message)| {
            let start = span.start.min(text.len());
            let before = text.get(..start).unwrap_or("");
            let line = 1 + before.matches('\n').count();
            let line_start = before.rfind('\n').map_or(0, |i| i + 1);
            let column = 1 + before[line_start..].chars().count();
            Diagnostic {
                line,
                column,
                message,
            }
        })
        .collect();
    out.sort_by_key(|d| (d.line, d.column));
    out.dedup();
    out
}

fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty()
        || !name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
        || name.starts_with('.')
    {
        return Err(format!(
            "{name:?} must be a plain file name (letters, digits, '_', '-', '.')"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
