//! Outputs that other tools open: a rotation track on one rigid skeleton ([`rotations`]) at the
//! motion's or an engine's frame rate ([`resample`]), moving or in place ([`in_place`]), BVH
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

pub mod armature;
pub mod bvh;
mod error;
mod folder;
pub mod glb;
pub mod gltf;
pub mod in_place;
mod outputs;
pub mod resample;
pub mod retarget;
pub mod rotations;
pub mod scene;
pub mod viewer;

pub use armature::{ArmatureNode, ArmatureTrack};
pub use error::{write_atomically, ExportError};
pub use folder::OutputFolder;
pub use outputs::{
    read_joints_npy, write_outputs, ExportInput, ExportManifest, ExportedSample, Probe, RigFile, RigProbe,
};
pub use rotations::{RigSkeleton, RotationTrack, SolveFit, ANIMATED_OFFSETS};
pub use scene::{position_targets, scene_boxes, PositionTarget, SceneBox, SceneExtent, SceneRole};
