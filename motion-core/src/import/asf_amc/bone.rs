//! A bone of an Acclaim skeleton ([`AsfBone`]), its degrees of freedom ([`Dof`]), and the
//! Euler rotations of its `axis` line and AMC values.

use glam::{DQuat, DVec3};

use crate::import::bvh::Axis;

/// A degree of freedom of a bone (its AMC values come in the order of the bone's `dof` line).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dof {
    /// `rx`, `ry`, `rz`: a rotation about an axis of the bone's local frame, degrees or radians.
    Rotation(Axis),
    /// `tx`, `ty`, `tz`: a translation along an axis of the bone's local frame (the root's is in
    /// world axes), ASF length units.
    Translation(Axis),
    /// `l`: a change of the bone's length, ASF length units.
    Length,
}

impl Dof {
    /// Parses a dof name (`rx`, `TX`, `l`, …; ASCII case-insensitive).
    pub(super) fn from_name(s: &str) -> Option<Dof> {
        let lower = s.to_ascii_lowercase();
        let axis = |c: u8| match c {
            b'x' => Some(Axis::X),
            b'y' => Some(Axis::Y),
            b'z' => Some(Axis::Z),
            _ => None,
        };
        match lower.as_bytes() {
            [b'l'] => Some(Dof::Length),
            [b'r', c] => axis(*c).map(Dof::Rotation),
            [b't', c] => axis(*c).map(Dof::Translation),
            _ => None,
        }
    }

    /// The name as written in ASF files.
    pub fn name(self) -> &'static str {
        match self {
            Dof::Rotation(Axis::X) => "rx",
            Dof::Rotation(Axis::Y) => "ry",
            Dof::Rotation(Axis::Z) => "rz",
            Dof::Translation(Axis::X) => "tx",
            Dof::Translation(Axis::Y) => "ty",
            Dof::Translation(Axis::Z) => "tz",
            Dof::Length => "l",
        }
    }
}

/// A bone of an [`Asf`](super::Asf); bone 0 is the root (no direction or length; its dofs are the root's
/// `order`, its axis the root's `orientation`).
#[derive(Debug, Clone, PartialEq)]
pub struct AsfBone {
    /// The name as written (`lfemur`; `root` for the root).
    pub name: String,
    /// Index of the parent bone; `None` for the root.
    pub parent: Option<usize>,
    /// Unit direction from the bone's start to its end at rest, world axes.
    pub direction: DVec3,
    /// Length, ASF units.
    pub length: f64,
    /// The bone's local frame `C` in world axes (from its `axis` line).
    pub axis: DQuat,
    /// Dofs in the order of their AMC values.
    pub dofs: Vec<Dof>,
    /// 1-based line of its `begin` (of `:root` for the root).
    pub line: usize,
}

/// A rotation order such as `XYZ`.
pub(super) fn rotation_order(tok: &str) -> Option<[Axis; 3]> {
    let axes: Vec<Axis> = tok
        .bytes()
        .map(|c| match c.to_ascii_uppercase() {
            b'X' => Some(Axis::X),
            b'Y' => Some(Axis::Y),
            b'Z' => Some(Axis::Z),
            _ => None,
        })
        .collect::<Option<_>>()?;
    match axes[..] {
        [a, b, c] if a != b && b != c && a != c => Some([a, b, c]),
        _ => None,
    }
}

/// The rotation of Euler angles (radians, indexed by axis x, y, z) applied about fixed axes in
/// `order`, the first first: `XYZ` is `R_z · R_y · R_x`.
pub(super) fn euler(order: &[Axis], angles: [f64; 3]) -> DQuat {
    order.iter().fold(DQuat::IDENTITY, |q, axis| axis_rotation(*axis, angles[*axis as usize]) * q)
}

/// A rotation of `radians` about a coordinate axis.
pub(super) fn axis_rotation(axis: Axis, radians: f64) -> DQuat {
    match axis {
        Axis::X => DQuat::from_rotation_x(radians),
        Axis::Y => DQuat::from_rotation_y(radians),
        Axis::Z => DQuat::from_rotation_z(radians),
    }
}
