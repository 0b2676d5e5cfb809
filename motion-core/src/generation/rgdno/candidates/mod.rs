//! RG-DNO's retrieval database (§4.3): the motions that retrieval crops, held once as joint
//! positions, and the candidate crops of a task's frame count, resized and placed in joint
//! space only while they are scored.
//!
//! **Sources** ([`RetrievalSource`]). By default the **train split** of the motion corpus
//! ([`crate::corpus`]); its validation and test clips are held out for evaluation and never
//! retrieved. Every corpus clip is also a candidate as its left/right mirror, made on the fly
//! (x negated, left and right joints swapped), described by the captions of its mirrored tags.
//! Or a motion database ([`crate::database`]: a `mogen data build` file, or a catalog built in
//! memory), whose sequences already hold its augmentations (mirrored copies, time warps): each
//! is recovered to joints once and described by its label.
//!
//! **Candidates** ([`Crop`]). Crops of every clip start every
//! [`RetrievalConfig::crop_stride_frames`] and span `T·f` frames for each resize factor `f` of
//! [`RetrievalConfig::resize_factors`] (`T·f + 1` poses); the joint positions are resized by
//! linear interpolation to `T + 1` poses, which the feature extraction turns into the task's
//! `T` feature frames (a factor above 1 plays the crop faster: a 2.5 s crawl resized to 1 s
//! covers the ground of the task's walk). A clip too short for `T + 1` poses is resized whole.
//!
//! **Placement.** A crop is scored where the generator would put it, as
//! [`crate::representation::canonicalize`] places a motion: the floor at its lowest joint, the
//! first frame's pelvis at x = z = 0, facing +z (see [`super::retrieval`] on why there is no
//! transform `H`). Its first `T` poses are then exactly the joints that
//! [`crate::representation::recover_from_ric`] gives from its features. A mirrored crop placed
//! is the recorded crop placed, then reflected.
//!
//! **Memory.** The joints are held once, f32 `[frames, 22, 3]` (264 bytes a frame: 111 MB for
//! the corpus's 5.8 h train split, 116 MB with the clips and captions). A crop is 16 bytes of
//! index, made per query (1.3 MB for the 78,678 crops of a 100-frame task); its joints exist only
//! while its batch is scored ([`RetrievalDatabase::place`]), and features are made only for the
//! retrieved few ([`RetrievalDatabase::features`]). Opening unpacks the corpus file (83 MB) and
//! decodes its train clips one at a time ([`PackedCorpus`]), never every split's f64 poses.

use std::ops::Range;
use std::path::PathBuf;

use candle_core::{Device, Tensor};
use glam::{DMat3, DVec3};
use serde::{Deserialize, Serialize};

use super::config::RetrievalConfig;
use super::error::RetrievalError;
use super::semantic::{named_actions, Described, Heard};
use crate::corpus::caption::Action;
use crate::corpus::caption::{captions, PHRASINGS};
use crate::corpus::family::{Families, Family};
use crate::corpus::file::PackedCorpus;
use crate::corpus::{Corpus, CorpusClip, CorpusWindow, Split};
use crate::database::{mirror_label, DatabaseSource, MotionDatabase, Window};
use crate::import::ImportWarning;
use crate::motion::mirror;
use crate::representation::{extract_features, facing_direction, heading_rotation, recover_from_ric, FEATURE_DIM};
use crate::skeleton::{Joint, Pose, FPS, NUM_JOINTS};

/// Coordinates of one pose: x, y, z of each joint in HumanML3D order.
const POSE: usize = 3 * NUM_JOINTS;

/// Where RG-DNO retrieves from.
#[derive(Debug, Clone, PartialEq)]
pub enum RetrievalSource {
    /// The train split of a motion corpus file ([`crate::corpus::file`]), every clip also
    /// mirrored.
    Corpus(PathBuf),
    /// A motion database, with the augmentations it was built with.
    Database(DatabaseSource),
}

impl RetrievalSource {
    /// The source a file names, by its name: a corpus (`.safetensors.gz`), a catalog of clips
    /// (`.json`, built in memory with the default augmentations), or a saved database (any
    /// other, `mogen data build`'s `.safetensors`).
    pub fn from_path(path: impl Into<PathBuf>) -> Self {
        let path = path.into();
        match path.extension().and_then(|e| e.to_str()) {
            Some("gz") => RetrievalSource::Corpus(path),
            Some("json") => RetrievalSource::Database(DatabaseSource::catalog(path)),
            _ => RetrievalSource::Database(DatabaseSource::File(path)),
        }
    }

    /// Reads the corpus, or loads or builds the database; a catalog's import warnings come
    /// beside it.
    pub fn open(&self) -> Result<(RetrievalDatabase, Vec<ImportWarning>), RetrievalError> {
        match self {
            RetrievalSource::Corpus(path) => {
                Ok((RetrievalDatabase::from_packed_corpus(&PackedCorpus::open(path)?)?, Vec::new()))
            }
            RetrievalSource::Database(source) => {
                let (database, warnings) = source.open().map_err(|error| RetrievalError::Database {
                    source_name: source.to_string(),
                    error: Box::new(error),
                })?;
                Ok((RetrievalDatabase::from_motion_database(&database)?, warnings))
            }
        }
    }
}

impl std::fmt::Display for RetrievalSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RetrievalSource::Corpus(path) => write!(f, "the train split of {} with mirrored copies", path.display()),
            RetrievalSource::Database(source) => write!(f, "{source}"),
        }
    }
}

/// The motions retrieval crops, as joints, with what is said of them.
#[derive(Debug, Clone)]
pub struct RetrievalDatabase {
    /// Every clip's joints, concatenated: `[frames, 22, 3]` row-major, f32 (m, y up, 20 fps).
    joints: Vec<f32>,
    clips: Vec<StoredClip>,
    windows: Vec<StoredWindow>,
    /// Whether every clip is also a candidate as its left/right mirror.
    mirror: bool,
    /// The index of each joint's mirror image ([`Joint::mirror`]).
    mirror_of: [usize; NUM_JOINTS],
    /// The actions some window's measured description names ([`named_actions`]), as recorded
    /// or mirrored: read once when the database is made.
    actions_done: Vec<Action>,
}

#[derive(Debug, Clone)]
struct StoredClip {
    /// A corpus clip's name (its take id) or a database sequence's source clip.
    name: String,
    /// First frame in the joints.
    offset: usize,
    frames: usize,
    /// A database's mirrored copy.
    mirrored: bool,
    /// Playback speed of a database's time-warped copy (1 for a corpus clip).
    speed: f64,
    /// Its windows in [`RetrievalDatabase::windows`], by start.
    windows: Range<usize>,
}

/// A stretch of a clip with one description (a corpus window; a database sequence whole).
#[derive(Debug, Clone)]
struct StoredWindow {
    start: usize,
    frames: usize,
    /// What is said of it as recorded (0) and mirrored (1).
    texts: [WindowText; 2],
    /// The skill families it is an example of as recorded (0) and mirrored (1): a corpus
    /// window's by its measurement ([`Families::happening_in`]), a database sequence's by the family
    /// its label names ([`Family::named_in`]).
    families: [Families; 2],
    /// How far it turns, either way, degrees (`|MotionTags::turn_deg|`; 0 for a database
    /// sequence, whose label measures nothing).
    turn_deg: f64,
}

#[derive(Debug, Clone)]
struct WindowText {
    /// See [`Described::measured`].
    measured: String,
    /// See [`Described::said`].
    said: String,
    /// The one sentence retrieval's caption similarity reads: a corpus window's caption that
    /// carries its take's description ("walk carrying a box: a person walks forward"), or its
    /// measured caption when the take has none; a database sequence's label.
    sentence: String,
}

impl WindowText {
    fn label(label: &str) -> Self {
        WindowText { measured: label.to_owned(), said: label.to_owned(), sentence: label.to_owned() }
    }

    fn described(&self) -> Described<'_> {
        Described { measured: &self.measured, said: &self.said }
    }
}

/// A candidate motion: poses `start..start + poses` of a clip, resized to the task's `T + 1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Crop {
    /// Index of the clip.
    pub clip: u32,
    /// First frame in the clip.
    pub start: u32,
    /// Poses taken (at least 2).
    pub poses: u32,
    /// Taken as its left/right mirror.
    pub mirrored: bool,
}

impl Crop {
    /// Whether `other` is this crop's left/right mirror image.
    pub fn is_mirror_of(&self, other: &Crop) -> bool {
        (self.clip, self.start, self.poses) == (other.clip, other.start, other.poses) && self.mirrored != other.mirrored
    }
}

/// Where a candidate motion comes from, as the report names it. Reports written before the
/// corpus (a `label` and a `sequence`, no window) still read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CandidateSource {
    /// The clip: a corpus clip's name, its take id (`07_01`; `07_01#1` for a take's second kept
    /// stretch), or the source clip of a database sequence.
    pub clip: String,
    /// What the crop's window does: its caption measured from the joints (a corpus window), or
    /// the sequence's label (a database); mirrored for mirrored copies.
    #[serde(alias = "label")]
    pub caption: String,
    /// The window of the clip that the caption describes, frames `[start, end)` (20 fps).
    #[serde(default)]
    pub window: [usize; 2],
    /// A left/right mirrored copy.
    pub mirrored: bool,
    /// Playback speed of a database's time-warped copy (1 for a corpus clip).
    pub speed: f64,
    /// Index of the clip in the retrieval database.
    #[serde(default, alias = "sequence")]
    pub clip_index: usize,
    /// First frame of the crop in the clip.
    pub start: usize,
    /// Frames taken from the clip (`start..start + frames`), resized to the task's.
    pub frames: usize,
    /// How much faster than captured the crop plays in the task's frames: `(frames − 1) / T`.
    #[serde(default)]
    pub played_at: f64,
}

impl std::fmt::Display for CandidateSource {
    /// `07_01 mirrored, frames 60..161 at ×1.00 of window 40..160: "a person walks forward"`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.clip)?;
        if self.mirrored {
            write!(f, " mirrored")?;
        }
        if self.speed != 1.0 {
            write!(f, " (time warp ×{})", self.speed)?;
        }
        write!(
            f,
            ", frames {}..{} at ×{:.2} of window {}..{}: {:?}",
            self.start,
            self.start + self.frames,
            self.played_at,
            self.window[0],
            self.window[1],
            self.caption
        )
    }
}

impl RetrievalDatabase {
    /// The train split of `corpus`, every clip also mirrored. Validation and test clips are
    /// left out.
    pub fn from_corpus(corpus: &Corpus) -> Result<Self, RetrievalError> {
        let mut database = Self::for_train_split(&corpus.clips);
        for (index, clip) in train_split(&corpus.clips) {
            database.push_corpus_clip(index, clip, &corpus.windows, corpus.clip_joints(clip));
        }
        database.checked()
    }

    /// The same database as [`RetrievalDatabase::from_corpus`] of the whole corpus, made from
    /// the file's packed joints one train clip at a time.
    pub fn from_packed_corpus(corpus: &PackedCorpus) -> Result<Self, RetrievalError> {
        let mut database = Self::for_train_split(&corpus.clips);
        let mut poses = Vec::new();
        for (index, clip) in train_split(&corpus.clips) {
            poses.clear();
            corpus.decode_clip(clip, &mut poses);
            database.push_corpus_clip(index, clip, &corpus.windows, &poses);
        }
        database.checked()
    }

    /// An empty database with every clip mirrored, its joints sized for the train split of
    /// `clips` (grown by doubling, the 111 MB would be copied and its pages zeroed again).
    fn for_train_split(clips: &[CorpusClip]) -> Self {
        let mut database = Self::empty(true);
        database.joints.reserve_exact(train_split(clips).map(|(_, c)| c.frames * POSE).sum());
        database
    }

    /// Appends corpus clip `index` with its `poses` and its windows among `windows`, each
    /// described as recorded and mirrored.
    fn push_corpus_clip(&mut self, index: usize, clip: &CorpusClip, windows: &[CorpusWindow], poses: &[Pose]) {
        let mirrored_description = mirror_label(&clip.description);
        let windows = windows.iter().enumerate().filter(|(_, w)| w.clip == index).map(|(number, w)| {
            let text = |captions: Vec<String>| {
                let measured = captions.first().cloned().unwrap_or_default();
                WindowText {
                    sentence: captions.get(PHRASINGS).cloned().unwrap_or_else(|| measured.clone()),
                    said: captions.join(" | "),
                    measured,
                }
            };
            let (window_poses, mirrored_tags) = (&poses[w.start..w.start + w.frames], w.tags.mirrored());
            StoredWindow {
                start: w.start,
                frames: w.frames,
                texts: [text(w.captions.clone()), text(captions(&mirrored_tags, &mirrored_description, number))],
                families: [
                    Families::happening_in(window_poses, &w.tags, &clip.description),
                    Families::happening_in(window_poses, &mirrored_tags, &mirrored_description),
                ],
                turn_deg: w.tags.turn_deg.abs(),
            }
        });
        self.push(&clip.name, poses.iter().flat_map(pose_coordinates), (false, 1.0), windows);
    }

    /// Every sequence of `database` (its augmentations included), its joints recovered from its
    /// features, described by its label.
    pub fn from_motion_database(database: &MotionDatabase) -> Result<Self, RetrievalError> {
        let mut out = Self::empty(false);
        for (index, sequence) in database.sequences().iter().enumerate() {
            let whole = Window { sequence: index, start: 0, frames: sequence.frames };
            let Some(features) = database.window_slice(&whole, 0, sequence.frames) else { continue };
            let features = Tensor::from_slice(features, (1, sequence.frames, FEATURE_DIM), &Device::Cpu)?;
            let joints = recover_from_ric(&features)?.flatten_all()?.to_vec1::<f32>()?;
            let mirrored_label = mirror_label(&sequence.label);
            let window = StoredWindow {
                start: 0,
                frames: sequence.frames,
                texts: [WindowText::label(&sequence.label), WindowText::label(&mirrored_label)],
                families: [&sequence.label, &mirrored_label].map(|label| Family::named_in(label).into_iter().collect()),
                turn_deg: 0.0,
            };
            out.push(&sequence.source, joints, (sequence.mirrored, sequence.speed), [window]);
        }
        out.checked()
    }

    fn empty(mirror: bool) -> Self {
        let mirror_of = Joint::ALL.map(|j| j.mirror().index());
        Self { joints: Vec::new(), clips: Vec::new(), windows: Vec::new(), mirror, mirror_of, actions_done: Vec::new() }
    }

    /// Appends a clip of joint coordinates (`[frames, 22, 3]`, flat) with its windows.
    fn push(
        &mut self,
        name: &str,
        coordinates: impl IntoIterator<Item = f32>,
        (mirrored, speed): (bool, f64),
        windows: impl IntoIterator<Item = StoredWindow>,
    ) {
        let offset = self.joints.len() / POSE;
        self.joints.extend(coordinates);
        let first = self.windows.len();
        self.windows.extend(windows);
        self.clips.push(StoredClip {
            name: name.to_owned(),
            offset,
            frames: self.joints.len() / POSE - offset,
            mirrored,
            speed,
            windows: first..self.windows.len(),
        });
    }

    /// `self` without spare capacity and with the actions its windows do, or
    /// [`RetrievalError::Empty`] when no clip has 2 frames.
    fn checked(mut self) -> Result<Self, RetrievalError> {
        self.joints.shrink_to_fit();
        self.windows.shrink_to_fit();
        for text in self.windows.iter().flat_map(|w| &w.texts) {
            for action in named_actions(&text.measured) {
                if !self.actions_done.contains(&action) {
                    self.actions_done.push(action);
                }
            }
        }
        if self.clips.iter().any(|c| c.frames >= 2) {
            Ok(self)
        } else {
            Err(RetrievalError::Empty)
        }
    }

    /// Clips held (mirrored copies made on the fly not counted).
    pub fn clips(&self) -> usize {
        self.clips.len()
    }

    /// Seconds of motion held (20 fps).
    pub fn seconds(&self) -> f64 {
        self.joints.len() as f64 / POSE as f64 / FPS
    }

    /// Bytes held: the joints and the index of clips and windows with their captions.
    pub fn bytes(&self) -> usize {
        let text = |t: &WindowText| t.measured.capacity() + t.said.capacity();
        self.joints.capacity() * size_of::<f32>()
            + self.clips.iter().map(|c| size_of::<StoredClip>() + c.name.capacity()).sum::<usize>()
            + self
                .windows
                .iter()
                .map(|w| size_of::<StoredWindow>() + w.texts.iter().map(text).sum::<usize>())
                .sum::<usize>()
    }

    /// Every candidate crop for a task of `frames` frames (module doc: starts every
    /// `crop_stride_frames`, one span per resize factor, a short clip whole; each also mirrored
    /// when the database mirrors), clip by clip, each crop beside its mirror.
    pub fn crops(&self, frames: usize, config: &RetrievalConfig) -> Result<Vec<Crop>, RetrievalError> {
        if frames < 2 || config.crop_stride_frames == 0 {
            return Err(RetrievalError::Setting(format!(
                "frames ({frames}) must be ≥ 2 and crop_stride_frames ({}) ≥ 1",
                config.crop_stride_frames
            )));
        }
        if let Some(f) = config.resize_factors.iter().find(|f| !(f.is_finite() && **f > 0.0 && **f <= 10.0)) {
            return Err(RetrievalError::Setting(format!("resize factors must lie in (0, 10], got {f}")));
        }
        let mirrored: &[bool] = if self.mirror { &[false, true] } else { &[false] };
        let mut crops = Vec::new();
        for (index, clip) in self.clips.iter().enumerate().filter(|(_, c)| c.frames >= 2) {
            // A crop and its mirror side by side: scoring reflects the one placed before.
            let mut push = |start: usize, poses: usize| {
                crops.extend(mirrored.iter().map(|&mirrored| Crop {
                    clip: index as u32,
                    start: start as u32,
                    poses: poses as u32,
                    mirrored,
                }));
            };
            if clip.frames <= frames {
                push(0, clip.frames);
            }
            for &factor in &config.resize_factors {
                let poses = (frames as f64 * factor).round().max(1.0) as usize + 1;
                for start in (0..).step_by(config.crop_stride_frames).take_while(|s| s + poses <= clip.frames) {
                    push(start, poses);
                }
            }
        }
        Ok(crops)
    }

    /// Whether each window, as recorded and as mirrored, passes the semantic check of the
    /// prompt `heard` ([`Heard::consistent`]), indexed like the windows.
    pub(super) fn consistent_windows(&self, heard: &Heard) -> Vec<[bool; 2]> {
        self.windows.iter().map(|w| w.texts.each_ref().map(|t| heard.consistent(t.described()))).collect()
    }

    /// The actions ([`named_actions`]) that the measured description of some window names, as
    /// recorded or mirrored.
    pub(super) fn actions_done(&self) -> &[Action] {
        &self.actions_done
    }

    /// Whether `crop` passes the semantic check, given [`Self::consistent_windows`]: every
    /// window that shares at least half of the shorter of the two with the crop must pass (a
    /// crop that walks, then runs, is a run); with none such, the window sharing the most.
    pub(super) fn crop_is_consistent(&self, crop: &Crop, consistent: &[[bool; 2]]) -> bool {
        let side = usize::from(crop.mirrored);
        let mut any = false;
        for (i, shared) in self.overlaps(crop) {
            let w = &self.windows[i];
            if 2 * shared >= w.frames.min(crop.poses as usize) {
                any = true;
                if !consistent[i][side] {
                    return false;
                }
            }
        }
        any || consistent.get(self.describing_window(crop)).is_some_and(|c| c[side])
    }

    /// `(window index, frames shared)` of every window of the crop's clip that it overlaps.
    fn overlaps<'a>(&'a self, crop: &'a Crop) -> impl Iterator<Item = (usize, usize)> + 'a {
        let (start, end) = (crop.start as usize, (crop.start + crop.poses) as usize);
        self.clips[crop.clip as usize].windows.clone().filter_map(move |i| {
            let w = &self.windows[i];
            let shared = end.min(w.start + w.frames).saturating_sub(start.max(w.start));
            (shared > 0).then_some((i, shared))
        })
    }

    /// The window that shares the most frames with the crop (the first of equals).
    fn describing_window(&self, crop: &Crop) -> usize {
        let mut best = (self.clips[crop.clip as usize].windows.start, 0);
        for (i, shared) in self.overlaps(crop) {
            if shared > best.1 {
                best = (i, shared);
            }
        }
        best.0
    }

    /// What `crop` does by measurement: the skill families of the window sharing the most frames
    /// with it, as recorded or mirrored, and how far that window turns (degrees, either way).
    pub(super) fn crop_skills(&self, crop: &Crop) -> (Families, f64) {
        self.windows
            .get(self.describing_window(crop))
            .map_or((Families::default(), 0.0), |w| (w.families[usize::from(crop.mirrored)], w.turn_deg))
    }

    /// The sentence caption similarity reads for `crop`: that of the window sharing the most
    /// frames with it, as recorded or mirrored.
    pub(super) fn sentence(&self, crop: &Crop) -> &str {
        self.windows.get(self.describing_window(crop)).map_or("", |w| &w.texts[usize::from(crop.mirrored)].sentence)
    }

    /// The take `crop` comes from: its clip's name up to a `#` (a take's kept stretches
    /// `07_01#0` and `07_01#1` are one take). A mirror image and a database's time-warped copies
    /// share their source clip's name, so they are the same take.
    pub(super) fn take(&self, crop: &Crop) -> &str {
        let name = &self.clips[crop.clip as usize].name;
        name.split('#').next().unwrap_or(name)
    }

    /// Where `crop` comes from, resized to `frames`.
    pub fn source(&self, crop: &Crop, frames: usize) -> CandidateSource {
        let clip = &self.clips[crop.clip as usize];
        let window = self.windows.get(self.describing_window(crop));
        CandidateSource {
            clip: clip.name.clone(),
            caption: window.map(|w| w.texts[usize::from(crop.mirrored)].measured.clone()).unwrap_or_default(),
            window: window.map_or([0, clip.frames], |w| [w.start, w.start + w.frames]),
            mirrored: clip.mirrored != crop.mirrored,
            speed: clip.speed,
            clip_index: crop.clip as usize,
            start: crop.start as usize,
            frames: crop.poses as usize,
            played_at: (crop.poses - 1) as f64 / frames as f64,
        }
    }

    /// The two frames of the clip that pose `t` of `0..=frames` of `crop`, resized to
    /// `frames + 1` poses, lies between (`[22, 3]` rows, f32), and its weight on the second.
    fn rows(&self, crop: &Crop, frames: usize, t: usize) -> (&[f32], &[f32], f32) {
        let clip = &self.clips[crop.clip as usize];
        let last = crop.start as usize + crop.poses as usize - 1;
        let position = crop.start as f64 + t as f64 * (crop.poses - 1) as f64 / frames as f64;
        let lower = (position.floor() as usize).min(last);
        let upper = (lower + 1).min(last);
        let row = |f: usize| &self.joints[(clip.offset + f) * POSE..(clip.offset + f + 1) * POSE];
        (row(lower), row(upper), (position - lower as f64) as f32)
    }

    /// Pose `t` of `0..=frames` of `crop` resized to `frames + 1` poses by linear
    /// interpolation, as recorded (not mirrored; m, y up).
    fn resized_pose(&self, crop: &Crop, frames: usize, t: usize) -> Pose {
        let (a, b, w) = self.rows(crop, frames, t);
        std::array::from_fn(|j| {
            DVec3::from_array(std::array::from_fn(|c| f64::from(a[3 * j + c] + w * (b[3 * j + c] - a[3 * j + c]))))
        })
    }

    /// Appends the first `frames` poses of `crop`, resized to `frames + 1` and placed as the
    /// generator places a motion (module doc), to `out` (`[frames, 22, 3]`, flat, m, y up): one
    /// pass that resizes, turns and shifts in x and z and finds the floor, then one that lowers
    /// y onto it; a mirrored crop is the reflection of the recorded one so placed
    /// (`Self::reflect`). `false` (and zeros) when the first pose has no facing direction (a
    /// body so twisted that it cannot be placed; the feature extraction refuses it too).
    pub fn place(&self, crop: &Crop, frames: usize, out: &mut Vec<f32>) -> bool {
        let begin = out.len();
        let first = self.resized_pose(crop, frames, 0);
        let Some(facing) = facing_direction(&first) else {
            out.resize(begin + frames * POSE, 0.0);
            return false;
        };
        // The heading is a rotation about y: x' = a·x + b·z, z' = c·x + d·z.
        let heading = DMat3::from_quat(heading_rotation(facing));
        let [a, b, c, d] = [heading.x_axis.x, heading.z_axis.x, heading.x_axis.z, heading.z_axis.z].map(|v| v as f32);
        let (origin_x, origin_z) = (first[0].x as f32, first[0].z as f32);
        let mut floor = f32::INFINITY;
        for t in 0..=frames {
            let (lower, upper, w) = self.rows(crop, frames, t);
            let lerp = |i: usize| lower[i] + w * (upper[i] - lower[i]);
            for j in 0..NUM_JOINTS {
                let y = lerp(3 * j + 1);
                floor = floor.min(y);
                // The last pose only gives the last feature frame's velocities, and the floor.
                if t < frames {
                    let (x, z) = (lerp(3 * j) - origin_x, lerp(3 * j + 2) - origin_z);
                    out.extend([a * x + b * z, y, c * x + d * z]);
                }
            }
        }
        let placed = &mut out[begin..];
        for p in placed.chunks_exact_mut(3) {
            p[1] -= floor;
        }
        if crop.mirrored {
            self.reflect(placed);
        }
        true
    }

    /// Reflects placed poses (`[frames, 22, 3]`, flat) left to right in place: x negated, left
    /// and right joints swapped ([`crate::motion::mirror`] on f32 rows). A placed crop reflected
    /// is its mirrored twin placed: the mirror of a motion faces the mirror of its heading.
    pub(super) fn reflect(&self, placed: &mut [f32]) {
        for row in placed.chunks_exact_mut(POSE) {
            let recorded: [f32; POSE] = std::array::from_fn(|i| row[i]);
            for (p, &other) in recorded.chunks_exact(3).zip(&self.mirror_of) {
                row[3 * other..3 * other + 3].copy_from_slice(&[-p[0], p[1], p[2]]);
            }
        }
    }

    /// The raw features `[frames, 263]` of `crop` resized to `frames + 1` poses (the
    /// extraction places the motion and gives one frame fewer than it is given).
    pub fn features(&self, crop: &Crop, frames: usize, device: &Device) -> Result<Tensor, RetrievalError> {
        let poses: Vec<Pose> = (0..=frames).map(|t| self.resized_pose(crop, frames, t)).collect();
        let poses = if crop.mirrored { mirror(&poses) } else { poses };
        let extracted = extract_features(&poses)
            .map_err(|error| RetrievalError::Features { crop: self.source(crop, frames).to_string(), error })?;
        let flat: Vec<f32> = extracted.features.iter().flatten().copied().collect();
        Ok(Tensor::from_vec(flat, (frames, FEATURE_DIM), device)?)
    }
}

/// The clips of the train split, with their indices.
fn train_split(clips: &[CorpusClip]) -> impl Iterator<Item = (usize, &CorpusClip)> {
    clips.iter().enumerate().filter(|(_, c)| c.split == Split::Train)
}

fn pose_coordinates(pose: &Pose) -> impl Iterator<Item = f32> + '_ {
    pose.iter().flat_map(|v| v.to_array()).map(|c| c as f32)
}

#[cfg(test)]
pub(super) mod tests;
