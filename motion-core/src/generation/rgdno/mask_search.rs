//! Stage 5a (eq. 13): the binary temporal and spatial masks `M` of `z' = M·z1 + (1 − M)·z2`,
//! every candidate sampled without gradients and scored by `F_C(G(z')) + R(G(z'), z')`; each
//! sample keeps its best.
//!
//! With [`Schedule::UntilMet`] the search is ordered and may end early: every candidate is
//! first sampled by a cheap sampler ([`SCREEN_DDIM_STEPS`] unguided DDIM steps: a tenth of the
//! denoiser passes of ten guided ones) and the candidates are put in the order of their best
//! rank over the samples by `F_C`, for a program without counts on the retrieval's proxy of
//! the program (joint centres only, every [`super::config::RetrievalConfig::proxy_frame_step`]-th
//! frame: ranking hundreds of motions, it costs a fraction of the exact program's body-surface
//! points on every frame; a counting program, whose winners are rarer, ranks on itself);
//! they are then scored exactly as above in that order, and the search stops sampling a sample
//! whose best has not changed over the last [`RgDnoConfig::mask_patience`] candidates (a
//! counting program's search goes on for every sample until none has changed), and ends once
//! at least [`SCREENED`] are scored and every sample's best meets the whole program at its
//! tolerance or has stopped changing; where every sample's best meets the program the soft
//! blend is skipped too. The order puts the likely winners first, so a long run without a
//! change means the rest are unlikely to win. The cheap sampler only orders; a candidate is
//! passed over only by that patience, never by its screened rank alone: keeping only each
//! sample's best 16 of the screen loses the masks that make the three touches touch
//! (`fixtures/results/issue59-mask-order/`).

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

/// Fewest candidates the until-met search scores before it may end on a met program.
pub const SCREENED: usize = 16;
/// DDIM steps of the sampler that orders the candidates (unguided).
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
    /// [`Schedule::UntilMet`] orders the candidates first and ends once the program is met.
    pub(super) schedule: Schedule,
}

/// Each sample's chosen binary mask.
pub(super) struct MaskChoice {
    /// Each sample's best candidate.
    pub(super) masks: Vec<ChosenMask>,
    /// The candidates' masks `[B, T, 263]`.
    pub(super) tensor: Tensor,
    /// Whether every sample's motion from its chosen mask meets every constraint of the
    /// program at its tolerance, as the until-met search judged it (always false in the
    /// paper's search, which never skips the soft blend).
    pub(super) met: bool,
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
        Ok(self.met_per_sample(joints)?.iter().all(|&m| m))
    }

    /// Whether each sample of joints `[B, T, 22, 3]` meets every constraint at its tolerance.
    pub(super) fn met_per_sample(&self, joints: &Tensor) -> candle_core::Result<Vec<bool>> {
        self.compiled.met_per_sample(joints, Some(self.initial)).map_err(candle_core::Error::wrap)
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
    ) -> Result<MaskChoice, RgDnoError> {
        let (rg, round) = (self.rg, self.round);
        let candidates: Vec<MaskCandidate> =
            MaskCandidate::all(rg.segments).into_iter().filter(|c| rg.mask_kinds.contains(&c.kind)).collect();
        let (candidates, stop_when_met) = match self.schedule {
            Schedule::Paper => (candidates, false),
            Schedule::UntilMet => (self.ordered(&candidates, (z1, z2))?, true),
        };
        self.choose(&candidates, (z1, z2), stop_when_met, rng, &mut |done| {
            progress(&StageProgress {
                stage: Stage::Masks,
                round,
                step: done,
                steps: candidates.len(),
                loss: 0.0,
                sample: None,
            })
        })
    }

    /// Every candidate, in the order of its best rank over the samples by `F_C` (the proxy's,
    /// for a program without counts) of the cheap sampler (equal ranks in their order in
    /// `candidates`).
    fn ordered(
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
        let proxy;
        let objective = match self.objective.compiled.has_counts() {
            true => self.objective,
            false => {
                let step = self.rg.retrieval.proxy_frame_step;
                proxy = self.objective.compiled.joints_only().thinned(step, z1.device())?;
                Objective { compiled: &proxy, ..self.objective }
            }
        };
        let (z1, z2) = (&z1.detach(), &z2.detach());
        let mut scores: Vec<Vec<f64>> = vec![Vec::with_capacity(candidates.len()); batch];
        for chunk in candidates.chunks(self.rg.mask_batch.max(1)) {
            let z = self.blended(chunk, (z1, z2), frames)?;
            let x = cheap.sampler.sample(cheap.denoiser, &z, &cheap.text.repeat((chunk.len(), 1))?, cheap.guidance)?;
            let constraint = to_vec(&objective.on_copies(&self.prior.to_joints(&x)?, chunk.len())?)?;
            for k in 0..chunk.len() {
                for (b, sample) in scores.iter_mut().enumerate() {
                    let c = constraint[k * batch + b];
                    sample.push(if c.is_finite() { c } else { f64::INFINITY });
                }
            }
        }
        let mut best_rank = vec![usize::MAX; candidates.len()];
        for sample in &scores {
            let mut order: Vec<usize> = (0..candidates.len()).collect();
            order.sort_by(|&a, &b| sample[a].total_cmp(&sample[b]));
            for (rank, &k) in order.iter().enumerate() {
                best_rank[k] = best_rank[k].min(rank);
            }
        }
        let mut order: Vec<usize> = (0..candidates.len()).collect();
        order.sort_by_key(|&k| best_rank[k]);
        Ok(order.into_iter().map(|k| candidates[k]).collect())
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

    /// Every candidate's `z' = M z1 + (1 − M) z2` is sampled (no gradient, in batches of
    /// `mask_batch` candidates) and scored by `F_C + R`, in order; with `stop_when_met`, for a
    /// program without counts a sample whose best has not changed over
    /// [`RgDnoConfig::mask_patience`] candidates is no longer sampled, and the search ends once
    /// at least [`SCREENED`] are scored and every sample's best meets the program or has
    /// stopped changing (for a counting program: or once no sample's best has changed over the
    /// patience). `done` gets the candidates done.
    fn choose(
        &self,
        candidates: &[MaskCandidate],
        (z1, z2): (&Tensor, &Tensor),
        stop_when_met: bool,
        rng: &mut StdRng,
        done: &mut dyn FnMut(usize),
    ) -> Result<MaskChoice, RgDnoError> {
        let per_batch = self.rg.mask_batch.max(1);
        let (batch, frames, _) = z1.dims3()?;
        let device = z1.device();
        // No gradient is taken here: detached inputs record no graph, and the denoiser then
        // keeps no activations for a backward pass.
        let (z1, z2) = (&z1.detach(), &z2.detach());
        let mut best: Vec<Option<(ChosenMask, f64)>> = vec![None; batch];
        // Each sample's best motion so far `[T, 22, 3]`, kept while the search may end early.
        let mut best_joints: Vec<Option<Tensor>> = vec![None; batch];
        // Per sample: whether its best meets the program, and whether it has stopped changing
        // (judged per sample for a program without counts; a counting program's late winners
        // are kept by the samples still searching).
        let per_sample = !self.objective.compiled.has_counts();
        let (mut met, mut ended) = (vec![false; batch], vec![false; batch]);
        // Whether a best changed since `met` was last judged (the judgement stands otherwise).
        let mut unjudged = false;
        for (chunk_index, chunk) in candidates.chunks(per_batch).enumerate() {
            let searching: Vec<usize> = (0..batch).filter(|&b| !ended[b]).collect();
            let rows = Tensor::new(searching.iter().map(|&b| b as u32).collect::<Vec<_>>().as_slice(), device)?;
            // The searching samples' rows of a per-sample tensor (one row serves every sample).
            let part = |t: &Tensor| match t.dim(0)? {
                n if n == 1 || searching.len() == batch => Ok(t.clone()),
                _ => t.index_select(&rows, 0),
            };
            let n = searching.len();
            // Rows ordered candidate-major: row k·n + i is candidate k on searching sample i.
            let z = self.blended(chunk, (&part(z1)?, &part(z2)?), frames)?;
            let text = part(&self.solver.text)?.repeat((chunk.len(), 1))?;
            let x = self.solver.sampler.sample(self.solver.denoiser, &z, &text, self.solver.guidance)?;
            let joints = self.prior.to_joints(&x)?;
            let initial = part(self.objective.initial)?;
            let objective = Objective { initial: &initial, ..self.objective };
            let constraint = to_vec(&objective.on_copies(&joints, chunk.len())?)?;
            let terms = to_vec(&reward(&joints, &z, self.weights, rng)?.total)?;
            for (k, candidate) in chunk.iter().enumerate() {
                for (i, &b) in searching.iter().enumerate() {
                    let (c, r) = (constraint[k * n + i], terms[k * n + i]);
                    let total = c + r;
                    if total.is_finite() && best[b].as_ref().is_none_or(|(_, t)| total < *t) {
                        let place = chunk_index * per_batch + k;
                        best[b] =
                            Some((ChosenMask { candidate: *candidate, constraint_error: c, reward: r, place }, total));
                        if stop_when_met {
                            best_joints[b] = Some(joints.get(k * n + i)?);
                            unjudged = true;
                        }
                    }
                }
            }
            let scored = ((chunk_index + 1) * per_batch).min(candidates.len());
            done(scored);
            if stop_when_met && (scored >= SCREENED || scored == candidates.len()) {
                let Some(motions) = best_joints.iter().cloned().collect::<Option<Vec<Tensor>>>() else { continue };
                if unjudged {
                    met = self.objective.met_per_sample(&Tensor::stack(&motions, 0)?)?;
                    unjudged = false;
                }
                let patience = self.rg.mask_patience;
                let last_change = |best: &Option<(ChosenMask, f64)>| best.as_ref().map_or(0, |(m, _)| m.place + 1);
                if per_sample {
                    for (ended, best) in ended.iter_mut().zip(&best) {
                        *ended |= patience > 0 && scored - last_change(best) >= patience;
                    }
                } else if patience > 0 && scored - best.iter().map(last_change).max().unwrap_or(0) >= patience {
                    break;
                }
                if met.iter().zip(&ended).all(|(&met, &ended)| met || ended) {
                    break;
                }
            }
        }
        let met = stop_when_met && met.iter().all(|&m| m);
        let chosen: Vec<ChosenMask> = best
            .into_iter()
            .map(|b| b.map(|(m, _)| m))
            .collect::<Option<Vec<_>>>()
            .ok_or_else(|| GenerationError::Setting("every mask candidate gave a non-finite objective".into()))?;
        let tensors = chosen
            .iter()
            .map(|m| m.candidate.tensor(frames, device)?.broadcast_as((1, frames, FEATURE_DIM))?.contiguous())
            .collect::<candle_core::Result<Vec<_>>>()?;
        Ok(MaskChoice { masks: chosen, tensor: Tensor::cat(&tensors, 0)?.to_dtype(z1.dtype())?, met })
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

    /// Scores two samples' 32 temporal candidates (no reward, so that the scores do not depend
    /// on how much of the random stream each search draws) in batches of `mask_batch` under a
    /// program given by its one constraint: the chosen masks, the candidates scored and
    /// whether the search judged the program met.
    fn search(constraint: &str, schedule: Schedule, rg: RgDnoConfig) -> (Vec<ChosenMask>, usize, bool) {
        let device = Device::Cpu;
        let prior = crate::generation::shipped_prior(&device);
        let program = TaskProgram::from_json_validated(&format!(
            r#"{{"text": "a person walks forward", "frames": 40, "constraints": [{{"id": "c1", "expr": {constraint}}}]}}"#
        ))
        .unwrap();
        let compiled = CompiledProgram::compile(&program, &device).unwrap();
        let text = prior.encode_text(&[program.text.as_str(); 2], &device).unwrap();
        let guidance = Guidance::default().for_text(&text).unwrap();
        let solver = UnrolledDdim::new(&prior.mdm, text, guidance, 10).unwrap();
        let z1 = gaussian((2, 40, FEATURE_DIM), 1, &device).unwrap();
        let z2 = gaussian((2, 40, FEATURE_DIM), 2, &device).unwrap();
        let x0 = solver.sampler.sample(solver.denoiser, &z1, &solver.text, solver.guidance).unwrap();
        let initial = prior.to_joints(&x0).unwrap();
        let rg = RgDnoConfig { segments: 5, mask_kinds: vec![MaskKind::Temporal], ..rg };
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
        let mut scored = 0;
        let choice = stages
            .binary_masks(&z1, &z2, &mut rng, &mut |p: &StageProgress| {
                assert_eq!(p.steps, 32);
                scored = p.step;
            })
            .unwrap();
        (choice.masks, scored, choice.met)
    }

    fn candidates(masks: &[ChosenMask]) -> Vec<MaskCandidate> {
        masks.iter().map(|m| m.candidate).collect()
    }

    const FAR: &str = r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"},
        "target": [50.0], "frames": {"keyframes": ["last"]}}"#;

    /// Where no candidate meets the program, the ordered search scores every candidate and
    /// chooses the full search's masks.
    #[test]
    fn the_ordered_search_chooses_the_full_searchs_masks_when_nothing_meets() {
        let (full, scored, met) = search(FAR, Schedule::Paper, RgDnoConfig::default());
        assert_eq!((scored, met), (32, false));
        let (ordered, scored, met) = search(FAR, Schedule::UntilMet, RgDnoConfig::default());
        assert_eq!((candidates(&ordered), scored, met), (candidates(&full), 32, false));
    }

    /// With a patience, the ordered search on a program nothing meets ends once each sample's
    /// best has gone unchanged over that many candidates (a sample is no longer sampled from
    /// then on), before the last, on the masks the search with no patience keeps wherever those
    /// were scored by then.
    #[test]
    fn the_patient_search_ends_once_no_sample_s_best_has_changed() {
        let patient = RgDnoConfig { mask_batch: 2, mask_patience: 6, ..RgDnoConfig::default() };
        let (kept, scored, met) = search(FAR, Schedule::UntilMet, patient);
        let last_change = kept.iter().map(|m| m.place + 1).max().unwrap();
        assert!(!met && scored < 32, "scored {scored} of 32");
        let waited = scored - last_change;
        assert!(waited >= 6 && (waited < 8 || scored == SCREENED), "last change {last_change}, scored {scored}");
        let (all, _, _) = search(FAR, Schedule::UntilMet, RgDnoConfig { mask_batch: 2, ..RgDnoConfig::default() });
        for (k, a) in kept.iter().zip(&all) {
            if a.place < scored {
                assert_eq!(k.candidate, a.candidate);
            }
        }
    }

    /// Where every candidate meets the program, the ordered search ends after the fewest it
    /// scores, on masks that meet it; the paper's search scores all.
    #[test]
    fn the_ordered_search_ends_once_every_sample_meets_the_program() {
        let standing = r#"{"op": "greater_than", "quantity": {"kind": "position", "of": {"joint": "pelvis"},
            "axes": "y"}, "min": 0.1, "frames": {"keyframes": ["first"]}}"#;
        let (_, scored, met) = search(standing, Schedule::UntilMet, RgDnoConfig::default());
        assert_eq!((scored, met), (SCREENED, true));
        assert_eq!(search(standing, Schedule::Paper, RgDnoConfig::default()).1, 32);
    }
}
