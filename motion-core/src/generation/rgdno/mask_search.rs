//! Stage 5a (eq. 13): the binary temporal and spatial masks `M` of `z' = M·z1 + (1 − M)·z2`,
//! every candidate sampled without gradients and scored by `F_C(G(z')) + R(G(z'), z')`; each
//! sample keeps its best.
//!
//! With [`Schedule::UntilMet`] the candidates are screened first: every one is sampled by a
//! cheap sampler ([`SCREEN_DDIM_STEPS`] unguided DDIM steps: a tenth of the denoiser passes of
//! ten guided ones) and ranked by `F_C` alone, and only each sample's best [`SCREENED`] are
//! scored as above. Two steps still rank the small case of this module's test as the full
//! sampler does; one step does not.

use candle_core::Tensor;
use rand::rngs::StdRng;

use super::config::RgDnoConfig;
use super::error::RgDnoError;
use super::figures::to_vec;
use super::mask::{blend, MaskCandidate};
use super::report::{ChosenMask, Stage, StageProgress};
use super::reward::{reward, RewardWeights};
use crate::constraints::CompiledProgram;
use crate::diffusion::{Denoiser, Guidance};
use crate::dno::UnrolledDdim;
use crate::generation::method::GenerationError;
use crate::generation::objective::{joints_objective, Guards};
use crate::generation::schedule::Schedule;
use crate::prior::Prior;
use crate::representation::FEATURE_DIM;

/// Candidates each sample keeps from the screening for the full sampler.
pub const SCREENED: usize = 16;
/// DDIM steps of the screening sampler (unguided).
pub const SCREEN_DDIM_STEPS: usize = 2;

/// The mask search of one restart: eq. 13's binary candidates, then the soft blend.
pub(super) struct MaskStages<'a, M: Denoiser + ?Sized> {
    pub(super) prior: &'a Prior,
    pub(super) rg: &'a RgDnoConfig,
    pub(super) solver: &'a UnrolledDdim<'a, M>,
    /// `F_C`, evaluated on joints the stage has already recovered.
    pub(super) objective: Objective<'a>,
    pub(super) weights: &'a RewardWeights,
    pub(super) round: usize,
    /// [`Schedule::UntilMet`] screens the candidates first.
    pub(super) schedule: Schedule,
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

    /// Whether every sample of joints `[B, T, 22, 3]` meets every constraint at its tolerance.
    pub(super) fn meets(&self, joints: &Tensor) -> candle_core::Result<bool> {
        self.compiled.met_by_every_sample(joints, Some(self.initial)).map_err(candle_core::Error::wrap)
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
        let candidates = match self.schedule {
            Schedule::Paper => candidates,
            Schedule::UntilMet => self.screen(&candidates, (z1, z2))?,
        };
        self.choose(&candidates, (z1, z2), rng, &mut |done| {
            progress(&StageProgress { stage: Stage::Masks, round, step: done, steps: candidates.len(), loss: 0.0 })
        })
    }

    /// The candidates among the best [`SCREENED`] of some sample by `F_C` of the cheap sampler
    /// (in their order in `candidates`).
    fn screen(
        &self,
        candidates: &[MaskCandidate],
        (z1, z2): (&Tensor, &Tensor),
    ) -> Result<Vec<MaskCandidate>, RgDnoError> {
        if candidates.len() <= SCREENED {
            return Ok(candidates.to_vec());
        }
        let text = self.solver.text.clone();
        let cheap = UnrolledDdim::new(self.solver.denoiser, text, Guidance::none(), SCREEN_DDIM_STEPS)?;
        let (batch, frames, _) = z1.dims3()?;
        let (z1, z2) = (&z1.detach(), &z2.detach());
        let mut scores: Vec<Vec<f64>> = vec![Vec::with_capacity(candidates.len()); batch];
        for chunk in candidates.chunks(self.rg.mask_batch.max(1)) {
            let z = self.blended(chunk, (z1, z2), frames)?;
            let x = cheap.sampler.sample(cheap.denoiser, &z, &cheap.text.repeat((chunk.len(), 1))?, cheap.guidance)?;
            let constraint = to_vec(&self.objective.on_copies(&self.prior.to_joints(&x)?, chunk.len())?)?;
            for k in 0..chunk.len() {
                for (b, sample) in scores.iter_mut().enumerate() {
                    let c = constraint[k * batch + b];
                    sample.push(if c.is_finite() { c } else { f64::INFINITY });
                }
            }
        }
        let mut keep = vec![false; candidates.len()];
        for sample in &scores {
            let mut order: Vec<usize> = (0..candidates.len()).collect();
            order.sort_by(|&a, &b| sample[a].total_cmp(&sample[b]));
            for &k in order.iter().take(SCREENED) {
                keep[k] = true;
            }
        }
        Ok(candidates.iter().zip(keep).filter(|(_, k)| *k).map(|(c, _)| *c).collect())
    }

    /// `z' = M z1 + (1 − M) z2` of every candidate of `chunk`, candidate-major: row `k·B + b`
    /// is candidate `k` on sample `b`.
    fn blended(
        &self,
        chunk: &[MaskCandidate],
        (z1, z2): (&Tensor, &Tensor),
        frames: usize,
    ) -> candle_core::Result<Tensor> {
        let masks = chunk
            .iter()
            .map(|c| c.tensor(frames, z1.device())?.broadcast_as((1, frames, FEATURE_DIM))?.contiguous())
            .collect::<candle_core::Result<Vec<_>>>()?;
        Tensor::cat(&masks.iter().map(|m| blend(m, z1, z2)).collect::<candle_core::Result<Vec<_>>>()?, 0)
    }

    /// Whether every sample's motion from the chosen masks `[B, T, 263]` meets every constraint
    /// of the program at its tolerance (then the soft blend has nothing to add).
    pub(super) fn masks_meet_the_program(
        &self,
        best_masks: &Tensor,
        z1: &Tensor,
        z2: &Tensor,
    ) -> Result<bool, RgDnoError> {
        let z = blend(best_masks, &z1.detach(), &z2.detach())?;
        let x = self.solver.sampler.sample(self.solver.denoiser, &z, &self.solver.text, self.solver.guidance)?;
        Ok(self.objective.meets(&self.prior.to_joints(&x)?)?)
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
            // Rows ordered candidate-major: row k·B + b is candidate k on sample b.
            let z = self.blended(chunk, (z1, z2), frames)?;
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

#[cfg(test)]
mod tests {
    use candle_core::Device;
    use rand::SeedableRng;

    use super::*;
    use crate::diffusion::noise::gaussian;
    use crate::generation::rgdno::mask::MaskKind;
    use crate::program::TaskProgram;

    /// On a small case (two samples, 32 temporal candidates, no reward so that the scores do not
    /// depend on how much of the random stream each search draws), the screened search keeps
    /// each sample's winner among its 16 and so chooses the full search's masks.
    #[test]
    fn the_screened_search_chooses_the_full_searchs_masks() {
        let device = Device::Cpu;
        let fixtures = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures");
        let prior = Prior::load(&fixtures.join("model/prior.safetensors"), &fixtures.join("text"), &device).unwrap();
        let program = TaskProgram::from_json_validated(
            r#"{"text": "a person walks forward", "frames": 40, "constraints": [{"id": "c1", "expr": {"op": "equal",
            "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "target": [1.5],
            "frames": {"keyframes": ["last"]}}}]}"#,
        )
        .unwrap();
        let compiled = CompiledProgram::compile(&program, &device).unwrap();
        let text = prior.encode_text(&[program.text.as_str(); 2], &device).unwrap();
        let guidance = Guidance::default().for_text(&text).unwrap();
        let solver = UnrolledDdim::new(&prior.mdm, text, guidance, 10).unwrap();
        let z1 = gaussian((2, 40, FEATURE_DIM), 1, &device).unwrap();
        let z2 = gaussian((2, 40, FEATURE_DIM), 2, &device).unwrap();
        let x0 = solver.sampler.sample(solver.denoiser, &z1, &solver.text, solver.guidance).unwrap();
        let initial = prior.to_joints(&x0).unwrap();
        let rg = RgDnoConfig { segments: 5, mask_kinds: vec![MaskKind::Temporal], ..RgDnoConfig::default() };
        let chosen = |schedule| {
            let stages = MaskStages {
                prior: &prior,
                rg: &rg,
                solver: &solver,
                objective: Objective { compiled: &compiled, initial: &initial, guards: Guards::DEFAULT },
                weights: &RewardWeights::NONE,
                round: 0,
                schedule,
            };
            let mut rng = StdRng::seed_from_u64(0);
            let (masks, _) = stages.binary_masks(&z1, &z2, &mut rng, &mut |_| {}).unwrap();
            let temporal: Vec<MaskCandidate> =
                MaskCandidate::all(5).into_iter().filter(|c| c.kind == MaskKind::Temporal).collect();
            let screened = stages.screen(&temporal, (&z1, &z2)).unwrap().len();
            (masks.into_iter().map(|m| m.candidate).collect::<Vec<_>>(), temporal.len(), screened)
        };
        let (full, all, screened) = chosen(Schedule::Paper);
        assert!(all == 32 && (SCREENED..all).contains(&screened), "the screen keeps {screened} of {all}");
        assert_eq!(chosen(Schedule::UntilMet).0, full);
    }
}
