//! BVH export end to end: a motion sampled from the shipped prior is solved into joint rotations,
//! written as BVH in metres and in centimetres, and read back by the project's importer.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use candle_core::Device;
use e2e_tests::fixtures;
use motion_core::diffusion::Guidance;
use motion_core::export::bvh::{write_bvh, BvhUnit};
use motion_core::export::rotations::ANIMATED_OFFSETS;
use motion_core::export::RotationTrack;
use motion_core::import::bvh::{BvhClip, BvhOptions, LengthUnit, Rig};
use motion_core::prior::{Prior, Sampling};
use motion_core::quality::joints_of;
use motion_core::skeleton::Pose;

const FRAMES: usize = 100;

/// Largest distance between the joints of two motions, m.
fn max_distance(a: &[Pose], b: &[Pose]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).flat_map(|(p, q)| p.iter().zip(q).map(|(u, v)| u.distance(*v))).fold(0.0, f64::max)
}

#[test]
fn a_sampled_motion_comes_back_from_bvh_as_solved() {
    let prior =
        Prior::load(&fixtures().join("model/prior.safetensors"), &fixtures().join("text"), &Device::Cpu).unwrap();
    // Few DDIM steps: the test is about the file, not the motion's quality.
    let x = prior
        .sample(
            &Sampling {
                prompt: "a person walks forward",
                frames: FRAMES,
                batch: 1,
                seed: 3,
                steps: 10,
                guidance: Guidance::default(),
            },
            &Device::Cpu,
        )
        .unwrap();
    let poses = joints_of(&prior, &x).unwrap().remove(0);
    let track = RotationTrack::solve(&poses, 20.0, 0).unwrap();
    let fk = track.forward_kinematics();
    let fit = track.fit(&poses);
    let moved = (0..track.frames())
        .flat_map(|t| ANIMATED_OFFSETS.map(|j| track.offset_m(t, j).distance(track.skeleton.offsets_m[j.index()])))
        .fold(0.0, f64::max);
    println!("animated offsets move at most {:.1} mm from rest", moved * 1e3);
    let dir = tempfile::tempdir().unwrap();
    for (unit, read_as) in [(BvhUnit::Metres, LengthUnit::Metres), (BvhUnit::Centimetres, LengthUnit::Centimetres)] {
        let path = dir.path().join(format!("{unit:?}.bvh"));
        write_bvh(&path, &track.armature(), unit.into()).unwrap();
        let (clip, warnings) = BvhClip::read(&path, &BvhOptions::default()).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        assert_eq!((clip.rig(), clip.animation().unit(), clip.animation().frames()), (Rig::Smpl, read_as, FRAMES));
        assert!((clip.fps() - 20.0).abs() < 1e-9);
        let read: Vec<Pose> = (0..FRAMES).map(|k| clip.mapped_pose_at(k as f64 / 20.0)).collect();
        let (to_track, to_input) = (max_distance(&read, &fk), max_distance(&read, &poses));
        println!(
            "{unit:?}: file vs track {to_track:.1e} m, vs the sample {to_input:.1e} m (solve: mean {:.1e} m, max \
             {:.1e} m)",
            fit.mean_m, fit.max_m
        );
        assert!(to_track < 1e-4, "{unit:?}: {to_track} m from the track");
        assert!(to_input < 0.01, "{unit:?}: {to_input} m from the sample");
    }
}
