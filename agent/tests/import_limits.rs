//! `mogen data build` on hostile or broken mocap (issue 18): every bad clip is an error that
//! names the file, where in it, and the rule or limit it breaks; never an abort, a huge
//! allocation or a message about a figure far downstream. HumanML3D folders are reachable
//! through the catalog.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::Output;

use candle_core::{Device, Tensor};
use motion_core::import::deepmimic::DeepMimicClip;
use motion_core::import::resample;
use motion_core::limits::MOCAP_FILE_BYTES;
use motion_core::representation::{extract_features, FEATURE_DIM};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures")
}

/// `mogen data build` on a catalog of the given entries (JSON objects) written into `dir`, with
/// any extra flags; the database goes to `dir/db.safetensors`.
fn build(dir: &Path, entries: &[String], flags: &[&str]) -> Output {
    let catalog = dir.join("catalog.json");
    std::fs::write(&catalog, format!("{{\"clips\": [{}]}}", entries.join(", "))).unwrap();
    std::process::Command::new(env!("CARGO_BIN_EXE_mogen"))
        .args(["data", "build", "--catalog"])
        .arg(&catalog)
        .arg("--out")
        .arg(dir.join("db.safetensors"))
        .args(flags)
        .current_dir(dir)
        .env("MOGEN_FIXTURES", fixtures())
        .env_remove("RUST_LOG")
        .output()
        .unwrap()
}

fn entry(file: &str, format: &str) -> String {
    format!(r#"{{"file": "{file}", "format": "{format}", "label": "a person walks forward"}}"#)
}

/// Runs `data build` on one clip and returns its stderr, checking that it failed cleanly
/// (exit status 1, not an abort or a signal) and wrote nothing.
fn refused(dir: &Path, file: &str, format: &str) -> String {
    let out = build(dir, &[entry(file, format)], &[]);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(!dir.join("db.safetensors").exists(), "{stderr}");
    stderr
}

/// The CMU walk (459 frames at 20 fps) with `edit` applied to its lines (0-based).
fn cmu_walk(edit: impl Fn(&mut Vec<String>)) -> String {
    let text = std::fs::read_to_string(fixtures().join("mocap/cmu/cmu_01_01_20fps.bvh")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    edit(&mut lines);
    lines.join("\n") + "\n"
}

/// 0-based index of the line `MOTION` in the CMU walk (frames start 3 lines later).
fn motion_line(lines: &[String]) -> usize {
    lines.iter().position(|l| l.trim() == "MOTION").unwrap()
}

/// A run of `n` digits, as `1e308` printed in full would show.
fn has_digit_run(s: &str, n: usize) -> bool {
    s.as_bytes().windows(n).any(|w| w.iter().all(u8::is_ascii_digit))
}

#[test]
fn a_bvh_frame_time_of_100000_s_is_an_error_not_an_abort() {
    let dir = tempfile::tempdir().unwrap();
    let text = cmu_walk(|lines| {
        let at = motion_line(lines) + 2;
        lines[at] = "Frame Time: 100000".into();
    });
    std::fs::write(dir.path().join("slow.bvh"), text).unwrap();
    let stderr = refused(dir.path(), "slow.bvh", "bvh");
    assert!(stderr.contains("slow.bvh") && stderr.contains("line 187"), "{stderr}");
    assert!(stderr.contains("Frame Time") && stderr.contains("100000"), "{stderr}");

    // A plausible frame time with a clip longer than the limit names the limit and the value.
    // 4000 frames a second apart: 3999 s, 79981 frames at 20 fps.
    let text = cmu_walk(|lines| {
        let at = motion_line(lines);
        let first = lines[at + 3].clone();
        lines.splice(at + 3..at + 3, std::iter::repeat_n(first, 4000 - 459));
        lines[at + 1] = "Frames: 4000".into();
        lines[at + 2] = "Frame Time: 1".into();
    });
    std::fs::write(dir.path().join("long.bvh"), text).unwrap();
    let stderr = refused(dir.path(), "long.bvh", "bvh");
    assert!(stderr.contains("long.bvh") && stderr.contains("lines 186-187"), "{stderr}");
    assert!(stderr.contains("is 79981 frames at 20 fps, over the limit of 72000"), "{stderr}");
    assert!(stderr.contains("imported clip length"), "{stderr}");
}

#[test]
fn a_rig_over_the_joint_limit_and_a_file_over_the_size_limit_are_refused_before_reading_on() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n");
    for j in 0..100_000 {
        text.push_str(&format!("JOINT J{j}\n{{\nOFFSET 0 1 0\nCHANNELS 0\n}}\n"));
    }
    text.push_str("}\nMOTION\nFrames: 1\nFrame Time: 0.05\n0 0 0\n");
    std::fs::write(dir.path().join("wide.bvh"), text).unwrap();
    let stderr = refused(dir.path(), "wide.bvh", "bvh");
    assert!(stderr.contains("wide.bvh") && stderr.contains("joints per rig"), "{stderr}");
    // The 1025th node is the first one over: JOINT J1023, five lines per joint after the root's.
    assert!(stderr.contains("line 5121") && stderr.contains("1025 joints"), "{stderr}");

    // A sparse file one byte over the limit: refused by size, whatever it holds.
    let big = std::fs::File::create(dir.path().join("big.bvh")).unwrap();
    big.set_len(MOCAP_FILE_BYTES.max + 1).unwrap();
    let stderr = refused(dir.path(), "big.bvh", "bvh");
    assert!(stderr.contains("big.bvh") && stderr.contains("mocap file size"), "{stderr}");
}

#[test]
fn a_bvh_value_of_1e308_names_the_file_frame_and_channel() {
    let dir = tempfile::tempdir().unwrap();
    let text = cmu_walk(|lines| {
        let at = motion_line(lines) + 3 + 10;
        let mut values: Vec<&str> = lines[at].split_whitespace().collect();
        values[1] = "1e308";
        lines[at] = values.join(" ");
    });
    std::fs::write(dir.path().join("far.bvh"), text).unwrap();
    let stderr = refused(dir.path(), "far.bvh", "bvh");
    assert!(stderr.contains("far.bvh") && stderr.contains("line 198"), "{stderr}");
    assert!(stderr.contains("frame 10") && stderr.contains("Yposition") && stderr.contains("1e308"), "{stderr}");
    assert!(!stderr.contains("mean[") && !has_digit_run(&stderr, 20), "{stderr}");
}

/// The DeepMimic walk with `edit` applied to its `Frames`.
fn deepmimic_walk(edit: impl Fn(&mut Vec<serde_json::Value>)) -> String {
    let text = std::fs::read_to_string(fixtures().join("mocap/deepmimic/humanoid3d_walk.txt")).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    edit(json["Frames"].as_array_mut().unwrap());
    json.to_string()
}

#[test]
fn a_deepmimic_root_at_1e300_is_out_of_range() {
    let dir = tempfile::tempdir().unwrap();
    let text = deepmimic_walk(|frames| frames[3][1] = serde_json::json!(1e300));
    std::fs::write(dir.path().join("far_walk.txt"), text).unwrap();
    let stderr = refused(dir.path(), "far_walk.txt", "deepmimic");
    assert!(stderr.contains("far_walk.txt") && stderr.contains("frame 3, value 1"), "{stderr}");
    assert!(stderr.contains("out of range") && stderr.contains("1e300"), "{stderr}");
    assert!(!stderr.contains("facing") && !has_digit_run(&stderr, 20), "{stderr}");
}

#[test]
fn huge_numbers_in_messages_are_short() {
    let dir = tempfile::tempdir().unwrap();
    let text = cmu_walk(|lines| {
        let at = motion_line(lines) + 2;
        lines[at] = "Frame Time: -1e308".into();
    });
    std::fs::write(dir.path().join("back.bvh"), text).unwrap();
    let stderr = refused(dir.path(), "back.bvh", "bvh");
    assert!(stderr.contains("back.bvh") && stderr.contains("-1e308"), "{stderr}");
    assert!(!has_digit_run(&stderr, 20), "{stderr}");

    let text = deepmimic_walk(|frames| frames[2][0] = serde_json::json!(-1e308));
    std::fs::write(dir.path().join("back.txt"), text).unwrap();
    let stderr = refused(dir.path(), "back.txt", "deepmimic");
    assert!(stderr.contains("back.txt") && stderr.contains("frame 2, value 0"), "{stderr}");
    assert!(stderr.contains("-1e308") && !has_digit_run(&stderr, 20), "{stderr}");
}

#[test]
fn loop_seconds_are_checked_when_the_flag_is_parsed() {
    let dir = tempfile::tempdir().unwrap();
    let walk = fixtures().join("mocap/deepmimic/humanoid3d_walk.txt");
    std::fs::copy(walk, dir.path().join("walk.txt")).unwrap();
    for (value, needle) in [("1e9", "imported clip length"), ("nan", "finite"), ("-3", "positive"), ("0", "positive")] {
        let out = build(dir.path(), &[entry("walk.txt", "deepmimic")], &[&format!("--loop-seconds={value}")]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--loop-seconds {value}: {stderr}");
        assert!(stderr.contains("--loop-seconds") && stderr.contains(needle), "--loop-seconds {value}: {stderr}");
    }
}

/// Writes `[frames, 263]` features as a float32 `.npy`.
fn write_features(path: &Path, features: &[[f32; FEATURE_DIM]]) {
    let flat: Vec<f32> = features.iter().flatten().copied().collect();
    Tensor::from_vec(flat, (features.len(), FEATURE_DIM), &Device::Cpu).unwrap().write_npy(path).unwrap();
}

#[test]
fn a_humanml3d_folder_builds_through_the_catalog() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("hml");
    std::fs::create_dir_all(root.join("new_joint_vecs")).unwrap();
    std::fs::create_dir_all(root.join("texts")).unwrap();
    let (walk, _) = DeepMimicClip::read(&fixtures().join("mocap/deepmimic/humanoid3d_walk.txt")).unwrap();
    let features = extract_features(&resample(&walk, 1.0, Some(4.0))).unwrap().features;
    write_features(&root.join("new_joint_vecs/000001.npy"), &features);
    write_features(&root.join("new_joint_vecs/000002.npy"), &features[..60]);
    std::fs::write(
        root.join("texts/000001.txt"),
        "a person strolls ahead.#a/DET person/NOUN stroll/VERB ahead/ADV#0.0#0.0\n\
         someone walks#someone/PRON walk/VERB#1.0#2.0\n",
    )
    .unwrap();
    std::fs::write(root.join("texts/000002.txt"), "a person takes a few steps#a/DET#0.0#0.0\n").unwrap();
    Tensor::zeros(FEATURE_DIM, candle_core::DType::F32, &Device::Cpu)
        .unwrap()
        .write_npy(root.join("Mean.npy"))
        .unwrap();
    Tensor::ones(FEATURE_DIM, candle_core::DType::F32, &Device::Cpu).unwrap().write_npy(root.join("Std.npy")).unwrap();

    let out = build(dir.path(), &[r#"{"file": "hml", "format": "humanml3d"}"#.to_owned()], &["--no-mirror"]);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stderr}");
    assert!(stdout.contains("a person strolls ahead.") && stdout.contains("a person takes a few steps"), "{stdout}");
    assert!(dir.path().join("db.safetensors").is_file());

    // A broken clip in the folder is named.
    std::fs::write(root.join("texts/000002.txt"), "no fields\n").unwrap();
    let out = build(dir.path(), &[r#"{"file": "hml", "format": "humanml3d"}"#.to_owned()], &[]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("000002.txt") && stderr.contains("line 1"), "{stderr}");
}
