//! A rotation track in place: the root's horizontal motion left out of the files, for engines
//! and animation layers that move the character themselves (root motion driven by gameplay,
//! a walk cycle on a path).
//!
//! The pelvis keeps its height and every rotation (turns, leans, the legs' swing), and stays
//! over its first position on the floor plane (x, z). Every joint keeps its place relative to
//! the pelvis, so a foot planted in the motion stays planted relative to the body: played with
//! the left-out path added back (a character moved by the engine along the same path), it is
//! the motion itself.

use super::rotations::RotationTrack;

impl RotationTrack {
    /// The track with the pelvis held over its first frame's x and z, m (y, every rotation and
    /// offset kept).
    pub fn in_place(&self) -> RotationTrack {
        let Some(first) = self.root_m.first().copied() else {
            return self.clone();
        };
        let root_m = self.root_m.iter().map(|p| glam::DVec3::new(first.x, p.y, first.z)).collect();
        RotationTrack { root_m, ..self.clone() }
    }
}

#[cfg(test)]
mod tests {
    use glam::{DQuat, DVec3};

    use crate::export::RotationTrack;
    use crate::skeleton::{rest_pose, Pose, NUM_JOINTS};

    #[test]
    fn in_place_the_pelvis_keeps_its_height_and_the_body_its_pose_with_the_path_left_out() {
        // 30 frames: walking 1.5 m/s along +z while turning and bobbing.
        let poses: Vec<Pose> = (0..30)
            .map(|t| {
                let time = t as f64 / 20.0;
                let turn = DQuat::from_rotation_y(0.5 * time);
                let root = DVec3::new(0.2 * time, 0.9 + 0.03 * (5.0 * time).sin(), 1.5 * time);
                let rest = rest_pose();
                rest.map(|p| root + turn * (p - rest[0]))
            })
            .collect();
        let track = RotationTrack::solve(&poses, 20.0, 0).unwrap();
        let held = track.in_place();
        let (moving, still) = (track.forward_kinematics(), held.forward_kinematics());
        for (t, (a, b)) in moving.iter().zip(&still).enumerate() {
            let path = a[0] - b[0];
            assert!(path.y.abs() < 1e-12, "frame {t}: the height is kept");
            assert!((b[0].x - poses[0][0].x).abs() < 1e-12 && (b[0].z - poses[0][0].z).abs() < 1e-12);
            for j in 0..NUM_JOINTS {
                assert!(
                    (a[j] - (b[j] + path)).length() < 1e-12,
                    "frame {t}, joint {j}: the path added back is the motion"
                );
            }
        }
    }
}
