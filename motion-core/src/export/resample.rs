//! A rotation track at another frame rate: the rate a game engine or an animation package runs
//! at (24, 30, 60 fps) instead of the motion's 20.
//!
//! Frame `k` of the new track is the motion at time `k / fps` s, which lies between source
//! frames `i` and `i + 1` at fraction `a` (`k·fps_src/fps = i + a`):
//! - every joint's local rotation is the spherical interpolation of its two rotations
//!   (`slerp`: constant angular speed along the shorter arc; a frame-dropping or component-wise
//!   blend would step or shrink the turn);
//! - the root translation is interpolated linearly (the pelvis path is kept, to rounding, at
//!   every source frame);
//! - an animated offset ([`super::ANIMATED_OFFSETS`]) turns between its two directions at its
//!   fixed length, so bones stay rigid.
//!
//! The new track spans the same time as the source: it ends at the last new frame that does not
//! pass the source's last frame, `floor(D·fps)/fps` for a duration `D = (n − 1)/fps_src`, less
//! than one new frame short of `D` (exactly `D` when `D·fps` is whole: 20 → 60 fps).

use glam::DVec3;

use super::error::ExportError;
use super::rotations::{AnimatedOffsets, RotationTrack};

/// Highest frame rate a track is resampled to, frames per second (a 1,000-frame clip at 20 fps
/// becomes 12,000 frames at 240).
pub const MAX_FPS: u32 = 240;

impl RotationTrack {
    /// The track at `fps` frames per second (1 to [`MAX_FPS`]); the same track when `fps` is its
    /// own rate.
    pub fn resampled(&self, fps: u32) -> Result<RotationTrack, ExportError> {
        if !(1..=MAX_FPS).contains(&fps) {
            return Err(ExportError::Shape(format!("frame rate {fps} fps is outside 1 to {MAX_FPS}")));
        }
        let target = f64::from(fps);
        if (target - self.fps).abs() < 1e-12 || self.frames() < 2 {
            return Ok(RotationTrack { fps: target, ..self.clone() });
        }
        let last = self.frames() - 1;
        let duration_s = last as f64 / self.fps;
        // The small allowance keeps a whole number of new frames whole despite rounding.
        let frames = (duration_s * target + 1e-9).floor() as usize + 1;
        let mut out = RotationTrack {
            skeleton: self.skeleton,
            root_m: Vec::with_capacity(frames),
            local: Vec::with_capacity(frames),
            animated_offsets_m: Vec::with_capacity(frames),
            fps: target,
        };
        for k in 0..frames {
            let at = (k as f64 * self.fps / target).min(last as f64);
            let i = (at.floor() as usize).min(last - 1);
            let a = at - i as f64;
            out.root_m.push(self.root_m[i].lerp(self.root_m[i + 1], a));
            out.local.push(std::array::from_fn(|j| self.local[i][j].slerp(self.local[i + 1][j], a).normalize()));
            let (from, to) = (&self.animated_offsets_m[i], &self.animated_offsets_m[i + 1]);
            let offsets: AnimatedOffsets = std::array::from_fn(|s| turn_between(from[s], to[s], a));
            out.animated_offsets_m.push(offsets);
        }
        Ok(out)
    }
}

/// The offset a fraction `a` of the way from `from` to `to`, at `from`'s length (the two have
/// one length: the bone's).
fn turn_between(from: DVec3, to: DVec3, a: f64) -> DVec3 {
    let direction = from.lerp(to, a).normalize_or_zero();
    if direction == DVec3::ZERO {
        return from;
    }
    direction * from.length()
}

#[cfg(test)]
mod tests {
    use glam::DQuat;

    use super::*;
    use crate::skeleton::{rest_pose, Joint, Pose, NUM_JOINTS};

    /// `frames` frames at 20 fps: the figure walks along +z at 1.2 m/s, the pelvis bobs, the left
    /// leg swings at a constant 1.5 rad/s and the whole body turns at 0.8 rad/s about y.
    fn track(frames: usize) -> RotationTrack {
        let poses: Vec<Pose> = (0..frames)
            .map(|t| {
                let time = t as f64 / 20.0;
                let turn = DQuat::from_rotation_y(0.8 * time);
                let rest = rest_pose();
                let mut pose = rest;
                for j in Joint::ALL {
                    pose[j.index()] = turn * (rest[j.index()] - rest[0]);
                }
                let hip = Joint::LeftHip.index();
                let bend = DQuat::from_rotation_x(1.5 * time);
                for j in [Joint::LeftKnee, Joint::LeftAnkle, Joint::LeftFoot] {
                    pose[j.index()] = pose[hip] + turn * bend * turn.inverse() * (pose[j.index()] - pose[hip]);
                }
                let root = DVec3::new(0.0, 0.9 + 0.02 * (6.0 * time).sin(), 1.2 * time);
                pose.map(|p| p + root)
            })
            .collect();
        RotationTrack::solve(&poses, 20.0, 0).unwrap()
    }

    fn bone_lengths(pose: &Pose) -> Vec<f64> {
        Joint::ALL
            .into_iter()
            .skip(1)
            .map(|j| pose[j.index()].distance(pose[j.parent().map_or(0, Joint::index)]))
            .collect()
    }

    #[test]
    fn at_three_times_the_rate_every_third_frame_is_a_source_frame_and_the_duration_is_kept() {
        let source = track(21);
        let fast = source.resampled(60).unwrap();
        assert_eq!((fast.fps, fast.frames()), (60.0, 61));
        let (a, b) = (source.forward_kinematics(), fast.forward_kinematics());
        for (t, pose) in a.iter().enumerate() {
            for j in 0..NUM_JOINTS {
                assert!(pose[j].distance(b[3 * t][j]) < 1e-9, "frame {t}, joint {j}");
            }
        }
        let rest = bone_lengths(&b[0]);
        for pose in &b {
            for (l, r) in bone_lengths(pose).iter().zip(&rest) {
                assert!((l - r).abs() < 1e-9, "bones stay rigid: {l} against {r}");
            }
        }
    }

    #[test]
    fn between_source_frames_rotations_turn_at_constant_speed_and_the_root_follows_its_path() {
        let source = track(21);
        let thirty = source.resampled(30).unwrap();
        // 1 s at 30 fps: frames 0..=30, the last at the source's last frame.
        assert_eq!(thirty.frames(), 31);
        let knee = Joint::LeftKnee.index();
        for k in 0..thirty.frames() {
            let time = k as f64 / 30.0;
            // The body turns at 0.8 rad/s about y: the pelvis has turned 0.8·t from its start.
            let turned = source.local[0][0].angle_between(thirty.local[k][0]);
            assert!((turned - 0.8 * time).abs() < 1e-6, "frame {k}: turned {turned} rad");
            let z = thirty.root_m[k].z;
            assert!((z - 1.2 * time).abs() < 1e-9, "frame {k}: root at z = {z} m");
        }
        // Every new frame's knee rotation lies on the arc between its two source frames.
        for k in 0..thirty.frames() {
            let at = k as f64 * 20.0 / 30.0;
            let i = (at.floor() as usize).min(19);
            let (from, to, now) = (source.local[i][knee], source.local[i + 1][knee], thirty.local[k][knee]);
            let whole = from.angle_between(to);
            assert!((from.angle_between(now) + now.angle_between(to) - whole).abs() < 1e-6, "frame {k}");
        }
    }

    #[test]
    fn a_rate_that_does_not_divide_the_duration_ends_less_than_one_frame_short() {
        // 20 frames: 0.95 s, 22.8 frames of 24 fps.
        let source = track(20);
        let film = source.resampled(24).unwrap();
        let end = (film.frames() - 1) as f64 / 24.0;
        assert!(end <= 0.95 && end > 0.95 - 1.0 / 24.0, "ends at {end} s");
        assert_eq!(source.resampled(20).unwrap(), source, "its own rate: the same track");
    }

    #[test]
    fn a_rate_out_of_range_is_named() {
        let source = track(21);
        for bad in [0, MAX_FPS + 1] {
            let error = source.resampled(bad).unwrap_err().to_string();
            assert!(error.contains(&format!("{bad} fps")), "{error}");
        }
    }
}
