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
    /// Reading an input file failed.
    #[error("{path}: {message}")]
    Read {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// An input file is unreadable, malformed or over a limit.
    #[error(transparent)]
    Import(#[from] crate::import::ImportError),
    /// Writing a file failed.
    #[error("{path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, creating
/// the folder; on any error the temporary file is removed and `path` is untouched.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let fail = |message: String| ExportError::Write { path: path.into(), message };
    let dir = match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) => dir.to_path_buf(),
        None => PathBuf::from("."),
    };
    std::fs::create_dir_all(&dir).map_err(|e| fail(e.to_string()))?;
    let name = path.file_name().ok_or_else(|| fail("not a file name".into()))?;
    let tmp = dir.join(format!(".{}.part{}", name.to_string_lossy(), std::process::id()));
    let written = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    if let Err(e) = written {
        let _ = std::fs::remove_file(&tmp);
        return Err(fail(e.to_string()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub").join("a.txt");
        write_atomically(&path, b"one").unwrap();
        write_atomically(&path, b"two").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        assert_eq!(std::fs::read_dir(path.parent().unwrap()).unwrap().count(), 1);
        // A folder where the file should go: an error naming the path, nothing left behind.
        let blocked = dir.path().join("blocked");
        std::fs::create_dir_all(blocked.join("x")).unwrap();
        let err = write_atomically(&blocked, b"three").unwrap_err();
        assert!(err.to_string().contains("blocked"), "{err}");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }
}
