//! Whether each constraint is met, in natural units: metres of penetration or to a target,
//! degrees off a direction, counted events against the target. The losses of [`super::Node`]
//! are squared, margined and averaged for optimisation, which can hide a violation; these
//! figures take the worst frame and point (or the best frame for "at some frame" constraints)
//! and are judged against the stated tolerances below.

use candle_core::{Tensor, D};
use serde::{Deserialize, Serialize};

use super::compiled::CompiledProgram;
use super::error::ConstraintError;
use super::frames::Frames;
use super::geometry::{constant, joint, norm, select_axes};
use super::node::{body_points, com_outside_support, Comparison, Node};
use super::scene::{is_obstacle, primitive_error};
use super::signal::signal;
use super::{carry, flight};
use crate::program::{Axes, Condition, EventRegion, Primitive, Quantity, Reduce};
use crate::skeleton::Joint;

/// Tolerance on distances, penetrations and positions, m (the bar for ProgMoGen's HSI
/// tasks: within 5 cm).
pub const DISTANCE_TOLERANCE_M: f64 = 0.05;
/// Tolerance on feet that must be planted and on limbs kept off the torso, m.
pub const CONTACT_TOLERANCE_M: f64 = 0.02;
/// Tolerance on velocities and speeds, m/s.
pub const SPEED_TOLERANCE_M_PER_S: f64 = 0.1;
/// Tolerance on accelerations, m/s².
pub const ACCELERATION_TOLERANCE_M_PER_S2: f64 = 0.5;
/// Tolerance on a bone's direction, degrees.
pub const ANGLE_TOLERANCE_DEG: f64 = 15.0;
/// Counts must be exact: |counted − target| below this.
pub const COUNT_TOLERANCE: f64 = 0.5;

/// Unit of a [`Check`]'s value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Unit {
    /// Metres.
    M,
    /// Metres per second.
    MPerS,
    /// Metres per second squared.
    MPerS2,
    /// Degrees.
    Deg,
    /// A number of events.
    Count,
}

impl std::fmt::Display for Unit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Unit::M => "m",
            Unit::MPerS => "m/s",
            Unit::MPerS2 => "m/s²",
            Unit::Deg => "°",
            Unit::Count => "",
        })
    }
}

/// One measured figure of a constraint, per sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// What is measured, in words ("penetration into overhead_barrier", "position off target").
    pub what: String,
    /// Unit of `value` and `tolerance`.
    pub unit: Unit,
    /// The violation per sample (0 = met exactly), in `unit`.
    pub value: Vec<f64>,
    /// A sample passes this check when its value is at most this.
    pub tolerance: f64,
}

impl Check {
    fn passes(&self, sample: usize) -> bool {
        self.value.get(sample).is_some_and(|v| *v <= self.tolerance)
    }
}

/// A constraint's checks and its verdict per sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Satisfaction {
    /// The constraint's id.
    pub id: String,
    /// Every leaf's figure.
    pub checks: Vec<Check>,
    /// Whether each sample meets the constraint (the logic of `and`/`or`/`not` applied to the
    /// leaves' verdicts).
    pub pass: Vec<bool>,
}

impl CompiledProgram {
    /// Whether every sample of joints `[B, T, 22, 3]` meets every constraint at its tolerance
    /// (the verdicts of [`CompiledProgram::satisfaction`]).
    pub fn met_by_every_sample(&self, joints: &Tensor, initial: Option<&Tensor>) -> Result<bool, ConstraintError> {
        Ok(self.met_per_sample(joints, initial)?.iter().all(|&met| met))
    }

    /// Whether each sample of joints `[B, T, 22, 3]` meets every constraint at its tolerance,
    /// `[B]`.
    pub fn met_per_sample(&self, joints: &Tensor, initial: Option<&Tensor>) -> Result<Vec<bool>, ConstraintError> {
        let mut met = vec![true; joints.dim(0)?];
        for constraint in self.satisfaction(joints, initial)? {
            for (m, pass) in met.iter_mut().zip(constraint.pass) {
                *m &= pass;
            }
        }
        Ok(met)
    }

    /// Every constraint's figures in natural units on joints `[B, T, 22, 3]` (no gradient);
    /// `initial` as for [`CompiledProgram::evaluate`].
    pub fn satisfaction(
        &self,
        joints: &Tensor,
        initial: Option<&Tensor>,
    ) -> Result<Vec<Satisfaction>, ConstraintError> {
        let joints = joints.detach().contiguous()?;
        let batch = joints.dim(0)?;
        self.constraints
            .iter()
            .map(|c| {
                let (checks, pass) = c.node.judge(&joints, initial, batch)?;
                Ok(Satisfaction { id: c.id.clone(), checks, pass })
            })
            .collect()
    }
}

/// Checks and the verdict per sample.
type Judged = (Vec<Check>, Vec<bool>);

impl Node {
    /// The node's checks and verdicts on joints `[B, T, 22, 3]` for `batch` samples: a leaf
    /// passes where all its checks do; `and`, `or` and `not` combine their arguments' verdicts.
    fn judge(&self, joints: &Tensor, initial: Option<&Tensor>, batch: usize) -> Result<Judged, ConstraintError> {
        let leaf = |check: Check| Ok(all_pass(vec![check], batch));
        match self {
            Node::And(args) => combine(args, true, joints, initial, batch),
            Node::Or(args) => combine(args, false, joints, initial, batch),
            Node::Not { arg, .. } => {
                let (checks, pass) = arg.judge(joints, initial, batch)?;
                Ok((checks, pass.into_iter().map(|p| !p).collect()))
            }
            Node::Compare { quantity, comparison, frames, when, reduce } => {
                leaf(compare_check(joints, quantity, comparison, frames, when, *reduce)?)
            }
            Node::Count { target, .. } => {
                // The node's own soft count: its error is (n − target)².
                let off = self.eval(joints, initial)?.sqrt()?.to_dtype(candle_core::DType::F64)?.to_vec1::<f64>()?;
                leaf(Check {
                    what: format!("count off the target {target}"),
                    unit: Unit::Count,
                    value: off,
                    tolerance: COUNT_TOLERANCE,
                })
            }
            Node::Steps { target, .. } => {
                let counted: Vec<f64> =
                    super::count::judged_footfalls(joints)?.into_iter().map(|n| (n - target).abs()).collect();
                leaf(Check {
                    what: format!("steps (footfalls) off the target {target}"),
                    unit: Unit::Count,
                    value: counted,
                    tolerance: COUNT_TOLERANCE,
                })
            }
            Node::Events { signal: quantity, region, hysteresis, target, frames, .. } => {
                leaf(events_check(joints, quantity, *region, *hysteresis, *target, frames)?)
            }
            Node::Airborne { clearance, length, starts, when } => {
                leaf(airborne_check(joints, *clearance, *length, starts, when)?)
            }
            Node::Carry { hands, diameter, clearance, frames, reduce } => {
                let checks = carry_checks(joints, *hands, *diameter, *clearance, frames, *reduce)?;
                Ok(all_pass(checks, batch))
            }
            Node::Scene { joints: set, surface, primitive, frames, when, reduce } => {
                leaf(scene_check(joints, set, *surface, primitive, frames, when, *reduce)?)
            }
            Node::BoneDirection { joint: j, parent, direction, frames, reduce } => {
                leaf(bone_direction_check(joints, *j, *parent, direction, frames, *reduce)?)
            }
            Node::FootContact { feet, at, max_height, max_speed } => {
                let checks = foot_contact_checks(joints, feet, at, *max_height, *max_speed, batch)?;
                Ok(all_pass(checks, batch))
            }
            Node::SelfCollision { limbs, torso, min_distance, axes, frames, reduce } => {
                leaf(self_collision_check(joints, limbs, torso, *min_distance, *axes, frames, *reduce)?)
            }
            Node::ComInSupport { support: feet, load, frames, reduce, .. } => {
                let outside = com_outside_support(joints, *feet, load, frames)?.relu()?;
                let value = over_frames(&outside, None, *reduce == Reduce::Min)?;
                leaf(Check {
                    what: "centre of mass outside the support".into(),
                    unit: Unit::M,
                    value,
                    tolerance: CONTACT_TOLERANCE_M,
                })
            }
            Node::StayNearInitial { quantities, .. } => {
                // Its loss is the mean squared change; the natural figure is its root.
                let rms = self.eval(joints, initial)?.sqrt()?.to_dtype(candle_core::DType::F64)?.to_vec1::<f64>()?;
                let (unit, tolerance) = quantities.first().map_or((Unit::M, DISTANCE_TOLERANCE_M), unit_of);
                leaf(Check { what: "RMS change from the initial motion".into(), unit, value: rms, tolerance })
            }
        }
    }
}

/// Checks that a sample passes when it passes them all.
fn all_pass(checks: Vec<Check>, batch: usize) -> Judged {
    let pass = (0..batch).map(|b| checks.iter().all(|c| c.passes(b))).collect();
    (checks, pass)
}

/// The arguments' checks, with a sample passing when all (`all`) or any of them pass.
fn combine(
    args: &[Node],
    all: bool,
    joints: &Tensor,
    initial: Option<&Tensor>,
    batch: usize,
) -> Result<Judged, ConstraintError> {
    let mut checks = Vec::new();
    let mut pass = vec![all; batch];
    for arg in args {
        let (c, p) = arg.judge(joints, initial, batch)?;
        checks.extend(c);
        for (acc, p) in pass.iter_mut().zip(p) {
            *acc = if all { *acc && p } else { *acc || p };
        }
    }
    Ok((checks, pass))
}

/// A comparison's figure: per frame, the distance to the target or the largest excess over the
/// bound of any component (in the quantity's unit), then the worst (or, for `min`, the best)
/// selected frame meeting `when`.
fn compare_check(
    joints: &Tensor,
    quantity: &Quantity,
    comparison: &Comparison,
    frames: &Frames,
    when: &Option<Condition>,
    reduce: Reduce,
) -> Result<Check, ConstraintError> {
    let q = signal(joints, quantity)?; // [B, n, C]
    let per_frame = match comparison {
        Comparison::Equal { target, .. } => {
            let target = constant(target, q.dtype(), q.device())?;
            norm(&q.broadcast_sub(&target)?)?
        }
        Comparison::LessThan(max) => (q - *max)?.relu()?.max(D::Minus1)?,
        Comparison::GreaterThan(min) => (*min - q)?.relu()?.max(D::Minus1)?,
    }; // [B, n]
    let mask = frames.condition_mask(joints, when, per_frame.dim(1)?)?;
    let value = over_frames(&frames.select(&per_frame)?, mask.as_ref(), reduce == Reduce::Min)?;
    let (unit, tolerance) = unit_of(quantity);
    let relation = match comparison {
        Comparison::Equal { .. } => "off target".to_owned(),
        Comparison::LessThan(max) => format!("above {max}"),
        Comparison::GreaterThan(min) => format!("below {min}"),
    };
    Ok(Check { what: format!("{} {relation}", kind_name(quantity)), unit, value, tolerance })
}

/// Events counted (with hysteresis) on the selected frames, off the target.
fn events_check(
    joints: &Tensor,
    quantity: &Quantity,
    region: EventRegion,
    hysteresis: f64,
    target: f64,
    frames: &Frames,
) -> Result<Check, ConstraintError> {
    let s = frames.select(&signal(joints, quantity)?.squeeze(D::Minus1)?)?;
    let off = super::count::judged_events(&s, region, hysteresis)?.into_iter().map(|n| (n - target).abs()).collect();
    let (relation, threshold) = match region {
        EventRegion::Below(t) => ("below", t),
        EventRegion::Above(t) => ("above", t),
    };
    Ok(Check {
        what: format!("events ({} {relation} {threshold}) off the target {target}", kind_name(quantity)),
        unit: Unit::Count,
        value: off,
        tolerance: COUNT_TOLERANCE,
    })
}

/// The best flight: the window (meeting `when`) whose lowest foot frame comes closest to
/// clearing, m; none meeting it: the whole clearance is missing.
fn airborne_check(
    joints: &Tensor,
    clearance: f64,
    length: usize,
    starts: &Tensor,
    when: &Option<Condition>,
) -> Result<Check, ConstraintError> {
    let deficit = flight::flight_deficit(joints, clearance)?.to_dtype(candle_core::DType::F64)?;
    let valid = match flight::windows_meeting(joints, when, starts, length)? {
        Some(valid) => Some(valid.to_dtype(candle_core::DType::F64)?.to_vec2::<f64>()?),
        None => None,
    };
    let starts = starts.to_vec1::<u32>()?;
    let value = deficit
        .to_vec2::<f64>()?
        .iter()
        .enumerate()
        .map(|(b, row)| {
            let worst = |s: u32| row[s as usize..s as usize + length].iter().copied().fold(0.0, f64::max);
            let kept = |w: &usize| valid.as_ref().is_none_or(|v| v[b][*w] > 0.5);
            let best = (0..starts.len()).filter(kept).map(|w| worst(starts[w])).fold(f64::INFINITY, f64::min);
            if best.is_finite() {
                best
            } else {
                clearance
            }
        })
        .collect();
    Ok(Check {
        what: format!("a foot below {clearance} m in the best {length}-frame flight"),
        unit: Unit::M,
        value,
        tolerance: CONTACT_TOLERANCE_M,
    })
}

/// Carrying: the hands' gap to the object's diameter and the object's intrusion within
/// `clearance` of the torso, m, over the selected frames.
fn carry_checks(
    joints: &Tensor,
    hands: [Joint; 2],
    diameter: f64,
    clearance: f64,
    frames: &Frames,
    reduce: Reduce,
) -> Result<Vec<Check>, ConstraintError> {
    let (gap, intrusion) = carry::carry_errors(joints, hands, diameter, clearance)?;
    let best = reduce == Reduce::Min;
    Ok(vec![
        Check {
            what: format!("hands off the object's {diameter} m"),
            unit: Unit::M,
            value: over_frames(&frames.select(&gap.abs()?)?, None, best)?,
            tolerance: DISTANCE_TOLERANCE_M,
        },
        Check {
            what: format!("object within {clearance} m of the torso"),
            unit: Unit::M,
            value: over_frames(&frames.select(&intrusion)?, None, best)?,
            tolerance: CONTACT_TOLERANCE_M,
        },
    ])
}

/// A scene constraint: the deepest penetration of an obstacle, or the distance off (or
/// outside) a target primitive, of the body's points, m, over the selected frames meeting
/// `when`.
fn scene_check(
    joints: &Tensor,
    set: &Option<Tensor>,
    surface: bool,
    primitive: &Primitive,
    frames: &Frames,
    when: &Option<Condition>,
    reduce: Reduce,
) -> Result<Check, ConstraintError> {
    let points = frames.select(&body_points(joints, set, surface)?)?;
    let depth = primitive_error(&points, primitive, true)?.max(D::Minus1)?; // [B, F]
    let depth = match primitive {
        Primitive::BalanceBeam(_) => depth.sqrt()?, // its error is squared
        _ => depth,
    };
    let mask = frames.condition_mask(joints, when, joints.dim(1)?)?;
    let value = over_frames(&depth, mask.as_ref(), reduce == Reduce::Min)?;
    let what = match primitive {
        Primitive::InsideBox(_) => "distance outside the inside_box".to_owned(),
        _ if is_obstacle(primitive) => format!("penetration into {}", primitive_name(primitive)),
        _ => format!("distance off the {}", primitive_name(primitive)),
    };
    Ok(Check { what, unit: Unit::M, value, tolerance: DISTANCE_TOLERANCE_M })
}

/// The angle between the bone from `parent` to `j` and `direction`, degrees, over the
/// selected frames.
fn bone_direction_check(
    joints: &Tensor,
    j: Joint,
    parent: Joint,
    direction: &[f64; 3],
    frames: &Frames,
    reduce: Reduce,
) -> Result<Check, ConstraintError> {
    let bone = frames.select(&(joint(joints, j)? - joint(joints, parent)?)?)?;
    let u = bone.broadcast_div(&norm(&bone)?.unsqueeze(D::Minus1)?)?;
    let target = constant(direction, u.dtype(), u.device())?;
    // |u − d| = 2 sin(θ/2) for unit vectors.
    let chord = norm(&u.broadcast_sub(&target)?)?.to_dtype(candle_core::DType::F64)?;
    let angle = chord.clamp(0.0, 2.0)?.to_vec2::<f64>()?;
    let angle: Vec<f64> = angle.iter().flatten().map(|c| (c / 2.0).asin().to_degrees() * 2.0).collect();
    let angle = Tensor::from_vec(angle, chord.shape(), chord.device())?;
    let value = over_frames(&angle, None, reduce == Reduce::Min)?;
    Ok(Check { what: format!("{j} bone off direction"), unit: Unit::Deg, value, tolerance: ANGLE_TOLERANCE_DEG })
}

/// Planted feet: the largest height above `max_height` (m) and, when `max_speed` is given, the
/// largest speed over it (m/s) of any foot at the contact frames `at`.
fn foot_contact_checks(
    joints: &Tensor,
    feet: &[Joint],
    at: &[usize],
    max_height: f64,
    max_speed: Option<f64>,
    batch: usize,
) -> Result<Vec<Check>, ConstraintError> {
    let frames = joints.dim(1)?;
    let (mut height, mut speed) = (vec![0f64; batch], vec![0f64; batch]);
    for &foot in feet {
        let p = joint(joints, foot)?.to_dtype(candle_core::DType::F64)?.to_vec3::<f64>()?;
        for (b, motion) in p.iter().enumerate() {
            for &t in at {
                height[b] = height[b].max(motion[t][1] - max_height);
                if let (Some(limit), true) = (max_speed, frames >= 2) {
                    let from = t.min(frames - 2);
                    let d = [0, 1, 2].map(|a| motion[from + 1][a] - motion[from][a]);
                    let v = d.iter().map(|x| x * x).sum::<f64>().sqrt() * crate::skeleton::FPS;
                    speed[b] = speed[b].max(v - limit);
                }
            }
        }
    }
    let mut checks = vec![Check {
        what: format!("foot above {max_height} m at the contact frames"),
        unit: Unit::M,
        value: height,
        tolerance: CONTACT_TOLERANCE_M,
    }];
    if let Some(limit) = max_speed {
        checks.push(Check {
            what: format!("foot faster than {limit} m/s at the contact frames"),
            unit: Unit::MPerS,
            value: speed,
            tolerance: SPEED_TOLERANCE_M_PER_S,
        });
    }
    Ok(checks)
}

/// The deepest intrusion of a limb point within `min_distance` of a torso point (on `axes`), m,
/// over the selected frames.
fn self_collision_check(
    joints: &Tensor,
    limbs: &Tensor,
    torso: &Tensor,
    min_distance: f64,
    axes: Axes,
    frames: &Frames,
    reduce: Reduce,
) -> Result<Check, ConstraintError> {
    let a = frames.select(&joints.index_select(limbs, 2)?)?.unsqueeze(3)?;
    let b = frames.select(&joints.index_select(torso, 2)?)?.unsqueeze(2)?;
    let distance = norm(&select_axes(&a.broadcast_sub(&b)?, axes)?)?; // [B, F, L, K]
    let (bt, f) = (distance.dim(0)?, distance.dim(1)?);
    let closer = (min_distance - distance)?.relu()?.reshape((bt, f, ()))?.max(D::Minus1)?;
    let value = over_frames(&closer, None, reduce == Reduce::Min)?;
    Ok(Check {
        what: format!("limb closer than {min_distance} m to the torso"),
        unit: Unit::M,
        value,
        tolerance: CONTACT_TOLERANCE_M,
    })
}

/// The worst (largest) value over the kept frames of `[B, F]` values, or the best (smallest)
/// with `best`; `mask` `[B, F]` keeps frames; a sample with no kept frame gets 0.
fn over_frames(values: &Tensor, mask: Option<&Tensor>, best: bool) -> Result<Vec<f64>, ConstraintError> {
    let values = values.to_dtype(candle_core::DType::F64)?.to_vec2::<f64>()?;
    let mask = match mask {
        Some(m) => Some(m.to_dtype(candle_core::DType::F64)?.to_vec2::<f64>()?),
        None => None,
    };
    Ok(values
        .iter()
        .enumerate()
        .map(|(b, row)| {
            let kept = row.iter().enumerate().filter(|(t, _)| mask.as_ref().is_none_or(|m| m[b][*t] > 0.5));
            let folded = if best {
                kept.map(|(_, v)| *v).fold(f64::INFINITY, f64::min)
            } else {
                kept.map(|(_, v)| *v).fold(f64::NEG_INFINITY, f64::max)
            };
            if folded.is_finite() {
                folded
            } else {
                0.0
            }
        })
        .collect())
}

/// Unit and tolerance of a quantity's values.
fn unit_of(quantity: &Quantity) -> (Unit, f64) {
    match quantity {
        Quantity::Velocity(_) | Quantity::Speed(_) => (Unit::MPerS, SPEED_TOLERANCE_M_PER_S),
        Quantity::Acceleration(_) => (Unit::MPerS2, ACCELERATION_TOLERANCE_M_PER_S2),
        _ => (Unit::M, DISTANCE_TOLERANCE_M),
    }
}

/// The quantity's `kind` name as programs spell it.
fn kind_name(quantity: &Quantity) -> String {
    serde_json::to_value(quantity)
        .ok()
        .and_then(|v| v.get("kind").and_then(|k| k.as_str()).map(str::to_owned))
        .unwrap_or_else(|| "quantity".into())
}

/// The primitive's `kind` name as programs spell it.
fn primitive_name(primitive: &Primitive) -> String {
    serde_json::to_value(primitive)
        .ok()
        .and_then(|v| v.get("kind").and_then(|k| k.as_str()).map(str::to_owned))
        .unwrap_or_else(|| "obstacle".into())
}
