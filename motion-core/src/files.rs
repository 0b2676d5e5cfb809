//! Whole files. Reading is bounded: a file longer than its [`Limit`] is refused before it is
//! read past the limit, and every error names the file ([`FileError`], the one error for files
//! that cannot be read or are not in their format). Writing builds the file in memory and writes
//! it through a temporary file in the same folder and a rename, so a kill or a failure leaves the
//! previous file whole and no half-written one behind.

use std::io::Read;
use std::path::{Path, PathBuf};

use crate::limits::{Limit, LimitExceeded};

/// SHA-256 of `bytes` as 64 lower-case hex digits: the name of a file's contents (a prior in
/// every report, a recorded LLM reply's request).
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// A file that could not be read, or whose contents are not what its format says; each names
/// the file.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The file could not be opened or read.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The file is malformed, damaged or of another version.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong, and where in the file.
        message: String,
    },
    /// The file is longer than its limit.
    #[error(transparent)]
    TooLarge(#[from] LimitExceeded),
}

impl FileError {
    /// `error` reading `path`.
    pub fn io(path: &Path, error: &std::io::Error) -> Self {
        Self::Io { path: path.into(), message: error.to_string() }
    }

    /// `path` is not in its format: `message` says what and where.
    pub fn format(path: &Path, message: impl Into<String>) -> Self {
        Self::Format { path: path.into(), message: message.into() }
    }
}

/// Reads a whole file as UTF-8 text, refusing one longer than `limit` before reading past it
/// (so `/dev/zero` or a multi-gigabyte file fails at once). Errors name the path.
pub fn read_text(path: &Path, limit: &Limit) -> Result<String, FileError> {
    let bytes = read_bytes(path, limit)?;
    String::from_utf8(bytes).map_err(|e| {
        FileError::format(path, format!("not UTF-8 text (byte {} is not valid UTF-8)", e.utf8_error().valid_up_to()))
    })
}

/// Reads a whole file, refusing one longer than `limit` before reading past it. Errors name the
/// path.
pub fn read_bytes(path: &Path, limit: &Limit) -> Result<Vec<u8>, FileError> {
    let io = |e: std::io::Error| FileError::io(path, &e);
    let file = std::fs::File::open(path).map_err(io)?;
    if file.metadata().map_err(io)?.is_dir() {
        return Err(FileError::Io { path: path.into(), message: "is a folder, not a file".into() });
    }
    let mut bytes = Vec::new();
    file.take(limit.max.saturating_add(1)).read_to_end(&mut bytes).map_err(io)?;
    limit.check_stream(bytes.len() as u64, path.display())?;
    Ok(bytes)
}

/// A file that could not be written.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct WriteError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong.
    pub message: String,
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, creating
/// the folder; on any error the temporary file is removed and `path` is untouched.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    let fail = |message: String| WriteError { path: path.into(), message };
    let dir = match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) => dir.to_path_buf(),
        None => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(|e| fail(e.to_string()))?;
    let name = path.file_name().ok_or_else(|| fail("not a file name".into()))?;
    let tmp = dir.join(format!(".{}.part{}", name.to_string_lossy(), std::process::id()));
    let written = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(fail(e.to_string()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_endless_file_is_refused_without_reading_it_all() {
        let limit = Limit { name: "test", max: 4096, unit: "bytes", advice: "a test" };
        let err = read_bytes(Path::new("/dev/zero"), &limit).unwrap_err().to_string();
        assert!(err.contains("/dev/zero is at least 4097 bytes, over the limit of 4096 bytes"), "{err}");
        let dir = tempfile::tempdir().unwrap();
        let err = read_text(dir.path(), &limit).unwrap_err().to_string();
        assert!(err.contains("is a folder"), "{err}");
        let file = dir.path().join("a.json");
        std::fs::write(&file, b"{\xff}").unwrap();
        let err = read_text(&file, &limit).unwrap_err().to_string();
        assert!(err.contains("a.json: not UTF-8 text (byte 1"), "{err}");
    }

    #[test]
    fn atomic_write_replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub").join("a.txt");
        write_atomically(&path, b"one").unwrap();
        write_atomically(&path, b"two").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(path.parent().unwrap()).unwrap().count(), 1);
        // A folder where the file should go: an error naming the path, nothing left behind.
        let blocked = dir.path().join("blocked");
        std::fs::create_dir_all(blocked.join("x")).unwrap();
        let err = write_atomically(&blocked, b"three").unwrap_err();
        assert!(err.to_string().contains("blocked"), "{err}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }
}
