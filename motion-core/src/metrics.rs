//! Motion quality metrics on joint positions at 20 fps, as ProgMoGen and DNO define them
//! (`reference/anchors.md` §3.7). Inputs are `[frames]` of [`Pose`]s in metres, y up, ground at
//! y = 0.

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

/// Maximum acceleration (ProgMoGen `get_jittor_stat(order=2, "max")`): the largest norm of the
/// second time difference of any joint, in **m/frame²** (not scaled by fps²).
pub fn max_acceleration(poses: &[Pose]) -> f64 {
    poses
        .windows(3)
        .flat_map(|w| (0..NUM_JOINTS).map(move |j| (w[2][j] - 2.0 * w[1][j] + w[0][j]).length()))
        .fold(0.0, f64::max)
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

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn still(frames: usize) -> Vec<Pose> {
        vec![[DVec3::new(0.0, 0.01, 0.0); NUM_JOINTS]; frames]
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
}
