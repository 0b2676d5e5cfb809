//! BVH (Biovision hierarchy) motion capture: a general reader ([`Bvh`]), joint maps from common
//! rigs to the 22 joints ([`Rig`]), and [`BvhClip`], which poses a file at any time on the
//! project's canonical skeleton.
//!
//! # Format and conventions
//! - `HIERARCHY`: one `ROOT`, nested `JOINT`s and `End Site`s, each with an `OFFSET` (its
//!   position in the parent's frame, file units) and, for joints, `CHANNELS n ...` with any of
//!   `Xposition Yposition Zposition Xrotation Yrotation Zrotation` in any order, on any joint.
//! - `MOTION`: `Frames: N`, `Frame Time: dt` (seconds), then one line of channel values per frame,
//!   in hierarchy order.
//! - Rotations are Euler angles in degrees, intrinsic in the order written:
//!   `R = R_first · R_second · R_third`. A position channel replaces that component of the
//!   joint's OFFSET (the usual reading for the root, whose OFFSET is normally zero).
//! - A joint's world transform is `parent_world · Translate(offset) · R`.
//! - Axes: Y-up files are right-handed with the character's left at +x when it faces +z, which
//!   are already our axes (CMU/cgspeed, Mixamo exports, Boxing_Toes all are). Z-up files
//!   (character facing −y, left at +x) are turned with `(x, y, z) → (x, z, −y)`.
//! - Units: see [`LengthUnit`]; without one, the unit is detected from the rest skeleton's height.

mod animation;
mod clip;
mod error;
mod file;
mod hierarchy;
mod rig;
mod units;

pub use animation::BvhAnimation;
pub use clip::{BvhClip, BvhOptions};
pub use file::Bvh;
pub use hierarchy::{Axis, BvhJoint, Channel};
pub use rig::Rig;
pub use units::{LengthUnit, UpAxis};

#[cfg(test)]
mod tests;
