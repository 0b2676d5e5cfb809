//! Stage 4 (eqs. 8–9): the two branches in one batch: `z1` from random noise fitted to `C1`
//! and `z2` from the inverted noise `z_R` fitted to `C2`, each `N1` DNO steps (or, under
//! [`crate::generation::schedule::Schedule::UntilMet`], until each branch meets its group or
//! no longer comes nearer to it; a branch that no longer does is held while the other goes on).

use candle_core::Tensor;

use super::error::RgDnoError;
use super::report::{Stage, StageProgress};
use super::stages::Stages;
use crate::diffusion::Denoiser;
use crate::dno::{self, DnoConfig, DnoStep};
use crate::generation::objective::program_objective;
use crate::generation::schedule::StageEnd;

/// The fitted branches `[B, T, 263]` and their criteria `F_{C1}(G(z1))`, `F_{C2}(G(z2))` per
/// sample.
pub(super) struct Branches {
    pub(super) z1: Tensor,
    pub(super) z2: Tensor,
    pub(super) z1_error: Vec<f64>,
    pub(super) z2_error: Vec<f64>,
}

impl<M: Denoiser + ?Sized> Stages<'_, M> {
    /// Rows 0..B are `z1` from the random noise `z0` fitted to `C1`, rows B..2B are `z2` from
    /// `z_R` fitted to `C2`; `initial_joints` is `G(z0)`, `seed` the restart's.
    pub(super) fn branches(
        &self,
        z0: &Tensor,
        initial_joints: &Tensor,
        seed: u64,
        round: usize,
        progress: &mut dyn FnMut(&StageProgress),
    ) -> Result<Branches, RgDnoError> {
        let Stages { prior, compiled, groups, config, rg, both, z_r, .. } = *self;
        let batch = z0.dim(0)?;
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
        let f1 = program_objective(prior, &c1, initial_joints, config.guards);
        let f2 = program_objective(prior, &c2, initial_joints, config.guards);
        let branches = |x: &Tensor| Tensor::cat(&[f1(&x.narrow(0, 0, batch)?)?, f2(&x.narrow(0, batch, batch)?)?], 0);
        let starts = Tensor::cat(&[z0, z_r], 0)?;
        let parts = vec![(&c1, Some(0..batch)), (&c2, Some(batch..2 * batch))];
        let mut end = StageEnd::intermediate(config.schedule, prior, parts, initial_joints, first.lr_warmup_steps);
        let done = |s: &DnoStep, x: &Tensor| end.done(round, s, x);
        let progress = |s: &DnoStep| progress(&StageProgress::of_dno(Stage::Branches, round, s));
        let fitted = dno::optimize_until(both, branches, &starts, &first, progress, done)?;
        Ok(Branches {
            z1: fitted.z.narrow(0, 0, batch)?,
            z2: fitted.z.narrow(0, batch, batch)?,
            z1_error: fitted.loss[..batch].to_vec(),
            z2_error: fitted.loss[batch..].to_vec(),
        })
    }
}
