//! [`MocapClip`]: what every importer makes of a file, and [`resample`] to 20 fps.

use crate::skeleton::{Pose, FPS};

/// A motion-capture clip that can be posed at any time (seconds from its start).
pub trait MocapClip {
    /// Length of one play-through, seconds.
    fn duration_s(&self) -> f64;
    /// Whether the clip is a cycle that [`MocapClip::pose_at`] can continue past its end.
    fn is_cyclic(&self) -> bool;
    /// Joint positions at time `t_s` (metres, y up, +x the character's left). Times past the end
    /// of a cyclic clip continue the cycle; other clips hold their end poses.
    fn pose_at(&self, t_s: f64) -> Pose;
}

/// Samples a clip at 20 fps played `speed` times faster than recorded (a time warp), for
/// `seconds` of output (default: one play-through). Always at least 2 frames.
pub fn resample(clip: &dyn MocapClip, speed: f64, seconds: Option<f64>) -> Vec<Pose> {
    let out_seconds = seconds.unwrap_or(clip.duration_s() / speed);
    let frames = ((out_seconds * FPS).floor() as usize + 1).max(2);
    (0..frames).map(|k| clip.pose_at(k as f64 / FPS * speed)).collect()
}
