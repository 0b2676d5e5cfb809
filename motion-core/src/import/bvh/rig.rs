//! Joint maps from common BVH rigs to the 22 joints.

use super::file::Bvh;
use crate::skeleton::{Joint, NUM_JOINTS};
use Source::{At, Between, TowardEnd};

/// Where one of our joints sits on a source rig.
#[derive(Debug, Clone, Copy)]
enum Source {
    /// At a source joint.
    At(&'static str),
    /// A fraction of the way from the first joint to the second (its descendant).
    Between(&'static str, &'static str, f64),
    /// A fraction of the way from a joint to its End Site (for rigs without toe joints).
    TowardEnd(&'static str, f64),
}

/// A family of joint names that [`BvhClip`](super::BvhClip) can map to the 22 joints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rig {
    /// CMU mocap in the cgspeed BVH conversion: Hips, LHipJoint, LeftUpLeg, LeftLeg, LeftFoot,
    /// LeftToeBase, LowerBack, Spine, Spine1, Neck, Neck1, Head, LeftShoulder, LeftArm,
    /// LeftForeArm, LeftHand, fingers; right side likewise.
    Cmu,
    /// Mixamo (`mixamorig:` prefix optional): Hips, Spine, Spine1, Spine2, Neck, Head,
    /// LeftShoulder, LeftArm, LeftForeArm, LeftHand, LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase.
    Mixamo,
    /// ACCAD's Open Motion Project takes (MotionBuilder's rig): Hips, ToSpine, Spine, Spine1, Neck,
    /// Head, LeftShoulder, LeftArm, LeftForeArm, LeftHand, LeftUpLeg, LeftLeg, LeftFoot,
    /// LeftToeBase; Mixamo's names without Spine2.
    Accad,
    /// Joint-named limbs on a Hips/Ab/Chest spine, as in assimp's Boxing_Toes.bvh: Hips, Ab,
    /// Chest, Neck, Head, LeftCollar, LeftShoulder, LeftElbow, LeftWrist, LeftHip, LeftKnee,
    /// LeftAnkle, LeftToes.
    HipsAbChest,
    /// MocapBank's rig (bvhtoolbox's `test_mocapbank.bvh`): Hips, Chest, Chest2, Neck, Head,
    /// LeftCollar, LeftShoulder, LeftElbow, LeftWrist, LeftHip, LeftKnee, LeftAnkle and an End
    /// Site at the toe tip instead of a toe joint.
    HipsChestChest2,
    /// The project's own export ([`crate::export::bvh`]): the 22 joints under their snake_case
    /// names, which are SMPL's (`pelvis`, `left_hip`, …), each at its own node. Its
    /// [`BvhClip::mapped_pose_at`](super::BvhClip::mapped_pose_at) is the exported motion itself.
    Smpl,
}

impl Rig {
    /// Every rig, in detection order.
    pub const ALL: [Rig; 6] = [Rig::Cmu, Rig::Mixamo, Rig::Accad, Rig::HipsAbChest, Rig::HipsChestChest2, Rig::Smpl];

    /// Display name.
    pub fn name(self) -> &'static str {
        match self {
            Rig::Cmu => "CMU (cgspeed)",
            Rig::Mixamo => "Mixamo",
            Rig::Accad => "ACCAD (MotionBuilder)",
            Rig::HipsAbChest => "Hips/Ab/Chest",
            Rig::HipsChestChest2 => "Hips/Chest/Chest2",
            Rig::Smpl => "SMPL",
        }
    }

    /// Our joints in [`Joint`](crate::skeleton::Joint) order, placed where the SMPL joint sits relative to the rig's.
    /// Spine points are spread like SMPL's (spine1 ≈ 23 %, spine2 ≈ 49 % of the way from pelvis
    /// to neck); spine3 sits at the base of the neck, where the canonical (DeepMimic) skeleton
    /// has it, and collars sit 35-40 % of the way out along the clavicle bone where a rig's
    /// clavicle starts on the mid-line.
    fn sources(self) -> [Source; NUM_JOINTS] {
        match self {
            // cgspeed's torso is short (Hips → Spine 0.115 m, → Spine1 0.23 m where neck and
            // clavicles start, shoulders 0.30 m, Neck1 0.33 m, Head 0.43 m), hence the fractions.
            Rig::Cmu => [
                At("Hips"),
                At("LeftUpLeg"),
                At("RightUpLeg"),
                Between("LowerBack", "Spine", 0.66),
                At("LeftLeg"),
                At("RightLeg"),
                Between("Spine", "Spine1", 0.42),
                At("LeftFoot"),
                At("RightFoot"),
                Between("Spine1", "Neck1", 0.4),
                At("LeftToeBase"),
                At("RightToeBase"),
                At("Neck1"),
                Between("LeftShoulder", "LeftArm", 0.4),
                Between("RightShoulder", "RightArm", 0.4),
                At("Head"),
                At("LeftArm"),
                At("RightArm"),
                At("LeftForeArm"),
                At("RightForeArm"),
                At("LeftHand"),
                At("RightHand"),
            ],
            Rig::Mixamo => [
                At("Hips"),
                At("LeftUpLeg"),
                At("RightUpLeg"),
                At("Spine"),
                At("LeftLeg"),
                At("RightLeg"),
                At("Spine1"),
                At("LeftFoot"),
                At("RightFoot"),
                Between("Spine2", "Neck", 0.8),
                At("LeftToeBase"),
                At("RightToeBase"),
                At("Neck"),
                At("LeftShoulder"),
                At("RightShoulder"),
                At("Head"),
                At("LeftArm"),
                At("RightArm"),
                At("LeftForeArm"),
                At("RightForeArm"),
                At("LeftHand"),
                At("RightHand"),
            ],
            // Mixamo's names without Spine2. Female1's rest: Spine 0.11 m above Hips, Spine1
            // 0.23 m (where the clavicles start, 0.08 m off the mid-line), Neck 0.50 m, Head
            // 0.59 m; spine3 at the base of the neck.
            Rig::Accad => {
                let mut sources = Rig::Mixamo.sources();
                sources[Joint::Spine3.index()] = Between("Spine1", "Neck", 0.85);
                sources
            }
            // Ab 0.08 m above Hips, Chest 0.31 m, Neck (and both collars) 0.53 m, Head 0.64 m.
            Rig::HipsAbChest => [
                At("Hips"),
                At("LeftHip"),
                At("RightHip"),
                Between("Ab", "Chest", 0.2),
                At("LeftKnee"),
                At("RightKnee"),
                Between("Ab", "Chest", 0.75),
                At("LeftAnkle"),
                At("RightAnkle"),
                Between("Chest", "Neck", 0.92),
                At("LeftToes"),
                At("RightToes"),
                At("Neck"),
                Between("LeftCollar", "LeftShoulder", 0.4),
                Between("RightCollar", "RightShoulder", 0.4),
                At("Head"),
                At("LeftShoulder"),
                At("RightShoulder"),
                At("LeftElbow"),
                At("RightElbow"),
                At("LeftWrist"),
                At("RightWrist"),
            ],
            // Chest 0.10 m above Hips, Chest2 0.26 m, Neck (and both collar joints) 0.43 m,
            // shoulders 0.40 m, Head 0.55 m. The collar joints sit above the shoulders, so our
            // collars go on the line Chest2 → shoulder, below them as in SMPL. The ankle's End
            // Site is the toe tip (0.19 m forward and 0.07 m down); 70 % of the way there is the
            // ball of the foot.
            Rig::HipsChestChest2 => [
                At("Hips"),
                At("LeftHip"),
                At("RightHip"),
                At("Chest"),
                At("LeftKnee"),
                At("RightKnee"),
                At("Chest2"),
                At("LeftAnkle"),
                At("RightAnkle"),
                Between("Chest2", "Neck", 0.85),
                TowardEnd("LeftAnkle", 0.7),
                TowardEnd("RightAnkle", 0.7),
                Between("Neck", "Head", 0.4),
                Between("Chest2", "LeftShoulder", 0.55),
                Between("Chest2", "RightShoulder", 0.55),
                At("Head"),
                At("LeftShoulder"),
                At("RightShoulder"),
                At("LeftElbow"),
                At("RightElbow"),
                At("LeftWrist"),
                At("RightWrist"),
            ],
            Rig::Smpl => Joint::ALL.map(|j| At(j.name())),
        }
    }

    /// Resolves the map on a file's nodes: per joint `(from, to, fraction)`, or the names missing.
    pub(super) fn resolve(self, bvh: &Bvh) -> Result<[(usize, usize, f64); NUM_JOINTS], Vec<String>> {
        let mut missing: Vec<String> = Vec::new();
        // The node of joint `name`, or of its End Site when `end`.
        let mut find = |name: &str, end: bool| {
            let joint = bvh.joint_index(name);
            let node = if end { joint.and_then(|j| bvh.end_site_of(j)) } else { joint };
            node.unwrap_or_else(|| {
                let what = if joint.is_some() { format!("{name} End Site") } else { name.to_owned() };
                if !missing.contains(&what) {
                    missing.push(what);
                }
                0
            })
        };
        let map = self.sources().map(|s| match s {
            At(a) => (find(a, false), find(a, false), 0.0),
            Between(a, b, t) => (find(a, false), find(b, false), t),
            TowardEnd(a, t) => (find(a, false), find(a, true), t),
        });
        if missing.is_empty() {
            Ok(map)
        } else {
            Err(missing)
        }
    }
}
