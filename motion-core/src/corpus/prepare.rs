//! Making a screened stretch of capture look like every other motion of the corpus: re-targeted
//! to the project's one rest skeleton (HumanML3D's `uniform_skeleton`: bone directions kept,
//! lengths replaced), the floor put under the stance feet, and the start canonicalised (frame
//! 0's pelvis at x = z = 0, facing +z).

use glam::DVec3;

use crate::motion::{retarget_bone_lengths, rotate_heading};
use crate::representation::facing_direction;
use crate::skeleton::rest_bone_lengths;
use crate::skeleton::{Joint, Pose, FPS};

/// Height of the lower toe joint above the floor while it bears weight, m: the median stance
/// toe height of the shipped DeepMimic walks (1.5–2 cm; the toe joint sits above the sole).
pub const STANCE_TOE_HEIGHT_M: f64 = 0.015;

/// A toe moving horizontally slower than this is taken to bear weight, m/s.
const STANCE_SPEED_M_PER_S: f64 = 0.3;

/// Fewest stance frames for the stance floor; with fewer, the floor is the 5th percentile of
/// the lowest joint.
const MIN_STANCE_FRAMES: usize = 10;

/// Re-targets, floors and canonicalises a stretch of capture (≥ 2 frames, finite).
pub fn prepare(poses: &[Pose]) -> Vec<Pose> {
    let retargeted = retarget_bone_lengths(poses, &rest_bone_lengths());
    let floored = put_on_floor(&retargeted);
    canonical_start(&floored)
}

/// Height of the floor under a motion, m: the median height of the lower toe over the frames in
/// which it stands (moves horizontally under 0.3 m/s), less [`STANCE_TOE_HEIGHT_M`]; for a
/// motion that never stands, the 5th percentile of the lowest joint per frame.
pub fn stance_floor(poses: &[Pose]) -> f64 {
    let toes = [Joint::LeftFoot.index(), Joint::RightFoot.index()];
    let mut stance: Vec<f64> = (0..poses.len())
        .filter_map(|t| {
            let (a, b) = (t.saturating_sub(1), (t + 1).min(poses.len() - 1));
            let lower = if poses[t][toes[0]].y <= poses[t][toes[1]].y { toes[0] } else { toes[1] };
            let step = poses[b][lower] - poses[a][lower];
            let speed = DVec3::new(step.x, 0.0, step.z).length() * FPS / (b - a).max(1) as f64;
            (speed < STANCE_SPEED_M_PER_S).then_some(poses[t][lower].y)
        })
        .collect();
    if stance.len() >= MIN_STANCE_FRAMES {
        stance.sort_by(f64::total_cmp);
        return stance[stance.len() / 2] - STANCE_TOE_HEIGHT_M;
    }
    let mut lowest: Vec<f64> = poses.iter().map(|p| p.iter().map(|v| v.y).fold(f64::INFINITY, f64::min)).collect();
    lowest.sort_by(f64::total_cmp);
    lowest.get(lowest.len() / 20).copied().unwrap_or(0.0)
}

/// The motion moved up or down so that [`stance_floor`] is at y = 0.
pub fn put_on_floor(poses: &[Pose]) -> Vec<Pose> {
    let floor = stance_floor(poses);
    poses.iter().map(|p| p.map(|v| v - DVec3::new(0.0, floor, 0.0))).collect()
}

/// The motion moved so frame 0's pelvis is at x = z = 0 and turned about y so frame 0 faces +z
/// (heights unchanged). A first frame with no facing direction is left unturned.
pub fn canonical_start(poses: &[Pose]) -> Vec<Pose> {
    let Some(first) = poses.first() else { return Vec::new() };
    let origin = DVec3::new(first[0].x, 0.0, first[0].z);
    let moved: Vec<Pose> = poses.iter().map(|p| p.map(|v| v - origin)).collect();
    match facing_direction(first) {
        Some(f) => rotate_heading(&moved, -f.x.atan2(f.z)),
        None => moved,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::test_support::walking_poses;
    use crate::skeleton::bone_lengths;

    #[test]
    fn a_raised_turned_walk_comes_back_to_the_floor_facing_z() {
        let walk = walking_poses(80, 0.0);
        let floor = stance_floor(&walk);
        let moved: Vec<Pose> =
            rotate_heading(&walk, 1.0).iter().map(|p| p.map(|v| v + DVec3::new(3.0, 0.25, -2.0))).collect();
        let out = prepare(&moved);
        assert!((stance_floor(&out)).abs() < 1e-9);
        assert!((stance_floor(&moved) - floor - 0.25).abs() < 1e-9);
        assert!(out[0][0].x.abs() < 1e-9 && out[0][0].z.abs() < 1e-9);
        let f = facing_direction(&out[0]).unwrap();
        assert!((f - DVec3::Z).length() < 1e-9, "{f}");
        let lengths = bone_lengths(&out[40]);
        let rest = rest_bone_lengths();
        assert!(lengths.iter().zip(rest).all(|(a, b)| (a - b).abs() < 1e-9));
    }
}
