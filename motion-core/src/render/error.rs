//! What can go wrong writing a picture, and the PNG writer that reports it.

/// Errors writing a picture.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// Nothing to draw or an impossible size.
    #[error("cannot draw: {0}")]
    Empty(String),
    /// Encoding or writing the picture failed.
    #[error("{path}: {message}")]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// What went wrong.
        message: String,
    },
}

pub(super) fn save_png(pixmap: &tiny_skia::Pixmap, path: &std::path::Path) -> Result<(), RenderError> {
    let write = |message: String| RenderError::Write { path: path.into(), message };
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(|e| write(e.to_string()))?;
    }
    pixmap.save_png(path).map_err(|e| write(e.to_string()))
}
