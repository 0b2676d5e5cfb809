//! DeepMimic humanoid clips (the 20 `humanoid3d_*.txt` / `walker/*.txt` files of the pybullet
//! wheel): parsing, forward kinematics, mapping to the 22 joints, and cycle looping.
//!
//! Clip layout (`reference/data.md` §2): JSON `{"Loop": "wrap"|"none", "Frames": [[44 floats]]}`;
//! per frame the keyframe duration (s), root position (m), root rotation (w,x,y,z) and the
//! local rotations of chest, neck, hips, knees (angle about local +z), ankles, shoulders and
//! elbows (angle). The DeepMimic world has y up, the character facing +x and +z on its right;
//! we map it to ours with x = −z_dm, y = y_dm, z = x_dm.

mod file;

use std::path::Path;

use file::{ClipFile, FRAME_WIDTH};
use glam::{DQuat, DVec3};

use super::clip::MocapClip;
use super::error::{ImportError, ImportWarning};
use super::values::{check_clip_length, in_reach, short_number, MAX_POSITION_M};
use crate::files::read_text;
use crate::limits::MOCAP_FILE_BYTES;

use crate::skeleton::{smoothstep, Pose, NUM_JOINTS};

/// DeepMimic joints.
pub(crate) const DM_JOINTS: usize = 15;

/// DeepMimic joint: name, parent, offset from the parent joint in the parent's frame (m), and
/// where its rotation lives in a frame (start, 4 for a quaternion or 1 for an angle about +z).
struct DmJoint {
    name: &'static str,
    parent: Option<usize>,
    offset: [f64; 3],
    slot: Option<(usize, usize)>,
}

const fn dm(name: &'static str, parent: Option<usize>, offset: [f64; 3], slot: Option<(usize, usize)>) -> DmJoint {
    DmJoint { name, parent, offset, slot }
}

/// The humanoid3d skeleton: URDF values × 0.25, identical to DeepMimic's `humanoid3d.txt`
/// (a 1.62 m character; [`STATURE_SCALE`] brings it to SMPL size).
const SKELETON: [DmJoint; DM_JOINTS] = [
    dm("root", None, [0.0, 0.0, 0.0], Some((4, 4))),
    dm("chest", Some(0), [0.0, 0.236151, 0.0], Some((8, 4))),
    dm("neck", Some(1), [0.0, 0.223894, 0.0], Some((12, 4))),
    dm("right_hip", Some(0), [0.0, 0.0, 0.084887], Some((16, 4))),
    dm("right_knee", Some(3), [0.0, -0.421546, 0.0], Some((20, 1))),
    dm("right_ankle", Some(4), [0.0, -0.409870, 0.0], Some((21, 4))),
    dm("right_shoulder", Some(1), [-0.02405, 0.24350, 0.18311], Some((25, 4))),
    dm("right_elbow", Some(6), [0.0, -0.274788, 0.0], Some((29, 1))),
    dm("right_wrist", Some(7), [0.0, -0.258947, 0.0], None),
    dm("left_hip", Some(0), [0.0, 0.0, -0.084887], Some((30, 4))),
    dm("left_knee", Some(9), [0.0, -0.421546, 0.0], Some((34, 1))),
    dm("left_ankle", Some(10), [0.0, -0.409870, 0.0], Some((35, 4))),
    dm("left_shoulder", Some(1), [-0.02405, 0.24350, -0.18311], Some((39, 4))),
    dm("left_elbow", Some(12), [0.0, -0.274788, 0.0], Some((43, 1))),
    dm("left_wrist", Some(13), [0.0, -0.258947, 0.0], None),
];

/// Uniform scale from the DeepMimic humanoid (1.62 m) to the SMPL neutral body's stature
/// (1.70 m), so heights in task programs mean what they mean for HumanML3D motions (a head
/// above 1.5 m when standing, ProgMoGen's HSI tasks). Applied to every output position.
pub const STATURE_SCALE: f64 = 1.70 / 1.62;

/// The SMPL ball of the foot in the ankle frame (front-bottom of the foot box), m.
const FOOT_BALL: [f64; 3] = [0.11, -0.045, 0.0];

/// Each of our 22 joints as a point fixed in a DeepMimic joint frame (`reference/data.md` §6),
/// with one change: spine3 sits on the DeepMimic neck joint instead of 9 cm above the chest
/// joint. Every bone must lie within one rigid DeepMimic body, and the spine3→neck bone crosses
/// the DeepMimic neck joint; placing spine3 on that joint keeps all 21 bone lengths exact (the
/// proposed mapping stretched spine3→neck by up to 5 mm when the head bends).
const SMPL22_FROM_DM: [(usize, [f64; 3]); NUM_JOINTS] = [
    (0, [0.0, 0.0, 0.0]),      // pelvis
    (9, [0.0, 0.0, 0.0]),      // left_hip
    (3, [0.0, 0.0, 0.0]),      // right_hip
    (0, [0.0, 0.118, 0.0]),    // spine1: half-way root → chest
    (10, [0.0, 0.0, 0.0]),     // left_knee
    (4, [0.0, 0.0, 0.0]),      // right_knee
    (1, [0.0, 0.0, 0.0]),      // spine2: the chest joint
    (11, [0.0, 0.0, 0.0]),     // left_ankle
    (5, [0.0, 0.0, 0.0]),      // right_ankle
    (2, [0.0, 0.0, 0.0]),      // spine3: the DeepMimic neck joint (see below)
    (11, FOOT_BALL),           // left_foot
    (5, FOOT_BALL),            // right_foot
    (2, [0.0, 0.06, 0.0]),     // neck
    (1, [-0.02, 0.20, -0.07]), // left_collar
    (1, [-0.02, 0.20, 0.07]),  // right_collar
    (2, [0.0, 0.16, 0.0]),     // head
    (12, [0.0, 0.0, 0.0]),     // left_shoulder
    (6, [0.0, 0.0, 0.0]),      // right_shoulder
    (13, [0.0, 0.0, 0.0]),     // left_elbow
    (7, [0.0, 0.0, 0.0]),      // right_elbow
    (14, [0.0, 0.0, 0.0]),     // left_wrist
    (8, [0.0, 0.0, 0.0]),      // right_wrist
];

/// Quaternions whose norm is further than this from 1 are reported when normalised.
const QUAT_NORM_TOLERANCE: f64 = 1e-3;
/// Cycles whose heading changes less than this are straightened instead of turning (rad, 20°).
const STRAIGHTEN_BELOW_RAD: f64 = 0.35;
/// Longest seam blend at the end of a cycle, s.
const MAX_SEAM_BLEND_S: f64 = 0.25;

/// One DeepMimic keyframe: root position (DeepMimic world, m) and rotations (root: world;
/// others: local to the parent; revolute joints as rotations about +z; wrists identity).
#[derive(Debug, Clone)]
struct Keyframe {
    root: DVec3,
    rot: [DQuat; DM_JOINTS],
}

/// How a cyclic clip continues past its end.
#[derive(Debug, Clone)]
struct Cycle {
    /// Yaw removed linearly over each cycle so near-straight cycles do not curve (rad per cycle).
    straighten_rad: f64,
    /// Yaw each cycle adds to the next (rad), for turning clips.
    turn_rad: f64,
    /// Horizontal root displacement of one cycle after straightening, DeepMimic world.
    step: DVec3,
    /// Corrections reached at the cycle end so the last pose meets the next cycle's first.
    root_seam: DQuat,
    joint_seam: [DQuat; DM_JOINTS],
    height_seam_m: f64,
    blend_s: f64,
}

/// A DeepMimic clip ready to be posed at any time.
#[derive(Debug, Clone)]
pub struct DeepMimicClip {
    name: String,
    /// Start time of each keyframe, s; the last entry is the clip duration.
    times: Vec<f64>,
    keys: Vec<Keyframe>,
    cycle: Option<Cycle>,
}

impl DeepMimicClip {
    /// Reads a clip file of at most [`MOCAP_FILE_BYTES`]. Non-unit quaternions are normalised
    /// and reported in the warnings.
    pub fn read(path: &Path) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let text = read_text(path, &MOCAP_FILE_BYTES)?;
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        Self::parse(&name, &text, path)
    }

    /// Parses clip text; `path` is only used in messages. Frames are read straight into
    /// 44-value rows (no JSON tree), so memory grows with the frames, not the text's tokens.
    pub fn parse(name: &str, text: &str, path: &Path) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let invalid = |location: String, message: String| ImportError::Invalid { path: path.into(), location, message };
        let clip: ClipFile = serde_json::from_str(text).map_err(|e| {
            let (line, column) = (e.line(), e.column());
            if e.classify() == serde_json::error::Category::Data {
                // Our own messages ("frame 3: expected 44 values, found 43") without serde's
                // position suffix, which goes into the location.
                let message = e.to_string();
                let suffix = format!(" at line {line} column {column}");
                let message = message.strip_suffix(&suffix).unwrap_or(&message).to_owned();
                invalid(format!("line {line}, column {column}"), message)
            } else {
                ImportError::Json { path: path.into(), line, column, message: e.to_string() }
            }
        })?;
        let cyclic = match clip.looping.as_deref() {
            Some("wrap") => true,
            Some("none") | None => false,
            Some(other) => {
                return Err(invalid("\"Loop\"".into(), format!("expected \"wrap\" or \"none\", found {other:?}")))
            }
        };
        let frames = clip.frames.0;
        if frames.is_empty() {
            return Err(ImportError::Empty { path: path.into() });
        }
        if frames.len() < 2 {
            return Err(invalid("Frames".into(), "a clip needs at least 2 frames".into()));
        }
        Self::from_frames(name, &frames, cyclic, path)
    }

    /// Builds a clip from raw 44-value frames.
    fn from_frames(
        name: &str,
        frames: &[[f64; FRAME_WIDTH]],
        cyclic: bool,
        path: &Path,
    ) -> Result<(Self, Vec<ImportWarning>), ImportError> {
        let invalid = |location: String, message: String| ImportError::Invalid { path: path.into(), location, message };
        let mut times = Vec::with_capacity(frames.len());
        let mut t = 0.0;
        for (f, frame) in frames.iter().enumerate() {
            times.push(t);
            if f + 1 < frames.len() && frame[0] <= 0.0 {
                return Err(invalid(
                    format!("frame {f}, value 0"),
                    format!("keyframe duration {} s must be positive", short_number(frame[0])),
                ));
            }
            if let Some(i) = (1..4).find(|i| !in_reach(frame[*i])) {
                return Err(invalid(
                    format!("frame {f}, value {i}"),
                    format!(
                        "root position {} m is out of range (more than {} m from the origin)",
                        short_number(frame[i]),
                        short_number(MAX_POSITION_M)
                    ),
                ));
            }
            t += frame[0];
        }
        // The last keyframe's duration is not played.
        let last = frames.len() - 1;
        let duration_s = t - frames[last][0];
        check_clip_length(
            duration_s,
            format_args!("{}: frames 0-{last}: {} s", path.display(), short_number(duration_s)),
        )?;
        let mut off_norm: Vec<(usize, usize, f64)> = Vec::new(); // (joint, frame, norm)
        let mut keys = Vec::with_capacity(frames.len());
        for (f, frame) in frames.iter().enumerate() {
            let mut rot = [DQuat::IDENTITY; DM_JOINTS];
            for (j, joint) in SKELETON.iter().enumerate() {
                rot[j] = match joint.slot {
                    Some((s, 4)) => {
                        let q = DQuat::from_xyzw(frame[s + 1], frame[s + 2], frame[s + 3], frame[s]);
                        let norm = q.length();
                        if norm < 1e-6 {
                            return Err(ImportError::Invalid {
                                path: path.into(),
                                location: format!("frame {f}, joint {}", joint.name),
                                message: "zero quaternion".into(),
                            });
                        }
                        if (norm - 1.0).abs() > QUAT_NORM_TOLERANCE {
                            off_norm.push((j, f, norm));
                        }
                        q / norm
                    }
                    Some((s, _)) => DQuat::from_rotation_z(frame[s]),
                    None => DQuat::IDENTITY,
                };
            }
            keys.push(Keyframe { root: DVec3::new(frame[1], frame[2], frame[3]), rot });
        }
        let warnings = summarize_norms(&off_norm, path);
        let mut clip = Self { name: name.to_owned(), times, keys, cycle: None };
        if cyclic {
            clip.cycle = Some(clip.cycle_seam());
        }
        Ok((clip, warnings))
    }

    /// The clip's file stem ("humanoid3d_walk", "turn_left0", ...).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Interpolated keyframe at `t` within one play-through (clamped to the clip).
    fn key_at(&self, t: f64) -> Keyframe {
        let last = self.keys.len() - 1;
        let k = self.times.partition_point(|s| *s <= t).saturating_sub(1).min(last);
        if k == last {
            return self.keys[last].clone();
        }
        let span = self.times[k + 1] - self.times[k];
        let a = ((t - self.times[k]) / span).clamp(0.0, 1.0);
        let (k0, k1) = (&self.keys[k], &self.keys[k + 1]);
        let mut rot = [DQuat::IDENTITY; DM_JOINTS];
        for (j, r) in rot.iter_mut().enumerate() {
            *r = k0.rot[j].slerp(k1.rot[j], a);
        }
        Keyframe { root: k0.root.lerp(k1.root, a), rot }
    }

    fn cycle_seam(&self) -> Cycle {
        let (first, last) = (&self.keys[0], &self.keys[self.keys.len() - 1]);
        let turn = wrap_angle(yaw(last.rot[0]) - yaw(first.rot[0]));
        let (straighten_rad, turn_rad) = if turn.abs() < STRAIGHTEN_BELOW_RAD { (turn, 0.0) } else { (0.0, turn) };
        let unturn = DQuat::from_rotation_y(-straighten_rad);
        let d = last.root - first.root;
        let step = unturn * DVec3::new(d.x, 0.0, d.z);
        let root_seam = (unturn * last.rot[0]).inverse() * (DQuat::from_rotation_y(turn_rad) * first.rot[0]);
        let mut joint_seam = [DQuat::IDENTITY; DM_JOINTS];
        for (j, s) in joint_seam.iter_mut().enumerate().skip(1) {
            *s = last.rot[j].inverse() * first.rot[j];
        }
        Cycle {
            straighten_rad,
            turn_rad,
            step,
            root_seam,
            joint_seam,
            height_seam_m: first.root.y - last.root.y,
            blend_s: MAX_SEAM_BLEND_S.min(self.duration_s() / 4.0),
        }
    }

    /// Root position and rotations (DeepMimic world) at any time, continuing cycles.
    fn world_key_at(&self, t: f64) -> Keyframe {
        let duration = self.duration_s();
        let Some(cycle) = &self.cycle else {
            return self.key_at(t.clamp(0.0, duration));
        };
        let c = (t / duration).floor().max(0.0);
        let tau = t - c * duration;
        let mut key = self.key_at(tau);
        let p0 = self.keys[0].root;
        let w = smoothstep((tau - (duration - cycle.blend_s)) / cycle.blend_s);
        let heading = DQuat::from_rotation_y(c * cycle.turn_rad);
        let straighten = DQuat::from_rotation_y(-cycle.straighten_rad * tau / duration);
        let mut origin = p0;
        for i in 0..c as usize {
            origin += DQuat::from_rotation_y(i as f64 * cycle.turn_rad) * cycle.step;
        }
        let rel = key.root - p0;
        key.root = origin + heading * (straighten * rel) + DVec3::Y * (w * cycle.height_seam_m);
        key.rot[0] = heading * straighten * key.rot[0] * DQuat::IDENTITY.slerp(cycle.root_seam, w);
        for j in 1..DM_JOINTS {
            key.rot[j] *= DQuat::IDENTITY.slerp(cycle.joint_seam[j], w);
        }
        key
    }
}

impl MocapClip for DeepMimicClip {
    fn duration_s(&self) -> f64 {
        self.times.last().copied().unwrap_or(0.0)
    }

    fn is_cyclic(&self) -> bool {
        self.cycle.is_some()
    }

    fn pose_at(&self, t_s: f64) -> Pose {
        smpl22(&self.world_key_at(t_s))
    }
}

/// Forward kinematics of one keyframe, mapped to the 22 joints in our axes.
fn smpl22(key: &Keyframe) -> Pose {
    let mut world = [DQuat::IDENTITY; DM_JOINTS];
    for (j, joint) in SKELETON.iter().enumerate() {
        world[j] = match joint.parent {
            None => key.rot[j],
            Some(p) => world[p] * key.rot[j],
        };
    }
    smpl22_from_world(key.root, &world)
}

/// Joint positions of the humanoid (DeepMimic world, m, unscaled) from the root position and
/// every joint's **world** rotation, in skeleton order (root, chest, neck, right hip, knee,
/// ankle, shoulder, elbow, wrist, then the same on the left): each joint sits at its parent plus
/// the parent's rotation applied to the skeleton offset, so bone lengths are exact.
pub(crate) fn joint_positions(root: DVec3, world: &[DQuat; DM_JOINTS]) -> [DVec3; DM_JOINTS] {
    let mut pos = [root; DM_JOINTS];
    for (j, joint) in SKELETON.iter().enumerate() {
        if let Some(p) = joint.parent {
            pos[j] = pos[p] + world[p] * DVec3::from_array(joint.offset);
        }
    }
    pos
}

/// The 22 joints in our axes (m, scaled by [`STATURE_SCALE`]) of the humanoid posed by its root
/// position and every joint's world rotation (DeepMimic world). Shared by every source of this
/// character (DeepMimic clips, Isaac Lab's AMP motions).
pub(crate) fn smpl22_from_world(root: DVec3, world: &[DQuat; DM_JOINTS]) -> Pose {
    let pos = joint_positions(root, world);
    SMPL22_FROM_DM.map(|(j, local)| {
        let v = (pos[j] + world[j] * DVec3::from_array(local)) * STATURE_SCALE;
        DVec3::new(-v.z, v.y, v.x)
    })
}

/// Heading of a DeepMimic root rotation: angle about +y of the rotated forward axis (+x), rad.
fn yaw(q: DQuat) -> f64 {
    let f = q * DVec3::X;
    (-f.z).atan2(f.x)
}

fn wrap_angle(a: f64) -> f64 {
    (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// One warning per joint with non-unit quaternions: how many, which frames, the extreme norm.
fn summarize_norms(off: &[(usize, usize, f64)], path: &Path) -> Vec<ImportWarning> {
    (0..DM_JOINTS)
        .filter_map(|j| {
            let hits: Vec<_> = off.iter().filter(|(jj, _, _)| *jj == j).collect();
            let (first, last) = (hits.first()?, hits.last()?);
            let worst =
                hits.iter().map(|h| h.2).fold(1.0, |a: f64, n| if (n - 1.0).abs() > (a - 1.0).abs() { n } else { a });
            Some(ImportWarning {
                path: path.into(),
                message: format!(
                    "normalised {} non-unit quaternions of {} (frames {}-{}, norm up to {worst:.3})",
                    hits.len(),
                    SKELETON[j].name,
                    first.1,
                    last.1
                ),
            })
        })
        .collect()
}

/// A synthetic 20 fps walk through the real forward kinematics, turning at `turn_rate` rad/s:
/// hips, knees, shoulders and elbows swing sinusoidally at 0.9 strides per second.
#[cfg(test)]
pub(crate) fn synthetic_walk(frames: usize, turn_rate: f64) -> Vec<Pose> {
    let dt = 1.0 / crate::skeleton::FPS;
    let rows: Vec<[f64; FRAME_WIDTH]> = (0..frames.max(2))
        .map(|k| {
            let t = k as f64 * dt;
            let phase = std::f64::consts::TAU * 0.9 * t;
            let mut f = [0f64; FRAME_WIDTH];
            f[0] = if k + 1 < frames { dt } else { 0.0 };
            let heading = turn_rate * t;
            // Forward speed 1 m/s along the heading (DeepMimic forward is +x).
            let (s, c) = heading.sin_cos();
            let dist = t;
            let (x, z) = if turn_rate.abs() > 1e-9 { (s / turn_rate, (1.0 - c) / turn_rate) } else { (dist, 0.0) };
            f[1] = x;
            f[2] = 0.88 + 0.02 * (2.0 * phase).cos();
            f[3] = -z;
            let q = |q: DQuat, at: usize, f: &mut [f64; FRAME_WIDTH]| {
                f[at] = q.w;
                f[at + 1] = q.x;
                f[at + 2] = q.y;
                f[at + 3] = q.z;
            };
            q(DQuat::from_rotation_y(heading), 4, &mut f);
            q(DQuat::IDENTITY, 8, &mut f);
            q(DQuat::IDENTITY, 12, &mut f);
            q(DQuat::from_rotation_z(0.4 * phase.sin()), 16, &mut f);
            f[20] = -0.5 * (phase.sin().max(0.0));
            q(DQuat::IDENTITY, 21, &mut f);
            q(DQuat::from_rotation_z(-0.3 * phase.sin()), 25, &mut f);
            f[29] = 0.3;
            q(DQuat::from_rotation_z(-0.4 * phase.sin()), 30, &mut f);
            f[34] = -0.5 * ((-phase.sin()).max(0.0));
            q(DQuat::IDENTITY, 35, &mut f);
            q(DQuat::from_rotation_z(0.3 * phase.sin()), 39, &mut f);
            f[43] = 0.3;
            f
        })
        .collect();
    let (clip, _) = match DeepMimicClip::from_frames("synthetic", &rows, false, Path::new("synthetic")) {
        Ok(c) => c,
        Err(e) => unreachable!("synthetic frames are valid: {e}"),
    };
    (0..frames).map(|k| clip.pose_at(k as f64 * dt)).collect()
}

/// The shipped DeepMimic clips (`fixtures/mocap/deepmimic/`), for tests.
#[cfg(test)]
pub(crate) mod shipped {
    use std::path::PathBuf;

    use super::DeepMimicClip;

    /// The folder of the shipped clips.
    pub fn dir() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/deepmimic")
    }

    /// The shipped clip `name` (such as `humanoid3d_run.txt`).
    pub fn clip(name: &str) -> DeepMimicClip {
        DeepMimicClip::read(&dir().join(name)).unwrap().0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::rest_pose;
    use crate::skeleton::{bone_lengths, Joint};

    #[test]
    fn rest_pose_matches_the_reference_table() {
        let p = rest_pose().map(|v| v / STATURE_SCALE);
        let at = |j: Joint| p[j.index()];
        assert!((at(Joint::LeftHip) - DVec3::new(0.084887, 0.0, 0.0)).length() < 1e-9);
        assert!((at(Joint::Head).y - 0.620045).abs() < 1e-6);
        assert!((at(Joint::LeftShoulder) - DVec3::new(0.18311, 0.479651, -0.02405)).length() < 1e-6);
        assert!((at(Joint::LeftFoot) - DVec3::new(0.084887, -0.876416, 0.11)).length() < 1e-6);
        // Upper arm 0.275 m, forearm 0.259 m.
        let l = bone_lengths(&p);
        assert!((at(Joint::Spine3).y - 0.460045).abs() < 1e-6);
        assert!((l[Joint::LeftElbow.index()] - 0.274788).abs() < 1e-9);
        assert!((l[Joint::LeftWrist.index()] - 0.258947).abs() < 1e-9);
    }

    #[test]
    fn bad_files_get_errors_naming_the_place() {
        let p = Path::new("clip.txt");
        let err = |t: &str| DeepMimicClip::parse("x", t, p).unwrap_err().to_string();
        assert!(err("{\"Frames\": [[1,2,").contains("line 1"));
        assert!(err("{}").contains("Frames"));
        assert!(err("{\"Frames\": []}").contains("no frames"));
        let short = format!("{{\"Frames\": [[{}], [{}]]}}", vec!["0.1"; 44].join(","), vec!["0"; 43].join(","));
        assert!(err(&short).contains("frame 1") && err(&short).contains("found 43"));
        let mut row = vec!["0.1".to_string(); 44];
        row[7] = "\"a\"".into();
        let bad = format!("{{\"Frames\": [[{}], [{}]]}}", row.join(","), vec!["0"; 44].join(","));
        assert!(err(&bad).contains("frame 0, value 7"));
        let zero_q = format!("{{\"Frames\": [[{}], [{}]]}}", vec!["0.1"; 44].join(","), vec!["0"; 44].join(","));
        assert!(err(&zero_q).contains("zero quaternion"));
        assert!(err(&format!("{{\"Loop\": \"bounce\", \"Frames\": [[{}]]}}", vec!["0"; 44].join(","))).contains("Loop"));
    }

    /// A clip of `frames` standing keyframes `duration_s` apart, with `edit` applied, as JSON.
    fn standing(frames: usize, duration_s: f64, edit: impl Fn(&mut Vec<Vec<f64>>)) -> String {
        let mut rows = vec![vec![0.0; FRAME_WIDTH]; frames];
        for r in &mut rows {
            r[0] = duration_s;
            for s in [4, 8, 12, 16, 21, 25, 30, 35, 39] {
                r[s] = 1.0;
            }
        }
        edit(&mut rows);
        serde_json::json!({ "Loop": "none", "Frames": rows }).to_string()
    }

    #[test]
    fn absurd_values_and_overlong_clips_are_named() {
        let err = |t: &str| DeepMimicClip::parse("x", t, Path::new("clip.txt")).unwrap_err().to_string();
        let e = err(&standing(3, 0.05, |r| r[1][1] = 1e300));
        assert!(e.starts_with("clip.txt: frame 1, value 1: ") && e.contains("1e300 m is out of range"), "{e}");
        let e = err(&standing(3, 0.05, |r| r[0][0] = -1e308));
        assert!(e.starts_with("clip.txt: frame 0, value 0: ") && e.contains("-1e308 s"), "{e}");
        assert!(e.len() < 200, "{e}");
        // Two keyframes 4000 s apart: 80001 frames at 20 fps.
        let e = err(&standing(2, 4000.0, |_| {}));
        assert!(e.starts_with("clip.txt: frames 0-1") && e.contains("80001 frames at 20 fps"), "{e}");
        assert!(e.contains("imported clip length"), "{e}");
        let e = err(&standing(2, 1e300, |_| {}));
        assert!(e.contains("imported clip length") && !e.contains("000000000000"), "{e}");
        assert!(DeepMimicClip::parse("x", &standing(2, 3000.0, |_| {}), Path::new("clip.txt")).is_ok());
    }

    #[test]
    fn non_unit_quaternions_are_normalised_with_a_warning() {
        let mut rows = vec![[0f64; FRAME_WIDTH]; 3];
        for (k, r) in rows.iter_mut().enumerate() {
            r[0] = if k < 2 { 0.05 } else { 0.0 };
            for s in [4, 8, 12, 16, 21, 25, 30, 35, 39] {
                r[s] = 1.0;
            }
        }
        rows[1][16] = 0.6; // right hip, norm 0.6
        let (clip, warnings) = DeepMimicClip::from_frames("x", &rows, false, Path::new("x.txt")).unwrap();
        assert_eq!(warnings.len(), 1);
        assert!(warnings[0].message.contains("right_hip") && warnings[0].message.contains("0.600"));
        assert!(bone_lengths(&clip.pose_at(0.05))
            .iter()
            .zip(bone_lengths(&rest_pose()))
            .all(|(a, b)| (a - b).abs() < 1e-9));
    }
}
