//! The error of the HumanML3D reader that names a place in a file.

use std::path::Path;

use crate::import::error::ImportError;

/// An error at `location` of `path`.
pub(super) fn invalid(path: &Path, location: impl Into<String>, message: impl Into<String>) -> ImportError {
    ImportError::Invalid { path: path.to_path_buf(), location: location.into(), message: message.into() }
}
