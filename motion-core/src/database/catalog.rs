//! The catalog of source clips a database is built from: a JSON file listing each clip's file,
//! format and text label (`fixtures/mocap/catalog.json` for the shipped mocap). An entry may
//! also name a HumanML3D folder, whose clips bring their own captions, or an AMC motion with the
//! ASF skeleton it is recorded on.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::files::read_text;
use crate::import::asf_amc::{AsfAmcClip, AsfAmcOptions};
use crate::import::bvh::{BvhClip, BvhOptions};
use crate::import::deepmimic::DeepMimicClip;
use crate::import::humanml3d::HumanMl3dFolder;
use crate::import::isaaclab::IsaacAmpClip;
use crate::import::{ImportError, ImportWarning, MocapClip};
use crate::limits::MOCAP_FILE_BYTES;

/// File format of a source clip.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SourceFormat {
    /// DeepMimic humanoid JSON clip.
    Deepmimic,
    /// Biovision hierarchy file (units, up axis and rig detected).
    Bvh,
    /// Acclaim AMC motion (CMU, HDM05) at 120 fps, on the ASF skeleton named by the entry's
    /// `skeleton`.
    AsfAmc,
    /// Isaac Lab AMP humanoid motion (NumPy archive, z up).
    IsaaclabAmp,
    /// A HumanML3D dataset folder (`new_joint_vecs/`, `texts/`, `Mean.npy`, `Std.npy`): every
    /// clip in it, labelled with its first whole-clip caption (or its first caption).
    Humanml3d,
}

/// One catalog entry.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CatalogEntry {
    /// Path relative to the catalog file (a folder for [`SourceFormat::Humanml3d`]).
    pub file: PathBuf,
    /// File format.
    pub format: SourceFormat,
    /// Text label of the whole clip ("a person walks forward"); required, except for
    /// [`SourceFormat::Humanml3d`], whose clips are labelled by their captions.
    #[serde(default)]
    pub label: Option<String>,
    /// The ASF skeleton file of an [`SourceFormat::AsfAmc`] entry, relative to the catalog file;
    /// required for that format and refused for the others.
    #[serde(default)]
    pub skeleton: Option<PathBuf>,
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
    /// File stem (`<folder>/<id>` for a HumanML3D clip), unique within a catalog.
    pub name: String,
    /// Text label.
    pub label: String,
    /// The clip.
    pub clip: Box<dyn MocapClip>,
}

impl Catalog {
    /// Reads a catalog file (within [`MOCAP_FILE_BYTES`]).
    pub fn read(path: &Path) -> Result<Self, ImportError> {
        let text = read_text(path, &MOCAP_FILE_BYTES)?;
        let mut catalog: Catalog = serde_json::from_str(&text).map_err(|e| ImportError::Json {
            path: path.into(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })?;
        catalog.base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        for (i, entry) in catalog.clips.iter().enumerate() {
            let problem = match (entry.format, &entry.label) {
                (SourceFormat::Humanml3d, Some(_)) => {
                    Some("a humanml3d folder takes its labels from the captions in texts/; remove `label`")
                }
                (SourceFormat::Humanml3d, None) => None,
                (_, None) => Some("no label"),
                (_, Some(label)) if label.trim().is_empty() => Some("empty label"),
                (_, Some(_)) => None,
            }
            .or(match (entry.format, &entry.skeleton) {
                (SourceFormat::AsfAmc, None) => {
                    Some("an asf_amc entry needs `skeleton`, the ASF file of its AMC motion")
                }
                (SourceFormat::AsfAmc, Some(_)) | (_, None) => None,
                (_, Some(_)) => Some("only asf_amc entries take `skeleton`"),
            });
            if let Some(message) = problem {
                return Err(ImportError::Invalid {
                    path: path.into(),
                    location: format!("clips[{i}]"),
                    message: message.into(),
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
            let label = entry.label.clone().unwrap_or_default();
            let clip = match entry.format {
                SourceFormat::Deepmimic => keep(DeepMimicClip::read(&path)?, &mut warnings),
                SourceFormat::Bvh => keep(BvhClip::read(&path, &BvhOptions::default())?, &mut warnings),
                SourceFormat::IsaaclabAmp => keep(IsaacAmpClip::read(&path)?, &mut warnings),
                SourceFormat::AsfAmc => {
                    let asf = self.base.join(entry.skeleton.as_deref().unwrap_or(Path::new("")));
                    keep(AsfAmcClip::read(&asf, &path, &AsfAmcOptions::default())?, &mut warnings)
                }
                SourceFormat::Humanml3d => {
                    clips.extend(humanml3d_clips(&path, &name)?);
                    continue;
                }
            };
            clips.push(SourceClip { name, label, clip });
        }
        Ok((clips, warnings))
    }
}

/// Every clip of the HumanML3D folder `root` (called `name` in clip names), labelled with its
/// first whole-clip caption, or its first caption when all describe parts.
fn humanml3d_clips(root: &Path, name: &str) -> Result<Vec<SourceClip>, ImportError> {
    let folder = HumanMl3dFolder::open(root)?;
    let mut clips = Vec::new();
    for item in folder.items(folder.ids()?) {
        let item = item?;
        let caption = item.captions.iter().find(|c| c.frames.is_none()).or(item.captions.first());
        let label = caption.map(|c| c.text.clone()).unwrap_or_default();
        let clip = Box::new(folder.clip(&item)?);
        clips.push(SourceClip { name: format!("{name}/{}", item.id), label, clip });
    }
    Ok(clips)
}

/// Boxes an imported clip and keeps its warnings.
fn keep<C: MocapClip + 'static>(
    (clip, clip_warnings): (C, Vec<ImportWarning>),
    warnings: &mut Vec<ImportWarning>,
) -> Box<dyn MocapClip> {
    warnings.extend(clip_warnings);
    Box::new(clip)
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Tensor};

    use super::*;
    use crate::import::deepmimic::synthetic_walk;
    use crate::representation::{extract_features, FEATURE_DIM};

    /// A catalog of `entries` (JSON objects) in `dir`, read back.
    fn catalog(dir: &Path, entries: &str) -> Result<Catalog, ImportError> {
        let path = dir.join("catalog.json");
        std::fs::write(&path, format!("{{\"clips\": [{entries}]}}")).unwrap();
        Catalog::read(&path)
    }

    #[test]
    fn a_humanml3d_folder_is_a_source_of_captioned_clips() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().join("HumanML3D");
        std::fs::create_dir_all(root.join("new_joint_vecs")).unwrap();
        std::fs::create_dir_all(root.join("texts")).unwrap();
        Tensor::zeros(FEATURE_DIM, DType::F32, &Device::Cpu).unwrap().write_npy(root.join("Mean.npy")).unwrap();
        Tensor::ones(FEATURE_DIM, DType::F32, &Device::Cpu).unwrap().write_npy(root.join("Std.npy")).unwrap();
        let walk = synthetic_walk(61, 0.0);
        let features: Vec<f32> = extract_features(&walk).unwrap().features.into_iter().flatten().collect();
        let tensor = Tensor::from_vec(features, (60, FEATURE_DIM), &Device::Cpu).unwrap();
        tensor.write_npy(root.join("new_joint_vecs/000007.npy")).unwrap();
        std::fs::write(root.join("texts/000007.txt"), "a man walks on#a/DET#1.0#2.0\na person walks#a/DET#0.0#0.0\n")
            .unwrap();

        let sources = catalog(dir.path(), r#"{"file": "HumanML3D", "format": "humanml3d"}"#).unwrap().load().unwrap().0;
        assert_eq!(sources.len(), 1);
        let (name, label, clip) = (&sources[0].name, &sources[0].label, &sources[0].clip);
        assert_eq!((name.as_str(), label.as_str()), ("HumanML3D/000007", "a person walks"));
        assert!((clip.duration_s() - 59.0 / 20.0).abs() < 1e-9 && !clip.is_cyclic());
        // Features hold the motion up to the heading and start: pelvis heights agree.
        let above_feet = |p: &crate::skeleton::Pose| p[0].y - p.iter().map(|j| j.y).fold(f64::MAX, f64::min);
        let (got, want) = (above_feet(&clip.pose_at(1.0)), above_feet(&walk[20]));
        assert!((got - want).abs() < 1e-3, "pelvis {got} m above the feet, expected {want}");

        let e = catalog(dir.path(), r#"{"file": "HumanML3D", "format": "humanml3d", "label": "x"}"#).unwrap_err();
        assert!(e.to_string().contains("clips[0]") && e.to_string().contains("texts/"), "{e}");
        let e = catalog(dir.path(), r#"{"file": "a.bvh", "format": "bvh"}"#).unwrap_err();
        assert!(e.to_string().contains("clips[0]") && e.to_string().contains("label"), "{e}");
    }

    #[test]
    fn an_amc_entry_names_its_asf_skeleton() {
        let hdm05 = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/hdm05");
        let dir = tempfile::tempdir().unwrap();
        for file in ["HDM_bk.asf", "HDM_bk_hopBothLegs1hops_020_120.amc"] {
            std::fs::copy(hdm05.join(file), dir.path().join(file)).unwrap();
        }
        let amc = r#""file": "HDM_bk_hopBothLegs1hops_020_120.amc", "format": "asf_amc", "label": "a person hops""#;
        let entry = format!(r#"{{{amc}, "skeleton": "HDM_bk.asf"}}"#);
        let (sources, warnings) = catalog(dir.path(), &entry).unwrap().load().unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!(
            (sources[0].name.as_str(), sources[0].label.as_str()),
            ("HDM_bk_hopBothLegs1hops_020_120", "a person hops")
        );
        assert!((sources[0].clip.duration_s() - 55.0 / 120.0).abs() < 1e-12);

        let e = catalog(dir.path(), &format!("{{{amc}}}")).unwrap_err().to_string();
        assert!(e.contains("clips[0]") && e.contains("needs `skeleton`"), "{e}");
        let e = catalog(dir.path(), r#"{"file": "a.bvh", "format": "bvh", "label": "x", "skeleton": "a.asf"}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("clips[0]") && e.contains("only asf_amc entries take `skeleton`"), "{e}");
    }
}
