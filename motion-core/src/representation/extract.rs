//! Joint positions → 263-d features, the way HumanML3D's `process_file` computes them.
//!
//! Steps: put the clip on the floor (lowest joint of the whole clip at y = 0), move frame 0's
//! pelvis to x = z = 0, turn the clip so frame 0 faces +z, detect foot contacts by displacement,
//! solve HumanML3D's swing inverse kinematics for the 6-D rotations, and express positions and
//! velocities in the per-frame heading frame.
//!
//! One deliberate difference: HumanML3D's `inverse_kinematics_np` unpacks the hip pair in the
//! wrong order, so its "across" vector is shoulders minus hips (later code calls this
//! `fix_bug`). We add the two left-to-right vectors as `process_file` does. Bone lengths are
//! not re-targeted here (HumanML3D's `uniform_skeleton`); importers do that with
//! [`crate::motion::retarget_bone_lengths`].

use glam::{DMat3, DQuat, DVec3};

use super::layout::{FeatureFrame, FEATURE_DIM, FOOT_CONTACT, LOCAL_VEL, RIC, ROT};
use crate::skeleton::{Joint, Pose, CONTACT_JOINTS, FACE_JOINTS, KINEMATIC_CHAIN, NUM_JOINTS};
use crate::MotionError;

/// A foot joint is in contact when its squared displacement over one frame is below this
/// (m², HumanML3D's `feet_thre`; 0.002 m² per frame is about 0.9 m/s at 20 fps).
pub const FOOT_CONTACT_THRESHOLD_M2: f64 = 0.002;

/// Standard deviation, in frames, of the Gaussian that smooths the facing direction
/// (HumanML3D's `smooth_forward`).
const FORWARD_SMOOTHING_SIGMA: f64 = 20.0;

/// Features of a clip together with the canonical joint positions they encode.
#[derive(Debug, Clone)]
pub struct ExtractedMotion {
    /// N−1 feature frames.
    pub features: Vec<FeatureFrame>,
    /// The N canonical joint frames (floor at y = 0, frame 0 at the origin facing +z); the
    /// first N−1 are what [`super::recover_from_ric`] reproduces.
    pub canonical: Vec<Pose>,
}

/// Puts a clip on the floor, moves frame 0's pelvis to x = z = 0 and turns it to face +z.
pub fn canonicalize(poses: &[Pose]) -> Result<Vec<Pose>, MotionError> {
    check_poses(poses)?;
    let floor = poses.iter().flat_map(|p| p.iter().map(|v| v.y)).fold(f64::INFINITY, f64::min);
    let first = poses.first().ok_or(MotionError::TooShort { frames: 0, min: 2 })?;
    let origin = DVec3::new(first[0].x, floor, first[0].z);
    let heading = heading_rotation(facing_direction(first).ok_or(MotionError::NoFacing { frame: 0 })?);
    Ok(poses.iter().map(|pose| pose.map(|v| heading * (v - origin))).collect())
}

/// Computes the 263-d features of a clip of joint positions (metres, y up, at the rate of the
/// clip; the project uses 20 fps). Needs at least 2 frames.
pub fn extract_features(poses: &[Pose]) -> Result<ExtractedMotion, MotionError> {
    let canonical = canonicalize(poses)?;
    let n = canonical.len();

    // Root heading per frame: rotation taking the smoothed facing direction to +z; frame 0
    // is the identity by construction (HumanML3D sets it so).
    let forward = smoothed_forward(&canonical)?;
    let mut r_rot: Vec<DQuat> = forward.iter().map(|f| heading_rotation(*f)).collect();
    if let Some(r0) = r_rot.first_mut() {
        *r0 = DQuat::IDENTITY;
    }
    make_continuous(&mut r_rot);
    let local_rot = swing_rotations(&canonical, &r_rot);

    let mut features = Vec::with_capacity(n - 1);
    for t in 0..n - 1 {
        let (cur, next) = (&canonical[t], &canonical[t + 1]);
        let mut f = [0f32; FEATURE_DIM];
        let r_vel = r_rot[t + 1] * r_rot[t].conjugate();
        f[0] = r_vel.y.clamp(-1.0, 1.0).asin() as f32;
        let root_vel = r_rot[t + 1] * (next[0] - cur[0]);
        f[1] = root_vel.x as f32;
        f[2] = root_vel.z as f32;
        f[3] = cur[0].y as f32;
        let root_xz = DVec3::new(cur[0].x, 0.0, cur[0].z);
        for j in 1..NUM_JOINTS {
            let ric = r_rot[t] * (cur[j] - root_xz);
            put3(&mut f, RIC.start + 3 * (j - 1), ric);
            let m = DMat3::from_quat(local_rot[t][j]);
            put3(&mut f, ROT.start + 6 * (j - 1), m.x_axis);
            put3(&mut f, ROT.start + 6 * (j - 1) + 3, m.y_axis);
        }
        for j in 0..NUM_JOINTS {
            put3(&mut f, LOCAL_VEL.start + 3 * j, r_rot[t] * (next[j] - cur[j]));
        }
        for (k, joint) in CONTACT_JOINTS.iter().enumerate() {
            let d = next[joint.index()] - cur[joint.index()];
            f[FOOT_CONTACT.start + k] = if d.length_squared() < FOOT_CONTACT_THRESHOLD_M2 { 1.0 } else { 0.0 };
        }
        features.push(f);
    }
    Ok(ExtractedMotion { features, canonical })
}

fn put3(f: &mut FeatureFrame, at: usize, v: DVec3) {
    f[at] = v.x as f32;
    f[at + 1] = v.y as f32;
    f[at + 2] = v.z as f32;
}

fn check_poses(poses: &[Pose]) -> Result<(), MotionError> {
    if poses.len() < 2 {
        return Err(MotionError::TooShort { frames: poses.len(), min: 2 });
    }
    for (frame, pose) in poses.iter().enumerate() {
        if let Some(joint) = pose.iter().position(|v| !v.is_finite()) {
            return Err(MotionError::NonFinite { frame, joint: Joint::ALL[joint] });
        }
    }
    Ok(())
}

/// Horizontal facing direction of a pose (unit, y = 0), from hips and shoulders; `None` when
/// the body is so twisted that the left-to-right vectors cancel or point straight up.
pub(crate) fn facing_direction(pose: &Pose) -> Option<DVec3> {
    let fj = FACE_JOINTS;
    let across = (pose[fj.right_hip.index()] - pose[fj.left_hip.index()])
        + (pose[fj.right_shoulder.index()] - pose[fj.left_shoulder.index()]);
    let forward = DVec3::Y.cross(across);
    (forward.length() > 1e-9).then(|| forward.normalize())
}

/// Rotation about y that takes the horizontal direction `forward` to +z.
pub(crate) fn heading_rotation(forward: DVec3) -> DQuat {
    DQuat::from_rotation_y(-forward.x.atan2(forward.z))
}

/// Facing directions smoothed over time with a Gaussian (σ = 20 frames, radius 80, edges
/// repeated), as `scipy.ndimage.gaussian_filter1d(..., 20, mode='nearest')`.
fn smoothed_forward(poses: &[Pose]) -> Result<Vec<DVec3>, MotionError> {
    let raw = poses
        .iter()
        .enumerate()
        .map(|(frame, p)| facing_direction(p).ok_or(MotionError::NoFacing { frame }))
        .collect::<Result<Vec<_>, _>>()?;
    let radius = (4.0 * FORWARD_SMOOTHING_SIGMA + 0.5) as i64;
    let weights: Vec<f64> =
        (-radius..=radius).map(|k| (-0.5 * (k as f64 / FORWARD_SMOOTHING_SIGMA).powi(2)).exp()).collect();
    let total: f64 = weights.iter().sum();
    let last = raw.len() as i64 - 1;
    (0..raw.len() as i64)
        .map(|i| {
            let s = (-radius..=radius)
                .zip(&weights)
                .map(|(k, w)| raw[(i + k).clamp(0, last) as usize] * *w)
                .fold(DVec3::ZERO, |a, b| a + b)
                / total;
            let s = DVec3::new(s.x, 0.0, s.z);
            if s.length() > 1e-9 {
                Ok(s.normalize())
            } else {
                Err(MotionError::NoFacing { frame: i as usize })
            }
        })
        .collect()
}

/// HumanML3D's swing IK: each joint's local rotation takes its rest bone direction
/// ([`Joint::raw_offset`]) to the observed bone direction, relative to the accumulated rotation
/// of its chain, which starts from the root heading at every chain start.
fn swing_rotations(poses: &[Pose], r_rot: &[DQuat]) -> Vec<[DQuat; NUM_JOINTS]> {
    let mut out: Vec<[DQuat; NUM_JOINTS]> = poses
        .iter()
        .zip(r_rot)
        .map(|(pose, root)| {
            let mut q = [DQuat::IDENTITY; NUM_JOINTS];
            q[0] = *root;
            for chain in KINEMATIC_CHAIN {
                let mut acc = *root;
                for pair in chain.windows(2) {
                    let (parent, child) = (pair[0].index(), pair[1].index());
                    let bone = pose[child] - pose[parent];
                    let swing = if bone.length() > 1e-12 {
                        DQuat::from_rotation_arc(pair[1].raw_offset(), bone.normalize())
                    } else {
                        DQuat::IDENTITY
                    };
                    let local = acc.conjugate() * swing;
                    q[child] = local;
                    acc *= local;
                }
            }
            q
        })
        .collect();
    for j in 0..NUM_JOINTS {
        let mut track: Vec<DQuat> = out.iter().map(|q| q[j]).collect();
        make_continuous(&mut track);
        for (frame, q) in out.iter_mut().zip(track) {
            frame[j] = q;
        }
    }
    out
}

/// Flips quaternion signs so consecutive ones have a non-negative dot product (`qfix`).
fn make_continuous(track: &mut [DQuat]) {
    for t in 1..track.len() {
        if track[t].dot(track[t - 1]) < 0.0 {
            track[t] = -track[t];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::test_support::walking_poses;

    #[test]
    fn canonical_clip_stands_on_the_floor_at_the_origin_facing_z() {
        let poses = walking_poses(30, 0.7);
        let c = canonicalize(&poses).unwrap();
        let min_y = c.iter().flat_map(|p| p.iter().map(|v| v.y)).fold(f64::INFINITY, f64::min);
        assert!(min_y.abs() < 1e-12);
        assert!(c[0][0].x.abs() < 1e-12 && c[0][0].z.abs() < 1e-12);
        let f = facing_direction(&c[0]).unwrap();
        assert!((f - DVec3::Z).length() < 1e-9, "{f}");
        // +x is the character's left.
        assert!(c[0][Joint::LeftHip.index()].x > 0.0);
    }

    #[test]
    fn features_have_one_frame_less_and_contacts_are_binary() {
        let poses = walking_poses(40, 0.3);
        let e = extract_features(&poses).unwrap();
        assert_eq!(e.features.len(), 39);
        for f in &e.features {
            assert!(f.iter().all(|v| v.is_finite()));
            for c in &f[FOOT_CONTACT] {
                assert!(*c == 0.0 || *c == 1.0);
            }
        }
    }

    #[test]
    fn bad_input_is_an_error_naming_frame_and_joint() {
        let mut poses = walking_poses(5, 0.0);
        poses[3][Joint::Head.index()].y = f64::NAN;
        let err = extract_features(&poses).unwrap_err().to_string();
        assert!(err.contains("frame 3") && err.contains("head"), "{err}");
        assert!(extract_features(&poses[..1]).is_err());
    }

    #[test]
    fn heading_rotation_takes_forward_to_z_even_when_facing_backwards() {
        for angle in [0.0, 0.5, 2.0, std::f64::consts::PI, -2.5] {
            let f = DVec3::new(angle.sin(), 0.0, angle.cos());
            assert!((heading_rotation(f) * f - DVec3::Z).length() < 1e-12);
        }
    }
}
