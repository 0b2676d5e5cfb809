//! [`TargetRig`]: a user's skeleton read from a BVH file (its hierarchy and rest offsets) or a
//! skinned glTF character ([`super::character`]), with the node of each of our joints, its unit
//! and its up axis.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::DVec3;

use super::character::{read_character, Character};
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
    /// Its nodes (a BVH's End Sites folded into their joints; a glTF's skin joints), rest offsets
    /// in metres and our axes; none translated.
    pub nodes: Vec<ArmatureNode>,
    /// The file's unit and up axis, which its motions are written in.
    pub axes: BvhAxes,
    /// The character, when the rig was read from a glTF file: its motions are written into it.
    pub character: Option<Box<Character>>,
    /// How its nodes were matched to our joints.
    pub matched: Matched,
    /// The node of each of our joints, in [`Joint`] order.
    pub map: [usize; NUM_JOINTS],
}

impl TargetRig {
    /// Reads the rig of a file: a skinned glTF character (`.glb`, `.gltf`: [`read_character`],
    /// its document kept to carry the motion) or a BVH file (its hierarchy and rest offsets; its
    /// motion, if any, is not used). `joint_map`: a JSON file `{"pelvis": "Hips", "left_hip":
    /// "LeftUpLeg", …}` naming the node of each of our 22 joints ([`Joint::name`]), for a rig
    /// whose names follow no known convention. The unit is the one under which the rest skeleton
    /// is closest to a person's height ([`LengthUnit::detect`]); a glTF is Y-up, a BVH Z-up when
    /// its head lies further from its pelvis along z than along y. Errors name the file and what
    /// is wrong: unreadable, not BVH or glTF, no skin, joints not matched, a flat rest pose.
    pub fn read(path: &Path, joint_map: Option<&Path>) -> Result<TargetRig, ExportError> {
        let explicit = joint_map.map(read_joint_map).transpose()?;
        let fail = |message: String| ExportError::Rig(format!("{}: {message}", path.display()));
        let extension = path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
        let (nodes, up, character) = if extension == "glb" || extension == "gltf" {
            let (character, nodes) = read_character(path).map_err(&fail)?;
            (nodes, Some(UpAxis::Y), Some(Box::new(character)))
        } else {
            (bvh_nodes(path)?, None, None)
        };
        let names: Vec<String> = nodes.iter().map(|n| n.name.clone()).collect();
        let (matched, map) = match_nodes(&names, explicit.as_ref()).map_err(&fail)?;
        // The rest positions in file axes and units, to find the up axis and the unit.
        let rest = rest_from_origin(&nodes);
        let rise = rest[map[Joint::Head.index()]] - rest[map[Joint::Pelvis.index()]];
        let up = up.unwrap_or(if rise.z.abs() > rise.y.abs() { UpAxis::Z } else { UpAxis::Y });
        let tips = nodes.iter().zip(&rest).filter_map(|(n, at)| n.end_site_m.map(|e| *at + e));
        let heights = rest.iter().copied().chain(tips).map(|p| up.to_ours(p).y);
        let height = heights.clone().fold(f64::NEG_INFINITY, f64::max) - heights.fold(f64::INFINITY, f64::min);
        let unit = LengthUnit::detect(height).ok_or_else(|| fail("the rest skeleton has no height".into()))?;
        let scale = unit.metres();
        let nodes = nodes
            .into_iter()
            .map(|node| ArmatureNode {
                offset_m: up.to_ours(node.offset_m) * scale,
                end_site_m: node.end_site_m.map(|e| up.to_ours(e) * scale),
                ..node
            })
            .collect();
        let axes = BvhAxes { per_metre: 1.0 / scale, up };
        Ok(TargetRig { path: path.into(), nodes, axes, matched, map, character })
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

/// The nodes of a BVH file's hierarchy (End Sites folded into their joints), in its units and
/// axes.
fn bvh_nodes(path: &Path) -> Result<Vec<ArmatureNode>, ExportError> {
    let (bvh, _) = Bvh::read(path).map_err(|e| ExportError::Rig(e.to_string()))?;
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
    Ok(nodes)
}

/// The rest positions of a rig's nodes, the root at its offset from the origin (as BVH places it).
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
