//! Isaac Lab AMP humanoid motions (`humanoid_{dance,run,walk}.npz` of the `isaaclab` 3.0.0
//! wheel, `isaaclab_tasks/contrib/humanoid_amp/motions/`), posed on the 22 joints.
//!
//! The character is the DeepMimic humanoid (same bodies, offsets and rest frames; the recorded
//! body positions agree with its forward kinematics to 3e-7 m), so the mapping is
//! `deepmimic::smpl22_from_world`. A file is a NumPy archive with, among others,
//! `fps` (int64), `body_positions` `[frames, 15, 3]` (m) and `body_rotations` `[frames, 15, 4]`
//! (world rotations, w x y z). Its world has **z up**, the character facing +x and +y on its
//! left; DeepMimic's has y up and +z on the right, so a vector maps as (x, y, z) → (x, z, −y)
//! (a right-handed rotation of −90° about x; nothing is mirrored) and a rotation `q` as
//! `c q c⁻¹` with `c` that rotation.
//!
//! `body_names` is a unicode array that `candle_core::npy` cannot read, so the body order is
//! fixed here ([`BODY_NAMES`]; `fixtures/mocap/isaaclab/extract.sh` checks it against each file)
//! and checked on import: every body must sit where the skeleton puts it.
//!
//! The files put the lowest *ankle* of the clip at z = 0, which sinks the soles (5 cm below the
//! ankle) into the floor, and the retargeted root height wanders: with one lift for the whole
//! clip the lowest sole point of each frame still ranged over −5.8…+3.8 cm in the walk. The
//! import therefore puts the ground under every frame (`ground_level`): in the frames where
//! the lowest sole point stands still (slower than [`STANCE_SPEED_M_PER_S`] horizontally: a
//! foot in stance) it is brought to y = 0; between such frames (a run's flight) the correction
//! is interpolated, so the flight stays in the air.

use std::f64::consts::FRAC_PI_2;
use std::path::Path;

use candle_core::Tensor;
use glam::{DQuat, DVec3};

use super::clip::MocapClip;
use super::deepmimic::{self, DM_JOINTS};
use super::error::{ImportError, ImportWarning};
use super::values::{check_clip_length, in_reach, short_number, MAX_POSITION_M};
use crate::files::FileError;
use crate::limits::MOCAP_FILE_BYTES;
use crate::skeleton::Pose;

/// The 15 bodies of a file, in file order (`body_names` of all three motions).
pub const BODY_NAMES: [&str; DM_JOINTS] = [
    "pelvis",
    "torso",
    "head",
    "right_upper_arm",
    "right_lower_arm",
    "right_hand",
    "left_upper_arm",
    "left_lower_arm",
    "left_hand",
    "right_thigh",
    "right_shin",
    "right_foot",
    "left_thigh",
    "left_shin",
    "left_foot",
];

/// For each DeepMimic joint (skeleton order: root, chest, neck, right hip, knee, ankle,
/// shoulder, elbow, wrist, then the left side), the file body whose frame is that joint's.
const BODY_OF_DM_JOINT: [usize; DM_JOINTS] = [0, 1, 2, 9, 10, 11, 3, 4, 5, 12, 13, 14, 6, 7, 8];
/// DeepMimic ankle joints (right, left) in skeleton order.
const DM_ANKLES: [usize; 2] = [5, 11];
/// Bottom corners of the humanoid's foot box in the ankle frame (DeepMimic axes: x forward,
/// y up, z right), m (`reference/data.md` §3).
const SOLE_CORNERS: [[f64; 3]; 4] =
    [[-0.0435, -0.05, -0.045], [-0.0435, -0.05, 0.045], [0.1335, -0.05, -0.045], [0.1335, -0.05, 0.045]];
/// Largest accepted distance between a recorded body position and the skeleton's, m (the
/// shipped files agree to 3e-7 m; a wrong body order is off by decimetres).
const BODY_TOLERANCE_M: f64 = 0.01;
/// Quaternions whose norm is further than this from 1 are reported when normalised.
const QUAT_NORM_TOLERANCE: f64 = 1e-3;

/// An Isaac Lab AMP motion, kept as the DeepMimic skeleton's root position and world joint
/// rotations per frame (DeepMimic world, floor lifted), interpolated in time. Not cyclic.
#[derive(Debug, Clone)]
pub struct IsaacAmpClip {
    fps: f64,
    /// Root (pelvis) position per frame, DeepMimic world, m.
    roots: Vec<DVec3>,
    /// World rotation of every DeepMimic joint per frame.
    rotations: Vec<[DQuat; DM_JOINTS]>,
}

impl IsaacAmpClip {
    /// Reads a motion file.
    pub fn read(path: &Path) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        // Opened first so that a missing or unreadable file is an I/O error with its OS reason,
        // not an npz message.
        let file = std::fs::File::open(path).map_err(|e| FileError::io(path, &e))?;
        let bytes = file.metadata().map_err(|e| FileError::io(path, &e))?.len();
        MOCAP_FILE_BYTES.check(bytes, path.display())?;
        let npz = |e: candle_core::Error| ImportError::Invalid {
            path: path.into(),
            location: "npz archive".into(),
            message: e.to_string(),
        };
        let arrays = Tensor::read_npz_by_name(path, &["fps", "body_positions", "body_rotations"]).map_err(npz)?;
        let [fps, positions, rotations] = arrays.as_slice() else {
            return Err(npz(candle_core::Error::Msg("expected 3 arrays".into())));
        };
        let array = |name: &str, t: &Tensor, width: usize| -> Result<(usize, Vec<f32>), ImportError> {
            let bad = |message: String| ImportError::Invalid { path: path.into(), location: name.into(), message };
            match t.dims() {
                [n, b, w] if *b == DM_JOINTS && *w == width => {
                    let values = t.flatten_all().and_then(|v| v.to_vec1::<f32>()).map_err(|e| bad(e.to_string()))?;
                    Ok((*n, values))
                }
                dims => Err(bad(format!("expected shape [frames, {DM_JOINTS}, {width}] of float32, found {dims:?}"))),
            }
        };
        let (frames, positions) = array("body_positions", positions, 3)?;
        let (frames_r, rotations) = array("body_rotations", rotations, 4)?;
        if frames_r != frames {
            return Err(ImportError::Invalid {
                path: path.into(),
                location: "body_rotations".into(),
                message: format!("{frames_r} frames but body_positions has {frames}"),
            });
        }
        let fps = fps.to_scalar::<i64>().map_err(|e| ImportError::Invalid {
            path: path.into(),
            location: "fps".into(),
            message: e.to_string(),
        })?;
        Self::from_arrays(fps, &positions, &rotations, path)
    }

    /// Builds a clip from the flattened `body_positions` (`[frames × 15 × 3]`, z up, m) and
    /// `body_rotations` (`[frames × 15 × 4]`, w x y z) arrays; `path` is only used in messages.
    pub fn from_arrays(
        fps: i64,
        positions: &[f32],
        rotations: &[f32],
        path: &Path,
    ) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let invalid = |location: String, message: String| ImportError::Invalid { path: path.into(), location, message };
        if !(1..=10_000).contains(&fps) {
            return Err(invalid("fps".into(), format!("{fps} is not a frame rate")));
        }
        let frames = positions.len() / (3 * DM_JOINTS);
        if frames == 0 {
            return Err(ImportError::Empty { path: path.into() });
        }
        if frames < 2 || positions.len() != frames * 3 * DM_JOINTS || rotations.len() != frames * 4 * DM_JOINTS {
            return Err(invalid(
                "body_positions".into(),
                format!(
                    "{} position and {} rotation values do not make 2 or more frames",
                    positions.len(),
                    rotations.len()
                ),
            ));
        }
        check_clip_length(
            (frames - 1) as f64 / fps as f64,
            format_args!("{}: body_positions: {frames} frames at {fps} fps", path.display()),
        )?;
        let z_up_to_y_up = DQuat::from_rotation_x(-FRAC_PI_2);
        let mut roots = Vec::with_capacity(frames);
        let mut all_rotations = Vec::with_capacity(frames);
        let mut off_norm = 0usize;
        for f in 0..frames {
            let position = |b: usize| {
                let v = &positions[(f * DM_JOINTS + b) * 3..][..3];
                z_up_to_y_up * DVec3::new(v[0].into(), v[1].into(), v[2].into())
            };
            let mut world = [DQuat::IDENTITY; DM_JOINTS];
            for (j, &b) in BODY_OF_DM_JOINT.iter().enumerate() {
                let v = &rotations[(f * DM_JOINTS + b) * 4..][..4];
                let q = DQuat::from_xyzw(v[1].into(), v[2].into(), v[3].into(), v[0].into());
                let norm = q.length();
                if !norm.is_finite() || norm < 1e-6 {
                    return Err(invalid(format!("frame {f}, body {}", BODY_NAMES[b]), format!("bad quaternion {v:?}")));
                }
                if (norm - 1.0).abs() > QUAT_NORM_TOLERANCE {
                    off_norm += 1;
                }
                world[j] = z_up_to_y_up * (q / norm) * z_up_to_y_up.inverse();
            }
            let root = position(BODY_OF_DM_JOINT[0]);
            if !root.to_array().into_iter().all(in_reach) {
                return Err(invalid(
                    format!("frame {f}, body {}", BODY_NAMES[BODY_OF_DM_JOINT[0]]),
                    format!(
                        "position ({}) m is out of range (more than {} m from the origin)",
                        root.to_array().map(short_number).join(", "),
                        short_number(MAX_POSITION_M)
                    ),
                ));
            }
            for (j, p) in deepmimic::joint_positions(root, &world).iter().enumerate() {
                let b = BODY_OF_DM_JOINT[j];
                let off = p.distance(position(b));
                if off.is_nan() || off > BODY_TOLERANCE_M {
                    return Err(invalid(
                        format!("frame {f}, body {}", BODY_NAMES[b]),
                        format!(
                            "{off:.3} m from where the humanoid's skeleton puts it (not the AMP humanoid, or bodies \
                             not in the order {})",
                            BODY_NAMES.join(", ")
                        ),
                    ));
                }
            }
            roots.push(root);
            all_rotations.push(world);
        }
        let mut warnings = Vec::new();
        if off_norm > 0 {
            warnings.push(ImportWarning {
                path: path.into(),
                message: format!("normalised {off_norm} non-unit body rotations"),
            });
        }
        let mut clip = Self { fps: fps as f64, roots, rotations: all_rotations };
        let ground = ground_level(&clip.lowest_soles(), clip.fps);
        for (r, ground) in clip.roots.iter_mut().zip(ground) {
            r.y -= ground;
        }
        Ok((clip, warnings))
    }

    /// Frames per second of the file.
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// Lowest point of either foot box's sole per frame (DeepMimic world, m).
    fn lowest_soles(&self) -> Vec<DVec3> {
        self.roots
            .iter()
            .zip(&self.rotations)
            .map(|(root, world)| {
                let pos = deepmimic::joint_positions(*root, world);
                DM_ANKLES
                    .iter()
                    .flat_map(|&a| SOLE_CORNERS.iter().map(move |c| pos[a] + world[a] * DVec3::from_array(*c)))
                    .fold(DVec3::INFINITY, |low, p| if p.y < low.y { p } else { low })
            })
            .collect()
    }
}

impl MocapClip for IsaacAmpClip {
    fn duration_s(&self) -> f64 {
        (self.roots.len() - 1) as f64 / self.fps
    }

    fn is_cyclic(&self) -> bool {
        false
    }

    fn pose_at(&self, t_s: f64) -> Pose {
        let last = self.roots.len() - 1;
        let x = (t_s * self.fps).clamp(0.0, last as f64);
        let k = (x.floor() as usize).min(last - 1);
        let a = x - k as f64;
        let root = self.roots[k].lerp(self.roots[k + 1], a);
        let (r0, r1) = (&self.rotations[k], &self.rotations[k + 1]);
        let world = std::array::from_fn(|j| r0[j].slerp(r1[j], a));
        deepmimic::smpl22_from_world(root, &world)
    }
}

/// A lowest sole point moving slower than this horizontally is a foot in stance, m/s (a
/// walking foot swings at 1–4 m/s).
pub const STANCE_SPEED_M_PER_S: f64 = 0.3;

/// Height of the ground under each frame, m, from the lowest sole point of each frame
/// (`soles`, DeepMimic world) at `fps`: that point's height in stance frames (the point moves
/// slower than [`STANCE_SPEED_M_PER_S`] horizontally, central differences), linearly
/// interpolated between stance frames and held before the first and after the last. A clip
/// without a stance frame keeps one level, its median lowest sole point.
fn ground_level(soles: &[DVec3], fps: f64) -> Vec<f64> {
    let n = soles.len();
    let stance: Vec<usize> = (0..n)
        .filter(|&t| {
            let (a, b) = (t.saturating_sub(1), (t + 1).min(n - 1));
            let step = (soles[b] - soles[a]) * DVec3::new(1.0, 0.0, 1.0);
            b > a && step.length() * fps / (b - a) as f64 <= STANCE_SPEED_M_PER_S
        })
        .collect();
    let (Some(&first), Some(&last)) = (stance.first(), stance.last()) else {
        let mut heights: Vec<f64> = soles.iter().map(|p| p.y).collect();
        heights.sort_by(f64::total_cmp);
        return vec![heights.get(n / 2).copied().unwrap_or(0.0); n];
    };
    let mut ground = vec![0.0; n];
    ground[..=first].fill(soles[first].y);
    ground[last..].fill(soles[last].y);
    for pair in stance.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        for (t, g) in ground.iter_mut().enumerate().take(b + 1).skip(a) {
            let w = (t - a) as f64 / (b - a) as f64;
            *g = soles[a].y * (1.0 - w) + soles[b].y * w;
        }
    }
    ground
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::resample;
    use crate::metrics::pace;
    use crate::motion::bone_length_spread;
    use crate::skeleton::{bone_lengths, Joint};

    const CLIPS: [&str; 3] = ["humanoid_walk", "humanoid_run", "humanoid_dance"];

    fn fixture(name: &str) -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/isaaclab").join(format!("{name}.npz"))
    }

    fn clip(name: &str) -> IsaacAmpClip {
        match IsaacAmpClip::read(&fixture(name)) {
            Ok((c, w)) => {
                assert!(w.is_empty(), "{name}: {w:?}");
                c
            }
            Err(e) => panic!("{e}"),
        }
    }

    fn at(p: &Pose, j: Joint) -> DVec3 {
        p[j.index()]
    }

    #[test]
    fn files_have_60_fps_and_their_documented_lengths() {
        for (name, frames) in CLIPS.into_iter().zip([154, 82, 902]) {
            let c = clip(name);
            assert_eq!((c.fps(), c.roots.len()), (60.0, frames), "{name}");
            assert!((c.duration_s() - (frames - 1) as f64 / 60.0).abs() < 1e-12);
        }
    }

    #[test]
    fn bones_keep_the_canonical_lengths_and_stance_soles_touch_the_floor() {
        let canonical = crate::skeleton::rest_bone_lengths();
        // (clip, least share of frames whose lowest sole point is within 1.5 cm of the floor):
        // the run is in flight for about half of its frames.
        for (name, grounded) in [("humanoid_walk", 0.95), ("humanoid_run", 0.45), ("humanoid_dance", 0.9)] {
            let c = clip(name);
            let poses = resample(&c, 1.0, None);
            assert!(bone_length_spread(&poses) < 1e-9, "{name}");
            for (len, want) in bone_lengths(&poses[0]).iter().zip(canonical) {
                assert!((len - want).abs() < 1e-9, "{name}");
            }
            // The ground is put under every frame: a sole point never sinks more than 2.5 cm
            // (one frame of a foot rolling in stance), and the lowest one rests on the floor
            // in most frames.
            let soles: Vec<f64> = c.lowest_soles().iter().map(|p| p.y).collect();
            let (lo, hi) = soles.iter().fold((f64::MAX, f64::MIN), |(lo, hi), s| (lo.min(*s), hi.max(*s)));
            let near = soles.iter().filter(|s| s.abs() < 0.015).count() as f64 / soles.len() as f64;
            println!(
                "{name}: lowest sole per frame {lo:.3}..{hi:.3} m, within 1.5 cm of the floor in {:.0} %",
                100.0 * near
            );
            assert!(lo > -0.025 && hi < 0.12 && near > grounded, "{name}: soles {lo}..{hi}, {near}");
            let toes = poses.iter().map(|p| at(p, Joint::LeftFoot).y.min(at(p, Joint::RightFoot).y));
            let lowest_toe = toes.fold(f64::MAX, f64::min);
            assert!((-0.01..0.03).contains(&lowest_toe), "{name}: lowest toe {lowest_toe}");
        }
    }

    #[test]
    fn walk_and_run_go_forward_along_z_with_the_left_side_at_plus_x() {
        // (clip, forward speed range m/s, least mean forward reach of the two toes m): the
        // runner is on the balls of the feet, toes pointing down.
        for (name, speed, reach) in [("humanoid_walk", (1.2, 1.8), 0.1), ("humanoid_run", (3.0, 4.0), 0.0)] {
            let c = clip(name);
            let poses = resample(&c, 1.0, None);
            let travel = at(&poses[poses.len() - 1], Joint::Pelvis) - at(&poses[0], Joint::Pelvis);
            let v = travel.z / c.duration_s();
            println!("{name}: travel {travel:.2} m, {v:.2} m/s forward");
            assert!(v > speed.0 && v < speed.1 && travel.x.abs() < 0.3 * travel.z, "{name}: {travel}");
            for p in &poses {
                for (l, r) in [(Joint::LeftHip, Joint::RightHip), (Joint::LeftShoulder, Joint::RightShoulder)] {
                    assert!(at(p, l).x > at(p, r).x + 0.1, "{name}: {l} not on the left");
                }
            }
            // Toes point forward on average and never clearly backwards (the run's swing foot
            // kicks up behind, 1.4 cm back at worst).
            let toes: Vec<f64> = poses
                .iter()
                .map(|p| {
                    (at(p, Joint::LeftFoot) - at(p, Joint::LeftAnkle) + at(p, Joint::RightFoot)
                        - at(p, Joint::RightAnkle))
                    .z
                })
                .collect();
            let lowest = toes.iter().copied().fold(f64::MAX, f64::min);
            let mean = crate::numeric::mean(toes.iter().copied());
            println!("{name}: toes reach {mean:.3} m forward on average, {lowest:.3} m at least");
            assert!(lowest > -0.03 && mean > reach, "{name}: toes reach {mean} m, {lowest} m at least");
        }
    }

    #[test]
    fn the_walk_alternates_legs_at_a_walking_pace() {
        let poses = resample(&clip("humanoid_walk"), 1.0, None);
        let (rate, spread) = pace(&poses);
        println!("walk: {rate:.2} steps/s, interval spread {spread:?}");
        assert!((1.2..2.2).contains(&rate), "{rate} steps/s");
        // The foot that leads is the one further forward on its own side.
        let lead_left = poses.iter().filter(|p| at(p, Joint::LeftFoot).z > at(p, Joint::RightFoot).z + 0.1);
        assert!(lead_left.clone().count() > 5);
        for p in lead_left {
            assert!(at(p, Joint::LeftFoot).x > at(p, Joint::RightFoot).x);
        }
    }

    #[test]
    fn matches_the_recorded_body_positions_between_frames_too() {
        // Half-way between two frames the pose is between the two recorded poses.
        let c = clip("humanoid_walk");
        let (a, b, mid) = (c.pose_at(0.5), c.pose_at(0.5 + 1.0 / 60.0), c.pose_at(0.5 + 0.5 / 60.0));
        for j in 0..a.len() {
            assert!((mid[j] - (a[j] + b[j]) / 2.0).length() < 0.01);
        }
    }

    #[test]
    fn truncated_garbled_and_misordered_files_give_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let bytes = std::fs::read(fixture("humanoid_run")).unwrap();
        let truncated = dir.path().join("truncated.npz");
        std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
        let garbled = dir.path().join("garbled.npz");
        std::fs::write(&garbled, b"PK\x03\x04 not really a zip").unwrap();
        for p in [&truncated, &garbled, &dir.path().join("missing.npz")] {
            let e = IsaacAmpClip::read(p).unwrap_err().to_string();
            assert!(e.contains(&p.display().to_string()), "{e}");
        }
        let n = 3 * DM_JOINTS;
        let mut pos = vec![0f32; 2 * n];
        let mut rot = [1f32, 0.0, 0.0, 0.0].repeat(2 * DM_JOINTS);
        let e = IsaacAmpClip::from_arrays(60, &pos, &rot, Path::new("x.npz")).unwrap_err().to_string();
        assert!(e.contains("x.npz: frame 0, body torso") && e.contains("from where"), "{e}");
        pos.truncate(n);
        assert!(IsaacAmpClip::from_arrays(60, &pos, &rot, Path::new("x.npz"))
            .unwrap_err()
            .to_string()
            .contains("frames"));
        rot[4] = f32::NAN;
        assert!(IsaacAmpClip::from_arrays(0, &pos, &rot, Path::new("x.npz")).unwrap_err().to_string().contains("fps"));
    }
}
