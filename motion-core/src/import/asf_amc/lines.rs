//! Line-level reading shared by the ASF and AMC parsers: numbered lines without comments, and
//! the error that names a line and a bone.

use std::path::Path;

use crate::import::error::ImportError;

/// An error at `line` of `path`, about `bone` when given.
pub(super) fn invalid(path: &Path, line: usize, bone: Option<&str>, message: impl Into<String>) -> ImportError {
    let location = match bone {
        Some(b) => format!("line {line}, bone {b}"),
        None => format!("line {line}"),
    };
    ImportError::Invalid { path: path.into(), location, message: message.into() }
}

/// Lines of `text` numbered from 1, comments (`#` to the end of the line) cut off.
pub(super) fn numbered_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    text.lines().enumerate().map(|(i, l)| (i + 1, l.split('#').next().unwrap_or_default()))
}
