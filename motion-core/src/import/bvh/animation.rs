//! [`BvhAnimation`]: a BVH file's motion in metres and quaternions, posed at any time by forward
//! kinematics on the file's own skeleton.

use std::path::Path;

use glam::{DQuat, DVec3};

use super::{Axis, Bvh, Channel, LengthUnit, UpAxis};
use crate::import::ImportError;

/// The motion of a [`Bvh`] ready for forward kinematics: per frame and node a local rotation and
/// translation, metres, file axes (positions come out in ours).
#[derive(Debug, Clone)]
pub struct BvhAnimation {
    unit: LengthUnit,
    up: UpAxis,
    frame_time_s: f64,
    frames: usize,
    parents: Vec<Option<usize>>,
    /// Rest offsets, metres.
    offsets_m: Vec<DVec3>,
    /// Local rotations, `[frames, nodes]`.
    rotations: Vec<DQuat>,
    /// Local translations (offsets with position channels applied), metres, `[frames, nodes]`.
    translations: Vec<DVec3>,
}

impl BvhAnimation {
    /// Converts a parsed file: lengths × the unit, Euler channels to quaternions (intrinsic, in the
    /// order written). Fails for a [`LengthUnit::MetresPer`] that is not positive and finite.
    pub fn new(bvh: &Bvh, unit: LengthUnit, up: UpAxis, path: &Path) -> Result<Self, ImportError> {
        let scale = unit.metres();
        if !(scale.is_finite() && scale > 0.0) {
            return Err(ImportError::Invalid {
                path: path.into(),
                location: "options".into(),
                message: format!("metres per file unit must be positive and finite, found {scale}"),
            });
        }
        let joints = bvh.joints();
        let offsets_m: Vec<DVec3> = joints.iter().map(|j| j.offset * scale).collect();
        let frames = bvh.frames();
        let mut rotations = Vec::with_capacity(frames * joints.len());
        let mut translations = Vec::with_capacity(frames * joints.len());
        for values in (0..frames).filter_map(|k| bvh.frame(k)) {
            let mut values = values.iter();
            for (joint, offset) in joints.iter().zip(&offsets_m) {
                let (mut rot, mut pos) = (DQuat::IDENTITY, *offset);
                for (channel, v) in joint.channels.iter().zip(values.by_ref()) {
                    match channel {
                        Channel::Position(Axis::X) => pos.x = v * scale,
                        Channel::Position(Axis::Y) => pos.y = v * scale,
                        Channel::Position(Axis::Z) => pos.z = v * scale,
                        Channel::Rotation(Axis::X) => rot *= DQuat::from_rotation_x(v.to_radians()),
                        Channel::Rotation(Axis::Y) => rot *= DQuat::from_rotation_y(v.to_radians()),
                        Channel::Rotation(Axis::Z) => rot *= DQuat::from_rotation_z(v.to_radians()),
                    }
                }
                rotations.push(rot);
                translations.push(pos);
            }
        }
        Ok(Self {
            unit,
            up,
            frame_time_s: bvh.frame_time_s(),
            frames,
            parents: joints.iter().map(|j| j.parent).collect(),
            offsets_m,
            rotations,
            translations,
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
        let n = self.parents.len();
        let last = self.frames.saturating_sub(1);
        let x = (t_s / self.frame_time_s).clamp(0.0, last as f64);
        let x = if x.is_nan() { 0.0 } else { x };
        let k = (x.floor() as usize).min(last);
        let k1 = (k + 1).min(last);
        let a = x - k as f64;
        let locals = (0..n).filter_map(|j| {
            let (r0, r1) = (self.rotations.get(k * n + j)?, self.rotations.get(k1 * n + j)?);
            let (t0, t1) = (self.translations.get(k * n + j)?, self.translations.get(k1 * n + j)?);
            Some((r0.slerp(*r1, a), t0.lerp(*t1, a)))
        });
        self.forward_kinematics(locals)
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
    use crate::import::bvh::tests::TINY;

    fn animation(text: &str, unit: LengthUnit, up: UpAxis) -> BvhAnimation {
        let (bvh, _) = Bvh::parse(text, Path::new("t.bvh")).unwrap();
        BvhAnimation::new(&bvh, unit, up, Path::new("t.bvh")).unwrap()
    }

    fn close(a: &[DVec3], b: &[[f64; 3]]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(p, q)| (*p - DVec3::from_array(*q)).length() < 1e-9)
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
