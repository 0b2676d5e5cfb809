//! Errors and warnings of the importers.

use std::path::PathBuf;

use crate::files::FileError;
use crate::limits::LimitExceeded;

/// A non-fatal problem found while importing (the clip is still usable).
#[derive(Debug, Clone, PartialEq)]
pub struct ImportWarning {
    /// The file.
    pub path: PathBuf,
    /// What was found and what was done about it.
    pub message: String,
}

impl std::fmt::Display for ImportWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.message)
    }
}

/// Errors reading motion-capture files. Every variant names the file and where in it.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file is not valid JSON.
    #[error("{path}: line {line}, column {column}: not valid JSON: {message}")]
    Json {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// serde_json's message.
        message: String,
    },
    /// A structural problem at a known place in the file.
    #[error("{path}: {location}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Where: "frame 12, value 7", "line 40, joint LeftArm", ...
        location: String,
        /// What is wrong.
        message: String,
    },
    /// The file holds no frames.
    #[error("{path}: no frames")]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// The file could not be read, within its size limit, or is not in its format (the message
    /// names the file).
    #[error(transparent)]
    File(#[from] FileError),
    /// The clip is over a limit (the message names the file and where).
    #[error(transparent)]
    Limit(#[from] LimitExceeded),
}
