//! Jobs — the manifest. In: the record of every job a run did or skipped. Out: `manifest.json`
//! in the output folder (or `manifest-shard-K-of-N.json` for one shard of a run): the program
//! version, the pipeline, per job its kind, resolved parameters, the SHA-256 of every input
//! and of every output, and its status, and the SHA-256 of every file of the split surveys a
//! whole run (or a merge) joined. The next run reads it back to skip unchanged jobs;
//! [`merge`] combines the manifests of a run's shards. Nothing in it depends on time or on the
//! number of threads, so repeated runs write the same bytes.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// The `format` field of every manifest this version writes.
pub const MANIFEST_FORMAT: &str = "ghostship-manifest-1";
/// The name of a whole run's manifest.
pub const MANIFEST_NAME: &str = "manifest.json";

/// One of N parts of a run, K = 1…N.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Shard {
    /// Which part, 1-based.
    pub index: usize,
    /// How many parts.
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// `K/N` with 1 ≤ K ≤ N.
    fn from_str(text: &str) -> Result<Self, String> {
        let parse = |s: &str| s.trim().parse::<usize>().ok();
        match text.split_once('/').map(|(k, n)| (parse(k), parse(n))) {
            Some((Some(index), Some(count))) if index >= 1 && index <= count => {
                Ok(Shard { index, count })
            }
            _ => Err(format!(
                "{text:?} is not K/N with whole numbers 1 ≤ K ≤ N (e.g. 2/4)"
            )),
        }
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// The manifest file name of this shard.
    pub fn manifest_name(&self) -> String {
        format!("manifest-shard-{}-of-{}.json", self.index, self.count)
    }
}

/// Whether a job produced its outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JobStatus {
    /// Every output was written.
    Ok,
    /// The job failed; see `error`.
    Failed,
}

/// One written file.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct OutputRecord {
    /// SHA-256 of the content (hex).
    pub sha256: String,
    /// Size in bytes.
    pub bytes: u64,
}

/// What the manifest says about one job.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JobRecord {
    /// `profile`, `trace` or `render`.
    pub kind: String,
    /// SHA-256 of program version, kind, parameters and input hashes: equal keys mean the job
    /// would write the same bytes.
    pub key: String,
    /// Whether it succeeded.
    pub status: JobStatus,
    /// Why it failed (file, line, reason).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The resolved parameters (paths relative to the pipeline file's folder).
    pub parameters: serde_json::Value,
    /// SHA-256 of every input file, by path relative to the pipeline file's folder.
    pub inputs: BTreeMap<String, String>,
    /// Every output, by path relative to the output folder.
    pub outputs: BTreeMap<String, OutputRecord>,
}

/// A run's (or a shard's) manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// [`MANIFEST_FORMAT`].
    pub format: String,
    /// `ghostship <version>`.
    pub program: String,
    /// The pipeline's name.
    pub pipeline: String,
    /// SHA-256 of the pipeline file.
    pub pipeline_sha256: String,
    /// Which shard this is; `None` for a whole run (or merged shards).
    pub shard: Option<Shard>,
    /// Every job of the pipeline, sorted (a shard records all of them, to let [`merge`] check
    /// that the shards cover the pipeline).
    pub jobs_in_pipeline: Vec<String>,
    /// The jobs this run (or shard) is responsible for.
    pub jobs: BTreeMap<String, JobRecord>,
    /// The split surveys this run (or merge) joined, by the folder they were joined into.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub joined: BTreeMap<String, JoinedRecord>,
}

/// A split survey joined from its parts (`<name>_part_K_of_N` jobs) into `<name>/`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JoinedRecord {
    /// The parts' job names, in part order.
    pub parts: Vec<String>,
    /// Every file of the joined survey, by path relative to the output folder.
    pub outputs: BTreeMap<String, OutputRecord>,
}

/// A manifest could not be read or merged.
#[derive(Debug, thiserror::Error)]
pub enum ManifestError {
    /// The file could not be read.
    #[error("cannot read manifest {path}")]
    Read {
        /// The manifest.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The file is not a manifest of this program.
    #[error("{path} is not a ghostship manifest")]
    Parse {
        /// The manifest.
        path: PathBuf,
        /// Why.
        #[source]
        source: serde_json::Error,
    },
    /// The shard manifests do not add up to the pipeline.
    #[error("cannot merge: {0}")]
    Merge(String),
    /// The merged manifest (or a copied output) could not be written.
    #[error(transparent)]
    Write(#[from] crate::output::WriteError),
}

impl Manifest {
    /// Serialise as pretty JSON with a final newline.
    pub fn to_json(&self) -> Vec<u8> {
        let mut text = serde_json::to_string_pretty(self).unwrap_or_default();
        text.push('\n');
        text.into_bytes()
    }

    /// Read a manifest file.
    pub fn read(path: &Path) -> Result<Self, ManifestError> {
        let bytes = crate::input::read_limited(path, crate::input::MAX_SOUNDING_BYTES).map_err(
            |source| ManifestError::Read {
                path: path.to_path_buf(),
                source,
            },
        )?;
        let manifest: Manifest =
            serde_json::from_slice(&bytes).map_err(|source| ManifestError::Parse {
                path: path.to_path_buf(),
                source,
            })?;
        if manifest.format != MANIFEST_FORMAT {
            return Err(ManifestError::Merge(format!(
                "{}: format {:?}, expected {MANIFEST_FORMAT:?}",
                path.display(),
                manifest.format
            )));
        }
        Ok(manifest)
    }
}

/// The manifest files in `dir`: `manifest.json` and every shard manifest, sorted by name.
pub fn manifest_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                n == MANIFEST_NAME || (n.starts_with("manifest-shard-") && n.ends_with(".json"))
            })
        })
        .collect();
    files.sort();
    files
}

/// The successful job records of earlier runs in `dir` (any manifest there; unreadable ones
/// are ignored: their jobs simply run again).
pub fn previous_records(dir: &Path) -> BTreeMap<String, JobRecord> {
    let mut records = BTreeMap::new();
    for path in manifest_files(dir) {
        if let Ok(manifest) = Manifest::read(&path) {
            for (name, record) in manifest.jobs {
                if record.status == JobStatus::Ok {
                    records.insert(name, record);
                }
            }
        }
    }
    records
}

/// Combine the shard manifests found in `dirs` into `<first dir>/manifest.json`, after checking
/// that they come from one pipeline split into N shards, that every shard 1…N is there exactly
/// once, that together they hold every job of the pipeline exactly once, and that every job
/// succeeded. Outputs recorded in another folder than the first are copied into it (and their
/// SHA-256 checked), then the split surveys are joined there (and recorded in the manifest).
pub fn merge(dirs: &[PathBuf]) -> Result<Merged, ManifestError> {
    let fail = |m: String| Err(ManifestError::Merge(m));
    let Some(target) = dirs.first() else {
        return fail("give at least one folder".into());
    };
    let mut shards: Vec<(PathBuf, PathBuf, Manifest)> = Vec::new();
    for dir in dirs {
        for path in manifest_files(dir) {
            if path.file_name().is_some_and(|n| n == MANIFEST_NAME) {
                continue;
            }
            let manifest = Manifest::read(&path)?;
            shards.push((dir.clone(), path, manifest));
        }
    }
    let Some((_, first_path, first)) = shards.first() else {
        return fail(format!(
            "no shard manifests (manifest-shard-K-of-N.json) in {}",
            dirs.iter()
                .map(|d| d.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    };
    let count = first.shard.map_or(0, |s| s.count);
    let mut seen_shards = BTreeMap::new();
    for (_, path, m) in &shards {
        let same = m.pipeline == first.pipeline
            && m.pipeline_sha256 == first.pipeline_sha256
            && m.jobs_in_pipeline == first.jobs_in_pipeline
            && m.program == first.program
            && m.shard.is_some_and(|s| s.count == count);
        if !same {
            return fail(format!(
                "{} and {} are not shards of the same run (pipeline, program version or shard count differ)",
                first_path.display(),
                path.display()
            ));
        }
        let index = m.shard.map_or(0, |s| s.index);
        if let Some(other) = seen_shards.insert(index, path.clone()) {
            return fail(format!(
                "shard {index}/{count} appears twice: {} and {}",
                other.display(),
                path.display()
            ));
        }
    }
    let missing: Vec<String> = (1..=count)
        .filter(|k| !seen_shards.contains_key(k))
        .map(|k| format!("{k}/{count}"))
        .collect();
    if !missing.is_empty() {
        return fail(format!("shard(s) {} missing", missing.join(", ")));
    }
    let jobs = merge_jobs(&shards)?;
    let expected: BTreeSet<&String> = first.jobs_in_pipeline.iter().collect();
    let got: BTreeSet<&String> = jobs.keys().map(|(name, _)| name).collect();
    let absent: Vec<&str> = expected.difference(&got).map(|s| s.as_str()).collect();
    let extra: Vec<&str> = got.difference(&expected).map(|s| s.as_str()).collect();
    if !absent.is_empty() || !extra.is_empty() {
        return fail(format!(
            "the shards do not hold exactly the pipeline's jobs (missing: [{}]; not in the pipeline: [{}])",
            absent.join(", "),
            extra.join(", ")
        ));
    }
    let mut merged = first.clone();
    merged.shard = None;
    merged.jobs = BTreeMap::new();
    merged.joined = BTreeMap::new();
    for ((name, dir), record) in jobs {
        if dir != *target {
            copy_outputs(&dir, target, &record)?;
        }
        merged.jobs.insert(name, record);
    }
    let groups = super::survey::split_surveys_in(target, &merged);
    let joined = super::survey::join_split_surveys(target, &groups, &mut merged, true);
    let path = target.join(MANIFEST_NAME);
    crate::output::write_atomic(&path, &merged.to_json())?;
    Ok(Merged { path, joined })
}

/// What [`merge`] wrote.
#[derive(Debug)]
pub struct Merged {
    /// The merged manifest.
    pub path: PathBuf,
    /// The split surveys it joined (or why one could not be joined).
    pub joined: Vec<super::survey::JoinOutcome>,
}

/// Every job record of the shards, keyed by name and folder; a job in two shards, or failed, is
/// an error.
fn merge_jobs(
    shards: &[(PathBuf, PathBuf, Manifest)],
) -> Result<BTreeMap<(String, PathBuf), JobRecord>, ManifestError> {
    let mut jobs = BTreeMap::new();
    let mut owner: BTreeMap<String, &Path> = BTreeMap::new();
    for (dir, path, m) in shards {
        for (name, record) in &m.jobs {
            if let Some(other) = owner.insert(name.clone(), path) {
                return Err(ManifestError::Merge(format!(
                    "job {name:?} appears twice: in {} and {}",
                    other.display(),
                    path.display()
                )));
            }
            if record.status != JobStatus::Ok {
                return Err(ManifestError::Merge(format!(
                    "job {name:?} failed in {}: {}",
                    path.display(),
                    record.error.as_deref().unwrap_or("no reason recorded")
                )));
            }
            jobs.insert((name.clone(), dir.clone()), record.clone());
        }
    }
    Ok(jobs)
}

fn copy_outputs(from: &Path, to: &Path, record: &JobRecord) -> Result<(), ManifestError> {
    for (rel, out) in &record.outputs {
        let src = from.join(rel);
        let bytes =
            crate::input::read_limited(&src, u64::MAX).map_err(|source| ManifestError::Read {
                path: src.clone(),
                source,
            })?;
        if super::sha256_hex(&bytes) != out.sha256 {
            return Err(ManifestError::Merge(format!(
                "{} does not match its SHA-256 in the manifest",
                src.display()
            )));
        }
        crate::output::write_atomic(&to.join(rel), &bytes)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_syntax() {
        assert_eq!(
            "2/4".parse::<Shard>().unwrap(),
            Shard { index: 2, count: 4 }
        );
        for bad in ["0/4", "5/4", "4", "a/b", "1/0", "-1/2"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad}");
        }
    }
}
