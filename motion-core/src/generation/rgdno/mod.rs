//! Retrieval-guided diffusion noise optimisation (RG-DNO, Liu et al.; `../shared/papers/rg-dno-*`
//! §4, Fig. 2): for a task whose relational parse names its most difficult constraint,
//!
//! 1. **groups** (§4.2, Algorithm 1, [`crate::program::TaskProgram::constraint_groups`]): the
//!    retrieval set `C_R`, the random-noise set `C1` and the retrieved-noise set `C2`;
//! 2. **retrieval** (§4.3, eqs. 5–6, [`retrieval`]): the motion `x_R` of the retrieval
//!    database ([`candidates`]: by default the corpus's train split) that best satisfies `C_R`,
//!    among those that pass the semantic check ([`semantic`]); beyond the paper, the best of
//!    several takes, each started from in turn ([`config::RgDnoConfig::retrieved_motions`]);
//! 3. **inversion** (eq. 7, `invert.rs`): `z_R = G⁻¹(x_R)` ([`crate::generation::inversion::invert_motion`]);
//! 4. **two branches** (eqs. 8–9, `branches.rs`): `z1` from random noise fitted to `C1`, `z2`
//!    from `z_R` fitted to `C2`, each `N1` DNO steps;
//! 5. **mask** (eqs. 10, 13, [`mask`], [`reward`]): the best of the binary temporal and spatial
//!    masks by `F_C(G(z')) + R(G(z'), z')`, all candidates evaluated without gradients
//!    (`mask_search.rs`), then the soft sigmoid blend optimised on the same objective
//!    (`soft_blend.rs`);
//! 6. **final round** (eq. 12, `final_round.rs`): DNO on the whole task from `z'` (`N2` steps).
//!
//! Settings and Table 4's ablations are in [`config`], what the stages did in [`report`]. The
//! output goes through the same finishing stages as every other method
//! ([`crate::generation::postprocess`]); [`crate::generation::generate`] dispatches here.

mod branches;
pub mod candidates;
pub mod config;
pub mod error;
mod figures;
mod final_round;
mod invert;
pub mod mask;
mod mask_search;
pub mod report;
pub mod retrieval;
pub mod reward;
pub mod semantic;
mod soft_blend;
mod stages;

use std::time::Instant;

use candle_core::{Device, Tensor};
use rand::rngs::StdRng;
use rand::SeedableRng;

use crate::constraints::CompiledProgram;
use crate::diffusion::noise::gaussian;
use crate::diffusion::{Denoiser, Guidance};
use crate::dno::{self, UnrolledDdim};
use crate::generation::inversion::InversionConfig;
use crate::generation::method::{Generated, GenerationConfig, GenerationError, Task};
use crate::generation::postprocess::{finish, finishing_foot_lock, Unfinished};
use crate::generation::side_by_side::{side_by_side, workers};
use crate::prior::Prior;
use crate::program::TaskProgram;
use crate::representation::FEATURE_DIM;
use branches::Branches;
use candidates::RetrievalDatabase;
use config::{Ablation, RgDnoConfig};
use error::RgDnoError;
use mask::blend;
use mask_search::{MaskChoice, MaskStages, Objective};
use report::{ChosenMask, InvertedReport, RetrievedReport, RgDnoReport, StageProgress, StageSeconds, StageSteps};
use retrieval::{retrieve, RetrievalQuery};
use reward::RewardWeights;
use stages::Stages;

/// A task as RG-DNO takes it: the program (with its relational parse), compiled, and the
/// retrieval database.
#[derive(Debug, Clone, Copy)]
pub struct RgDnoTask<'a> {
    /// The program.
    pub program: &'a TaskProgram,
    /// The program compiled.
    pub compiled: &'a CompiledProgram,
    /// The motions retrieval crops.
    pub database: &'a RetrievalDatabase,
}

/// Generates `config.samples` motions for `task` with RG-DNO. `config` gives the samples,
/// seed, guidance, DDIM steps, the DNO regulariser, the jitter guard, the clean-up and the
/// restarts `N_S` (`config.dno.restarts`); `rg` the RG-DNO stages. Retrieval runs once; each
/// retrieved motion the stages start from ([`RgDnoConfig::retrieved_motions`], one by default)
/// is inverted once, and its restart r runs the stages after the inversion from the random
/// noise of seed `seed + r` (under the until-met schedule, for a program without counts, every
/// sample on its own worker, [`crate::generation::side_by_side`], sample `i` from row `i` of that
/// noise). Each sample keeps the attempt whose final motion has the lowest `F_C`.
pub fn generate_rg_dno(
    prior: &Prior,
    task: RgDnoTask<'_>,
    config: &GenerationConfig,
    rg: &RgDnoConfig,
    device: &Device,
    mut on_progress: impl FnMut(&StageProgress),
) -> Result<(Generated, RgDnoReport), RgDnoError> {
    let batch = config.samples;
    // The steps each sample ran on its own and, last, those of the stages run once for every
    // sample, each with the mask candidates it has scored so far.
    let mut tallies = vec![(StageSteps::default(), 0); batch + 1];
    let mut progress = |p: &StageProgress| {
        let (steps, masks_done) = &mut tallies[p.sample.map_or(batch, |i| i.min(batch))];
        steps.record(p, masks_done);
        on_progress(p)
    };
    let RgDnoTask { program, compiled, database } = task;
    rg.validate(compiled.frames())?;
    config.check(compiled.frames())?;
    config.dno.validate()?;
    let start = Instant::now();
    let all = program.constraints.iter().map(|c| c.id.clone()).collect();
    let groups = rg.ablation.groups(program.constraint_groups().ok_or(RgDnoError::NoParse)?, all);
    let parse = program.relational_parse.as_ref().ok_or(RgDnoError::NoParse)?;
    let mut seconds = StageSeconds::default();

    // Retrieval (eqs. 5–6).
    let clock = Instant::now();
    let c_r = compiled.subset(&groups.retrieval);
    let query = RetrievalQuery {
        program: &c_r,
        most_difficult: &parse.most_difficult,
        prompt: &program.text,
        counting: c_r.has_counts(),
        encoder: Some(&prior.encoder),
    };
    let found = retrieve(database, &query, &rg.retrieval_keeping_used(), device)?;
    if found.retrieved.is_empty() {
        return Err(RgDnoError::NothingRetrieved { missing: found.missing_actions.clone() });
    }
    seconds.retrieval = clock.elapsed().as_secs_f64();

    // The solver, as DNO's, for the rows each job of the stages after the inversion runs, and
    // for their two branches side by side: one sample per job under the until-met schedule for a
    // program without counts, else every sample in one job ([`Stages::attempts`]).
    let counts = compiled.has_counts();
    let rows = if RgDnoConfig::side_by_side_under(config.schedule, counts) { 1 } else { batch };
    let text = prior.encode_text(&vec![program.text.as_str(); rows], device)?;
    let guidance = Guidance { scale: config.guidance }.for_text(&text)?;
    // The stages before the final round may sample through fewer of the sampler's timesteps,
    // and without guidance.
    let stride = rg.early_stride_under(config.schedule, counts);
    let early_guidance = rg.early_guidance_under(config.schedule, counts, guidance);
    let ddim_steps = config.dno.ddim_steps;
    let solver = UnrolledDdim::new(&prior.mdm, text.clone(), guidance, ddim_steps)?;
    let early = UnrolledDdim::new(&prior.mdm, text.clone(), early_guidance, ddim_steps)?.every(stride);
    let both = UnrolledDdim::new(&prior.mdm, text.repeat((2, 1))?, early_guidance, ddim_steps)?.every(stride);
    let inversion = InversionConfig {
        guidance: early_guidance.scale,
        ddim_steps,
        sampler_stride: stride,
        schedule: config.schedule,
        stop_within_tolerance: !counts,
        ..rg.inversion.clone()
    };
    let foot_lock = finishing_foot_lock(program, config);
    let mut kept: Option<Attempt> = None;
    let (mut inverted, mut restart, mut motion) = (Vec::new(), vec![0; batch], vec![0; batch]);
    let restarts = config.dno.restarts;
    for (j, index) in rg.used_motions(found.retrieved.len()).into_iter().enumerate() {
        // Inversion (eq. 7), once for every sample.
        let clock = Instant::now();
        let (x_r, one) = (&found.retrieved[index].features, text.narrow(0, 0, 1)?);
        let (z_r, error_m) = invert::invert_retrieved(prior, x_r, &one, &inversion, j, &mut progress)?;
        let z_r = z_r.broadcast_as((rows, compiled.frames(), FEATURE_DIM))?.contiguous()?;
        seconds.inversion += clock.elapsed().as_secs_f64();
        inverted.push(InvertedReport { motion: index, error_m });
        let stages = Stages {
            prior,
            compiled,
            groups: &groups,
            config,
            rg,
            solver: &solver,
            early: &early,
            both: &both,
            z_r: &z_r,
            foot_lock: &foot_lock,
        };
        for r in 0..restarts {
            let round = j * restarts + r;
            let attempt =
                stages.attempts(config.seed.wrapping_add(r as u64), batch, round, &mut seconds, &mut progress)?;
            kept = Some(match kept {
                None => {
                    motion.fill(index);
                    attempt
                }
                Some(old) => {
                    let take: Vec<bool> =
                        attempt.objective.iter().zip(&old.objective).map(|(&new, &old)| dno::beats(new, old)).collect();
                    for b in (0..batch).filter(|&b| take[b]) {
                        (restart[b], motion[b]) = (r, index);
                    }
                    old.merge(attempt, &take)?
                }
            });
        }
    }
    let kept = kept.ok_or_else(|| GenerationError::Setting("RG-DNO ran no restarts".into()))?;

    let unfinished =
        Unfinished { features: kept.features, initial_joints: kept.initial_joints, loss_history: kept.history };
    let generated = finish(prior, Task { program, compiled }, config, unfinished, start)?;
    let report = RgDnoReport {
        retrieval_set: groups.retrieval,
        random_noise_set: groups.random_noise,
        retrieved_noise_set: groups.retrieved_noise,
        candidates: found.candidates,
        consistent_candidates: found.consistent,
        missing_actions: found.missing_actions.iter().map(|a| a.verb().to_owned()).collect(),
        skills: found.skills.clone(),
        retrieved: found
            .retrieved
            .iter()
            .map(|r| RetrievedReport {
                source: r.source.clone(),
                score: r.score,
                per_constraint: r.per_constraint.clone(),
                caption_similarity: r.caption_similarity,
            })
            .collect(),
        inverted,
        motion,
        z1_error: kept.z1_error,
        z2_error: kept.z2_error,
        masks: kept.masks,
        soft_blend_objective: kept.soft_blend_objective,
        restart,
        final_objective: kept.objective,
        seconds,
        steps: tallies[batch].0.plus(&StageSteps::longest(tallies[..batch].iter().map(|(steps, _)| steps))),
        config: rg.clone(),
    };
    Ok((generated, report))
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

    /// The samples' attempts as one batch: rows and lists in sample order.
    fn concat(attempts: Vec<Attempt>) -> candle_core::Result<Attempt> {
        let rows = |f: fn(&Attempt) -> &Tensor| Tensor::cat(&attempts.iter().map(f).collect::<Vec<_>>(), 0);
        let (features, initial_joints) = (rows(|a| &a.features)?, rows(|a| &a.initial_joints)?);
        let mut all = Attempt {
            features,
            initial_joints,
            objective: Vec::new(),
            z1_error: Vec::new(),
            z2_error: Vec::new(),
            masks: Vec::new(),
            soft_blend_objective: Vec::new(),
            history: Vec::new(),
        };
        for a in attempts {
            all.objective.extend(a.objective);
            all.z1_error.extend(a.z1_error);
            all.z2_error.extend(a.z2_error);
            all.masks.extend(a.masks);
            all.soft_blend_objective.extend(a.soft_blend_objective);
            all.history.extend(a.history);
        }
        Ok(all)
    }
}

/// The seed of sample `i`'s optimisers and random terms in the attempt from `seed`: `seed`
/// itself for sample 0, so that one sample runs as it would alone.
fn sample_seed(seed: u64, i: usize) -> u64 {
    seed.wrapping_add((i as u64) << 32)
}

impl<M: Denoiser + Sync + ?Sized> Stages<'_, M> {
    /// The stages after the inversion for `batch` samples from the random noise of `seed`. With
    /// `z_R` of one row ([`RgDnoConfig::side_by_side_under`]), every sample on its own worker
    /// ([`side_by_side`]): sample `i` from row `i` of that noise, its optimisers seeded with
    /// [`sample_seed`], and `seconds` gains each stage's seconds summed over the samples and
    /// divided by the workers that ran them side by side. With `z_R` of `batch` rows, every
    /// sample in one batch on the current pool.
    fn attempts(
        &self,
        seed: u64,
        batch: usize,
        round: usize,
        seconds: &mut StageSeconds,
        progress: &mut dyn FnMut(&StageProgress),
    ) -> Result<Attempt, RgDnoError> {
        let (rows, frames, _) = self.z_r.dims3()?;
        let z0 = gaussian((batch, frames, FEATURE_DIM), seed, self.z_r.device())?;
        if rows > 1 {
            return self.attempt(&z0, seed, round, seconds, progress);
        }
        let job = |i: usize, report: &mut dyn FnMut(StageProgress)| {
            let mut own = StageSeconds::default();
            let z0 = z0.narrow(0, i, 1)?;
            let attempt = self.attempt(&z0, sample_seed(seed, i), round, &mut own, &mut |p| report(p.clone()))?;
            Ok::<_, RgDnoError>((attempt, own))
        };
        let on = |i: usize, p: StageProgress| progress(&StageProgress { sample: Some(i), ..p });
        let runs = side_by_side(batch, job, on)
            .map_err(|e| GenerationError::Setting(format!("the samples' worker threads did not start: {e}")))?;
        let mut attempts = Vec::with_capacity(batch);
        let workers = workers(batch) as f64;
        for run in runs {
            let (attempt, own) = run?;
            *seconds = seconds.zip_with(&own, |all, one| all + one / workers);
            attempts.push(attempt);
        }
        Ok(Attempt::concat(attempts)?)
    }

    /// The stages after the inversion from the random noise `z0` `[rows of z_R, T, 263]`: both
    /// branches, the binary masks, the soft blend and the final round; `seed` seeds their
    /// optimisers and random terms.
    fn attempt(
        &self,
        z0: &Tensor,
        seed: u64,
        round: usize,
        seconds: &mut StageSeconds,
        progress: &mut dyn FnMut(&StageProgress),
    ) -> Result<Attempt, RgDnoError> {
        let Stages { prior, compiled, config, rg, solver, early, .. } = *self;
        let initial_joints =
            prior.to_joints(&solver.sampler.sample(solver.denoiser, z0, &solver.text, solver.guidance)?)?;

        let clock = Instant::now();
        let Branches { z1, z2, z1_error, z2_error } = self.branches(z0, &initial_joints, seed, round, progress)?;
        seconds.branches += clock.elapsed().as_secs_f64();

        let reward_weights = if rg.ablation == Ablation::NoReward { RewardWeights::NONE } else { rg.reward };
        let (z_blend, masks, soft_blend_objective) = match rg.ablation.fixed_mask() {
            Some(m) => (blend(&Tensor::new(m, z1.device())?, &z1, &z2)?, Vec::new(), Vec::new()),
            None => {
                let stages = MaskStages {
                    prior,
                    rg,
                    solver: early,
                    objective: Objective { compiled, initial: &initial_joints, guards: config.guards },
                    weights: &reward_weights,
                    round,
                    schedule: config.schedule,
                };
                // One stream for the reward's random terms of both stages.
                let mut rng = StdRng::seed_from_u64(seed ^ 0x0052_4744_4e4f);
                let clock = Instant::now();
                let MaskChoice { masks, tensor: best_masks, met } =
                    stages.binary_masks(&z1, &z2, &mut rng, progress)?;
                seconds.masks += clock.elapsed().as_secs_f64();
                let clock = Instant::now();
                // With the until-met schedule, masks whose motion meets the whole program skip
                // the soft blend; its objective is then the chosen masks' F_C + R.
                let (z_blend, objective) = if met {
                    let chosen = masks.iter().map(|m| m.constraint_error + m.reward).collect();
                    (blend(&best_masks, &z1, &z2)?, chosen)
                } else {
                    stages.soft_blend(&best_masks, &z1, &z2, &mut rng, progress)?
                };
                seconds.soft_blend += clock.elapsed().as_secs_f64();
                (z_blend, masks, objective)
            }
        };

        let clock = Instant::now();
        let run = self.final_round(&z_blend, &initial_joints, seed, round, progress)?;
        seconds.final_round += clock.elapsed().as_secs_f64();
        Ok(Attempt {
            features: run.x,
            initial_joints,
            objective: run.loss,
            z1_error,
            z2_error,
            masks,
            soft_blend_objective,
            history: run.history.into_iter().map(|h| h.loss).collect(),
        })
    }
}
