//! Where the shipped defaults live, and where outputs go.
//!
//! The binary carries its defaults: the trained prior, the recorded LLM replies, the task
//! programs and the mocap catalog with its clips (`fixtures/` when it was built; `build.rs`).
//! On first use it unpacks them into a data directory, so an installed `mogen` runs from any
//! folder with its source clone moved or deleted. The defaults folder is, in order:
//!
//! 1. `$MOGEN_FIXTURES`: a fixtures folder used as it is (a clone's `fixtures/`, say, while
//!    editing recordings); nothing is unpacked;
//! 2. `$MOGEN_DATA_DIR/fixtures-<version>-<digest>`;
//! 3. `$XDG_DATA_HOME/mogen/fixtures-<version>-<digest>`;
//! 4. `$HOME/.local/share/mogen/fixtures-<version>-<digest>`.
//!
//! `<digest>` hashes the embedded files, so a binary with other defaults never reads a stale
//! copy. Unpacking writes a temporary folder and renames it into place, so an interrupted
//! first run leaves no half-written defaults.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/embedded_fixtures.rs"));
}

/// Marks a completely unpacked defaults folder.
const COMPLETE_MARK: &str = ".complete";

/// Why the defaults could not be made available.
#[derive(Debug, Clone, thiserror::Error)]
pub enum DefaultsError {
    /// No variable names a data directory.
    #[error("no data directory for the shipped defaults: set MOGEN_DATA_DIR (or HOME, XDG_DATA_HOME), or MOGEN_FIXTURES to a fixtures folder")]
    NoDataDir,
    /// Writing them failed.
    #[error("unpacking the shipped defaults into {path}: {message} (set MOGEN_DATA_DIR to a writable folder)")]
    Unpack {
        /// The folder.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// The name of the unpacked defaults folder for this binary.
fn folder_name() -> String {
    format!("fixtures-{}-{}", env!("CARGO_PKG_VERSION"), embedded::DIGEST)
}

/// The folder the defaults are unpacked to, from the variables the module doc lists (without
/// `MOGEN_FIXTURES`), or `None` when none is set.
fn data_dir(var: impl Fn(&str) -> Option<std::ffi::OsString>) -> Option<PathBuf> {
    let non_empty = |name: &str| var(name).filter(|v| !v.is_empty()).map(PathBuf::from);
    non_empty("MOGEN_DATA_DIR")
        .or_else(|| non_empty("XDG_DATA_HOME").map(|d| d.join("mogen")))
        .or_else(|| non_empty("HOME").map(|d| d.join(".local").join("share").join("mogen")))
        .map(|d| d.join(folder_name()))
}

/// Unpacks the embedded defaults into `dir` unless it is already complete; returns `dir`.
pub fn unpack_defaults(dir: &Path) -> Result<PathBuf, DefaultsError> {
    if dir.join(COMPLETE_MARK).is_file() {
        return Ok(dir.to_path_buf());
    }
    let fail = |message: String| DefaultsError::Unpack { path: dir.to_path_buf(), message };
    let parent = dir.parent().ok_or_else(|| fail("no parent folder".into()))?;
    std::fs::create_dir_all(parent).map_err(|e| fail(e.to_string()))?;
    let staging = parent.join(format!(".{}.part{}", folder_name(), std::process::id()));
    let written = (|| -> std::io::Result<()> {
        for (name, bytes) in embedded::FILES {
            let path = staging.join(name);
            if let Some(folder) = path.parent() {
                std::fs::create_dir_all(folder)?;
            }
            std::fs::write(path, bytes)?;
        }
        std::fs::write(staging.join(COMPLETE_MARK), embedded::DIGEST)?;
        // Another process may have finished first: its copy is identical, keep it.
        match std::fs::rename(&staging, dir) {
            Err(_) if dir.join(COMPLETE_MARK).is_file() => std::fs::remove_dir_all(&staging),
            other => other,
        }
    })();
    written.map_err(|e| {
        let _ = std::fs::remove_dir_all(&staging);
        fail(e.to_string())
    })?;
    Ok(dir.to_path_buf())
}

/// The defaults folder ([module doc](self)), unpacked on first use.
pub fn fixtures() -> Result<PathBuf, DefaultsError> {
    static FIXTURES: OnceLock<Result<PathBuf, DefaultsError>> = OnceLock::new();
    FIXTURES
        .get_or_init(|| {
            if let Some(dir) = std::env::var_os("MOGEN_FIXTURES").filter(|v| !v.is_empty()) {
                return Ok(PathBuf::from(dir));
            }
            unpack_defaults(&data_dir(|name| std::env::var_os(name)).ok_or(DefaultsError::NoDataDir)?)
        })
        .clone()
}

/// The defaults folder for a default argument value: [`fixtures`], or where it would be when it
/// cannot be unpacked (the command then fails opening the file; `main` reports why first).
pub fn fixtures_dir() -> PathBuf {
    fixtures().unwrap_or_else(|_| PathBuf::from(folder_name()))
}

/// The catalog of shipped mocap clips.
pub fn default_catalog() -> PathBuf {
    fixtures_dir().join("mocap").join("catalog.json")
}

/// The shipped motion corpus.
pub fn default_corpus() -> PathBuf {
    fixtures_dir().join("corpus").join("corpus.safetensors.gz")
}

/// Where `data build` writes the database by default.
pub fn default_database() -> PathBuf {
    PathBuf::from("out").join("database.safetensors")
}

/// The shipped trained prior.
pub fn default_prior() -> PathBuf {
    fixtures_dir().join("model").join("prior.safetensors")
}

/// The text–motion evaluator of the prior report (in the source tree's fixtures; not embedded).
pub fn default_evaluator() -> PathBuf {
    fixtures_dir().join("model").join("evaluator").join("evaluator.safetensors")
}

/// The held-out paraphrases of the prior report (in the source tree's fixtures; not embedded).
pub fn default_paraphrases() -> PathBuf {
    fixtures_dir().join("model").join("held_out_paraphrases.tsv")
}

/// The folder of the sentence encoders a prior may condition on (one folder per encoder).
pub fn text_models() -> PathBuf {
    fixtures_dir().join("text")
}

/// The recorded LLM exchanges that replay answers from.
pub fn default_recordings() -> PathBuf {
    fixtures_dir().join("llm").join("recorded")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_data_directory_follows_the_documented_order() {
        let vars = |set: &'static [(&'static str, &'static str)]| {
            move |name: &str| set.iter().find(|(k, _)| *k == name).map(|(_, v)| (*v).into())
        };
        let name = folder_name();
        assert_eq!(
            data_dir(vars(&[("MOGEN_DATA_DIR", "/d"), ("XDG_DATA_HOME", "/x"), ("HOME", "/h")])),
            Some(PathBuf::from("/d").join(&name))
        );
        assert_eq!(
            data_dir(vars(&[("XDG_DATA_HOME", "/x"), ("HOME", "/h")])),
            Some(PathBuf::from("/x/mogen").join(&name))
        );
        assert_eq!(
            data_dir(vars(&[("MOGEN_DATA_DIR", ""), ("HOME", "/h")])),
            Some(PathBuf::from("/h/.local/share/mogen").join(&name))
        );
        assert_eq!(data_dir(vars(&[])), None);
    }

    #[test]
    fn the_embedded_defaults_unpack_to_the_shipped_files() {
        let temp = tempfile::tempdir().unwrap();
        let dir = unpack_defaults(&temp.path().join(folder_name())).unwrap();
        let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures");
        for relative in ["model/prior.safetensors", "mocap/catalog.json", "tasks/rgdno_task2_low_barrier.json"] {
            assert_eq!(
                std::fs::read(dir.join(relative)).unwrap(),
                std::fs::read(source.join(relative)).unwrap(),
                "{relative}"
            );
        }
        let recorded = |d: &Path| std::fs::read_dir(d.join("llm/recorded")).unwrap().count();
        assert_eq!(recorded(&dir), recorded(&source));
        // Every catalog entry's file is there.
        let catalog: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("mocap/catalog.json")).unwrap()).unwrap();
        let text = catalog.to_string();
        for file in text.split("\"file\":\"").skip(1).filter_map(|s| s.split('"').next()) {
            assert!(dir.join("mocap").join(file).is_file(), "{file}");
        }
        // A second call finds it complete; no staging folder is left.
        assert_eq!(unpack_defaults(&dir).unwrap(), dir);
        assert_eq!(std::fs::read_dir(temp.path()).unwrap().count(), 1);
    }

    #[test]
    fn an_unwritable_data_directory_is_a_clear_error() {
        let temp = tempfile::tempdir().unwrap();
        let file = temp.path().join("a-file");
        std::fs::write(&file, "").unwrap();
        let err = unpack_defaults(&file.join("sub").join(folder_name())).unwrap_err().to_string();
        assert!(err.contains("a-file") && err.contains("MOGEN_DATA_DIR"), "{err}");
    }
}
