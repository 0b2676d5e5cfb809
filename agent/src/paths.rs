//! Default locations of the shipped fixtures and of outputs.

use std::path::PathBuf;

/// The `fixtures/` folder: `$MOGEN_FIXTURES` if set, else the one of the source tree the binary
/// was built from.
pub fn fixtures_dir() -> PathBuf {
    std::env::var_os("MOGEN_FIXTURES")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("fixtures"))
}

/// The catalog of shipped mocap clips.
pub fn default_catalog() -> PathBuf {
    fixtures_dir().join("mocap").join("catalog.json")
}

/// Where `data build` writes the database by default.
pub fn default_database() -> PathBuf {
    PathBuf::from("out").join("database.safetensors")
}

/// The shipped trained prior.
pub fn default_prior() -> PathBuf {
    fixtures_dir().join("model").join("prior.safetensors")
}

/// The recorded LLM exchanges that replay answers from.
pub fn default_recordings() -> PathBuf {
    fixtures_dir().join("llm").join("recorded")
}
