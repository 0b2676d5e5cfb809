//! Importers of real motion capture into the 22-joint skeleton.
//!
//! Each importer turns a file into a [`MocapClip`]: something that can be posed at any time,
//! so resampling to 20 fps and time-warping interpolate the source's own rotations rather than
//! joint positions (bone lengths stay exact).

pub mod asf_amc;
pub mod bvh;
pub mod deepmimic;
pub mod humanml3d;
pub mod isaaclab;

use std::path::PathBuf;

use crate::files::FileError;
use crate::limits::{LimitExceeded, CLIP_FRAMES};
use crate::skeleton::{Pose, FPS};

/// Largest distance of an imported position from the origin after unit scaling, m. Real
/// captures stay within a few hundred metres; beyond this a value is a unit or export error,
/// and far beyond it the features overflow.
pub const MAX_POSITION_M: f64 = 1e4;

/// A motion-capture clip that can be posed at any time (seconds from its start).
pub trait MocapClip {
    /// Length of one play-through, seconds.
    fn duration_s(&self) -> f64;
    /// Whether the clip is a cycle that [`MocapClip::pose_at`] can continue past its end.
    fn is_cyclic(&self) -> bool;
    /// Joint positions at time `t_s` (metres, y up, +x the character's left). Times past the end
    /// of a cyclic clip continue the cycle; other clips hold their end poses.
    fn pose_at(&self, t_s: f64) -> Pose;
}

/// Samples a clip at 20 fps played `speed` times faster than recorded (a time warp), for
/// `seconds` of output (default: one play-through). Always at least 2 frames.
pub fn resample(clip: &dyn MocapClip, speed: f64, seconds: Option<f64>) -> Vec<Pose> {
    let out_seconds = seconds.unwrap_or(clip.duration_s() / speed);
    let frames = ((out_seconds * FPS).floor() as usize + 1).max(2);
    (0..frames).map(|k| clip.pose_at(k as f64 / FPS * speed)).collect()
}

/// Whether a coordinate, m, is finite and within [`MAX_POSITION_M`] of zero.
pub(crate) fn in_reach(v_m: f64) -> bool {
    v_m.abs() <= MAX_POSITION_M
}

/// Frames of a clip of `duration_s` seconds sampled at 20 fps (what [`resample`] makes of it at
/// speed 1), checked against [`CLIP_FRAMES`] before anything is allocated for them. `what`
/// names the file and where its length comes from.
pub fn check_clip_length(duration_s: f64, what: impl std::fmt::Display) -> Result<(), LimitExceeded> {
    let frames = duration_s * FPS;
    // Saturating: a non-finite duration is reported as the largest count.
    let count = if frames.is_finite() && frames >= 0.0 { (frames.floor() as u64).saturating_add(1) } else { u64::MAX };
    CLIP_FRAMES.check(count, what)
}

/// A number as messages print it: as written for ordinary magnitudes, in exponent form when
/// huge or tiny (`1e308`, not 309 digits).
pub fn short_number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e6).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// A non-fatal problem found while importing (the clip is still usable).
#[derive(Debug, Clone, PartialEq)]
pub struct ImportWarning {
    /// The file.
    pub path: PathBuf,
    /// What was found and what was done about it.
    pub message: String,
}

impl std::fmt::Display for ImportWarning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.message)
    }
}

/// Errors reading motion-capture files. Every variant names the file and where in it.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// The file is not valid JSON.
    #[error("{path}: line {line}, column {column}: not valid JSON: {message}")]
    Json {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// serde_json's message.
        message: String,
    },
    /// A structural problem at a known place in the file.
    #[error("{path}: {location}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Where: "frame 12, value 7", "line 40, joint LeftArm", ...
        location: String,
        /// What is wrong.
        message: String,
    },
    /// The file holds no frames.
    #[error("{path}: no frames")]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// The file could not be read, within its size limit, or is not in its format (the message
    /// names the file).
    #[error(transparent)]
    File(#[from] FileError),
    /// The clip is over a limit (the message names the file and where).
    #[error(transparent)]
    Limit(#[from] LimitExceeded),
}
