//! The error of the BVH reader that names a line and a joint.

use std::path::Path;

use crate::import::error::ImportError;

/// An error at `line` of `path`, about `joint` when given.
pub(super) fn invalid(path: &Path, line: usize, joint: Option<&str>, message: impl Into<String>) -> ImportError {
    let location = match joint {
        Some(j) => format!("line {line}, joint {j}"),
        None => format!("line {line}"),
    };
    ImportError::Invalid { path: path.into(), location, message: message.into() }
}
