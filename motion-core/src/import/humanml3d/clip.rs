//! [`HumanMl3dClip`]: a HumanML3D clip's 263-d features posed at any time, so that a dataset
//! folder can be a source of the motion database like any mocap file.

use std::path::Path;

use candle_core::{Device, Tensor};
use glam::{DQuat, DVec3};

use super::error::invalid;
use crate::import::clip::MocapClip;
use crate::import::error::ImportError;
use crate::import::values::{in_reach, short_number, MAX_POSITION_M};
use crate::motion::retarget_bone_lengths;
use crate::representation::{recover_from_ric, FeatureFrame, FEATURE_DIM};
use crate::skeleton::{Pose, FPS, NUM_JOINTS};

/// Frames recovered at once: [`recover_from_ric`] builds `[frames, frames]` cumulative-sum
/// matrices, so a long clip is recovered in pieces of this many frames (HumanML3D's longest
/// training clip), each joined to the previous one at their shared frame.
const CHUNK_FRAMES: usize = 196;

/// A HumanML3D clip as a [`MocapClip`]: joint positions recovered from its (un-normalised)
/// features, bone lengths retargeted to the canonical skeleton ([`crate::skeleton::rest_pose`], as
/// every importer does), positions interpolated linearly between its 20 fps frames. The clip
/// starts at the origin facing +z. Not cyclic.
#[derive(Debug, Clone)]
pub struct HumanMl3dClip {
    /// Joint positions per feature frame, metres, y up.
    poses: Vec<Pose>,
}

impl HumanMl3dClip {
    /// Recovers the poses of `features` (`[frames, 263]`, at least one frame); `path` is only
    /// used in messages. Fails when a recovered joint is further than [`MAX_POSITION_M`] from
    /// the origin (absurd features), naming the frame.
    pub fn from_features(features: &[FeatureFrame], path: &Path) -> Result<Self, ImportError> {
        let recover_err = |e: candle_core::Error| invalid(path, "features", format!("cannot recover positions: {e}"));
        let mut poses: Vec<Pose> = Vec::with_capacity(features.len());
        let mut start = 0;
        while start < features.len() {
            let end = (start + CHUNK_FRAMES).min(features.len());
            let local = recover(&features[start..end]).map_err(recover_err)?;
            match poses.last() {
                // The chunk begins at the last frame recovered; its own start is at the origin
                // facing +z, so it is turned and moved onto that frame.
                Some(joined) => {
                    let (turn, shift) = yaw_fit(&local[0], joined);
                    poses.extend(local[1..].iter().map(|p| p.map(|j| turn * j + shift)));
                }
                None => poses.extend(local),
            }
            if end == features.len() {
                break;
            }
            start = end - 1;
        }
        for (frame, pose) in poses.iter().enumerate() {
            if let Some(j) = pose.iter().position(|p| !p.to_array().into_iter().all(in_reach)) {
                return Err(invalid(
                    path,
                    format!("frame {frame}, joint {j}"),
                    format!(
                        "recovered position ({}) m is out of range (more than {} m from the origin)",
                        pose[j].to_array().map(short_number).join(", "),
                        short_number(MAX_POSITION_M)
                    ),
                ));
            }
        }
        let poses = retarget_bone_lengths(&poses, &crate::skeleton::rest_bone_lengths());
        Ok(Self { poses })
    }
}

/// Joint positions of `features` (`[frames, 263]`), each frame a pose.
fn recover(features: &[FeatureFrame]) -> candle_core::Result<Vec<Pose>> {
    let flat: Vec<f32> = features.iter().flatten().copied().collect();
    let input = Tensor::from_vec(flat, (1, features.len(), FEATURE_DIM), &Device::Cpu)?;
    let positions = recover_from_ric(&input)?.flatten_all()?.to_vec1::<f32>()?;
    Ok(positions
        .chunks_exact(3 * NUM_JOINTS)
        .map(|p| std::array::from_fn(|j| DVec3::new(p[3 * j].into(), p[3 * j + 1].into(), p[3 * j + 2].into())))
        .collect())
}

/// The turn about +y and the shift that put pose `from` onto `to` (the same pose turned and
/// moved): the angle is the least-squares fit of the joints' horizontal offsets from the pelvis.
fn yaw_fit(from: &Pose, to: &Pose) -> (DQuat, DVec3) {
    let (mut sin, mut cos) = (0.0, 0.0);
    for (a, b) in from.iter().zip(to) {
        let (a, b) = (*a - from[0], *b - to[0]);
        sin += a.z * b.x - a.x * b.z;
        cos += a.x * b.x + a.z * b.z;
    }
    let turn = DQuat::from_rotation_y(sin.atan2(cos));
    (turn, to[0] - turn * from[0])
}

impl MocapClip for HumanMl3dClip {
    fn duration_s(&self) -> f64 {
        self.poses.len().saturating_sub(1) as f64 / FPS
    }

    fn is_cyclic(&self) -> bool {
        false
    }

    fn pose_at(&self, t_s: f64) -> Pose {
        let last = self.poses.len().saturating_sub(1);
        let x = (t_s * FPS).clamp(0.0, last as f64);
        let x = if x.is_nan() { 0.0 } else { x };
        let k = (x.floor() as usize).min(last);
        let (Some(p0), Some(p1)) = (self.poses.get(k), self.poses.get((k + 1).min(last))) else {
            return [DVec3::ZERO; NUM_JOINTS];
        };
        let a = x - k as f64;
        std::array::from_fn(|j| p0[j].lerp(p1[j], a))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::deepmimic::synthetic_walk;
    use crate::representation::{extract_features, RIC};

    #[test]
    fn a_long_clip_recovered_in_pieces_matches_the_motion_it_came_from() {
        // 30 s of a turning walk: three joins between pieces.
        let walk = synthetic_walk(601, 0.3);
        let extracted = extract_features(&walk).unwrap();
        let clip = HumanMl3dClip::from_features(&extracted.features, Path::new("long.npy")).unwrap();
        assert!((clip.duration_s() - 29.95).abs() < 1e-9);
        // The canonical frames are the walk turned to face +z at its start, on the floor; the
        // clip must agree with them everywhere, joins included (f32 features: millimetres).
        for k in [0, 100, 195, 196, 300, 390, 391, 599] {
            let (got, want) = (clip.pose_at(k as f64 / FPS), extracted.canonical[k]);
            let off = got.iter().zip(&want).map(|(a, b)| a.distance(*b)).fold(0.0, f64::max);
            assert!(off < 5e-3, "frame {k}: {off} m off");
        }
        assert!((clip.pose_at(0.025)[0] - clip.pose_at(0.0)[0].lerp(clip.pose_at(0.05)[0], 0.5)).length() < 1e-12);
    }

    #[test]
    fn absurd_features_are_named() {
        let mut features = extract_features(&synthetic_walk(41, 0.0)).unwrap().features;
        features[7][RIC.start] = 1e30;
        let e = HumanMl3dClip::from_features(&features, Path::new("far.npy")).unwrap_err().to_string();
        assert!(e.starts_with("far.npy: frame 7") && e.contains("out of range"), "{e}");
    }
}
