//! The 22-joint SMPL / HumanML3D skeleton and the project's conventions.
//!
//! # Conventions (stated once, used everywhere)
//! - **Axes**: right-handed, **y up**, the ground is the plane y = 0. A canonical motion starts with
//!   its pelvis at x = z = 0 and the character **facing +z**; **+x is the character's left**.
//! - **Units**: metres, seconds, radians. Frame indices count from 0.
//! - **Frame rate**: [`FPS`] = 20 frames per second, HumanML3D's rate.
//! - **Joints**: the 22 SMPL body joints in HumanML3D's order ([`Joint`]); joint-position tensors are
//!   `[batch, frames, 22, 3]` with the last axis (x, y, z).

use std::fmt;
use std::str::FromStr;

use glam::DVec3;
use serde::{Deserialize, Serialize};

/// Frames per second of every motion inside the project.
pub const FPS: f64 = 20.0;

/// Number of joints of the skeleton.
pub const NUM_JOINTS: usize = 22;

macro_rules! joints {
    ($($variant:ident = $name:literal),+ $(,)?) => {
        /// A joint of the 22-joint SMPL body skeleton, in HumanML3D index order.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        #[serde(rename_all = "snake_case")]
        pub enum Joint { $($variant),+ }

        impl Joint {
            /// Every joint, in index order.
            pub const ALL: [Joint; NUM_JOINTS] = [$(Joint::$variant),+];

            /// The snake_case name used in files, prompts and constraint programs.
            pub const fn name(self) -> &'static str {
                match self { $(Joint::$variant => $name),+ }
            }
        }
    };
}

joints! {
    Pelvis = "pelvis",
    LeftHip = "left_hip",
    RightHip = "right_hip",
    Spine1 = "spine1",
    LeftKnee = "left_knee",
    RightKnee = "right_knee",
    Spine2 = "spine2",
    LeftAnkle = "left_ankle",
    RightAnkle = "right_ankle",
    Spine3 = "spine3",
    LeftFoot = "left_foot",
    RightFoot = "right_foot",
    Neck = "neck",
    LeftCollar = "left_collar",
    RightCollar = "right_collar",
    Head = "head",
    LeftShoulder = "left_shoulder",
    RightShoulder = "right_shoulder",
    LeftElbow = "left_elbow",
    RightElbow = "right_elbow",
    LeftWrist = "left_wrist",
    RightWrist = "right_wrist",
}

/// Parent of each joint (`None` for the pelvis, the root), by index.
const PARENTS: [Option<usize>; NUM_JOINTS] = [
    None,
    Some(0),
    Some(0),
    Some(0),
    Some(1),
    Some(2),
    Some(3),
    Some(4),
    Some(5),
    Some(6),
    Some(7),
    Some(8),
    Some(9),
    Some(9),
    Some(9),
    Some(12),
    Some(13),
    Some(14),
    Some(16),
    Some(17),
    Some(18),
    Some(19),
];

/// HumanML3D's `t2m_kinematic_chain`: right leg, left leg, spine to head, right arm, left arm.
pub const KINEMATIC_CHAIN: [&[Joint]; 5] = [
    &[Joint::Pelvis, Joint::RightHip, Joint::RightKnee, Joint::RightAnkle, Joint::RightFoot],
    &[Joint::Pelvis, Joint::LeftHip, Joint::LeftKnee, Joint::LeftAnkle, Joint::LeftFoot],
    &[Joint::Pelvis, Joint::Spine1, Joint::Spine2, Joint::Spine3, Joint::Neck, Joint::Head],
    &[Joint::Spine3, Joint::RightCollar, Joint::RightShoulder, Joint::RightElbow, Joint::RightWrist],
    &[Joint::Spine3, Joint::LeftCollar, Joint::LeftShoulder, Joint::LeftElbow, Joint::LeftWrist],
];

/// HumanML3D's `t2m_raw_offsets`: the rest direction of the bone from the parent to each joint
/// (unit vectors; the pelvis entry is zero). The rest pose has the arms hanging down.
const RAW_OFFSETS: [[f64; 3]; NUM_JOINTS] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [-1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, 0.0, 1.0],
    [0.0, 1.0, 0.0],
    [1.0, 0.0, 0.0],
    [-1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
];

impl Joint {
    /// Index of the joint in `[.., 22, 3]` tensors.
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The joint with this index, if any.
    pub fn from_index(index: usize) -> Option<Joint> {
        Joint::ALL.get(index).copied()
    }

    /// Parent joint in the kinematic tree; `None` for the pelvis.
    pub fn parent(self) -> Option<Joint> {
        PARENTS[self.index()].and_then(Joint::from_index)
    }

    /// Rest direction of the bone from the parent to this joint (HumanML3D `t2m_raw_offsets`).
    pub fn raw_offset(self) -> DVec3 {
        DVec3::from_array(RAW_OFFSETS[self.index()])
    }

    /// The joint on the other side of the body (itself for joints on the mid-line).
    pub fn mirror(self) -> Joint {
        let name = self.name();
        let swapped = if let Some(rest) = name.strip_prefix("left_") {
            format!("right_{rest}")
        } else if let Some(rest) = name.strip_prefix("right_") {
            format!("left_{rest}")
        } else {
            return self;
        };
        // Every left_* joint has a right_* twin and vice versa (checked by a test).
        swapped.parse().unwrap_or(self)
    }
}

impl fmt::Display for Joint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A joint name that is not one of the 22 [`Joint`]s.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown joint `{name}`; the joints are: {}", Joint::ALL.map(Joint::name).join(", "))]
pub struct UnknownJoint {
    /// The name as given.
    pub name: String,
}

impl FromStr for Joint {
    type Err = UnknownJoint;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Joint::ALL.into_iter().find(|j| j.name() == s).ok_or_else(|| UnknownJoint { name: s.to_owned() })
    }
}

/// HumanML3D's `face_joint_indx`: the hips and shoulders that define the facing direction.
pub const FACE_JOINTS: FaceJoints = FaceJoints {
    right_hip: Joint::RightHip,
    left_hip: Joint::LeftHip,
    right_shoulder: Joint::RightShoulder,
    left_shoulder: Joint::LeftShoulder,
};

/// The four joints whose left-to-right vectors give a body's facing direction.
#[derive(Debug, Clone, Copy)]
pub struct FaceJoints {
    /// Right hip.
    pub right_hip: Joint,
    /// Left hip.
    pub left_hip: Joint,
    /// Right shoulder.
    pub right_shoulder: Joint,
    /// Left shoulder.
    pub left_shoulder: Joint,
}

/// The four foot joints whose contacts the 263-d features carry, in feature order
/// `[left_ankle, left_foot, right_ankle, right_foot]`.
pub const CONTACT_JOINTS: [Joint; 4] = [Joint::LeftAnkle, Joint::LeftFoot, Joint::RightAnkle, Joint::RightFoot];

/// The 21 bones (parent, child) of the tree, in child index order.
pub fn bones() -> impl Iterator<Item = (Joint, Joint)> {
    Joint::ALL.into_iter().filter_map(|j| j.parent().map(|p| (p, j)))
}

/// Joint positions of one frame, metres, in the project's axes.
pub type Pose = [DVec3; NUM_JOINTS];

/// Bone lengths of a pose, indexed by child joint (entry 0, the pelvis, is 0).
pub fn bone_lengths(pose: &Pose) -> [f64; NUM_JOINTS] {
    let mut out = [0.0; NUM_JOINTS];
    for (parent, child) in bones() {
        out[child.index()] = (pose[child.index()] - pose[parent.index()]).length();
    }
    out
}

/// The canonical rest pose, m: the DeepMimic humanoid's zero pose mapped to the 22 joints
/// (scaled to SMPL stature, pelvis at the origin, arms hanging down, feet flat, facing +z), as
/// the importer's forward kinematics gives it to the bit (a test checks it). Its bone lengths
/// are the project's canonical skeleton.
const REST_POSE: [[f64; 3]; NUM_JOINTS] = [
    [-0.0, 0.0, 0.0],
    [0.08907895061728395, 0.0, 0.0],
    [-0.08907895061728395, 0.0, 0.0],
    [-0.0, 0.12382716049382715, 0.0],
    [0.08907895061728395, -0.4423630864197531, 0.0],
    [-0.08907895061728395, -0.4423630864197531, 0.0],
    [-0.0, 0.24781277777777777, 0.0],
    [0.08907895061728395, -0.8724735802469135, 0.0],
    [-0.08907895061728395, -0.8724735802469135, 0.0],
    [-0.0, 0.4827632716049383, 0.0],
    [0.08907895061728395, -0.9196958024691357, 0.1154320987654321],
    [-0.08907895061728395, -0.9196958024691357, 0.1154320987654321],
    [-0.0, 0.5457262345679014, 0.0],
    [0.0734567901234568, 0.45768932098765436, -0.020987654320987655],
    [-0.0734567901234568, 0.45768932098765436, -0.020987654320987655],
    [-0.0, 0.6506645061728396, 0.0],
    [0.19215246913580247, 0.5033374691358025, -0.02523765432098765],
    [-0.19215246913580247, 0.5033374691358025, -0.02523765432098765],
    [0.19215246913580247, 0.21497969135802472, -0.02523765432098765],
    [-0.19215246913580247, 0.21497969135802472, -0.02523765432098765],
    [0.19215246913580247, -0.05675481481481478, -0.02523765432098765],
    [-0.19215246913580247, -0.05675481481481478, -0.02523765432098765],
];

/// Bone lengths of the canonical rest pose, m, indexed by child joint: the one skeleton every
/// importer re-targets to.
pub fn rest_bone_lengths() -> [f64; NUM_JOINTS] {
    bone_lengths(&rest_pose())
}

/// The canonical rest pose (`REST_POSE`): what retargeting, the rigid skeleton and the
/// exports' rotations measure bones against.
pub fn rest_pose() -> Pose {
    REST_POSE.map(DVec3::from_array)
}

/// Hermite ease `3x² − 2x³` of `x` clamped to [0, 1] (the blends of looping clips and of the
/// foot clean-up's releases).
pub fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rest_pose_is_the_deepmimic_zero_pose_to_the_bit() {
        use crate::import::deepmimic::{smpl22_from_world, DM_JOINTS};
        let zero = smpl22_from_world(DVec3::ZERO, &[glam::DQuat::IDENTITY; DM_JOINTS]);
        let bits = |p: Pose| p.map(|v| v.to_array().map(f64::to_bits));
        assert_eq!(bits(rest_pose()), bits(zero));
    }

    #[test]
    fn names_round_trip_and_unknown_names_are_listed() {
        for j in Joint::ALL {
            assert_eq!(j.name().parse::<Joint>().unwrap(), j);
            assert_eq!(Joint::from_index(j.index()), Some(j));
        }
        let err = "left_toe".parse::<Joint>().unwrap_err();
        assert!(err.to_string().contains("left_toe"));
        assert!(err.to_string().contains("right_wrist"));
    }

    #[test]
    fn tree_matches_the_kinematic_chain() {
        for chain in KINEMATIC_CHAIN {
            for pair in chain.windows(2) {
                assert_eq!(pair[1].parent(), Some(pair[0]));
            }
        }
        assert_eq!(bones().count(), NUM_JOINTS - 1);
        // Parents come before children, so one pass in index order is a valid traversal.
        for (p, c) in bones() {
            assert!(p.index() < c.index());
        }
    }

    #[test]
    fn mirror_swaps_sides_and_is_an_involution() {
        assert_eq!(Joint::LeftWrist.mirror(), Joint::RightWrist);
        assert_eq!(Joint::Head.mirror(), Joint::Head);
        for j in Joint::ALL {
            assert_eq!(j.mirror().mirror(), j);
            assert_eq!(j.mirror().parent().map(Joint::mirror), j.parent());
            let o = j.raw_offset();
            assert_eq!(j.mirror().raw_offset(), DVec3::new(-o.x, o.y, o.z));
        }
    }

    #[test]
    fn serde_uses_snake_case_names() {
        let s = serde_json::to_string(&Joint::LeftWrist).unwrap();
        assert_eq!(s, "\"left_wrist\"");
        assert!(serde_json::from_str::<Joint>("\"LeftWrist\"").is_err());
    }
}
