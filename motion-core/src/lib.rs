//! Constrained human motion generation: the numerical core.
//!
//! Conventions for every module are stated once in [`skeleton`]: y up, metres, +x is the
//! character's left, a canonical motion starts facing +z, 20 frames per second.

pub mod cleanup;
pub mod constraints;
pub mod corpus;
pub mod database;
pub mod diffusion;
pub mod dno;
pub mod evaluation;
pub mod evaluator;
pub mod export;
pub mod files;
pub mod generation;
pub mod import;
pub mod limits;
pub mod metrics;
pub mod model;
pub mod motion;
pub mod nn;
pub mod npy;
pub mod numeric;
pub mod optim;
pub mod pipeline;
pub mod prior;
pub mod program;
pub mod quality;
pub mod render;
pub mod representation;
pub mod skeleton;
pub mod tensor_file;
#[cfg(any(test, feature = "testing"))]
pub mod testing;
pub mod text;
pub mod training;

use skeleton::Joint;

/// Errors about a motion given as joint positions.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MotionError {
    /// Too few frames for the operation.
    #[error("motion has {frames} frames; at least {min} are needed")]
    TooShort {
        /// Frames given.
        frames: usize,
        /// Frames needed.
        min: usize,
    },
    /// A coordinate is NaN or infinite.
    #[error("frame {frame}, joint {joint}: coordinate is not finite")]
    NonFinite {
        /// Frame index.
        frame: usize,
        /// The joint.
        joint: Joint,
    },
    /// The hips and shoulders give no horizontal facing direction.
    #[error("frame {frame}: hips and shoulders give no horizontal facing direction")]
    NoFacing {
        /// Frame index.
        frame: usize,
    },
}
