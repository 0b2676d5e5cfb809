//! HumanML3D dataset folders: 263-d feature clips, their captions, Mean/Std and the splits.
//!
//! Layout (as produced by HumanML3D's scripts):
//!
//! ```text
//! <root>/new_joint_vecs/<id>.npy   float32 [frames, 263] (float64 is accepted too)
//! <root>/texts/<id>.txt            one caption a line: `caption#word/POS ...#start_s#end_s`
//! <root>/Mean.npy, <root>/Std.npy  [263] statistics of the training set
//! <root>/{train,val,test}.txt      optional split files, one id a line
//! ```
//!
//! A caption's `start_s#end_s` of `0.0#0.0` (NaN counts as 0.0) describes the whole clip;
//! otherwise it describes frames `[⌊start_s·20⌋, ⌊end_s·20⌋)` (HumanML3D's
//! `motion[int(f_tag*20):int(to_tag*20)]`, `data_loaders/humanml/data/dataset.py`).
//!
//! The `.npy` reader is our own ([`crate::npy`]): it checks the header against the file's size before
//! reading, so a truncated or corrupt file is an error naming the file, never a panic or a huge
//! allocation. [`HumanMl3dClip`] poses a clip's features for the motion database.

mod clip;
mod error;

use std::ops::Range;
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};

use crate::npy::read_float_npy;
pub use clip::HumanMl3dClip;

use super::error::ImportError;
use super::values::check_clip_length;
use crate::files::{read_text, FileError};
use crate::limits::MOCAP_FILE_BYTES;
use crate::representation::{FeatureFrame, MeanStd, FEATURE_DIM};
use crate::skeleton::FPS;
use error::invalid;

/// Which clips (and sub-clips) a training set keeps, by length in feature frames.
///
/// HumanML3D's `Text2MotionDatasetV2` keeps `40 ≤ frames < 200` ([`LengthRule::HUMANML3D`]);
/// MDM then crops to at most 196 frames (`max_motion_length`) when it samples a batch, which
/// is the trainer's job, not the reader's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LengthRule {
    /// Shortest accepted clip, frames (inclusive).
    pub min_frames: usize,
    /// First rejected length, frames (exclusive upper bound).
    pub max_frames_exclusive: usize,
}

impl LengthRule {
    /// HumanML3D's training rule: `40 ≤ frames < 200`.
    pub const HUMANML3D: Self = Self { min_frames: 40, max_frames_exclusive: 200 };

    /// Whether a clip of `frames` feature frames is kept.
    pub fn accepts(&self, frames: usize) -> bool {
        (self.min_frames..self.max_frames_exclusive).contains(&frames)
    }
}

impl Default for LengthRule {
    fn default() -> Self {
        Self::HUMANML3D
    }
}

/// One annotation of a clip.
#[derive(Debug, Clone, PartialEq)]
pub struct Caption {
    /// The sentence, as written by the annotator.
    pub text: String,
    /// spaCy tokens `word/POS` (HumanML3D's second field; used by the T2M evaluator).
    pub tokens: Vec<String>,
    /// `None`: the caption describes the whole clip. `Some(r)`: it describes feature frames
    /// `r` (20 fps), clamped to the clip; may be empty when the annotation lies past the end.
    pub frames: Option<Range<usize>>,
}

/// One clip of the dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct HumanMl3dItem {
    /// The file stem, e.g. `"000021"` or `"M000021"` (mirrored); sub-clips made by
    /// [`HumanMl3dItem::into_training_items`] are named `"<id>#<start>..<end>"` (frames).
    pub id: String,
    /// Un-normalised features, one `[f32; 263]` per frame (20 fps).
    pub features: Vec<FeatureFrame>,
    /// The clip's captions.
    pub captions: Vec<Caption>,
}

impl HumanMl3dItem {
    /// Number of feature frames.
    pub fn frames(&self) -> usize {
        self.features.len()
    }

    /// The features as a tensor `[frames, 263]`, f32, un-normalised.
    pub fn to_tensor(&self, device: &Device) -> candle_core::Result<Tensor> {
        let flat: Vec<f32> = self.features.iter().flatten().copied().collect();
        Tensor::from_vec(flat, (self.features.len(), FEATURE_DIM), device)
    }

    /// HumanML3D's training-set construction for this clip (`Text2MotionDatasetV2.__init__`):
    /// nothing if the clip's length fails `rule`; each caption with a frame range whose
    /// sub-clip passes `rule` becomes its own item (failing ones are dropped); the clip
    /// itself is kept with its whole-clip captions if it has any. Every caption of a returned
    /// item describes that whole item (`frames: None`).
    pub fn into_training_items(self, rule: &LengthRule) -> Vec<HumanMl3dItem> {
        if !rule.accepts(self.frames()) {
            return Vec::new();
        }
        let mut out = Vec::new();
        let mut whole = Vec::new();
        for caption in self.captions {
            match caption.frames.clone() {
                None => whole.push(caption),
                Some(r) if rule.accepts(r.len()) => out.push(HumanMl3dItem {
                    id: format!("{}#{}..{}", self.id, r.start, r.end),
                    features: self.features[r].to_vec(),
                    captions: vec![Caption { frames: None, ..caption }],
                }),
                Some(_) => {}
            }
        }
        if !whole.is_empty() {
            out.insert(0, HumanMl3dItem { id: self.id, features: self.features, captions: whole });
        }
        out
    }
}

/// A HumanML3D folder whose layout and statistics have been checked.
#[derive(Debug, Clone)]
pub struct HumanMl3dFolder {
    root: PathBuf,
    mean_std: MeanStd,
}

impl HumanMl3dFolder {
    /// Checks that `root` has `new_joint_vecs/` and `texts/`, and reads `Mean.npy`/`Std.npy`.
    pub fn open(root: &Path) -> Result<Self, ImportError> {
        for dir in ["new_joint_vecs", "texts"] {
            let path = root.join(dir);
            if !path.is_dir() {
                return Err(FileError::Io { path, message: "folder not found".into() }.into());
            }
        }
        let stats = |name: &str| -> Result<Vec<f32>, ImportError> {
            let path = root.join(name);
            let array = read_float_npy(&path, |shape| match shape {
                [FEATURE_DIM] => Ok(()),
                _ => Err(invalid(&path, "npy header", format!("shape {shape:?}; expected [{FEATURE_DIM}]"))),
            })?;
            Ok(array.data)
        };
        let (mean, std) = (stats("Mean.npy")?, stats("Std.npy")?);
        let mean_std = MeanStd::from_vecs(mean, std, &Device::Cpu)
            .map_err(|e| invalid(&root.join("Mean.npy"), "statistics (with Std.npy)", e.to_string()))?;
        Ok(Self { root: root.to_path_buf(), mean_std })
    }

    /// The dataset folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The dataset's `Mean.npy`/`Std.npy`, what MDM normalises with.
    pub fn mean_std(&self) -> &MeanStd {
        &self.mean_std
    }

    /// Every id with a `new_joint_vecs/<id>.npy`, sorted.
    pub fn ids(&self) -> Result<Vec<String>, ImportError> {
        let dir = self.root.join("new_joint_vecs");
        let io = |e| ImportError::from(FileError::io(&dir, &e));
        let mut ids = Vec::new();
        for entry in std::fs::read_dir(&dir).map_err(io)? {
            let path = entry.map_err(io)?.path();
            if path.extension().is_some_and(|e| e == "npy") {
                if let Some(stem) = path.file_stem().and_then(|s| s.to_str()) {
                    ids.push(stem.to_owned());
                }
            }
        }
        ids.sort();
        Ok(ids)
    }

    /// The ids listed in `<root>/<name>.txt` (`"train"`, `"val"`, `"test"`, ...), in file order.
    pub fn split_ids(&self, name: &str) -> Result<Vec<String>, ImportError> {
        let path = self.root.join(format!("{name}.txt"));
        let text = read_text(&path, &MOCAP_FILE_BYTES)?;
        let ids: Vec<String> = text.lines().map(str::trim).filter(|l| !l.is_empty()).map(str::to_owned).collect();
        if ids.is_empty() {
            return Err(ImportError::Empty { path });
        }
        Ok(ids)
    }

    /// `new_joint_vecs/<id>.npy`.
    fn features_path(&self, id: &str) -> PathBuf {
        self.root.join("new_joint_vecs").join(format!("{id}.npy"))
    }

    /// Reads one clip: its features and its captions, both validated.
    pub fn load_item(&self, id: &str) -> Result<HumanMl3dItem, ImportError> {
        let features = read_features(&self.features_path(id))?;
        let captions = read_captions(&self.root.join("texts").join(format!("{id}.txt")), features.len())?;
        Ok(HumanMl3dItem { id: id.to_owned(), features, captions })
    }

    /// Poses a clip read by [`HumanMl3dFolder::load_item`] (see [`HumanMl3dClip`]); errors name
    /// its features file.
    pub fn clip(&self, item: &HumanMl3dItem) -> Result<HumanMl3dClip, ImportError> {
        HumanMl3dClip::from_features(&item.features, &self.features_path(&item.id))
    }

    /// Reads the clips `ids` lazily, one at a time (the whole dataset is about 1 GB of f32).
    pub fn items<'a>(
        &'a self,
        ids: impl IntoIterator<Item = String> + 'a,
    ) -> impl Iterator<Item = Result<HumanMl3dItem, ImportError>> + 'a {
        ids.into_iter().map(move |id| self.load_item(&id))
    }

    /// Reads every clip of split `name` (see [`HumanMl3dFolder::split_ids`]). With a `rule`,
    /// the clips go through [`HumanMl3dItem::into_training_items`] (HumanML3D's training set
    /// construction); without, they come back as stored.
    pub fn load_split(&self, name: &str, rule: Option<&LengthRule>) -> Result<Vec<HumanMl3dItem>, ImportError> {
        let mut out = Vec::new();
        for item in self.items(self.split_ids(name)?) {
            match rule {
                Some(rule) => out.extend(item?.into_training_items(rule)),
                None => out.push(item?),
            }
        }
        Ok(out)
    }
}

/// Reads `new_joint_vecs/<id>.npy`: shape `[frames, 263]` with at most [`CLIP_FRAMES`]
/// frames (checked from the header), every value finite.
///
/// [`CLIP_FRAMES`]: crate::limits::CLIP_FRAMES
fn read_features(path: &Path) -> Result<Vec<FeatureFrame>, ImportError> {
    let array = read_float_npy(path, |shape| match *shape {
        [0, FEATURE_DIM] => Err(ImportError::Empty { path: path.to_path_buf() }),
        [frames, FEATURE_DIM] => Ok(check_clip_length(
            (frames - 1) as f64 / FPS,
            format_args!("{}: npy header: shape {shape:?}", path.display()),
        )?),
        _ => Err(invalid(path, "npy header", format!("shape {shape:?}; expected [frames, {FEATURE_DIM}]"))),
    })?;
    let mut frames = Vec::with_capacity(array.shape[0]);
    for (frame, chunk) in array.data.chunks_exact(FEATURE_DIM).enumerate() {
        if let Some(feature) = chunk.iter().position(|v| !v.is_finite()) {
            return Err(invalid(
                path,
                format!("frame {frame}, feature {feature}"),
                format!("value {} is not finite", chunk[feature]),
            ));
        }
        let mut f = [0f32; FEATURE_DIM];
        f.copy_from_slice(chunk);
        frames.push(f);
    }
    Ok(frames)
}

/// Reads `texts/<id>.txt` for a clip of `clip_frames` feature frames.
fn read_captions(path: &Path, clip_frames: usize) -> Result<Vec<Caption>, ImportError> {
    let text = read_text(path, &MOCAP_FILE_BYTES)?;
    let mut captions = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let location = format!("line {}", i + 1);
        captions.push(parse_caption(line, clip_frames).map_err(|message| invalid(path, location, message))?);
    }
    if captions.is_empty() {
        return Err(ImportError::Empty { path: path.to_path_buf() });
    }
    Ok(captions)
}

/// Parses `caption#tokens#start_s#end_s`. Splits from the right so a `#` inside the caption
/// stays in the caption.
fn parse_caption(line: &str, clip_frames: usize) -> Result<Caption, String> {
    let mut fields = line.rsplitn(4, '#');
    let (Some(end), Some(start), Some(tokens), Some(text)) =
        (fields.next(), fields.next(), fields.next(), fields.next())
    else {
        return Err(format!("expected `caption#tokens#start#end`, found {} field(s)", line.split('#').count()));
    };
    let seconds = |name: &str, s: &str| -> Result<f64, String> {
        let v: f64 = s.trim().parse().map_err(|_| format!("{name} time `{s}` is not a number"))?;
        // NaN means "not annotated", which HumanML3D reads as 0.0.
        let v = if v.is_nan() { 0.0 } else { v };
        if !v.is_finite() || v < 0.0 {
            return Err(format!("{name} time `{s}` must be a finite number of seconds ≥ 0"));
        }
        Ok(v)
    };
    let (start_s, end_s) = (seconds("start", start)?, seconds("end", end)?);
    let text = text.trim();
    if text.is_empty() {
        return Err("empty caption".into());
    }
    let frames = if start_s == 0.0 && end_s == 0.0 {
        None
    } else if end_s < start_s {
        return Err(format!("end time {end_s} s is before start time {start_s} s"));
    } else {
        // int(t * 20) in HumanML3D: truncation, then Python's slice clamping.
        let to_frame = |t: f64| ((t * FPS) as usize).min(clip_frames);
        Some(to_frame(start_s)..to_frame(end_s))
    };
    Ok(Caption { text: text.to_owned(), tokens: tokens.split_whitespace().map(str::to_owned).collect(), frames })
}

#[cfg(test)]
mod tests {
    use candle_core::DType;

    use super::*;

    fn frames(n: usize, seed: f32) -> Tensor {
        let v: Vec<f32> = (0..n * FEATURE_DIM).map(|i| seed + (i % 97) as f32 * 0.01).collect();
        Tensor::from_vec(v, (n, FEATURE_DIM), &Device::Cpu).unwrap()
    }

    /// A folder with clips `000001` (60 frames, a whole-clip caption and two ranged ones) and
    /// `000002` (30 frames), Mean/Std and a train split.
    fn dataset() -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        std::fs::create_dir(root.join("new_joint_vecs")).unwrap();
        std::fs::create_dir(root.join("texts")).unwrap();
        Tensor::zeros(FEATURE_DIM, DType::F32, &Device::Cpu).unwrap().write_npy(root.join("Mean.npy")).unwrap();
        Tensor::ones(FEATURE_DIM, DType::F64, &Device::Cpu).unwrap().write_npy(root.join("Std.npy")).unwrap();
        frames(60, 0.0).write_npy(root.join("new_joint_vecs/000001.npy")).unwrap();
        frames(30, 1.0).write_npy(root.join("new_joint_vecs/000002.npy")).unwrap();
        std::fs::write(
            root.join("texts/000001.txt"),
            "a person walks forward.#a/DET person/NOUN walk/VERB forward/ADV#0.0#0.0\n\
             a man waves.#a/DET man/NOUN wave/VERB#0.5#2.6\n\
             he turns#he/PRON turn/VERB#nan#nan\n\
             a short bit#a/DET short/ADJ bit/NOUN#0.0#1.0\n",
        )
        .unwrap();
        std::fs::write(root.join("texts/000002.txt"), "someone jumps#someone/PRON jump/VERB#0.0#0.0\n").unwrap();
        std::fs::write(root.join("train.txt"), "000001\n000002\n").unwrap();
        dir
    }

    #[test]
    fn reads_items_captions_and_splits() {
        let dir = dataset();
        let ds = HumanMl3dFolder::open(dir.path()).unwrap();
        assert_eq!(ds.ids().unwrap(), ["000001", "000002"]);
        assert_eq!(ds.mean_std().std().to_vec1::<f32>().unwrap()[5], 1.0);
        let item = ds.load_item("000001").unwrap();
        assert_eq!(item.frames(), 60);
        assert_eq!(item.features[2][5], ((2 * FEATURE_DIM + 5) % 97) as f32 * 0.01);
        assert_eq!(item.to_tensor(&Device::Cpu).unwrap().dims(), [60, FEATURE_DIM]);
        let c = &item.captions;
        assert_eq!(
            (c.len(), c[0].text.as_str(), c[0].tokens.len(), c[0].frames.clone()),
            (4, "a person walks forward.", 4, None)
        );
        assert_eq!(c[1].frames, Some(10..52));
        assert_eq!(c[2].frames, None, "NaN#NaN is the whole clip");
        assert_eq!(c[3].frames, Some(0..20));

        let raw = ds.load_split("train", None).unwrap();
        assert_eq!(raw.len(), 2);
        let lazy: Vec<_> = ds.items(ds.split_ids("train").unwrap()).map(|r| r.unwrap().id).collect();
        assert_eq!(lazy, ["000001", "000002"]);

        // HumanML3D's rule: 000002 (30 frames) and the 20-frame sub-clip are dropped; the
        // 42-frame sub-clip becomes its own item.
        let train = ds.load_split("train", Some(&LengthRule::HUMANML3D)).unwrap();
        let ids: Vec<_> = train.iter().map(|i| (i.id.as_str(), i.frames(), i.captions.len())).collect();
        assert_eq!(ids, [("000001", 60, 2), ("000001#10..52", 42, 1)]);
        assert_eq!(train[1].features[0], item.features[10]);
        let loose = LengthRule { min_frames: 1, max_frames_exclusive: usize::MAX };
        assert_eq!(ds.load_split("train", Some(&loose)).unwrap().len(), 4);
        assert!(!LengthRule::default().accepts(200) && LengthRule::default().accepts(199));
    }

    fn err_of(ds: &HumanMl3dFolder, id: &str) -> String {
        ds.load_item(id).unwrap_err().to_string()
    }

    #[test]
    fn bad_feature_files_are_named() {
        let dir = dataset();
        let root = dir.path();
        let ds = HumanMl3dFolder::open(root).unwrap();
        let npy = |id: &str| root.join(format!("new_joint_vecs/{id}.npy"));
        let txt =
            |id: &str| std::fs::copy(root.join("texts/000002.txt"), root.join(format!("texts/{id}.txt"))).unwrap();

        Tensor::zeros((5, 251), DType::F32, &Device::Cpu).unwrap().write_npy(npy("w251")).unwrap();
        txt("w251");
        let e = err_of(&ds, "w251");
        assert!(e.contains("w251.npy") && e.contains("[5, 251]"), "{e}");

        Tensor::zeros(263, DType::F32, &Device::Cpu).unwrap().write_npy(npy("flat")).unwrap();
        let e = err_of(&ds, "flat");
        assert!(e.contains("flat.npy") && e.contains("[263]"), "{e}");

        Tensor::zeros((5, 263), DType::I64, &Device::Cpu).unwrap().write_npy(npy("ints")).unwrap();
        let e = err_of(&ds, "ints");
        assert!(e.contains("ints.npy") && e.contains("<i8"), "{e}");

        Tensor::zeros((0, 263), DType::F32, &Device::Cpu).unwrap().write_npy(npy("empty")).unwrap();
        assert!(err_of(&ds, "empty").contains("no frames"));

        let mut nan = vec![0f32; 4 * FEATURE_DIM];
        nan[2 * FEATURE_DIM + 7] = f32::NAN;
        Tensor::from_vec(nan, (4, FEATURE_DIM), &Device::Cpu).unwrap().write_npy(npy("nan")).unwrap();
        txt("nan");
        let e = err_of(&ds, "nan");
        assert!(e.contains("nan.npy") && e.contains("frame 2, feature 7"), "{e}");

        // f64 features are accepted (converted).
        frames(3, 0.5).to_dtype(DType::F64).unwrap().write_npy(npy("f64")).unwrap();
        txt("f64");
        assert_eq!(ds.load_item("f64").unwrap().features[0][0], 0.5);

        // A valid file cut at every kind of place: Err naming the file, never a panic.
        let good = std::fs::read(npy("000002")).unwrap();
        for len in [0, 3, 6, 9, 11, 40, 127, 128, 129, 1000, good.len() - 4, good.len() - 1] {
            std::fs::write(npy("cut"), &good[..len]).unwrap();
            txt("cut");
            let e = err_of(&ds, "cut");
            assert!(e.contains("cut.npy"), "cut at {len}: {e}");
        }
        let mut long = good.clone();
        long.extend_from_slice(&[0; 4]);
        std::fs::write(npy("long"), long).unwrap();
        assert!(err_of(&ds, "long").contains("long.npy"));
        // A header claiming a gigantic shape must be refused, not allocated.
        let data_start = 10 + usize::from(u16::from_le_bytes([good[8], good[9]]));
        let header = String::from_utf8_lossy(&good[10..data_start]).replace("(30,", "(999999999999999,");
        let mut huge = good[..8].to_vec();
        huge.extend_from_slice(&(header.len() as u16).to_le_bytes());
        huge.extend_from_slice(header.as_bytes());
        huge.extend_from_slice(&good[data_start..]);
        std::fs::write(npy("huge"), huge).unwrap();
        assert!(err_of(&ds, "huge").contains("huge.npy"));
        // A clip longer than the limit is refused from its header.
        let header = String::from_utf8_lossy(&good[10..data_start]).replace("(30,", "(72001,");
        let mut overlong = good[..8].to_vec();
        overlong.extend_from_slice(&(header.len() as u16).to_le_bytes());
        overlong.extend_from_slice(header.as_bytes());
        overlong.extend_from_slice(&good[data_start..]);
        std::fs::write(npy("overlong"), overlong).unwrap();
        let e = err_of(&ds, "overlong");
        assert!(e.contains("overlong.npy") && e.contains("is 72001 frames at 20 fps, over the limit"), "{e}");
    }

    #[test]
    fn bad_text_files_are_named() {
        let dir = dataset();
        let root = dir.path();
        let ds = HumanMl3dFolder::open(root).unwrap();
        frames(50, 0.0).write_npy(root.join("new_joint_vecs/t.npy")).unwrap();
        let e = err_of(&ds, "t");
        assert!(e.contains("t.txt: No such file"), "{e}");
        for (body, needle) in [
            ("ok#a/DET#0.0#0.0\nonly#two\n", "line 2"),
            ("ok#a/DET#0.0#0.0\n\nbad#a/DET#zero#1.0\n", "line 3"),
            ("bad#a/DET#2.0#1.0\n", "before start"),
            ("bad#a/DET#-1.0#1.0\n", "line 1"),
            ("#a/DET#0.0#0.0\n", "empty caption"),
            ("\n\n", "no frames"),
        ] {
            std::fs::write(root.join("texts/t.txt"), body).unwrap();
            let e = err_of(&ds, "t");
            assert!(e.contains("t.txt") && e.contains(needle), "{body:?}: {e}");
        }
        std::fs::write(root.join("texts/t.txt"), "a #1 move#a/DET#0.0#0.0\n").unwrap();
        assert_eq!(ds.load_item("t").unwrap().captions[0].text, "a #1 move");
    }

    #[test]
    fn bad_folders_are_named() {
        let dir = dataset();
        let root = dir.path();
        let e = HumanMl3dFolder::open(&root.join("nowhere")).unwrap_err().to_string();
        assert!(e.contains("new_joint_vecs"), "{e}");
        let ds = HumanMl3dFolder::open(root).unwrap();
        assert!(ds.split_ids("val").unwrap_err().to_string().contains("val.txt"));
        assert!(err_of(&ds, "missing").contains("missing.npy"));

        Tensor::zeros(100, DType::F32, &Device::Cpu).unwrap().write_npy(root.join("Std.npy")).unwrap();
        let e = HumanMl3dFolder::open(root).unwrap_err().to_string();
        assert!(e.contains("Std.npy") && e.contains("[100]"), "{e}");
        Tensor::zeros(FEATURE_DIM, DType::F32, &Device::Cpu).unwrap().write_npy(root.join("Std.npy")).unwrap();
        let e = HumanMl3dFolder::open(root).unwrap_err().to_string();
        assert!(e.contains("std[0]"), "zero std: {e}");
        std::fs::remove_file(root.join("Mean.npy")).unwrap();
        let e = HumanMl3dFolder::open(root).unwrap_err().to_string();
        assert!(e.contains("Mean.npy"), "{e}");
    }
}
