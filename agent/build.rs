//! Embeds the shipped defaults (`fixtures/` subsets) into the binary: writes
//! `$OUT_DIR/embedded_fixtures.rs` with every file's path relative to `fixtures/`, its bytes
//! (`include_bytes!`) and a digest of them all, which names the data directory they are unpacked
//! to (`src/paths.rs`).

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// What the installed binary needs: the prior, the sentence encoder it is conditioned on and
/// the WordNet verbs its prompts are restated with (each with its licence and provenance), the recorded LLM replies, the task programs, the mocap
/// catalog with its clips, and the motion corpus.
const EMBEDDED: [&str; 7] = [
    "model/prior.safetensors",
    "text/all-MiniLM-L6-v2",
    "text/wordnet",
    "llm/recorded",
    "tasks",
    "mocap",
    "corpus/corpus.safetensors.gz",
];

fn files_under(path: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    if path.is_dir() {
        let mut entries: Vec<PathBuf> =
            std::fs::read_dir(path)?.map(|e| e.map(|e| e.path())).collect::<Result<_, _>>()?;
        entries.sort();
        for entry in entries {
            files_under(&entry, out)?;
        }
    } else {
        out.push(path.to_path_buf());
    }
    Ok(())
}

fn main() -> std::io::Result<()> {
    let manifest = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").map_err(std::io::Error::other)?);
    let fixtures = manifest.join("..").join("fixtures").canonicalize()?;
    let mut files = Vec::new();
    for part in EMBEDDED {
        let path = fixtures.join(part);
        println!("cargo:rerun-if-changed={}", path.display());
        files_under(&path, &mut files)?;
    }
    let mut digest = Sha256::new();
    let mut table = String::from("/// Every embedded file: path relative to `fixtures/` (with `/`), bytes.\n");
    table.push_str("pub static FILES: &[(&str, &[u8])] = &[\n");
    for file in &files {
        let relative = file.strip_prefix(&fixtures).map_err(std::io::Error::other)?;
        let name = relative.components().map(|c| c.as_os_str().to_string_lossy()).collect::<Vec<_>>().join("/");
        digest.update(name.as_bytes());
        digest.update(std::fs::read(file)?);
        table.push_str(&format!("    ({name:?}, include_bytes!({:?})),\n", file.display().to_string()));
    }
    table.push_str("];\n");
    let hex: String = digest.finalize().iter().take(6).map(|b| format!("{b:02x}")).collect();
    table.push_str(&format!(
        "/// SHA-256 (first 12 hex digits) of the paths and bytes.\npub const DIGEST: &str = {hex:?};\n"
    ));
    let out = PathBuf::from(std::env::var("OUT_DIR").map_err(std::io::Error::other)?);
    std::fs::write(out.join("embedded_fixtures.rs"), table)
}
