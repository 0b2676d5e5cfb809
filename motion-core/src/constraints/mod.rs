//! The built-in constraint library and its compiler: a validated [`TaskProgram`] becomes a
//! batched, differentiable loss on joint positions (ProgMoGen §3.2–3.3, RG-DNO supp. D).
//!
//! [`CompiledProgram::compile`] validates the program and resolves everything that does not
//! depend on the motion (frame selections, unit vectors, joint lists) once per run;
//! [`CompiledProgram::evaluate`] maps joints `[B, T, 22, 3]` (m, y up, 20 fps, `T` = the
//! program's frames) to the total `Σ_i w_i·E_i` `[B]` and every constraint's error `E_i` `[B]`.
//! Every error is finite and ≥ 0 and is 0 when its constraint holds; each formula is documented
//! on its [`Expr`] variant. Gradients flow to the joints through every term except the
//! frame masks of conditions and scene gates, which select without gradient as ProgMoGen does.

mod body;
mod carry;
mod count;
mod flight;
mod frames;
mod geometry;
mod probe;
mod satisfaction;
mod scene;
mod signal;
mod support;
#[cfg(test)]
mod tests;

use candle_core::{Result, Tensor, D};

pub use body::{bone_radius_m, surface_points, HEAD_RADIUS_M, SURFACE_POINTS};
pub use carry::{carry_errors, torso_distance, TORSO_CHAIN};
pub use count::soft_event_count;
pub use flight::{flight_deficit, FLIGHT_JOINTS};
pub use geometry::NORM_EPS;
pub use probe::{probe_motion, GradientCheck, STANDING};
pub use satisfaction::{Check, Satisfaction, Unit};
pub use scene::{is_obstacle, primitive_error};
pub use signal::{centre_of_mass_weights, point, root_relative, second_difference, signal, velocity};
pub use support::FOOT_HALF_WIDTH_M;

use crate::program::{
    Airborne, BoneDirection, CarriedLoad, Carry, ComInSupport, Condition, Count, Equal, EventRegion, Events, Expr,
    Extremum, FootContact, FrameRef, GreaterThan, JointSet, LessThan, Metric, Primitive, ProgramError, Quantity,
    Reduce, SceneConstraint, SelfCollision, StayNearInitial, Steps, TaskProgram,
};
use crate::skeleton::{Joint, FPS};
use frames::{reduce, Frames};
use geometry::{constant, joint, norm, select_axes, unit};

/// Why a program cannot be compiled or evaluated.
#[derive(Debug, thiserror::Error)]
pub enum ConstraintError {
    /// The program is invalid (each error names the JSON path).
    #[error("invalid program:\n{}", .0.iter().map(|e| format!("  - {e}")).collect::<Vec<_>>().join("\n"))]
    Invalid(Vec<ProgramError>),
    /// The motion does not fit the program.
    #[error("motion of shape {shape:?} does not fit the program: expected [batch, {frames}, 22, 3]")]
    Shape {
        /// Shape given.
        shape: Vec<usize>,
        /// The program's frame count.
        frames: usize,
    },
    /// A program with `stay_near_initial` was evaluated without an initial motion.
    #[error("constraint {0} (stay_near_initial) needs the initial motion")]
    NoInitialMotion(String),
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
}

/// The errors of one evaluation.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// `Σ_i w_i·E_i`, `[B]`.
    pub total: Tensor,
    /// `(id, E_i)` per constraint in program order, `[B]` each (unweighted).
    pub per_constraint: Vec<(String, Tensor)>,
}

/// A program compiled for motions of its frame count.
#[derive(Debug, Clone)]
pub struct CompiledProgram {
    frames: usize,
    constraints: Vec<Compiled>,
}

#[derive(Debug, Clone)]
struct Compiled {
    id: String,
    weight: f64,
    node: Node,
}

/// A comparison of a quantity's components with targets or bounds, per frame.
#[derive(Debug, Clone)]
enum Comparison {
    Equal { target: Vec<f64>, metric: Metric },
    LessThan(f64),
    GreaterThan(f64),
}

/// A compiled expression.
#[derive(Debug, Clone)]
enum Node {
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
    },
    Events {
        signal: Quantity,
        region: EventRegion,
        hysteresis: f64,
        target: f64,
        frames: Frames,
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
        joints: Tensor,
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

impl CompiledProgram {
    /// Validates `program` and compiles it for motions of `program.frames` frames on `device`.
    pub fn compile(program: &TaskProgram, device: &candle_core::Device) -> std::result::Result<Self, ConstraintError> {
        program.validate().map_err(ConstraintError::Invalid)?;
        let frames = program.frames as usize;
        let compiler = Compiler { frames, device };
        let constraints = program
            .constraints
            .iter()
            .map(|c| Ok(Compiled { id: c.id.clone(), weight: c.weight(), node: compiler.expr(&c.id, &c.expr)? }))
            .collect::<Result<Vec<_>>>()?;
        Ok(CompiledProgram { frames, constraints })
    }

    /// Frames of the motions this program evaluates.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Constraint ids in program order.
    pub fn ids(&self) -> impl Iterator<Item = &str> {
        self.constraints.iter().map(|c| c.id.as_str())
    }

    /// Whether some constraint compares the motion with the initial one.
    pub fn needs_initial(&self) -> bool {
        self.constraints.iter().any(|c| c.node.needs_initial())
    }

    /// Evaluates the program on joints `[B, T, 22, 3]`. `initial` (`[B or 1, T, 22, 3]`) is the
    /// unoptimised motion that `stay_near_initial` terms compare with.
    pub fn evaluate(
        &self,
        joints: &Tensor,
        initial: Option<&Tensor>,
    ) -> std::result::Result<Evaluation, ConstraintError> {
        let dims = joints.dims();
        if dims.len() != 4 || dims[1] != self.frames || dims[2] != 22 || dims[3] != 3 {
            return Err(ConstraintError::Shape { shape: dims.to_vec(), frames: self.frames });
        }
        // index_select (joint and frame selections) needs contiguous storage.
        let joints = &joints.contiguous()?;
        let mut total = Tensor::zeros(dims[0], joints.dtype(), joints.device())?;
        let mut per_constraint = Vec::with_capacity(self.constraints.len());
        for c in &self.constraints {
            let error = c.node.eval(joints, initial)?;
            total = (total + (&error * c.weight)?)?;
            per_constraint.push((c.id.clone(), error));
        }
        Ok(Evaluation { total, per_constraint })
    }

    /// This program with every counting sharpness capped at `max` (per unit of its signal).
    pub fn with_sharpness_at_most(&self, max: f64) -> CompiledProgram {
        let mut softened = self.clone();
        for c in &mut softened.constraints {
            c.node.walk_mut(&mut |node| {
                if let Node::Count { sharpness, .. } = node {
                    *sharpness = sharpness.min(max);
                }
            });
        }
        softened
    }

    /// This program with every scene term on the joint centres only, without body-surface
    /// points: a proxy about 20× cheaper to evaluate (the surface lies within a bone radius,
    /// ≤ 0.1 m, of the joints), for ranking many motions before scoring the best exactly.
    pub fn joints_only(&self) -> CompiledProgram {
        let mut proxy = self.clone();
        for c in &mut proxy.constraints {
            c.node.walk_mut(&mut |node| {
                if let Node::Scene { surface, .. } = node {
                    *surface = false;
                }
            });
        }
        proxy
    }

    /// This program's geometric constraints only, without those a motion makes by moving (any
    /// constraint with a `steps`, `count`, `events` or `airborne` term): what a joint-space
    /// refinement may act on ([`crate::refine`]), since a count is made by the motion's own
    /// strides and extrema and a flight by a jump, not by shifting joints.
    pub fn geometric(&self) -> CompiledProgram {
        let made_by_moving = |node: &Node| {
            let mut found = false;
            let _ = node.walk(&mut |n| {
                found |=
                    matches!(n, Node::Count { .. } | Node::Steps { .. } | Node::Events { .. } | Node::Airborne { .. });
                Ok(())
            });
            found
        };
        let constraints = self.constraints.iter().filter(|c| !made_by_moving(&c.node)).cloned().collect();
        CompiledProgram { frames: self.frames, constraints }
    }

    /// Whether the program has no constraint.
    pub fn is_empty(&self) -> bool {
        self.constraints.is_empty()
    }

    /// Only the constraints with these ids (RG-DNO's subsets `C1`, `C2`, `C_R`); unknown ids are
    /// ignored.
    pub fn subset(&self, ids: &[String]) -> CompiledProgram {
        let constraints = self.constraints.iter().filter(|c| ids.contains(&c.id)).cloned().collect();
        CompiledProgram { frames: self.frames, constraints }
    }

    /// Deepest penetration (m) of any surface point or joint into any obstacle of the program's
    /// scene constraints (margins ignored: the obstacle itself), per sample `[B]`; `None` when
    /// the program has no obstacle (RG-DNO's "Max SP").
    pub fn max_scene_penetration(&self, joints: &Tensor) -> Result<Option<Tensor>> {
        let mut worst: Option<Tensor> = None;
        let mut visit = |node: &Node| -> Result<()> {
            if let Node::Scene { joints: set, surface, primitive, frames, when, .. } = node {
                if is_obstacle(primitive) {
                    let points = frames.select(&body_points(joints, set, *surface)?)?;
                    let depth = primitive_error(&points, primitive, true)?.max(D::Minus1)?; // [B, F]
                    let depth = match frames.condition_mask(joints, when, joints.dim(1)?)? {
                        Some(mask) => (depth * mask)?,
                        None => depth,
                    };
                    let depth = depth.max(D::Minus1)?;
                    worst = Some(match worst.take() {
                        None => depth,
                        Some(w) => w.maximum(&depth)?,
                    });
                }
            }
            Ok(())
        };
        for c in &self.constraints {
            c.node.walk(&mut visit)?;
        }
        Ok(worst)
    }

    /// `(constraint id, target count)` of every counting expression (counts, steps, events), for
    /// the step-count metric and retrieval's check of counting tasks.
    pub fn count_targets(&self) -> Vec<(String, u32)> {
        let mut found = Vec::new();
        for c in &self.constraints {
            let _ = c.node.walk(&mut |node: &Node| {
                if let Node::Count { target, .. } | Node::Steps { target } | Node::Events { target, .. } = node {
                    found.push((c.id.clone(), *target as u32));
                }
                Ok(())
            });
        }
        found
    }
}

struct Compiler<'a> {
    frames: usize,
    device: &'a candle_core::Device,
}

impl Compiler<'_> {
    /// Frames of the quantity's signal.
    fn length(&self, quantity: &Quantity) -> usize {
        self.frames.saturating_sub(quantity.lag() as usize)
    }

    fn select(&self, selection: &crate::program::FrameSelection, n: usize) -> Result<Frames> {
        Frames::resolve(selection, n, self.device)
    }

    fn joint_index(&self, joints: &[Joint]) -> Result<Tensor> {
        Tensor::from_vec(joints.iter().map(|j| j.index() as u32).collect::<Vec<_>>(), joints.len(), self.device)
    }

    fn compare(
        &self,
        quantity: &Quantity,
        comparison: Comparison,
        frames: &crate::program::FrameSelection,
        when: &Option<Condition>,
        reduce: Reduce,
    ) -> Result<Node> {
        Ok(Node::Compare {
            quantity: quantity.clone(),
            comparison,
            frames: self.select(frames, self.length(quantity))?,
            when: when.clone(),
            reduce,
        })
    }

    fn expr(&self, id: &str, expr: &Expr) -> Result<Node> {
        Ok(match expr {
            Expr::Equal(Equal { quantity, target, metric, frames, when, reduce }) => self.compare(
                quantity,
                Comparison::Equal { target: target.clone(), metric: *metric },
                frames,
                when,
                *reduce,
            )?,
            Expr::LessThan(LessThan { quantity, max, frames, when, reduce }) => {
                self.compare(quantity, Comparison::LessThan(*max), frames, when, *reduce)?
            }
            Expr::GreaterThan(GreaterThan { quantity, min, frames, when, reduce }) => {
                self.compare(quantity, Comparison::GreaterThan(*min), frames, when, *reduce)?
            }
            Expr::And(args) => Node::And(args.args.iter().map(|a| self.expr(id, a)).collect::<Result<_>>()?),
            Expr::Or(args) => Node::Or(args.args.iter().map(|a| self.expr(id, a)).collect::<Result<_>>()?),
            Expr::Not(not) => Node::Not { arg: Box::new(self.expr(id, &not.arg)?), margin: not.margin },
            Expr::Count(Count { signals, extremum, threshold, target_count, sharpness, smoothing_frames, frames }) => {
                let n = signals.iter().map(|s| self.length(s)).min().unwrap_or(0);
                Node::Count {
                    signals: signals.to_vec(),
                    extremum: *extremum,
                    threshold: *threshold,
                    target: f64::from(*target_count),
                    sharpness: *sharpness,
                    smoothing: *smoothing_frames as usize,
                    frames: self.select(frames, n)?.kept().to_vec(),
                }
            }
            Expr::Steps(Steps { target_count }) => Node::Steps { target: f64::from(*target_count) },
            Expr::Events(events @ Events { signal, event, target_count, frames, .. }) => Node::Events {
                signal: signal.clone(),
                region: *event,
                hysteresis: events.hysteresis(),
                target: f64::from(*target_count),
                frames: self.select(frames, self.length(signal))?,
            },
            Expr::Airborne(Airborne { clearance_m, min_frames, frames, when }) => {
                let length = *min_frames as usize;
                let starts = flight::window_starts(self.select(frames, self.frames)?.kept(), length);
                if starts.is_empty() {
                    candle_core::bail!("constraint {id}: no {length} consecutive frames in its frames");
                }
                let n = starts.len();
                Node::Airborne {
                    clearance: *clearance_m,
                    length,
                    starts: Tensor::from_vec(starts.into_iter().map(|f| f as u32).collect::<Vec<_>>(), n, self.device)?,
                    when: when.clone(),
                }
            }
            Expr::Carry(Carry { hands, diameter_m, clearance_m, frames, reduce }) => Node::Carry {
                hands: *hands,
                diameter: *diameter_m,
                clearance: *clearance_m,
                frames: self.select(frames, self.frames)?,
                reduce: *reduce,
            },
            Expr::Scene(SceneConstraint { body, primitive, frames, when, reduce }) => {
                let joints = match &body.joints {
                    JointSet::All => Joint::ALL.to_vec(),
                    JointSet::Only(list) => list.to_vec(),
                };
                Node::Scene {
                    joints: self.joint_index(&joints)?,
                    surface: body.surface,
                    primitive: primitive.clone(),
                    frames: self.select(frames, self.frames)?,
                    when: when.clone(),
                    reduce: *reduce,
                }
            }
            Expr::BoneDirection(BoneDirection { joint, direction, frames, reduce }) => Node::BoneDirection {
                joint: *joint,
                parent: joint.parent().ok_or_else(|| candle_core::Error::Msg("the pelvis has no bone".into()))?,
                direction: unit(*direction),
                frames: self.select(frames, self.frames)?,
                reduce: *reduce,
            },
            Expr::FootContact(FootContact { feet, at, during, max_height_m, max_speed_m_per_s }) => {
                let resolve = |f: &FrameRef| {
                    f.resolve(self.frames as u32).map(|f| f as usize).ok_or_else(|| {
                        candle_core::Error::Msg(format!("frame {f:?} is outside the clip of {} frames", self.frames))
                    })
                };
                let mut kept: Vec<usize> = at.iter().map(resolve).collect::<Result<_>>()?;
                if let Some(range) = during {
                    kept.extend(resolve(&range.from)?..=resolve(&range.to)?);
                }
                kept.sort_unstable();
                kept.dedup();
                Node::FootContact {
                    feet: feet.to_vec(),
                    at: kept,
                    max_height: *max_height_m,
                    max_speed: *max_speed_m_per_s,
                }
            }
            Expr::SelfCollision(SelfCollision { limbs, torso, min_distance_m, axes, frames, reduce }) => {
                Node::SelfCollision {
                    limbs: self.joint_index(limbs)?,
                    torso: self.joint_index(torso)?,
                    min_distance: *min_distance_m,
                    axes: *axes,
                    frames: self.select(frames, self.frames)?,
                    reduce: *reduce,
                }
            }
            Expr::ComInSupport(ComInSupport { support, margin_m, load, frames, reduce }) => Node::ComInSupport {
                support: *support,
                margin: *margin_m,
                load: load.clone(),
                frames: self.select(frames, self.frames)?,
                reduce: *reduce,
            },
            Expr::StayNearInitial(StayNearInitial { quantities, frames }) => {
                let n = quantities.iter().map(|q| self.length(q)).min().unwrap_or(0);
                Node::StayNearInitial {
                    id: id.to_owned(),
                    quantities: quantities.to_vec(),
                    frames: self.select(frames, n)?,
                }
            }
        })
    }
}

/// The tested points `[B, T, P, 3]`: the listed joints, then the surface points if asked for.
/// Signed distance (m, positive outside) of the centre of mass (with a carried `load`) from the
/// support region of `feet` on the selected frames, both projected on the ground (x, z), `[B, F]`.
fn com_outside_support(
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

fn body_points(joints: &Tensor, set: &Tensor, surface: bool) -> Result<Tensor> {
    let listed = joints.index_select(set, 2)?;
    if surface {
        Tensor::cat(&[listed, surface_points(joints)?], 2)
    } else {
        Ok(listed)
    }
}

impl Node {
    fn needs_initial(&self) -> bool {
        match self {
            Node::StayNearInitial { .. } => true,
            Node::And(args) | Node::Or(args) => args.iter().any(Node::needs_initial),
            Node::Not { arg, .. } => arg.needs_initial(),
            _ => false,
        }
    }

    /// Calls `visit` on this node and every node below it, mutably.
    fn walk_mut(&mut self, visit: &mut impl FnMut(&mut Node)) {
        visit(self);
        match self {
            Node::And(args) | Node::Or(args) => args.iter_mut().for_each(|a| a.walk_mut(visit)),
            Node::Not { arg, .. } => arg.walk_mut(visit),
            _ => {}
        }
    }

    /// Calls `visit` on this node and every node below it.
    fn walk(&self, visit: &mut impl FnMut(&Node) -> Result<()>) -> Result<()> {
        visit(self)?;
        match self {
            Node::And(args) | Node::Or(args) => args.iter().try_for_each(|a| a.walk(visit)),
            Node::Not { arg, .. } => arg.walk(visit),
            _ => Ok(()),
        }
    }

    /// The node's error `[B]`.
    fn eval(&self, joints: &Tensor, initial: Option<&Tensor>) -> std::result::Result<Tensor, ConstraintError> {
        Ok(match self {
            Node::Compare { quantity, comparison, frames, when, reduce: how } => {
                let q = signal(joints, quantity)?; // [B, n, C]
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
                .sum(D::Minus1)?; // [B, n]
                let mask = frames.condition_mask(joints, when, per_frame.dim(1)?)?;
                reduce(&frames.select(&per_frame)?, mask.as_ref(), *how)?
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
            Node::Steps { target } => (count::soft_step_count(joints)? - *target)?.sqr()?,
            Node::Events { signal: quantity, region, hysteresis, target, frames } => {
                let s = frames.select(&signal(joints, quantity)?.squeeze(D::Minus1)?)?;
                (count::soft_event_count(&s, *region, *hysteresis)? - *target)?.sqr()?
            }
            Node::Airborne { clearance, length, starts, when } => {
                let deficit = flight::flight_deficit(joints, *clearance)?.sqr()?;
                let means = flight::window_means(&deficit, starts, *length)?; // [B, W]
                match flight::windows_meeting(joints, when, starts, *length)? {
                    None => means.min(D::Minus1)?,
                    Some(valid) => {
                        // Windows that do not meet `when` are pushed far up; a sample with none
                        // that meets it has no flight where it must: clearance².
                        let best = (means + ((1.0 - &valid)? * 1e9)?)?.min(D::Minus1)?;
                        let any = valid.max(D::Minus1)?;
                        ((best * &any)? + ((1.0 - any)? * clearance.powi(2))?)?
                    }
                }
            }
            Node::Carry { hands, diameter, clearance, frames, reduce: how } => {
                let (gap, intrusion) = carry::carry_errors(joints, *hands, *diameter, *clearance)?;
                reduce(&frames.select(&(gap.sqr()? + intrusion.sqr()?)?)?, None, *how)?
            }
            Node::Scene { joints: set, surface, primitive, frames, when, reduce: how } => {
                let points = frames.select(&body_points(joints, set, *surface)?)?;
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
                let frames = joints.dim(1)?;
                let mut terms = Vec::new();
                for &foot in feet {
                    let p = joint(joints, foot)?; // [B, T, 3]
                    for &t in at {
                        let y = p.narrow(1, t, 1)?.narrow(D::Minus1, 1, 1)?.squeeze(D::Minus1)?.squeeze(1)?;
                        let mut term = (y - *max_height)?.relu()?.sqr()?;
                        if let (Some(limit), true) = (max_speed, frames >= 2) {
                            let from = t.min(frames - 2);
                            let v = ((p.narrow(1, from + 1, 1)? - p.narrow(1, from, 1)?)? * FPS)?;
                            let speed = norm(&v)?.squeeze(1)?;
                            term = (term + (speed - *limit)?.relu()?.sqr()?)?;
                        }
                        terms.push(term);
                    }
                }
                Tensor::stack(&terms, 1)?.mean(1)?
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
                    Some(s) => s.mean(D::Minus1)?,
                    None => Tensor::zeros(batch, joints.dtype(), joints.device())?,
                }
            }
        })
    }
}
