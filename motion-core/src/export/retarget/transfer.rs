//! The motion of a [`RotationTrack`] carried onto a [`TargetRig`]: bone directions by rotation
//! transfer, the pelvis path scaled by the leg-length ratio, and the feet put back where the
//! motion plants them by two-bone IK on the rig's legs.
//!
//! Every position here is in metres and our axes (y up); the rig's rest frames are the world's,
//! as in its BVH file (rotations zero at rest).
//!
//! 1. **Alignment at rest.** For each of our joints `j` on rig node `n`, a constant rotation
//!    `C_n` takes the rig's rest bone onto ours: for a joint with one child, the shortest arc
//!    from the rig's rest direction (node → the child's node) to our skeleton's rest direction,
//!    so a T-pose or A-pose arm is turned down to ours about the forward axis and no twist is
//!    added; for the branching joints (pelvis, spine3), the rotation between the two rest
//!    frames of up (to the spine) and across (right → left hip or collar).
//! 2. **Transfer.** At frame `t` the node turns in the world by `D_n(t) = G_j(t) · C_n`, where
//!    `G_j(t)` is our joint's world rotation from rest ([`RotationTrack::global_rotations`]), so
//!    the rig's bone points where ours does. An end joint (head, wrists, toes), a node no joint
//!    names (fingers, twist bones, props, a `root` above the pelvis) and a bone of no length on
//!    the rig turn with their parent: they keep their rest pose relative to it.
//! 3. **Root.** The pelvis node is at `s · p(t) + (0, h'_pelvis − s · h_pelvis, 0)`, `s` the
//!    ratio of the rig's legs (hip → knee → ankle) to ours and `h` each skeleton's rest height
//!    above its toes; a node above the pelvis (Unreal's `root`) moves on the floor under it,
//!    carrying the horizontal path as engines take root motion (none with `--in-place`).
//! 4. **Feet.** Each leg is solved ([`solve_leg`]) so that its toe is at ours scaled the same
//!    way, `s · p_toe(t) + (0, h'_toe − s · h_toe, 0)` (on the floor at contact when ours is),
//!    and its ankle a rig foot behind it, turned as our foot is; the knee bends as it bends, and
//!    the thigh, shin and foot turn by the arc from where the transfer put them. On a rig of our
//!    proportions this moves nothing; on other proportions it keeps the feet planted where a
//!    bone-direction copy would slide or sink them. Where a stride asks more than the rig's legs
//!    reach (shorter legs under the same trunk), the pelvis first comes down by what is missing,
//!    eased over `DROP_EASE_S` either side ([`eased_envelope`]).
//!
//! What cannot carry over exactly is reported, not hidden ([`RetargetReport`]): a rig of other
//! proportions puts a hand elsewhere than ours scaled (a world-position constraint on the hand
//! may no longer be met), and a target beyond the rig's leg reach is approached, not reached.

use glam::{DMat3, DQuat, DVec3};
use serde::Serialize;

use super::rig::TargetRig;
use crate::export::armature::ArmatureTrack;
use crate::export::error::ExportError;
use crate::export::rotations::RotationTrack;
use crate::metrics::{foot_skate_ratio, SKATE_CONTACT_HEIGHT_M};
use crate::motion::leg_ik::{knee_bend, solve_leg, Leg};
use crate::motion::retarget_bone_lengths;
use crate::numeric::eased_envelope;
use crate::skeleton::{Joint, Pose, NUM_JOINTS};

/// Width of the soft zone below the rig's full leg reach, m ([`solve_leg`]).
const SOFT_REACH_M: f64 = 0.005;

/// A leg whose ankle and toe are this near their targets is left as the transfer put it, m.
const AT_GOAL_M: f64 = 1e-4;

/// The pelvis comes down over this many seconds before and after a frame that needs it (the
/// ease of [`eased_envelope`]).
const DROP_EASE_S: f64 = 0.15;

/// The pelvis comes down at most this fraction of the rig's leg reach.
const MAX_DROP_OF_LEG: f64 = 0.15;

/// A rig bone shorter than this has no direction to transfer, m: it turns with its parent.
const NO_LENGTH_M: f64 = 1e-3;

/// The legs: hip, knee, ankle and toe joints of each side.
const LEGS: [[Joint; 4]; 2] = [
    [Joint::LeftHip, Joint::LeftKnee, Joint::LeftAnkle, Joint::LeftFoot],
    [Joint::RightHip, Joint::RightKnee, Joint::RightAnkle, Joint::RightFoot],
];

/// How a rig node turns.
#[derive(Debug, Clone, Copy)]
enum Drive {
    /// With our joint: `D(t) = G_joint(t) · align`.
    Joint(Joint, DQuat),
    /// Rigidly with its parent (a root: not at all).
    Parent,
}

/// What carried over and what did not.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RetargetReport {
    /// The rig's name (its file's stem).
    pub rig: String,
    /// How its nodes were matched to our joints (a convention, or the explicit map).
    pub matched: &'static str,
    /// Its nodes.
    pub nodes: usize,
    /// Its nodes that no joint names (they keep their rest pose relative to their parent).
    pub unmatched_nodes: usize,
    /// Ratio of the rig's leg length (hip → knee → ankle) to ours.
    pub leg_ratio: f64,
    /// Largest distance over frames and joints between a rig joint divided by the leg ratio and
    /// ours, m (0 for a rig of our proportions; other proportions move the hands and head).
    pub from_ours_max_m: f64,
    /// The joint of that distance.
    pub from_ours_joint: &'static str,
    /// Largest distance over frames of a rig joint above the knees from ours with the rig's bone
    /// lengths (every bone's direction kept, the pelvis path scaled by the leg ratio and lifted
    /// as the rig stands: [`retarget_bone_lengths`]), m: how faithfully the bones were turned,
    /// whatever the proportions. The knees, ankles and toes are the leg IK's
    /// ([`RetargetReport::leg_fix_max_m`], [`RetargetReport::contact_miss_max_m`]).
    pub from_ours_on_rig_bones_max_m: f64,
    /// The joint of that distance.
    pub from_ours_on_rig_bones_joint: &'static str,
    /// Largest distance the pelvis came down so that the rig's legs reach the ankle targets, m
    /// (eased over `DROP_EASE_S` either side; 0 on a rig of our proportions).
    pub pelvis_lowered_max_m: f64,
    /// Largest distance the leg IK moved a knee, ankle or toe from where the transfer put it, m.
    pub leg_fix_max_m: f64,
    /// Largest distance of a rig ankle or toe from its scaled target at the frames where our foot
    /// is on the floor (below 5 cm), m.
    pub contact_miss_max_m: f64,
    /// Frames where an ankle target lay beyond the rig's leg reach.
    pub unreached_frames: usize,
    /// Foot skate ratio of our motion ([`foot_skate_ratio`], at the track's frame rate).
    pub skate_ours: f64,
    /// The same of the rig's joints divided by the leg ratio.
    pub skate_rig: f64,
}

/// A motion on a rig.
#[derive(Debug, Clone, PartialEq)]
pub struct Retargeted {
    /// The rig's armature and its motion (m, our axes; the root and the pelvis node translated).
    pub track: ArmatureTrack,
    /// The rig's nodes of our 22 joints at every frame, m, our axes.
    pub poses: Vec<Pose>,
    /// What carried over.
    pub report: RetargetReport,
}

/// Carries `track` onto `rig` (see the module doc). Fails on a track without frames.
pub fn retarget(track: &RotationTrack, rig: &TargetRig) -> Result<Retargeted, ExportError> {
    if track.frames() == 0 {
        return Err(ExportError::Shape("a motion without frames cannot be retargeted".into()));
    }
    let carrier = Carrier::new(track, rig)?;
    let ours = track.forward_kinematics();
    let globals: Vec<[DQuat; NUM_JOINTS]> = (0..ours.len()).map(|t| track.global_rotations(t)).collect();
    let turned: Vec<Vec<DQuat>> = globals.iter().map(|g| turns(rig, &carrier.drives, g)).collect();
    let needed: Vec<f64> = ours.iter().zip(&turned).map(|(p, d)| carrier.drop_needed(p, d)).collect();
    let drops = eased_envelope(&needed, (DROP_EASE_S * track.fps).round() as usize);
    let (map, pelvis) = (rig.map, carrier.pelvis);
    let mut nodes = rig.nodes.clone();
    nodes[0].translated = true;
    nodes[pelvis].translated = true;
    let mut out = ArmatureTrack { nodes, fps: track.fps, local: Vec::new(), translations_m: Vec::new() };
    let mut poses = Vec::with_capacity(ours.len());
    let mut fixes = LegFix::default();
    for (((p, g), mut d), drop) in ours.iter().zip(&globals).zip(turned).zip(&drops) {
        let (pelvis_at, root_at) = carrier.place(p, *drop);
        let before = positions(rig, &d, root_at, pelvis, pelvis_at);
        fixes.merge(carrier.fix_legs(p, g, &mut d, &before));
        let after = positions(rig, &d, root_at, pelvis, pelvis_at);
        for j in LEGS.iter().flatten() {
            fixes.moved_m = fixes.moved_m.max(after[map[j.index()]].distance(before[map[j.index()]]));
        }
        poses.push(Joint::ALL.map(|j| after[map[j.index()]]));
        let parent_turn = |n: usize| rig.nodes[n].parent.map_or(DQuat::IDENTITY, |q| d[q]);
        out.local.push((0..rig.nodes.len()).map(|n| (parent_turn(n).conjugate() * d[n]).normalize()).collect());
        let mut translations = vec![root_at];
        if let Some(parent) = rig.nodes[pelvis].parent {
            translations.push(d[parent].conjugate() * (pelvis_at - after[parent]));
        }
        out.translations_m.push(translations);
    }
    let report = carrier.report(&ours, &poses, &fixes, drops.iter().copied().fold(0.0, f64::max));
    Ok(Retargeted { track: out, poses, report })
}

/// What the leg IK did over the frames.
#[derive(Debug, Default)]
struct LegFix {
    /// Largest distance it moved a knee, ankle or toe, m.
    moved_m: f64,
    /// Largest distance of an ankle or toe from its target at our contact frames, m.
    contact_miss_m: f64,
    /// Frames with an ankle target beyond the leg's reach.
    unreached: usize,
}

impl LegFix {
    fn merge(&mut self, other: LegFix) {
        self.moved_m = self.moved_m.max(other.moved_m);
        self.contact_miss_m = self.contact_miss_m.max(other.contact_miss_m);
        self.unreached += other.unreached;
    }
}

/// What every frame of one retarget shares: the rig, its alignment to our skeleton and the
/// scale between them.
struct Carrier<'a> {
    rig: &'a TargetRig,
    drives: Vec<Drive>,
    /// The rig's rest positions per node, m.
    rest_rig: Vec<DVec3>,
    /// Our skeleton's rest positions, m.
    rest_ours: Pose,
    /// Leg-length ratio, rig / ours.
    s: f64,
    /// The pelvis node.
    pelvis: usize,
    /// The pelvis node's rest offset from the root node, m.
    chain: DVec3,
}

impl<'a> Carrier<'a> {
    fn new(track: &RotationTrack, rig: &'a TargetRig) -> Result<Self, ExportError> {
        let rest_rig = rig.rest_positions();
        let rest_ours = track.skeleton.rest_positions(DVec3::ZERO);
        let leg = |pos: &dyn Fn(Joint) -> DVec3| {
            LEGS.iter().map(|[h, k, a, _]| pos(*h).distance(pos(*k)) + pos(*k).distance(pos(*a))).sum::<f64>()
        };
        let s = leg(&|j: Joint| rest_rig[rig.map[j.index()]]) / leg(&|j: Joint| rest_ours[j.index()]);
        if !(s.is_finite() && s > 0.0) {
            return Err(ExportError::Rig(format!("{}: the rig's legs have no length", rig.path.display())));
        }
        let pelvis = rig.map[Joint::Pelvis.index()];
        let chain = rest_rig[pelvis] - rest_rig[0];
        let drives = drives(rig, &rest_rig, &rest_ours);
        Ok(Carrier { rig, drives, rest_rig, rest_ours, s, pelvis, chain })
    }

    /// The rig's rest position of `joint`'s node, m.
    fn at(&self, joint: Joint) -> DVec3 {
        self.rest_rig[self.rig.map[joint.index()]]
    }

    /// How far the rig's `joint` stands above where ours scaled by `s` does, both at rest and
    /// measured from the toes, m: what puts the rig's joint over the floor where ours is.
    fn lift(&self, joint: Joint) -> f64 {
        let toes = |y: &dyn Fn(Joint) -> f64| 0.5 * (y(Joint::LeftFoot) + y(Joint::RightFoot));
        let rig_toes = toes(&|j| self.at(j).y);
        let our_toes = toes(&|j| self.rest_ours[j.index()].y);
        (self.at(joint).y - rig_toes) - self.s * (self.rest_ours[joint.index()].y - our_toes)
    }

    /// At a frame with our joints `p`, the pelvis lowered by `drop` m: the pelvis node's position
    /// and the root's, m.
    fn place(&self, p: &Pose, drop: f64) -> (DVec3, DVec3) {
        let pelvis_at = self.s * p[0] + DVec3::Y * (self.lift(Joint::Pelvis) - drop);
        let root_at = if self.pelvis == 0 {
            pelvis_at
        } else {
            DVec3::new(pelvis_at.x - self.chain.x, 0.0, pelvis_at.z - self.chain.z)
        };
        (pelvis_at, root_at)
    }

    /// Where the ankle and toe of a leg go at a frame with our joints `p` and node turns `d`, m:
    /// the toe at ours scaled, the ankle a rig foot behind it, turned as our foot is.
    fn goals(&self, p: &Pose, d: &[DQuat], [_, _, ankle, toe]: [Joint; 4]) -> (DVec3, DVec3) {
        let toe_goal = self.s * p[toe.index()] + DVec3::Y * self.lift(toe);
        let foot = self.at(toe) - self.at(ankle);
        (toe_goal - d[self.rig.map[ankle.index()]] * foot, toe_goal)
    }

    /// How far the pelvis must come down at a frame (our joints `p`, node turns `d`) for both
    /// ankle targets to lie within the
    /// rig's legs' full reach, m (0 where they do; a target within reach is the IK's); at most
    /// [`MAX_DROP_OF_LEG`] of the leg.
    fn drop_needed(&self, p: &Pose, d: &[DQuat]) -> f64 {
        let (pelvis_at, root_at) = self.place(p, 0.0);
        let at = positions(self.rig, d, root_at, self.pelvis, pelvis_at);
        let mut drop = 0.0_f64;
        for leg in LEGS {
            let [hip, knee, ankle, _] = leg.map(|j| self.at(j));
            let reach = hip.distance(knee) + knee.distance(ankle);
            let to_goal = self.goals(p, d, leg).0 - at[self.rig.map[leg[0].index()]];
            let across = DVec3::new(to_goal.x, 0.0, to_goal.z).length();
            let down = if across < reach { (reach * reach - across * across).sqrt() } else { 0.0 };
            drop = drop.max((-to_goal.y - down).clamp(0.0, MAX_DROP_OF_LEG * reach));
        }
        drop
    }

    /// Solves both legs at a frame (our joints `p`, turns `g`, node turns `d` turned in place,
    /// node positions `before`), and says what it did at this frame.
    fn fix_legs(&self, p: &Pose, g: &[DQuat; NUM_JOINTS], d: &mut [DQuat], before: &[DVec3]) -> LegFix {
        let map = self.rig.map;
        let node = |j: Joint| map[j.index()];
        let forward = g[0] * DVec3::Z;
        let mut fix = LegFix::default();
        let mut unreached = false;
        for leg_joints in LEGS {
            let [hip, knee, ankle, toe] = leg_joints;
            let leg = Leg {
                hip: before[node(hip)],
                knee: before[node(knee)],
                ankle: before[node(ankle)],
                toe: before[node(toe)],
            };
            let (ankle_goal, toe_goal) = self.goals(p, d, leg_joints);
            if leg.toe.distance(toe_goal).max(leg.ankle.distance(ankle_goal)) < AT_GOAL_M {
                continue;
            }
            let solved = solve_leg(&leg, ankle_goal, toe_goal, knee_bend(&leg, forward), SOFT_REACH_M);
            unreached |= !solved.reached;
            let new = solved.leg;
            for (j, from, to) in [
                (hip, leg.knee - leg.hip, new.knee - new.hip),
                (knee, leg.ankle - leg.knee, new.ankle - new.knee),
                (ankle, leg.toe - leg.ankle, new.toe - new.ankle),
            ] {
                if let (Some(from), Some(to)) = (from.try_normalize(), to.try_normalize()) {
                    d[node(j)] = DQuat::from_rotation_arc(from, to) * d[node(j)];
                }
            }
            if p[toe.index()].y < SKATE_CONTACT_HEIGHT_M {
                fix.contact_miss_m =
                    fix.contact_miss_m.max(new.toe.distance(toe_goal)).max(new.ankle.distance(ankle_goal));
            }
        }
        fix.unreached = usize::from(unreached);
        // Nodes that turn with a leg bone follow its new turn.
        for (n, drive) in self.drives.iter().enumerate() {
            if let (Drive::Parent, Some(parent)) = (drive, self.rig.nodes[n].parent) {
                d[n] = d[parent];
            }
        }
        fix
    }

    /// The report of a retarget of `ours` that gave the rig's joints `poses`.
    fn report(&self, ours: &[Pose], poses: &[Pose], fixes: &LegFix, pelvis_lowered_m: f64) -> RetargetReport {
        let (rig, s) = (self.rig, self.s);
        let (from_ours_max_m, from_ours_joint) = farthest(poses, ours, s, &Joint::ALL);
        let rig_bones = Joint::ALL.map(|j| j.parent().map_or(0.0, |parent| self.at(j).distance(self.at(parent))));
        let on_rig_bones: Vec<Pose> = retarget_bone_lengths(ours, &rig_bones)
            .into_iter()
            .map(|pose| pose.map(|v| v + DVec3::Y * self.lift(Joint::Pelvis)))
            .collect();
        let above_knees: Vec<Joint> =
            Joint::ALL.into_iter().filter(|j| !LEGS.iter().any(|leg| leg[1..].contains(j))).collect();
        let (from_ours_on_rig_bones_max_m, from_ours_on_rig_bones_joint) =
            farthest(poses, &on_rig_bones, 1.0, &above_knees);
        let scaled: Vec<Pose> = poses.iter().map(|pose| pose.map(|v| v / s)).collect();
        RetargetReport {
            rig: rig.name(),
            matched: rig.matched.name(),
            nodes: rig.nodes.len(),
            unmatched_nodes: rig.nodes.len() - NUM_JOINTS,
            leg_ratio: s,
            from_ours_max_m,
            from_ours_joint,
            from_ours_on_rig_bones_max_m,
            from_ours_on_rig_bones_joint,
            pelvis_lowered_max_m: pelvis_lowered_m,
            leg_fix_max_m: fixes.moved_m,
            contact_miss_max_m: fixes.contact_miss_m,
            unreached_frames: fixes.unreached,
            skate_ours: foot_skate_ratio(ours),
            skate_rig: foot_skate_ratio(&scaled),
        }
    }
}

/// How each rig node turns ([`Drive`]), from the two rest poses (`rest_rig` per node,
/// `rest_ours` per joint, m).
fn drives(rig: &TargetRig, rest_rig: &[DVec3], rest_ours: &Pose) -> Vec<Drive> {
    let map = rig.map;
    let rig_at = |j: Joint| rest_rig[map[j.index()]];
    let ours_at = |j: Joint| rest_ours[j.index()];
    let mut drives = vec![Drive::Parent; rig.nodes.len()];
    for j in Joint::ALL {
        let children: Vec<Joint> = Joint::ALL.into_iter().filter(|c| c.parent() == Some(j)).collect();
        let align = match children.as_slice() {
            [child] => {
                let (rig_bone, our_bone) = (rig_at(*child) - rig_at(j), ours_at(*child) - ours_at(j));
                (rig_bone.length() > NO_LENGTH_M)
                    .then(|| DQuat::from_rotation_arc(rig_bone.normalize(), our_bone.normalize()))
            }
            [_, _, _] => {
                let (up, (left, right)) = match j {
                    Joint::Pelvis => (
                        // The first spine joint clear of the pelvis on the rig.
                        [Joint::Spine1, Joint::Spine2, Joint::Spine3]
                            .into_iter()
                            .find(|s| rig_at(*s).distance(rig_at(j)) > NO_LENGTH_M)
                            .unwrap_or(Joint::Neck),
                        (Joint::LeftHip, Joint::RightHip),
                    ),
                    _ => (Joint::Neck, (Joint::LeftCollar, Joint::RightCollar)),
                };
                let rig_frame = frame(rig_at(up) - rig_at(j), rig_at(left) - rig_at(right));
                let our_frame = frame(ours_at(up) - ours_at(j), ours_at(left) - ours_at(right));
                rig_frame.zip(our_frame).map(|(r, o)| DQuat::from_mat3(&(o * r.transpose())).normalize())
            }
            _ => None,
        };
        if let Some(align) = align {
            drives[map[j.index()]] = Drive::Joint(j, align);
        }
    }
    drives
}

/// The orthonormal frame (columns across, up, forward) of a body segment from its `up` and
/// `across` (right → left) vectors; `None` when they are parallel or zero.
fn frame(up: DVec3, across: DVec3) -> Option<DMat3> {
    let x = across.try_normalize()?;
    let y = (up - x * up.dot(x)).try_normalize()?;
    Some(DMat3::from_cols(x, y, x.cross(y)))
}

/// Each rig node's world turn from rest at a frame whose joint turns are `g`.
fn turns(rig: &TargetRig, drives: &[Drive], g: &[DQuat; NUM_JOINTS]) -> Vec<DQuat> {
    let mut d: Vec<DQuat> = Vec::with_capacity(drives.len());
    for (node, drive) in rig.nodes.iter().zip(drives) {
        let turn = match drive {
            Drive::Joint(j, align) => g[j.index()] * *align,
            Drive::Parent => node.parent.map_or(DQuat::IDENTITY, |p| d[p]),
        };
        d.push(turn);
    }
    d
}

/// Each rig node's world position, m, with node turns `d`, the root at `root_at` and the pelvis
/// node (`pelvis`) at `pelvis_at`.
fn positions(rig: &TargetRig, d: &[DQuat], root_at: DVec3, pelvis: usize, pelvis_at: DVec3) -> Vec<DVec3> {
    let mut out: Vec<DVec3> = Vec::with_capacity(rig.nodes.len());
    for (n, node) in rig.nodes.iter().enumerate() {
        let at = match node.parent {
            None => root_at,
            Some(_) if n == pelvis => pelvis_at,
            Some(p) => out[p] + d[p] * node.offset_m,
        };
        out.push(at);
    }
    out
}

/// The largest distance over `joints` between `rig` joints divided by `s` and `ours`, m, and its
/// joint.
fn farthest(rig: &[Pose], ours: &[Pose], s: f64, joints: &[Joint]) -> (f64, &'static str) {
    let mut worst = (0.0, Joint::Pelvis.name());
    for (a, b) in rig.iter().zip(ours) {
        for &j in joints {
            let distance = (a[j.index()] / s).distance(b[j.index()]);
            if distance > worst.0 {
                worst = (distance, j.name());
            }
        }
    }
    worst
}
