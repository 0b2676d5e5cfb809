//! Binary glTF 2.0 (GLB): one file per sample holding an armature, its animation, a skinned
//! capsule body and the scene, for any glTF viewer or Blender. One writer serves any
//! [`ArmatureTrack`]: our 22 joints ([`RotationTrack::armature`]) and a user's rig
//! ([`super::retarget`]).
//!
//! What [`glb_bytes`] writes:
//! - **Skeleton**: a node per armature node, under its name, in its tree (node `i` of the file is
//!   node `i` of the armature). Its translation is the node's rest offset from its parent
//!   ([`ArmatureNode::offset_m`]) and its rotation the identity, so the rest pose is the bind
//!   pose; the root rests at its first frame's position. On our track the nodes are the joints
//!   under [`Joint::name`] in the SMPL tree.
//! - **Skin** over every node in node order (skin joint `i` is node `i`); each inverse bind matrix
//!   inverts its node's rest global transform, a pure translation.
//! - **Animation**, named after the label: at every frame `k` (time `k / fps` s, `LINEAR`) the
//!   translation of every [`ArmatureNode::translated`] node ([`ArmatureTrack::translations_m`]:
//!   the root's world position, another node's offset from its parent at that frame; on our
//!   track the pelvis and the six [`ANIMATED_OFFSETS`] joints, hips, spine1, neck and collars) and
//!   the local rotation of every node. So the file poses the armature's forward kinematics
//!   ([`ArmatureTrack::world`]).
//! - **Body** (`geometry`): round the nodes of our 22 joints (on a rig, [`TargetRig::map`]) a
//!   capsule per bone and spheres for the head and hands, thin capsules along the other bones
//!   below the pelvis (fingers, twist bones), each vertex bound with weight 1 to one node (a
//!   bone's capsule to the bone's parent); one material.
//! - **Scene**: every [`SceneBox`] an unskinned node of its name holding a unit cube scaled to
//!   the box, with a material per [`SceneRole`].
//!
//! Axes are glTF's and ours (metres, y up, the character faces +z, +x is its left), so nothing is
//! converted, whatever unit and up axis a rig's BVH has. The file is a GLB header, a JSON chunk
//! padded with spaces and a BIN chunk padded with zeros; every accessor has a buffer view of its
//! own starting on a 4-byte boundary.
//!
//! [`RotationTrack::armature`]: super::RotationTrack::armature
//! [`ANIMATED_OFFSETS`]: super::ANIMATED_OFFSETS
//! [`TargetRig::map`]: super::retarget::TargetRig::map

use std::collections::BTreeMap;
use std::path::Path;

use glam::{DMat4, DVec3};
use gltf_json as json;
use json::accessor::{ComponentType, GenericComponentType, Type};
use json::animation::{Interpolation, Property};
use json::buffer::Target;
use json::material::{AlphaMode, PbrBaseColorFactor, PbrMetallicRoughness, StrengthFactor};
use json::mesh::{Mode, Semantic};
use json::validation::{Checked, Checked::Valid, USize64};
use json::{Index, Root};

use super::armature::{rest_positions, ArmatureNode, ArmatureTrack};
use super::error::{write_atomically, ExportError};
use super::glb::glb_container;
use super::scene::{SceneBox, SceneRole};
use crate::skeleton::{Joint, NUM_JOINTS};

mod geometry;
#[cfg(test)]
mod tests;

use geometry::{body, Geometry};

/// Most nodes a GLB's skin holds: its vertices name their node in a `u16`.
const MAX_NODES: usize = 1 << 16;

/// Writes the GLB of [`glb_bytes`] to `path` with [`write_atomically`].
pub fn write_glb(
    path: &Path,
    label: &str,
    track: &ArmatureTrack,
    joint_nodes: &[usize; NUM_JOINTS],
    scene: &[SceneBox],
) -> Result<(), ExportError> {
    write_atomically(path, &glb_bytes(label, track, joint_nodes, scene)?)
}

/// The GLB of one sample: `track` (m, our axes) with a skinned body, its animation named `label`,
/// and the `scene` boxes. `joint_nodes` is the node of each of our joints ([`Joint`] order),
/// which the body's capsules run between: [`our_joint_nodes`] for our own track, the rig's
/// [`map`] for a rig. Fails naming what is wrong on a track without frames or whose
/// shapes disagree ([`ArmatureTrack::inconsistency`]), a frame rate that is not positive, a
/// joint node that is not one of the track's, more than 65536 nodes, or a value that is not
/// finite.
///
/// [`our_joint_nodes`]: super::armature::our_joint_nodes
/// [`map`]: super::retarget::TargetRig::map
pub fn glb_bytes(
    label: &str,
    track: &ArmatureTrack,
    joint_nodes: &[usize; NUM_JOINTS],
    scene: &[SceneBox],
) -> Result<Vec<u8>, ExportError> {
    check(label, track, joint_nodes, scene)?;
    let mut glb = Builder::default();
    glb.root.asset.generator = Some("mogen".into());
    armature_nodes(&mut glb.root, track);
    let bind = rest_positions(&track.nodes, track.translations_m[0][0]);
    let body = body_node(&mut glb, &bind, &track.nodes, joint_nodes);
    let boxes = scene_box_nodes(&mut glb, scene);
    animation(&mut glb, label, track);
    glb.finish(label, [node(0), body].into_iter().chain(boxes).collect())
}

fn check(
    label: &str,
    track: &ArmatureTrack,
    joint_nodes: &[usize; NUM_JOINTS],
    scene: &[SceneBox],
) -> Result<(), ExportError> {
    let fail = |what: String| Err(ExportError::Shape(format!("sample `{label}`: {what}")));
    let nodes = &track.nodes;
    if track.frames() == 0 {
        return fail("the track has no frames".into());
    }
    if let Some(what) = track.inconsistency() {
        return fail(what);
    }
    if !(track.fps.is_finite() && track.fps > 0.0) {
        return fail(format!("frame rate {} is not a positive number", track.fps));
    }
    if nodes.len() > MAX_NODES {
        return fail(format!("{} nodes; a GLB skin here holds at most {MAX_NODES}", nodes.len()));
    }
    if let Some((j, n)) = joint_nodes.iter().enumerate().find(|(_, n)| **n >= nodes.len()) {
        return fail(format!("`{}` is on node {n}, not one of the {} nodes", Joint::ALL[j].name(), nodes.len()));
    }
    if let Some(n) = nodes.iter().find(|n| !(n.offset_m.is_finite() && n.end_site_m.is_none_or(|e| e.is_finite()))) {
        return fail(format!("the rest offset or end site of `{}` is not finite", n.name));
    }
    let translated: Vec<&ArmatureNode> = nodes.iter().filter(|n| n.translated).collect();
    for (frame, (local, translations)) in track.local.iter().zip(&track.translations_m).enumerate() {
        if let Some(k) = translations.iter().position(|t| !t.is_finite()) {
            return fail(format!("frame {frame}: the translation of `{}` is not finite", translated[k].name));
        }
        if let Some(n) = local.iter().position(|q| !q.is_finite()) {
            return fail(format!("frame {frame}: the rotation of `{}` is not finite", nodes[n].name));
        }
    }
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    match scene.iter().find(|b| !(finite(&b.centre_m) && finite(&b.half_extents_m) && finite(&b.rotation_xyzw))) {
        Some(b) => fail(format!("scene box `{}` is not finite", b.name)),
        None => Ok(()),
    }
}

/// The file's node of armature node `i`: armature nodes come first, in their order.
fn node(i: usize) -> Index<json::Node> {
    Index::new(i as u32)
}

fn non_empty<T>(items: impl Iterator<Item = T>) -> Option<Vec<T>> {
    let items: Vec<T> = items.collect();
    (!items.is_empty()).then_some(items)
}

/// A file node per armature node, in its order: the root rests where the motion starts, every
/// other node at its rest offset from its parent, all unrotated.
fn armature_nodes(root: &mut Root, track: &ArmatureTrack) {
    for (i, n) in track.nodes.iter().enumerate() {
        let rest = match n.parent {
            None => track.translations_m[0][0],
            Some(_) => n.offset_m,
        };
        root.nodes.push(json::Node {
            name: Some(n.name.clone()),
            translation: Some(rest.as_vec3().to_array()),
            children: non_empty((0..track.nodes.len()).filter(|c| track.nodes[*c].parent == Some(i)).map(node)),
            ..Default::default()
        });
    }
}

/// The skinned body node, its skin and mesh, with the armature's `nodes` at `bind` (m) in the
/// bind pose and our joints on `joint_nodes`.
fn body_node(
    glb: &mut Builder,
    bind: &[DVec3],
    nodes: &[ArmatureNode],
    joint_nodes: &[usize; NUM_JOINTS],
) -> Index<json::Node> {
    let inverse_bind: Vec<f32> =
        bind.iter().flat_map(|p| DMat4::from_translation(-*p).as_mat4().to_cols_array()).collect();
    let inverse_bind_matrices = Some(glb.accessor(Values::F32(&inverse_bind), Type::Mat4, None));
    let skin = glb.root.push(json::Skin {
        extensions: None,
        extras: Default::default(),
        inverse_bind_matrices,
        joints: (0..nodes.len()).map(node).collect(),
        name: Some("body".into()),
        skeleton: Some(node(0)),
    });
    let (body, bound_to) = body(bind, nodes, joint_nodes);
    let (mut attributes, indices) = glb.geometry(&body);
    let joints = glb.accessor(Values::U16(&bound_to), Type::Vec4, Some(Target::ArrayBuffer));
    attributes.insert(Valid(Semantic::Joints(0)), joints);
    let weights = [1.0, 0.0, 0.0, 0.0].repeat(body.positions.len());
    let weights = glb.accessor(Values::F32(&weights), Type::Vec4, Some(Target::ArrayBuffer));
    attributes.insert(Valid(Semantic::Weights(0)), weights);
    let material = glb.root.push(material("body", [0.62, 0.66, 0.74, 1.0]));
    let mesh = glb.root.push(mesh("body", attributes, indices, material));
    glb.root.push(json::Node { name: Some("body".into()), mesh: Some(mesh), skin: Some(skin), ..Default::default() })
}

/// Data of an accessor, stored little-endian in the BIN chunk.
enum Values<'a> {
    F32(&'a [f32]),
    U16(&'a [u16]),
    U32(&'a [u32]),
}

/// Scalars per element of an accessor type.
fn components(kind: Type) -> usize {
    match kind {
        Type::Scalar => 1,
        Type::Vec2 => 2,
        Type::Vec3 => 3,
        Type::Vec4 | Type::Mat2 => 4,
        Type::Mat3 => 9,
        Type::Mat4 => 16,
    }
}

/// Accessors of a mesh's vertex attributes by semantic.
type Attributes = BTreeMap<Checked<Semantic>, Index<json::Accessor>>;

/// A glTF document and its BIN chunk, filled in together.
#[derive(Default)]
struct Builder {
    root: Root,
    bin: Vec<u8>,
}

impl Builder {
    /// Appends `values` to the BIN chunk in a buffer view of their own, starting on a 4-byte
    /// boundary, and adds the accessor reading them as elements of `kind`. Float accessors carry
    /// their per-component min and max, which glTF requires of positions and animation inputs.
    fn accessor(&mut self, values: Values, kind: Type, target: Option<Target>) -> Index<json::Accessor> {
        let width = components(kind);
        let offset = self.bin.len();
        let (component_type, len, bounds) = match values {
            Values::F32(v) => {
                self.bin.extend(v.iter().flat_map(|x| x.to_le_bytes()));
                (ComponentType::F32, v.len(), Some(bounds(v, width)))
            }
            Values::U16(v) => {
                self.bin.extend(v.iter().flat_map(|x| x.to_le_bytes()));
                (ComponentType::U16, v.len(), None)
            }
            Values::U32(v) => {
                self.bin.extend(v.iter().flat_map(|x| x.to_le_bytes()));
                (ComponentType::U32, v.len(), None)
            }
        };
        let byte_length = USize64::from(self.bin.len() - offset);
        self.bin.resize(self.bin.len().next_multiple_of(4), 0);
        let view = self.root.push(json::buffer::View {
            buffer: Index::new(0),
            byte_length,
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        });
        let (min, max) = bounds.unzip();
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(len / width),
            component_type: Valid(GenericComponentType(component_type)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(kind),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    /// The `POSITION` and `NORMAL` accessors of `geometry`, and that of its triangles' indices.
    fn geometry(&mut self, geometry: &Geometry) -> (Attributes, Index<json::Accessor>) {
        let mut attributes = BTreeMap::new();
        for (semantic, points) in [(Semantic::Positions, &geometry.positions), (Semantic::Normals, &geometry.normals)] {
            let values = floats3(points);
            attributes
                .insert(Valid(semantic), self.accessor(Values::F32(&values), Type::Vec3, Some(Target::ArrayBuffer)));
        }
        let indices: Vec<u32> = geometry.triangles.iter().flatten().copied().collect();
        let indices = self.accessor(Values::U32(&indices), Type::Scalar, Some(Target::ElementArrayBuffer));
        (attributes, indices)
    }

    /// The GLB: the scene `label` of root `nodes`, the buffer, both chunks.
    fn finish(mut self, label: &str, nodes: Vec<Index<json::Node>>) -> Result<Vec<u8>, ExportError> {
        let scene = json::Scene { extensions: None, extras: Default::default(), name: Some(label.into()), nodes };
        self.root.scene = Some(self.root.push(scene));
        self.root.buffers.push(json::Buffer {
            byte_length: USize64::from(self.bin.len()),
            name: None,
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
        let text = self.root.to_vec().map_err(|e| ExportError::Shape(format!("glTF JSON of `{label}`: {e}")))?;
        glb_container(&text, &self.bin)
    }
}

/// Per-component minimum and maximum of `values`, elements of `width` scalars (glTF's accessor
/// `min` and `max`).
pub(crate) fn bounds(values: &[f32], width: usize) -> (json::Value, json::Value) {
    let mut min = vec![f32::INFINITY; width];
    let mut max = vec![f32::NEG_INFINITY; width];
    for element in values.chunks(width) {
        for (i, &x) in element.iter().enumerate() {
            min[i] = min[i].min(x);
            max[i] = max[i].max(x);
        }
    }
    (json::Value::from(min), json::Value::from(max))
}

fn floats3(points: &[DVec3]) -> Vec<f32> {
    points.iter().flat_map(|p| p.as_vec3().to_array()).collect()
}

fn mesh(
    name: &str,
    attributes: Attributes,
    indices: Index<json::Accessor>,
    material: Index<json::Material>,
) -> json::Mesh {
    json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some(name.into()),
        primitives: vec![json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: Some(indices),
            material: Some(material),
            mode: Valid(Mode::Triangles),
            targets: None,
        }],
        weights: None,
    }
}

/// A matte material of colour `rgba` (linear, 0–1); blended and two-sided when translucent.
fn material(name: &str, rgba: [f32; 4]) -> json::Material {
    let translucent = rgba[3] < 1.0;
    json::Material {
        name: Some(name.into()),
        alpha_mode: Valid(if translucent { AlphaMode::Blend } else { AlphaMode::Opaque }),
        double_sided: translucent,
        pbr_metallic_roughness: PbrMetallicRoughness {
            base_color_factor: PbrBaseColorFactor(rgba),
            metallic_factor: StrengthFactor(0.0),
            roughness_factor: StrengthFactor(0.8),
            ..Default::default()
        },
        ..Default::default()
    }
}

/// Name and colour (linear RGBA) of the boxes of a role: obstacles translucent red, regions
/// translucent blue, supports opaque brown.
fn role_look(role: SceneRole) -> (&'static str, [f32; 4]) {
    match role {
        SceneRole::Obstacle => ("obstacle", [0.8, 0.12, 0.08, 0.45]),
        SceneRole::Region => ("region", [0.1, 0.3, 0.9, 0.35]),
        SceneRole::Support => ("support", [0.45, 0.3, 0.15, 1.0]),
        SceneRole::Target => ("target", [0.1, 0.65, 0.25, 0.6]),
    }
}

/// A node per scene box: the unit cube (one mesh per role) scaled, turned and moved onto it.
fn scene_box_nodes(glb: &mut Builder, scene: &[SceneBox]) -> Vec<Index<json::Node>> {
    if scene.is_empty() {
        return Vec::new();
    }
    let mut cube = Geometry::default();
    cube.unit_cube();
    let (attributes, indices) = glb.geometry(&cube);
    let mut meshes: Vec<(SceneRole, Index<json::Mesh>)> = Vec::new();
    let mut nodes = Vec::with_capacity(scene.len());
    for scene_box in scene {
        let mesh_index = match meshes.iter().find(|(role, _)| *role == scene_box.role) {
            Some(&(_, index)) => index,
            None => {
                let (name, rgba) = role_look(scene_box.role);
                let material = glb.root.push(material(name, rgba));
                let index = glb.root.push(mesh(name, attributes.clone(), indices, material));
                meshes.push((scene_box.role, index));
                index
            }
        };
        nodes.push(glb.root.push(json::Node {
            name: Some(scene_box.name.clone()),
            mesh: Some(mesh_index),
            translation: Some(scene_box.centre_m.map(|x| x as f32)),
            rotation: Some(json::scene::UnitQuaternion(scene_box.rotation_xyzw.map(|x| x as f32))),
            scale: Some(scene_box.half_extents_m.map(|h| (2.0 * h) as f32)),
            ..Default::default()
        }));
    }
    nodes
}

/// The animation `label`: the translation of every translated node, then every node's rotation,
/// at every frame.
fn animation(glb: &mut Builder, label: &str, track: &ArmatureTrack) {
    let times: Vec<f32> = (0..track.frames()).map(|k| (k as f64 / track.fps) as f32).collect();
    let input = glb.accessor(Values::F32(&times), Type::Scalar, None);
    let translated = (0..track.nodes.len()).filter(|n| track.nodes[*n].translated);
    let mut outputs = Vec::new();
    for (k, n) in translated.enumerate() {
        let translations: Vec<DVec3> = track.translations_m.iter().map(|frame| frame[k]).collect();
        let output = glb.accessor(Values::F32(&floats3(&translations)), Type::Vec3, None);
        outputs.push((node(n), Property::Translation, output));
    }
    for n in 0..track.nodes.len() {
        let rotations: Vec<f32> = track.local.iter().flat_map(|frame| frame[n].as_quat().to_array()).collect();
        outputs.push((node(n), Property::Rotation, glb.accessor(Values::F32(&rotations), Type::Vec4, None)));
    }
    let (samplers, channels) = outputs
        .into_iter()
        .enumerate()
        .map(|(i, (node, path, output))| {
            let sampler = json::animation::Sampler {
                extensions: None,
                extras: Default::default(),
                input,
                interpolation: Valid(Interpolation::Linear),
                output,
            };
            let channel = json::animation::Channel {
                sampler: Index::new(i as u32),
                target: json::animation::Target {
                    extensions: None,
                    extras: Default::default(),
                    node,
                    path: Valid(path),
                },
                extensions: None,
                extras: Default::default(),
            };
            (sampler, channel)
        })
        .unzip();
    glb.root.push(json::Animation {
        extensions: None,
        extras: Default::default(),
        channels,
        name: Some(label.into()),
        samplers,
    });
}
