//! Scene primitives tested against a set of body points: walls forming a gap, an overhead
//! barrier, a hurdle, the ground, a box region, a wall (half-space) and a balance beam.
//!
//! Each primitive maps the body points `[B, T, P, 3]` to a per-point, per-frame error `[B, T, P]`
//! (a penetration depth in metres, or a squared distance for the beam); the scene constraint then
//! reduces it. Gates such as `z_range_m` test each point's own coordinate, as the walls and
//! barriers of ProgMoGen HSI-4/HSI-5 and RG-DNO Task-1/2 exist only over that stretch of the path.
//! Axis-aligned primitives assume the canonical walk along +z. A point outside a gate has error 0
//! and still counts in a mean, so an empty gate gives 0, never NaN (ProgMoGen HSI-4 averages over
//! the gated frames only; its weights therefore differ by the gated fraction).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::serde_util::{tag_first_deserialize, JointName, NonEmpty};
use crate::skeleton::Joint;

/// The body points a scene constraint tests: joints and, optionally, surface points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Body {
    /// Which skeleton joints.
    pub joints: JointSet,
    /// Also test points sampled on the body surface (the capsule body model that stands in for
    /// RG-DNO's SMPL vertices).
    #[serde(default)]
    pub surface: bool,
}

/// A set of joints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum JointSet {
    /// All 22 joints.
    All,
    /// Only these joints.
    Only(#[schemars(with = "NonEmpty<JointName>")] NonEmpty<Joint>),
}

/// A scene primitive. Lengths in metres; `margin_m` (≥ 0) keeps points that much further from
/// the obstacle; `z_range_m` = `[min, max]` gates by each point's z (absent: the whole path), and
/// `x_range_m` likewise by x where a primitive has one (a table is an overhead barrier with both).
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Primitive {
    /// Two walls parallel to z at `x = centre_x_m ± width_m / 2`: error
    /// `relu(|x − centre_x_m| − (width_m/2 − margin_m))` (ProgMoGen HSI-5 `less_than`/`greater_than`
    /// on x; RG-DNO Task-1).
    Gap(Gap),
    /// A barrier whose underside is at `underside_height_m`: error `relu(y − (h − margin_m))` for
    /// points inside `z_range_m` (and `x_range_m` when given: a table top) (HSI-4, RG-DNO Task-2).
    OverheadBarrier(OverheadBarrier),
    /// A hurdle of `height_m` standing on the ground: error `relu(h + margin_m − y)` for points
    /// inside `z_range_m` (and `x_range_m` when given) (they must pass above it).
    Hurdle(Hurdle),
    /// The ground `y = height_m`: error `relu(height_m − y)`.
    Ground(Ground),
    /// Stay inside an axis-aligned box: per bounded axis `relu(lo − c) + relu(c − hi)`, summed over
    /// axes (HSI-3's 2 m square is `x_range_m = z_range_m = [−1, 1]`).
    InsideBox(InsideBox),
    /// A wall (plane through `point_m`); points stay on the side `normal` points to:
    /// error `relu(margin_m − signed_distance)`.
    Wall(Wall),
    /// A balance beam: the line through `point_m` along `direction`; error
    /// `relu(distance_to_line − half_width_m)²` (GEO-2 with `half_width_m` 0, squared as
    /// ProgMoGen's `loss_distance_3d_point_line`). With `horizontal` the distance is taken in the
    /// ground plane (x, z), so a foot lifted above the beam is still on it; with `extent_m` only
    /// points whose position along the beam lies inside it are tested (a beam along part of the
    /// path).
    BalanceBeam(BalanceBeam),
}

tag_first_deserialize!(Primitive, "kind", {
    Gap(Gap) = "gap",
    OverheadBarrier(OverheadBarrier) = "overhead_barrier",
    Hurdle(Hurdle) = "hurdle",
    Ground(Ground) = "ground",
    InsideBox(InsideBox) = "inside_box",
    Wall(Wall) = "wall",
    BalanceBeam(BalanceBeam) = "balance_beam",
});

/// Fields of [`Primitive::Gap`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Gap {
    /// x of the gap's centre line (m).
    #[schemars(range(min = -100.0, max = 100.0))]
    pub centre_x_m: f64,
    /// Distance between the walls (m, > 2·margin_m).
    #[schemars(range(min = 0.0, max = 100.0))]
    pub width_m: f64,
    /// Clearance kept from each wall (m).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub margin_m: f64,
    /// Where the walls are along z (m); absent: everywhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(inner(inner(range(min = -100.0, max = 100.0))))]
    pub z_range_m: Option<[f64; 2]>,
}

/// Fields of [`Primitive::OverheadBarrier`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct OverheadBarrier {
    /// Height of the barrier's underside above the ground (m).
    #[schemars(range(min = 0.0, max = 100.0))]
    pub underside_height_m: f64,
    /// Clearance kept below it (m).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub margin_m: f64,
    /// Where the barrier is along z (m).
    #[schemars(inner(range(min = -100.0, max = 100.0)))]
    pub z_range_m: [f64; 2],
    /// Where the barrier is across, along x (m); absent: it spans the whole width.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(inner(inner(range(min = -100.0, max = 100.0))))]
    pub x_range_m: Option<[f64; 2]>,
}

/// Fields of [`Primitive::Hurdle`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Hurdle {
    /// Height of the hurdle's top (m).
    #[schemars(range(min = 0.0, max = 100.0))]
    pub height_m: f64,
    /// Clearance kept above it (m).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub margin_m: f64,
    /// Where the hurdle is along z (m).
    #[schemars(inner(range(min = -100.0, max = 100.0)))]
    pub z_range_m: [f64; 2],
    /// Where the hurdle is across, along x (m); absent: it spans the whole width.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(inner(inner(range(min = -100.0, max = 100.0))))]
    pub x_range_m: Option<[f64; 2]>,
}

/// Fields of [`Primitive::Ground`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Ground {
    /// Height of the ground (m); HumanML3D puts it at 0.
    #[serde(default)]
    #[schemars(range(min = -100.0, max = 100.0))]
    pub height_m: f64,
}

/// Fields of [`Primitive::InsideBox`]: each range is `[min, max]` in metres; absent: unbounded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct InsideBox {
    /// Allowed x range (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(inner(inner(range(min = -100.0, max = 100.0))))]
    pub x_range_m: Option<[f64; 2]>,
    /// Allowed y range (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(inner(inner(range(min = -100.0, max = 100.0))))]
    pub y_range_m: Option<[f64; 2]>,
    /// Allowed z range (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(inner(inner(range(min = -100.0, max = 100.0))))]
    pub z_range_m: Option<[f64; 2]>,
}

/// Fields of [`Primitive::Wall`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Wall {
    /// A point on the wall (m).
    #[schemars(inner(range(min = -100.0, max = 100.0)))]
    pub point_m: [f64; 3],
    /// Normal pointing to the free side (any non-zero length).
    pub normal: [f64; 3],
    /// Clearance kept from the wall (m).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub margin_m: f64,
}

/// Fields of [`Primitive::BalanceBeam`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BalanceBeam {
    /// A point on the beam's centre line (m).
    #[schemars(inner(range(min = -100.0, max = 100.0)))]
    pub point_m: [f64; 3],
    /// Direction of the beam (any non-zero length).
    pub direction: [f64; 3],
    /// Half the beam's width (m); 0: a line.
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub half_width_m: f64,
    /// Measure the distance in the ground plane (x, z) only: a beam on the floor, where lifting
    /// the swing foot does not leave it. The direction then needs a horizontal part.
    #[serde(default)]
    pub horizontal: bool,
    /// `[from, to]`: the stretch of the beam, in metres along `direction` from `point_m`; points
    /// beyond it are not tested. Absent: an endless line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(inner(inner(range(min = -100.0, max = 100.0))))]
    pub extent_m: Option<[f64; 2]>,
}
