//! Body figures of a motion: foot skate, accelerations, travel, bone lengths, ground
//! penetration and contact, raised hands, how the hands are held and the head–neck distance.

use crate::numeric::{mean, standard_deviation};
use crate::representation::facing_direction;
use crate::skeleton::{bone_lengths, Joint, Pose, FPS, NUM_JOINTS};

/// A foot is in contact when its height is below this, m (ProgMoGen / DNO).
pub const SKATE_CONTACT_HEIGHT_M: f64 = 0.05;
/// A foot in contact skates when its horizontal speed exceeds this, m/s.
pub const SKATE_SPEED_M_PER_S: f64 = 0.5;

/// Foot skate ratio (ProgMoGen `calculate_skating_ratio`, identical to DNO's): over the frame
/// pairs (t, t+1) of the left and right foot (toe-ball) joints, the fraction where some foot is
/// below 5 cm in both frames while its horizontal speed, and the zero-padded 5-frame box
/// average of that speed, both exceed 0.5 m/s. Returns 0 for fewer than 2 frames.
pub fn foot_skate_ratio(poses: &[Pose]) -> f64 {
    if poses.len() < 2 {
        return 0.0;
    }
    let pairs = poses.len() - 1;
    let mut skating = vec![false; pairs];
    for foot in [Joint::LeftFoot, Joint::RightFoot] {
        let j = foot.index();
        let speed: Vec<f64> = poses
            .windows(2)
            .map(|w| {
                let (a, b) = (w[0][j], w[1][j]);
                ((b.x - a.x).powi(2) + (b.z - a.z).powi(2)).sqrt() * FPS
            })
            .collect();
        for t in 0..pairs {
            // scipy's uniform_filter1d(size=5, mode='constant'): window t-2..=t+2, zeros outside.
            let avg = (t as i64 - 2..=t as i64 + 2)
                .filter_map(|k| usize::try_from(k).ok().and_then(|k| speed.get(k)))
                .sum::<f64>()
                / 5.0;
            let contact = poses[t][j].y < SKATE_CONTACT_HEIGHT_M && poses[t + 1][j].y < SKATE_CONTACT_HEIGHT_M;
            if contact && speed[t] > SKATE_SPEED_M_PER_S && avg > SKATE_SPEED_M_PER_S {
                skating[t] = true;
            }
        }
    }
    skating.iter().filter(|s| **s).count() as f64 / pairs as f64
}

/// Foot skate ratio of the corpus's held-out walks ([`foot_skate_ratio`];
/// `fixtures/model/report.md`, the walk family's held-out capture).
pub const CAPTURE_FOOT_SKATE: f64 = 0.121;
/// Peak joint acceleration of the same held-out walks, m/frame² ([`max_acceleration`]).
pub const CAPTURE_MAX_ACCELERATION: f64 = 0.111;
/// How far above its bar (capture's figure, or the figure of the motion a step starts from)
/// a generated motion's foot skate or peak acceleration may lie, as a fraction of the bar:
/// the optimiser's look bars and the foot clean-up's judgement of its locks share it.
pub const LOOK_SLACK: f64 = 0.10;

/// Maximum acceleration (ProgMoGen `get_jittor_stat(order=2, "max")`): the largest norm of the
/// second time difference of any joint, in **m/frame²** (not scaled by fps²).
pub fn max_acceleration(poses: &[Pose]) -> f64 {
    poses
        .windows(3)
        .flat_map(|w| (0..NUM_JOINTS).map(move |j| (w[2][j] - 2.0 * w[1][j] + w[0][j]).length()))
        .fold(0.0, f64::max)
}

/// Mean norm of the second time difference of the left and right foot joints, m/frame²:
/// how much the feet jitter (0 for fewer than 3 frames).
pub fn mean_foot_acceleration(poses: &[Pose]) -> f64 {
    let feet = [Joint::LeftFoot.index(), Joint::RightFoot.index()];
    let n = poses.len().saturating_sub(2) * feet.len();
    if n == 0 {
        return 0.0;
    }
    let total: f64 = poses.windows(3).flat_map(|w| feet.map(|j| (w[2][j] - 2.0 * w[1][j] + w[0][j]).length())).sum();
    total / n as f64
}

/// Horizontal (x–z) distance of the pelvis from the first to the last frame, m (0 when empty).
pub fn root_travel(poses: &[Pose]) -> f64 {
    match (poses.first(), poses.last()) {
        (Some(a), Some(b)) => {
            let d = b[Joint::Pelvis.index()] - a[Joint::Pelvis.index()];
            d.x.hypot(d.z)
        }
        _ => 0.0,
    }
}

/// Largest difference between any bone's longest and shortest length over the motion, m.
pub fn bone_length_range(poses: &[Pose]) -> f64 {
    let mut lo = [f64::INFINITY; NUM_JOINTS];
    let mut hi = [0f64; NUM_JOINTS];
    for p in poses {
        for (j, l) in bone_lengths(p).into_iter().enumerate() {
            lo[j] = lo[j].min(l);
            hi[j] = hi[j].max(l);
        }
    }
    (1..NUM_JOINTS).map(|j| hi[j] - lo[j]).filter(|d| d.is_finite()).fold(0.0, f64::max)
}

/// Deepest point of any joint below the ground plane y = 0, m (0 when none is below).
pub fn ground_penetration(poses: &[Pose]) -> f64 {
    poses.iter().flat_map(|p| p.iter().map(|v| -v.y)).fold(0.0, f64::max)
}

/// Fraction of frames where some foot is below the contact height (ProgMoGen's contact ratio).
pub fn foot_contact_ratio(poses: &[Pose]) -> f64 {
    if poses.is_empty() {
        return 0.0;
    }
    let on = poses
        .iter()
        .filter(|p| [Joint::LeftFoot, Joint::RightFoot].iter().any(|f| p[f.index()].y < SKATE_CONTACT_HEIGHT_M))
        .count();
    on as f64 / poses.len() as f64
}

/// Rest length of our head–neck bone, m: 0.1049 in every frame of the training database
/// (DeepMimic's humanoid scaled to 1.70 m). SMPL's is about 0.08 m.
pub const HEAD_NECK_REST_M: f64 = 0.105;

/// Head–neck bone lengths outside this open interval count as incorrect, m. ProgMoGen
/// (`main_eval_bone_length.py`) accepts SMPL's 0.08 m ± 0.025; we keep the ± 0.025 m tolerance
/// around our own rest length [`HEAD_NECK_REST_M`].
pub const HEAD_NECK_VALID_M: (f64, f64) = (HEAD_NECK_REST_M - 0.025, HEAD_NECK_REST_M + 0.025);

/// Semantic success of "raise the hands" tasks (RG-DNO Task-3): a wrist is above its shoulder
/// (y) in at least half of the frames.
pub fn hands_raised(poses: &[Pose]) -> bool {
    let raised = poses
        .iter()
        .filter(|p| {
            p[Joint::LeftWrist.index()].y > p[Joint::LeftShoulder.index()].y
                || p[Joint::RightWrist.index()].y > p[Joint::RightShoulder.index()].y
        })
        .count();
    !poses.is_empty() && 2 * raised >= poses.len()
}

/// How the hands are held over a motion, in the body's own frame (the pelvis, facing the way the
/// hips and shoulders face): what tells a carried object from swinging arms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandHold {
    /// The nearer wrist's mean distance ahead of the pelvis along the facing direction, m.
    pub ahead_m: f64,
    /// The lower wrist's mean height above the pelvis, m (negative: below it).
    pub above_pelvis_m: f64,
    /// Mean distance between the wrists, m.
    pub gap_m: f64,
    /// Standard deviation of that distance over the frames, m: near 0 when the hands hold one
    /// rigid thing.
    pub gap_spread_m: f64,
    /// The larger of the two wrists' standard deviations of their distance ahead of the pelvis,
    /// m: a walk's arm swing.
    pub swing_m: f64,
}

/// The motion's [`HandHold`], over the frames whose facing direction is defined; `None` when
/// there are none.
pub fn hand_hold(poses: &[Pose]) -> Option<HandHold> {
    let wrists = [Joint::LeftWrist, Joint::RightWrist];
    let mut ahead = [Vec::new(), Vec::new()];
    let mut above = [Vec::new(), Vec::new()];
    let mut gap = Vec::new();
    for pose in poses {
        let Some(forward) = facing_direction(pose) else { continue };
        let pelvis = pose[Joint::Pelvis.index()];
        for (k, wrist) in wrists.iter().enumerate() {
            let d = pose[wrist.index()] - pelvis;
            ahead[k].push(d.dot(forward));
            above[k].push(d.y);
        }
        gap.push((pose[Joint::LeftWrist.index()] - pose[Joint::RightWrist.index()]).length());
    }
    if gap.is_empty() {
        return None;
    }
    let lesser = |v: &[Vec<f64>; 2]| mean(&v[0]).min(mean(&v[1]));
    Some(HandHold {
        ahead_m: lesser(&ahead),
        above_pelvis_m: lesser(&above),
        gap_m: mean(&gap),
        gap_spread_m: standard_deviation(&gap),
        swing_m: standard_deviation(&ahead[0]).max(standard_deviation(&ahead[1])),
    })
}

/// Head–neck bone lengths at frames 0, L//2 and L−1 that fall outside [`HEAD_NECK_VALID_M`]
/// (ProgMoGen's bone-length check against neck stretching): `(incorrect, checked)`.
pub fn head_neck_incorrect(poses: &[Pose]) -> (usize, usize) {
    if poses.is_empty() {
        return (0, 0);
    }
    let n = poses.len();
    let (lo, hi) = HEAD_NECK_VALID_M;
    let bad = [0, n / 2, n - 1]
        .iter()
        .filter(|&&t| {
            let l = (poses[t][Joint::Head.index()] - poses[t][Joint::Neck.index()]).length();
            !(l > lo && l < hi)
        })
        .count();
    (bad, 3)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn still(frames: usize) -> Vec<Pose> {
        vec![[DVec3::new(0.0, 0.01, 0.0); NUM_JOINTS]; frames]
    }

    #[test]
    fn travel_is_the_horizontal_pelvis_displacement() {
        let mut poses = still(3);
        poses[2][Joint::Pelvis.index()] = DVec3::new(3.0, 5.0, 4.0);
        poses[1][Joint::Pelvis.index()] = DVec3::new(-9.0, 0.0, 0.0);
        assert_eq!(root_travel(&poses), 5.0);
        assert_eq!(root_travel(&[]), 0.0);
    }

    #[test]
    fn a_sliding_foot_on_the_ground_skates() {
        // Feet at 1 cm height sliding at 1 m/s: every pair skates.
        let poses: Vec<Pose> = (0..20).map(|t| [DVec3::new(0.0, 0.01, t as f64 * 0.05); NUM_JOINTS]).collect();
        assert!((foot_skate_ratio(&poses) - 1.0).abs() < 0.15, "{}", foot_skate_ratio(&poses));
        assert_eq!(foot_skate_ratio(&still(20)), 0.0);
        // The same slide 10 cm up is a swing, not a skate.
        let lifted: Vec<Pose> = poses.iter().map(|p| p.map(|v| v + DVec3::Y * 0.1)).collect();
        assert_eq!(foot_skate_ratio(&lifted), 0.0);
    }

    #[test]
    fn foot_jitter_is_the_mean_second_difference_of_the_feet() {
        assert_eq!(mean_foot_acceleration(&still(5)), 0.0);
        assert_eq!(mean_foot_acceleration(&still(2)), 0.0);
        // The left foot flips ±1 cm every frame: each second difference is 4 cm; the right
        // foot and every other joint stay still.
        let mut poses = still(6);
        for (t, p) in poses.iter_mut().enumerate() {
            p[Joint::LeftFoot.index()].x = if t % 2 == 0 { 0.01 } else { -0.01 };
            p[Joint::Head.index()].y = t as f64;
        }
        assert!((mean_foot_acceleration(&poses) - 0.02).abs() < 1e-12, "{}", mean_foot_acceleration(&poses));
    }

    #[test]
    fn acceleration_is_the_second_difference_in_metres_per_frame_squared() {
        let mut poses = still(5);
        poses[2][Joint::Head.index()].y += 0.03;
        assert!((max_acceleration(&poses) - 0.06).abs() < 1e-12);
    }

    #[test]
    fn penetration_and_contact() {
        let mut poses = still(4);
        poses[1][Joint::LeftWrist.index()].y = -0.02;
        assert!((ground_penetration(&poses) - 0.02).abs() < 1e-12);
        assert_eq!(foot_contact_ratio(&poses), 1.0);
        assert!((bone_length_range(&poses) - 0.03).abs() < 1e-12);
    }

    #[test]
    fn hands_and_neck_by_hand() {
        let poses = still(32);
        assert!(!hands_raised(&poses));
        let mut up = still(4);
        for p in &mut up[..2] {
            p[Joint::LeftWrist.index()].y = 1.0;
        }
        assert!(hands_raised(&up));
        let mut neck = still(5);
        neck[2][Joint::Head.index()].y += 0.1;
        assert_eq!(head_neck_incorrect(&neck), (2, 3), "0 m at the ends, 0.1 m in the middle");
    }
}
