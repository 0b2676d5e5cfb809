//! A compiled expression ([`Node`]) and its evaluation on joints `[B, T, 22, 3]`: each
//! constraint's error per sample `[B]`, finite, ≥ 0 and 0 where it holds.

use candle_core::{Result, Tensor, D};

use super::body::surface_points;
use super::error::ConstraintError;
use super::frames::{reduce, Frames};
use super::geometry::{constant, joint, norm, select_axes};
use super::scene::primitive_error;
use super::signal::{point, signal};
use super::{carry, count, flight, support};
use crate::program::{CarriedLoad, Condition, EventRegion, Extremum, Metric, Primitive, Quantity, Reduce};
use crate::skeleton::{Joint, FPS};

/// A comparison of a quantity's components with targets or bounds, per frame.
#[derive(Debug, Clone)]
pub(super) enum Comparison {
    Equal { target: Vec<f64>, metric: Metric },
    LessThan(f64),
    GreaterThan(f64),
}

/// What the error `(n − target)²` of a count the judge makes by a state machine (steps, events)
/// takes as `n`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum CountValue {
    /// The judge's own count ([`count::judged_footfalls`], [`count::judged_events`]) as the value,
    /// with the soft count's gradient ([`count::judged_error`]): the error is 0 exactly when the
    /// judge passes the count, so the optimiser's minimum is the judge's.
    Judged,
    /// The soft count, value and gradient: for ranking many motions at once, where the judge's
    /// count of each would cost more than the ranking.
    Soft,
}

/// A compiled expression.
#[derive(Debug, Clone)]
pub(super) enum Node {
    Compare {
        quantity: Quantity,
        comparison: Comparison,
        frames: Frames,
        when: Option<Condition>,
        reduce: Reduce,
    },
    And(Vec<Node>),
    Or(Vec<Node>),
    Not {
        arg: Box<Node>,
        margin: f64,
    },
    Count {
        signals: Vec<Quantity>,
        extremum: Extremum,
        threshold: f64,
        target: f64,
        sharpness: f64,
        smoothing: usize,
        frames: Vec<usize>,
    },
    Steps {
        target: f64,
        value: CountValue,
    },
    Events {
        signal: Quantity,
        region: EventRegion,
        hysteresis: f64,
        target: f64,
        frames: Frames,
        value: CountValue,
    },
    Airborne {
        clearance: f64,
        length: usize,
        /// Start frames `[W]` (u32) of the windows of `length` selected frames.
        starts: Tensor,
        when: Option<Condition>,
    },
    Carry {
        hands: [Joint; 2],
        diameter: f64,
        clearance: f64,
        frames: Frames,
        reduce: Reduce,
    },
    Scene {
        /// The listed joints `[J]` (u32); `None`: every joint.
        joints: Option<Tensor>,
        surface: bool,
        primitive: Primitive,
        frames: Frames,
        when: Option<Condition>,
        reduce: Reduce,
    },
    BoneDirection {
        joint: Joint,
        parent: Joint,
        direction: [f64; 3],
        frames: Frames,
        reduce: Reduce,
    },
    FootContact {
        feet: Vec<Joint>,
        at: Vec<usize>,
        max_height: f64,
        max_speed: Option<f64>,
    },
    SelfCollision {
        limbs: Tensor,
        torso: Tensor,
        min_distance: f64,
        axes: crate::program::Axes,
        frames: Frames,
        reduce: Reduce,
    },
    ComInSupport {
        support: crate::program::Support,
        margin: f64,
        load: Option<CarriedLoad>,
        frames: Frames,
        reduce: Reduce,
    },
    StayNearInitial {
        id: String,
        quantities: Vec<Quantity>,
        frames: Frames,
    },
}

/// The tested points `[B, T, P, 3]`: the listed joints, then the surface points if asked for.
/// Signed distance (m, positive outside) of the centre of mass (with a carried `load`) from the
/// support region of `feet` on the selected frames, both projected on the ground (x, z), `[B, F]`.
pub(super) fn com_outside_support(
    joints: &Tensor,
    feet: crate::program::Support,
    load: &Option<CarriedLoad>,
    frames: &Frames,
) -> Result<Tensor> {
    let centre = crate::program::CentreOfMass { exclude_head: false, load: load.clone() };
    let com = point(joints, &crate::program::Point::CentreOfMass(centre))?;
    let com = frames.select(&select_axes(&com, crate::program::Axes::Xz)?)?;
    let list = support::support_joints(feet);
    let index =
        Tensor::from_vec(list.iter().map(|j| j.index() as u32).collect::<Vec<_>>(), list.len(), joints.device())?;
    let points = frames.select(&select_axes(&joints.index_select(&index, 2)?, crate::program::Axes::Xz)?)?;
    support::signed_distance(&com, &points)
}

/// A scene or self-collision constraint's error per sample `[B]` from per-point errors
/// `[B, T, P]`: each frame's worst point (m, the deepest penetration or the closest limb), then
/// `how` over the frames (those `mask` `[B, T]` keeps, when given); `mean` averages over the
/// frames that violate (a mask without gradient), so a violation keeps its depth however few
/// frames and points it involves and cannot be averaged away by the frames and points that are
/// clear.
fn worst_point_reduce(errors: &Tensor, mask: Option<&Tensor>, how: Reduce) -> Result<Tensor> {
    let worst = errors.max(D::Minus1)?; // [B, T]
    match how {
        Reduce::Mean => {
            let violating = worst.detach().gt(0.0)?.to_dtype(worst.dtype())?;
            let kept = match mask {
                Some(mask) => (violating * mask)?,
                None => violating,
            };
            reduce(&worst, Some(&kept), Reduce::Mean)
        }
        other => reduce(&worst, mask, other),
    }
}

pub(super) fn body_points(joints: &Tensor, set: &Option<Tensor>, surface: bool) -> Result<Tensor> {
    let listed = match set {
        Some(set) => joints.index_select(set, 2)?,
        None => joints.clone(),
    };
    if surface {
        Tensor::cat(&[listed, surface_points(joints)?], 2)
    } else {
        Ok(listed)
    }
}

impl Node {
    pub(super) fn needs_initial(&self) -> bool {
        match self {
            Node::StayNearInitial { .. } => true,
            Node::And(args) | Node::Or(args) => args.iter().any(Node::needs_initial),
            Node::Not { arg, .. } => arg.needs_initial(),
            _ => false,
        }
    }

    /// Calls `visit` on this node and every node below it, mutably.
    pub(super) fn walk_mut(&mut self, visit: &mut impl FnMut(&mut Node)) {
        visit(self);
        match self {
            Node::And(args) | Node::Or(args) => args.iter_mut().for_each(|a| a.walk_mut(visit)),
            Node::Not { arg, .. } => arg.walk_mut(visit),
            _ => {}
        }
    }

    /// Calls `visit` on this node and every node below it.
    pub(super) fn walk(&self, visit: &mut impl FnMut(&Node) -> Result<()>) -> Result<()> {
        visit(self)?;
        match self {
            Node::And(args) | Node::Or(args) => args.iter().try_for_each(|a| a.walk(visit)),
            Node::Not { arg, .. } => arg.walk(visit),
            _ => Ok(()),
        }
    }

    /// The node's error `[B]`: each leaf's error, summed over `and`, the least over `or`, and
    /// the margin's shortfall for `not`.
    pub(super) fn eval(
        &self,
        joints: &Tensor,
        initial: Option<&Tensor>,
    ) -> std::result::Result<Tensor, ConstraintError> {
        Ok(match self {
            Node::Compare { quantity, comparison, frames, when, reduce: how } => {
                compare_error(joints, quantity, comparison, frames, when, *how)?
            }
            Node::And(args) => {
                let mut sum = args[0].eval(joints, initial)?;
                for arg in &args[1..] {
                    sum = (sum + arg.eval(joints, initial)?)?;
                }
                sum
            }
            Node::Or(args) => {
                let errors =
                    args.iter().map(|a| a.eval(joints, initial)).collect::<std::result::Result<Vec<_>, _>>()?;
                Tensor::stack(&errors, 1)?.min(1)?
            }
            Node::Not { arg, margin } => (*margin - arg.eval(joints, initial)?)?.relu()?,
            Node::Count { signals, extremum, threshold, target, sharpness, smoothing, frames } => {
                let frames_in = joints.dim(1)?;
                let n = signals.iter().map(|s| frames_in.saturating_sub(s.lag() as usize)).min().unwrap_or(0);
                let half = smoothing / 2;
                let mut total = Tensor::zeros(joints.dim(0)?, joints.dtype(), joints.device())?;
                for quantity in signals {
                    let s = signal(joints, quantity)?.squeeze(D::Minus1)?.narrow(1, 0, n)?;
                    let smooth = count::box_filter(&s, *smoothing)?;
                    let shifted: Vec<usize> = frames.iter().filter_map(|&t| t.checked_sub(half)).collect();
                    total = (total + count::soft_count(&smooth, &shifted, *extremum, *threshold, *sharpness)?)?;
                }
                (total - *target)?.sqr()?
            }
            Node::Steps { target, value } => {
                let soft = count::soft_footfalls(joints)?;
                match value {
                    CountValue::Judged => count::judged_error(&soft, count::judged_footfalls(joints)?, *target)?,
                    CountValue::Soft => (soft - *target)?.sqr()?,
                }
            }
            Node::Events { signal: quantity, region, hysteresis, target, frames, value } => {
                let s = frames.select(&signal(joints, quantity)?.squeeze(D::Minus1)?)?;
                let soft = count::soft_event_count(&s, *region, *hysteresis)?;
                match value {
                    CountValue::Judged => {
                        count::judged_error(&soft, count::judged_events(&s, *region, *hysteresis)?, *target)?
                    }
                    CountValue::Soft => (soft - *target)?.sqr()?,
                }
            }
            Node::Airborne { clearance, length, starts, when } => {
                flight_error(joints, *clearance, *length, starts, when)?
            }
            Node::Carry { hands, diameter, clearance, frames, reduce: how } => {
                let (gap, intrusion) = carry::carry_errors(joints, *hands, *diameter, *clearance)?;
                reduce(&frames.select(&(gap.sqr()? + intrusion.sqr()?)?)?, None, *how)?
            }
            Node::Scene { joints: set, surface, primitive, frames, when, reduce: how } => {
                // The points are per frame: selecting the frames first spares the others.
                let points = body_points(&frames.select(joints)?, set, *surface)?;
                let mask = frames.condition_mask(joints, when, joints.dim(1)?)?;
                worst_point_reduce(&primitive_error(&points, primitive, false)?, mask.as_ref(), *how)?
            }
            Node::BoneDirection { joint: j, parent, direction, frames, reduce: how } => {
                let bone = frames.select(&(joint(joints, *j)? - joint(joints, *parent)?)?)?;
                let length = norm(&bone)?.unsqueeze(D::Minus1)?;
                let u = bone.broadcast_div(&length)?;
                let target = constant(direction, u.dtype(), u.device())?;
                reduce(&u.broadcast_sub(&target)?.sqr()?.sum(D::Minus1)?, None, *how)?
            }
            Node::FootContact { feet, at, max_height, max_speed } => {
                foot_contact_error(joints, feet, at, *max_height, *max_speed)?
            }
            Node::SelfCollision { limbs, torso, min_distance, axes, frames, reduce: how } => {
                let a = frames.select(&joints.index_select(limbs, 2)?)?.unsqueeze(3)?; // [B, F, L, 1, 3]
                let b = frames.select(&joints.index_select(torso, 2)?)?.unsqueeze(2)?; // [B, F, 1, K, 3]
                let distance = norm(&select_axes(&a.broadcast_sub(&b)?, *axes)?)?; // [B, F, L, K]
                worst_point_reduce(&(*min_distance - distance)?.relu()?.flatten_from(2)?, None, *how)?
            }
            Node::ComInSupport { support: feet, margin, load, frames, reduce: how } => {
                let distance = com_outside_support(joints, *feet, load, frames)?;
                reduce(&(distance + *margin)?.relu()?.sqr()?, None, *how)?
            }
            Node::StayNearInitial { id, quantities, frames } => {
                let initial = initial.ok_or_else(|| ConstraintError::NoInitialMotion(id.clone()))?;
                stay_near_initial_error(joints, initial, quantities, frames)?
            }
        })
    }
}

/// A comparison's error `[B]`: per selected frame, the target's squared (or absolute) miss or
/// the bound's excess summed over the quantity's components, then `how` over the frames that
/// meet `when`.
fn compare_error(
    joints: &Tensor,
    quantity: &Quantity,
    comparison: &Comparison,
    frames: &Frames,
    when: &Option<Condition>,
    how: Reduce,
) -> Result<Tensor> {
    let q = signal(joints, quantity)?; // [B, n, C]
    let n = q.dim(1)?;
    // The comparison is per frame: selecting the frames first spares the others.
    let q = frames.select(&q)?;
    let per_frame = match comparison {
        Comparison::Equal { target, metric } => {
            let target = constant(target, q.dtype(), q.device())?;
            let diff = q.broadcast_sub(&target)?;
            match metric {
                Metric::Squared => diff.sqr()?,
                Metric::Absolute => diff.abs()?,
            }
        }
        Comparison::LessThan(max) => (q - *max)?.relu()?,
        Comparison::GreaterThan(min) => (*min - q)?.relu()?,
    }
    .sum(D::Minus1)?; // [B, F]
    let mask = frames.condition_mask(joints, when, n)?;
    reduce(&per_frame, mask.as_ref(), how)
}

/// A flight's error `[B]`: the smallest mean squared clearance deficit (m²) over the windows
/// of `length` frames starting at `starts` that meet `when`; clearance² where none meets it.
fn flight_error(
    joints: &Tensor,
    clearance: f64,
    length: usize,
    starts: &Tensor,
    when: &Option<Condition>,
) -> Result<Tensor> {
    let deficit = flight::flight_deficit(joints, clearance)?.sqr()?;
    let means = flight::window_means(&deficit, starts, length)?; // [B, W]
    Ok(match flight::windows_meeting(joints, when, starts, length)? {
        None => means.min(D::Minus1)?,
        Some(valid) => {
            // Windows that do not meet `when` are pushed far up; a sample with none
            // that meets it has no flight where it must: clearance².
            let best = (means + ((1.0 - &valid)? * 1e9)?)?.min(D::Minus1)?;
            let any = valid.max(D::Minus1)?;
            ((best * &any)? + ((1.0 - any)? * clearance.powi(2))?)?
        }
    })
}

/// A foot contact's error `[B]`: per foot and contact frame `at`, the squared height above
/// `max_height` (m) plus, when `max_speed` is given, the squared speed over it (m/s), averaged.
fn foot_contact_error(
    joints: &Tensor,
    feet: &[Joint],
    at: &[usize],
    max_height: f64,
    max_speed: Option<f64>,
) -> Result<Tensor> {
    let frames = joints.dim(1)?;
    let mut terms = Vec::new();
    for &foot in feet {
        let p = joint(joints, foot)?; // [B, T, 3]
        for &t in at {
            let y = p.narrow(1, t, 1)?.narrow(D::Minus1, 1, 1)?.squeeze(D::Minus1)?.squeeze(1)?;
            let mut term = (y - max_height)?.relu()?.sqr()?;
            if let (Some(limit), true) = (max_speed, frames >= 2) {
                let from = t.min(frames - 2);
                let v = ((p.narrow(1, from + 1, 1)? - p.narrow(1, from, 1)?)? * FPS)?;
                let speed = norm(&v)?.squeeze(1)?;
                term = (term + (speed - limit)?.relu()?.sqr()?)?;
            }
            terms.push(term);
        }
    }
    Tensor::stack(&terms, 1)?.mean(1)
}

/// Staying near the initial motion: the squared change of each quantity on the selected frames,
/// summed over the quantities and averaged over the frames, `[B]` (0 for no quantities).
fn stay_near_initial_error(
    joints: &Tensor,
    initial: &Tensor,
    quantities: &[Quantity],
    frames: &Frames,
) -> Result<Tensor> {
    let batch = joints.dim(0)?;
    let initial = initial.detach().broadcast_as(joints.shape())?;
    let mut sum: Option<Tensor> = None;
    for q in quantities {
        let n = frames.kept().len();
        let now = frames.select(&signal(joints, q)?)?;
        let then = frames.select(&signal(&initial, q)?)?;
        let per_frame = (now - then)?.sqr()?.sum(D::Minus1)?.narrow(1, 0, n)?;
        sum = Some(match sum {
            None => per_frame,
            Some(s) => (s + per_frame)?,
        });
    }
    match sum {
        Some(s) => s.mean(D::Minus1),
        None => Tensor::zeros(batch, joints.dtype(), joints.device()),
    }
}
