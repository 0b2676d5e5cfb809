//! Stage 5a (eq. 13): the binary temporal and spatial masks `M` of `z' = M·z1 + (1 − M)·z2`,
//! every candidate sampled without gradients and scored by `F_C(G(z')) + R(G(z'), z')`; each
//! sample keeps its best.

use candle_core::Tensor;
use rand::rngs::StdRng;

use super::config::RgDnoConfig;
use super::error::RgDnoError;
use super::figures::to_vec;
use super::mask::{blend, MaskCandidate};
use super::report::{ChosenMask, Stage, StageProgress};
use super::reward::{reward, RewardWeights};
use crate::constraints::CompiledProgram;
use crate::diffusion::Denoiser;
use crate::dno::UnrolledDdim;
use crate::generation::method::GenerationError;
use crate::generation::objective::{joints_objective, Guards};
use crate::prior::Prior;
use crate::representation::FEATURE_DIM;

/// The mask search of one restart: eq. 13's binary candidates, then the soft blend.
pub(super) struct MaskStages<'a, M: Denoiser + ?Sized> {
    pub(super) prior: &'a Prior,
    pub(super) rg: &'a RgDnoConfig,
    pub(super) solver: &'a UnrolledDdim<'a, M>,
    /// `F_C`, evaluated on joints the stage has already recovered.
    pub(super) objective: Objective<'a>,
    pub(super) weights: &'a RewardWeights,
    pub(super) round: usize,
}

/// The program objective's parts ([`crate::generation::objective::program_objective`]): the compiled
/// program, the initial joints `[B or 1, T, 22, 3]` and the guards.
#[derive(Clone, Copy)]
pub(super) struct Objective<'a> {
    pub(super) compiled: &'a CompiledProgram,
    pub(super) initial: &'a Tensor,
    pub(super) guards: Guards,
}

impl Objective<'_> {
    /// Per row `[copies·B]` for joints whose row `k·B + b` belongs to sample `b`.
    pub(super) fn on_copies(&self, joints: &Tensor, copies: usize) -> candle_core::Result<Tensor> {
        let initial = match (self.initial.dim(0)?, copies) {
            (1, _) | (_, 1) => self.initial.clone(),
            _ => self.initial.repeat((copies, 1, 1, 1))?,
        };
        let objective = joints_objective(self.compiled, &initial, self.guards);
        objective(joints)
    }
}

impl<M: Denoiser + ?Sized> MaskStages<'_, M> {
    /// Eq. 13 per sample over the configured mask kinds: each sample's best candidate and its
    /// mask `[B, T, 263]`.
    pub(super) fn binary_masks(
        &self,
        z1: &Tensor,
        z2: &Tensor,
        rng: &mut StdRng,
        progress: &mut dyn FnMut(&StageProgress),
    ) -> Result<(Vec<ChosenMask>, Tensor), RgDnoError> {
        let (rg, round) = (self.rg, self.round);
        let candidates: Vec<MaskCandidate> =
            MaskCandidate::all(rg.segments).into_iter().filter(|c| rg.mask_kinds.contains(&c.kind)).collect();
        self.choose(&candidates, (z1, z2), rng, &mut |done| {
            progress(&StageProgress { stage: Stage::Masks, round, step: done, steps: candidates.len(), loss: 0.0 })
        })
    }

    /// Every candidate's `z' = M z1 + (1 − M) z2` is sampled (no gradient, in batches of
    /// `mask_batch` candidates) and scored by `F_C + R`; `done` gets the candidates done.
    fn choose(
        &self,
        candidates: &[MaskCandidate],
        (z1, z2): (&Tensor, &Tensor),
        rng: &mut StdRng,
        done: &mut dyn FnMut(usize),
    ) -> Result<(Vec<ChosenMask>, Tensor), RgDnoError> {
        let per_batch = self.rg.mask_batch.max(1);
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
            let text = self.solver.text.repeat((chunk.len(), 1))?;
            let x = self.solver.sampler.sample(self.solver.denoiser, &z, &text, self.solver.guidance)?;
            let joints = self.prior.to_joints(&x)?;
            let constraint = to_vec(&self.objective.on_copies(&joints, chunk.len())?)?;
            let terms = to_vec(&reward(&joints, &z, self.weights, rng)?.total)?;
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
}
