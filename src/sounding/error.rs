//! Stage 1 — ingest: the error type. In: whatever went wrong while reading a sounding. Out: a
//! [`SoundingError`] that names the file, the 1-based line and the column where relevant, e.g.
//! `data/x.csv: line 17, column temperature_c: cannot parse "abc" as a number`.

use std::path::{Path, PathBuf};

/// What [`SoundingError::NetcdfNotBuilt`] says after the file name.
pub const NETCDF_NOT_BUILT: &str = "the file is a netCDF file; this ghostship was built without \
     netCDF support: rebuild with `cargo build --release --features netcdf` (needs libnetcdf-dev)";

/// Why a sounding could not be read. Every variant names the file; line and column are given
/// whenever the problem sits in one place of the file.
#[derive(Debug, thiserror::Error)]
pub enum SoundingError {
    /// The file could not be read at all.
    #[error("{}: cannot read the file: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error.
        #[source]
        source: std::io::Error,
    },
    /// The bytes are not UTF-8 text.
    #[error("{}: line {line}: not UTF-8 text (invalid byte at offset {byte_offset})", path.display())]
    NotUtf8 {
        /// The file.
        path: PathBuf,
        /// 1-based line holding the first invalid byte.
        line: usize,
        /// 0-based byte offset of the first invalid byte in the file.
        byte_offset: usize,
    },
    /// The file is netCDF, and this build was made without the cargo feature `netcdf`.
    #[error("{}: {}", path.display(), NETCDF_NOT_BUILT)]
    NetcdfNotBuilt {
        /// The file.
        path: PathBuf,
    },
    /// A problem with the file as a whole (unknown format, too few levels, no such IGRA2 time…).
    #[error("{}: {message}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A problem with one line (a row that cannot be placed, heights out of order…).
    #[error("{}: line {line}: {message}", path.display())]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A problem with one field of one line (not a number, a sentinel, out of range…).
    #[error("{}: line {line}, column {column}: {message}", path.display())]
    Field {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// Column name (as in the file's header, or the format's documented field name).
        column: String,
        /// What is wrong.
        message: String,
    },
}

impl SoundingError {
    /// The 1-based line the error points at, if it points at one.
    pub fn line(&self) -> Option<usize> {
        match self {
            SoundingError::NotUtf8 { line, .. }
            | SoundingError::Line { line, .. }
            | SoundingError::Field { line, .. } => Some(*line),
            SoundingError::Io { .. }
            | SoundingError::NetcdfNotBuilt { .. }
            | SoundingError::File { .. } => None,
        }
    }

    /// The column the error points at, if it points at one.
    pub fn column(&self) -> Option<&str> {
        match self {
            SoundingError::Field { column, .. } => Some(column),
            _ => None,
        }
    }

    /// The message without the file name: `line 17, column temperature_c: cannot parse …`.
    pub fn detail(&self) -> String {
        match self {
            SoundingError::Io { source, .. } => format!("cannot read the file: {source}"),
            SoundingError::NotUtf8 {
                line, byte_offset, ..
            } => format!("line {line}: not UTF-8 text (invalid byte at offset {byte_offset})"),
            SoundingError::NetcdfNotBuilt { .. } => NETCDF_NOT_BUILT.to_string(),
            SoundingError::File { message, .. } => message.clone(),
            SoundingError::Line { line, message, .. } => format!("line {line}: {message}"),
            SoundingError::Field {
                line,
                column,
                message,
                ..
            } => format!("line {line}, column {column}: {message}"),
        }
    }

    pub(crate) fn file(path: &Path, message: impl Into<String>) -> Self {
        SoundingError::File {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    pub(crate) fn line_error(path: &Path, line: usize, message: impl Into<String>) -> Self {
        SoundingError::Line {
            path: path.to_path_buf(),
            line,
            message: message.into(),
        }
    }

    pub(crate) fn field(
        path: &Path,
        line: usize,
        column: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        SoundingError::Field {
            path: path.to_path_buf(),
            line,
            column: column.into(),
            message: message.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_error_reads_like_the_issue_example() {
        let e = SoundingError::field(
            Path::new("data/x.csv"),
            17,
            "temperature_c",
            "cannot parse \"abc\" as a number",
        );
        assert_eq!(
            e.to_string(),
            "data/x.csv: line 17, column temperature_c: cannot parse \"abc\" as a number"
        );
        assert_eq!(e.line(), Some(17));
        assert_eq!(e.column(), Some("temperature_c"));
    }
}
