//! Binary glTF 2.0 (GLB): one file per sample holding the skeleton, its animation, a skinned
//! capsule body and the scene, for any glTF viewer or Blender.
//!
//! What [`glb_bytes`] writes:
//! - **Skeleton**: a node per joint, named by [`Joint::name`], in the SMPL tree. Its translation
//!   is the joint's rest offset from its parent ([`RigSkeleton::offsets_m`]) and its rotation the
//!   identity, so the rest pose is the bind pose; the pelvis rests at the first frame's position.
//! - **Skin** over the 22 joint nodes in [`Joint::ALL`] order (skin joint `i` is node `i`); each
//!   inverse bind matrix inverts its joint's rest global transform, a pure translation.
//! - **Animation**, named after the label: at every frame `k` (time `k / fps` s, `LINEAR`) the
//!   local rotation of every joint ([`RotationTrack::local`]), the pelvis translation
//!   ([`RotationTrack::root_m`]) and the translation of the six joints with animated offsets
//!   ([`ANIMATED_OFFSETS`]: hips, spine1, neck, collars), their offset from their parent at that
//!   frame ([`RotationTrack::offset_m`]). So the file poses the track's forward kinematics.
//! - **Body**: a capsule round every bone and spheres for the head and hands, each vertex bound
//!   with weight 1 to one joint (a bone's capsule to the bone's parent joint); one material.
//! - **Scene**: every [`SceneBox`] an unskinned node of its name holding a unit cube scaled to
//!   the box, with a material per [`SceneRole`].
//!
//! Axes are glTF's and ours (metres, y up, the character faces +z, +x is its left), so nothing is
//! converted. The file is a GLB header, a JSON chunk padded with spaces and a BIN chunk padded
//! with zeros; every accessor has a buffer view of its own starting on a 4-byte boundary.
//!
//! [`RigSkeleton::offsets_m`]: super::RigSkeleton::offsets_m

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

use super::error::{write_atomically, ExportError};
use super::rotations::{RotationTrack, ANIMATED_OFFSETS};
use super::scene::{SceneBox, SceneRole};
use crate::skeleton::{Joint, Pose};

mod geometry;

use geometry::{body, Geometry};

/// GLB chunk types: `JSON` and `BIN\0` read as little-endian `u32`.
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

/// Writes the GLB of [`glb_bytes`] to `path` with [`write_atomically`].
pub fn write_glb(path: &Path, label: &str, track: &RotationTrack, scene: &[SceneBox]) -> Result<(), ExportError> {
    write_atomically(path, &glb_bytes(label, track, scene)?)
}

/// The GLB of one sample: `track` on its skeleton with a skinned body, its animation named
/// `label`, and the `scene` boxes. Fails on an empty track, a frame rate that is not positive,
/// root positions, animated offsets and rotations of different lengths, or a value that is not
/// finite.
pub fn glb_bytes(label: &str, track: &RotationTrack, scene: &[SceneBox]) -> Result<Vec<u8>, ExportError> {
    check(label, track, scene)?;
    let mut glb = Builder::default();
    glb.root.asset.generator = Some("mogen".into());
    joint_nodes(&mut glb.root, track);
    let body = body_node(&mut glb, &track.skeleton.rest_positions(track.root_m[0]));
    let boxes = scene_box_nodes(&mut glb, scene);
    animation(&mut glb, label, track);
    glb.finish(label, [node(Joint::Pelvis), body].into_iter().chain(boxes).collect())
}

fn check(label: &str, track: &RotationTrack, scene: &[SceneBox]) -> Result<(), ExportError> {
    let frames = track.frames();
    let fail = |what: String| Err(ExportError::Shape(format!("sample `{label}`: {what}")));
    if frames == 0 {
        return fail("the rotation track has no frames".into());
    }
    if track.root_m.len() != frames {
        return fail(format!("{} root positions for {frames} frames of rotations", track.root_m.len()));
    }
    if track.animated_offsets_m.len() != frames {
        return fail(format!(
            "{} frames of animated offsets for {frames} of rotations",
            track.animated_offsets_m.len()
        ));
    }
    if !(track.fps.is_finite() && track.fps > 0.0) {
        return fail(format!("frame rate {} is not a positive number", track.fps));
    }
    if let Some(j) = track.skeleton.offsets_m.iter().position(|o| !o.is_finite()) {
        return fail(format!("the rest offset of `{}` is not finite", Joint::ALL[j].name()));
    }
    for (frame, ((root, local), offsets)) in
        track.root_m.iter().zip(&track.local).zip(&track.animated_offsets_m).enumerate()
    {
        if !root.is_finite() {
            return fail(format!("frame {frame}: the pelvis position {root} is not finite"));
        }
        if let Some(j) = local.iter().position(|q| !q.is_finite()) {
            return fail(format!("frame {frame}: the rotation of `{}` is not finite", Joint::ALL[j].name()));
        }
        if let Some(k) = offsets.iter().position(|o| !o.is_finite()) {
            return fail(format!("frame {frame}: the offset of `{}` is not finite", ANIMATED_OFFSETS[k].name()));
        }
    }
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    match scene.iter().find(|b| !(finite(&b.centre_m) && finite(&b.half_extents_m) && finite(&b.rotation_xyzw))) {
        Some(b) => fail(format!("scene box `{}` is not finite", b.name)),
        None => Ok(()),
    }
}

/// The node of a joint: joint nodes come first, in index order.
fn node(joint: Joint) -> Index<json::Node> {
    Index::new(joint.index() as u32)
}

fn non_empty<T>(items: impl Iterator<Item = T>) -> Option<Vec<T>> {
    let items: Vec<T> = items.collect();
    (!items.is_empty()).then_some(items)
}

/// The 22 joint nodes, in index order: the pelvis rests where the motion starts, every other
/// joint at its rest offset from its parent, all unrotated.
fn joint_nodes(root: &mut Root, track: &RotationTrack) {
    for joint in Joint::ALL {
        let rest = match joint.parent() {
            None => track.root_m[0],
            Some(_) => track.skeleton.offsets_m[joint.index()],
        };
        root.nodes.push(json::Node {
            name: Some(joint.name().into()),
            translation: Some(rest.as_vec3().to_array()),
            children: non_empty(Joint::ALL.into_iter().filter(|c| c.parent() == Some(joint)).map(node)),
            ..Default::default()
        });
    }
}

/// The skinned body node, its skin and mesh, with the joints at `bind` (m) in the bind pose.
fn body_node(glb: &mut Builder, bind: &Pose) -> Index<json::Node> {
    let inverse_bind: Vec<f32> =
        bind.iter().flat_map(|p| DMat4::from_translation(-*p).as_mat4().to_cols_array()).collect();
    let inverse_bind_matrices = Some(glb.accessor(Values::F32(&inverse_bind), Type::Mat4, None));
    let skin = glb.root.push(json::Skin {
        extensions: None,
        extras: Default::default(),
        inverse_bind_matrices,
        joints: Joint::ALL.into_iter().map(node).collect(),
        name: Some("body".into()),
        skeleton: Some(node(Joint::Pelvis)),
    });
    let (body, bound_to) = body(bind);
    let (mut attributes, indices) = glb.geometry(&body);
    let joints = glb.accessor(Values::U8(&bound_to), Type::Vec4, Some(Target::ArrayBuffer));
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
    U8(&'a [u8]),
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
            Values::U8(v) => {
                self.bin.extend_from_slice(v);
                (ComponentType::U8, v.len(), None)
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

/// Per-component minimum and maximum of `values`, elements of `width` scalars.
fn bounds(values: &[f32], width: usize) -> (json::Value, json::Value) {
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

/// The animation `label`: the pelvis translation, the translations of the [`ANIMATED_OFFSETS`]
/// joints and every joint's rotation at every frame.
fn animation(glb: &mut Builder, label: &str, track: &RotationTrack) {
    let times: Vec<f32> = (0..track.frames()).map(|k| (k as f64 / track.fps) as f32).collect();
    let input = glb.accessor(Values::F32(&times), Type::Scalar, None);
    let translation = floats3(&track.root_m);
    let mut outputs =
        vec![(node(Joint::Pelvis), Property::Translation, glb.accessor(Values::F32(&translation), Type::Vec3, None))];
    for joint in ANIMATED_OFFSETS {
        let offsets: Vec<DVec3> = (0..track.frames()).map(|k| track.offset_m(k, joint)).collect();
        outputs.push((
            node(joint),
            Property::Translation,
            glb.accessor(Values::F32(&floats3(&offsets)), Type::Vec3, None),
        ));
    }
    for joint in Joint::ALL {
        let rotations: Vec<f32> =
            track.local.iter().flat_map(|frame| frame[joint.index()].as_quat().to_array()).collect();
        outputs.push((node(joint), Property::Rotation, glb.accessor(Values::F32(&rotations), Type::Vec4, None)));
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

/// The GLB container: 12-byte header, the JSON chunk padded with spaces, the BIN chunk padded
/// with zeros, each chunk a multiple of 4 bytes.
fn glb_container(json: &[u8], bin: &[u8]) -> Result<Vec<u8>, ExportError> {
    let padded = |len: usize| len.next_multiple_of(4);
    let total = 12 + 8 + padded(json.len()) + 8 + padded(bin.len());
    let total_u32 = u32::try_from(total)
        .map_err(|_| ExportError::Shape(format!("a GLB holds at most 4 GiB; this one needs {total} bytes")))?;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend(total_u32.to_le_bytes());
    for (chunk, kind, fill) in [(json, CHUNK_JSON, b' '), (bin, CHUNK_BIN, 0)] {
        let len = padded(chunk.len());
        // Fits in a u32: the whole file's length does.
        out.extend((len as u32).to_le_bytes());
        out.extend(kind.to_le_bytes());
        out.extend_from_slice(chunk);
        out.resize(out.len() + len - chunk.len(), fill);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use glam::DQuat;
    use json::validation::Validate;

    use super::*;
    use crate::import::{deepmimic::shipped, MocapClip};
    use crate::skeleton::NUM_JOINTS;

    /// The first `frames` frames of the shipped DeepMimic kick at 20 fps (a clip whose branch
    /// offsets move), and their solve.
    fn kick(frames: usize) -> (Vec<Pose>, RotationTrack) {
        let clip = shipped::clip("humanoid3d_kick.txt");
        let poses: Vec<Pose> = (0..frames).map(|k| clip.pose_at(k as f64 / 20.0)).collect();
        let track = RotationTrack::solve(&poses, 20.0, 0).unwrap();
        (poses, track)
    }

    fn wall() -> SceneBox {
        SceneBox {
            name: "gap left wall".into(),
            role: SceneRole::Obstacle,
            centre_m: [0.3, 1.0, 2.0],
            half_extents_m: [0.05, 1.0, 1.5],
            rotation_xyzw: [0.0, 0.0, 0.0, 1.0],
        }
    }

    /// A GLB read back: its JSON and its BIN chunk.
    struct Glb {
        root: Root,
        bin: Vec<u8>,
    }

    impl Glb {
        fn read(bytes: &[u8]) -> Self {
            let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
            assert_eq!(&bytes[..4], b"glTF");
            assert_eq!(word(4), 2);
            assert_eq!(word(8) as usize, bytes.len());
            let json_len = word(12) as usize;
            assert_eq!((word(16), json_len % 4), (CHUNK_JSON, 0));
            let root = Root::from_slice(&bytes[20..20 + json_len]).unwrap();
            let at = 20 + json_len;
            assert_eq!(word(at + 4), CHUNK_BIN);
            let bin = bytes[at + 8..at + 8 + word(at) as usize].to_vec();
            assert_eq!(at + 8 + bin.len(), bytes.len());
            Self { root, bin }
        }

        /// The floats of an `F32` accessor, element after element.
        fn floats(&self, index: Index<json::Accessor>) -> Vec<f32> {
            let accessor = &self.root.accessors[index.value()];
            let view = &self.root.buffer_views[accessor.buffer_view.unwrap().value()];
            let start = (view.byte_offset.unwrap().0 + accessor.byte_offset.map_or(0, |o| o.0)) as usize;
            assert_eq!(start % 4, 0);
            let n = accessor.count.0 as usize * components(accessor.type_.unwrap());
            self.bin[start..start + 4 * n].chunks(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
        }

        fn node_named(&self, name: &str) -> usize {
            self.root.nodes.iter().position(|n| n.name.as_deref() == Some(name)).unwrap()
        }

        /// World transform of every node at `frame` of the first animation (`None`: at rest).
        fn world(&self, frame: Option<usize>) -> Vec<DMat4> {
            let nodes = &self.root.nodes;
            let mut translation: Vec<DVec3> =
                nodes.iter().map(|n| DVec3::from(n.translation.unwrap_or_default().map(f64::from))).collect();
            let mut rotation: Vec<DQuat> =
                nodes.iter().map(|n| DQuat::from_array(n.rotation.unwrap_or_default().0.map(f64::from))).collect();
            if let Some(k) = frame {
                let animation = &self.root.animations[0];
                for channel in &animation.channels {
                    let values: Vec<f64> = self
                        .floats(animation.samplers[channel.sampler.value()].output)
                        .into_iter()
                        .map(f64::from)
                        .collect();
                    let node = channel.target.node.value();
                    match channel.target.path.unwrap() {
                        Property::Translation => translation[node] = DVec3::from_slice(&values[3 * k..]),
                        Property::Rotation => rotation[node] = DQuat::from_slice(&values[4 * k..]),
                        other => panic!("unexpected channel {other:?}"),
                    }
                }
            }
            let mut parent = vec![None; nodes.len()];
            for (i, n) in nodes.iter().enumerate() {
                for c in n.children.iter().flatten() {
                    parent[c.value()] = Some(i);
                }
            }
            let local = |i: usize| DMat4::from_rotation_translation(rotation[i], translation[i]);
            (0..nodes.len())
                .map(|i| {
                    let mut world = local(i);
                    let mut at = i;
                    while let Some(p) = parent[at] {
                        world = local(p) * world;
                        at = p;
                    }
                    world
                })
                .collect()
        }
    }

    #[test]
    fn the_animation_reproduces_forward_kinematics_and_the_input() {
        let (poses, track) = kick(40);
        let glb = Glb::read(&glb_bytes("kick", &track, &[]).unwrap());
        let root = &glb.root;
        let mut problems = Vec::new();
        root.validate(root, json::Path::new, &mut |path, error| problems.push(format!("{}: {error}", path())));
        assert!(problems.is_empty(), "{problems:?}");

        let skin = &root.skins[0];
        assert_eq!(skin.joints.len(), NUM_JOINTS);
        for (j, node) in Joint::ALL.into_iter().zip(&skin.joints) {
            assert_eq!(root.nodes[node.value()].name.as_deref(), Some(j.name()));
        }
        let animation = &root.animations[0];
        assert_eq!(animation.name.as_deref(), Some("kick"));
        assert_eq!(animation.channels.len(), NUM_JOINTS + 1 + ANIMATED_OFFSETS.len());
        let translated: Vec<&str> = animation
            .channels
            .iter()
            .filter(|c| c.target.path == Valid(Property::Translation))
            .map(|c| root.nodes[c.target.node.value()].name.as_deref().unwrap())
            .collect();
        assert_eq!(translated, ["pelvis", "left_hip", "right_hip", "spine1", "neck", "left_collar", "right_collar"]);
        let input = &root.accessors[animation.samplers[0].input.value()];
        assert_eq!(input.count.0, 40);
        let times = glb.floats(animation.samplers[0].input);
        assert_eq!(times[0], 0.0);
        assert!((f64::from(times[39]) - 39.0 / 20.0).abs() < 1e-6);
        assert_eq!(input.max.as_ref().and_then(|m| m[0].as_f64()), Some(f64::from(times[39])));

        let pelvis = glb.node_named("pelvis");
        let fk = track.forward_kinematics();
        let (mut to_track, mut to_input) = (0.0_f64, 0.0_f64);
        for (k, (pose, input)) in fk.iter().zip(&poses).enumerate() {
            let world = glb.world(Some(k));
            assert!(world[pelvis].w_axis.truncate().distance(track.root_m[k]) < 1e-5);
            for j in Joint::ALL {
                let at = world[glb.node_named(j.name())].w_axis.truncate();
                to_track = to_track.max(at.distance(pose[j.index()]));
                to_input = to_input.max(at.distance(input[j.index()]));
            }
        }
        eprintln!("largest distance of the GLB's joints from forward kinematics {to_track:.2e} m, from the input {to_input:.2e} m");
        assert!(to_track < 1e-5 && to_input < 1e-5, "{to_track} {to_input}");

        // The rest pose is the bind pose: every joint's rest transform times its inverse bind
        // matrix is the identity.
        let rest = glb.world(None);
        let inverse_bind = glb.floats(skin.inverse_bind_matrices.unwrap());
        for (node, matrix) in skin.joints.iter().zip(inverse_bind.chunks(16)) {
            let matrix = DMat4::from_cols_slice(&matrix.iter().map(|&x| f64::from(x)).collect::<Vec<_>>());
            assert!((rest[node.value()] * matrix).abs_diff_eq(DMat4::IDENTITY, 1e-5));
        }
    }

    #[test]
    fn a_scene_box_is_a_node_of_its_own() {
        let (_, track) = kick(3);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sample_0").join("motion.glb");
        write_glb(&path, "walk", &track, &[wall()]).unwrap();
        let glb = Glb::read(&std::fs::read(&path).unwrap());
        let node = &glb.root.nodes[glb.node_named("gap left wall")];
        assert!(node.skin.is_none());
        assert_eq!(node.scale, Some([0.1, 2.0, 3.0]));
        assert_eq!(node.translation, Some([0.3, 1.0, 2.0]));
        let mesh = &glb.root.meshes[node.mesh.unwrap().value()];
        let material = &glb.root.materials[mesh.primitives[0].material.unwrap().value()];
        assert_eq!((material.name.as_deref(), material.alpha_mode), (Some("obstacle"), Valid(AlphaMode::Blend)));
        assert!(glb.root.scenes[0]
            .nodes
            .iter()
            .any(|n| glb.root.nodes[n.value()].name.as_deref() == Some("gap left wall")));
    }

    #[test]
    fn bad_input_is_an_error() {
        let (_, track) = kick(2);
        let empty = RotationTrack { root_m: vec![], local: vec![], animated_offsets_m: vec![], ..track.clone() };
        assert!(glb_bytes("walk", &empty, &[]).unwrap_err().to_string().contains("no frames"));
        let short = RotationTrack { root_m: track.root_m[..1].to_vec(), ..track.clone() };
        assert!(glb_bytes("walk", &short, &[]).is_err());
        let short = RotationTrack { animated_offsets_m: track.animated_offsets_m[..1].to_vec(), ..track.clone() };
        assert!(glb_bytes("walk", &short, &[]).unwrap_err().to_string().contains("animated offsets"));
        let mut broken = track.clone();
        broken.animated_offsets_m[1][3].y = f64::INFINITY;
        let err = glb_bytes("walk", &broken, &[]).unwrap_err().to_string();
        assert!(err.contains("frame 1") && err.contains("`neck`"), "{err}");
        let mut broken = track.clone();
        broken.local[1][Joint::LeftElbow.index()].x = f64::NAN;
        let err = glb_bytes("walk", &broken, &[]).unwrap_err().to_string();
        assert!(err.contains("frame 1") && err.contains("left_elbow"), "{err}");
        let mut bad_box = wall();
        bad_box.centre_m[1] = f64::INFINITY;
        assert!(glb_bytes("walk", &track, &[bad_box]).unwrap_err().to_string().contains("gap left wall"));
    }
}
