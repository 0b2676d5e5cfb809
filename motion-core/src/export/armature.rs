//! An armature: named nodes with rest offsets in a tree, and a motion on it as each node's local
//! rotation per frame plus a translation per frame on some nodes. It is what the BVH writer
//! ([`super::bvh`]) writes, whether the nodes are our 22 joints ([`RotationTrack::armature`]) or
//! a user's rig ([`super::retarget`]).
//!
//! Conventions: metres, the project's axes (y up, +z the way the motion starts facing, +x its
//! left); in the rest pose every node's frame is the world's, so a node's world transform is
//! `parent_world · Translate(t) · L`, where `t` is its translation at the frame if it has one
//! (the root's is its world position) and its rest offset otherwise, and `L` its local rotation.

use glam::{DQuat, DVec3};

use super::rotations::{RotationTrack, ANIMATED_OFFSETS};
use crate::skeleton::{Joint, NUM_JOINTS};

/// Length of each End Site of our track along its joint's bone, m: about the head above the SMPL
/// head joint, the hand beyond the wrist and the toes beyond the ball of the foot.
pub const END_SITE_M: f64 = 0.1;

/// One node of an armature.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmatureNode {
    /// Name, as files write it.
    pub name: String,
    /// Index of the parent node, always smaller than this node's; `None` for the root.
    pub parent: Option<usize>,
    /// Rest offset from the parent in the parent's rest frame, m (zero for the root).
    pub offset_m: DVec3,
    /// For a node without children, where its bone ends (BVH's `End Site`), from the node, m.
    pub end_site_m: Option<DVec3>,
    /// Whether the node has a translation per frame ([`ArmatureTrack::translations_m`]).
    pub translated: bool,
}

/// A motion on an armature.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmatureTrack {
    /// The nodes, parents before children, node 0 the root.
    pub nodes: Vec<ArmatureNode>,
    /// Frames per second.
    pub fps: f64,
    /// Per frame, each node's rotation relative to its parent (the root's is global), unit
    /// quaternions, `[frames][nodes]`.
    pub local: Vec<Vec<DQuat>>,
    /// Per frame, the translation of each node with [`ArmatureNode::translated`], in node order,
    /// m: the root's world position, any other node's offset from its parent in the parent's
    /// frame (it replaces the rest offset for the frame).
    pub translations_m: Vec<Vec<DVec3>>,
}

/// Each node's rest position, m: the root at `root_m` (in place of its offset, as its
/// translation replaces it), every other node at its parent's plus its [`ArmatureNode::offset_m`]
/// (rest frames are the world's). `nodes` lists parents before children.
pub fn rest_positions(nodes: &[ArmatureNode], root_m: DVec3) -> Vec<DVec3> {
    let mut rest: Vec<DVec3> = Vec::with_capacity(nodes.len());
    for node in nodes {
        let at = node.parent.map_or(root_m, |p| rest[p] + node.offset_m);
        rest.push(at);
    }
    rest
}

impl ArmatureTrack {
    /// Frames in the track.
    pub fn frames(&self) -> usize {
        self.local.len()
    }

    /// A description of what is inconsistent (a parent after its child, frames of different
    /// lengths, no frames, a root without a translation), or `None` for a track the writers take.
    pub fn inconsistency(&self) -> Option<String> {
        let frames = self.frames();
        let translated = self.nodes.iter().filter(|n| n.translated).count();
        if self.nodes.is_empty() || frames == 0 {
            return Some(format!("{} nodes and {frames} frames; at least one of each is needed", self.nodes.len()));
        }
        if !self.nodes[0].translated || self.nodes[0].parent.is_some() {
            return Some(format!("node 0 (`{}`) is not a root with a translation", self.nodes[0].name));
        }
        if let Some((i, n)) = self.nodes.iter().enumerate().skip(1).find(|(i, n)| n.parent.is_none_or(|p| p >= *i)) {
            return Some(format!("node {i} (`{}`) does not follow its parent", n.name));
        }
        if self.translations_m.len() != frames
            || self.local.iter().any(|f| f.len() != self.nodes.len())
            || self.translations_m.iter().any(|f| f.len() != translated)
        {
            return Some(format!(
                "{frames} frames of rotations for {} nodes and {} frames of translations for {translated} nodes do not \
                 agree",
                self.nodes.len(),
                self.translations_m.len()
            ));
        }
        None
    }

    /// Each node's world position and rotation at `frame`, m.
    pub fn world(&self, frame: usize) -> Vec<(DVec3, DQuat)> {
        let mut out: Vec<(DVec3, DQuat)> = Vec::with_capacity(self.nodes.len());
        let mut translations = self.translations_m[frame].iter();
        for (node, local) in self.nodes.iter().zip(&self.local[frame]) {
            let offset =
                if node.translated { translations.next().copied().unwrap_or(node.offset_m) } else { node.offset_m };
            let world = match node.parent {
                Some(p) => (out[p].0 + out[p].1 * offset, out[p].1 * *local),
                None => (offset, *local),
            };
            out.push(world);
        }
        out
    }
}

/// The node of each of our joints ([`Joint`] order) in [`RotationTrack::armature`], which lists
/// the joints in index order: joint `i` is node `i`.
pub fn our_joint_nodes() -> [usize; NUM_JOINTS] {
    Joint::ALL.map(Joint::index)
}

impl RotationTrack {
    /// The track as an armature of the 22 joints in index order, under their names, with an
    /// `End Site` [`END_SITE_M`] along the bone of each end joint; the root and the six
    /// [`ANIMATED_OFFSETS`] joints are translated.
    pub fn armature(&self) -> ArmatureTrack {
        let nodes: Vec<ArmatureNode> = Joint::ALL
            .into_iter()
            .map(|j| {
                let offset_m = self.skeleton.offsets_m[j.index()];
                let leaf = Joint::ALL.iter().all(|c| c.parent() != Some(j));
                ArmatureNode {
                    name: j.name().to_owned(),
                    parent: j.parent().map(Joint::index),
                    offset_m,
                    end_site_m: leaf.then(|| offset_m.try_normalize().unwrap_or(j.raw_offset()) * END_SITE_M),
                    translated: j.parent().is_none() || ANIMATED_OFFSETS.contains(&j),
                }
            })
            .collect();
        let translations_m = (0..self.frames())
            .map(|t| {
                std::iter::once(self.root_m[t]).chain(ANIMATED_OFFSETS.iter().map(|j| self.offset_m(t, *j))).collect()
            })
            .collect();
        ArmatureTrack {
            nodes,
            fps: self.fps,
            local: self.local.iter().map(|frame| frame.to_vec()).collect(),
            translations_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::rotations::tests::shipped_clips;

    #[test]
    fn our_track_as_an_armature_poses_the_same_joints() {
        let (_, _, poses) = shipped_clips().into_iter().next().unwrap();
        let track = RotationTrack::solve(&poses[..poses.len().min(40)], 20.0, 0).unwrap();
        let armature = track.armature();
        assert_eq!(armature.inconsistency(), None);
        for (t, pose) in track.forward_kinematics().iter().enumerate() {
            for (j, (p, _)) in armature.world(t).iter().enumerate() {
                assert!(p.distance(pose[j]) < 1e-12, "frame {t}, joint {j}");
            }
        }
        let mut broken = armature.clone();
        broken.translations_m.pop();
        assert!(broken.inconsistency().unwrap().contains("do not agree"));
        broken.nodes[3].parent = Some(5);
        assert!(broken.inconsistency().unwrap().contains("node 3 (`spine1`) does not follow its parent"));
    }
}
