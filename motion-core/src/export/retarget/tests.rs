//! Retargeting onto the shipped rigs (`fixtures/rigs/`), a real capture rig (CMU), and our own
//! skeleton, read back through the BVH importer.

use std::path::{Path, PathBuf};

use glam::DVec3;

use super::{judge_on_rig, retarget, Convention, Matched, Retargeted, RigJudge, TargetRig};
use crate::export::bvh::bvh_text;
use crate::export::rotations::RotationTrack;
use crate::import::bvh::{Bvh, BvhAnimation, LengthUnit, UpAxis};
use crate::import::{deepmimic, resample};
use crate::skeleton::{Joint, Pose};

fn fixture(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures").join(path)
}

/// Four seconds of the DeepMimic humanoid's walk, solved at 20 fps, and its joints. Its
/// branches are rigid (no animated offsets), which a rig's fixed bones cannot carry.
fn walk() -> (RotationTrack, Vec<Pose>) {
    let (clip, _) = deepmimic::DeepMimicClip::read(&fixture("mocap/deepmimic/humanoid3d_walk.txt")).unwrap();
    let poses = resample(&clip, 1.0, Some(4.0));
    let track = RotationTrack::solve(&poses, 20.0, 0).unwrap();
    let fk = track.forward_kinematics();
    (track, fk)
}

/// The written BVH of `done` read back by the importer in the rig's unit and axes: every node's
/// largest distance from the retargeted motion, m.
fn read_back(done: &Retargeted, rig: &TargetRig) -> f64 {
    let text = bvh_text(&done.track, rig.axes);
    let path = Path::new("retargeted.bvh");
    let (bvh, warnings) = Bvh::parse(&text, path).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let animation =
        BvhAnimation::new(&bvh, LengthUnit::MetresPer(1.0 / rig.axes.per_metre), rig.axes.up, path).unwrap();
    let mut worst = 0.0_f64;
    for t in 0..done.track.frames() {
        let read = animation.positions_at(t as f64 * animation.frame_time_s());
        let world = done.track.world(t);
        let nodes: Vec<DVec3> = bvh.joints().iter().zip(&read).filter(|(j, _)| !j.end_site).map(|(_, p)| *p).collect();
        assert_eq!(nodes.len(), world.len());
        for (a, (b, _)) in nodes.iter().zip(&world) {
            worst = worst.max(a.distance(*b));
        }
    }
    worst
}

#[test]
fn our_own_skeleton_as_the_target_reproduces_our_joints() {
    let (track, fk) = walk();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ours.bvh");
    std::fs::write(&path, bvh_text(&track.armature(), crate::export::bvh::BvhUnit::Metres.into())).unwrap();
    let rig = TargetRig::read(&path, None).unwrap();
    assert_eq!((rig.matched.clone(), rig.axes.up), (Matched::Convention(Convention::Smpl), UpAxis::Y));
    let done = retarget(&track, &rig).unwrap();
    let worst =
        done.poses.iter().zip(&fk).flat_map(|(a, b)| a.iter().zip(b).map(|(p, q)| p.distance(*q))).fold(0.0, f64::max);
    println!("{:?}", done.report);
    assert!(worst < 1e-3, "{worst} m from our joints");
    assert!((done.report.leg_ratio - 1.0).abs() < 1e-5);
    assert!(read_back(&done, &rig) < 1e-4);
}

/// The README's main command's motion (the shipped prior's, committed with that command's
/// results under `fixtures/results/`): a walk through a gap, on the prior's skeleton, whose
/// trunk and shoulder shape the shipped rigs follow.
fn main_command_motion() -> RotationTrack {
    let motions = crate::export::read_joints_npy(&fixture("results/session35-main/joints.npy")).unwrap();
    RotationTrack::solve(&motions[0], 20.0, 0).unwrap()
}

#[test]
fn every_shipped_rig_carries_the_walk_with_the_feet_where_it_plants_them() {
    let track = main_command_motion();
    for (file, convention, ratio, up, same_proportions) in [
        ("mixamo.bvh", Convention::Mixamo, 1.05, UpAxis::Y, true),
        ("a_pose.bvh", Convention::Mixamo, 1.0, UpAxis::Y, true),
        ("unreal.bvh", Convention::Unreal, 1.0, UpAxis::Z, true),
        ("unity.bvh", Convention::Unity, 0.95, UpAxis::Y, true),
        ("short_legs.bvh", Convention::Smpl, 0.7, UpAxis::Y, false),
    ] {
        let rig = TargetRig::read(&fixture("rigs").join(file), None).unwrap();
        assert_eq!((rig.matched.clone(), rig.axes.up), (Matched::Convention(convention), up), "{file}");
        let done = retarget(&track, &rig).unwrap();
        let r = &done.report;
        println!("{file}: {r:?}");
        assert!((r.leg_ratio - ratio).abs() < 0.01, "{file}: leg ratio {}", r.leg_ratio);
        if same_proportions {
            assert!(r.from_ours_max_m < 0.03, "{file}: {} m from ours ({})", r.from_ours_max_m, r.from_ours_joint);
            assert!(r.leg_fix_max_m < 0.01, "{file}: the leg fix moved a joint {} m", r.leg_fix_max_m);
        }
        assert!(r.contact_miss_max_m < 0.01, "{file}: a planted foot is {} m off", r.contact_miss_max_m);
        assert!(
            r.from_ours_on_rig_bones_max_m < 0.03,
            "{file}: {} m from ours on the rig's bones ({})",
            r.from_ours_on_rig_bones_max_m,
            r.from_ours_on_rig_bones_joint
        );
        assert!(
            r.skate_rig <= r.skate_ours * 1.1 + 1e-9,
            "{file}: skate {} against ours {}",
            r.skate_rig,
            r.skate_ours
        );
        if same_proportions {
            assert_eq!((r.unreached_frames, r.pelvis_lowered_max_m), (0, 0.0), "{file}");
        } else {
            // Strides our legs reach are too long for the rig's: the pelvis comes down a little.
            assert!(r.pelvis_lowered_max_m > 0.0 && r.pelvis_lowered_max_m < 0.03, "{file}: {r:?}");
        }
        let back = read_back(&done, &rig);
        assert!(back < 1e-4, "{file}: read back {back} m off");
    }
}

#[test]
fn a_capture_rig_takes_the_motion_in_its_own_unit() {
    let (track, _) = walk();
    let rig = TargetRig::read(&fixture("mocap/cmu/cmu_01_01_20fps.bvh"), None).unwrap();
    assert_eq!(rig.matched, Matched::Convention(Convention::Cmu));
    let done = retarget(&track, &rig).unwrap();
    println!("{:?}", done.report);
    assert!(done.report.contact_miss_max_m < 0.01, "{:?}", done.report);
    assert!(read_back(&done, &rig) < 1e-4);
    // The rig's proportions differ from ours (a shorter torso), so its joints are not ours
    // scaled, but the arms, neck and head point as ours do (the legs bend as the feet need).
    let (_, fk) = walk();
    let mut worst = 0.0_f64;
    for (a, b) in done.poses.iter().zip(&fk) {
        for (from, to) in [
            (Joint::LeftShoulder, Joint::LeftElbow),
            (Joint::RightElbow, Joint::RightWrist),
            (Joint::Neck, Joint::Head),
        ] {
            let (ours, rig) = (b[to.index()] - b[from.index()], a[to.index()] - a[from.index()]);
            worst = worst.max(ours.angle_between(rig).to_degrees());
        }
    }
    assert!(worst < 0.5, "a bone turned {worst}° from ours");
}

#[test]
fn a_rig_that_cannot_be_matched_is_refused_naming_what_it_lacks() {
    let dir = tempfile::tempdir().unwrap();
    let text =
        std::fs::read_to_string(fixture("rigs/mixamo.bvh")).unwrap().replace("mixamorig:LeftToeBase", "mixamorig:Toe");
    let path = dir.path().join("toeless.bvh");
    std::fs::write(&path, text).unwrap();
    let err = TargetRig::read(&path, None).unwrap_err().to_string();
    assert!(err.contains("toeless.bvh") && err.contains("Mixamo, lacks LeftToeBase (left_foot)"), "{err}");
    let map = dir.path().join("map.json");
    std::fs::write(&map, "[1, 2]").unwrap();
    let err = TargetRig::read(&path, Some(&map)).unwrap_err().to_string();
    assert!(err.contains("map.json: a joint map is a JSON object"), "{err}");
    let missing = TargetRig::read(&dir.path().join("none.bvh"), None).unwrap_err().to_string();
    assert!(missing.contains("none.bvh"), "{missing}");
}

#[test]
fn the_tasks_constraints_are_judged_again_where_the_rig_stands_and_at_our_scale() {
    let text = std::fs::read_to_string(fixture("results/session35-main/program.json")).unwrap();
    let program = crate::program::TaskProgram::from_json(&text).unwrap();
    let checked = crate::constraints::checked::CheckedProgram::check(program, &candle_core::Device::Cpu).unwrap();
    let judge = RigJudge { compiled: checked.compiled(), device: checked.device(), initial: None };
    let track = main_command_motion();
    let ours = track.forward_kinematics();
    let verdicts = |file: &str| {
        let rig = TargetRig::read(&fixture("rigs").join(file), None).unwrap();
        let done = retarget(&track, &rig).unwrap();
        let judged = judge_on_rig(&judge, 0, &ours, &done.poses, done.report.leg_ratio).unwrap();
        judged.into_iter().map(|c| (c.id, [c.ours, c.on_rig, c.at_our_scale])).collect::<Vec<_>>()
    };
    // Our size: every constraint holds on the rig as on ours.
    let same = verdicts("a_pose.bvh");
    assert_eq!(same, ["c1", "c2", "c3"].map(|id| (id.to_owned(), [true; 3])), "{same:?}");
    // 1.05 times our size: the pelvis ends 5.25 m ahead, so the 5 m target holds only at our
    // scale; the gap and the standing feet hold on the rig.
    let larger = verdicts("mixamo.bvh");
    assert_eq!(larger[1], ("c2".to_owned(), [true, false, true]), "{larger:?}");
    assert_eq!((larger[0].1, larger[2].1), ([true; 3], [true; 3]), "{larger:?}");
    // The wrong frame count judges nothing.
    assert!(judge_on_rig(&judge, 0, &ours[..50], &ours[..50], 1.0).unwrap().is_empty());
}
