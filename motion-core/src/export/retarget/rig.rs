//! [`TargetRig`]: a user's skeleton read from a BVH file (its hierarchy and rest offsets), with
//! the node of each of our joints, its unit and its up axis.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::names::{match_nodes, Matched};
use crate::export::armature::{rest_positions, ArmatureNode};
use crate::export::bvh::BvhAxes;
use crate::export::error::ExportError;
use crate::files::read_bytes;
use crate::import::bvh::{Bvh, LengthUnit, UpAxis};
use crate::limits::MOCAP_FILE_BYTES;
use crate::skeleton::{Joint, NUM_JOINTS};

/// A rig to retarget onto.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetRig {
    /// The file it was read from.
    pub path: PathBuf,
    /// Its nodes (End Sites folded into their joints), rest offsets in metres and our axes; none
    /// translated.
    pub nodes: Vec<ArmatureNode>,
    /// The file's unit and up axis, which its motions are written in.
    pub axes: BvhAxes,
    /// How its nodes were matched to our joints.
    pub matched: Matched,
    /// The node of each of our joints, in [`Joint`] order.
    pub map: [usize; NUM_JOINTS],
}

impl TargetRig {
    /// Reads the rig of a BVH file (its motion, if any, is not used). `joint_map`: a JSON file
    /// `{"pelvis": "Hips", "left_hip": "LeftUpLeg", …}` naming the node of each of our 22 joints
    /// ([`Joint::name`]), for a rig whose names follow no known convention. The unit is the one
    /// under which the rest skeleton is closest to a person's height ([`LengthUnit::detect`]);
    /// the file is Z-up when its head lies further from its pelvis along z than along y. Errors
    /// name the file and what is wrong: unreadable, not BVH, joints not matched, a flat rest pose.
    pub fn read_bvh(path: &Path, joint_map: Option<&Path>) -> Result<TargetRig, ExportError> {
        let explicit = joint_map.map(read_joint_map).transpose()?;
        let (bvh, _) = Bvh::read(path).map_err(|e| ExportError::Rig(e.to_string()))?;
        let fail = |message: String| ExportError::Rig(format!("{}: {message}", path.display()));
        // Nodes without the End Sites, and where each file node went.
        let mut index = vec![None; bvh.joints().len()];
        let mut nodes: Vec<ArmatureNode> = Vec::new();
        for (i, joint) in bvh.joints().iter().enumerate() {
            let parent = joint.parent.and_then(|p| index[p]);
            if joint.end_site {
                if let Some(node) = parent.and_then(|p: usize| nodes.get_mut(p)) {
                    node.end_site_m.get_or_insert(joint.offset);
                }
                continue;
            }
            index[i] = Some(nodes.len());
            nodes.push(ArmatureNode {
                name: joint.name.clone(),
                parent,
                offset_m: joint.offset,
                end_site_m: None,
                translated: false,
            });
        }
        let names: Vec<String> = nodes.iter().map(|n| n.name.clone()).collect();
        let (matched, map) = match_nodes(&names, explicit.as_ref()).map_err(&fail)?;
        // The rest positions in file axes and units, to find the up axis and the unit.
        let rest = rest_from_origin(&nodes);
        let rise = rest[map[Joint::Head.index()]] - rest[map[Joint::Pelvis.index()]];
        let up = if rise.z.abs() > rise.y.abs() { UpAxis::Z } else { UpAxis::Y };
        let unit =
            LengthUnit::detect(bvh.rest_height(up)).ok_or_else(|| fail("the rest skeleton has no height".into()))?;
        let scale = unit.metres();
        for node in &mut nodes {
            node.offset_m = up.to_ours(node.offset_m) * scale;
            node.end_site_m = node.end_site_m.map(|e| up.to_ours(e) * scale);
        }
        Ok(TargetRig { path: path.into(), nodes, axes: BvhAxes { per_metre: 1.0 / scale, up }, matched, map })
    }

    /// The rig's name: its file's stem.
    pub fn name(&self) -> String {
        self.path.file_stem().map_or_else(|| "rig".into(), |s| s.to_string_lossy().into_owned())
    }

    /// Each node's rest position, m, our axes, the root at its offset from the origin.
    pub fn rest_positions(&self) -> Vec<DVec3> {
        rest_from_origin(&self.nodes)
    }
}

/// The rest positions of BVH nodes, the root at its offset from the origin (as BVH places it).
fn rest_from_origin(nodes: &[ArmatureNode]) -> Vec<DVec3> {
    rest_positions(nodes, nodes.first().map_or(DVec3::ZERO, |root| root.offset_m))
}

/// Reads a joint map: a JSON object of our joint names to node names.
fn read_joint_map(path: &Path) -> Result<BTreeMap<String, String>, ExportError> {
    let bytes = read_bytes(path, &MOCAP_FILE_BYTES)?;
    serde_json::from_slice(&bytes).map_err(|e| {
        ExportError::Rig(format!("{}: a joint map is a JSON object of joint names to node names: {e}", path.display()))
    })
}
