//! What a constraint measures ([`Quantity`] of a [`Point`]) and on which frames ([`FrameSelection`],
//! [`FrameRef`], [`Condition`]).
//!
//! Conventions ([`crate::skeleton`]): y up, metres, +x is the character's left, a motion starts at
//! the origin facing +z, 20 fps. A quantity maps joints `[B, T, 22, 3]` to a per-frame signal
//! `[B, T − lag, C]`: `lag` is 0 for positions and distances, 1 for velocities (forward
//! difference), 2 for accelerations; `C` is the number of [`Axes`] (1 for distances and speeds).

use std::fmt;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::serde_util::{tag_first_deserialize, JointName};
use crate::skeleton::Joint;

/// Which coordinates of a point a quantity keeps (y is up).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Axes {
    /// Left (+x) / right.
    X,
    /// Height (up).
    Y,
    /// Forward (+z, the initial facing direction).
    Z,
    /// The ground plane (x, z).
    Xz,
    /// x and y.
    Xy,
    /// y and z.
    Yz,
    /// All three.
    Xyz,
}

impl Axes {
    /// Indices into the last axis of `[.., 3]` tensors.
    pub fn indices(self) -> &'static [usize] {
        match self {
            Axes::X => &[0],
            Axes::Y => &[1],
            Axes::Z => &[2],
            Axes::Xz => &[0, 2],
            Axes::Xy => &[0, 1],
            Axes::Yz => &[1, 2],
            Axes::Xyz => &[0, 1, 2],
        }
    }
}

/// The frame positions are expressed in.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Space {
    /// World coordinates.
    #[default]
    World,
    /// HumanML3D's root frame ("ric"): relative to the pelvis on the ground plane (y stays
    /// absolute) and rotated so the body faces +z; +x is then always the character's left.
    Root,
}

/// Physical unit of a quantity, shared by the comparison bounds applied to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unit {
    /// Metres.
    Metre,
    /// Metres per second.
    MetrePerSecond,
    /// Metres per second squared.
    MetrePerSecondSquared,
}

impl Unit {
    /// Largest magnitude that is not absurd for a human motion (checked by validation).
    pub fn absurd_limit(self) -> f64 {
        match self {
            Unit::Metre | Unit::MetrePerSecond => 100.0,
            Unit::MetrePerSecondSquared => 1000.0,
        }
    }
}

impl Unit {
    /// Default hysteresis of [`super::Events`] in this unit: how far a signal goes back past
    /// its threshold between two events (claps: the wrists 5 cm further apart).
    pub fn event_hysteresis(self) -> f64 {
        match self {
            Unit::Metre => 0.05,
            Unit::MetrePerSecond => 0.1,
            Unit::MetrePerSecondSquared => 0.5,
        }
    }

    /// SI symbol.
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::Metre => "m",
            Unit::MetrePerSecond => "m/s",
            Unit::MetrePerSecondSquared => "m/s²",
        }
    }
}

impl fmt::Display for Unit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.symbol())
    }
}

/// A point of the body (or of the scene) per frame, `[B, T, 3]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Point {
    /// A skeleton joint: `joints[:, :, j]`.
    Joint(#[schemars(with = "JointName")] Joint),
    /// Midpoint of two joints, e.g. between the hands holding a ball (ProgMoGen `mid_point`).
    Midpoint(#[schemars(with = "[JointName; 2]")] [Joint; 2]),
    /// Centre of mass: mass-weighted bone midpoints (ProgMoGen `get_center_of_mass`, anchors §3.2).
    CentreOfMass(CentreOfMass),
    /// A fixed scene point `[x, y, z]` in metres (the same on every frame).
    FixedM(#[schemars(inner(range(min = -100.0, max = 100.0)))] [f64; 3]),
}

/// Options of [`Point::CentreOfMass`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CentreOfMass {
    /// Give the neck–head bone zero mass (ProgMoGen `get_center_of_mass_fixhead`).
    #[serde(default)]
    pub exclude_head: bool,
    /// An object carried between two joints, added as a point mass at their midpoint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load: Option<CarriedLoad>,
}

/// A carried object for [`CentreOfMass`]: PBG-2's heavy ball has `mass_ratio` 1.0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CarriedLoad {
    /// The object sits at the midpoint of these two joints.
    #[schemars(with = "[JointName; 2]")]
    pub between: [Joint; 2],
    /// Object mass divided by body mass (dimensionless, > 0).
    #[schemars(range(min = 0.0, max = 100.0))]
    pub mass_ratio: f64,
}

/// A differentiable per-frame measurement of the motion (ProgMoGen §3.2 atomic constraints).
/// Output `[B, T − lag, C]`; see the module docs.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Quantity {
    /// Position of `of` (m); `C` = number of `axes`; lag 0.
    Position(Position),
    /// `x[t] − x[since]` (m), e.g. a planted foot: lag 0.
    Displacement(Displacement),
    /// Forward difference × 20 fps (m/s): `v[t] = (x[t+1] − x[t])·fps`, lag 1. ProgMoGen's
    /// `get_velocity` is in m/frame: its 0.05 m/frame is 1 m/s here.
    Velocity(Derivative),
    /// ‖velocity‖ over `axes` (m/s), `C` = 1, lag 1.
    Speed(Derivative),
    /// Second difference × fps² (m/s²), lag 2.
    Acceleration(Derivative),
    /// ‖a − b‖ over `axes` (m), `C` = 1: between joints, or to a fixed point (ProgMoGen
    /// `dist_to_point`).
    Distance(Distance),
    /// Distance of `of` to the line through `point_m` along `direction` (m), `C` = 1
    /// (ProgMoGen `distance_3d_point_line`: ‖(p − p0) × d̂‖).
    DistanceToLine(DistanceToLine),
    /// Distance of `of` to the plane through `point_m` with `normal` (m), `C` = 1 (ProgMoGen
    /// `dist_to_plane`); signed: positive on the side the normal points to.
    DistanceToPlane(DistanceToPlane),
}

tag_first_deserialize!(Quantity, "kind", {
    Position(Position) = "position",
    Displacement(Displacement) = "displacement",
    Velocity(Derivative) = "velocity",
    Speed(Derivative) = "speed",
    Acceleration(Derivative) = "acceleration",
    Distance(Distance) = "distance",
    DistanceToLine(DistanceToLine) = "distance_to_line",
    DistanceToPlane(DistanceToPlane) = "distance_to_plane",
});

/// Fields of [`Quantity::Position`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Position {
    /// The measured point.
    pub of: Point,
    /// Kept coordinates.
    pub axes: Axes,
    /// World (default) or root-relative coordinates.
    #[serde(default)]
    pub space: Space,
}

/// Fields of [`Quantity::Displacement`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Displacement {
    /// The measured point.
    pub of: Point,
    /// Reference frame of the displacement.
    pub since: FrameRef,
    /// Kept coordinates.
    pub axes: Axes,
}

/// Fields of [`Quantity::Velocity`], [`Quantity::Speed`] and [`Quantity::Acceleration`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Derivative {
    /// The measured point.
    pub of: Point,
    /// Kept coordinates (for a speed: the norm is taken over them).
    pub axes: Axes,
}

/// Fields of [`Quantity::Distance`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Distance {
    /// First point.
    pub a: Point,
    /// Second point.
    pub b: Point,
    /// Coordinates the norm is taken over (`xz`: horizontal distance).
    pub axes: Axes,
}

/// Fields of [`Quantity::DistanceToLine`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DistanceToLine {
    /// The measured point.
    pub of: Point,
    /// A point on the line (m).
    #[schemars(inner(range(min = -100.0, max = 100.0)))]
    pub point_m: [f64; 3],
    /// Direction of the line (any non-zero length).
    pub direction: [f64; 3],
}

/// Fields of [`Quantity::DistanceToPlane`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DistanceToPlane {
    /// The measured point.
    pub of: Point,
    /// A point on the plane (m).
    #[schemars(inner(range(min = -100.0, max = 100.0)))]
    pub point_m: [f64; 3],
    /// Normal of the plane (any non-zero length).
    pub normal: [f64; 3],
    /// Keep the sign (positive on the normal's side) instead of the absolute distance.
    #[serde(default)]
    pub signed: bool,
}

impl Quantity {
    /// Frames lost to finite differences: the signal has `frames − lag` frames.
    pub fn lag(&self) -> u32 {
        match self {
            Quantity::Velocity(_) | Quantity::Speed(_) => 1,
            Quantity::Acceleration(_) => 2,
            _ => 0,
        }
    }

    /// Number of components `C` per frame.
    pub fn components(&self) -> usize {
        match self {
            Quantity::Position(Position { axes, .. })
            | Quantity::Displacement(Displacement { axes, .. })
            | Quantity::Velocity(Derivative { axes, .. })
            | Quantity::Acceleration(Derivative { axes, .. }) => axes.indices().len(),
            _ => 1,
        }
    }

    /// Unit of the values (and of any bound compared with them).
    pub fn unit(&self) -> Unit {
        match self {
            Quantity::Velocity(_) | Quantity::Speed(_) => Unit::MetrePerSecond,
            Quantity::Acceleration(_) => Unit::MetrePerSecondSquared,
            _ => Unit::Metre,
        }
    }
}

/// One frame of a signal with `n` frames (`n` = clip frames − the quantity's lag).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum FrameRef {
    /// Frame 0.
    First,
    /// Frame `n / 2` (floor; ProgMoGen's `L//2`).
    Middle,
    /// Frame `n − 1`.
    Last,
    /// An explicit 0-based frame index (20 fps), `< n`.
    Frame(#[schemars(range(max = super::limits::MAX_FRAMES))] u32),
    /// `round(f · (n − 1))` for `f` in [0, 1].
    Fraction(#[schemars(range(min = 0.0, max = 1.0))] f64),
}

impl FrameRef {
    /// The frame index in a signal of `n ≥ 1` frames; `None` when it lies outside.
    pub fn resolve(self, n: u32) -> Option<u32> {
        let last = n.checked_sub(1)?;
        let frame = match self {
            FrameRef::First => 0,
            FrameRef::Middle => n / 2,
            FrameRef::Last => last,
            FrameRef::Frame(frame) => frame,
            // In range by the check below; `as` saturates anyway.
            FrameRef::Fraction(f) if (0.0..=1.0).contains(&f) => (f * f64::from(last)).round() as u32,
            FrameRef::Fraction(_) => return None,
        };
        (frame <= last).then_some(frame)
    }
}

/// Frames a constraint applies to (before any [`Condition`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum FrameSelection {
    /// Every frame of the signal.
    #[default]
    All,
    /// These frames ("key-frame constraint", ProgMoGen `keyframe_list`).
    Keyframes(super::serde_util::NonEmpty<FrameRef>),
    /// Frames `from..=to`.
    Range(FrameRange),
}

/// Inclusive frame range of [`FrameSelection::Range`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FrameRange {
    /// First frame of the range.
    pub from: FrameRef,
    /// Last frame of the range (inclusive).
    pub to: FrameRef,
}

/// Keep only frames where a scalar quantity lies between `min` and `max` (strictly), or outside when
/// `outside` is set; e.g. "while the pelvis z is between 0.5 and 3.5". ProgMoGen's if-else: the
/// selection is a boolean mask of the current motion (no gradient through it); frames with no
/// value of the condition (lag) are dropped; an empty selection contributes 0, not NaN.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Condition {
    /// A scalar quantity (one component), e.g. the pelvis `z` position.
    pub of: Quantity,
    /// Lower bound, in the quantity's unit; none: unbounded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = -1000.0, max = 1000.0))]
    pub min: Option<f64>,
    /// Upper bound, in the quantity's unit; none: unbounded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = -1000.0, max = 1000.0))]
    pub max: Option<f64>,
    /// Select the complement (`z < min or z > max`).
    #[serde(default)]
    pub outside: bool,
}

/// How per-frame (and per-point) errors of a leaf become one number per sample, `[B]`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Reduce {
    /// Mean over the selected frames (ProgMoGen's usual `.mean()`).
    #[default]
    Mean,
    /// Sum over the selected frames.
    Sum,
    /// Worst frame.
    Max,
    /// Best frame: "at some frame" (e.g. a foot reaches a target once).
    Min,
}
