//! Stage 6 (eq. 12): DNO on the whole task from the blended noise `z'`, `N2` steps.
//!
//! Where the stages before it sample through fewer timesteps, unguided
//! ([`super::config::RgDnoConfig::early_stride`], [`super::config::RgDnoConfig::early_unguided`],
//! under the until-met schedule), the round
//! starts on that coarse sampler until the motion meets every constraint (or all but a quarter
//! of `N2`, at least one step, are spent), then finishes on the whole sampler, which makes the
//! motion it hands on, under the shown stage's stopping rule ([`StageEnd::shown`]). For a
//! program without counts the round hands on, per sample, the best-looking met motion its
//! judgements saw ([`StageEnd::handing_on_best_look`]), and so waits one judgement without a
//! gain of look, not three. The whole sampler's Adam starts afresh, so its learning rate warms
//! up over [`WHOLE_SAMPLER_WARMUP_STEPS`].

use candle_core::Tensor;

use super::error::RgDnoError;
use super::figures::to_vec;
use super::report::{Stage, StageProgress};
use super::stages::Stages;
use crate::diffusion::Denoiser;
use crate::dno::{self, DnoConfig, DnoStep, SampleHistory};
use crate::generation::objective::program_objective;
use crate::generation::schedule::StageEnd;

/// Steps over which the whole sampler's learning rate rises to the round's, after the coarse
/// sampler: a fresh Adam's first updates move every element of `z` by about the learning rate
/// whatever its gradient, which throws a motion the coarse steps brought near the program far
/// off it again.
pub const WHOLE_SAMPLER_WARMUP_STEPS: usize = 10;

/// The final round's motion per sample.
pub(super) struct FinalMotion {
    /// The motion handed on, normalised features `[B, T, 263]`: the best iterate of the whole
    /// sampler's steps, or where the stopping rule saw a met motion that looks better, that one
    /// ([`StageEnd::best_looking`]).
    pub(super) x: Tensor,
    /// `F_C` with the guards of `x`, per sample.
    pub(super) loss: Vec<f64>,
    /// The criterion at every step of both samplers.
    pub(super) history: Vec<SampleHistory>,
}

impl<M: Denoiser + ?Sized> Stages<'_, M> {
    /// The final round from `z_blend` `[B, T, 263]` on `F_C` with the jitter guard.
    pub(super) fn final_round(
        &self,
        z_blend: &Tensor,
        initial_joints: &Tensor,
        seed: u64,
        round: usize,
        progress: &mut dyn FnMut(&StageProgress),
    ) -> Result<FinalMotion, RgDnoError> {
        let Stages { prior, compiled, config, rg, solver, early, foot_lock, .. } = *self;
        let full = program_objective(prior, compiled, initial_joints, config.guards);
        let last = DnoConfig {
            steps: rg.final_steps,
            lr: rg.final_lr,
            seed,
            restarts: 1,
            keep_best: true,
            ..config.dno.clone()
        };
        let mut report = |stage: Stage, offset: usize, s: &DnoStep| {
            let p = StageProgress::of_dno(stage, round, s);
            progress(&StageProgress { step: offset + p.step, steps: rg.final_steps, ..p })
        };
        let (mut z, mut last, mut offset, mut coarse_history) = (z_blend.clone(), last, 0, None);
        if early.sampler != solver.sampler && rg.final_steps >= 2 {
            let fine = (rg.final_steps / 4).max(1);
            let coarse = DnoConfig { steps: rg.final_steps - fine, keep_best: false, ..last.clone() };
            let parts = vec![(compiled, None)];
            let mut end = StageEnd::intermediate(config.schedule, prior, parts, initial_joints, 0);
            let done = |s: &DnoStep, x: &Tensor| end.done(round, s, x);
            let run = dno::optimize_until(early, &full, &z, &coarse, |s| report(Stage::FinalRoundCoarse, 0, s), done)?;
            offset = run.history.first().map_or(0, |h| h.loss.len());
            // The rest of the budget on the whole sampler, its learning rate warmed up and decayed
            // over it.
            (z, coarse_history) = (run.z, Some(run.history));
            let steps = rg.final_steps - offset;
            let warmup = WHOLE_SAMPLER_WARMUP_STEPS.min(steps - 1);
            last = DnoConfig { steps, lr_warmup_steps: warmup, lr_decay_steps: None, ..last };
        }
        let mut end =
            StageEnd::shown(config.schedule, prior, compiled, initial_joints, last.lr_warmup_steps, foot_lock)
                .handing_on_best_look();
        let done = |s: &DnoStep, x: &Tensor| end.done(round, s, x);
        let mut run = dno::optimize_until(solver, &full, &z, &last, |s| report(Stage::FinalRound, offset, s), done)?;
        let (x, loss) = match end.best_looking(&run.x)? {
            Some(x) => {
                let loss = to_vec(&full(&x)?)?;
                (x, loss)
            }
            None => (run.x, run.loss),
        };
        if let Some(coarse) = coarse_history {
            // The round's curves over both samplers, step by step.
            for (whole, mut first) in run.history.iter_mut().zip(coarse) {
                first.loss.append(&mut whole.loss);
                first.decorrelation.append(&mut whole.decorrelation);
                first.grad_norm.append(&mut whole.grad_norm);
                *whole = first;
            }
        }
        Ok(FinalMotion { x, loss, history: run.history })
    }
}
