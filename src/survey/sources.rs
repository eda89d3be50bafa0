//! Survey — its inputs. In: what the user named (files, folders, glob patterns) and an optional
//! date range. Out: [`SurveyItem`]s, one per sounding, in a fixed order (sources as given,
//! folders and globs sorted by path, soundings in file order), each the sounding or why it
//! cannot be read, and each file's size and SHA-256 ([`InputFile`]).

use std::path::{Path, PathBuf};

use super::SurveyError;
use crate::sounding::{ReadOptions, Sounding, SoundingError, soundings_in};

/// One sounding to survey.
#[derive(Debug)]
pub struct SurveyItem {
    /// The file, and `:line` of the sounding's header in a multi-sounding file.
    pub origin: String,
    /// Its nominal time (`"YYYY-MM-DD HH"`), when known before reading it.
    pub time: Option<String>,
    /// The sounding, or why it cannot be read.
    pub sounding: Result<Sounding, SoundingError>,
}

/// Inclusive range of nominal dates (`"YYYY-MM-DD"`) to keep.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct DateRange {
    /// First day kept.
    pub from: Option<String>,
    /// Last day kept.
    pub to: Option<String>,
}

impl DateRange {
    /// Check the dates' form (`YYYY-MM-DD`) and order; an error names the key (`from`, `to`).
    pub fn validate(&self) -> Result<(), SurveyError> {
        for (key, d) in [("from", &self.from), ("to", &self.to)] {
            if let Some(d) = d {
                let ok = d.len() == 10
                    && d.bytes().enumerate().all(|(i, b)| match i {
                        4 | 7 => b == b'-',
                        _ => b.is_ascii_digit(),
                    });
                if !ok {
                    return Err(SurveyError::BadOption {
                        key,
                        message: format!("date {key} {d:?} is not YYYY-MM-DD"),
                    });
                }
            }
        }
        if let (Some(a), Some(b)) = (&self.from, &self.to)
            && a > b
        {
            return Err(SurveyError::BadOption {
                key: "to",
                message: format!("date to {b} is before from {a}: the date range is empty"),
            });
        }
        Ok(())
    }

    /// Whether a sounding at `time` (`"YYYY-MM-DD HH"`) is kept; one of unknown time is kept.
    pub fn keeps(&self, time: Option<&str>) -> bool {
        let is_day = |d: &&str| {
            d.bytes().enumerate().all(|(i, b)| match i {
                4 | 7 => b == b'-',
                _ => b.is_ascii_digit(),
            })
        };
        let Some(day) = time.and_then(|t| t.get(..10)).filter(is_day) else {
            return true;
        };
        self.from.as_deref().is_none_or(|f| day >= f) && self.to.as_deref().is_none_or(|t| day <= t)
    }
}

/// The files `sources` name: a file as is, a folder's regular files (not `*.md`, not hidden),
/// a pattern with `*`, `?` or `[` every file it matches; folders and patterns sorted by path.
/// A folder or pattern with no file, or a source that does not exist, is an error.
pub fn expand_files(sources: &[PathBuf]) -> Result<Vec<PathBuf>, SurveyError> {
    let mut files = Vec::new();
    for source in sources {
        let text = source.to_string_lossy();
        // An existing file or folder is taken as named, even if its name holds `[`, `*` or `?`
        // (a pipeline passes the files its globs matched).
        let found = if source.is_file() {
            vec![source.clone()]
        } else if source.is_dir() {
            folder_files(source)?
        } else if crate::input::is_glob(&text) {
            crate::input::glob_files(source).map_err(SurveyError::Invalid)?
        } else {
            return Err(SurveyError::Invalid(format!(
                "{}: no such file or folder",
                source.display()
            )));
        };
        if found.is_empty() {
            return Err(SurveyError::Invalid(format!(
                "{text}: no sounding file there"
            )));
        }
        files.extend(found);
    }
    Ok(files)
}

fn folder_files(folder: &Path) -> Result<Vec<PathBuf>, SurveyError> {
    let entries = std::fs::read_dir(folder)
        .map_err(|e| SurveyError::Invalid(format!("{}: {e}", folder.display())))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.is_file())
        .filter(|p| {
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy())
                .unwrap_or_default();
            !name.starts_with('.') && !name.to_ascii_lowercase().ends_with(".md")
        })
        .collect();
    files.sort();
    Ok(files)
}

/// One input file of a survey as it was read: how rows name it, its size and SHA-256 (`None`
/// for a file that could not be read; its row says why).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct InputFile {
    /// The file's label (as rows name it).
    pub file: String,
    /// Size in bytes, as stored (before any gzip or zip is inflated).
    pub bytes: Option<u64>,
    /// SHA-256 of those bytes (hex).
    pub sha256: Option<String>,
}

/// Every sounding in `files` within `dates`, read with `read` (in parallel by file; the order
/// is the files' and, inside a file, the soundings'), and each file's size and SHA-256. Each
/// item's origin is its file's label in `labels` (the same order as `files`), with `:LINE` of
/// its header in a record.
pub fn expand_sources(
    files: &[PathBuf],
    labels: &[String],
    dates: &DateRange,
    read: &ReadOptions,
) -> (Vec<SurveyItem>, Vec<InputFile>) {
    use rayon::prelude::*;
    let per_file: Vec<(Vec<SurveyItem>, InputFile)> = files
        .par_iter()
        .zip(labels)
        .map(|(path, label)| file_items(path, label, dates, read))
        .collect();
    let (items, inputs): (Vec<_>, Vec<_>) = per_file.into_iter().unzip();
    (items.into_iter().flatten().collect(), inputs)
}

fn file_items(
    path: &Path,
    label: &str,
    dates: &DateRange,
    read: &ReadOptions,
) -> (Vec<SurveyItem>, InputFile) {
    let name = label.to_string();
    let mut input = InputFile {
        file: name.clone(),
        bytes: None,
        sha256: None,
    };
    let entries = crate::input::read_limited(path, crate::input::MAX_SOUNDING_BYTES)
        .map_err(|source| SoundingError::Io {
            path: path.to_path_buf(),
            source,
        })
        .and_then(|bytes| {
            input.bytes = Some(bytes.len() as u64);
            input.sha256 = Some(crate::jobs::sha256_hex(&bytes));
            soundings_in(path, bytes, read)
        });
    let entries = match entries {
        Ok(e) => e,
        Err(e) => {
            let item = SurveyItem {
                origin: name,
                time: None,
                sounding: Err(e),
            };
            return (vec![item], input);
        }
    };
    let items = entries
        .into_iter()
        .map(|mut e| {
            if e.time.is_none() {
                e.time = e.result.as_ref().ok().and_then(super::sounding_time);
            }
            e
        })
        .filter(|e| dates.keeps(e.time.as_deref()))
        .map(|e| SurveyItem {
            origin: match e.line {
                Some(line) => format!("{name}:{line}"),
                None => name.clone(),
            },
            time: e.time,
            sounding: e.result,
        })
        .collect();
    (items, input)
}
