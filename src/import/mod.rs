//! Converters from real data sets' formats into cells.
//!
//! Each importer reads files in the instrument's or the data set's own units and conventions and
//! produces a [`Cell`] in SI units (metres, radians) that passes the cell-file validation of
//! [`crate::domain::cell`], plus human-readable notes on what was assumed or left out.
//!
//! - [`ur10_ipa`]: the UR10 laser-tracker data set (semicolon CSV with decimal commas, 6D poses).
//! - [`three_reflector`]: a joints file plus one positions file per tracker reflector.
//!
//! Errors name the file, the 1-based line and the column (or joint) of the offending value; no
//! input makes an importer panic.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::cell::Cell;
use crate::kinematics::model::ModelError;

pub mod three_reflector;
pub mod ur10_ipa;

/// An imported cell and the notes an importer wants the user to read (assumptions, data left out,
/// anomalies found in the files).
#[derive(Clone, Debug, PartialEq)]
pub struct Imported {
    pub cell: Cell,
    pub notes: Vec<String>,
}

/// Why a data set could not be imported.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A value that does not parse or is out of range.
    #[error("{} line {line}, column {column}: {reason}", file.display())]
    Value { file: PathBuf, line: u64, column: String, reason: String },
    /// A line whose shape is wrong (number of fields, undecodable text).
    #[error("{} line {line}: {reason}", file.display())]
    Line { file: PathBuf, line: u64, reason: String },
    #[error("{}: no column '{column}' in the header", file.display())]
    MissingColumn { file: PathBuf, column: String },
    #[error("{}: {reason}", file.display())]
    File { file: PathBuf, reason: String },
    #[error("{}: not a 4×4 homogeneous transform: {reason}", file.display())]
    Matrix { file: PathBuf, reason: String },
    /// Line-aligned files that do not hold the same number of poses.
    #[error("{} has {count} poses but {} has {other_count}", file.display(), other.display())]
    PoseCount { file: PathBuf, count: usize, other: PathBuf, other_count: usize },
    #[error("{0}")]
    Input(String),
    #[error("robot model: {0}")]
    Model(#[from] ModelError),
}

impl ImportError {
    fn io(path: &Path, source: std::io::Error) -> Self {
        ImportError::Io { path: path.to_path_buf(), source }
    }

    fn value(file: &Path, line: u64, column: impl fmt::Display, reason: impl Into<String>) -> Self {
        ImportError::Value { file: file.to_path_buf(), line, column: column.to_string(), reason: reason.into() }
    }

    fn line(file: &Path, line: u64, reason: impl Into<String>) -> Self {
        ImportError::Line { file: file.to_path_buf(), line, reason: reason.into() }
    }
}

/// The whole text of a file.
fn read_text(path: &Path) -> Result<String, ImportError> {
    std::fs::read_to_string(path).map_err(|e| ImportError::io(path, e))
}

/// A run of 1-based line numbers written compactly for notes: `3, 7, 12 and 4 more`.
fn line_list(lines: &[u64]) -> String {
    const SHOWN: usize = 5;
    let head: Vec<String> = lines.iter().take(SHOWN).map(u64::to_string).collect();
    if lines.len() > SHOWN { format!("{} and {} more", head.join(", "), lines.len() - SHOWN) } else { head.join(", ") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_read_file_line_column_reason() {
        let e = ImportError::value(Path::new("m.csv"), 17, "elbow_joint", "'1,2x' is not a number");
        assert_eq!(e.to_string(), "m.csv line 17, column elbow_joint: '1,2x' is not a number");
        let e = ImportError::PoseCount { file: "a.txt".into(), count: 3, other: "b.txt".into(), other_count: 4 };
        assert_eq!(e.to_string(), "a.txt has 3 poses but b.txt has 4");
    }

    #[test]
    fn line_lists_are_short() {
        assert_eq!(line_list(&[3, 7]), "3, 7");
        assert_eq!(line_list(&[1, 2, 3, 4, 5, 6, 7]), "1, 2, 3, 4, 5 and 2 more");
    }
}
