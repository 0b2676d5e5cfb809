//! Stage 5b (supplementary A): the soft blend `z' = σ(M')·z1 + (1 − σ(M'))·z2`, its logits
//! `M'` started from each sample's chosen binary mask and optimised with Adam on
//! `F_C + R` for `N1` steps (under [`Schedule::UntilMet`], until the objective has stalled or
//! the blend's motion meets the program: the final round finishes the motion), the gradient normalised per sample as in DNO's loop.

use candle_core::{Tensor, Var};
use rand::rngs::StdRng;

use super::error::RgDnoError;
use super::figures::to_vec;
use super::mask::{soft_blend, soft_logits};
use super::mask_search::MaskStages;
use super::report::{Stage, StageProgress};
use super::reward::reward;
use crate::diffusion::Denoiser;
use crate::dno::{self, DnoConfig};
use crate::generation::schedule::Schedule;
use crate::generation::stall::Stall;
use crate::numeric::mean;
use crate::optim::AdamW;

impl<M: Denoiser + ?Sized> MaskStages<'_, M> {
    /// The blended noise `z'` `[B, T, 263]` (detached) from the chosen masks `best_masks`
    /// `[B, T, 263]`, and each sample's `F_C + R` at the last step.
    pub(super) fn soft_blend(
        &self,
        best_masks: &Tensor,
        z1: &Tensor,
        z2: &Tensor,
        rng: &mut StdRng,
        progress: &mut dyn FnMut(&StageProgress),
    ) -> Result<(Tensor, Vec<f64>), RgDnoError> {
        let MaskStages { prior, rg, solver, objective, weights, round, schedule } = *self;
        let batch = z1.dim(0)?;
        // Soft blend (supp. A): logits M' from the chosen masks, Adam on F_C + R.
        let logits = Var::from_tensor(&soft_logits(best_masks)?)?;
        let mut adam = AdamW::new(vec![logits.clone()], 0.0)?;
        let blend_schedule =
            DnoConfig { steps: rg.first_steps, lr: rg.first_lr, lr_warmup_steps: 0, ..DnoConfig::default() };
        let mut soft_blend_objective = vec![f64::NAN; batch];
        let mut stall = Stall::default();
        for step in 0..rg.first_steps {
            let z = soft_blend(logits.as_tensor(), z1, z2)?;
            let x = dno::Solver::solve(solver, &z)?;
            let joints = prior.to_joints(&x)?;
            let terms = reward(&joints, &z, weights, rng)?;
            // F_C on its own recovery of the joints, as DNO's objective takes them: sharing
            // `joints` with the reward gives the same values but sums the gradient in another
            // order, which 500 later steps carry into centimetres.
            let total = (objective.on_copies(&prior.to_joints(&x)?, 1)? + terms.total)?;
            soft_blend_objective = to_vec(&total)?;
            progress(&StageProgress {
                stage: Stage::SoftBlend,
                round,
                step: step + 1,
                steps: rg.first_steps,
                loss: mean(&soft_blend_objective),
                sample: None,
            });
            // Under the until-met schedule the blend is handed on, before its update, once its
            // objective has stalled or its motion meets the program.
            if schedule == Schedule::UntilMet {
                let stalled = stall.stalled_after(mean(&soft_blend_objective), 0);
                if stalled || (stall.at_check(0) && objective.meets(&joints)?) {
                    break;
                }
            }
            let mut grads = total.sum_all()?.backward()?;
            let grad = grads
                .remove(logits.as_tensor())
                .ok_or_else(|| candle_core::Error::Msg("no gradient reached the mask".into()))?;
            // Per-sample gradient normalisation, as DNO's loop.
            let norm = dno::per_sample_norm(&grad)?;
            grads.insert(logits.as_tensor(), grad.broadcast_div(&norm.reshape((batch, 1, 1))?)?);
            adam.step(&grads, blend_schedule.learning_rate(step))?;
        }
        Ok((soft_blend(logits.as_tensor(), z1, z2)?.detach(), soft_blend_objective))
    }
}
