//! [`RetargetedClip`]: a capture on its own skeleton, mapped to the 22 joints and retargeted to
//! the canonical bone lengths. The BVH and ASF/AMC importers differ only in their
//! [`SourceSkeleton`].

use crate::motion::retarget_pose;
use crate::skeleton::{Pose, NUM_JOINTS};

use super::clip::MocapClip;

/// A capture format's motion on its own skeleton, with the 22 points it picks from it.
pub trait SourceSkeleton {
    /// Length of the source motion, seconds.
    fn duration_s(&self) -> f64;
    /// Seconds between source frames.
    fn frame_time_s(&self) -> f64;
    /// The 22 joints at `t_s` with the source's own bone lengths (metres, our axes).
    fn mapped_pose_at(&self, t_s: f64) -> Pose;
    /// The source's rest skeleton mapped to the 22 joints (metres, our axes).
    fn mapped_rest_pose(&self) -> Pose;
}

/// A named capture posed on the 22 joints: the source ([`SourceSkeleton`]) picks the 22 points
/// and bone lengths are retargeted to `target` with
/// [`retarget_pose`](crate::motion::retarget_pose) (bone directions kept, the root trajectory
/// scaled by the leg-length ratio). Not cyclic.
#[derive(Debug, Clone)]
pub struct RetargetedClip<S> {
    pub(super) name: String,
    pub(super) source: S,
    /// Bone lengths the poses are retargeted to, m, per joint (to its parent).
    pub(super) target: [f64; NUM_JOINTS],
}

impl<S: SourceSkeleton> RetargetedClip<S> {
    /// The clip's name (the file's stem).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Source frame rate, frames per second (1 / frame time).
    pub fn fps(&self) -> f64 {
        1.0 / self.source.frame_time_s()
    }

    /// The 22 joints at `t_s` with the source's own bone lengths (metres, our axes).
    pub fn mapped_pose_at(&self, t_s: f64) -> Pose {
        self.source.mapped_pose_at(t_s)
    }

    /// The source's rest skeleton mapped to the 22 joints.
    pub fn mapped_rest_pose(&self) -> Pose {
        self.source.mapped_rest_pose()
    }
}

impl<S: SourceSkeleton> MocapClip for RetargetedClip<S> {
    fn duration_s(&self) -> f64 {
        self.source.duration_s()
    }

    fn is_cyclic(&self) -> bool {
        false
    }

    fn pose_at(&self, t_s: f64) -> Pose {
        retarget_pose(self.mapped_pose_at(t_s), &self.target)
    }
}
