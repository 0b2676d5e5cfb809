//! Foot locking: a planted foot stays where it was planted, on the floor.
//!
//! A foot is planted while its toe joint is low and slow (thresholds measured on the DeepMimic
//! walks, whose stance toes sit a few mm up and barely move). Each planted stretch of at least
//! [`FootLockConfig::min_contact_frames`] frames gets one horizontal toe position, the mean of
//! the stretch (heights are left as they are: the toe rolls as the heel lifts). Over the
//! stretch the toe is moved there, the ankle by the same offset (the foot keeps its
//! orientation), and the knee
//! and ankle are re-solved by two-bone leg IK ([`super::leg_ik::solve_leg`]) from the unchanged
//! hip; the offset fades in and out over [`FootLockConfig::blend_frames`] frames on either side.
//! Bones keep their lengths (to 0.1 mm). The pelvis is never moved, so a hip that outruns its
//! planted foot by more than the leg's reach drags the foot along (the IK takes the closest
//! reachable point): on the DeepMimic walk carried 0.1 m/s faster than its feet, 40 of 99
//! locked frames were out of reach. If the whole figure floats or sinks (the median height of
//! its lower toe off the standing height by more than [`FootLockConfig::floor_tolerance_m`]), the
//! motion is first moved vertically onto the floor.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::leg_ik::solve_leg;
use crate::metrics::{foot_skate_ratio, stance_toe_height};
use crate::skeleton::{bone_lengths, Joint, Pose, FPS, NUM_JOINTS};

/// Settings of [`foot_lock`], with the documented defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FootLockConfig {
    /// Whether the clean-up runs (default true).
    pub enabled: bool,
    /// A toe lower than this is low enough to be planted, m (default 0.05, the skate metric's
    /// contact height).
    pub contact_height_m: f64,
    /// A toe slower than this (horizontal) is slow enough to be planted, m/s (default 0.3;
    /// stance toes of the walks move under 0.1 m/s, swinging ones over 1 m/s).
    pub contact_speed_m_per_s: f64,
    /// Planted stretches shorter than this are left alone, frames (default 3).
    pub min_contact_frames: usize,
    /// Frames over which the lock fades in before and out after a stretch (default 3).
    pub blend_frames: usize,
    /// Height of a standing toe joint above the floor, m, for the floor check (default 0.005:
    /// the median lower-toe height of the training database's walks is 0.003 m).
    pub toe_height_m: f64,
    /// The figure is moved onto the floor when its median lower-toe height is off
    /// `toe_height_m` by more than this, m (default 0.02).
    pub floor_tolerance_m: f64,
}

impl Default for FootLockConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            contact_height_m: 0.05,
            contact_speed_m_per_s: 0.3,
            min_contact_frames: 3,
            blend_frames: 3,
            toe_height_m: 0.005,
            floor_tolerance_m: 0.02,
        }
    }
}

/// What the clean-up did to one motion.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct FootLockReport {
    /// Planted stretches locked (both feet).
    pub contacts: usize,
    /// Frames with a foot locked (both feet).
    pub locked_frames: usize,
    /// Locked frames whose ankle target was out of the leg's reach.
    pub unreachable_frames: usize,
    /// Vertical shift applied to the whole motion, m (0 when it stood on the floor).
    pub floor_shift_m: f64,
    /// Largest displacement of any joint, m.
    pub max_displacement_m: f64,
    /// Foot skate ratio before and after.
    pub skate_before: f64,
    /// Foot skate ratio after.
    pub skate_after: f64,
    /// Largest change of any bone length, m.
    pub max_bone_change_m: f64,
}

/// One leg's joints.
struct Leg {
    hip: usize,
    knee: usize,
    ankle: usize,
    toe: usize,
}

const LEGS: [Leg; 2] = [
    Leg {
        hip: Joint::LeftHip.index(),
        knee: Joint::LeftKnee.index(),
        ankle: Joint::LeftAnkle.index(),
        toe: Joint::LeftFoot.index(),
    },
    Leg {
        hip: Joint::RightHip.index(),
        knee: Joint::RightKnee.index(),
        ankle: Joint::RightAnkle.index(),
        toe: Joint::RightFoot.index(),
    },
];

/// The motion with its planted feet locked (see the module documentation), and what changed.
/// With `enabled` off the motion comes back unchanged.
pub fn foot_lock(poses: &[Pose], config: &FootLockConfig) -> (Vec<Pose>, FootLockReport) {
    let skate_before = foot_skate_ratio(poses);
    let mut out = poses.to_vec();
    let mut report = FootLockReport { skate_before, skate_after: skate_before, ..FootLockReport::default() };
    if !config.enabled || poses.len() < 2 {
        return (out, report);
    }
    let drift = stance_toe_height(poses) - config.toe_height_m;
    if drift.abs() > config.floor_tolerance_m {
        report.floor_shift_m = -drift;
        for pose in &mut out {
            for v in pose.iter_mut() {
                v.y -= drift;
            }
        }
    }
    let shifted = out.clone();
    for leg in &LEGS {
        let offsets = toe_offsets(&shifted, leg.toe, config, &mut report);
        for (t, offset) in offsets.into_iter().enumerate() {
            if offset.length() < 1e-9 {
                continue;
            }
            let p = &shifted[t];
            let target = p[leg.ankle] + offset;
            let (knee, ankle, reached) = solve_leg(p[leg.hip], p[leg.knee], p[leg.ankle], target);
            if !reached {
                report.unreachable_frames += 1;
            }
            out[t][leg.knee] = knee;
            out[t][leg.ankle] = ankle;
            out[t][leg.toe] = ankle + (p[leg.toe] - p[leg.ankle]);
        }
    }
    report.skate_after = foot_skate_ratio(&out);
    report.max_displacement_m = poses
        .iter()
        .zip(&out)
        .flat_map(|(a, b)| (0..NUM_JOINTS).map(move |j| (a[j] - b[j]).length()))
        .fold(0.0, f64::max);
    report.max_bone_change_m = poses
        .iter()
        .zip(&out)
        .flat_map(|(a, b)| {
            let (la, lb) = (bone_lengths(a), bone_lengths(b));
            (0..NUM_JOINTS).map(move |j| (la[j] - lb[j]).abs())
        })
        .fold(0.0, f64::max);
    (out, report)
}

/// Per frame, how far the toe must move to stay locked (zero where it is free), m.
fn toe_offsets(poses: &[Pose], toe: usize, config: &FootLockConfig, report: &mut FootLockReport) -> Vec<DVec3> {
    let n = poses.len();
    let speed = |t: usize| {
        let (a, b) = if t + 1 < n { (poses[t][toe], poses[t + 1][toe]) } else { (poses[t - 1][toe], poses[t][toe]) };
        (b - a).with_y(0.0).length() * FPS
    };
    let planted: Vec<bool> =
        (0..n).map(|t| poses[t][toe].y < config.contact_height_m && speed(t) < config.contact_speed_m_per_s).collect();
    let mut offsets = vec![DVec3::ZERO; n];
    let mut weights = vec![0.0f64; n];
    let mut t = 0;
    while t < n {
        if !planted[t] {
            t += 1;
            continue;
        }
        let start = t;
        while t < n && planted[t] {
            t += 1;
        }
        let end = t; // exclusive
        if end - start < config.min_contact_frames {
            continue;
        }
        report.contacts += 1;
        report.locked_frames += end - start;
        let lock = (start..end).map(|k| poses[k][toe]).sum::<DVec3>() / (end - start) as f64;
        let blend = config.blend_frames;
        for k in start.saturating_sub(blend)..(end + blend).min(n) {
            // Inside the stretch the toe goes to the lock; outside, the correction of the nearest
            // planted frame fades out (the swinging toe itself is not pulled to the lock).
            let (w, from) = if k < start {
                (1.0 - (start - k) as f64 / (blend + 1) as f64, start)
            } else if k >= end {
                (1.0 - (k + 1 - end) as f64 / (blend + 1) as f64, end - 1)
            } else {
                (1.0, k)
            };
            // Overlapping fades of neighbouring stretches: the stronger lock wins.
            if w > weights[k] {
                weights[k] = w;
                offsets[k] = (lock - poses[from][toe]).with_y(0.0) * w;
            }
        }
    }
    offsets
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::import::deepmimic::{rest_pose, DeepMimicClip};
    use crate::import::resample;
    use crate::metrics::{spike_frames, stance_toe_height};

    /// The rest pose on the floor with its left foot sliding forward 5 cm per frame for 10
    /// frames (a stance that skates), the hips still.
    fn sliding_stance() -> Vec<Pose> {
        let mut rest = rest_pose();
        let floor = rest[Joint::LeftFoot.index()].y.min(rest[Joint::RightFoot.index()].y) - 0.02;
        for v in rest.iter_mut() {
            v.y -= floor;
        }
        // Bend the left knee a little so the leg can reach.
        rest[Joint::LeftKnee.index()].z += 0.05;
        (0..10)
            .map(|t| {
                let mut p = rest;
                for j in [Joint::LeftAnkle, Joint::LeftFoot] {
                    p[j.index()].z += 0.05 * t as f64 - 0.2;
                }
                p
            })
            .collect()
    }

    #[test]
    fn a_sliding_stance_foot_is_held_with_rigid_bones_and_a_still_motion_is_unchanged() {
        let poses = sliding_stance();
        let (out, report) =
            foot_lock(&poses, &FootLockConfig { contact_speed_m_per_s: 1.5, ..FootLockConfig::default() });
        let toe = Joint::LeftFoot.index();
        let first = out[0][toe];
        for p in &out {
            assert!((p[toe] - first).length() < 1e-3, "the toe stays put: {:?} vs {first:?}", p[toe]);
        }
        assert!(report.max_bone_change_m < 1e-4, "{report:?}");
        for (a, b) in poses.iter().zip(&out) {
            assert_eq!(a[Joint::Pelvis.index()], b[Joint::Pelvis.index()]);
            let moved = (a[Joint::RightFoot.index()] - b[Joint::RightFoot.index()]).length();
            assert!(moved < 1e-6, "the planted right foot is not moved: {moved}");
        }
        let still = vec![poses[0]; 10];
        let (same, r) = foot_lock(&still, &FootLockConfig::default());
        assert!(same.iter().zip(&still).all(|(a, b)| (0..NUM_JOINTS).all(|j| (a[j] - b[j]).length() < 1e-9)));
        assert_eq!(r.floor_shift_m, 0.0);
        let (off, r) = foot_lock(&poses, &FootLockConfig { enabled: false, ..FootLockConfig::default() });
        assert_eq!(off, poses);
        assert_eq!(r.contacts, 0);
    }

    fn walk(name: &str) -> Vec<Pose> {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/deepmimic").join(name);
        resample(&DeepMimicClip::read(&path).unwrap().0, 1.0, Some(6.0))
    }

    #[test]
    fn real_walks_barely_change_and_a_floating_walk_is_put_on_the_floor() {
        for name in ["humanoid3d_walk.txt", "walker_0walk_forward.txt", "walker_turn_right0.txt"] {
            let poses = walk(name);
            let (out, r) = foot_lock(&poses, &FootLockConfig::default());
            assert!(r.max_displacement_m < 0.05, "{name}: {r:?}");
            assert!(r.max_bone_change_m < 1e-4 && r.skate_after <= r.skate_before + 1e-9, "{name}: {r:?}");
            assert_eq!(spike_frames(&out), 0, "{name}");
        }
        let poses = walk("walker_0walk_forward.txt");
        // The walk floating 10 cm above the floor is put back on it.
        let floating: Vec<Pose> = poses.iter().map(|p| p.map(|v| v + DVec3::Y * 0.1)).collect();
        let (out, r) = foot_lock(&floating, &FootLockConfig::default());
        assert!(r.floor_shift_m < -0.09, "{r:?}");
        assert!((stance_toe_height(&out) - 0.005).abs() < 0.005, "{}", stance_toe_height(&out));
        assert!(r.max_bone_change_m < 1e-4);
    }
}
