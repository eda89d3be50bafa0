//! Pipeline — expansion of one job table into jobs. In: the names a job table gives (an
//! atmosphere file, a glob of soundings, an IGRA2 file with a time selection, `us1976`; scene
//! files or globs) relative to the pipeline file. Out: the concrete atmosphere sources and
//! scene paths, each with the label the manifest records, and the `{stem}`-style job names.

use std::path::Path;

use crate::atmosphere::AtmosphereSource;

/// One concrete atmosphere of an expanded job.
#[derive(Debug, Clone, PartialEq)]
pub struct AtmosphereChoice {
    /// What to load.
    pub source: AtmosphereSource,
    /// Which IGRA2 sounding (`"YYYY-MM-DD HH"`), if one was chosen.
    pub sounding_time: Option<String>,
    /// `{stem}` in job names: the file stem, with `_YYYYMMDDHH` for one of several IGRA2
    /// soundings.
    pub stem: String,
}

pub use crate::input::{glob_files, is_glob, relative_label};

/// Which IGRA2 soundings a job's `sounding_time` selects: one `"YYYY-MM-DD HH"`, `"all"`, or an
/// inclusive range `"FROM..TO"` (either end may be left out).
#[derive(Debug, Clone, PartialEq)]
pub enum TimeSelection {
    /// The file's first sounding (no `sounding_time`).
    First,
    /// One sounding.
    One(String),
    /// Every sounding from `from` to `to` (inclusive; `None`: open).
    Range(Option<String>, Option<String>),
}

impl TimeSelection {
    /// Parse an `sounding_time` value.
    pub fn parse(text: Option<&str>) -> Result<Self, String> {
        let Some(text) = text.map(str::trim) else {
            return Ok(TimeSelection::First);
        };
        if text.eq_ignore_ascii_case("all") {
            return Ok(TimeSelection::Range(None, None));
        }
        let check = |t: &str| -> Result<Option<String>, String> {
            let t = t.trim();
            if t.is_empty() {
                return Ok(None);
            }
            crate::sounding::time::canonical_time(t)
                .map(Some)
                .map_err(|e| format!("sounding_time: {e}, \"all\" or \"FROM..TO\""))
        };
        match text.split_once("..") {
            Some((from, to)) => Ok(TimeSelection::Range(check(from)?, check(to)?)),
            None => Ok(TimeSelection::One(check(text)?.unwrap_or_default())),
        }
    }
}

/// The atmospheres `names` (each a file, a glob or `us1976`, relative to `folder`) and
/// `times` select.
pub fn atmospheres(
    names: &[String],
    times: &TimeSelection,
    folder: &Path,
) -> Result<Vec<AtmosphereChoice>, String> {
    let mut out = Vec::new();
    for name in names {
        let source = AtmosphereSource::parse(name);
        let Some(path) = source.path() else {
            out.push(AtmosphereChoice {
                source,
                sounding_time: None,
                stem: "us1976".into(),
            });
            continue;
        };
        let path = folder.join(path);
        let files = if is_glob(name) {
            glob_files(&path)?
        } else {
            check_file(&path)?;
            vec![path]
        };
        for file in files {
            out.extend(with_times(
                AtmosphereSource::parse(&file.to_string_lossy()),
                times,
            )?);
        }
    }
    Ok(out)
}

/// `path` is a readable regular file.
pub fn check_file(path: &Path) -> Result<(), String> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(()),
        Ok(_) => Err(format!("{} is not a regular file", path.display())),
        Err(e) => Err(format!("{}: {e}", path.display())),
    }
}

fn with_times(
    source: AtmosphereSource,
    times: &TimeSelection,
) -> Result<Vec<AtmosphereChoice>, String> {
    let stem = source.stem();
    let (from, to) = match times {
        TimeSelection::First => (None, None),
        TimeSelection::One(t) => {
            if let Some(path) = source.path()
                && let Some(all) =
                    crate::sounding::sounding_times(path).map_err(|e| e.to_string())?
                && !all.contains(t)
            {
                return Err(format!(
                    "{}: {}",
                    path.display(),
                    crate::sounding::time::no_such_time(t, &all)
                ));
            }
            return Ok(vec![AtmosphereChoice {
                source,
                sounding_time: Some(t.clone()),
                stem,
            }]);
        }
        TimeSelection::Range(from, to) => (from.clone(), to.clone()),
    };
    let Some(path) = source.path().filter(|_| *times != TimeSelection::First) else {
        return Ok(vec![AtmosphereChoice {
            source,
            sounding_time: None,
            stem,
        }]);
    };
    let Some(all) = crate::sounding::sounding_times(path).map_err(|e| e.to_string())? else {
        // Not IGRA2: the file's one sounding is all of them.
        return Ok(vec![AtmosphereChoice {
            source,
            sounding_time: None,
            stem,
        }]);
    };
    let mut chosen: Vec<String> = all
        .into_iter()
        .filter(|t| from.as_ref().is_none_or(|f| t >= f) && to.as_ref().is_none_or(|e| t <= e))
        .collect();
    // A time the file holds twice is one job (the reader takes the first and says so).
    let mut seen = std::collections::HashSet::new();
    chosen.retain(|t| seen.insert(t.clone()));
    if chosen.is_empty() {
        return Err(format!(
            "{}: no IGRA2 sounding in the time range",
            path.display()
        ));
    }
    Ok(chosen
        .into_iter()
        .map(|t| AtmosphereChoice {
            stem: format!("{stem}_{}", t.replace(['-', ' '], "")),
            source: source.clone(),
            sounding_time: Some(t),
        })
        .collect())
}

/// `template` with `{stem}`, `{scene}` and `{height}` replaced; an unknown `{…}` is an error.
pub fn job_name(
    template: &str,
    stem: &str,
    scene: &str,
    height_m: Option<f64>,
) -> Result<String, String> {
    let height = height_m.map(|h| format!("{h}m")).unwrap_or_default();
    let mut out = String::new();
    let mut rest = template;
    while let Some(open) = rest.find('{') {
        out.push_str(&rest[..open]);
        let close = rest[open..]
            .find('}')
            .ok_or_else(|| format!("name {template:?}: unclosed {{"))?;
        out.push_str(match &rest[open + 1..open + close] {
            "stem" => stem,
            "scene" => scene,
            "height" => &height,
            other => {
                return Err(format!(
                    "name {template:?}: unknown placeholder {{{other}}} (use {{stem}}, {{scene}} or {{height}})"
                ));
            }
        });
        rest = &rest[open + close + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_labels() {
        assert_eq!(
            job_name("{stem}_{scene}_{height}", "u", "fig", Some(10.0)).unwrap(),
            "u_fig_10m"
        );
        assert!(job_name("{nope}", "u", "", None).is_err());
        assert_eq!(
            relative_label(
                Path::new("/r/pipelines/../data/x.csv"),
                Path::new("/r/pipelines")
            ),
            "../data/x.csv"
        );
    }

    #[test]
    fn time_selections() {
        assert_eq!(TimeSelection::parse(None).unwrap(), TimeSelection::First);
        assert_eq!(
            TimeSelection::parse(Some("ALL")).unwrap(),
            TimeSelection::Range(None, None)
        );
        assert_eq!(
            TimeSelection::parse(Some("2010-06-01 00..")).unwrap(),
            TimeSelection::Range(Some("2010-06-01 00".into()), None)
        );
        assert!(TimeSelection::parse(Some("2010-6-1")).is_err());
    }
}
