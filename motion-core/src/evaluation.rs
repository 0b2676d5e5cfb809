//! The report of one constrained-generation run: every constraint's error per sample and the
//! papers' motion metrics (`reference/anchors.md` §3.7, RG-DNO §5), as serialisable data.

use std::fmt;

use candle_core::{DType, Tensor};
use serde::{Deserialize, Serialize};

use crate::cleanup::FootLockReport;
use crate::constraints::{Check, CompiledProgram};
use crate::corpus::family::Family;
use crate::generation::method::{Generated, GenerationConfig};
use crate::generation::refine::RefineReport;
use crate::generation::rgdno::report::RgDnoReport;
use crate::generation::rgdno::semantic::missing_actions_note;
use crate::metrics::{footfalls, step_count, MetricMeans};
use crate::motion::tensor_to_poses;
use crate::numeric::mean;
use crate::program::TaskProgram;
use crate::skeleton::Pose;

/// One constraint's errors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConstraintReport {
    /// Its id (`c1`, ...).
    pub id: String,
    /// Its description from the program, if any.
    pub description: Option<String>,
    /// Its weight in the total.
    pub weight: f64,
    /// Unweighted loss per sample, in the constraint's own unit (squared, margined or averaged
    /// as the optimiser sees it).
    pub error: Vec<f64>,
    /// Its figures in natural units (worst frame, worst point) with their tolerances.
    pub checks: Vec<Check>,
    /// Whether each sample meets it within the tolerances.
    pub pass: Vec<bool>,
}

/// The skill the prompt names ([`Family::named_in`]), judged on each written sample by the
/// family's detector ([`Family::detect`]), the one `mogen report prior` applies to free samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SkillReport {
    /// The family's name ([`Family::name`]).
    pub family: String,
    /// What its detector checks ([`Family::detector`]).
    pub detector: String,
    /// Whether each sample passes the detector.
    pub pass: Vec<bool>,
    /// Whether the prompt asks for the skill, beyond walking ([`Family::is_walking`]): a sample
    /// that fails its detector then falls short like one that misses a constraint, and is tried
    /// again ([`crate::pipeline::TaskSettings::retry_unmet`]). A walk's detector is only
    /// reported, since prompts name walking loosely. False in reports written before it was
    /// judged.
    #[serde(default)]
    pub asked: bool,
}

impl SkillReport {
    /// The skill `prompt` names, judged on `motions`; `None` when it names none.
    pub fn judge(prompt: &str, motions: &[Vec<Pose>]) -> Option<SkillReport> {
        let family = Family::named_in(prompt)?;
        Some(SkillReport {
            family: family.name().to_owned(),
            detector: family.detector().to_owned(),
            pass: motions.iter().map(|m| family.detect(m)).collect(),
            asked: !family.is_walking(),
        })
    }

    /// `3/4`: samples that pass, of all.
    pub fn passed_text(&self) -> String {
        format!("{}/{}", self.pass.iter().filter(|&&p| p).count(), self.pass.len())
    }
}

/// Step counting against a counting constraint's target.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepReport {
    /// The counting constraint's target, in footfalls.
    pub target: u32,
    /// Leg alternations per sample ([`crate::metrics::step_count`]), a reported figure beside
    /// the footfalls: from feet side by side, usually one fewer.
    pub counts: Vec<usize>,
    /// Footfalls per sample ([`crate::metrics::footfalls`]: every swing of either foot, as a
    /// person, the RG-DNO paper and the `steps` constraint count steps). Absent in reports
    /// written before it was measured.
    #[serde(default)]
    pub footfalls: Vec<usize>,
    /// Fraction of samples with exactly `target` footfalls (in reports written before footfalls
    /// were the constraint's count, `target` leg alternations).
    pub success_rate: f64,
}

impl StepReport {
    /// The footfalls, with the leg alternations beside them: `[6, 7] (leg alternations [5, 6])`
    /// (the alternations alone in reports written before footfalls were measured).
    pub fn counts_text(&self) -> String {
        if self.footfalls.is_empty() {
            format!("leg alternations {:?}", self.counts)
        } else {
            format!("{:?} (leg alternations {:?})", self.footfalls, self.counts)
        }
    }
}

/// The figures of the network's motion before the contact-aware clean-up, to set beside the
/// report's (which are measured after it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BeforeCleanup {
    /// Mean over samples of `Σ wᵢ·Eᵢ`.
    pub constraint_error: f64,
    /// Fraction of samples that meet every constraint within its tolerance.
    pub success_rate: f64,
    /// The deepest penetration of any sample into an obstacle, m.
    pub max_scene_penetration_m: Option<f64>,
    /// Steps counted per sample, for programs with a counting constraint.
    pub steps: Option<Vec<usize>>,
    /// The motion figures of the samples.
    #[serde(flatten)]
    pub motion: MetricMeans,
}

/// What the finishing stages did to the run: the kinematic refinement ([`crate::generation::refine`]) and
/// the contact-aware clean-up ([`fn@crate::cleanup::foot_lock`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CleanupReport {
    /// Whether the foot clean-up ran (when neither stage ran, `before` equals the report's own
    /// figures).
    pub enabled: bool,
    /// Per sample: contacts locked, displacements, foot skate before and after.
    pub samples: Vec<FootLockReport>,
    /// Whether the refinement ran.
    #[serde(default)]
    pub refine_enabled: bool,
    /// Per sample: whether the refinement was kept, the program's error before and after it and
    /// the largest joint offset.
    #[serde(default)]
    pub refine: Vec<RefineReport>,
    /// The run's figures before both stages (the network's motion).
    pub before: BeforeCleanup,
}

/// The report of a run (written as `report.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskReport {
    /// The program's prompt.
    pub text: String,
    /// Frames per motion (20 fps).
    pub frames: usize,
    /// The run's settings (method, samples, seed, optimiser settings).
    pub config: GenerationConfig,
    /// The prior that made the motions (its file and SHA-256); absent in reports written
    /// before it was recorded, and for a prior built in memory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<crate::prior::PriorIdentity>,
    /// Wall-clock seconds of the method.
    pub seconds: f64,
    /// Constraint error: mean over samples of `Σ wᵢ·Eᵢ` (ProgMoGen's mean `f_eval`).
    pub constraint_error: f64,
    /// `Σ wᵢ·Eᵢ` per sample.
    pub constraint_error_per_sample: Vec<f64>,
    /// Every constraint's errors.
    pub constraints: Vec<ConstraintReport>,
    /// The deepest penetration of any sample into an obstacle (m; margins ignored; RG-DNO's Max
    /// SP); `None` without obstacles.
    pub max_scene_penetration_m: Option<f64>,
    /// Each sample's deepest penetration into an obstacle, m.
    pub scene_penetration_per_sample_m: Option<Vec<f64>>,
    /// Fraction of samples that meet every constraint within its tolerance.
    pub success_rate: f64,
    /// Step counting, for programs with a counting constraint over foot speeds.
    pub steps: Option<StepReport>,
    /// The skill the prompt names, judged on each sample; absent when it names none, and in
    /// reports written before it was judged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skill: Option<SkillReport>,
    /// The motion figures of the samples (foot skate, accelerations, pace, toe flicker, stance
    /// toe height, depth under the floor, hands raised, head–neck lengths, ...).
    #[serde(flatten)]
    pub motion: MetricMeans,
    /// The clean-up and the figures before it (every figure above is measured after it, on the
    /// written joints).
    pub cleanup: CleanupReport,
    /// What each RG-DNO stage did (RG-DNO runs only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rg_dno: Option<RgDnoReport>,
    /// Why the method that ran is not the one asked for (RG-DNO falling back to DNO).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fallback: Option<String>,
    /// With retries of the samples that miss a constraint ([`crate::pipeline::TaskSettings::retry_unmet`]):
    /// the attempt each sample kept (0: the first); absent when retries are off.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attempt: Option<Vec<usize>>,
}

/// The constraint figures of one set of joints.
struct Judged {
    per_sample: Vec<f64>,
    constraints: Vec<ConstraintReport>,
    success_rate: f64,
    penetration: Option<Vec<f64>>,
    steps: Option<StepReport>,
    /// The joints as poses, per sample.
    motions: Vec<Vec<Pose>>,
}

fn judge(
    program: &TaskProgram,
    compiled: &CompiledProgram,
    joints: &Tensor,
    initial: &Tensor,
) -> candle_core::Result<Judged> {
    let evaluation = compiled.evaluate(joints, Some(initial)).map_err(candle_core::Error::wrap)?;
    let per_sample = to_f64(&evaluation.total)?;
    let satisfaction = compiled.satisfaction(joints, Some(initial)).map_err(candle_core::Error::wrap)?;
    let constraints = evaluation
        .per_constraint
        .iter()
        .zip(satisfaction)
        .map(|((id, error), judged)| {
            let spec = program.constraint(id);
            Ok(ConstraintReport {
                id: id.clone(),
                description: spec.and_then(|c| c.description.clone()),
                weight: spec.map_or(1.0, |c| c.weight()),
                error: to_f64(error)?,
                checks: judged.checks,
                pass: judged.pass,
            })
        })
        .collect::<candle_core::Result<Vec<_>>>()?;
    let samples = per_sample.len();
    let successes =
        (0..samples).filter(|&b| constraints.iter().all(|c| c.pass.get(b).copied().unwrap_or(false))).count();
    let penetration = compiled.max_scene_penetration(joints)?.map(|t| to_f64(&t)).transpose()?;
    let motions = tensor_to_poses(joints)?;
    let steps = compiled.count_targets().into_iter().find(|(id, _)| is_step_count(program, id)).map(|(_, target)| {
        let counts = motions.iter().map(|m| step_count(m)).collect();
        let footfalls: Vec<usize> = motions.iter().map(|m| footfalls(m)).collect();
        let hits = footfalls.iter().filter(|&&c| c == target as usize).count();
        StepReport { target, success_rate: hits as f64 / footfalls.len().max(1) as f64, counts, footfalls }
    });
    let success_rate = successes as f64 / samples.max(1) as f64;
    Ok(Judged { per_sample, constraints, success_rate, penetration, steps, motions })
}

fn worst(values: &Option<Vec<f64>>) -> Option<f64> {
    values.as_ref().map(|p| p.iter().copied().fold(0.0, f64::max))
}

impl TaskReport {
    /// The samples that miss at least one constraint at its tolerance.
    pub fn unmet_samples(&self) -> Vec<usize> {
        (0..self.samples()).filter(|&b| self.met_constraints(b) < self.constraints.len()).collect()
    }

    /// The samples that meet every constraint but fail the detector of the skill the prompt
    /// asks for ([`SkillReport::asked`]): a hop that glides, a carry with swinging arms.
    pub fn skill_missed_samples(&self) -> Vec<usize> {
        (0..self.samples())
            .filter(|&b| self.met_constraints(b) == self.constraints.len() && !self.does_asked_skill(b))
            .collect()
    }

    fn samples(&self) -> usize {
        self.constraint_error_per_sample.len()
    }

    fn met_constraints(&self, b: usize) -> usize {
        self.constraints.iter().filter(|c| c.pass.get(b).copied().unwrap_or(false)).count()
    }

    /// Whether sample `b` passes the detector of the skill the prompt asks for (true when it
    /// asks for none).
    fn does_asked_skill(&self, b: usize) -> bool {
        self.skill.as_ref().is_none_or(|s| !s.asked || s.pass.get(b).copied().unwrap_or(false))
    }

    /// Whether sample `i` of `other` (another attempt at the same program) is better than this
    /// report's sample `b`: more constraints met at their tolerances; or as many, and the skill
    /// the prompt asks for done where `b` does not do it; or as many, the skill alike, and a
    /// lower constraint error (a number beats NaN).
    pub fn beaten_by(&self, b: usize, other: &TaskReport, i: usize) -> bool {
        let own = (self.met_constraints(b), self.does_asked_skill(b));
        let theirs = (other.met_constraints(i), other.does_asked_skill(i));
        let error = |r: &TaskReport, s: usize| r.constraint_error_per_sample.get(s).copied().unwrap_or(f64::NAN);
        theirs > own || (theirs == own && crate::dno::beats(error(other, i), error(self, b)))
    }

    /// The name of the first figure that is NaN or infinite (`None` when all are finite): a
    /// report must never store a broken figure as `null` or print it as a pass.
    pub fn non_finite_figure(&self) -> Option<String> {
        let scalars = [("constraint error", self.constraint_error), ("success rate", self.success_rate)];
        if let Some(name) =
            scalars.iter().find(|(_, v)| !v.is_finite()).map(|(name, _)| *name).or(self.motion.non_finite_figure())
        {
            return Some(name.to_owned());
        }
        let penetration =
            self.max_scene_penetration_m.iter().chain(self.scene_penetration_per_sample_m.iter().flatten());
        if penetration.into_iter().any(|v| !v.is_finite()) {
            return Some("scene penetration".to_owned());
        }
        if let Some(i) = self.constraint_error_per_sample.iter().position(|v| !v.is_finite()) {
            return Some(format!("constraint error of sample {i}"));
        }
        for c in &self.constraints {
            if let Some(i) = c.error.iter().position(|v| !v.is_finite()) {
                return Some(format!("error of constraint {} in sample {i}", c.id));
            }
            for check in &c.checks {
                if let Some(i) = check.value.iter().position(|v| !v.is_finite()) {
                    return Some(format!("{} of constraint {} in sample {i}", check.what, c.id));
                }
            }
        }
        None
    }
}

/// Builds the report of `generated` for `program`.
pub fn report(
    program: &TaskProgram,
    compiled: &CompiledProgram,
    generated: &Generated,
    config: &GenerationConfig,
) -> candle_core::Result<TaskReport> {
    let judged = judge(program, compiled, &generated.joints, &generated.initial_joints)?;
    let raw = judge(program, compiled, &generated.raw_joints, &generated.initial_joints)?;
    let cleanup = CleanupReport {
        enabled: config.foot_lock.enabled,
        samples: generated.foot_lock.clone(),
        refine_enabled: config.refines(),
        refine: generated.refine.clone(),
        before: BeforeCleanup {
            constraint_error: mean(&raw.per_sample),
            success_rate: raw.success_rate,
            max_scene_penetration_m: worst(&raw.penetration),
            steps: raw.steps.map(|s| s.counts),
            motion: MetricMeans::of(&raw.motions),
        },
    };
    Ok(TaskReport {
        text: program.text.clone(),
        frames: compiled.frames(),
        config: config.clone(),
        prior: None,
        seconds: generated.seconds,
        constraint_error: mean(&judged.per_sample),
        max_scene_penetration_m: worst(&judged.penetration),
        scene_penetration_per_sample_m: judged.penetration,
        constraint_error_per_sample: judged.per_sample,
        constraints: judged.constraints,
        success_rate: judged.success_rate,
        steps: judged.steps,
        skill: SkillReport::judge(&program.text, &judged.motions),
        motion: MetricMeans::of(&judged.motions),
        cleanup,
        rg_dno: None,
        fallback: None,
        attempt: None,
    })
}

/// Whether constraint `id` counts steps: `steps`, or a count over foot speeds.
fn is_step_count(program: &TaskProgram, id: &str) -> bool {
    use crate::program::{Expr, Point, Quantity};
    use crate::skeleton::Joint;
    let count = match program.constraint(id).map(|c| &c.expr) {
        Some(Expr::Steps(_)) => return true,
        Some(Expr::Count(count)) => count,
        _ => return false,
    };
    count.signals.iter().all(|s| {
        matches!(s, Quantity::Speed(d) | Quantity::Velocity(d)
            if matches!(d.of, Point::Joint(Joint::LeftFoot | Joint::RightFoot | Joint::LeftAnkle | Joint::RightAnkle)))
    })
}

fn to_f64(t: &Tensor) -> candle_core::Result<Vec<f64>> {
    t.to_dtype(DType::F64)?.to_vec1::<f64>()
}

#[cfg(test)]
mod tests {
    use candle_core::Device;

    use super::*;
    use crate::constraints::STANDING;
    use crate::generation::method::Method;

    /// The skill the prompt names is judged per sample by its family's detector: a straight
    /// walk passes "walks forward", fails "crawls", "turns left" and "carries a box" (its arms
    /// swing), and a prompt that names no skill (a reach) gets none.
    #[test]
    fn the_skill_the_prompt_names_is_detected_per_sample() {
        let walk = crate::motion::test_support::walking_poses(120, 0.0);
        let turn = crate::motion::test_support::walking_poses(120, 0.8);
        let motions = [walk, turn];
        let walked = SkillReport::judge("a person walks forward", &motions[..1]).unwrap();
        assert_eq!(
            (walked.family.as_str(), walked.pass.as_slice(), walked.passed_text()),
            ("walk", [true].as_slice(), "1/1".to_owned())
        );
        let crawled = SkillReport::judge("a person crawls forward", &motions).unwrap();
        assert_eq!(crawled.pass, [false, false]);
        let turned = SkillReport::judge("a person walks and turns left", &motions).unwrap();
        assert_eq!(turned.pass, [false, true]);
        let carried = SkillReport::judge("a person carries a box", &motions).unwrap();
        assert_eq!((carried.family.as_str(), carried.pass.as_slice()), ("carry", [false, false].as_slice()));
        assert!(SkillReport::judge("a person reaches up high", &motions).is_none());
    }

    /// The report's maximum scene penetration is the maximum over the samples, not their mean: of
    /// two standing figures, one with a toe 16 cm under the floor on one frame, the report gives
    /// 0.16 m, the per-sample figures 0 and 0.16, the floor depth 0.16 and a failed check.
    #[test]
    fn a_joint_under_the_floor_is_the_reports_maximum() {
        let frames = 10;
        let mut flat = Vec::new();
        for sample in 0..2 {
            for t in 0..frames {
                let mut pose = STANDING;
                if sample == 1 && t == 5 {
                    pose[crate::skeleton::Joint::LeftFoot.index()][1] = -0.16;
                }
                flat.extend(pose.iter().flatten().copied());
            }
        }
        let joints = Tensor::from_vec(flat, (2, frames, 22, 3), &Device::Cpu).unwrap();
        let program = TaskProgram::from_json(
            r#"{"text": "a person stands", "frames": 10, "constraints": [{"id": "c1", "expr":
                {"op": "scene", "body": {"joints": "all"}, "primitive": {"kind": "ground"}}}]}"#,
        )
        .unwrap();
        let compiled = CompiledProgram::compile(&program, &Device::Cpu).unwrap();
        let generated = Generated {
            features: Tensor::zeros((2, frames, 263), DType::F64, &Device::Cpu).unwrap(),
            joints: joints.clone(),
            raw_joints: joints.clone(),
            refine: Vec::new(),
            foot_lock: Vec::new(),
            initial_joints: joints,
            loss_history: vec![Vec::new(); 2],
            seconds: 0.0,
        };
        let r = report(&program, &compiled, &generated, &GenerationConfig::new(Method::Unconstrained)).unwrap();
        let depths = r.scene_penetration_per_sample_m.clone().unwrap();
        assert!(depths[0].abs() < 1e-9 && (depths[1] - 0.16).abs() < 1e-9, "{depths:?}");
        assert!((r.max_scene_penetration_m.unwrap() - 0.16).abs() < 1e-9);
        // Poses are f32: 0.16 to single precision.
        assert!((r.motion.max_under_floor_m - 0.16).abs() < 1e-6, "{}", r.motion.max_under_floor_m);
        assert_eq!(r.constraints[0].pass, vec![true, false]);
        assert_eq!(r.success_rate, 0.5);
        // The sample under the floor is the one to retry; the standing one beats it, not the
        // reverse, and a sample never beats itself.
        assert_eq!(r.unmet_samples(), vec![1]);
        assert!(r.beaten_by(1, &r, 0));
        assert!(!r.beaten_by(0, &r, 1));
        assert!(!r.beaten_by(1, &r, 1));
        // A sample that meets every constraint but not the skill the prompt asks for falls
        // short too; constraints still come first, then the skill, then the error.
        let mut hop = r.clone();
        let skill = SkillReport {
            family: "hop on one foot".into(),
            detector: "airborne".into(),
            pass: vec![false, true],
            asked: true,
        };
        hop.skill = Some(skill.clone());
        assert_eq!((hop.unmet_samples(), hop.skill_missed_samples()), (vec![1], vec![0]));
        assert!(hop.beaten_by(1, &hop, 0) && !hop.beaten_by(0, &hop, 1), "the met sample wins though it glides");
        hop.constraints[0].pass = vec![true, true];
        hop.constraint_error_per_sample = vec![0.0, 1.0];
        assert!(hop.beaten_by(0, &hop, 1), "the sample that hops wins over a lower error");
        assert!(!hop.beaten_by(1, &hop, 0));
        // A walk's detector is only reported: prompts name walking loosely.
        hop.skill = Some(SkillReport { asked: false, ..skill });
        assert!(hop.skill_missed_samples().is_empty() && hop.beaten_by(1, &hop, 0));
    }
}

impl TaskReport {
    /// The headline figures as a person reads them after a run: every constraint with its
    /// checks, RG-DNO's retrieval, masks and stage seconds, the motion figures, the refinement
    /// and the foot clean-up.
    pub fn summary(&self) -> Summary<'_> {
        Summary(self)
    }
}

/// [`TaskReport::summary`], written by its `Display`.
#[derive(Debug, Clone, Copy)]
pub struct Summary<'a>(&'a TaskReport);

impl fmt::Display for Summary<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let report = self.0;
        let per_sample: Vec<String> = report.constraint_error_per_sample.iter().map(|e| format!("{e:.5}")).collect();
        writeln!(
            f,
            "{}: constraint error {:.6} (per sample {per_sample:?}) in {:.1} s",
            report.config.method, report.constraint_error, report.seconds
        )?;
        for c in &report.constraints {
            constraint_lines(f, c)?;
        }
        writeln!(f, "  all constraints met by {:.0}% of the samples", 100.0 * report.success_rate)?;
        if let Some(skill) = &report.skill {
            writeln!(
                f,
                "  the skill the prompt names, {} ({}): detected in {} samples",
                skill.family,
                skill.detector,
                skill.passed_text()
            )?;
        }
        if let Some(why) = &report.fallback {
            writeln!(f, "  RG-DNO fell back to DNO: {why}")?;
        }
        if let Some(attempt) = report.attempt.as_ref().filter(|a| a.iter().any(|&k| k > 0)) {
            let kept: Vec<String> = attempt.iter().map(|k| (k + 1).to_string()).collect();
            writeln!(f, "  attempt kept per sample (1 = the first): {}", kept.join(", "))?;
        }
        if let Some(rg) = &report.rg_dno {
            rg_dno_lines(f, report, rg)?;
        }
        let penetration = report.max_scene_penetration_m.map_or("n/a".to_owned(), |p| format!("{p:.4} m"));
        writeln!(
            f,
            "  foot skate {:.3}, max acceleration {:.4} m/frame², max scene penetration {penetration}, head-neck \
             incorrect {:.2}",
            report.motion.foot_skate_ratio, report.motion.max_acceleration, report.motion.head_neck_incorrect_ratio
        )?;
        if let Some(steps) = &report.steps {
            writeln!(
                f,
                "  steps (footfalls) {} (target {}), success {:.2}",
                steps.counts_text(),
                steps.target,
                steps.success_rate
            )?;
        }
        refinement_line(f, &report.cleanup)?;
        cleanup_line(f, &report.cleanup)
    }
}

/// A constraint's loss, how many samples meet it, and each of its checks.
fn constraint_lines(f: &mut fmt::Formatter<'_>, c: &ConstraintReport) -> fmt::Result {
    let passed = c.pass.iter().filter(|p| **p).count();
    writeln!(
        f,
        "  {} (weight {}): loss {:.6}, met by {passed}/{} samples  {}",
        c.id,
        c.weight,
        mean(&c.error),
        c.pass.len(),
        c.description.as_deref().unwrap_or("")
    )?;
    for check in &c.checks {
        let worst = check.value.iter().copied().fold(0.0, f64::max);
        let per_sample: Vec<String> = check.value.iter().map(|v| format!("{v:.3}")).collect();
        writeln!(
            f,
            "      {}: worst {worst:.3} {} (tolerance {}; per sample {per_sample:?})",
            check.what, check.unit, check.tolerance
        )?;
    }
    Ok(())
}

/// RG-DNO's retrieved motion, each sample's mask and the stages' seconds.
fn rg_dno_lines(f: &mut fmt::Formatter<'_>, report: &TaskReport, rg: &RgDnoReport) -> fmt::Result {
    for (k, used) in rg.inverted.iter().enumerate() {
        let Some(r) = rg.retrieved.get(used.motion) else { continue };
        let similarity = r.caption_similarity.map_or(String::new(), |s| format!(", caption similarity {s:.2}"));
        let rank = if used.motion == 0 { String::new() } else { format!(" (retrieved motion {})", used.motion) };
        let pool = match k {
            0 => format!(
                ", best of {} candidates ({} after the semantic check) in {:.1} s",
                rg.candidates, rg.consistent_candidates, rg.seconds.retrieval
            ),
            _ => String::new(),
        };
        writeln!(
            f,
            "  retrieved{rank} {} resized to {} frames, C_R score {:.4}{similarity}{pool}; inversion error {:.3} m",
            r.source, report.frames, r.score, used.error_m
        )?;
    }
    if let Some(note) = missing_actions_note(rg.missing_actions.iter().map(String::as_str)) {
        writeln!(f, "  {note}: the retrieved motion is a stand-in the prompt's other actions accept")?;
    }
    if let Some(skills) = &rg.skills {
        writeln!(f, "  {skills}")?;
    }
    let restarts = report.config.dno.restarts;
    for (i, m) in rg.masks.iter().enumerate() {
        let restart = rg
            .restart
            .get(i)
            .filter(|_| restarts > 1)
            .map_or(String::new(), |r| format!(" (restart {r} of {restarts})"));
        let restart = match rg.motion.get(i) {
            Some(&j) if rg.inverted.len() > 1 || j > 0 => format!("{restart}, from retrieved motion {j}"),
            _ => restart,
        };
        writeln!(
            f,
            "  sample {i}: {:?} mask {:0w$b}, F_C {:.4}, reward {:.4}, place {} in the scoring order{restart}",
            m.candidate.kind,
            m.candidate.bits,
            m.constraint_error,
            m.reward,
            m.place + 1,
            w = m.candidate.segments
        )?;
    }
    let s = &rg.seconds;
    writeln!(
        f,
        "  RG-DNO seconds: retrieval {:.1}, inversion {:.1}, branches {:.1}, masks {:.1}, soft blend {:.1}, final \
         round {:.1}",
        s.retrieval, s.inversion, s.branches, s.masks, s.soft_blend, s.final_round
    )?;
    let n = &rg.steps;
    let coarse = match n.final_round_coarse {
        0 => String::new(),
        k => format!(" ({k} on the coarse sampler)"),
    };
    writeln!(
        f,
        "  RG-DNO steps: inversion {}, branches {}, masks {} candidates, soft blend {}, final round {}{coarse}",
        n.inversion, n.branches, n.masks, n.soft_blend, n.final_round
    )
}

/// Whether the refinement was kept, how far it moved joints, and the error before and after.
fn refinement_line(f: &mut fmt::Formatter<'_>, cleanup: &CleanupReport) -> fmt::Result {
    if !cleanup.refine_enabled {
        return writeln!(f, "  refinement: off");
    }
    let kept = cleanup.refine.iter().filter(|r| r.applied).count();
    let moved = cleanup.refine.iter().filter(|r| r.applied).map(|r| r.max_offset_m).fold(0.0, f64::max);
    let errors: Vec<String> =
        cleanup.refine.iter().map(|r| format!("{:.4} → {:.4}", r.error_before, r.error_after)).collect();
    writeln!(
        f,
        "  refinement: kept for {kept}/{} samples, joints moved up to {moved:.3} m, constraint error {}",
        cleanup.refine.len(),
        errors.join(", ")
    )
}

/// What the foot clean-up did and the network's figures before the refinement and the clean-up.
fn cleanup_line(f: &mut fmt::Formatter<'_>, cleanup: &CleanupReport) -> fmt::Result {
    if !cleanup.enabled {
        return writeln!(f, "  foot clean-up: off");
    }
    let before = &cleanup.before;
    let locked: usize = cleanup.samples.iter().flat_map(|s| s.contacts.iter()).map(|c| c.locked_frames).sum();
    let moved = cleanup.samples.iter().map(|s| s.max_displacement_m).fold(0.0, f64::max);
    let shortened: usize = cleanup.samples.iter().map(|s| s.shortened).sum();
    let raised = cleanup.samples.iter().map(|s| s.raised_m).fold(0.0, f64::max);
    let held: usize = cleanup.samples.iter().map(|s| s.held_above_floor).sum();
    let penetration = before.max_scene_penetration_m.map_or("n/a".to_owned(), |p| format!("{p:.4} m"));
    let undone: Vec<String> = cleanup
        .samples
        .iter()
        .enumerate()
        .filter(|(_, s)| !s.undone_for.is_empty())
        .map(|(i, s)| format!("sample {i} (it would break {})", s.undone_for.join(", ")))
        .collect();
    if !undone.is_empty() {
        writeln!(f, "  foot clean-up undone for {}: the motion before it is kept", undone.join("; "))?;
    }
    let given_up: Vec<String> =
        cleanup.samples.iter().enumerate().filter(|(_, s)| s.locks_given_up).map(|(i, _)| i.to_string()).collect();
    if !given_up.is_empty() {
        writeln!(
            f,
            "  foot locks given up for sample {}: they would raise the foot skate or jerk the motion; it is only set on the floor",
            given_up.join(", ")
        )?;
    }
    writeln!(
        f,
        "  foot clean-up: {locked} joint-frames locked ({shortened} sliding contacts cut to their steadiest \
         stretch), sinking frames raised up to {raised:.3} m, {held} leg-frames held above the floor, joints \
         moved up to {moved:.3} m; the network's motion before the refinement and the clean-up: foot skate {:.3}, \
         all constraints met by {:.0}%, max scene penetration {penetration}{}",
        before.motion.foot_skate_ratio,
        100.0 * before.success_rate,
        before.steps.as_ref().map_or(String::new(), |s| format!(", steps {s:?}"))
    )
}
