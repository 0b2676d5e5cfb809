//! [`BvhAnimation`]: a BVH file's motion in metres and quaternions, posed at any time by forward
//! kinematics on the file's own skeleton.

use std::path::Path;

use glam::{DQuat, DVec3};

use super::error::invalid;
use super::file::Bvh;
use super::hierarchy::{Axis, Channel};
use super::units::{LengthUnit, UpAxis};
use crate::import::error::ImportError;
use crate::import::frames::bracket;
use crate::import::values::{in_reach, short_number, MAX_POSITION_M};

/// Largest accepted rotation channel value, degrees (unwrapped angles of a long spin stay far
/// below; beyond it an angle has lost its precision and is an export error).
const MAX_ROTATION_DEG: f64 = 1e6;

/// The motion of a [`Bvh`] ready for forward kinematics: the channel values in metres and
/// radians, file axes (positions come out in ours). Local transforms are made from them when a
/// time is posed, so memory grows with the file's values, not with frames × nodes (a rig's
/// channel-less nodes cost nothing per frame).
#[derive(Debug, Clone)]
pub struct BvhAnimation {
    unit: LengthUnit,
    up: UpAxis,
    frame_time_s: f64,
    frames: usize,
    parents: Vec<Option<usize>>,
    /// Rest offsets, metres.
    offsets_m: Vec<DVec3>,
    /// Per node: the index of its first value on a frame row, and its channels.
    channels: Vec<(usize, Vec<Channel>)>,
    /// Channel values `[frames, channel_count]`, row-major: positions in metres, rotations in
    /// radians.
    values: Vec<f64>,
    channel_count: usize,
}

impl BvhAnimation {
    /// Converts a parsed file: lengths × the unit, degrees to radians. Fails for a
    /// [`LengthUnit::MetresPer`] that is not positive and finite, and for an OFFSET or a
    /// position further than [`MAX_POSITION_M`] from the origin or a rotation beyond
    /// ±10⁶ degrees (the error names the line, joint, frame and channel).
    pub fn new(bvh: &Bvh, unit: LengthUnit, up: UpAxis, path: &Path) -> Result<Self, ImportError> {
        let scale = unit.metres();
        if !(scale.is_finite() && scale > 0.0) {
            return Err(ImportError::Invalid {
                path: path.into(),
                location: "options".into(),
                message: format!("metres per file unit must be positive and finite, found {}", short_number(scale)),
            });
        }
        let out_of_range = |line: usize, joint: &str, what: String, limit: String| {
            invalid(path, line, Some(joint), format!("{what} is out of range ({limit})"))
        };
        let far = format!("more than {} m from the origin", short_number(MAX_POSITION_M));
        let joints = bvh.joints();
        let mut offsets_m = Vec::with_capacity(joints.len());
        for joint in joints {
            let m = joint.offset * scale;
            if let Some(v) = joint.offset.to_array().into_iter().find(|v| !in_reach(v * scale)) {
                let what = format!("OFFSET: {} ({} m)", short_number(v), short_number(v * scale));
                return Err(out_of_range(joint.line, &joint.name, what, far.clone()));
            }
            offsets_m.push(m);
        }
        let mut channels = Vec::with_capacity(joints.len());
        let mut first = 0;
        for joint in joints {
            channels.push((first, joint.channels.clone()));
            first += joint.channels.len();
        }
        let frames = bvh.frames();
        let mut values = Vec::with_capacity(frames * first);
        for k in 0..frames {
            let (Some(row), Some(line)) = (bvh.frame(k), bvh.frame_line(k)) else { break };
            let mut row = row.iter();
            for joint in joints {
                for (channel, &v) in joint.channels.iter().zip(row.by_ref()) {
                    let converted = match channel {
                        Channel::Position(_) if !in_reach(v * scale) => {
                            let what = format!(
                                "frame {k}, {}: {} ({} m)",
                                channel.name(),
                                short_number(v),
                                short_number(v * scale)
                            );
                            return Err(out_of_range(line, &joint.name, what, far.clone()));
                        }
                        Channel::Position(_) => v * scale,
                        Channel::Rotation(_) if v.abs() > MAX_ROTATION_DEG => {
                            let what = format!("frame {k}, {}: {} degrees", channel.name(), short_number(v));
                            let limit = format!("beyond ±{} degrees", short_number(MAX_ROTATION_DEG));
                            return Err(out_of_range(line, &joint.name, what, limit));
                        }
                        Channel::Rotation(_) => v.to_radians(),
                    };
                    values.push(converted);
                }
            }
        }
        Ok(Self {
            unit,
            up,
            frame_time_s: bvh.frame_time_s(),
            frames,
            parents: joints.iter().map(|j| j.parent).collect(),
            offsets_m,
            channels,
            values,
            channel_count: first,
        })
    }

    /// The file's length unit.
    pub fn unit(&self) -> LengthUnit {
        self.unit
    }

    /// Number of frames (at least 1).
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Seconds between frames.
    pub fn frame_time_s(&self) -> f64 {
        self.frame_time_s
    }

    /// Time from the first frame to the last, s.
    pub fn duration_s(&self) -> f64 {
        self.frames.saturating_sub(1) as f64 * self.frame_time_s
    }

    /// World positions of every node (end sites included) at `t_s`, metres, our axes, in
    /// [`Bvh::joints`] order. Rotations are slerped and translations lerped between the two
    /// nearest frames; times outside the clip hold its end frames.
    pub fn positions_at(&self, t_s: f64) -> Vec<DVec3> {
        let (k, k1, a) = bracket(t_s, self.frames, self.frame_time_s);
        let locals = (0..self.parents.len()).map(|j| {
            let ((r0, t0), (r1, t1)) = (self.local(k, j), self.local(k1, j));
            (r0.slerp(r1, a), t0.lerp(t1, a))
        });
        self.forward_kinematics(locals)
    }

    /// Local rotation and translation of node `j` at frame `k`: its OFFSET with the position
    /// channels applied, and its Euler channels composed in the order written.
    fn local(&self, k: usize, j: usize) -> (DQuat, DVec3) {
        let (mut rot, mut pos) = (DQuat::IDENTITY, self.offsets_m[j]);
        let (first, channels) = &self.channels[j];
        let row = self.values.get(k * self.channel_count + first..).unwrap_or_default();
        for (channel, &v) in channels.iter().zip(row) {
            match channel {
                Channel::Position(Axis::X) => pos.x = v,
                Channel::Position(Axis::Y) => pos.y = v,
                Channel::Position(Axis::Z) => pos.z = v,
                Channel::Rotation(Axis::X) => rot *= DQuat::from_rotation_x(v),
                Channel::Rotation(Axis::Y) => rot *= DQuat::from_rotation_y(v),
                Channel::Rotation(Axis::Z) => rot *= DQuat::from_rotation_z(v),
            }
        }
        (rot, pos)
    }

    /// World positions of the rest skeleton (OFFSETs only, no rotations), metres, our axes.
    pub fn rest_positions(&self) -> Vec<DVec3> {
        self.forward_kinematics(self.offsets_m.iter().map(|o| (DQuat::IDENTITY, *o)))
    }

    /// `(rotation, translation)` per node, file axes → world positions, our axes.
    fn forward_kinematics(&self, locals: impl Iterator<Item = (DQuat, DVec3)>) -> Vec<DVec3> {
        let n = self.parents.len();
        let mut pos = vec![DVec3::ZERO; n];
        let mut rot = vec![DQuat::IDENTITY; n];
        for (j, (r, t)) in locals.enumerate().take(n) {
            let (p, q) = match self.parents[j] {
                Some(parent) => (pos[parent] + rot[parent] * t, rot[parent] * r),
                None => (t, r),
            };
            pos[j] = p;
            rot[j] = q;
        }
        pos.into_iter().map(|p| self.up.to_ours(p)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::bvh::tests::{edit, TINY};

    fn animation(text: &str, unit: LengthUnit, up: UpAxis) -> BvhAnimation {
        let (bvh, _) = Bvh::parse(text, Path::new("t.bvh")).unwrap();
        BvhAnimation::new(&bvh, unit, up, Path::new("t.bvh")).unwrap()
    }

    fn close(a: &[DVec3], b: &[[f64; 3]]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(p, q)| (*p - DVec3::from_array(*q)).length() < 1e-9)
    }

    #[test]
    fn absurd_values_name_the_file_line_frame_and_channel() {
        let path = Path::new("t.bvh");
        for (line, text, unit, place, what) in [
            (20, "1 1e308 3 90 0 0 0 0 90", LengthUnit::Metres, "line 20, joint Hips", "frame 1, Yposition: 1e308"),
            (20, "1 2 3 90 0 0 0 0 90", LengthUnit::MetresPer(1e300), "line 6, joint Arm", "OFFSET: 1 (1e300 m)"),
            (19, "0 0 0 0 0 0 0 2e7 0", LengthUnit::Metres, "line 19, joint Arm", "frame 0, Xrotation: 2e7"),
            (8, "OFFSET 1e7 0 0", LengthUnit::Centimetres, "line 6, joint Arm", "OFFSET: 1e7"),
        ] {
            let (bvh, _) = Bvh::parse(&edit(line, Some(text)), path).unwrap();
            let e = BvhAnimation::new(&bvh, unit, UpAxis::Y, path).unwrap_err().to_string();
            assert!(e.starts_with("t.bvh: ") && e.contains(place) && e.contains(what), "{e}");
            assert!(e.contains("out of range"), "{e}");
        }
        // 1e5 cm is 1 km: far, but a place.
        let (bvh, _) = Bvh::parse(&edit(20, Some("1e5 2 3 90 0 0 0 0 90")), path).unwrap();
        assert!(BvhAnimation::new(&bvh, LengthUnit::Centimetres, UpAxis::Y, path).is_ok());
    }

    #[test]
    fn two_joint_chain_gives_hand_computed_positions() {
        // Frame 1: root at (1, 2, 3) turned 90° about z, the arm turned 90° about its y:
        // arm = root + Rz90·(1,0,0) = (1,3,3); tip = arm + Rz90·Ry90·(1,0,0) = arm + (0,0,−1).
        let a = animation(TINY, LengthUnit::Metres, UpAxis::Y);
        assert_eq!((a.frames(), a.duration_s()), (2, 0.5));
        assert!(close(&a.positions_at(0.0), &[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]));
        assert!(close(&a.positions_at(0.5), &[[1.0, 2.0, 3.0], [1.0, 3.0, 3.0], [1.0, 3.0, 2.0]]));
        // Half way: root lerped, both rotations slerped to 45°.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let mid = [[0.5, 1.0, 1.5], [0.5 + h, 1.0 + h, 1.5], [0.5 + h + 0.5, 1.0 + h + 0.5, 1.5 - h]];
        assert!(close(&a.positions_at(0.25), &mid));
        // Outside the clip the end frames hold.
        assert!(close(&a.positions_at(-3.0), &[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]));
        assert!(close(&a.positions_at(9.0), &[[1.0, 2.0, 3.0], [1.0, 3.0, 3.0], [1.0, 3.0, 2.0]]));
        assert!(close(&a.positions_at(f64::NAN), &[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]));
        assert!(close(&a.rest_positions(), &[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]));
    }

    #[test]
    fn euler_channels_are_intrinsic_in_the_written_order() {
        let file = |order: &str| {
            format!(
                "HIERARCHY\nROOT R\n{{\nOFFSET 0 0 0\nCHANNELS 2 {order}\nEnd Site\n{{\nOFFSET 1 0 0\n}}\n}}\n\
                 MOTION\nFrames: 1\nFrame Time: 0.1\n90 90\n"
            )
        };
        // Rz90·Rx90·x = Rz90·x = +y; Rx90·Rz90·x = Rx90·y = +z.
        let zx = animation(&file("Zrotation Xrotation"), LengthUnit::Metres, UpAxis::Y);
        assert!(close(&zx.positions_at(0.0), &[[0.0; 3], [0.0, 1.0, 0.0]]));
        let xz = animation(&file("Xrotation Zrotation"), LengthUnit::Metres, UpAxis::Y);
        assert!(close(&xz.positions_at(0.0), &[[0.0; 3], [0.0, 0.0, 1.0]]));
    }

    #[test]
    fn position_channels_of_a_non_root_joint_replace_its_offset_in_the_parents_frame() {
        // As the exporter writes the joints with animated offsets (and Blender reads them): the
        // arm's position channels are its offset from the root in the root's turned frame.
        let moved = TINY
            .replace(
                "CHANNELS 3 Zrotation Xrotation Yrotation",
                "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation",
            )
            .replace("0 0 0 0 0 0 0 0 0", "0 0 0 0 0 0 1 0 0 0 0 0")
            .replace("1 2 3 90 0 0 0 0 90", "1 2 3 90 0 0 0 2 0 0 0 0");
        let a = animation(&moved, LengthUnit::Metres, UpAxis::Y);
        assert!(close(&a.positions_at(0.0), &[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]));
        // Root at (1, 2, 3) turned 90° about z: arm = root + Rz90·(0, 2, 0), tip = arm + Rz90·(1, 0, 0).
        assert!(close(&a.positions_at(0.5), &[[1.0, 2.0, 3.0], [-1.0, 2.0, 3.0], [-1.0, 3.0, 3.0]]));
        // The rest skeleton keeps the OFFSET.
        assert!(close(&a.rest_positions(), &[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]));
    }

    #[test]
    fn position_channels_units_and_z_up() {
        // A position channel on a non-root joint replaces that component of its OFFSET.
        let moved = TINY
            .replace("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 4 Xposition Zrotation Xrotation Yrotation")
            .replace("0 0 0 0 0 0 0 0 0", "0 0 0 0 0 0 5 0 0 0")
            .replace("1 2 3 90 0 0 0 0 90", "0 0 0 0 0 0 5 0 0 0");
        let a = animation(&moved, LengthUnit::Centimetres, UpAxis::Y);
        assert!(close(&a.positions_at(0.0), &[[0.0; 3], [0.05, 0.0, 0.0], [0.06, 0.0, 0.0]]));
        let half = animation(TINY, LengthUnit::MetresPer(0.5), UpAxis::Y);
        assert!(close(&half.positions_at(0.5), &[[0.5, 1.0, 1.5], [0.5, 1.5, 1.5], [0.5, 1.5, 1.0]]));
        // Z up: (x, y, z) → (x, z, −y).
        let z_up = animation(TINY, LengthUnit::Metres, UpAxis::Z);
        assert!(close(&z_up.positions_at(0.5), &[[1.0, 3.0, -2.0], [1.0, 3.0, -3.0], [1.0, 2.0, -3.0]]));
        let (bvh, _) = Bvh::parse(TINY, Path::new("t.bvh")).unwrap();
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            let e = BvhAnimation::new(&bvh, LengthUnit::MetresPer(bad), UpAxis::Y, Path::new("t.bvh")).unwrap_err();
            assert!(e.to_string().contains("options"));
        }
    }
}
