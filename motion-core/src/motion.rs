//! Whole-clip operations on joint-position motions: bone-length retargeting, mirroring,
//! heading rotation and statistics, and the conversion between pose lists and joint tensors
//! `[batch, frames, 22, 3]`; two-bone leg IK ([`leg_ik`]), shared by the foot clean-up and the
//! export's retargeting. A motion is a `[Pose]` at 20 fps unless stated otherwise.

pub mod leg_ik;

use candle_core::{DType, Device, Tensor};
use glam::{DQuat, DVec3};

use crate::skeleton::{bone_lengths, bones, Joint, Pose, NUM_JOINTS};

/// Re-targets a motion to other bone lengths, HumanML3D's `uniform_skeleton`: every bone keeps
/// its direction and takes its length from `target` (indexed by child joint); the pelvis
/// trajectory is scaled by the ratio of leg lengths (thigh + shin) of target and source, so
/// stride and height stay in proportion.
pub fn retarget_bone_lengths(poses: &[Pose], target: &[f64; NUM_JOINTS]) -> Vec<Pose> {
    let Some(first) = poses.first() else { return Vec::new() };
    let src = bone_lengths(first);
    let leg = |l: &[f64; NUM_JOINTS]| l[Joint::RightKnee.index()] + l[Joint::RightAnkle.index()];
    let scale = if leg(&src) > 0.0 { leg(target) / leg(&src) } else { 1.0 };
    poses
        .iter()
        .map(|pose| {
            let mut out = [DVec3::ZERO; NUM_JOINTS];
            out[0] = pose[0] * scale;
            for (parent, child) in bones() {
                let dir = (pose[child.index()] - pose[parent.index()]).normalize_or_zero();
                out[child.index()] = out[parent.index()] + dir * target[child.index()];
            }
            out
        })
        .collect()
}

/// One pose re-targeted to `target` bone lengths ([`retarget_bone_lengths`] of a single frame).
pub fn retarget_pose(pose: Pose, target: &[f64; NUM_JOINTS]) -> Pose {
    retarget_bone_lengths(&[pose], target).into_iter().next().unwrap_or(pose)
}

/// Mirrors a motion left to right: x is negated and left/right joints swap.
pub fn mirror(poses: &[Pose]) -> Vec<Pose> {
    poses
        .iter()
        .map(|pose| {
            let mut out = [DVec3::ZERO; NUM_JOINTS];
            for j in Joint::ALL {
                let v = pose[j.index()];
                out[j.mirror().index()] = DVec3::new(-v.x, v.y, v.z);
            }
            out
        })
        .collect()
}

/// Rotates a whole motion by `angle_rad` about the vertical axis through the origin.
pub fn rotate_heading(poses: &[Pose], angle_rad: f64) -> Vec<Pose> {
    let q = DQuat::from_rotation_y(angle_rad);
    poses.iter().map(|pose| pose.map(|v| q * v)).collect()
}

/// Largest deviation of any bone's length from its length in frame 0, metres.
pub fn bone_length_spread(poses: &[Pose]) -> f64 {
    let Some(first) = poses.first() else { return 0.0 };
    let l0 = bone_lengths(first);
    poses
        .iter()
        .flat_map(|p| {
            let l = bone_lengths(p);
            (0..NUM_JOINTS).map(move |j| (l[j] - l0[j]).abs())
        })
        .fold(0.0, f64::max)
}

/// `[batch, frames, 22, 3]` → per-sample pose lists.
pub fn tensor_to_poses(joints: &Tensor) -> candle_core::Result<Vec<Vec<Pose>>> {
    let (b, t, _, _) = joints.dims4()?;
    let flat = joints.reshape((b, t, NUM_JOINTS * 3))?.to_dtype(DType::F32)?.to_vec3::<f32>()?;
    Ok(flat
        .iter()
        .map(|m| {
            m.iter()
                .map(|row| {
                    std::array::from_fn(|j| {
                        glam::DVec3::new(f64::from(row[3 * j]), f64::from(row[3 * j + 1]), f64::from(row[3 * j + 2]))
                    })
                })
                .collect()
        })
        .collect())
}

/// Per-sample pose lists (equal lengths) → `[batch, frames, 22, 3]` of `dtype` on `device`.
pub fn poses_to_tensor(motions: &[Vec<Pose>], dtype: DType, device: &Device) -> candle_core::Result<Tensor> {
    let frames = motions.first().map_or(0, Vec::len);
    if motions.iter().any(|m| m.len() != frames) {
        candle_core::bail!("motions of different lengths cannot form one tensor");
    }
    let data: Vec<f64> = motions.iter().flatten().flat_map(|pose| pose.iter().flat_map(|v| v.to_array())).collect();
    Tensor::from_vec(data, (motions.len(), frames, NUM_JOINTS, 3), device)?.to_dtype(dtype)
}

/// Helpers that build small synthetic motions for unit tests.
#[cfg(test)]
pub(crate) mod test_support {
    use super::*;
    use crate::import::deepmimic::synthetic_walk;

    /// A walking stick figure of `frames` frames at 20 fps turning at `turn_rate` rad/s,
    /// built with the DeepMimic forward kinematics.
    pub fn walking_poses(frames: usize, turn_rate: f64) -> Vec<Pose> {
        synthetic_walk(frames, turn_rate)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use test_support::walking_poses;

    #[test]
    fn retargeting_sets_every_bone_length() {
        let poses = walking_poses(10, 0.2);
        let mut target = bone_lengths(&poses[0]);
        target.iter_mut().for_each(|l| *l *= 1.1);
        let out = retarget_bone_lengths(&poses, &target);
        for p in &out {
            let l = bone_lengths(p);
            for j in 1..NUM_JOINTS {
                assert!((l[j] - target[j]).abs() < 1e-9);
            }
        }
        assert!(bone_length_spread(&out) < 1e-9);
    }

    #[test]
    fn mirror_twice_is_identity_and_swaps_sides() {
        let poses = walking_poses(5, 0.5);
        let m = mirror(&poses);
        let l = Joint::LeftWrist.index();
        let r = Joint::RightWrist.index();
        assert!((m[2][r].x + poses[2][l].x).abs() < 1e-12);
        let mm = mirror(&m);
        assert!((mm[4][l] - poses[4][l]).length() < 1e-12);
    }
}
