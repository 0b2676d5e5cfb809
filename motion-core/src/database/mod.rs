//! The motion database: augmented 20 fps feature sequences cut into labelled windows, stored as
//! one safetensors file with its index. It is the training set of the prior, and RG-DNO's
//! retrieval database when one is named (`--database`; by default RG-DNO retrieves from the
//! corpus's train split, [`crate::generation::rgdno::candidates`]).
//!
//! Augmentations: left/right mirroring (labels swap "left" and "right"), time warps (replaying
//! the source at other speeds, interpolating its rotations), looping of cyclic clips with
//! blended seams (done by the importers), and short holds of the first and last pose around
//! one-shot clips. Heading rotation is **not** an augmentation here: the 263-d features are
//! heading-invariant by construction (every clip is canonicalised to face +z at its start), so
//! rotated copies would be identical rows; `tests/database.rs` checks that invariance.

pub mod catalog;

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::files::FileError;
use crate::import::ImportWarning;
use crate::import::{check_clip_length, resample, short_number};
use crate::limits::LimitExceeded;
use crate::motion::mirror;
use crate::representation::{
    extract_features, recover_from_ric, FeatureFrame, MeanStd, NormalizationError, RestSkeleton, FEATURE_DIM,
};
use crate::skeleton::{Pose, FPS};
use crate::tensor_file::{read_metadata, write_safetensors};
use crate::MotionError;
use catalog::{Catalog, SourceClip};

/// Version of the file layout, checked on load.
const FORMAT_VERSION: u32 = 1;

/// How sequences and windows are made from source clips. Defaults are documented per field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatabaseConfig {
    /// Playback speeds (time warps); default 0.8, 1.0, 1.25 (within 0.75–1.33×).
    pub speeds: Vec<f64>,
    /// Also add left/right mirrored copies; default true.
    pub mirror: bool,
    /// Seconds of motion generated from each cyclic clip by looping it; default 10 s.
    pub loop_seconds: f64,
    /// Seconds the first and last poses of a one-shot clip are held; default 0.5 s.
    pub hold_seconds: f64,
    /// Longest window, frames; default 196 (HumanML3D's maximum).
    pub max_window_frames: usize,
    /// Shortest window, frames; sequences shorter than this are left out; default 40.
    pub min_window_frames: usize,
    /// Step between window starts, frames; default 20 (1 s).
    pub window_stride_frames: usize,
}

impl DatabaseConfig {
    /// Checks that every figure is one [`MotionDatabase::build`] can use: speeds finite and
    /// positive, loop and hold seconds finite (loops positive, holds not negative).
    pub fn check(&self) -> Result<(), DatabaseError> {
        let bad = |field: String, value: f64, rule: &str| {
            Err(DatabaseError::Config { field, message: format!("{} {rule}", short_number(value)) })
        };
        if let Some((i, &speed)) = self.speeds.iter().enumerate().find(|(_, s)| !(s.is_finite() && **s > 0.0)) {
            return bad(format!("speeds[{i}]"), speed, "is not a positive, finite speed");
        }
        if !(self.loop_seconds.is_finite() && self.loop_seconds > 0.0) {
            return bad("loop_seconds".into(), self.loop_seconds, "is not a positive, finite number of seconds");
        }
        if !(self.hold_seconds.is_finite() && self.hold_seconds >= 0.0) {
            return bad("hold_seconds".into(), self.hold_seconds, "is not a finite number of seconds ≥ 0");
        }
        Ok(())
    }
}

impl Default for DatabaseConfig {
    fn default() -> Self {
        Self {
            speeds: vec![0.8, 1.0, 1.25],
            mirror: true,
            loop_seconds: 10.0,
            hold_seconds: 0.5,
            max_window_frames: 196,
            min_window_frames: 40,
            window_stride_frames: 20,
        }
    }
}

/// One augmented copy of a source clip.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sequence {
    /// Source clip name (file stem).
    pub source: String,
    /// Text label (mirrored when `mirrored`).
    pub label: String,
    /// Left/right mirrored copy.
    pub mirrored: bool,
    /// Playback speed of the source.
    pub speed: f64,
    /// First feature row in the database.
    pub offset: usize,
    /// Number of feature frames.
    pub frames: usize,
}

/// A window of one sequence: the unit of training and retrieval.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Window {
    /// Index into the sequences.
    pub sequence: usize,
    /// First frame within the sequence.
    pub start: usize,
    /// Number of frames.
    pub frames: usize,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
struct Index {
    format_version: u32,
    fps: f64,
    config: DatabaseConfig,
    sequences: Vec<Sequence>,
    windows: Vec<Window>,
}

/// Errors building, saving or loading a database.
#[derive(Debug, thiserror::Error)]
pub enum DatabaseError {
    /// A source clip could not be turned into features.
    #[error("clip {source_name}: {error}")]
    Motion {
        /// The clip.
        source_name: String,
        /// What went wrong.
        error: MotionError,
    },
    /// Normalisation statistics could not be computed.
    #[error("normalisation: {0}")]
    Normalization(#[from] NormalizationError),
    /// A figure of the [`DatabaseConfig`] is unusable.
    #[error("database config `{field}`: {message}")]
    Config {
        /// The field (`speeds[1]`, `loop_seconds`, ...).
        field: String,
        /// The value and the rule it breaks.
        message: String,
    },
    /// An augmented sequence would be longer than a clip may be.
    #[error(transparent)]
    Limit(#[from] LimitExceeded),
    /// No sequence was long enough for a window.
    #[error("no sequence has {min} frames or more; nothing to store")]
    Empty {
        /// Shortest window.
        min: usize,
    },
    /// The database file could not be read or written, or is malformed or incompatible.
    #[error(transparent)]
    File(#[from] FileError),
    /// A catalog or one of its clips could not be read.
    #[error("catalog {path}: {source}")]
    Catalog {
        /// The catalog file.
        path: PathBuf,
        /// What went wrong (boxed: an import error is large).
        source: Box<crate::import::ImportError>,
    },
}

/// Where a database comes from: a file written by [`MotionDatabase::save`] (`mogen data
/// build`), or a catalog of clips built in memory when it is opened (about 0.5 s for the shipped
/// catalog, so nothing needs building beforehand).
#[derive(Debug, Clone, PartialEq)]
pub enum DatabaseSource {
    /// A saved database file.
    File(PathBuf),
    /// A catalog JSON, built with these settings on [`DatabaseSource::open`].
    Catalog {
        /// The catalog file.
        path: PathBuf,
        /// The augmentations.
        config: DatabaseConfig,
    },
}

impl DatabaseSource {
    /// The shipped catalog at `path` with the default augmentations (as `mogen data build`).
    pub fn catalog(path: impl Into<PathBuf>) -> Self {
        DatabaseSource::Catalog { path: path.into(), config: DatabaseConfig::default() }
    }

    /// Loads the file or builds the catalog; a catalog's import warnings (e.g. normalised
    /// quaternions) are returned beside the database.
    pub fn open(&self) -> Result<(MotionDatabase, Vec<ImportWarning>), DatabaseError> {
        match self {
            DatabaseSource::File(path) => Ok((MotionDatabase::load(path)?, Vec::new())),
            DatabaseSource::Catalog { path, config } => {
                let catalog_error = |source| DatabaseError::Catalog { path: path.clone(), source: Box::new(source) };
                let (sources, warnings) = Catalog::read(path).and_then(|c| c.load()).map_err(catalog_error)?;
                Ok((MotionDatabase::build(&sources, config)?, warnings))
            }
        }
    }
}

impl std::fmt::Display for DatabaseSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            DatabaseSource::File(path) => write!(f, "{}", path.display()),
            DatabaseSource::Catalog { path, .. } => write!(f, "the clips of {} (built in memory)", path.display()),
        }
    }
}

/// Labelled, augmented, normalisable motion windows.
#[derive(Debug, Clone)]
pub struct MotionDatabase {
    features: Vec<f32>,
    sequences: Vec<Sequence>,
    windows: Vec<Window>,
    mean_std: MeanStd,
    config: DatabaseConfig,
}

impl MotionDatabase {
    /// Builds the database from loaded source clips. The config is checked first, and each
    /// augmented sequence's length against [`crate::limits::CLIP_FRAMES`] before it is sampled.
    pub fn build(sources: &[SourceClip], config: &DatabaseConfig) -> Result<Self, DatabaseError> {
        config.check()?;
        let mut features: Vec<FeatureFrame> = Vec::new();
        let mut sequences = Vec::new();
        let mut windows = Vec::new();
        for source in sources {
            for mirrored in if config.mirror { vec![false, true] } else { vec![false] } {
                for &speed in &config.speeds {
                    let poses = augmented_poses(source, speed, mirrored, config)?;
                    let extracted = extract_features(&poses)
                        .map_err(|error| DatabaseError::Motion { source_name: source.name.clone(), error })?;
                    let frames = extracted.features.len();
                    if frames < config.min_window_frames {
                        continue;
                    }
                    let sequence = sequences.len();
                    windows.extend(window_starts(frames, config).map(|(start, len)| Window {
                        sequence,
                        start,
                        frames: len,
                    }));
                    sequences.push(Sequence {
                        source: source.name.clone(),
                        label: if mirrored { mirror_label(&source.label) } else { source.label.clone() },
                        mirrored,
                        speed,
                        offset: features.len(),
                        frames,
                    });
                    features.extend(extracted.features);
                }
            }
        }
        if sequences.is_empty() {
            return Err(DatabaseError::Empty { min: config.min_window_frames });
        }
        let mean_std = MeanStd::from_frames(&features)?;
        Ok(Self {
            features: features.into_iter().flatten().collect(),
            sequences,
            windows,
            mean_std,
            config: config.clone(),
        })
    }

    /// The augmented sequences.
    pub fn sequences(&self) -> &[Sequence] {
        &self.sequences
    }

    /// The windows.
    pub fn windows(&self) -> &[Window] {
        &self.windows
    }

    /// Normalisation statistics of all frames.
    pub fn mean_std(&self) -> &MeanStd {
        &self.mean_std
    }

    /// The build configuration.
    pub fn config(&self) -> &DatabaseConfig {
        &self.config
    }

    /// Total feature frames.
    pub fn total_frames(&self) -> usize {
        self.features.len() / FEATURE_DIM
    }

    /// Label of a window.
    pub fn label(&self, window: &Window) -> &str {
        self.sequences.get(window.sequence).map_or("", |s| s.label.as_str())
    }

    /// Raw (de-normalised) features of `frames` frames of a window starting at `offset` within
    /// it, as a flat row-major `[frames, 263]` slice; `None` when out of range.
    pub fn window_slice(&self, window: &Window, offset: usize, frames: usize) -> Option<&[f32]> {
        let seq = self.sequences.get(window.sequence)?;
        if offset + frames > window.frames || window.start + offset + frames > seq.frames {
            return None;
        }
        let row = seq.offset + window.start + offset;
        self.features.get(row * FEATURE_DIM..(row + frames) * FEATURE_DIM)
    }

    /// Raw features of a window as a `[frames, 263]` tensor.
    pub fn window_tensor(&self, window: &Window, device: &Device) -> candle_core::Result<Tensor> {
        let data = self
            .window_slice(window, 0, window.frames)
            .ok_or_else(|| candle_core::Error::Msg(format!("window {window:?} is out of range")))?;
        Tensor::from_slice(data, (window.frames, FEATURE_DIM), device)
    }

    /// The mean bone lengths of the first frame of every window (the importers retarget every
    /// clip to one skeleton, so they agree); `None` for an empty database.
    pub fn rest_skeleton(&self) -> candle_core::Result<Option<RestSkeleton>> {
        let firsts: Vec<f32> =
            self.windows.iter().filter_map(|w| self.window_slice(w, 0, 1)).flatten().copied().collect();
        let rows = firsts.len() / FEATURE_DIM;
        if rows == 0 {
            return Ok(None);
        }
        let features = Tensor::from_vec(firsts, (rows, 1, FEATURE_DIM), &Device::Cpu)?;
        RestSkeleton::mean_of(&recover_from_ric(&features)?)
    }

    /// Seconds of motion per label (whole sequences, all augmentations), sorted by label.
    pub fn seconds_per_label(&self) -> BTreeMap<String, f64> {
        let mut out = BTreeMap::new();
        for s in &self.sequences {
            *out.entry(s.label.clone()).or_insert(0.0) += s.frames as f64 / FPS;
        }
        out
    }

    /// Distinct labels, sorted.
    pub fn labels(&self) -> Vec<String> {
        self.seconds_per_label().into_keys().collect()
    }

    /// Writes the database as one safetensors file: tensors `features` `[N, 263]`, `mean`,
    /// `std` (f32) and the index as JSON in the header metadata under `index`.
    pub fn save(&self, path: &Path) -> Result<(), DatabaseError> {
        let format = |message: String| DatabaseError::from(FileError::format(path, message));
        let index = Index {
            format_version: FORMAT_VERSION,
            fps: FPS,
            config: self.config.clone(),
            sequences: self.sequences.clone(),
            windows: self.windows.clone(),
        };
        let features = Tensor::from_slice(&self.features, (self.total_frames(), FEATURE_DIM), &Device::Cpu)
            .map_err(|e| format(e.to_string()))?;
        let tensors = vec![
            ("features".to_owned(), features),
            ("mean".to_owned(), self.mean_std.mean().clone()),
            ("std".to_owned(), self.mean_std.std().clone()),
        ];
        let json = serde_json::to_string(&index).map_err(|e| format(e.to_string()))?;
        write_safetensors(path, &tensors, HashMap::from([("index".to_owned(), json)])).map_err(format)
    }

    /// Reads a database written by [`MotionDatabase::save`], checking its consistency.
    pub fn load(path: &Path) -> Result<Self, DatabaseError> {
        let format = |message: String| DatabaseError::from(FileError::format(path, message));
        let bytes = std::fs::read(path).map_err(|e| FileError::io(path, &e))?;
        let st = safetensors::SafeTensors::deserialize(&bytes)
            .map_err(|e| format(format!("not a safetensors file: {e}")))?;
        let meta = read_metadata(&bytes).map_err(format)?;
        let json = meta.get("index").ok_or_else(|| format("no `index` in the header metadata".into()))?;
        let index: Index = serde_json::from_str(json).map_err(|e| format(format!("bad index: {e}")))?;
        if index.format_version != FORMAT_VERSION {
            return Err(format(format!("format version {} (expected {FORMAT_VERSION})", index.format_version)));
        }
        let read = |name: &str, shape: &[usize]| -> Result<Vec<f32>, DatabaseError> {
            let t = st.tensor(name).map_err(|e| format(format!("tensor `{name}`: {e}")))?;
            if t.dtype() != safetensors::Dtype::F32 || t.shape() != shape {
                return Err(format(format!(
                    "tensor `{name}` is {:?} {:?}, expected F32 {shape:?}",
                    t.dtype(),
                    t.shape()
                )));
            }
            Ok(t.data().chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
        };
        let total: usize = index.sequences.iter().map(|s| s.frames).sum();
        let features = read("features", &[total, FEATURE_DIM])?;
        if features.iter().any(|v| !v.is_finite()) {
            return Err(format("features contain NaN or infinite values".into()));
        }
        let mean_std = MeanStd::from_vecs(read("mean", &[FEATURE_DIM])?, read("std", &[FEATURE_DIM])?, &Device::Cpu)?;
        let mut offset = 0;
        for (i, s) in index.sequences.iter().enumerate() {
            if s.offset != offset {
                return Err(format(format!("sequence {i} starts at row {} (expected {offset})", s.offset)));
            }
            offset += s.frames;
        }
        for (i, w) in index.windows.iter().enumerate() {
            let ok = index.sequences.get(w.sequence).is_some_and(|s| w.start + w.frames <= s.frames && w.frames > 0);
            if !ok {
                return Err(format(format!("window {i} ({w:?}) lies outside its sequence")));
            }
        }
        Ok(Self { features, sequences: index.sequences, windows: index.windows, mean_std, config: index.config })
    }
}

/// 20 fps joint positions of one augmentation of a source clip, its length checked against
/// [`CLIP_FRAMES`](crate::limits::CLIP_FRAMES) (holds included) before it is sampled.
fn augmented_poses(
    source: &SourceClip,
    speed: f64,
    mirrored: bool,
    config: &DatabaseConfig,
) -> Result<Vec<Pose>, DatabaseError> {
    let clip = source.clip.as_ref();
    let hold = (config.hold_seconds * FPS).round() as usize;
    let seconds =
        if clip.is_cyclic() { config.loop_seconds } else { clip.duration_s() / speed + 2.0 * hold as f64 / FPS };
    check_clip_length(seconds, format_args!("clip {} at speed {speed}", source.name))?;
    let mut poses = if clip.is_cyclic() {
        resample(clip, speed, Some(config.loop_seconds))
    } else {
        let body = resample(clip, speed, None);
        let (first, last) = (body.first().copied(), body.last().copied());
        let mut poses = Vec::with_capacity(body.len() + 2 * hold);
        poses.extend(first.into_iter().cycle().take(hold));
        poses.extend(body);
        poses.extend(last.into_iter().cycle().take(hold));
        poses
    };
    if mirrored {
        poses = mirror(&poses);
    }
    Ok(poses)
}

/// Window (start, length) pairs covering a sequence of `frames` frames.
fn window_starts(frames: usize, config: &DatabaseConfig) -> impl Iterator<Item = (usize, usize)> {
    let len = frames.min(config.max_window_frames);
    let last = frames - len;
    let stride = config.window_stride_frames.max(1);
    let mut starts: Vec<usize> = (0..=last).step_by(stride).collect();
    if starts.last() != Some(&last) {
        starts.push(last);
    }
    starts.into_iter().map(move |s| (s, len))
}

/// Swaps the words "left" and "right" in a label, punctuation and a capital first letter kept
/// ("to the left, sideways" → "to the right, sideways"; "Left" → "Right").
pub fn mirror_label(label: &str) -> String {
    label
        .split(' ')
        .map(|w| {
            let core = w.trim_matches(|c: char| !c.is_alphanumeric());
            let swapped = match core {
                "left" => "right",
                "right" => "left",
                "Left" => "Right",
                "Right" => "Left",
                _ => return w.to_owned(),
            };
            w.replacen(core, swapped, 1)
        })
        .collect::<Vec<_>>()
        .join(" ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::MocapClip;

    #[test]
    fn windows_cover_the_sequence_and_end_at_its_end() {
        let cfg = DatabaseConfig::default();
        let w: Vec<_> = window_starts(250, &cfg).collect();
        assert_eq!(w.first(), Some(&(0, 196)));
        assert_eq!(w.last(), Some(&(54, 196)));
        let w: Vec<_> = window_starts(60, &cfg).collect();
        assert_eq!(w, vec![(0, 60)]);
    }

    /// A clip standing still for `duration_s`.
    struct Still {
        duration_s: f64,
        cyclic: bool,
    }

    impl MocapClip for Still {
        fn duration_s(&self) -> f64 {
            self.duration_s
        }
        fn is_cyclic(&self) -> bool {
            self.cyclic
        }
        fn pose_at(&self, _t_s: f64) -> Pose {
            crate::skeleton::rest_pose()
        }
    }

    fn source(duration_s: f64, cyclic: bool) -> SourceClip {
        SourceClip {
            name: "still".into(),
            label: "a person stands".into(),
            clip: Box::new(Still { duration_s, cyclic }),
        }
    }

    #[test]
    fn sequences_over_the_clip_limit_and_bad_configs_are_refused_before_sampling() {
        let e = MotionDatabase::build(&[source(1e9, false)], &DatabaseConfig::default()).unwrap_err().to_string();
        assert!(e.starts_with("clip still at speed 0.8 is ") && e.contains("imported clip length"), "{e}");
        let looped = DatabaseConfig { loop_seconds: 1e7, ..DatabaseConfig::default() };
        let e = MotionDatabase::build(&[source(2.0, true)], &looped).unwrap_err().to_string();
        assert!(e.contains("200000001 frames at 20 fps") && e.contains("imported clip length"), "{e}");
        for (config, field) in [
            (DatabaseConfig { loop_seconds: f64::NAN, ..DatabaseConfig::default() }, "loop_seconds"),
            (DatabaseConfig { hold_seconds: -1.0, ..DatabaseConfig::default() }, "hold_seconds"),
            (DatabaseConfig { speeds: vec![1.0, 0.0], ..DatabaseConfig::default() }, "speeds[1]"),
            (DatabaseConfig { speeds: vec![f64::INFINITY], ..DatabaseConfig::default() }, "speeds[0]"),
        ] {
            let e = MotionDatabase::build(&[source(2.0, true)], &config).unwrap_err().to_string();
            assert!(e.contains(field), "{field}: {e}");
        }
    }

    #[test]
    fn mirrored_labels_swap_sides() {
        assert_eq!(mirror_label("a person kicks with the right leg"), "a person kicks with the left leg");
        assert_eq!(mirror_label("a person walks and turns left"), "a person walks and turns right");
        assert_eq!(mirror_label("to the left, sideways (Right leg)"), "to the right, sideways (Left leg)");
        assert_eq!(mirror_label("leftover rights"), "leftover rights");
        // A file-name description mirrors once it is in words.
        let readable = crate::corpus::caption::readable_description("RunningWideLeft CleanedGRS");
        assert_eq!(mirror_label(&readable), "running wide right");
    }
}
