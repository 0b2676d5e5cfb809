//! `mogen export` as a user calls it: motions they already have become BVH, GLB and the viewer;
//! bad input gets an error naming the problem and writes nothing.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;
use std::process::{Command, Output};

use candle_core::{Device, Tensor};

fn mogen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mogen")).args(args).output().unwrap()
}

/// A standing figure drifting forward: `[samples, frames, 22, 3]` built from the canonical
/// rest pose, with the pelvis 0.9 m up.
fn standing(samples: usize, frames: usize) -> Vec<f32> {
    let rest = motion_core::skeleton::rest_pose();
    let mut out = Vec::new();
    for s in 0..samples {
        for t in 0..frames {
            for p in rest {
                let q = p + glam::DVec3::new(0.3 * s as f64, 0.9, 0.05 * t as f64);
                out.extend([q.x as f32, q.y as f32, q.z as f32]);
            }
        }
    }
    out
}

fn files_under(dir: &Path) -> usize {
    if !dir.exists() {
        return 0;
    }
    std::fs::read_dir(dir).unwrap().count()
}

#[test]
fn a_joints_file_becomes_bvh_glb_and_the_viewer() {
    let dir = tempfile::tempdir().unwrap();
    let npy = dir.path().join("joints.npy");
    Tensor::from_vec(standing(2, 30), (2, 30, 22, 3), &Device::Cpu).unwrap().write_npy(&npy).unwrap();
    let out = dir.path().join("exported");
    let output =
        mogen(&["export", &npy.display().to_string(), "--out", &out.display().to_string(), "--centimetres", "--gif"]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    for file in ["sample_0/motion.bvh", "sample_1/motion.glb", "viewer.html", "export.json", "motion.gif"] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    let bvh = std::fs::read_to_string(out.join("sample_1/motion.bvh")).unwrap();
    assert!(bvh.contains("Frames: 30") && bvh.contains("Frame Time: 0.05"), "{bvh}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("export.json")).unwrap()).unwrap();
    assert_eq!(manifest["bvh_unit"], "centimetres");
    assert_eq!(manifest["samples"].as_array().unwrap().len(), 2);
    // A rigid figure is reproduced by the rotations.
    assert!(manifest["samples"][0]["fit_max_m"].as_f64().unwrap() < 1e-6);

    // One motion `[frames, 22, 3]` works too, into the npy's own folder.
    let single = dir.path().join("one").join("joints.npy");
    std::fs::create_dir_all(single.parent().unwrap()).unwrap();
    Tensor::from_vec(standing(1, 12), (12, 22, 3), &Device::Cpu).unwrap().write_npy(&single).unwrap();
    let output = mogen(&["export", &single.display().to_string()]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(dir.path().join("one/sample_0/motion.glb").is_file());
    assert!(!dir.path().join("one/motion.gif").exists(), "a GIF only on request");
}

#[test]
fn files_at_an_engines_frame_rate_keep_the_duration_and_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let npy = dir.path().join("joints.npy");
    // 30 frames at 20 fps: 1.45 s, walking 0.05 m per frame.
    Tensor::from_vec(standing(1, 30), (1, 30, 22, 3), &Device::Cpu).unwrap().write_npy(&npy).unwrap();
    let export = |fps: &str| {
        let out = dir.path().join(format!("at{fps}"));
        let output = mogen(&["export", &npy.display().to_string(), "--out", &out.display().to_string(), "--fps", fps]);
        assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
        let manifest: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("export.json")).unwrap()).unwrap();
        (std::fs::read_to_string(out.join("sample_0/motion.bvh")).unwrap(), manifest)
    };
    let (bvh, manifest) = export("60");
    // 1.45 s at 60 fps: 87 frame times, 88 frames.
    assert!(bvh.contains("Frames: 88") && bvh.contains("Frame Time: 0.016666667"), "{bvh}");
    assert_eq!((manifest["fps"].as_f64(), manifest["motion_fps"].as_f64()), (Some(60.0), Some(20.0)));
    // The last probe is the last frame: the pelvis has walked 29 × 0.05 m, as at 20 fps.
    let probes = manifest["samples"][0]["probes"].as_array().unwrap();
    let last = probes.iter().rfind(|p| p["joint"] == "pelvis").unwrap();
    assert_eq!(last["frame"], 87);
    assert!((last["position_m"][2].as_f64().unwrap() - 1.45).abs() < 1e-5, "{last}");
    let (bvh, _) = export("24");
    // 1.45 s is 34.8 frame times at 24 fps: 35 frames, ending 0.2 frame times early.
    assert!(bvh.contains("Frames: 35"), "{bvh}");

    // In place at 30 fps: the pelvis stays over its first position, at its height.
    let out = dir.path().join("in-place");
    let output = mogen(&[
        "export",
        &npy.display().to_string(),
        "--out",
        &out.display().to_string(),
        "--fps",
        "30",
        "--in-place",
    ]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("export.json")).unwrap()).unwrap();
    assert_eq!(manifest["in_place"], true);
    let pelvis: Vec<&serde_json::Value> =
        manifest["samples"][0]["probes"].as_array().unwrap().iter().filter(|p| p["joint"] == "pelvis").collect();
    assert_eq!(pelvis.last().unwrap()["frame"], 43, "1.45 s at 30 fps: 44 frames");
    for probe in &pelvis {
        let xyz: Vec<f64> = (0..3).map(|k| probe["position_m"][k].as_f64().unwrap()).collect();
        let first: Vec<f64> = (0..3).map(|k| pelvis[0]["position_m"][k].as_f64().unwrap()).collect();
        assert!((xyz[0] - first[0]).abs() < 1e-9 && (xyz[2] - first[2]).abs() < 1e-9, "{probe}");
        assert!((xyz[1] - first[1]).abs() < 1e-9, "the standing figure keeps its height: {probe}");
    }

    let output = mogen(&[
        "export",
        &npy.display().to_string(),
        "--out",
        &dir.path().join("bad").display().to_string(),
        "--fps",
        "0",
    ]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success() && stderr.contains("--fps") && stderr.contains("1..=240"), "{stderr}");
    assert!(!dir.path().join("bad").exists());
}

#[test]
fn a_users_rig_gets_the_motion_in_its_own_unit_and_axes_and_a_rig_without_our_joints_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let npy = dir.path().join("joints.npy");
    Tensor::from_vec(standing(2, 12), (2, 12, 22, 3), &Device::Cpu).unwrap().write_npy(&npy).unwrap();
    let rigs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/rigs");
    let out = dir.path().join("unreal");
    let rig = rigs.join("unreal.bvh");
    let args = ["export", &npy.display().to_string(), "--out", &out.display().to_string(), "--rig"];
    let output = mogen(&[&args[..], &[rig.to_str().unwrap()]].concat());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("on the rig `unreal` (Unreal mannequin, 40 nodes"), "{stderr}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("export.json")).unwrap()).unwrap();
    for i in 0..2 {
        let rig = &manifest["samples"][i]["rig"];
        assert_eq!(
            (rig["bvh"].as_str(), rig["z_up"].as_bool()),
            (Some(format!("sample_{i}/unreal.bvh").as_str()), Some(true))
        );
        assert_eq!(rig["units_per_metre"], 100.0);
        assert_eq!(rig["glb"].as_str(), Some(format!("sample_{i}/unreal.glb").as_str()));
        assert!(std::fs::read(out.join(format!("sample_{i}/unreal.glb"))).unwrap().starts_with(b"glTF"));
        assert!(rig["report"]["contact_miss_max_m"].as_f64().unwrap() < 0.01, "{rig}");
        let bvh = std::fs::read_to_string(out.join(format!("sample_{i}/unreal.bvh"))).unwrap();
        // Unreal's own hierarchy, Z-up centimetres: the pelvis 96 cm over the root on the floor.
        assert!(bvh.starts_with("HIERARCHY\nROOT root\n") && bvh.contains("JOINT pelvis\n"), "{bvh}");
        assert!(bvh.contains("JOINT upperarm_twist_01_l") && bvh.contains("Frames: 12"), "{bvh}");
    }
    assert!(out.join("rig_strip.png").is_file(), "the picture of ours and the rig");
    let page = std::fs::read_to_string(out.join("viewer.html")).unwrap();
    assert_eq!(page.matches("\"glb_base64\":").count(), 2, "the viewer plays each sample on the rig");
    // The rig (our size) puts its right toe (`ball_r`) where ours is on every probed frame.
    let toe = |probes: &serde_json::Value| -> Vec<serde_json::Value> {
        probes.as_array().unwrap().iter().filter(|p| p["joint"] == "right_foot").cloned().collect()
    };
    let (on_rig, ours) = (toe(&manifest["samples"][0]["rig"]["probes"]), toe(&manifest["samples"][0]["probes"]));
    assert_eq!((on_rig.len(), on_rig[0]["node"].as_str()), (4, Some("ball_r")));
    for (a, b) in on_rig.iter().zip(&ours) {
        let distance = (0..3)
            .map(|k| (a["position_m"][k].as_f64().unwrap() - b["position_m"][k].as_f64().unwrap()).powi(2))
            .sum::<f64>()
            .sqrt();
        assert!(distance < 0.005, "{a} against {b}");
    }

    let broken = dir.path().join("no_toes.bvh");
    std::fs::write(&broken, std::fs::read_to_string(&rig).unwrap().replace("ball_l", "toe_l")).unwrap();
    let out = dir.path().join("refused");
    let args = ["export", &npy.display().to_string(), "--out", &out.display().to_string(), "--rig"];
    let output = mogen(&[&args[..], &[broken.to_str().unwrap()]].concat());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(stderr.contains("no_toes.bvh") && stderr.contains("lacks ball_l (left_foot)"), "{stderr}");
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn a_skinned_character_gets_the_motion_in_its_own_file_and_a_gltf_missing_its_buffer_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let npy = dir.path().join("joints.npy");
    Tensor::from_vec(standing(1, 12), (1, 12, 22, 3), &Device::Cpu).unwrap().write_npy(&npy).unwrap();
    let character = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/rigs/mixamo_character.glb");
    let out = dir.path().join("character");
    let args = ["export", npy.to_str().unwrap(), "--out", out.to_str().unwrap(), "--rig", character.to_str().unwrap()];
    let output = mogen(&args);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("on the rig `mixamo_character` (Mixamo, 28 nodes"), "{stderr}");
    // The character's own document: its mesh, skin and nodes, and the motion as its animation.
    let json_of = |bytes: &[u8]| -> serde_json::Value {
        let length = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        serde_json::from_slice(&bytes[20..20 + length]).unwrap()
    };
    let original = json_of(&std::fs::read(&character).unwrap());
    let written = json_of(&std::fs::read(out.join("sample_0/mixamo_character.glb")).unwrap());
    assert_eq!((&written["meshes"], &written["skins"]), (&original["meshes"], &original["skins"]));
    let channels = written["animations"][0]["channels"].as_array().unwrap();
    assert_eq!(channels.len(), 2 * 28, "a translation and a rotation channel per joint");
    let bvh = std::fs::read_to_string(out.join("sample_0/mixamo_character.bvh")).unwrap();
    assert!(bvh.starts_with("HIERARCHY\nROOT mixamorig:Hips\n") && bvh.contains("Frames: 12"), "{bvh}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("export.json")).unwrap()).unwrap();
    assert_eq!(manifest["samples"][0]["rig"]["units_per_metre"], 1.0);

    // A .gltf whose buffer file is not beside it.
    let gltf = dir.path().join("character.gltf");
    let mut document = original.clone();
    document["buffers"][0]["uri"] = "character.bin".into();
    std::fs::write(&gltf, serde_json::to_vec(&document).unwrap()).unwrap();
    let out = dir.path().join("refused");
    let args = ["export", npy.to_str().unwrap(), "--out", out.to_str().unwrap(), "--rig", gltf.to_str().unwrap()];
    let output = mogen(&args);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "{stderr}");
    assert!(stderr.contains("character.gltf: buffer 0") && stderr.contains("character.bin"), "{stderr}");
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn a_rig_of_other_names_is_matched_through_a_joint_map() {
    let dir = tempfile::tempdir().unwrap();
    let npy = dir.path().join("joints.npy");
    Tensor::from_vec(standing(1, 6), (1, 6, 22, 3), &Device::Cpu).unwrap().write_npy(&npy).unwrap();
    let mixamo = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/rigs/mixamo.bvh"));
    // Names of no convention: `rig_` glued on, and the upper chest called `Chest`.
    let rig = dir.path().join("house_style.bvh");
    std::fs::write(&rig, mixamo.unwrap().replace("mixamorig:", "rig_").replace("rig_Spine2", "rig_Chest")).unwrap();
    let ours_to_mixamo = [
        ("pelvis", "Hips"),
        ("left_hip", "LeftUpLeg"),
        ("right_hip", "RightUpLeg"),
        ("spine1", "Spine"),
        ("left_knee", "LeftLeg"),
        ("right_knee", "RightLeg"),
        ("spine2", "Spine1"),
        ("left_ankle", "LeftFoot"),
        ("right_ankle", "RightFoot"),
        ("spine3", "Chest"),
        ("left_foot", "LeftToeBase"),
        ("right_foot", "RightToeBase"),
        ("neck", "Neck"),
        ("left_collar", "LeftShoulder"),
        ("right_collar", "RightShoulder"),
        ("head", "Head"),
        ("left_shoulder", "LeftArm"),
        ("right_shoulder", "RightArm"),
        ("left_elbow", "LeftForeArm"),
        ("right_elbow", "RightForeArm"),
        ("left_wrist", "LeftHand"),
        ("right_wrist", "RightHand"),
    ];
    let map: serde_json::Map<String, serde_json::Value> =
        ours_to_mixamo.iter().map(|(ours, node)| (ours.to_string(), format!("rig_{node}").into())).collect();
    let map_path = dir.path().join("map.json");
    std::fs::write(&map_path, serde_json::Value::Object(map).to_string()).unwrap();
    let export = |extra: &[&str]| {
        let out = dir.path().join(format!("out{}", extra.len()));
        let args = ["export", npy.to_str().unwrap(), "--out", out.to_str().unwrap(), "--rig", rig.to_str().unwrap()];
        (mogen(&[&args[..], extra].concat()), out)
    };
    let (output, out) = export(&[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success() && stderr.contains("name the nodes with a joint map"), "{stderr}");
    assert!(!out.exists());
    let (output, out) = export(&["--rig-map", map_path.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success() && stderr.contains("(explicit map, 28 nodes"), "{stderr}");
    assert!(out.join("sample_0/house_style.bvh").is_file() && out.join("sample_0/house_style.glb").is_file());
}

#[test]
fn bad_input_is_named_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let out_arg = out.display().to_string();
    let check = |input: &Path, expected: &[&str]| {
        let output = mogen(&["export", &input.display().to_string(), "--out", &out_arg]);
        let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
        assert!(!output.status.success(), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        for needle in expected {
            assert!(stderr.contains(needle), "{needle:?} not in {stderr}");
        }
        assert_eq!(files_under(&out), 0, "{stderr}");
    };
    check(&dir.path().join("missing.npy"), &["missing.npy", "no such file"]);

    let wrong = dir.path().join("wrong.npy");
    Tensor::zeros((4, 21, 3), candle_core::DType::F32, &Device::Cpu).unwrap().write_npy(&wrong).unwrap();
    check(&wrong, &["wrong.npy", "[4, 21, 3]", "[frames, 22, 3]"]);

    let text = dir.path().join("text.npy");
    std::fs::write(&text, "not an array").unwrap();
    check(&text, &["text.npy", "not a .npy file"]);

    // A header promising more than the file holds (or than memory allows) is refused from the
    // header, before anything is allocated for it.
    let huge = dir.path().join("huge.npy");
    let mut bytes = npy_header("(1000000000000, 22, 3)");
    bytes.extend_from_slice(&[0; 64]);
    std::fs::write(&huge, bytes).unwrap();
    check(&huge, &["huge.npy", "1000000000000 frames at 20 fps, over the limit of 72000"]);

    let mut values = standing(2, 5);
    values[(5 + 2) * 66 + 3 * 3 + 1] = f32::NAN; // sample 1, frame 2, spine1, y
    let nan = dir.path().join("nan.npy");
    Tensor::from_vec(values, (2, 5, 22, 3), &Device::Cpu).unwrap().write_npy(&nan).unwrap();
    check(&nan, &["sample 1", "frame 2", "spine1", "not finite"]);
}

/// The first bytes of a float32 `.npy` (version 1.0) of `shape`, e.g. `(2, 22, 3)`.
fn npy_header(shape: &str) -> Vec<u8> {
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    header.push_str(&" ".repeat(63 - (10 + header.len()) % 64));
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    bytes
}
