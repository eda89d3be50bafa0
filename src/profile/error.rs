//! Stage 2 — fit: the errors. In: anything that can go wrong while fitting a sounding or reading a
//! synthetic atmosphere. Out: one typed [`ProfileError`] that names the file, line and column.

use std::path::PathBuf;

/// Why a profile could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    /// A synthetic atmosphere file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A synthetic atmosphere file is not valid TOML for the schema, or holds an invalid value.
    /// Line and column are 1-based and point at the offending key, value or table.
    #[error("{path}:{line}:{column}: {message}")]
    Syntax {
        /// The file (or the description passed for in-memory text).
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column (in characters).
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A sounding cannot be fitted (empty, unsorted, non-finite or implausible values).
    #[error("{path}: line {line}: {message}")]
    BadSounding {
        /// The sounding's source file.
        path: PathBuf,
        /// 1-based line of the offending level in its source file (0 when not tied to a level).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// An option is out of its valid range.
    #[error("invalid option {name}: {message}")]
    BadOption {
        /// The option's field name.
        name: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The layer fit's optimiser (argmin) stopped with an error.
    #[error("the layer fit of {path} failed in the optimiser: {message}")]
    LayerFitFailed {
        /// The sounding being fitted.
        path: std::path::PathBuf,
        /// argmin's error, as text (its error type is not `Clone`/`'static`-friendly).
        message: String,
    },
}

/// 1-based line and column (in characters) of a byte offset in `text`.
pub(crate) fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    // Step back to a char boundary so slicing cannot panic on a malformed offset.
    let mut end = offset;
    while end > 0 && !text.is_char_boundary(end) {
        end -= 1;
    }
    let before = &text[..end];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before[line_start..].chars().count() + 1;
    (line, column)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_and_column_are_one_based() {
        let text = "a = 1\nbb = 2\n";
        assert_eq!(line_column(text, 0), (1, 1));
        assert_eq!(line_column(text, 6), (2, 1));
        assert_eq!(line_column(text, 9), (2, 4));
        assert_eq!(line_column(text, 1000), (3, 1));
    }
}
