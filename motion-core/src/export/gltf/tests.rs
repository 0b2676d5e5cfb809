//! The GLB read back: its structure, and its animation posed by forward kinematics against our
//! track's and a shipped rig's.

use std::path::Path;

use glam::DQuat;
use json::validation::Validate;

use super::*;
use crate::export::armature::our_joint_nodes;
use crate::export::glb::{CHUNK_BIN, CHUNK_JSON};
use crate::export::retarget::{retarget, TargetRig};
use crate::export::rotations::{RotationTrack, ANIMATED_OFFSETS};
use crate::import::{deepmimic::shipped, MocapClip};
use crate::skeleton::Pose;

/// The first `frames` frames of the shipped DeepMimic kick at 20 fps (a clip whose branch
/// offsets move), and their solve.
fn kick(frames: usize) -> (Vec<Pose>, RotationTrack) {
    let clip = shipped::clip("humanoid3d_kick.txt");
    let poses: Vec<Pose> = (0..frames).map(|k| clip.pose_at(k as f64 / 20.0)).collect();
    let track = RotationTrack::solve(&poses, 20.0, 0).unwrap();
    (poses, track)
}

/// The GLB of our own track, through its armature.
fn ours(label: &str, track: &RotationTrack, scene: &[SceneBox]) -> Result<Vec<u8>, ExportError> {
    glb_bytes(label, &track.armature(), &our_joint_nodes(), scene)
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

    /// Each node's parent, from the nodes' children.
    fn parents(&self) -> Vec<Option<usize>> {
        let mut parent = vec![None; self.root.nodes.len()];
        for (i, n) in self.root.nodes.iter().enumerate() {
            for c in n.children.iter().flatten() {
                parent[c.value()] = Some(i);
            }
        }
        parent
    }

    /// Every problem glTF's validation finds.
    fn assert_valid(&self) {
        let root = &self.root;
        let mut problems = Vec::new();
        root.validate(root, json::Path::new, &mut |path, error| problems.push(format!("{}: {error}", path())));
        assert!(problems.is_empty(), "{problems:?}");
    }

    /// The rest pose is the bind pose: every skin joint's rest transform times its inverse bind
    /// matrix is the identity.
    fn assert_rest_is_bind(&self) {
        let skin = &self.root.skins[0];
        let rest = self.world(None);
        let inverse_bind = self.floats(skin.inverse_bind_matrices.unwrap());
        for (node, matrix) in skin.joints.iter().zip(inverse_bind.chunks(16)) {
            let matrix = DMat4::from_cols_slice(&matrix.iter().map(|&x| f64::from(x)).collect::<Vec<_>>());
            assert!((rest[node.value()] * matrix).abs_diff_eq(DMat4::IDENTITY, 1e-5));
        }
    }

    /// Names of the nodes of the first animation's translation channels, in channel order.
    fn translated(&self) -> Vec<&str> {
        self.root.animations[0]
            .channels
            .iter()
            .filter(|c| c.target.path == Valid(Property::Translation))
            .map(|c| self.root.nodes[c.target.node.value()].name.as_deref().unwrap())
            .collect()
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
        let parent = self.parents();
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
    let glb = Glb::read(&ours("kick", &track, &[]).unwrap());
    glb.assert_valid();
    let root = &glb.root;

    let skin = &root.skins[0];
    assert_eq!(skin.joints.len(), NUM_JOINTS);
    for (j, node) in Joint::ALL.into_iter().zip(&skin.joints) {
        assert_eq!(root.nodes[node.value()].name.as_deref(), Some(j.name()));
    }
    let animation = &root.animations[0];
    assert_eq!(animation.name.as_deref(), Some("kick"));
    assert_eq!(animation.channels.len(), NUM_JOINTS + 1 + ANIMATED_OFFSETS.len());
    assert_eq!(glb.translated(), ["pelvis", "left_hip", "right_hip", "spine1", "neck", "left_collar", "right_collar"]);
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
    glb.assert_rest_is_bind();
}

#[test]
fn a_scene_box_is_a_node_of_its_own() {
    let (_, track) = kick(3);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sample_0").join("motion.glb");
    write_glb(&path, "walk", &track.armature(), &our_joint_nodes(), &[wall()]).unwrap();
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
    let armature = track.armature();
    let joints = our_joint_nodes();
    let error = |bad: &ArmatureTrack| glb_bytes("walk", bad, &joints, &[]).unwrap_err().to_string();
    let empty = ArmatureTrack { local: vec![], translations_m: vec![], ..armature.clone() };
    assert!(error(&empty).contains("no frames"));
    let short = ArmatureTrack { translations_m: armature.translations_m[..1].to_vec(), ..armature.clone() };
    assert!(error(&short).contains("do not agree"));
    let mut short = armature.clone();
    short.translations_m[1].pop();
    assert!(error(&short).contains("translations for 7 nodes do not agree"), "{}", error(&short));
    let mut broken = track.clone();
    broken.animated_offsets_m[1][3].y = f64::INFINITY;
    let err = error(&broken.armature());
    assert!(err.contains("frame 1") && err.contains("`neck`"), "{err}");
    let mut broken = track.clone();
    broken.local[1][Joint::LeftElbow.index()].x = f64::NAN;
    let err = error(&broken.armature());
    assert!(err.contains("frame 1") && err.contains("left_elbow"), "{err}");
    let mut broken = armature.clone();
    broken.nodes[Joint::LeftKnee.index()].offset_m.z = f64::NAN;
    assert!(error(&broken).contains("rest offset or end site of `left_knee`"), "{}", error(&broken));
    let slow = ArmatureTrack { fps: 0.0, ..armature.clone() };
    assert!(error(&slow).contains("frame rate 0"));
    let mut astray = joints;
    astray[Joint::Head.index()] = 40;
    let err = glb_bytes("walk", &armature, &astray, &[]).unwrap_err().to_string();
    assert!(err.contains("`head` is on node 40, not one of the 22 nodes"), "{err}");
    let mut bad_box = wall();
    bad_box.centre_m[1] = f64::INFINITY;
    assert!(ours("walk", &track, &[bad_box]).unwrap_err().to_string().contains("gap left wall"));
}

/// A shipped rig (`fixtures/rigs/`).
fn shipped_rig(file: &str) -> TargetRig {
    TargetRig::read(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/rigs").join(file), None).unwrap()
}

#[test]
fn a_rigs_glb_has_its_nodes_and_poses_the_retargeted_motion() {
    let (_, track) = kick(40);
    // Unreal: Z-up centimetres, a `root` on the floor above the pelvis, twist, finger and IK
    // bones; Mixamo: the pelvis is the root. The GLB is metres, y up, either way.
    for (file, translated) in [("unreal.bvh", ["root", "pelvis"].as_slice()), ("mixamo.bvh", &["mixamorig:Hips"])] {
        let rig = shipped_rig(file);
        let done = retarget(&track, &rig).unwrap();
        let glb = Glb::read(&glb_bytes(file, &done.track, &rig.map, &[wall()]).unwrap());
        glb.assert_valid();
        let parents = glb.parents();
        for (i, node) in rig.nodes.iter().enumerate() {
            assert_eq!(glb.root.nodes[i].name.as_deref(), Some(node.name.as_str()), "{file}");
            assert_eq!(parents[i], node.parent, "{file}: the parent of `{}`", node.name);
        }
        let skin = &glb.root.skins[0];
        assert_eq!(skin.joints, (0..rig.nodes.len()).map(node).collect::<Vec<_>>(), "{file}");
        assert_eq!(glb.translated(), translated, "{file}");
        glb.assert_rest_is_bind();

        let (mut to_nodes, mut to_joints) = (0.0_f64, 0.0_f64);
        for k in 0..done.track.frames() {
            let world = glb.world(Some(k));
            for (at, (want, _)) in world.iter().zip(done.track.world(k)) {
                to_nodes = to_nodes.max(at.w_axis.truncate().distance(want));
            }
            for j in Joint::ALL {
                to_joints =
                    to_joints.max(world[rig.map[j.index()]].w_axis.truncate().distance(done.poses[k][j.index()]));
            }
        }
        eprintln!(
            "{file}: the GLB's nodes within {to_nodes:.2e} m of the retargeted nodes, {to_joints:.2e} m of its joints"
        );
        assert!(to_nodes < 1e-4 && to_joints < 1e-4, "{file}: {to_nodes} {to_joints}");
    }
}
