//! What can go wrong turning motions into files, and the atomic write that reports it.

use std::path::{Path, PathBuf};

use crate::files::WriteError;

/// Errors turning motions into files.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// A joint position is NaN or infinite.
    #[error("sample {sample}, frame {frame}, joint `{joint}`: position {value:?} is not finite")]
    NonFinite {
        /// Sample index.
        sample: usize,
        /// Frame index.
        frame: usize,
        /// Joint name.
        joint: &'static str,
        /// The offending position, m.
        value: [f64; 3],
    },
    /// Nothing to export, or samples of different lengths where one length is needed.
    #[error("cannot export: {0}")]
    Shape(String),
    /// A rig to retarget onto cannot be read or matched to our joints (the message names the
    /// file).
    #[error("cannot retarget: {0}")]
    Rig(String),
    /// An input file is unreadable, malformed or over a limit.
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// Writing a file failed.
    #[error("{path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// [`crate::files::write_atomically`] with the export's error.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    Ok(crate::files::write_atomically(path, bytes)?)
}

impl From<WriteError> for ExportError {
    fn from(WriteError { path, message }: WriteError) -> Self {
        ExportError::Write { path, message }
    }
}
