//! Importers of real motion capture into the 22-joint skeleton.
//!
//! Each importer turns a file into a [`MocapClip`]: something that can be posed at any time,
//! so resampling to 20 fps and time-warping interpolate the source's own rotations rather than
//! joint positions (bone lengths stay exact).

pub mod asf_amc;
pub mod bvh;
mod clip;
pub mod deepmimic;
mod error;
mod frames;
pub mod humanml3d;
pub mod isaaclab;
mod retargeted;
mod values;

pub use clip::{resample, MocapClip};
pub use error::{ImportError, ImportWarning};
pub use retargeted::{RetargetedClip, SourceSkeleton};
pub use values::{check_clip_length, short_number, MAX_POSITION_M};
