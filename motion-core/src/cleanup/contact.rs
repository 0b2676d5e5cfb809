//! Foot contacts from joint positions: where the floor is, and when each foot joint rests on it
//! (low and slow, with hysteresis), as HumanML3D's four contact channels label them.

use std::ops::Range;

use glam::DVec3;

use crate::skeleton::{Pose, CONTACT_JOINTS, FPS, NUM_JOINTS};

/// Fraction of frames whose lowest point lies below the floor estimate ([`floor_height`]):
/// a low percentile, so a jump's flight or a few sunken frames do not move it.
pub const FLOOR_PERCENTILE: f64 = 0.2;

/// Lowest height of the centre of a joint other than the feet above the floor, m: about a limb's
/// radius (the kneeling knees of the shipped crawl rest 3.7 cm up at the floor percentile).
pub const JOINT_CLEARANCE_M: f64 = 0.03;

/// Height of the floor under a motion, m: the [`FLOOR_PERCENTILE`] quantile over frames of the
/// frame's lowest `y_j − h_j`, where `h_j` is `standing_m` for the four [`CONTACT_JOINTS`]
/// (their heights when the foot stands on the floor) and [`JOINT_CLEARANCE_M`] for every other
/// joint. 0 for a motion resting on y = 0; the float of a motion hovering above it. `NaN`
/// coordinates are ignored; 0 for an empty motion.
pub fn floor_height(poses: &[Pose], standing_m: &[f64; 4]) -> f64 {
    let mut clearance = [JOINT_CLEARANCE_M; NUM_JOINTS];
    for (joint, h) in CONTACT_JOINTS.iter().zip(standing_m) {
        clearance[joint.index()] = *h;
    }
    let mut lowest: Vec<f64> = poses
        .iter()
        .map(|p| p.iter().zip(&clearance).map(|(v, h)| v.y - h).fold(f64::INFINITY, f64::min))
        .filter(|y| y.is_finite())
        .collect();
    if lowest.is_empty() {
        return 0.0;
    }
    lowest.sort_by(f64::total_cmp);
    lowest[((lowest.len() - 1) as f64 * FLOOR_PERCENTILE).round() as usize]
}

/// How far each frame of a motion must rise so that no joint centre lies below the floor y = 0,
/// m, spread smoothly over ±`radius` frames: each frame's depth `max(0, −min_j y_j)`, dilated
/// (the largest depth within `radius` frames), then averaged over the same window. Every window
/// holding frame t holds only values ≥ t's depth, so the lift never falls short of a frame's own
/// depth, and it rises and falls over `radius` frames instead of popping. `NaN` coordinates are
/// ignored.
pub fn sinking_lift(poses: &[Pose], radius: usize) -> Vec<f64> {
    let depth: Vec<f64> =
        poses.iter().map(|p| p.iter().map(|v| -v.y).filter(|d| d.is_finite()).fold(0.0, f64::max)).collect();
    crate::numeric::eased_envelope(&depth, radius)
}

/// Speed of a joint per frame, m/s: central differences, one-sided at the ends (0 for one frame).
pub fn speeds(track: &[DVec3]) -> Vec<f64> {
    let last = track.len().saturating_sub(1);
    (0..track.len())
        .map(|t| {
            let (a, b) = (t.saturating_sub(1), (t + 1).min(last));
            if a == b {
                0.0
            } else {
                (track[b] - track[a]).length() * FPS / (b - a) as f64
            }
        })
        .collect()
}

/// Thresholds of contact detection (see [`super::FootLockConfig`] for the defaults).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hysteresis {
    /// A joint enters contact below this height above its standing height, m ...
    pub enter_height_m: f64,
    /// ... while slower than this, m/s.
    pub enter_speed_m_per_s: f64,
    /// It stays in contact below this height, m ...
    pub leave_height_m: f64,
    /// ... while slower than this, m/s.
    pub leave_speed_m_per_s: f64,
}

/// Contact frames of one joint from its height above its standing height (m) and its speed
/// (m/s) per frame: it enters contact when both are under the entering thresholds and stays
/// while both are under the (looser) leaving ones. Half-open frame ranges, in order.
pub fn detect(clearance_m: &[f64], speed_m_per_s: &[f64], h: &Hysteresis) -> Vec<Range<usize>> {
    let mut on = false;
    let flags: Vec<bool> = clearance_m
        .iter()
        .zip(speed_m_per_s)
        .map(|(&c, &v)| {
            on = if on {
                c < h.leave_height_m && v < h.leave_speed_m_per_s
            } else {
                c < h.enter_height_m && v < h.enter_speed_m_per_s
            };
            on
        })
        .collect();
    runs(flags)
}

/// The runs of `true` in per-frame flags, as half-open frame ranges.
pub fn runs(flags: impl IntoIterator<Item = bool>) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    let mut start = None;
    let mut frames = 0;
    for (t, flag) in flags.into_iter().enumerate() {
        match (flag, start) {
            (true, None) => start = Some(t),
            (false, Some(s)) => {
                out.push(s..t);
                start = None;
            }
            _ => {}
        }
        frames = t + 1;
    }
    if let Some(s) = start {
        out.push(s..frames);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const H: Hysteresis =
        Hysteresis { enter_height_m: 0.02, enter_speed_m_per_s: 1.0, leave_height_m: 0.04, leave_speed_m_per_s: 1.5 };

    #[test]
    fn runs_are_half_open_ranges() {
        assert_eq!(runs([true, true, false, true]), vec![0..2, 3..4]);
        assert_eq!(runs([false, false]), Vec::<Range<usize>>::new());
        assert_eq!(runs(Vec::new()), Vec::<Range<usize>>::new());
    }

    #[test]
    fn contact_enters_low_and_slow_and_leaves_past_the_looser_thresholds() {
        // Frame 1 is low but fast; 2 enters; 3 stays (between the two heights); 4 leaves (fast).
        let clearance = [0.0, 0.0, 0.01, 0.03, 0.03, 0.03, 0.01];
        let speed = [2.0, 1.2, 0.5, 1.2, 1.6, 1.2, 0.2];
        assert_eq!(detect(&clearance, &speed, &H), vec![2..4, 6..7]);
    }

    #[test]
    fn a_sinking_frame_is_lifted_by_at_least_its_depth_and_the_lift_ramps() {
        // Frames 5 and 6 sink 4 and 2 cm; the rest stand on the floor.
        let mut poses = vec![[DVec3::new(0.0, 0.05, 0.0); NUM_JOINTS]; 12];
        poses[5][3].y = -0.04;
        poses[6][7].y = -0.02;
        let lift = sinking_lift(&poses, 2);
        assert!(lift[5] >= 0.04 - 1e-12 && lift[6] >= 0.02 - 1e-12, "{lift:?}");
        // The dilation reaches frames 3..=8, the average 1..=10.
        assert!(lift[..1].iter().chain(&lift[11..]).all(|&l| l == 0.0) && lift[1] > 0.0, "{lift:?}");
        // Never more than the deepest frame, and at most a window's share of it per frame.
        assert!(lift.iter().all(|&l| l <= 0.04 + 1e-12));
        assert!(lift.windows(2).all(|w| (w[1] - w[0]).abs() <= 0.04 / 5.0 * 2.0 + 1e-12), "{lift:?}");
        assert_eq!(sinking_lift(&poses[..2], 2), vec![0.0, 0.0]);
        assert!(sinking_lift(&[], 2).is_empty());
    }

    #[test]
    fn speeds_are_central_differences_in_metres_per_second() {
        let track: Vec<DVec3> = [0.0, 0.05, 0.15, 0.3].iter().map(|&z| DVec3::new(0.0, 0.0, z)).collect();
        let v = speeds(&track);
        let expected = [1.0, 1.5, 2.5, 3.0];
        for (a, b) in v.iter().zip(expected) {
            assert!((a - b).abs() < 1e-12, "{v:?}");
        }
        assert_eq!(speeds(&track[..1]), vec![0.0]);
    }

    #[test]
    fn the_floor_is_a_low_percentile_of_the_lowest_clearance() {
        let standing = [0.065, 0.02, 0.065, 0.02];
        // Every joint high up but the left toe, which is 12 cm above its standing height in
        // 8 frames of 10 and 50 cm in the other two (a short hop).
        let poses: Vec<Pose> = (0..10)
            .map(|t| {
                let mut p = [DVec3::new(0.0, 1.0, 0.0); NUM_JOINTS];
                p[crate::skeleton::Joint::LeftFoot.index()].y = if t < 2 { 0.52 } else { 0.14 };
                p
            })
            .collect();
        assert!((floor_height(&poses, &standing) - 0.12).abs() < 1e-12);
        assert_eq!(floor_height(&[], &standing), 0.0);
    }
}
