//! A program compiled for motions of its frame count, and its evaluation: each constraint's
//! error per sample.

use candle_core::{Result, Tensor, D};

use super::error::ConstraintError;
use super::flight;
use super::frames::Frames;
use super::geometry::unit;
use super::node::{body_points, Comparison, CountValue, Node};
use super::scene::{is_obstacle, primitive_error};
use crate::program::{
    Airborne, BoneDirection, Carry, ComInSupport, Condition, Count, Equal, Events, Expr, FootContact, FrameRef,
    GreaterThan, JointSet, LessThan, Quantity, Reduce, SceneConstraint, SelfCollision, StayNearInitial, Steps,
    TaskProgram,
};
use crate::skeleton::Joint;

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
    pub(super) frames: usize,
    pub(super) constraints: Vec<Compiled>,
}

#[derive(Debug, Clone)]
pub(super) struct Compiled {
    pub(super) id: String,
    pub(super) weight: f64,
    pub(super) node: Node,
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

    /// This program with every step and event count valued by its soft count
    /// (`CountValue::Soft`) instead of the judge's: a proxy for ranking many motions at once,
    /// where counting each one's steps as the judge does would cost more than the ranking.
    pub fn soft_counts(&self) -> CompiledProgram {
        let mut proxy = self.clone();
        for c in &mut proxy.constraints {
            c.node.walk_mut(&mut |node| {
                if let Node::Steps { value, .. } | Node::Events { value, .. } = node {
                    *value = CountValue::Soft;
                }
            });
        }
        proxy
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

    /// This program with every span of frames that a constraint reduces over (all frames, a
    /// range) thinned to every `step`-th frame, its first and last kept (`Frames::thinned`);
    /// keyframes, counts, steps, events and flights as they are. A proxy about `step`× cheaper
    /// for a scene constraint over all frames (5 Hz at `step` 4), for ranking many motions before
    /// scoring the best on every frame.
    pub fn thinned(&self, step: usize, device: &candle_core::Device) -> Result<CompiledProgram> {
        let mut proxy = self.clone();
        let mut failed = None;
        for c in &mut proxy.constraints {
            c.node.walk_mut(&mut |node| {
                if let Node::Compare { frames, .. }
                | Node::Scene { frames, .. }
                | Node::Carry { frames, .. }
                | Node::BoneDirection { frames, .. }
                | Node::SelfCollision { frames, .. }
                | Node::ComInSupport { frames, .. }
                | Node::StayNearInitial { frames, .. } = node
                {
                    match frames.thinned(step, device) {
                        Ok(thinned) => *frames = thinned,
                        Err(e) => failed = Some(e),
                    }
                }
            });
        }
        match failed {
            Some(e) => Err(e),
            None => Ok(proxy),
        }
    }

    /// This program's geometric constraints only, without those a motion makes by moving (any
    /// constraint with a `steps`, `count`, `events` or `airborne` term): what a joint-space
    /// refinement may act on ([`crate::generation::refine`]), since a count is made by the motion's own
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

    /// Whether any constraint counts events (steps, counted extrema): such a program's stages
    /// end together on every sample's judgement.
    pub fn has_counts(&self) -> bool {
        !self.count_targets().is_empty()
    }

    /// `(constraint id, target count)` of every counting expression (counts, steps, events), for
    /// the step-count metric and retrieval's check of counting tasks.
    pub fn count_targets(&self) -> Vec<(String, u32)> {
        let mut found = Vec::new();
        for c in &self.constraints {
            let _ = c.node.walk(&mut |node: &Node| {
                if let Node::Count { target, .. } | Node::Steps { target, .. } | Node::Events { target, .. } = node {
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

    /// The node of an expression of constraint `id`, its frames resolved in the clip.
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
            Expr::Count(count) => self.count(count)?,
            Expr::Steps(Steps { target_count }) => {
                Node::Steps { target: f64::from(*target_count), value: CountValue::Judged }
            }
            Expr::Events(events @ Events { signal, event, target_count, frames, .. }) => Node::Events {
                signal: signal.clone(),
                region: *event,
                hysteresis: events.hysteresis(),
                target: f64::from(*target_count),
                frames: self.select(frames, self.length(signal))?,
                value: CountValue::Judged,
            },
            Expr::Airborne(airborne) => self.airborne(id, airborne)?,
            Expr::Carry(Carry { hands, diameter_m, clearance_m, frames, reduce }) => Node::Carry {
                hands: *hands,
                diameter: *diameter_m,
                clearance: *clearance_m,
                frames: self.select(frames, self.frames)?,
                reduce: *reduce,
            },
            Expr::Scene(scene) => self.scene(scene)?,
            Expr::BoneDirection(BoneDirection { joint, direction, frames, reduce }) => Node::BoneDirection {
                joint: *joint,
                parent: joint.parent().ok_or_else(|| candle_core::Error::Msg("the pelvis has no bone".into()))?,
                direction: unit(*direction),
                frames: self.select(frames, self.frames)?,
                reduce: *reduce,
            },
            Expr::FootContact(contact) => self.foot_contact(contact)?,
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

    /// A soft count: its frames are those of the shortest signal.
    fn count(&self, count: &Count) -> Result<Node> {
        let Count { signals, extremum, threshold, target_count, sharpness, smoothing_frames, frames } = count;
        let n = signals.iter().map(|s| self.length(s)).min().unwrap_or(0);
        Ok(Node::Count {
            signals: signals.to_vec(),
            extremum: *extremum,
            threshold: *threshold,
            target: f64::from(*target_count),
            sharpness: *sharpness,
            smoothing: *smoothing_frames as usize,
            frames: self.select(frames, n)?.kept().to_vec(),
        })
    }

    /// A flight: the start frames of every window of `min_frames` consecutive selected frames;
    /// none is an error of constraint `id`.
    fn airborne(&self, id: &str, airborne: &Airborne) -> Result<Node> {
        let Airborne { clearance_m, min_frames, frames, when } = airborne;
        let length = *min_frames as usize;
        let starts = flight::window_starts(self.select(frames, self.frames)?.kept(), length);
        if starts.is_empty() {
            candle_core::bail!("constraint {id}: no {length} consecutive frames in its frames");
        }
        let n = starts.len();
        Ok(Node::Airborne {
            clearance: *clearance_m,
            length,
            starts: Tensor::from_vec(starts.into_iter().map(|f| f as u32).collect::<Vec<_>>(), n, self.device)?,
            when: when.clone(),
        })
    }

    /// A scene constraint on the listed joints (all when none are listed).
    fn scene(&self, scene: &SceneConstraint) -> Result<Node> {
        let SceneConstraint { body, primitive, frames, when, reduce } = scene;
        let joints = match &body.joints {
            JointSet::All => None,
            JointSet::Only(list) => Some(self.joint_index(list)?),
        };
        Ok(Node::Scene {
            joints,
            surface: body.surface,
            primitive: primitive.clone(),
            frames: self.select(frames, self.frames)?,
            when: when.clone(),
            reduce: *reduce,
        })
    }

    /// A foot contact at the frames `at` and `during`, resolved in the clip, sorted, each once.
    fn foot_contact(&self, contact: &FootContact) -> Result<Node> {
        let FootContact { feet, at, during, max_height_m, max_speed_m_per_s } = contact;
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
        Ok(Node::FootContact {
            feet: feet.to_vec(),
            at: kept,
            max_height: *max_height_m,
            max_speed: *max_speed_m_per_s,
        })
    }
}
