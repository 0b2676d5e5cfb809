//! The catalog of source clips a database is built from: a JSON file listing each clip's file,
//! format and text label (`fixtures/mocap/catalog.json` for the shipped mocap).

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::import::bvh::{BvhClip, BvhOptions};
use crate::import::deepmimic::DeepMimicClip;
use crate::import::isaaclab::IsaacAmpClip;
use crate::import::{ImportError, ImportWarning, MocapClip};

/// File format of a source clip.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SourceFormat {
    /// DeepMimic humanoid JSON clip.
    Deepmimic,
    /// Biovision hierarchy file (units, up axis and rig detected).
    Bvh,
    /// Isaac Lab AMP humanoid motion (NumPy archive, z up).
    IsaaclabAmp,
}

/// One catalog entry.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CatalogEntry {
    /// Path relative to the catalog file.
    pub file: PathBuf,
    /// File format.
    pub format: SourceFormat,
    /// Text label of the whole clip ("a person walks forward").
    pub label: String,
}

/// A list of source clips with labels.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Catalog {
    /// The clips.
    pub clips: Vec<CatalogEntry>,
    #[serde(skip)]
    base: PathBuf,
}

/// A source clip loaded and ready to sample.
pub struct SourceClip {
    /// File stem, unique within a catalog.
    pub name: String,
    /// Text label.
    pub label: String,
    /// The clip.
    pub clip: Box<dyn MocapClip>,
}

impl Catalog {
    /// Reads a catalog file.
    pub fn read(path: &Path) -> Result<Self, ImportError> {
        let text = std::fs::read_to_string(path).map_err(|source| ImportError::Io { path: path.into(), source })?;
        let mut catalog: Catalog = serde_json::from_str(&text).map_err(|e| ImportError::Json {
            path: path.into(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })?;
        catalog.base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        for (i, entry) in catalog.clips.iter().enumerate() {
            if entry.label.trim().is_empty() {
                return Err(ImportError::Invalid {
                    path: path.into(),
                    location: format!("clips[{i}]"),
                    message: "empty label".into(),
                });
            }
        }
        Ok(catalog)
    }

    /// Loads every clip; warnings (e.g. normalised quaternions) are returned, not printed.
    pub fn load(&self) -> Result<(Vec<SourceClip>, Vec<ImportWarning>), ImportError> {
        let mut clips = Vec::with_capacity(self.clips.len());
        let mut warnings = Vec::new();
        for entry in &self.clips {
            let path = self.base.join(&entry.file);
            let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let clip = match entry.format {
                SourceFormat::Deepmimic => keep(DeepMimicClip::read(&path)?, &mut warnings),
                SourceFormat::Bvh => keep(BvhClip::read(&path, &BvhOptions::default())?, &mut warnings),
                SourceFormat::IsaaclabAmp => keep(IsaacAmpClip::read(&path)?, &mut warnings),
            };
            clips.push(SourceClip { name, label: entry.label.clone(), clip });
        }
        Ok((clips, warnings))
    }
}

/// Boxes an imported clip and keeps its warnings.
fn keep<C: MocapClip + 'static>(
    (clip, clip_warnings): (C, Vec<ImportWarning>),
    warnings: &mut Vec<ImportWarning>,
) -> Box<dyn MocapClip> {
    warnings.extend(clip_warnings);
    Box::new(clip)
}
