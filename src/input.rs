//! Input — every input file is read through here. In: a path and a size limit. Out: the file's
//! bytes, or an `std::io::Error` saying why not. Only regular files are read (a FIFO, a device
//! such as `/dev/zero` or a folder is refused before it is opened), and never more than the
//! limit, so a mistyped path cannot block the program or read until memory runs out.

use std::io::Read;
use std::path::Path;

/// Largest sounding file read (an IGRA2 station record of decades of soundings fits).
pub const MAX_SOUNDING_BYTES: u64 = 512 * 1024 * 1024;
/// Largest TOML file read (scenes, synthetic atmospheres, pipelines).
pub const MAX_TOML_BYTES: u64 = 16 * 1024 * 1024;
/// Largest card image read.
pub const MAX_IMAGE_BYTES: u64 = 256 * 1024 * 1024;

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
        .take(limit_bytes + 1)
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
}
