//! Retrieval-guided diffusion noise optimisation (RG-DNO, Liu et al.; `../shared/papers/rg-dno-*`
//! §4, Fig. 2): for a task whose relational parse names its most difficult constraint,
//!
//! 1. **groups** (§4.2, Algorithm 1, [`crate::program::TaskProgram::constraint_groups`]): the
//!    retrieval set `C_R`, the random-noise set `C1` and the retrieved-noise set `C2`;
//! 2. **retrieval** (§4.3, eqs. 5–6, [`retrieval`]): the database motion `x_R` that best
//!    satisfies `C_R`;
//! 3. **inversion** (eq. 7): `z_R = G⁻¹(x_R)` ([`crate::inversion::invert_motion`]);
//! 4. **two branches** (eqs. 8–9): `z1` from random noise fitted to `C1`, `z2` from `z_R`
//!    fitted to `C2`, each `N1` DNO steps;
//! 5. **mask** (eqs. 10, 13, [`mask`], [`reward`]): the best of the binary temporal and spatial
//!    masks by `F_C(G(z')) + R(G(z'), z')`, all candidates evaluated without gradients, then the
//!    soft sigmoid blend optimised on the same objective;
//! 6. **final round** (eq. 12): DNO on the whole task from `z'` (`N2` steps).
//!
//! The output goes through the same contact-aware clean-up as every other method.

pub mod mask;
pub mod retrieval;
pub mod reward;

use std::time::Instant;

use candle_core::{DType, Device, Tensor, Var};
use rand::rngs::StdRng;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use crate::constraints::CompiledProgram;
use crate::diffusion::noise::gaussian;
use crate::diffusion::{Denoiser, Guidance};
use crate::dno::{self, DnoConfig, UnrolledDdim};
use crate::generation::{
    finish, joints_objective, pick_rows, program_objective, Generated, GenerationConfig, GenerationError,
};
use crate::inversion::{invert_motion, mean_joint_distance, InversionConfig};
use crate::prior::Prior;
use crate::program::{ConstraintGroups, TaskProgram};
use crate::representation::FEATURE_DIM;
use crate::training::AdamW;
use mask::{blend, soft_blend, soft_logits, MaskCandidate, MaskKind};
use retrieval::{retrieve, CandidateSource, RetrievalConfig, RetrievalCorpus, RetrievalQuery};
use reward::{reward, RewardWeights};

/// Every RG-DNO setting (the paper's defaults, §5.2: N1 = 100 at lr 0.05, N2 = 400 at lr 0.02).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RgDnoConfig {
    /// Constraint-based retrieval.
    pub retrieval: RetrievalConfig,
    /// The inversion of the retrieved motion (its `guidance` and `ddim_steps` are replaced by
    /// the run's; default: 50 + 50 polish steps).
    pub inversion: InversionConfig,
    /// DNO steps `N1` of each branch and of the soft blend (default 100).
    pub first_steps: usize,
    /// Peak learning rate of the branches and the soft blend (default 0.05).
    pub first_lr: f64,
    /// Temporal segments `N_T` (default 8).
    pub segments: usize,
    /// Which mask kinds are tried (default both; the supplementary picks by eq. 13).
    pub mask_kinds: Vec<MaskKind>,
    /// Mask candidates sampled per batch, per sample (default 16).
    pub mask_batch: usize,
    /// The reward weights λ of eq. 14.
    pub reward: RewardWeights,
    /// DNO steps `N2` of the final round (default 400).
    pub final_steps: usize,
    /// Peak learning rate of the final round (default 0.02).
    pub final_lr: f64,
    /// One of Table 4's ablations instead of the full method (default: none).
    pub ablation: Ablation,
}

/// Table 4's ablations of RG-DNO (each leaves one part of the method out).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Ablation {
    /// The full method.
    #[default]
    None,
    /// `z' = z1`: the random-noise branch alone (no retrieved noise, no mask).
    RandomOnly,
    /// `z' = z2`: the retrieved branch alone (no random noise, no mask).
    RetrievedOnly,
    /// Without relational task parsing: `C_R = C`.
    NoParsing,
    /// Without mask optimisation: `M = 0.5` everywhere.
    HalfMask,
    /// Without the reward: masks and the soft blend by `F_C` alone.
    NoReward,
    /// `C1 = C2 = C`.
    SameSets,
}

impl Ablation {
    /// Algorithm 1's groups as this ablation changes them.
    fn groups(self, groups: ConstraintGroups, all: Vec<String>) -> ConstraintGroups {
        match self {
            Ablation::NoParsing => ConstraintGroups { retrieval: all, ..groups },
            Ablation::SameSets => ConstraintGroups { random_noise: all.clone(), retrieved_noise: all, ..groups },
            _ => groups,
        }
    }

    /// The fixed blend of the branches, where the ablation replaces the mask search: the mask
    /// value `M` of `z' = M·z1 + (1 − M)·z2`.
    fn fixed_mask(self) -> Option<f64> {
        match self {
            Ablation::RandomOnly => Some(1.0),
            Ablation::RetrievedOnly => Some(0.0),
            Ablation::HalfMask => Some(0.5),
            _ => None,
        }
    }
}

impl Default for RgDnoConfig {
    fn default() -> Self {
        Self {
            retrieval: RetrievalConfig::default(),
            // Half the inversion's default polish: on Task-1's retrieved clip, 50 + 50 steps left
            // 0.038 m of mean joint error against 0.037 m with 100 + 100, in 5.5 s instead of 12.
            inversion: InversionConfig { feature_polish_steps: 50, polish_steps: 50, ..InversionConfig::default() },
            first_steps: 100,
            first_lr: 0.05,
            segments: 8,
            mask_kinds: vec![MaskKind::Temporal, MaskKind::Spatial],
            mask_batch: 16,
            reward: RewardWeights::default(),
            final_steps: 400,
            final_lr: 0.02,
            ablation: Ablation::None,
        }
    }
}

/// Most temporal segments `N_T` (2^12 = 4,096 temporal candidates).
pub const MAX_SEGMENTS: usize = 12;

impl RgDnoConfig {
    /// The settings with every optimisation stage's steps (the inversion's two polishes, the
    /// branches and the soft blend `N1`, the final round `N2`) scaled by `steps / 500`, DNO's
    /// default: the defaults' 50 + 50 polish, 100 for the branches and the blend, 400 final at
    /// 500; each at least 1 unless it is 0. For quick runs.
    pub fn scaled_to(&self, steps: usize) -> RgDnoConfig {
        // A stage switched off (0 steps) stays off.
        let scale = |n: usize| if n == 0 { 0 } else { (n * steps).div_ceil(DnoConfig::default().steps).max(1) };
        let mut scaled = self.clone();
        scaled.first_steps = scale(self.first_steps);
        scaled.final_steps = scale(self.final_steps);
        scaled.inversion.feature_polish_steps = scale(self.inversion.feature_polish_steps);
        scaled.inversion.polish_steps = scale(self.inversion.polish_steps);
        scaled
    }

    /// Errors on settings the stages cannot run with, naming the field.
    pub fn validate(&self, frames: usize) -> Result<(), GenerationError> {
        let bad = |message: String| Err(GenerationError::Setting(message));
        if !(1..=MAX_SEGMENTS.min(frames)).contains(&self.segments) {
            return bad(format!(
                "rg_dno.segments must be between 1 and {} (and at most the {frames} frames), got {}",
                MAX_SEGMENTS, self.segments
            ));
        }
        if self.mask_kinds.is_empty() {
            return bad("rg_dno.mask_kinds must name at least one of \"temporal\", \"spatial\"".into());
        }
        if self.first_steps == 0 || self.final_steps == 0 {
            return bad(format!(
                "rg_dno.first_steps and final_steps must be at least 1, got {} and {}",
                self.first_steps, self.final_steps
            ));
        }
        for (name, value) in [("first_lr", self.first_lr), ("final_lr", self.final_lr)] {
            if !(value.is_finite() && value > 0.0) {
                return bad(format!("rg_dno.{name} must be a positive number, got {value}"));
            }
        }
        let w = &self.reward;
        for (name, value) in [
            ("jitter", w.jitter),
            ("foot_skate", w.foot_skate),
            ("decorrelation", w.decorrelation),
            ("semantic", w.semantic),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return bad(format!("rg_dno.reward.{name} must be finite and ≥ 0, got {value}"));
            }
        }
        Ok(())
    }
}

/// Why RG-DNO did not run (the caller falls back to DNO and says why).
#[derive(Debug, thiserror::Error)]
pub enum RgDnoError {
    /// The program has no relational parse.
    #[error("the program has no relational parse, so there is nothing to retrieve")]
    NoParse,
    /// No database motion passed the semantic check and the threshold.
    #[error("no database motion passed the semantic check and the retrieval threshold")]
    NothingRetrieved,
    /// The retrieval database could not be opened.
    #[error("the retrieval database ({source_name}): {error}")]
    Database {
        /// Where it was looked for.
        source_name: String,
        /// What went wrong.
        error: Box<crate::database::DatabaseError>,
    },
    /// Retrieval failed.
    #[error(transparent)]
    Retrieval(#[from] retrieval::RetrievalError),
    /// Generation failed.
    #[error(transparent)]
    Generation(#[from] GenerationError),
}

impl From<candle_core::Error> for RgDnoError {
    fn from(error: candle_core::Error) -> Self {
        RgDnoError::Generation(GenerationError::Tensor(error))
    }
}

/// A retrieved motion as the report gives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RetrievedReport {
    /// Where it comes from.
    pub source: CandidateSource,
    /// `Σ w_i·E_i` over `C_R`.
    pub score: f64,
    /// `(id, E_i)` per constraint of `C_R`.
    pub per_constraint: Vec<(String, f64)>,
}

/// The mask chosen for one sample.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChosenMask {
    /// The binary candidate.
    pub candidate: MaskCandidate,
    /// `F_C` of its motion.
    pub constraint_error: f64,
    /// `R` of its motion and noise.
    pub reward: f64,
}

/// Seconds per stage.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StageSeconds {
    /// Scoring the corpus.
    pub retrieval: f64,
    /// Inverting `x_R`.
    pub inversion: f64,
    /// Fitting `z1` and `z2` (all restarts).
    pub branches: f64,
    /// Evaluating the binary masks.
    pub masks: f64,
    /// Optimising the soft blend.
    pub soft_blend: f64,
    /// The final DNO round.
    pub final_round: f64,
}

impl StageSeconds {
    /// The seconds of both runs, stage by stage.
    fn plus(&self, other: &StageSeconds) -> StageSeconds {
        StageSeconds {
            retrieval: self.retrieval + other.retrieval,
            inversion: self.inversion + other.inversion,
            branches: self.branches + other.branches,
            masks: self.masks + other.masks,
            soft_blend: self.soft_blend + other.soft_blend,
            final_round: self.final_round + other.final_round,
        }
    }
}

impl RgDnoReport {
    /// This report with the per-sample figures of `other` (another attempt at the same task)
    /// where `rows[b]` is `Some(i)`, as [`Generated::with_rows_from`]; the seconds add up.
    pub fn with_rows_from(self, other: RgDnoReport, rows: &[Option<usize>]) -> RgDnoReport {
        RgDnoReport {
            z1_error: pick_rows(self.z1_error, &other.z1_error, rows),
            z2_error: pick_rows(self.z2_error, &other.z2_error, rows),
            masks: pick_rows(self.masks, &other.masks, rows),
            soft_blend_objective: pick_rows(self.soft_blend_objective, &other.soft_blend_objective, rows),
            restart: pick_rows(self.restart, &other.restart, rows),
            final_objective: pick_rows(self.final_objective, &other.final_objective, rows),
            seconds: self.seconds.plus(&other.seconds),
            ..self
        }
    }
}

/// What each RG-DNO stage did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RgDnoReport {
    /// `C_R`, `C1`, `C2` by id.
    pub retrieval_set: Vec<String>,
    /// `C1`.
    pub random_noise_set: Vec<String>,
    /// `C2`.
    pub retrieved_noise_set: Vec<String>,
    /// Candidates in the corpus (before the semantic check).
    pub candidates: usize,
    /// The retrieved motions, best first; the first is `x_R`.
    pub retrieved: Vec<RetrievedReport>,
    /// Mean joint distance of `G(z_R)` to `x_R`, m.
    pub inversion_error_m: f64,
    /// `F_{C1}(G(z1))` per sample.
    pub z1_error: Vec<f64>,
    /// `F_{C2}(G(z2))` per sample.
    pub z2_error: Vec<f64>,
    /// The chosen binary mask per sample.
    pub masks: Vec<ChosenMask>,
    /// `F_C + R` after the soft blend, per sample.
    pub soft_blend_objective: Vec<f64>,
    /// The restart each sample kept (all 0 with `N_S` = 1).
    #[serde(default)]
    pub restart: Vec<usize>,
    /// `F_C` (with the jitter guard) of each sample's final motion, the restart criterion.
    #[serde(default)]
    pub final_objective: Vec<f64>,
    /// Seconds per stage.
    pub seconds: StageSeconds,
    /// The settings.
    pub config: RgDnoConfig,
}

/// A stage of RG-DNO, for progress reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Polishing the inverted noise.
    Inversion,
    /// Fitting `z1` to `C1` and `z2` to `C2` (one batch).
    Branches,
    /// Evaluating the binary masks (step = candidates done).
    Masks,
    /// Optimising the soft blend.
    SoftBlend,
    /// The final DNO round.
    FinalRound,
}

impl Stage {
    /// A short name.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Inversion => "inversion",
            Stage::Branches => "z1 (random noise, C1) and z2 (retrieved noise, C2)",
            Stage::Masks => "masks",
            Stage::SoftBlend => "soft blend",
            Stage::FinalRound => "final round",
        }
    }
}

/// Progress of a running stage.
#[derive(Debug, Clone)]
pub struct StageProgress {
    /// The stage.
    pub stage: Stage,
    /// The restart (0 to `N_S` − 1; 0 for the inversion, which runs once).
    pub round: usize,
    /// Steps done.
    pub step: usize,
    /// Steps of the stage.
    pub steps: usize,
    /// Mean loss over the samples (0 where a stage has none).
    pub loss: f64,
}

impl StageProgress {
    /// The progress of a DNO step of `stage` in restart `round`.
    fn of_dno(stage: Stage, round: usize, step: &dno::DnoStep) -> Self {
        StageProgress { stage, round, step: step.step + 1, steps: step.steps, loss: mean(&step.loss) }
    }
}

/// A task as RG-DNO takes it: the program (with its relational parse), compiled, and the
/// retrieval corpus built for its frame count.
#[derive(Debug, Clone, Copy)]
pub struct RgDnoTask<'a> {
    /// The program.
    pub program: &'a TaskProgram,
    /// The program compiled.
    pub compiled: &'a CompiledProgram,
    /// Candidates of `program.frames` frames.
    pub corpus: &'a RetrievalCorpus,
}

/// Generates `config.samples` motions for `task` with RG-DNO. `config` gives the samples,
/// seed, guidance, DDIM steps, the DNO regulariser, the jitter guard, the clean-up and the
/// restarts `N_S` (`config.dno.restarts`: retrieval and inversion run once; restart r runs the
/// stages after them from the random noise of seed `seed + r`, and each sample keeps the
/// restart whose final motion has the lowest `F_C`); `rg` the RG-DNO stages.
pub fn generate_rg_dno(
    prior: &Prior,
    task: RgDnoTask<'_>,
    config: &GenerationConfig,
    rg: &RgDnoConfig,
    device: &Device,
    mut progress: impl FnMut(&StageProgress),
) -> Result<(Generated, RgDnoReport), RgDnoError> {
    let RgDnoTask { program, compiled, corpus } = task;
    rg.validate(compiled.frames())?;
    config.check(compiled.frames())?;
    config.dno.validate()?;
    let start = Instant::now();
    let all = program.constraints.iter().map(|c| c.id.clone()).collect();
    let groups = rg.ablation.groups(program.constraint_groups().ok_or(RgDnoError::NoParse)?, all);
    let parse = program.relational_parse.as_ref().ok_or(RgDnoError::NoParse)?;
    let mut seconds = StageSeconds::default();
    let batch = config.samples;

    // Retrieval (eqs. 5–6).
    let clock = Instant::now();
    let c_r = compiled.subset(&groups.retrieval);
    let query = RetrievalQuery {
        program: &c_r,
        most_difficult: &parse.most_difficult,
        prompt: &program.text,
        counting: !c_r.count_targets().is_empty(),
    };
    let retrieved = retrieve(corpus, &query, &rg.retrieval)?;
    let best = retrieved.first().ok_or(RgDnoError::NothingRetrieved)?;
    seconds.retrieval = clock.elapsed().as_secs_f64();

    // The solver, as DNO's, for the batch and for both branches side by side.
    let text = prior.encode_text(&vec![program.text.as_str(); batch], device)?;
    let guidance = Guidance { scale: config.guidance }.for_text(&text)?;
    let solver = UnrolledDdim::new(&prior.mdm, text.clone(), guidance, config.dno.ddim_steps)?;
    let both = UnrolledDdim::new(&prior.mdm, text.repeat((2, 1))?, guidance, config.dno.ddim_steps)?;

    // Inversion (eq. 7), once for the batch.
    let clock = Instant::now();
    let x_r = prior.mean_std.normalize(&best.features.to_dtype(DType::F32)?.unsqueeze(0)?)?;
    let inversion =
        InversionConfig { guidance: config.guidance, ddim_steps: config.dno.ddim_steps, ..rg.inversion.clone() };
    let polish_steps = inversion.feature_polish_steps + inversion.polish_steps;
    let mut polished = 0;
    let inverted = invert_motion(prior, &x_r, &text.narrow(0, 0, 1)?, &inversion, |s| {
        polished += 1;
        progress(&StageProgress {
            stage: Stage::Inversion,
            round: 0,
            step: polished,
            steps: polish_steps,
            loss: mean(&s.loss),
        });
    })?;
    let inversion_error_m = scalar(&mean_joint_distance(&prior.to_joints(&inverted.x)?, &prior.to_joints(&x_r)?)?)?;
    let z_r = inverted.z.broadcast_as((batch, compiled.frames(), FEATURE_DIM))?.contiguous()?;
    seconds.inversion = clock.elapsed().as_secs_f64();

    let stages = Stages { prior, compiled, groups: &groups, config, rg, solver: &solver, both: &both, z_r: &z_r };
    let mut kept: Option<Attempt> = None;
    let mut restart = vec![0; batch];
    for r in 0..config.dno.restarts {
        let attempt = stages.attempt(config.seed.wrapping_add(r as u64), r, &mut seconds, &mut progress)?;
        kept = Some(match kept {
            None => attempt,
            Some(old) => {
                let take: Vec<bool> =
                    attempt.objective.iter().zip(&old.objective).map(|(&new, &old)| dno::beats(new, old)).collect();
                for (chosen, _) in restart.iter_mut().zip(&take).filter(|(_, &t)| t) {
                    *chosen = r;
                }
                old.merge(attempt, &take)?
            }
        });
    }
    let kept = kept.ok_or_else(|| GenerationError::Setting("RG-DNO ran no restarts".into()))?;

    let generated = finish(prior, program, compiled, config, kept.features, kept.initial_joints, kept.history, start)?;
    let report = RgDnoReport {
        retrieval_set: groups.retrieval,
        random_noise_set: groups.random_noise,
        retrieved_noise_set: groups.retrieved_noise,
        candidates: corpus.len(),
        retrieved: retrieved
            .iter()
            .map(|r| RetrievedReport {
                source: r.source.clone(),
                score: r.score,
                per_constraint: r.per_constraint.clone(),
            })
            .collect(),
        inversion_error_m,
        z1_error: kept.z1_error,
        z2_error: kept.z2_error,
        masks: kept.masks,
        soft_blend_objective: kept.soft_blend_objective,
        restart,
        final_objective: kept.objective,
        seconds,
        config: rg.clone(),
    };
    Ok((generated, report))
}

/// What every restart shares: the compiled task and its groups, the settings, the two solvers
/// (batch `B` and `2B`) and the inverted noise `z_R` `[B, T, 263]`.
struct Stages<'a, M: Denoiser + ?Sized> {
    prior: &'a Prior,
    compiled: &'a CompiledProgram,
    groups: &'a ConstraintGroups,
    config: &'a GenerationConfig,
    rg: &'a RgDnoConfig,
    solver: &'a UnrolledDdim<'a, M>,
    both: &'a UnrolledDdim<'a, M>,
    z_r: &'a Tensor,
}

/// One restart's outcome, per sample.
struct Attempt {
    /// Normalised features of the final motion `[B, T, 263]`.
    features: Tensor,
    /// `G(z0)` of the restart's random noise as joints `[B, T, 22, 3]`.
    initial_joints: Tensor,
    /// `F_C` of the final motion (the restart criterion).
    objective: Vec<f64>,
    z1_error: Vec<f64>,
    z2_error: Vec<f64>,
    masks: Vec<ChosenMask>,
    soft_blend_objective: Vec<f64>,
    /// The final round's criterion per step.
    history: Vec<Vec<f64>>,
}

impl Attempt {
    /// `self` with the samples of `other` where `take` is true.
    fn merge(self, other: Attempt, take: &[bool]) -> candle_core::Result<Attempt> {
        fn pick<T>(old: Vec<T>, new: Vec<T>, take: &[bool]) -> Vec<T> {
            old.into_iter().zip(new).zip(take).map(|((o, n), &t)| if t { n } else { o }).collect()
        }
        Ok(Attempt {
            features: dno::take_rows(take, &other.features, &self.features)?,
            initial_joints: dno::take_rows(take, &other.initial_joints, &self.initial_joints)?,
            objective: pick(self.objective, other.objective, take),
            z1_error: pick(self.z1_error, other.z1_error, take),
            z2_error: pick(self.z2_error, other.z2_error, take),
            masks: pick(self.masks, other.masks, take),
            soft_blend_objective: pick(self.soft_blend_objective, other.soft_blend_objective, take),
            history: pick(self.history, other.history, take),
        })
    }
}

impl<M: Denoiser + ?Sized> Stages<'_, M> {
    /// The stages after the inversion from the random noise of `seed`: both branches, the
    /// binary masks, the soft blend and the final round.
    fn attempt(
        &self,
        seed: u64,
        round: usize,
        seconds: &mut StageSeconds,
        progress: &mut dyn FnMut(&StageProgress),
    ) -> Result<Attempt, RgDnoError> {
        let Stages { prior, compiled, groups, config, rg, solver, both, z_r, .. } = *self;
        let (batch, frames, _) = z_r.dims3()?;
        let device = z_r.device();
        let guidance = solver.guidance;
        let z0 = gaussian((batch, frames, FEATURE_DIM), seed, device)?;
        let initial_joints =
            prior.to_joints(&solver.sampler.sample(solver.denoiser, &z0, &solver.text, guidance)?)?;

        // The two branches (eqs. 8–9) in one batch: rows 0..B are z1 from random noise fitted to
        // C1, rows B..2B are z2 from z_R fitted to C2.
        let clock = Instant::now();
        let first = DnoConfig {
            steps: rg.first_steps,
            lr: rg.first_lr,
            lr_warmup_steps: rg.first_steps / 10,
            lr_decay_steps: None,
            seed,
            restarts: 1,
            keep_best: true,
            ..config.dno.clone()
        };
        let (c1, c2) = (compiled.subset(&groups.random_noise), compiled.subset(&groups.retrieved_noise));
        let f1 = program_objective(prior, &c1, &initial_joints, config.jitter_weight);
        let f2 = program_objective(prior, &c2, &initial_joints, config.jitter_weight);
        let branches = |x: &Tensor| Tensor::cat(&[f1(&x.narrow(0, 0, batch)?)?, f2(&x.narrow(0, batch, batch)?)?], 0);
        let starts = Tensor::cat(&[&z0, z_r], 0)?;
        let fitted = dno::optimize(both, branches, &starts, &first, |s| {
            progress(&StageProgress::of_dno(Stage::Branches, round, s))
        })?;
        let (z1, z2) = (fitted.z.narrow(0, 0, batch)?, fitted.z.narrow(0, batch, batch)?);
        let (z1_error, z2_error) = (fitted.loss[..batch].to_vec(), fitted.loss[batch..].to_vec());
        seconds.branches += clock.elapsed().as_secs_f64();

        let reward_weights = if rg.ablation == Ablation::NoReward { RewardWeights::NONE } else { rg.reward };
        let full = program_objective(prior, compiled, &initial_joints, config.jitter_weight);
        let (z_blend, masks, soft_blend_objective) = match rg.ablation.fixed_mask() {
            Some(m) => (blend(&Tensor::new(m, z1.device())?, &z1, &z2)?, Vec::new(), Vec::new()),
            None => {
                let stages = MaskStages {
                    prior,
                    rg,
                    solver,
                    objective: Objective { compiled, initial: &initial_joints, jitter_weight: config.jitter_weight },
                    weights: &reward_weights,
                    round,
                };
                stages.search(&z1, &z2, seed, seconds, progress)?
            }
        };

        // Final round (eq. 12).
        let clock = Instant::now();
        let last = DnoConfig {
            steps: rg.final_steps,
            lr: rg.final_lr,
            seed,
            restarts: 1,
            keep_best: true,
            ..config.dno.clone()
        };
        let run = dno::optimize(solver, &full, &z_blend, &last, |s| {
            progress(&StageProgress::of_dno(Stage::FinalRound, round, s))
        })?;
        // With the best iterate kept, `run.x` is the motion of `run.z` and `run.loss` its F_C.
        let (features, objective) = (run.x, run.loss);
        seconds.final_round += clock.elapsed().as_secs_f64();
        Ok(Attempt {
            features,
            initial_joints: initial_joints.clone(),
            objective,
            z1_error,
            z2_error,
            masks,
            soft_blend_objective,
            history: run.history.into_iter().map(|h| h.loss).collect(),
        })
    }
}

/// The mask search of one restart: eq. 13's binary candidates, then the soft blend.
struct MaskStages<'a, M: Denoiser + ?Sized> {
    prior: &'a Prior,
    rg: &'a RgDnoConfig,
    solver: &'a UnrolledDdim<'a, M>,
    /// `F_C`, evaluated on joints the stage has already recovered.
    objective: Objective<'a>,
    weights: &'a RewardWeights,
    round: usize,
}

/// The program objective's parts ([`program_objective`]): the compiled program, the initial
/// joints `[B or 1, T, 22, 3]` and the jitter guard's weight.
#[derive(Clone, Copy)]
struct Objective<'a> {
    compiled: &'a CompiledProgram,
    initial: &'a Tensor,
    jitter_weight: f64,
}

impl Objective<'_> {
    /// Per row `[copies·B]` for joints whose row `k·B + b` belongs to sample `b`.
    fn on_copies(&self, joints: &Tensor, copies: usize) -> candle_core::Result<Tensor> {
        let initial = match (self.initial.dim(0)?, copies) {
            (1, _) | (_, 1) => self.initial.clone(),
            _ => self.initial.repeat((copies, 1, 1, 1))?,
        };
        let objective = joints_objective(self.compiled, &initial, self.jitter_weight);
        objective(joints)
    }
}

impl<M: Denoiser + ?Sized> MaskStages<'_, M> {
    /// The blended noise `z'`, each sample's chosen binary mask and its `F_C + R` after the
    /// soft blend.
    fn search(
        &self,
        z1: &Tensor,
        z2: &Tensor,
        seed: u64,
        seconds: &mut StageSeconds,
        progress: &mut dyn FnMut(&StageProgress),
    ) -> Result<(Tensor, Vec<ChosenMask>, Vec<f64>), RgDnoError> {
        let MaskStages { prior, rg, solver, objective, weights, round } = *self;
        let batch = z1.dim(0)?;
        // Binary masks (eq. 13), no gradients.
        let clock = Instant::now();
        let mut rng = StdRng::seed_from_u64(seed ^ 0x0052_4744_4e4f);
        let candidates: Vec<MaskCandidate> =
            MaskCandidate::all(rg.segments).into_iter().filter(|c| rg.mask_kinds.contains(&c.kind)).collect();
        let (masks, best_masks) = choose_masks(
            &candidates,
            (z1, z2),
            solver,
            objective,
            prior,
            weights,
            rg.mask_batch.max(1),
            &mut rng,
            &mut |done| {
                progress(&StageProgress { stage: Stage::Masks, round, step: done, steps: candidates.len(), loss: 0.0 })
            },
        )?;
        seconds.masks += clock.elapsed().as_secs_f64();

        // Soft blend (supp. A): logits M' from the chosen masks, Adam on F_C + R.
        let clock = Instant::now();
        let logits = Var::from_tensor(&soft_logits(&best_masks)?)?;
        let mut adam = AdamW::new(vec![logits.clone()], 0.0)?;
        let blend_schedule =
            DnoConfig { steps: rg.first_steps, lr: rg.first_lr, lr_warmup_steps: 0, ..DnoConfig::default() };
        let mut soft_blend_objective = vec![f64::NAN; batch];
        for step in 0..rg.first_steps {
            let z = soft_blend(logits.as_tensor(), z1, z2)?;
            let x = dno::Solver::solve(solver, &z)?;
            let joints = prior.to_joints(&x)?;
            let terms = reward(&joints, &z, weights, &mut rng)?;
            // F_C on its own recovery of the joints, as DNO's objective takes them: sharing
            // `joints` with the reward gives the same values but sums the gradient in another
            // order, which 500 later steps carry into centimetres.
            let total = (objective.on_copies(&prior.to_joints(&x)?, 1)? + terms.total)?;
            soft_blend_objective = to_vec(&total)?;
            let mut grads = total.sum_all()?.backward()?;
            let grad = grads
                .remove(logits.as_tensor())
                .ok_or_else(|| candle_core::Error::Msg("no gradient reached the mask".into()))?;
            // Per-sample gradient normalisation, as DNO's loop.
            let norm = dno::per_sample_norm(&grad)?;
            grads.insert(logits.as_tensor(), grad.broadcast_div(&norm.reshape((batch, 1, 1))?)?);
            adam.step(&grads, blend_schedule.learning_rate(step))?;
            progress(&StageProgress {
                stage: Stage::SoftBlend,
                round,
                step: step + 1,
                steps: rg.first_steps,
                loss: mean(&soft_blend_objective),
            });
        }
        let z_blend = soft_blend(logits.as_tensor(), z1, z2)?.detach();
        seconds.soft_blend += clock.elapsed().as_secs_f64();
        Ok((z_blend, masks, soft_blend_objective))
    }
}

/// Eq. 13 per sample: every candidate's `z' = M z1 + (1 − M) z2` is sampled (no gradient) and
/// scored by `F_C + R`; returns each sample's best candidate and its mask `[B, T, 263]`.
#[allow(clippy::too_many_arguments)]
fn choose_masks<M: Denoiser + ?Sized>(
    candidates: &[MaskCandidate],
    (z1, z2): (&Tensor, &Tensor),
    solver: &UnrolledDdim<'_, M>,
    objective: Objective<'_>,
    prior: &Prior,
    weights: &RewardWeights,
    per_batch: usize,
    rng: &mut StdRng,
    done: &mut dyn FnMut(usize),
) -> Result<(Vec<ChosenMask>, Tensor), RgDnoError> {
    let (batch, frames, _) = z1.dims3()?;
    let device = z1.device();
    // No gradient is taken here: detached inputs record no graph, and the denoiser then
    // keeps no activations for a backward pass.
    let (z1, z2) = (&z1.detach(), &z2.detach());
    let mut best: Vec<Option<(ChosenMask, f64)>> = vec![None; batch];
    for (chunk_index, chunk) in candidates.chunks(per_batch).enumerate() {
        let masks = chunk
            .iter()
            .map(|c| c.tensor(frames, device)?.broadcast_as((1, frames, FEATURE_DIM))?.contiguous())
            .collect::<candle_core::Result<Vec<_>>>()?;
        // Rows ordered candidate-major: row k·B + b is candidate k on sample b.
        let z = Tensor::cat(&masks.iter().map(|m| blend(m, z1, z2)).collect::<candle_core::Result<Vec<_>>>()?, 0)?;
        let text = solver.text.repeat((chunk.len(), 1))?;
        let x = solver.sampler.sample(solver.denoiser, &z, &text, solver.guidance)?;
        let joints = prior.to_joints(&x)?;
        let constraint = to_vec(&objective.on_copies(&joints, chunk.len())?)?;
        let terms = to_vec(&reward(&joints, &z, weights, rng)?.total)?;
        for (k, candidate) in chunk.iter().enumerate() {
            for b in 0..batch {
                let (c, r) = (constraint[k * batch + b], terms[k * batch + b]);
                let total = c + r;
                if total.is_finite() && best[b].as_ref().is_none_or(|(_, t)| total < *t) {
                    best[b] = Some((ChosenMask { candidate: *candidate, constraint_error: c, reward: r }, total));
                }
            }
        }
        done(((chunk_index + 1) * per_batch).min(candidates.len()));
    }
    let chosen: Vec<ChosenMask> = best
        .into_iter()
        .map(|b| b.map(|(m, _)| m))
        .collect::<Option<Vec<_>>>()
        .ok_or_else(|| GenerationError::Setting("every mask candidate gave a non-finite objective".into()))?;
    let tensors = chosen
        .iter()
        .map(|m| m.candidate.tensor(frames, device)?.broadcast_as((1, frames, FEATURE_DIM))?.contiguous())
        .collect::<candle_core::Result<Vec<_>>>()?;
    Ok((chosen, Tensor::cat(&tensors, 0)?.to_dtype(z1.dtype())?))
}

fn to_vec(t: &Tensor) -> candle_core::Result<Vec<f64>> {
    t.to_dtype(DType::F64)?.to_vec1::<f64>()
}

fn scalar(t: &Tensor) -> candle_core::Result<f64> {
    Ok(mean(&to_vec(t)?))
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaled_stages_keep_the_ratio_and_switched_off_stages() {
        let paper = RgDnoConfig::default();
        assert_eq!(paper.scaled_to(500), paper);
        let quick = paper.scaled_to(50);
        assert_eq!((quick.first_steps, quick.final_steps), (10, 40));
        assert_eq!((quick.inversion.feature_polish_steps, quick.inversion.polish_steps), (5, 5));
        let tiny = paper.scaled_to(1);
        assert_eq!((tiny.first_steps, tiny.final_steps, tiny.inversion.polish_steps), (1, 1, 1));
        let mut unpolished = paper.clone();
        unpolished.inversion.polish_steps = 0;
        assert_eq!(unpolished.scaled_to(50).inversion.polish_steps, 0);
    }

    #[test]
    fn ablations_change_the_groups_or_the_blend_they_name() {
        let parsed = ConstraintGroups {
            retrieval: vec!["c1".into()],
            random_noise: vec!["c2".into()],
            retrieved_noise: vec!["c1".into(), "c2".into()],
        };
        let all = || vec!["c1".to_owned(), "c2".to_owned(), "c3".to_owned()];
        assert_eq!(Ablation::None.groups(parsed.clone(), all()), parsed);
        assert_eq!(Ablation::NoParsing.groups(parsed.clone(), all()).retrieval, all());
        let same = Ablation::SameSets.groups(parsed.clone(), all());
        assert_eq!((same.retrieval, same.random_noise, same.retrieved_noise), (parsed.retrieval, all(), all()));
        assert_eq!(Ablation::RandomOnly.fixed_mask(), Some(1.0));
        assert_eq!(Ablation::RetrievedOnly.fixed_mask(), Some(0.0));
        assert_eq!(Ablation::HalfMask.fixed_mask(), Some(0.5));
        assert_eq!(Ablation::NoReward.fixed_mask(), None);
        let config: RgDnoConfig = serde_json::from_str(r#"{"ablation": "half_mask"}"#).unwrap();
        assert_eq!(config.ablation, Ablation::HalfMask);
    }
}
