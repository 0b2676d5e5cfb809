//! Outputs that other tools open: a rotation track on one rigid skeleton ([`rotations`]), BVH
//! ([`bvh`]), binary glTF with a skinned capsule body and the scene ([`gltf`]), a self-contained
//! 3-D viewer page ([`viewer`]), and the scene primitives as solid boxes ([`scene`]) shared by the
//! last two.
//!
//! Axes and units are the project's ([`crate::skeleton`]): metres, **y up**, the character
//! starts facing **+z** and **+x is its left**; 20 frames per second unless a motion says
//! otherwise. These are glTF's own axes, so a GLB needs no conversion; BVH files state theirs in
//! [`bvh`].
//!
//! Every writer builds its file in memory and writes it with [`write_atomically`]: a failure
//! leaves no half-written file behind.

pub mod bvh;
mod folder;
pub mod gltf;
mod outputs;
pub mod rotations;
pub mod scene;
pub mod viewer;

use std::path::{Path, PathBuf};

use crate::files::WriteError;

pub use folder::OutputFolder;
pub use outputs::{read_joints_npy, write_outputs, ExportInput, ExportManifest, ExportedSample, Probe};
pub use rotations::{RigSkeleton, RotationTrack, SolveFit, ANIMATED_OFFSETS};
pub use scene::{position_targets, scene_boxes, PositionTarget, SceneBox, SceneExtent, SceneRole};

/// Errors turning motions into files.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// A joint position is NaN or infinite.
    #[error("sample {sample}, frame {frame}, joint `{joint}`: position {value:?} is not finite")]
    NonFinite {
        /// Sample index.
        sample: usize,
        /// Frame index.
        frame: usize,
        /// Joint name.
        joint: &'static str,
        /// The offending position, m.
        value: [f64; 3],
    },
    /// Nothing to export, or samples of different lengths where one length is needed.
    #[error("cannot export: {0}")]
    Shape(String),
    /// An input file is unreadable, malformed or over a limit.
    #[error(transparent)]
    File(#[from] crate::files::FileError),
    /// Writing a file failed.
    #[error("{path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// [`crate::files::write_atomically`] with the export's error.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    Ok(crate::files::write_atomically(path, bytes)?)
}

impl From<WriteError> for ExportError {
    fn from(WriteError { path, message }: WriteError) -> Self {
        ExportError::Write { path, message }
    }
}
