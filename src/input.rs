//! Input — every input file is read through here. In: a path and a size limit. Out: the file's
//! bytes, or an `std::io::Error` saying why not. Only regular files are read (a FIFO, a device
//! such as `/dev/zero` or a folder is refused before it is opened), and never more than the
//! limit, so a mistyped path cannot block the program or read until memory runs out.
//! [`unpack`] opens gzip files and one-member zip archives (IGRA2 ships as `.txt.zip`, archives
//! as `.gz`), again never inflating past the limit.

use std::io::Read;
use std::path::{Component, Path, PathBuf};

/// Largest sounding file read (an IGRA2 station record of decades of soundings fits).
pub const MAX_SOUNDING_BYTES: u64 = 512 * 1024 * 1024;
/// Largest TOML file read (scenes, synthetic atmospheres, pipelines).
pub const MAX_TOML_BYTES: u64 = 16 * 1024 * 1024;
/// Largest card image read.
pub const MAX_IMAGE_BYTES: u64 = 256 * 1024 * 1024;

/// Whether `text` holds a glob wildcard (`*`, `?` or `[`).
pub fn is_glob(text: &str) -> bool {
    text.contains(['*', '?', '['])
}

/// The regular files matching the glob `pattern` (`*`, `?`, `[...]` and `**`, in folders as in
/// file names; a wildcard never matches a hidden file or folder), sorted by path. An
/// error when the pattern is malformed or matches no file.
pub fn glob_files(pattern: &Path) -> Result<Vec<PathBuf>, String> {
    let text = pattern.to_string_lossy();
    let options = glob::MatchOptions {
        require_literal_leading_dot: true,
        ..glob::MatchOptions::new()
    };
    let paths = glob::glob_with(&text, options).map_err(|e| format!("pattern {text:?}: {e}"))?;
    let mut files: Vec<PathBuf> = paths
        .filter_map(Result::ok)
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(format!("no file matches {text}"));
    }
    Ok(files)
}

/// `path` relative to `base`, both made absolute and normalised lexically (`a/../b` → `b`), with
/// `/` separators: the label a manifest records, the same from any working directory.
pub fn relative_label(path: &Path, base: &Path) -> String {
    let path = normalise(path);
    let base = normalise(base);
    let common = path
        .components()
        .zip(base.components())
        .take_while(|(a, b)| a == b)
        .count();
    let mut parts: Vec<String> = base
        .components()
        .skip(common)
        .map(|_| "..".into())
        .collect();
    parts.extend(
        path.components()
            .skip(common)
            .map(|c| c.as_os_str().to_string_lossy().into_owned()),
    );
    parts.join("/")
}

fn normalise(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut out = PathBuf::new();
    for c in absolute.components() {
        match c {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    out
}

/// Read the regular file at `path`, refusing anything else and anything over `limit_bytes`.
pub fn read_limited(path: &Path, limit_bytes: u64) -> std::io::Result<Vec<u8>> {
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "not a regular file (a folder, FIFO or device); refusing to read it",
        ));
    }
    if meta.len() > limit_bytes {
        return Err(too_large(meta.len(), limit_bytes));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    std::fs::File::open(path)?
        .take(limit_bytes.saturating_add(1))
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit_bytes {
        // The file grew while it was read.
        return Err(too_large(bytes.len() as u64, limit_bytes));
    }
    Ok(bytes)
}

/// [`read_limited`] as UTF-8 text.
pub fn read_limited_text(path: &Path, limit_bytes: u64) -> std::io::Result<String> {
    String::from_utf8(read_limited(path, limit_bytes)?).map_err(|e| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "not UTF-8 text (invalid byte at offset {})",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

/// How a file's bytes were stored.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Packing {
    /// As they are.
    Plain,
    /// A gzip stream (`.gz`).
    Gzip,
    /// A zip archive holding one file, this member.
    Zip {
        /// The member's name inside the archive.
        member: String,
    },
}

impl Packing {
    /// A short description for metadata (`gzip`, `zip member X`); `None` for plain bytes.
    pub fn describe(&self) -> Option<String> {
        match self {
            Packing::Plain => None,
            Packing::Gzip => Some("gzip".to_string()),
            Packing::Zip { member } => Some(format!("zip member {member}")),
        }
    }
}

const GZIP_MAGIC: &[u8] = &[0x1f, 0x8b];
const ZIP_MAGIC: &[u8] = b"PK\x03\x04";

/// The content of `bytes`: inflated if they are a gzip stream or a zip archive of exactly one
/// file, as they are otherwise. The inflated content may not exceed `limit_bytes` (a small
/// archive can inflate to far more than it holds).
pub fn unpack(bytes: Vec<u8>, limit_bytes: u64) -> std::io::Result<(Vec<u8>, Packing)> {
    if bytes.starts_with(GZIP_MAGIC) {
        let decoder = flate2::read::MultiGzDecoder::new(bytes.as_slice());
        let inflated = read_capped(decoder, limit_bytes, "gzip stream")?;
        return Ok((inflated, Packing::Gzip));
    }
    if bytes.starts_with(ZIP_MAGIC) {
        return unzip_one(&bytes, limit_bytes);
    }
    Ok((bytes, Packing::Plain))
}

/// The one file of a zip archive.
fn unzip_one(bytes: &[u8], limit_bytes: u64) -> std::io::Result<(Vec<u8>, Packing)> {
    let invalid = |m: String| std::io::Error::new(std::io::ErrorKind::InvalidData, m);
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| invalid(format!("a zip archive that cannot be opened: {e}")))?;
    let members: Vec<String> = (0..archive.len())
        .filter_map(|i| {
            let file = archive.by_index(i).ok().filter(|f| f.is_file())?;
            file.name().ok().map(|name| name.to_string())
        })
        .collect();
    let [member] = members.as_slice() else {
        return Err(invalid(format!(
            "a zip archive of {} files ({}); ghostship reads an archive of exactly one: unpack it \
             and name the file you want",
            members.len(),
            members.join(", ")
        )));
    };
    let file = archive
        .by_name(member)
        .map_err(|e| invalid(format!("zip member {member}: {e}")))?;
    let inflated = read_capped(file, limit_bytes, "zip member")?;
    Ok((
        inflated,
        Packing::Zip {
            member: member.clone(),
        },
    ))
}

/// Everything `reader` yields, refusing more than `limit_bytes`.
fn read_capped(reader: impl Read, limit_bytes: u64, what: &str) -> std::io::Result<Vec<u8>> {
    let mut out = Vec::new();
    reader
        .take(limit_bytes.saturating_add(1))
        .read_to_end(&mut out)
        .map_err(|e| {
            std::io::Error::new(e.kind(), format!("a {what} that cannot be inflated: {e}"))
        })?;
    if out.len() as u64 > limit_bytes {
        return Err(std::io::Error::new(
            std::io::ErrorKind::FileTooLarge,
            format!(
                "the {what} inflates to more than the limit of {limit_bytes} bytes ({} MiB)",
                limit_bytes / (1024 * 1024)
            ),
        ));
    }
    Ok(out)
}

fn too_large(len_bytes: u64, limit_bytes: u64) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::FileTooLarge,
        format!(
            "the file is {len_bytes} bytes, more than the limit of {limit_bytes} bytes ({} MiB)",
            limit_bytes / (1024 * 1024)
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globs_match_files_sorted_without_hidden_ones() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["b.csv", "a.csv", ".hidden.csv", "c.txt", "sub/d.csv"] {
            let path = dir.path().join(name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, "x").unwrap();
        }
        let names = |pattern: &str| -> Vec<String> {
            glob_files(&dir.path().join(pattern))
                .unwrap()
                .iter()
                .map(|p| p.strip_prefix(dir.path()).unwrap().display().to_string())
                .collect()
        };
        assert_eq!(names("*.csv"), ["a.csv", "b.csv"]);
        assert_eq!(names("[ab].csv"), ["a.csv", "b.csv"]);
        assert_eq!(names("s*/*.csv"), ["sub/d.csv"]);
        assert_eq!(names("**/*.csv"), ["a.csv", "b.csv", "sub/d.csv"]);
        assert_eq!(names(".hidden.csv"), [".hidden.csv"]);
        assert!(glob_files(&dir.path().join(".h*.csv")).is_err());
        let err = glob_files(&dir.path().join("*.nc")).unwrap_err();
        assert!(err.starts_with("no file matches"), "{err}");
        assert!(glob_files(&dir.path().join("[.csv")).is_err());
        assert!(is_glob("a*") && is_glob("a?") && is_glob("[a]") && !is_glob("a.csv"));
    }

    #[test]
    fn an_unbounded_limit_reads_the_whole_file() {
        // `pipeline merge` copies outputs with no limit: u64::MAX must not wrap to "read 0".
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f");
        std::fs::write(&path, b"twelve bytes").unwrap();
        assert_eq!(read_limited(&path, u64::MAX).unwrap(), b"twelve bytes");
    }

    #[test]
    fn refuses_devices_folders_and_large_files() {
        let dir = tempfile::tempdir().unwrap();
        let err = read_limited(dir.path(), 10).unwrap_err();
        assert!(err.to_string().contains("not a regular file"), "{err}");
        if Path::new("/dev/zero").exists() {
            let err = read_limited(Path::new("/dev/zero"), 10).unwrap_err();
            assert!(err.to_string().contains("not a regular file"), "{err}");
        }
        let big = dir.path().join("big");
        std::fs::File::create(&big)
            .unwrap()
            .set_len(1 << 30)
            .unwrap();
        let err = read_limited(&big, 1 << 20).unwrap_err();
        assert!(err.to_string().contains("limit"), "{err}");
        let small = dir.path().join("small");
        std::fs::write(&small, b"abc").unwrap();
        assert_eq!(read_limited(&small, 3).unwrap(), b"abc");
        assert!(read_limited(&small, 2).is_err());
    }

    fn gzip(data: &[u8]) -> Vec<u8> {
        use std::io::Write;
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(data).unwrap();
        e.finish().unwrap()
    }

    fn zip_of(members: &[(&str, &[u8])]) -> Vec<u8> {
        use std::io::Write;
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        for (name, data) in members {
            w.start_file(*name, zip::write::SimpleFileOptions::default())
                .unwrap();
            w.write_all(data).unwrap();
        }
        w.finish().unwrap().into_inner()
    }

    #[test]
    fn unpacks_gzip_and_one_member_zips_within_the_limit() {
        let text = b"# header\n1,2,3\n".repeat(100);
        let (plain, how) = unpack(text.clone(), 1 << 20).unwrap();
        assert_eq!((plain, how), (text.clone(), Packing::Plain));
        let (got, how) = unpack(gzip(&text), 1 << 20).unwrap();
        assert_eq!((got, how), (text.clone(), Packing::Gzip));
        let (got, how) = unpack(zip_of(&[("a-data.txt", &text)]), 1 << 20).unwrap();
        assert_eq!(got, text);
        assert_eq!(how.describe().unwrap(), "zip member a-data.txt");
        // A bomb: small packed, large inflated.
        let err = unpack(gzip(&vec![b'x'; 1 << 20]), 1000).unwrap_err();
        assert!(err.to_string().contains("inflates to more than"), "{err}");
        let err = unpack(zip_of(&[("a", b"1"), ("b", b"2")]), 1000).unwrap_err();
        assert!(err.to_string().contains("2 files (a, b)"), "{err}");
        let mut broken = gzip(&text);
        broken.truncate(broken.len() / 2);
        let err = unpack(broken, 1 << 20).unwrap_err();
        assert!(err.to_string().contains("cannot be inflated"), "{err}");
    }
}
