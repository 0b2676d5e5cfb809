//! Joint rotations on one skeleton of rigid bones, solved from joint positions (inverse
//! kinematics), and their forward kinematics.
//!
//! Our motions are joint positions. Animation tools want a skeleton with fixed offsets and a
//! rotation per joint per frame. [`RotationTrack::solve`] finds, on the 22-joint chain, a
//! rotation for every joint, the root (pelvis) translation, and a small offset animation on the
//! six [`ANIMATED_OFFSETS`] joints:
//!
//! - **Skeleton** ([`RigSkeleton`]): each bone keeps the motion's mean length. Its rest direction
//!   is that of the canonical rest pose ([`rest_pose`]: standing, arms hanging down,
//!   feet flat, facing +z), except for the children of the two branching joints, the pelvis
//!   (hips, spine1) and spine3 (neck, collars), whose rest directions are their mean directions
//!   in the branching joint's frame over the motion.
//! - **Branching joints**: the rotation that best maps the rest offsets of the three children
//!   onto where the input puts them (least squares: Wahba's problem), started from the frame of
//!   up = the spine bone and across = right → left hip or collar (HumanML3D's facing joints);
//!   this carries the twist of the trunk, and is the best pose for a reader that ignores the
//!   offset animation.
//! - **Animated offsets** ([`ANIMATED_OFFSETS`], [`RotationTrack::animated_offsets_m`]): the
//!   children of a branching joint do not keep one shape in our data (the DeepMimic neck sits on
//!   the head's body and the collars on the chest's; the BVH rigs' hips and collars are points
//!   interpolated along bones of different bodies), so no rotation of the branch places all
//!   three; the fit alone misses the shipped clips by up to 34 mm. Each of these six joints
//!   therefore has, per frame, its own offset from its parent: the rest offset's length (bones
//!   stay rigid) along the direction, in the branching joint's solved frame, of the input joint.
//!   On the shipped clips these offsets move at most 33 mm from rest (Boxing_Toes; mean over
//!   a clip at most 6 mm, zero on the DeepMimic walk and run, whose branches are rigid); on a
//!   sample of the prior at most 2 mm (measured 1.6–1.8 mm on `mogen sample` and `mogen run`).
//! - **Other joints with a child**: the rotation that swings the parent's frame so the bone
//!   points, from where forward kinematics put the joint, at its child, with no twist about the
//!   bone (HumanML3D's `inverse_kinematics_np`); so an error does not carry down the limb.
//! - **End joints** (head, wrists, feet): the parent's rotation (local identity).
//!
//! Forward kinematics: `p_child = p_parent + G_parent · offset_child(t)`, `G_child = G_parent ·
//! L_child`, from the pelvis position (the root translation), where `offset_child(t)` is the
//! skeleton's offset except for the six animated ones ([`RotationTrack::offset_m`]). Where the
//! input's bones keep their lengths (every shipped clip does), this reproduces every joint to
//! rounding; otherwise the difference, the bones' change of length, is reported by [`SolveFit`].

use glam::{DMat3, DQuat, DVec3};

use super::error::ExportError;
use crate::skeleton::{rest_pose, Joint, Pose, NUM_JOINTS};

/// Below this length (m) a direction is taken as undefined and the parent's frame is kept.
const DEGENERATE_M: f64 = 1e-9;

/// The joints whose offset from their parent is animated ([`RotationTrack::animated_offsets_m`]):
/// the children of the two branching joints, the pelvis (hips, spine1) and spine3 (neck,
/// collars), in index order.
pub const ANIMATED_OFFSETS: [Joint; 6] =
    [Joint::LeftHip, Joint::RightHip, Joint::Spine1, Joint::Neck, Joint::LeftCollar, Joint::RightCollar];

/// Offsets of the [`ANIMATED_OFFSETS`] joints at one frame, in that order, m.
pub type AnimatedOffsets = [DVec3; ANIMATED_OFFSETS.len()];

/// The position of `joint` in [`ANIMATED_OFFSETS`], if its offset is animated.
fn animated_slot(joint: Joint) -> Option<usize> {
    ANIMATED_OFFSETS.iter().position(|j| *j == joint)
}

/// A skeleton of fixed bone offsets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigSkeleton {
    /// Offset of each joint from its parent in the parent's rest frame, m (project axes; the
    /// pelvis entry is zero). In the rest pose every joint's frame is the world's.
    pub offsets_m: [DVec3; NUM_JOINTS],
}

impl RigSkeleton {
    /// Joint positions of the rest pose with the pelvis at `pelvis_m`, m.
    pub fn rest_positions(&self, pelvis_m: DVec3) -> Pose {
        let mut out = [pelvis_m; NUM_JOINTS];
        for j in Joint::ALL.into_iter().skip(1) {
            let parent = j.parent().map_or(0, Joint::index);
            out[j.index()] = out[parent] + self.offsets_m[j.index()];
        }
        out
    }
}

/// How closely forward kinematics of a solved track reproduces the input positions.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SolveFit {
    /// Mean over frames and joints of the distance, m.
    pub mean_m: f64,
    /// Largest distance, m.
    pub max_m: f64,
}

/// One motion as a rotation track on a [`RigSkeleton`]: per frame the root translation, the local
/// rotation of every joint and the offsets of the six [`ANIMATED_OFFSETS`] joints.
#[derive(Debug, Clone, PartialEq)]
pub struct RotationTrack {
    /// The skeleton.
    pub skeleton: RigSkeleton,
    /// Pelvis position per frame, m.
    pub root_m: Vec<DVec3>,
    /// Rotation of each joint relative to its parent per frame (the pelvis's is global), unit
    /// quaternions; consecutive frames lie in the same hemisphere.
    pub local: Vec<[DQuat; NUM_JOINTS]>,
    /// Offset of each [`ANIMATED_OFFSETS`] joint from its parent in the parent's frame per frame,
    /// m, `[frames][6]`: the skeleton's rest offset of that joint, same length, turned to the
    /// direction of the input joint. Every other joint's offset is the skeleton's at every frame.
    pub animated_offsets_m: Vec<AnimatedOffsets>,
    /// Frames per second.
    pub fps: f64,
}

impl RotationTrack {
    /// Solves the rotations of `poses` (frames of 22 joints, m, project axes) at `fps` frames per
    /// second. `sample` only numbers errors. Fails on an empty motion or a non-finite position.
    pub fn solve(poses: &[Pose], fps: f64, sample: usize) -> Result<Self, ExportError> {
        if poses.is_empty() {
            return Err(ExportError::Shape(format!("sample {sample} has no frames")));
        }
        if !(fps.is_finite() && fps > 0.0) {
            return Err(ExportError::Shape(format!("frame rate {fps} is not a positive number")));
        }
        check_finite(poses, sample)?;
        let skeleton = rig_skeleton(poses);
        let mut local = Vec::with_capacity(poses.len());
        let mut animated_offsets_m = Vec::with_capacity(poses.len());
        let mut previous: Option<[DQuat; NUM_JOINTS]> = None;
        for pose in poses {
            let (global, offsets) = solve_pose(pose, &skeleton);
            animated_offsets_m.push(offsets);
            let mut frame: [DQuat; NUM_JOINTS] = std::array::from_fn(|j| {
                let parent = Joint::ALL[j].parent().map_or(DQuat::IDENTITY, |p| global[p.index()]);
                (parent.inverse() * global[j]).normalize()
            });
            if let Some(prev) = previous {
                for (q, p) in frame.iter_mut().zip(prev) {
                    if q.dot(p) < 0.0 {
                        *q = -*q;
                    }
                }
            }
            previous = Some(frame);
            local.push(frame);
        }
        Ok(Self { skeleton, root_m: poses.iter().map(|p| p[0]).collect(), local, animated_offsets_m, fps })
    }

    /// Frames in the track.
    pub fn frames(&self) -> usize {
        self.local.len()
    }

    /// Offset of `joint` from its parent in the parent's frame at `frame`, m: the animated offset
    /// of an [`ANIMATED_OFFSETS`] joint, the skeleton's for any other (zero for the pelvis).
    pub fn offset_m(&self, frame: usize, joint: Joint) -> DVec3 {
        match animated_slot(joint) {
            Some(k) => self.animated_offsets_m[frame][k],
            None => self.skeleton.offsets_m[joint.index()],
        }
    }

    /// Global rotation of every joint at `frame`.
    pub fn global_rotations(&self, frame: usize) -> [DQuat; NUM_JOINTS] {
        let mut global = [DQuat::IDENTITY; NUM_JOINTS];
        for j in Joint::ALL {
            let parent = j.parent().map_or(DQuat::IDENTITY, |p| global[p.index()]);
            global[j.index()] = parent * self.local[frame][j.index()];
        }
        global
    }

    /// Joint positions by forward kinematics, one pose per frame, m.
    pub fn forward_kinematics(&self) -> Vec<Pose> {
        (0..self.frames())
            .map(|t| {
                let global = self.global_rotations(t);
                let mut pose = [self.root_m[t]; NUM_JOINTS];
                for j in Joint::ALL.into_iter().skip(1) {
                    let parent = j.parent().map_or(0, Joint::index);
                    pose[j.index()] = pose[parent] + global[parent] * self.offset_m(t, j);
                }
                pose
            })
            .collect()
    }

    /// Distances between [`Self::forward_kinematics`] and `poses` (the solved input).
    pub fn fit(&self, poses: &[Pose]) -> SolveFit {
        SolveFit::between(&self.forward_kinematics(), poses)
    }
}

impl SolveFit {
    /// Distances between forward-kinematics poses `fk` and the input `poses`, frame by frame.
    pub fn between(fk: &[Pose], poses: &[Pose]) -> SolveFit {
        let (mut sum, mut max, mut n) = (0.0, 0.0_f64, 0usize);
        for (a, b) in fk.iter().zip(poses) {
            for (p, q) in a.iter().zip(b) {
                let d = p.distance(*q);
                sum += d;
                max = max.max(d);
                n += 1;
            }
        }
        SolveFit { mean_m: if n == 0 { 0.0 } else { sum / n as f64 }, max_m: max }
    }
}

fn check_finite(poses: &[Pose], sample: usize) -> Result<(), ExportError> {
    for (frame, pose) in poses.iter().enumerate() {
        for (j, p) in pose.iter().enumerate() {
            if !p.is_finite() {
                return Err(ExportError::NonFinite { sample, frame, joint: Joint::ALL[j].name(), value: p.to_array() });
            }
        }
    }
    Ok(())
}

/// A joint whose children are placed by a two-direction frame, with the child along "up" and
/// the two children across.
struct Branch {
    joint: Joint,
    up: Joint,
    left: Joint,
    right: Joint,
}

impl Branch {
    /// The joints whose parent is the branching joint.
    fn children(&self) -> impl Iterator<Item = Joint> + '_ {
        Joint::ALL.into_iter().filter(|c| c.parent() == Some(self.joint))
    }
}

/// Rounds of (rest directions of a branch's children, the branch's frames) refinement.
const BRANCH_REFINEMENTS: usize = 3;
/// Small-rotation steps of a branch fit.
const WAHBA_ITERATIONS: usize = 50;

const BRANCHES: [Branch; 2] = [
    Branch { joint: Joint::Pelvis, up: Joint::Spine1, left: Joint::LeftHip, right: Joint::RightHip },
    Branch { joint: Joint::Spine3, up: Joint::Neck, left: Joint::LeftCollar, right: Joint::RightCollar },
];

/// The child that a non-branching joint's rotation aims its bone at.
fn aim_child(joint: Joint) -> Option<Joint> {
    Joint::ALL.into_iter().find(|c| c.parent() == Some(joint))
}

/// The rotation whose columns are (across, up, across × up) built from `up` and `across`, or
/// `None` when either is degenerate or they are parallel.
fn two_vector_frame(up: DVec3, across: DVec3) -> Option<DQuat> {
    let y = up.try_normalize()?;
    let x = (across - y * across.dot(y)).try_normalize()?;
    let z = x.cross(y);
    Some(DQuat::from_mat3(&DMat3::from_cols(x, y, z)).normalize())
}

fn branch_frame(branch: &Branch, pose: &Pose) -> Option<DQuat> {
    let at = |j: Joint| pose[j.index()];
    two_vector_frame(at(branch.up) - at(branch.joint), at(branch.left) - at(branch.right))
}

/// Bone lengths (motion means) along the canonical rest directions, the branching joints'
/// children along their mean directions in the branch frame (refined with the fitted frames).
fn rig_skeleton(poses: &[Pose]) -> RigSkeleton {
    let rest = rest_pose();
    let mut offsets = [DVec3::ZERO; NUM_JOINTS];
    for j in Joint::ALL.into_iter().skip(1) {
        let parent = j.parent().map_or(0, Joint::index);
        let length = crate::numeric::mean(poses.iter().map(|p| p[j.index()].distance(p[parent])));
        let direction = (rest[j.index()] - rest[parent]).try_normalize().unwrap_or(j.raw_offset());
        offsets[j.index()] = direction * length;
    }
    for branch in &BRANCHES {
        let mut frames: Vec<Option<DQuat>> = poses.iter().map(|p| branch_frame(branch, p)).collect();
        for _ in 0..BRANCH_REFINEMENTS {
            for child in branch.children() {
                let mean: DVec3 = poses
                    .iter()
                    .zip(&frames)
                    .filter_map(|(p, frame)| {
                        (frame.as_ref()?.inverse() * (p[child.index()] - p[branch.joint.index()])).try_normalize()
                    })
                    .sum();
                if let Some(direction) = mean.try_normalize() {
                    offsets[child.index()] = direction * offsets[child.index()].length();
                }
            }
            for (frame, pose) in frames.iter_mut().zip(poses) {
                *frame = frame.map(|f| fit_branch(branch, f, &offsets, pose, pose[branch.joint.index()]));
            }
        }
    }
    RigSkeleton { offsets_m: offsets }
}

/// The rotation that best maps the rest offsets of `branch`'s children onto their bones in
/// `pose` as seen from `at` (least squares in metres: Wahba's problem), by small-rotation steps
/// from `start`.
fn fit_branch(branch: &Branch, start: DQuat, offsets: &[DVec3; NUM_JOINTS], pose: &Pose, at: DVec3) -> DQuat {
    let mut rotation = start;
    for _ in 0..WAHBA_ITERATIONS {
        let (mut torque, mut scale) = (DVec3::ZERO, 0.0);
        for child in branch.children() {
            let (from, to) = (rotation * offsets[child.index()], pose[child.index()] - at);
            torque += from.cross(to);
            scale += from.length() * to.length();
        }
        if scale <= 0.0 {
            break;
        }
        let step = torque / scale;
        rotation = (DQuat::from_scaled_axis(step) * rotation).normalize();
        if step.length() < 1e-12 {
            break;
        }
    }
    rotation
}

/// Global rotation of every joint of one pose on `skeleton`, and the offsets of the
/// [`ANIMATED_OFFSETS`] joints. Joints are placed by forward kinematics as they are solved: a
/// branching joint's children at their rest lengths along their input directions, and a joint
/// with one child aims its bone from where it was placed at the child's input position, so an
/// error does not carry down the limb.
fn solve_pose(pose: &Pose, skeleton: &RigSkeleton) -> ([DQuat; NUM_JOINTS], AnimatedOffsets) {
    let mut global = [DQuat::IDENTITY; NUM_JOINTS];
    let mut placed = [pose[0]; NUM_JOINTS];
    let mut animated = ANIMATED_OFFSETS.map(|j| skeleton.offsets_m[j.index()]);
    for j in Joint::ALL {
        let parent = j.parent().map_or(DQuat::IDENTITY, |p| global[p.index()]);
        if let Some(p) = j.parent() {
            let rest = skeleton.offsets_m[j.index()];
            let offset = match animated_slot(j) {
                Some(k) => {
                    let input = parent.inverse() * (pose[j.index()] - placed[p.index()]);
                    animated[k] = match input.try_normalize() {
                        Some(direction) if input.length() > DEGENERATE_M => direction * rest.length(),
                        _ => rest,
                    };
                    animated[k]
                }
                None => rest,
            };
            placed[j.index()] = placed[p.index()] + parent * offset;
        }
        global[j.index()] = if let Some(branch) = BRANCHES.iter().find(|b| b.joint == j) {
            match branch_frame(branch, pose) {
                Some(start) => fit_branch(branch, start, &skeleton.offsets_m, pose, placed[j.index()]),
                None => parent,
            }
        } else if let Some(child) = aim_child(j) {
            let bone = pose[child.index()] - placed[j.index()];
            let rest = parent * skeleton.offsets_m[child.index()];
            match (rest.try_normalize(), bone.try_normalize()) {
                (Some(from), Some(to)) if bone.length() > DEGENERATE_M => {
                    (DQuat::from_rotation_arc(from, to) * parent).normalize()
                }
                _ => parent,
            }
        } else {
            parent
        };
    }
    (global, animated)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::database::catalog::{Catalog, SourceFormat};
    use crate::import::bvh::{BvhClip, BvhOptions};
    use crate::import::isaaclab::IsaacAmpClip;
    use crate::import::{deepmimic::shipped, resample, MocapClip};

    /// Every shipped clip (the catalog's, the mocapbank BVH and the three Isaac Lab AMP clips)
    /// with its name and format, resampled to 20 fps.
    pub(in crate::export) fn shipped_clips() -> Vec<(String, SourceFormat, Vec<Pose>)> {
        let mocap = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap");
        let catalog = Catalog::read(&mocap.join("catalog.json")).unwrap();
        let (sources, _) = catalog.load().unwrap();
        let mut clips: Vec<(String, SourceFormat, Box<dyn MocapClip>)> =
            catalog.clips.iter().zip(sources).map(|(entry, s)| (s.name, entry.format, s.clip)).collect();
        let (bank, _) = BvhClip::read(&mocap.join("bvhtoolbox/test_mocapbank.bvh"), &BvhOptions::default()).unwrap();
        clips.push(("test_mocapbank".into(), SourceFormat::Bvh, Box::new(bank)));
        for name in ["humanoid_dance", "humanoid_run", "humanoid_walk"] {
            let (clip, _) = IsaacAmpClip::read(&mocap.join(format!("isaaclab/{name}.npz"))).unwrap();
            clips.push((name.into(), SourceFormat::IsaaclabAmp, Box::new(clip)));
        }
        assert_eq!(clips.len(), 27);
        clips.into_iter().map(|(name, family, clip)| (name, family, resample(clip.as_ref(), 1.0, None))).collect()
    }

    /// Largest and mean distance of the animated offsets from their rest offsets, m.
    fn offset_motion(track: &RotationTrack) -> (f64, f64) {
        let distances: Vec<f64> = track
            .animated_offsets_m
            .iter()
            .flat_map(|frame| {
                ANIMATED_OFFSETS.iter().zip(frame).map(|(j, o)| o.distance(track.skeleton.offsets_m[j.index()]))
            })
            .collect();
        (distances.iter().copied().fold(0.0, f64::max), crate::numeric::mean(distances.iter().copied()))
    }

    /// A pose on a rigid skeleton: the rest pose with the left elbow bent by `elbow` about +x,
    /// the whole body turned by `yaw` about +y and moved to `at`.
    fn posed(skeleton: &RigSkeleton, yaw: f64, elbow: f64, at: DVec3) -> (Pose, [DQuat; NUM_JOINTS]) {
        let mut local = [DQuat::IDENTITY; NUM_JOINTS];
        local[0] = DQuat::from_rotation_y(yaw);
        local[Joint::LeftElbow.index()] = DQuat::from_rotation_x(elbow);
        let track = RotationTrack {
            skeleton: *skeleton,
            root_m: vec![at],
            local: vec![local],
            animated_offsets_m: vec![ANIMATED_OFFSETS.map(|j| skeleton.offsets_m[j.index()])],
            fps: 20.0,
        };
        (track.forward_kinematics()[0], local)
    }

    #[test]
    fn a_known_rotation_is_recovered() {
        let rest = rest_pose();
        let skeleton = rig_skeleton(&[rest]);
        // The rest pose is its own rest: every rotation is the identity.
        let track = RotationTrack::solve(&[rest], 20.0, 0).unwrap();
        for q in track.local[0] {
            assert!(q.angle_between(DQuat::IDENTITY) < 1e-9, "{q:?}");
        }
        let (pose, truth) = posed(&skeleton, 0.7, -1.1, DVec3::new(1.0, 0.9, 2.0));
        let track = RotationTrack::solve(&[pose], 20.0, 0).unwrap();
        assert!(track.local[0][0].angle_between(truth[0]) < 1e-9);
        let elbow = Joint::LeftElbow.index();
        assert!(track.local[0][elbow].angle_between(truth[elbow]) < 1e-9, "{:?}", track.local[0][elbow]);
        assert!(track.fit(&[pose]).max_m < 1e-9);
        assert_eq!(track.root_m[0], DVec3::new(1.0, 0.9, 2.0));
    }

    #[test]
    fn forward_kinematics_reproduces_a_real_clip() {
        let clip = shipped::clip("humanoid3d_walk.txt");
        let poses: Vec<Pose> = (0..60).map(|k| clip.pose_at(k as f64 / 20.0)).collect();
        let track = RotationTrack::solve(&poses, 20.0, 0).unwrap();
        let fit = track.fit(&poses);
        assert!(fit.max_m < 0.01, "{fit:?}");
        // Consecutive frames stay in one hemisphere (no sign flips for the exporters).
        for pair in track.local.windows(2) {
            for (a, b) in pair[0].iter().zip(pair[1]) {
                assert!(a.dot(b) >= 0.0);
            }
        }
    }

    /// The shipped clips keep their bone lengths, but not the shape of the two branches: the
    /// DeepMimic neck sits on the head's body and the collars on the chest's, and the BVH rigs'
    /// hips and collars are points along bones of different bodies. The branch fit alone missed
    /// them by up to 34 mm (neck, collars, hips); the animated offsets take up the rest.
    #[test]
    fn forward_kinematics_reproduces_every_shipped_clip() {
        let mut worst: Vec<(SourceFormat, [f64; 3])> = Vec::new();
        for (name, family, poses) in shipped_clips() {
            let track = RotationTrack::solve(&poses, 20.0, 0).unwrap();
            let fit = track.fit(&poses);
            let (moved, moved_mean) = offset_motion(&track);
            println!(
                "{family:?}/{name}: FK mean {:.1e} m, max {:.1e} m; animated offsets from rest: max {:.1} mm, mean \
                 {:.1} mm",
                fit.mean_m,
                fit.max_m,
                moved * 1e3,
                moved_mean * 1e3
            );
            // Issue 16 asks for 1 cm; bones of constant length come back to rounding.
            assert!(fit.max_m < 1e-6, "{name}: {fit:?}");
            let figures = [fit.max_m, moved, moved_mean];
            match worst.iter_mut().find(|(f, _)| *f == family) {
                Some((_, w)) => *w = std::array::from_fn(|k| w[k].max(figures[k])),
                None => worst.push((family, figures)),
            }
        }
        for (family, [fit, moved, moved_mean]) in worst {
            println!(
                "{family:?}: FK max {fit:.1e} m; animated offsets from rest: max {:.1} mm, largest mean {:.1} mm",
                moved * 1e3,
                moved_mean * 1e3
            );
        }
    }

    #[test]
    fn animated_offsets_keep_their_rest_length_and_belong_to_the_branches() {
        let children: Vec<Joint> = BRANCHES.iter().flat_map(Branch::children).collect();
        let mut animated = ANIMATED_OFFSETS.to_vec();
        animated.sort_by_key(|j| j.index());
        assert_eq!(animated, children);
        // A clip whose branches change shape most, so the offsets do move.
        let (name, _, poses) = shipped_clips().into_iter().find(|(name, _, _)| name == "boxing_toes_20fps").unwrap();
        let track = RotationTrack::solve(&poses, 20.0, 0).unwrap();
        assert_eq!(track.animated_offsets_m.len(), track.frames());
        assert!(offset_motion(&track).0 > 0.01, "{name}: {:?}", offset_motion(&track));
        for t in 0..track.frames() {
            for j in Joint::ALL {
                let (offset, rest) = (track.offset_m(t, j), track.skeleton.offsets_m[j.index()]);
                assert!((offset.length() - rest.length()).abs() < 1e-12, "{name} frame {t} {}", j.name());
                if !ANIMATED_OFFSETS.contains(&j) {
                    assert_eq!(offset, rest);
                }
            }
        }
    }

    #[test]
    fn bad_input_names_the_sample_frame_and_joint() {
        let mut poses = vec![rest_pose(); 3];
        poses[2][Joint::LeftWrist.index()].y = f64::NAN;
        let err = RotationTrack::solve(&poses, 20.0, 4).unwrap_err().to_string();
        assert!(err.contains("sample 4") && err.contains("frame 2") && err.contains("left_wrist"), "{err}");
        assert!(RotationTrack::solve(&[], 20.0, 0).is_err());
        assert!(RotationTrack::solve(&poses[..1], 0.0, 0).is_err());
    }
}
