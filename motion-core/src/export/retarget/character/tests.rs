//! A character read from glTF and its animated GLB posed again by forward kinematics: our own
//! skeleton with rotated bone frames under a scaled and turned armature node, the same in
//! centimetres, the shipped Mixamo-named character, and damaged files.

use std::path::{Path, PathBuf};

use glam::{DMat4, DQuat, DVec3};
use serde_json::{json, Value};

use super::*;
use crate::export::armature::rest_positions;
use crate::export::retarget::{retarget, Convention, Matched, Retargeted, TargetRig};
use crate::export::rotations::RotationTrack;
use crate::import::{deepmimic, resample};

fn fixture(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures").join(path)
}

/// Three seconds of the DeepMimic humanoid's walk, solved at 20 fps.
fn walk() -> RotationTrack {
    let (clip, _) = deepmimic::DeepMimicClip::read(&fixture("mocap/deepmimic/humanoid3d_walk.txt")).unwrap();
    RotationTrack::solve(&resample(&clip, 1.0, Some(3.0)), 20.0, 0).unwrap()
}

/// A `.gltf` of our own rest skeleton (the armature of `track`) as a skinned character: each
/// joint's bone frame turned off the world's (y along the bone, as Blender writes bones, and a
/// twist), all under an `Armature` node of matrix `armature`, the joints' own lengths divided by
/// `metres_per_unit`, the inverse bind matrices in a base64 buffer. Written into `dir`.
fn our_skeleton_as_gltf(dir: &Path, track: &RotationTrack, armature: DMat4, metres_per_unit: f64) -> PathBuf {
    let nodes = track.armature().nodes;
    let rest = rest_positions(&nodes, nodes[0].offset_m);
    let bind: Vec<DMat4> = (0..nodes.len())
        .map(|i| {
            let along = nodes.iter().position(|c| c.parent == Some(i)).map_or(DVec3::Y, |c| rest[c] - rest[i]);
            let frame = DQuat::from_rotation_arc(DVec3::Y, along.normalize()) * DQuat::from_rotation_y(0.3 * i as f64);
            armature * DMat4::from_rotation_translation(frame, rest[i] / metres_per_unit)
        })
        .collect();
    let mut gltf_nodes = vec![json!({"name": "Armature", "children": [1]})];
    let (s, r, t) = armature.to_scale_rotation_translation();
    gltf_nodes[0]["scale"] = json!(s.to_array());
    gltf_nodes[0]["rotation"] = json!(r.to_array());
    gltf_nodes[0]["translation"] = json!(t.to_array());
    for (i, node) in nodes.iter().enumerate() {
        let above = node.parent.map_or(armature, |p| bind[p]);
        let (s, r, t) = (above.inverse() * bind[i]).to_scale_rotation_translation();
        let children: Vec<usize> = (0..nodes.len()).filter(|c| nodes[*c].parent == Some(i)).map(|c| c + 1).collect();
        gltf_nodes.push(json!({"name": node.name, "children": children, "translation": t.to_array(),
            "rotation": r.to_array(), "scale": s.to_array()}));
    }
    let ibm: Vec<u8> =
        bind.iter().flat_map(|b| b.inverse().to_cols_array()).flat_map(|x| (x as f32).to_le_bytes()).collect();
    let uri =
        format!("data:application/octet-stream;base64,{}", base64::engine::general_purpose::STANDARD.encode(&ibm));
    let document = json!({
        "asset": {"version": "2.0"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": gltf_nodes,
        "skins": [{"joints": (1..=nodes.len()).collect::<Vec<_>>(), "inverseBindMatrices": 0}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": nodes.len(), "type": "MAT4"}],
        "bufferViews": [{"buffer": 0, "byteLength": ibm.len()}],
        "buffers": [{"byteLength": ibm.len(), "uri": uri}],
    });
    let path = dir.join("ours.gltf");
    std::fs::write(&path, serde_json::to_vec(&document).unwrap()).unwrap();
    path
}

/// The world matrix of every node of an animated GLB at every frame of its animation (channels
/// sampled at their keys).
fn posed(glb: &[u8]) -> Vec<Vec<DMat4>> {
    let (text, bin) = glb_chunks(glb).unwrap();
    let (document, bin): (Value, &[u8]) = (serde_json::from_slice(text).unwrap(), bin.unwrap());
    let nodes = array(&document, "nodes");
    let mut parents = vec![None; nodes.len()];
    for (i, n) in nodes.iter().enumerate() {
        for c in array(n, "children") {
            parents[c.as_u64().unwrap() as usize] = Some(i);
        }
    }
    let order = parents_first(&parents).unwrap();
    let animation = &array(&document, "animations")[0];
    let samplers = array(animation, "samplers");
    let frames = accessor_floats(&document, bin, count(&samplers[0], "input").unwrap(), "SCALAR").unwrap().len();
    let mut keys = Vec::new();
    for channel in array(animation, "channels") {
        let sampler = &samplers[count(channel, "sampler").unwrap()];
        let path = channel["target"]["path"].as_str().unwrap();
        let kind = if path == "rotation" { "VEC4" } else { "VEC3" };
        let values = accessor_floats(&document, bin, count(sampler, "output").unwrap(), kind).unwrap();
        keys.push((count(&channel["target"], "node").unwrap(), path.to_owned(), values));
    }
    (0..frames)
        .map(|k| {
            let mut world = vec![DMat4::IDENTITY; nodes.len()];
            for &n in &order {
                let mut node = nodes[n].clone();
                for (_, path, values) in keys.iter().filter(|(target, _, _)| *target == n) {
                    let width = if path == "rotation" { 4 } else { 3 };
                    node[path] = json!(values[k * width..(k + 1) * width]);
                }
                world[n] = parents[n].map_or(DMat4::IDENTITY, |p| world[p]) * local_matrix(&node).unwrap();
            }
            world
        })
        .collect()
}

/// The largest distance over frames between the GLB's node of each of our joints (divided by
/// the file's units per metre) and the retargeted poses, m; and between a point skinned to each
/// rig node (its bind position plus a fixed offset, moved by the file's world and inverse bind
/// matrices) and where the retargeted motion's turn of the node takes it, m.
fn glb_from_motion(glb: &[u8], rig: &TargetRig, done: &Retargeted) -> (f64, f64) {
    let character = rig.character.as_ref().unwrap();
    let u = rig.axes.per_metre;
    let rest = rig.rest_positions();
    let frames = posed(glb);
    assert_eq!(frames.len(), done.poses.len());
    let (mut joints, mut skinned) = (0.0_f64, 0.0_f64);
    let offset = DVec3::new(0.1, 0.05, -0.02);
    for (t, (world, pose)) in frames.iter().zip(&done.poses).enumerate() {
        for (j, &r) in rig.map.iter().enumerate() {
            let at = world[character.joints[r]].w_axis.truncate() / u;
            joints = joints.max(at.distance(pose[j]));
        }
        for (r, (at, turn)) in done.track.world(t).into_iter().enumerate() {
            let bind = DMat4::from_translation(rest[r] * u) * DMat4::from_mat3(character.linear[r]);
            let point = world[character.joints[r]] * bind.inverse() * (rest[r] * u + offset * u).extend(1.0);
            skinned = skinned.max((point.truncate() / u).distance(at + turn * offset));
        }
    }
    (joints, skinned)
}

#[test]
fn our_skeleton_with_turned_bone_frames_round_trips_in_metres_and_centimetres() {
    let track = walk();
    let ours = track.forward_kinematics();
    let turned = DMat4::from_scale_rotation_translation(
        DVec3::splat(0.01),
        DQuat::from_rotation_y(2.0),
        DVec3::new(1.0, 0.0, -3.0),
    );
    for (armature, metres_per_unit, per_metre) in
        [(turned, 0.01, 1.0), (DMat4::IDENTITY, 0.01, 100.0), (DMat4::IDENTITY, 1.0, 1.0)]
    {
        let dir = tempfile::tempdir().unwrap();
        let rig = TargetRig::read(&our_skeleton_as_gltf(dir.path(), &track, armature, metres_per_unit), None).unwrap();
        assert_eq!((rig.matched.clone(), rig.axes.per_metre), (Matched::Convention(Convention::Smpl), per_metre));
        let done = retarget(&track, &rig).unwrap();
        assert!(done.report.from_ours_max_m < 1e-3, "{:?}", done.report);
        for (a, b) in done.poses.iter().zip(&ours) {
            for j in 0..a.len() {
                assert!(a[j].distance(b[j]) < 1e-3, "per metre {per_metre}: joint {j}");
            }
        }
        let glb = rig.character.as_ref().unwrap().animated_glb("walk", &done.track, rig.axes.per_metre).unwrap();
        let (joints, skinned) = glb_from_motion(&glb, &rig, &done);
        assert!(
            joints < 1e-4 && skinned < 1e-4,
            "per metre {per_metre}: joints {joints} m, skinned points {skinned} m"
        );
    }
}

#[test]
fn the_shipped_character_matches_its_bvh_rig_and_keeps_its_meshes() {
    let path = fixture("rigs/mixamo_character.glb");
    let rig = TargetRig::read(&path, None).unwrap();
    assert_eq!(rig.matched, Matched::Convention(Convention::Mixamo));
    let bvh = TargetRig::read(&fixture("rigs/mixamo.bvh"), None).unwrap();
    let (a, b) = (rig.rest_positions(), bvh.rest_positions());
    for j in 0..rig.map.len() {
        let distance = a[rig.map[j]].distance(b[bvh.map[j]]);
        assert!(distance < 1e-3, "joint {j}: the character's bind pose is {distance} m from the BVH rig's");
    }
    let track = walk();
    let done = retarget(&track, &rig).unwrap();
    let glb = rig.character.as_ref().unwrap().animated_glb("walk", &done.track, rig.axes.per_metre).unwrap();
    let (joints, skinned) = glb_from_motion(&glb, &rig, &done);
    assert!(joints < 1e-4 && skinned < 1e-4, "joints {joints} m, skinned points {skinned} m");
    let original: Value = serde_json::from_slice(glb_chunks(&std::fs::read(&path).unwrap()).unwrap().0).unwrap();
    let written: Value = serde_json::from_slice(glb_chunks(&glb).unwrap().0).unwrap();
    for key in ["meshes", "skins", "materials"] {
        assert_eq!(written[key], original[key], "{key}");
    }
    assert_eq!(array(&written, "animations").len(), 1);
}

#[test]
fn damaged_characters_are_refused_naming_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, document: Value| {
        let path = dir.path().join(name);
        std::fs::write(&path, serde_json::to_vec(&document).unwrap()).unwrap();
        path
    };
    let error = |path: &Path| TargetRig::read(path, None).unwrap_err().to_string();
    let unskinned = write("a.gltf", json!({"asset": {"version": "2.0"}, "nodes": [{"name": "Hips"}]}));
    assert!(error(&unskinned).contains("a.gltf: it has no skin"), "{}", error(&unskinned));
    let cycle = write("b.gltf", json!({"asset": {"version": "2.0"}, "nodes": [{"children": [1]}, {"children": [0]}]}));
    assert!(error(&cycle).contains("two parents") || error(&cycle).contains("cycle"), "{}", error(&cycle));
    let missing =
        write("c.gltf", json!({"asset": {"version": "2.0"}, "buffers": [{"byteLength": 4, "uri": "gone.bin"}]}));
    assert!(error(&missing).contains("buffer 0") && error(&missing).contains("gone.bin"), "{}", error(&missing));
    let old = write("d.gltf", json!({"asset": {"version": "1.0"}}));
    assert!(error(&old).contains("only glTF 2.0"), "{}", error(&old));
    let lacking =
        write("e.gltf", json!({"asset": {"version": "2.0"}, "nodes": [{"name": "Hips"}], "skins": [{"joints": [0]}]}));
    assert!(error(&lacking).contains("no naming convention"), "{}", error(&lacking));
    std::fs::write(dir.path().join("f.glb"), b"glTF\x01\0\0\0").unwrap();
    assert!(error(&dir.path().join("f.glb")).contains("version 1"));
}
