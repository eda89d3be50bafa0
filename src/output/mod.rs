//! Output — the one place that writes files. Exporters elsewhere return bytes; this module writes
//! them atomically (temporary file in the same folder, then rename), so a failed or killed run
//! never leaves a partly written output under its final name; [`write_all_atomic`] writes every
//! file of a set before it renames any, so a failed write leaves the earlier set as it was.
//! Temporary files are named
//! `.<name>.ghostship-tmp.<host>.<pid>`: [`remove_dead_temp_files`] finds those whose process
//! has died on this host and deletes them.

pub mod exr;
pub mod film;
pub mod gif;
pub mod plot;
pub mod png;

use std::io::Write;
use std::path::{Path, PathBuf};

/// An output file could not be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {path}: {source}")]
pub struct WriteError {
    /// The file that was to be written.
    pub path: PathBuf,
    /// The underlying I/O error.
    #[source]
    pub source: std::io::Error,
}

/// Write `bytes` to `path` atomically: the data goes to a temporary file beside `path`, is flushed
/// to disk and then renamed over `path`. Parent folders are created.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_all_atomic(&[(path, bytes)], &[])
}

/// Write a set of files that belong together (one job's outputs): every file is first written
/// to a temporary file beside its final name and flushed to disk; only when all of them are
/// written are the files in `remove` deleted (missing ones are fine) and the temporary files
/// renamed into place, in the order given. A failure while writing changes no file under a
/// final name and leaves no temporary file. Parent folders are created.
pub fn write_all_atomic(files: &[(&Path, &[u8])], remove: &[PathBuf]) -> Result<(), WriteError> {
    let staged = files
        .iter()
        .map(|&(path, bytes)| StagedFile::write(path, bytes))
        .collect::<Result<Vec<_>, _>>()?;
    commit_staged(staged, remove)
}

/// A file written under a temporary name beside its final one and flushed to disk, not yet
/// renamed into place ([`commit_staged`]). Dropped without being committed, it removes its
/// temporary file. Staging the files of a set as each becomes ready (several at once) and
/// committing them together keeps [`write_all_atomic`]'s all-or-nothing rule.
#[derive(Debug)]
pub struct StagedFile {
    tmp: PathBuf,
    path: PathBuf,
    renamed: bool,
}

impl StagedFile {
    /// Write `bytes` to a temporary file beside `path` (parent folders created) and flush it.
    pub fn write(path: &Path, bytes: &[u8]) -> Result<Self, WriteError> {
        Ok(StagedFile {
            tmp: stage(path, bytes)?,
            path: path.to_path_buf(),
            renamed: false,
        })
    }

    /// The final name.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for StagedFile {
    fn drop(&mut self) {
        if !self.renamed {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// Delete the files in `remove` (missing ones are fine), then rename the staged files into
/// place in the order given. On a failure no further file is renamed and the temporary files
/// not yet renamed are removed.
pub fn commit_staged(mut staged: Vec<StagedFile>, remove: &[PathBuf]) -> Result<(), WriteError> {
    for path in remove {
        match std::fs::remove_file(path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(WriteError {
                    path: path.clone(),
                    source: e,
                });
            }
            _ => {}
        }
    }
    for file in &mut staged {
        std::fs::rename(&file.tmp, &file.path).map_err(|source| WriteError {
            path: file.path.clone(),
            source,
        })?;
        file.renamed = true;
    }
    Ok(())
}

/// Write `bytes` to a temporary file beside `path` (parent folders created), flushed to disk;
/// returns the temporary file's path.
fn stage(path: &Path, bytes: &[u8]) -> Result<PathBuf, WriteError> {
    let wrap = |source| WriteError {
        path: path.to_path_buf(),
        source,
    };
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    std::fs::create_dir_all(&parent).map_err(wrap)?;
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    let tmp = parent.join(format!(
        ".{file_name}{TEMP_MARKER}{}.{}",
        host_name(),
        std::process::id()
    ));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    })();
    if let Err(source) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(wrap(source));
    }
    Ok(tmp)
}

/// What sits between an output's name and the host and pid in its temporary file's name.
const TEMP_MARKER: &str = ".ghostship-tmp.";

/// This machine's name, reduced to letters, digits and `-` (temp names are shared by hosts
/// writing into one network folder, so each host only removes its own).
fn host_name() -> &'static str {
    static HOST: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HOST.get_or_init(|| {
        let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .or_else(|_| std::fs::read_to_string("/etc/hostname"))
            .unwrap_or_default();
        let name: String = raw
            .trim()
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
            .collect();
        if name.is_empty() { "host".into() } else { name }
    })
}

/// The pid of a temporary file left by [`write_atomic`] on this host (also the older
/// `.<name>.tmp-<pid>` form), or `None` for any other file.
fn temp_file_pid(file_name: &str) -> Option<u32> {
    if !file_name.starts_with('.') {
        return None;
    }
    if let Some((_, rest)) = file_name.rsplit_once(TEMP_MARKER) {
        let (host, pid) = rest.rsplit_once('.')?;
        return (host == host_name()).then(|| pid.parse().ok())?;
    }
    file_name.rsplit_once(".tmp-")?.1.parse().ok()
}

/// Whether process `pid` is running (on Linux, from `/proc`; elsewhere every pid counts as
/// running, so nothing is removed).
fn process_alive(pid: u32) -> bool {
    if !Path::new("/proc/self").exists() {
        return true;
    }
    Path::new("/proc").join(pid.to_string()).exists()
}

/// Delete, under `dir` (recursively), the temporary files of writers on this host whose process
/// is no longer running; returns the files removed. Missing folders are not an error.
pub fn remove_dead_temp_files(dir: &Path) -> Result<Vec<PathBuf>, WriteError> {
    let mut removed = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(folder) = stack.pop() {
        let entries = match std::fs::read_dir(&folder) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(source) => {
                return Err(WriteError {
                    path: folder,
                    source,
                });
            }
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let is_dir = entry.file_type().is_ok_and(|t| t.is_dir());
            let name = entry.file_name().to_string_lossy().into_owned();
            if is_dir {
                stack.push(path);
            } else if temp_file_pid(&name).is_some_and(|pid| !process_alive(pid)) {
                std::fs::remove_file(&path).map_err(|source| WriteError {
                    path: path.clone(),
                    source,
                })?;
                removed.push(path);
            }
        }
    }
    removed.sort();
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_and_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("sub/a.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        let leftovers: Vec<_> = std::fs::read_dir(p.parent().unwrap()).unwrap().collect();
        assert_eq!(leftovers.len(), 1);
    }

    #[test]
    fn removes_only_dead_writers_temp_files() {
        let dir = tempfile::tempdir().unwrap();
        let sub = dir.path().join("job");
        std::fs::create_dir_all(&sub).unwrap();
        // pid 0 is never a process's; ours is alive; another host's file is not ours to judge.
        let dead = sub.join(format!(".a.png{TEMP_MARKER}{}.0", host_name()));
        let alive = sub.join(format!(
            ".b.png{TEMP_MARKER}{}.{}",
            host_name(),
            std::process::id()
        ));
        let other_host = sub.join(format!(".c.png{TEMP_MARKER}elsewhere-{}.0", host_name()));
        let legacy = dir.path().join(".layers.json.tmp-0");
        let plain = dir.path().join("d.png");
        for p in [&dead, &alive, &other_host, &legacy, &plain] {
            std::fs::write(p, b"x").unwrap();
        }
        let removed = remove_dead_temp_files(dir.path()).unwrap();
        assert_eq!(removed, vec![legacy.clone(), dead.clone()]);
        assert!(alive.exists() && other_host.exists() && plain.exists());
    }

    #[test]
    fn staged_files_appear_only_when_committed_and_leave_nothing_when_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.png"), dir.path().join("b.exr"));
        std::fs::write(&a, b"old").unwrap();
        let names = || {
            let mut v: Vec<String> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        };
        // Staged, not committed: the final names are untouched; dropped: no temporary left.
        let staged = [
            StagedFile::write(&a, b"new").unwrap(),
            StagedFile::write(&b, b"b").unwrap(),
        ];
        assert_eq!(std::fs::read(&a).unwrap(), b"old");
        assert!(!b.exists());
        assert_eq!(names().len(), 3, "{:?}", names());
        drop(staged);
        assert_eq!(names(), ["a.png"]);
        // Committed: both in place, nothing else.
        let staged = vec![
            StagedFile::write(&a, b"new").unwrap(),
            StagedFile::write(&b, b"b").unwrap(),
        ];
        assert_eq!(staged[1].path(), b.as_path());
        commit_staged(staged, &[]).unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), b"new");
        assert_eq!(std::fs::read(&b).unwrap(), b"b");
        assert_eq!(names(), ["a.png", "b.exr"]);
    }

    #[test]
    fn reports_the_path_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let blocker = dir.path().join("file");
        std::fs::write(&blocker, b"x").unwrap();
        let err = write_atomic(&blocker.join("child.txt"), b"y").unwrap_err();
        assert!(err.to_string().contains("child.txt"));
    }
}
