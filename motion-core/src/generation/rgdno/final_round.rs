//! Stage 6 (eq. 12): DNO on the whole task from the blended noise `z'`, `N2` steps.

use candle_core::Tensor;

use super::error::RgDnoError;
use super::report::{Stage, StageProgress};
use super::stages::Stages;
use crate::diffusion::Denoiser;
use crate::dno::{self, DnoConfig, DnoResult, DnoStep};
use crate::generation::objective::program_objective;
use crate::generation::schedule::StageEnd;

impl<M: Denoiser + ?Sized> Stages<'_, M> {
    /// The final round from `z_blend` `[B, T, 263]` on `F_C` with the jitter guard, keeping the
    /// best iterate: its `x` is the motion of its `z` and its `loss` that motion's `F_C`.
    pub(super) fn final_round(
        &self,
        z_blend: &Tensor,
        initial_joints: &Tensor,
        seed: u64,
        round: usize,
        progress: &mut dyn FnMut(&StageProgress),
    ) -> Result<DnoResult, RgDnoError> {
        let Stages { prior, compiled, config, rg, solver, foot_lock, .. } = *self;
        let full = program_objective(prior, compiled, initial_joints, config.guards);
        let last = DnoConfig {
            steps: rg.final_steps,
            lr: rg.final_lr,
            seed,
            restarts: 1,
            keep_best: true,
            ..config.dno.clone()
        };
        let mut end =
            StageEnd::shown(config.schedule, prior, compiled, initial_joints, last.lr_warmup_steps, foot_lock);
        let done = |s: &DnoStep, x: &Tensor| end.done(round, s, x);
        let progress = |s: &DnoStep| progress(&StageProgress::of_dno(Stage::FinalRound, round, s));
        Ok(dno::optimize_until(solver, &full, z_blend, &last, progress, done)?)
    }
}
