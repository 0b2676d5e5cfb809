//! Constraint expressions: atomic constraints and ProgMoGen's logical operators (ProgMoGen §3.2–3.3)
//! plus RG-DNO's counting constraints (RG-DNO supp. D, eqs. 15–16).
//!
//! Every expression evaluates to a non-negative error per sample, shape `[B]`, from joints
//! `[B, T, 22, 3]` (and, for [`Expr::StayNearInitial`], the unoptimised initial motion). A leaf
//! computes an error per selected frame (and point) and reduces it with its [`Reduce`]. Bounds such
//! as `target`, `min`, `max`, `threshold` are in the unit of their quantity ([`Quantity::unit`]).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::quantity::{Axes, CarriedLoad, Condition, FrameRange, FrameRef, FrameSelection, Quantity, Reduce};
use super::scene::{Body, Primitive};
use super::serde_util::{tag_first_deserialize, JointName, NonEmpty};
use crate::skeleton::Joint;

/// A constraint expression; JSON objects tagged by `op`.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(tag = "op", rename_all = "snake_case")]
pub enum Expr {
    /// "=": per frame `Σ_c (q_c − target_c)²` (ProgMoGen `equal`/`equal_sum`), or `Σ_c |q_c − target_c|`
    /// with `metric: absolute` (`equal_L1`).
    Equal(Equal),
    /// "<": per frame `Σ_c relu(q_c − max)` (ProgMoGen `less_than`, `max(E − margin, 0)`).
    LessThan(LessThan),
    /// ">": per frame `Σ_c relu(min − q_c)` (ProgMoGen `greater_than`, `max(margin − E, 0)`).
    GreaterThan(GreaterThan),
    /// AND: the sum of the arguments' errors (ProgMoGen `E1 + E2`).
    And(Args),
    /// OR: the minimum of the arguments' errors per sample (ProgMoGen `min(E1, E2)`).
    Or(Args),
    /// NOT as a hinge on the complement: `relu(margin − E(arg))`. Zero once the argument's error is
    /// at least `margin` (the argument is violated by that much). ProgMoGen writes NOT as `−E`,
    /// which is unbounded below and would swamp the sum; the hinge keeps every error ≥ 0.
    Not(Not),
    /// Counting (RG-DNO eqs. 15–16): `(n − target_count)²` with `n` a soft count of extrema.
    Count(Count),
    /// Steps taken, counted as footfalls, as a person counts steps (`metrics::footfalls`: every
    /// swing of either foot, its toe faster than 1 m/s until it slows under 0.5 m/s, travelling at
    /// least 15 cm): `(n − target_count)²` with `n` the judge's count and the gradient of the soft
    /// count (each toe's horizontal speed over 3 frames as events above 1.5 m/s with the band
    /// down to 1 m/s). Leg alternations stay a reported figure.
    Steps(Steps),
    /// Counted events (claps, touches, hops): `(n − target_count)²` with `n` the soft number of
    /// times a scalar signal enters the event region (below or above a threshold) and leaves it
    /// past a hysteresis band: the soft state `l = σ((θ − s)/w) − σ((s − θ − h)/w)` ∈ [−1, 1]
    /// (for `below`; mirrored for `above`), `h` the hysteresis, `w = h/4`, and
    /// `n = ½(Σ_t ½|l[t+1] − l[t]| + (1 + l[first])/2 + (1 + l[last])/2)`. Unlike
    /// [`Expr::Count`]'s extrema, an event needs the signal to reach the threshold (the hands to
    /// meet), and its check counts events with [`crate::metrics::event_count`] (the soft count
    /// adds ½ for a signal that goes into the band and back where the metric adds 0).
    Events(Events),
    /// A flight phase: both feet (ankles and toes) higher than `clearance_m` on at least
    /// `min_frames` consecutive frames somewhere in `frames` (and, with `when`, where the
    /// condition holds on every frame of the flight: "over the box" is the pelvis above it). Per
    /// frame `g[t] = relu(clearance_m − lowest foot joint's y)`; the error is the smallest, over
    /// the windows of `min_frames` consecutive selected frames, of the window's mean `g²` (m²);
    /// when no window meets `when`, no flight happened where it must: `clearance_m²`.
    Airborne(Airborne),
    /// An object held between two hands (ProgMoGen HOI-2): per frame
    /// `(‖a − b‖ − diameter_m)² + relu(r + clearance_m − d_torso)²`, with `r` the object's
    /// radius, its centre the hands' midpoint, and `d_torso` the distance from that centre to the
    /// torso's surface (the capsules of the spine bones); reduced over the selected frames.
    Carry(Carry),
    /// Body points against a scene primitive: the primitive's per-point error; each frame's worst
    /// point, reduced over the selected frames.
    Scene(SceneConstraint),
    /// Bone direction (ProgMoGen `loss_directional`): per frame `‖u − d/‖d‖‖²` with `u` the unit
    /// vector from the joint's parent to the joint (ProgMoGen detaches the norm of `u`; we keep
    /// its gradient, so the loss's gradient is the true one).
    BoneDirection(BoneDirection),
    /// Feet planted at given frames: per foot and frame `relu(y − max_height_m)² +
    /// relu(speed − max_speed_m_per_s)²` (speed term only when given), averaged (RG-DNO
    /// `loss_foot_both_ends`, `loss_ground_contact`).
    FootContact(FootContact),
    /// Limbs kept away from the torso: per pair and frame `relu(min_distance_m − ‖a − b‖)`
    /// (RG-DNO `loss_self_collision`, ProgMoGen HSI-5's wrist–pelvis term); each frame's closest
    /// pair, reduced over the frames as a scene constraint is (mean: over the violating frames),
    /// so one limb in the torso is not averaged away by the pairs that are clear.
    SelfCollision(SelfCollision),
    /// The centre of mass projected on the ground lies inside the support region, the convex hull
    /// (x, z) of the supporting feet's ankle and foot joints shrunk by `margin_m`: per frame
    /// `relu(signed_distance_outside + margin_m)²` (ProgMoGen §3.2 "centre-of-mass constraint").
    ComInSupport(ComInSupport),
    /// Regulariser: per frame `Σ_c (q_c − q_c^initial)²` summed over the quantities, with
    /// `q^initial` measured on the unoptimised first sample (ProgMoGen's `equal(sample, sample_0)`
    /// terms, here in joint space rather than feature space).
    StayNearInitial(StayNearInitial),
}

tag_first_deserialize!(Expr, "op", {
    Equal(Equal) = "equal",
    LessThan(LessThan) = "less_than",
    GreaterThan(GreaterThan) = "greater_than",
    And(Args) = "and",
    Or(Args) = "or",
    Not(Not) = "not",
    Count(Count) = "count",
    Steps(Steps) = "steps",
    Events(Events) = "events",
    Airborne(Airborne) = "airborne",
    Carry(Carry) = "carry",
    Scene(SceneConstraint) = "scene",
    BoneDirection(BoneDirection) = "bone_direction",
    FootContact(FootContact) = "foot_contact",
    SelfCollision(SelfCollision) = "self_collision",
    ComInSupport(ComInSupport) = "com_in_support",
    StayNearInitial(StayNearInitial) = "stay_near_initial",
});

/// Distance used by [`Expr::Equal`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    /// Squared error.
    #[default]
    Squared,
    /// Absolute error.
    Absolute,
}

/// Fields of [`Expr::Equal`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Equal {
    /// The measured quantity.
    pub quantity: Quantity,
    /// Target, one value per component of the quantity, in its unit.
    #[schemars(length(min = 1, max = 3), inner(range(min = -1000.0, max = 1000.0)))]
    pub target: Vec<f64>,
    /// Squared (default) or absolute error.
    #[serde(default)]
    pub metric: Metric,
    /// Frames the constraint applies to (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
    /// Further keep only frames meeting this condition.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub when: Option<Condition>,
    /// Reduction over frames (default: mean).
    #[serde(default)]
    pub reduce: Reduce,
}

/// Fields of [`Expr::LessThan`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LessThan {
    /// The measured quantity.
    pub quantity: Quantity,
    /// Upper bound for every component, in the quantity's unit.
    #[schemars(range(min = -1000.0, max = 1000.0))]
    pub max: f64,
    /// Frames the constraint applies to (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
    /// Further keep only frames meeting this condition.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub when: Option<Condition>,
    /// Reduction over frames (default: mean).
    #[serde(default)]
    pub reduce: Reduce,
}

/// Fields of [`Expr::GreaterThan`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GreaterThan {
    /// The measured quantity.
    pub quantity: Quantity,
    /// Lower bound for every component, in the quantity's unit.
    #[schemars(range(min = -1000.0, max = 1000.0))]
    pub min: f64,
    /// Frames the constraint applies to (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
    /// Further keep only frames meeting this condition.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub when: Option<Condition>,
    /// Reduction over frames (default: mean).
    #[serde(default)]
    pub reduce: Reduce,
}

/// Arguments of [`Expr::And`] and [`Expr::Or`] (at least one).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Args {
    /// The combined expressions.
    pub args: NonEmpty<Expr>,
}

/// Fields of [`Expr::Not`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Not {
    /// The negated expression.
    pub arg: Box<Expr>,
    /// Error of `arg` at which NOT is satisfied (> 0, in `arg`'s error units).
    #[schemars(range(min = 0.0, max = 1000.0))]
    pub margin: f64,
}

/// Which extrema [`Expr::Count`] counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Extremum {
    /// Local maxima above `threshold` (eq. 15: steps as foot-speed peaks):
    /// `Σ_t σ(T(s[t]−s[t+1]))·σ(T(s[t]−s[t−1]))·σ(T(s[t]−θ))`.
    Peaks,
    /// Local minima below `threshold` (eq. 16: claps and touches as distance minima):
    /// `Σ_t σ(T(s[t+1]−s[t]))·σ(T(s[t−1]−s[t]))·σ(T(θ−s[t]))`.
    Valleys,
}

/// Fields of [`Expr::Count`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Count {
    /// Scalar signals whose counts are added (e.g. the speeds of both feet for steps).
    pub signals: NonEmpty<Quantity>,
    /// Peaks or valleys.
    pub extremum: Extremum,
    /// θ, in the signals' unit.
    #[schemars(range(min = -1000.0, max = 1000.0))]
    pub threshold: f64,
    /// Required number of extrema.
    #[schemars(range(max = super::limits::MAX_FRAMES))]
    pub target_count: u32,
    /// Sigmoid scale T, per unit of the signal (RG-DNO uses 10000).
    #[serde(default = "default_sharpness")]
    #[schemars(range(min = 0.0, max = 1000000.0))]
    pub sharpness: f64,
    /// Width (frames, odd) of the box filter applied to each signal first; 1: none.
    #[serde(default = "default_smoothing")]
    #[schemars(range(min = 1, max = 101))]
    pub smoothing_frames: u32,
    /// Frames searched (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
}

/// Fields of [`Expr::Steps`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Steps {
    /// Required number of steps over the whole motion, counted as footfalls: every step of either
    /// foot, the first from a standing start included ("6 steps" is 6).
    #[schemars(range(max = 1000))]
    pub target_count: u32,
}

/// Where [`Expr::Events`]'s event region lies, e.g. `{"below": 0.08}` for hands that meet.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum EventRegion {
    /// The signal is below this value (a clap: the wrists closer than it).
    Below(#[schemars(range(min = -1000.0, max = 1000.0))] f64),
    /// The signal is above this value (a hop: the pelvis higher than it).
    Above(#[schemars(range(min = -1000.0, max = 1000.0))] f64),
}

/// Fields of [`Expr::Events`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Events {
    /// A scalar quantity (one component), e.g. the distance between the wrists.
    pub signal: Quantity,
    /// The event region: `{"below": θ}` or `{"above": θ}` in the signal's unit.
    pub event: EventRegion,
    /// How far past θ the signal must go back before another event can start, in the signal's
    /// unit (> 0; default: 0.05 m, 0.1 m/s or 0.5 m/s² by its unit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 0.0, max = 1000.0))]
    pub hysteresis: Option<f64>,
    /// Required number of events.
    #[schemars(range(max = super::limits::MAX_FRAMES))]
    pub target_count: u32,
    /// Frames searched (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
}

impl Expr {
    /// Calls `visit` on this expression and then, depth first in order, on every expression
    /// under its `and`, `or` and `not`, each with its JSON path: `path` for this one,
    /// `path.args[i]` and `path.arg` below it. The one walk over the tree, for validation
    /// and for everything a program is searched for (scene primitives, carried objects,
    /// position targets).
    pub fn walk<'a>(&'a self, path: &str, visit: &mut impl FnMut(&'a Expr, &str)) {
        visit(self, path);
        match self {
            Expr::And(args) | Expr::Or(args) => {
                for (i, arg) in args.args.iter().enumerate() {
                    arg.walk(&index(&field(path, "args"), i), visit);
                }
            }
            Expr::Not(not) => not.arg.walk(&field(path, "arg"), visit),
            _ => {}
        }
    }
}

/// The JSON path of field `name` under `path` (`name` itself at the top).
pub(super) fn field(path: &str, name: &str) -> String {
    if path.is_empty() {
        name.to_owned()
    } else {
        format!("{path}.{name}")
    }
}

/// The JSON path of element `i` of the array at `path`.
pub(super) fn index(path: &str, i: usize) -> String {
    format!("{path}[{i}]")
}

impl Events {
    /// The hysteresis, given or the default of the signal's unit.
    pub fn hysteresis(&self) -> f64 {
        self.hysteresis.unwrap_or_else(|| self.signal.unit().event_hysteresis())
    }
}

/// Fields of [`Expr::Airborne`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Airborne {
    /// Height both feet's joints must exceed (m); the report calls a frame airborne above 0.1.
    #[schemars(range(min = 0.0, max = 100.0))]
    pub clearance_m: f64,
    /// Consecutive frames of flight (20 fps; a jump over a hurdle: about 4).
    #[schemars(range(min = 1, max = super::limits::MAX_FRAMES))]
    pub min_frames: u32,
    /// Frames where the flight may happen (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
    /// Where the flight must happen, e.g. while the pelvis is over the obstacle (every frame of
    /// the flight meets it; no gradient flows through the selection).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub when: Option<Condition>,
}

/// Fields of [`Expr::Carry`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Carry {
    /// The hands holding the object (default: both wrists).
    #[serde(default = "default_hands")]
    #[schemars(with = "[JointName; 2]")]
    pub hands: [Joint; 2],
    /// Diameter of the object, the distance between the hands (m).
    #[schemars(range(min = 0.0, max = 100.0))]
    pub diameter_m: f64,
    /// Gap kept between the object and the torso's surface (m).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub clearance_m: f64,
    /// Frames the object is held (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
    /// Reduction over frames (default: mean).
    #[serde(default)]
    pub reduce: Reduce,
}

fn default_hands() -> [Joint; 2] {
    [Joint::LeftWrist, Joint::RightWrist]
}

fn default_sharpness() -> f64 {
    10_000.0
}

fn default_smoothing() -> u32 {
    1
}

/// Fields of [`Expr::Scene`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SceneConstraint {
    /// Tested body points.
    pub body: Body,
    /// The obstacle or region.
    pub primitive: Primitive,
    /// Frames the constraint applies to (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
    /// Further keep only frames meeting this condition (e.g. while the pelvis is between two z).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub when: Option<Condition>,
    /// Reduction over frames of each frame's worst point (default: mean, over the frames that
    /// violate, so a short violation is not averaged away by the clear frames).
    #[serde(default)]
    pub reduce: Reduce,
}

/// Fields of [`Expr::BoneDirection`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BoneDirection {
    /// The bone from this joint's parent to it (not the pelvis).
    #[schemars(with = "JointName")]
    pub joint: Joint,
    /// Wanted direction (any non-zero length).
    pub direction: [f64; 3],
    /// Frames the constraint applies to (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
    /// Reduction over frames (default: mean).
    #[serde(default)]
    pub reduce: Reduce,
}

/// Fields of [`Expr::FootContact`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FootContact {
    /// Foot joints (`left_ankle`, `right_ankle`, `left_foot`, `right_foot`).
    #[schemars(with = "NonEmpty<JointName>")]
    pub feet: NonEmpty<Joint>,
    /// Frames of contact (of the clip; a speed at the last frame uses the backward difference);
    /// may be left out when `during` is given.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub at: Vec<FrameRef>,
    /// A stretch of contact: every frame `from..=to` (with `at`'s frames), e.g. "stand on the
    /// right foot for two seconds" is the right foot in contact during 40 frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub during: Option<FrameRange>,
    /// Height below which a foot counts as on the ground (m).
    #[schemars(range(min = 0.0, max = 100.0))]
    pub max_height_m: f64,
    /// Speed below which a foot counts as still (m/s); absent: no speed term.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub max_speed_m_per_s: Option<f64>,
}

/// Fields of [`Expr::SelfCollision`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SelfCollision {
    /// Moving joints kept away (e.g. elbows and wrists).
    #[schemars(with = "NonEmpty<JointName>")]
    pub limbs: NonEmpty<Joint>,
    /// Joints they must avoid (e.g. pelvis and spine); disjoint from `limbs`.
    #[schemars(with = "NonEmpty<JointName>")]
    pub torso: NonEmpty<Joint>,
    /// Minimum distance between every limb–torso pair (m).
    #[schemars(range(min = 0.0, max = 100.0))]
    pub min_distance_m: f64,
    /// Coordinates the distance is measured over (`xz`: horizontal).
    pub axes: Axes,
    /// Frames the constraint applies to (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
    /// Reduction over frames of each frame's closest pair (default: mean, over the frames that
    /// violate).
    #[serde(default)]
    pub reduce: Reduce,
}

/// Supporting feet of [`Expr::ComInSupport`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Support {
    /// Both feet: the hull of both ankles and both foot joints.
    BothFeet,
    /// Standing on the left foot.
    LeftFoot,
    /// Standing on the right foot.
    RightFoot,
}

/// Fields of [`Expr::ComInSupport`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ComInSupport {
    /// Which feet carry the body.
    pub support: Support,
    /// Distance the projected centre of mass keeps inside the region's edge (m).
    #[serde(default)]
    #[schemars(range(min = 0.0, max = 100.0))]
    pub margin_m: f64,
    /// A carried object counted in the centre of mass (PBG-2's heavy ball).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub load: Option<CarriedLoad>,
    /// Frames the constraint applies to (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
    /// Reduction over frames (default: mean).
    #[serde(default)]
    pub reduce: Reduce,
}

/// Fields of [`Expr::StayNearInitial`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct StayNearInitial {
    /// Quantities kept close to their values on the initial sample.
    pub quantities: NonEmpty<Quantity>,
    /// Frames the constraint applies to (default: all).
    #[serde(default)]
    pub frames: FrameSelection,
}
