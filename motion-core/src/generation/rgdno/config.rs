//! RG-DNO's settings (the paper's defaults, §5.2) and Table 4's ablations.

use serde::{Deserialize, Serialize};

use super::mask::MaskKind;
use super::reward::RewardWeights;
use crate::diffusion::Guidance;
use crate::dno::DnoConfig;
use crate::generation::inversion::InversionConfig;
use crate::generation::method::GenerationError;
use crate::generation::schedule::Schedule;
use crate::program::ConstraintGroups;

/// Settings of constraint-based retrieval ([`super::retrieval::retrieve`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RetrievalConfig {
    /// Frames between the starts of consecutive crops of one clip (default 20: 1 s).
    pub crop_stride_frames: usize,
    /// Crop lengths as multiples of the task's frame count, each resized to it (default 1,
    /// 1.5, 2, 2.5: the crop played at 1–2.5× its speed).
    pub resize_factors: Vec<f64>,
    /// Weight of `C_R`'s constraints other than `c_D` in the score (default 0.1).
    pub related_weight: f64,
    /// Retrieved motions kept, best first, each from a different take (default 5).
    pub top_k: usize,
    /// A motion is kept only when its score is at most this (default `None`: no threshold).
    pub threshold: Option<f64>,
    /// Crops scored per batch (default 32: 0.7 MB of f32 joints for a 100-frame task, small
    /// enough that candle runs the proxy's element-wise ops inline on the batch's worker).
    pub batch: usize,
    /// Candidates re-scored exactly (body-surface points, every frame) after ranking all on
    /// the proxy (default 64; at least `top_k`).
    pub exact_shortlist: usize,
    /// The proxy that ranks every candidate reads every `proxy_frame_step`-th frame of the
    /// spans its constraints reduce over, keyframes kept ([`crate::constraints::CompiledProgram::thinned`]), and the
    /// joint centres only (default 4: 5 Hz; 1: every frame).
    pub proxy_frame_step: usize,
    /// `λ` of the caption similarity in the shortlist's ranking,
    /// `Σ_i w_i·E_i + λ·(1 − cos(prompt, sentence))` (beyond the paper; default 0: `C_R` alone,
    /// as the paper ranks; 0.05 retrieves a box carry for "carries a box" but changed three of
    /// Table 6's picks, `fixtures/results/issue60-caption/`). [`super::retrieval`] says what it
    /// reads.
    pub caption_weight: f64,
    /// `λ` of the same ranking when the prompt asks for a skill and only crops that do it are
    /// scored ([`super::semantic::Heard::skills`]; default 0.05): among takes that all do the
    /// skill, a near tie in `C_R` goes to the one whose words match the prompt ("hops on one
    /// foot forward" over "hops on one foot forward and turns right").
    pub skill_caption_weight: f64,
}

impl Default for RetrievalConfig {
    fn default() -> Self {
        Self {
            crop_stride_frames: 20,
            resize_factors: vec![1.0, 1.5, 2.0, 2.5],
            related_weight: 0.1,
            top_k: 5,
            threshold: None,
            batch: 32,
            exact_shortlist: 64,
            proxy_frame_step: 4,
            caption_weight: 0.0,
            skill_caption_weight: 0.05,
        }
    }
}

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
    /// Under [`crate::generation::schedule::Schedule::UntilMet`], a sample's best candidate
    /// that has not changed over this many candidates scored in its order ends that sample's
    /// search (its rows are no longer sampled; default 64; 0: a sample's search ends only
    /// when the program is met, or after every candidate). The paper's search scores every
    /// candidate.
    pub mask_patience: usize,
    /// Under [`crate::generation::schedule::Schedule::UntilMet`], for a program without
    /// counts, the inversion, the branches, the mask search and the soft blend sample through
    /// every `early_stride`-th timestep of the run's DDIM sampler, counted down from its start
    /// ([`crate::diffusion::DdimSampler::every`]: ddim10 by 2 is 900, 700, …, 100); the final
    /// round starts on that sampler and finishes on the whole one (default 2; 1: every stage on
    /// the whole sampler, as the paper's schedule and a counting program always run). The noise
    /// they hand on starts the same sampler, so the final round refines the same motion.
    pub early_stride: usize,
    /// Under the same conditions as [`Self::early_stride`], the stages before the final round
    /// also sample without classifier-free guidance: the conditional prediction alone, one
    /// denoiser pass per timestep instead of two (default true; false: the run's guidance, as
    /// the paper's schedule and a counting program always run). The restart's unoptimised
    /// motion and the final round's whole sampler keep the run's guidance, so the motion handed
    /// on is a guided sample of its noise.
    pub early_unguided: bool,
    /// The reward weights λ of eq. 14.
    pub reward: RewardWeights,
    /// DNO steps `N2` of the final round (default 400).
    pub final_steps: usize,
    /// Peak learning rate of the final round (default 0.02).
    pub final_lr: f64,
    /// One of Table 4's ablations instead of the full method (default: none).
    pub ablation: Ablation,
    /// Retrieved motions `m` the stages start from (beyond the paper, whose stated future work
    /// this is; default 1, the paper's): the best crops of `m` different takes
    /// ([`super::retrieval`]), each inverted and run through every stage with the run's
    /// restarts; each sample keeps its best attempt by `F_C`, as restarts do.
    pub retrieved_motions: usize,
    /// Retrieved motions passed over, best first (default 0): a retry of the samples that
    /// missed a constraint starts from the takes after those the earlier attempts used
    /// ([`crate::pipeline`]). Counted around when it passes the last one retrieved.
    pub skip_retrieved: usize,
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
    pub(super) fn groups(self, groups: ConstraintGroups, all: Vec<String>) -> ConstraintGroups {
        match self {
            Ablation::NoParsing => ConstraintGroups { retrieval: all, ..groups },
            Ablation::SameSets => ConstraintGroups { random_noise: all.clone(), retrieved_noise: all, ..groups },
            _ => groups,
        }
    }

    /// The fixed blend of the branches, where the ablation replaces the mask search: the mask
    /// value `M` of `z' = M·z1 + (1 − M)·z2`.
    pub(super) fn fixed_mask(self) -> Option<f64> {
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
            mask_patience: 64,
            early_stride: 2,
            early_unguided: true,
            reward: RewardWeights::default(),
            final_steps: 400,
            final_lr: 0.02,
            ablation: Ablation::None,
            retrieved_motions: 1,
            skip_retrieved: 0,
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
        if self.retrieved_motions == 0 {
            return bad("rg_dno.retrieved_motions must be at least 1, got 0".into());
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

    /// The stride of the stages before the final round under `schedule`, for a program that
    /// `counts` (steps, counted extrema or events) or not: 1 under the paper's schedule, and
    /// for a count, which is made of discrete events that the whole sampler may not place where
    /// the coarser one did (`fixtures/results/issue59-early-stride/`).
    pub(super) fn early_stride_under(&self, schedule: Schedule, counts: bool) -> usize {
        if Self::early_stages_eased(schedule, counts) {
            self.early_stride.max(1)
        } else {
            1
        }
    }

    /// The guidance of the stages before the final round under `schedule`, for a program that
    /// `counts` or not, in a run guided by `guidance`: none where [`Self::early_unguided`]
    /// applies (as [`Self::early_stride_under`]), else `guidance`.
    pub(super) fn early_guidance_under(&self, schedule: Schedule, counts: bool, guidance: Guidance) -> Guidance {
        if self.early_unguided && Self::early_stages_eased(schedule, counts) {
            Guidance::none()
        } else {
            guidance
        }
    }

    /// Whether each sample runs the stages after the inversion on its own worker
    /// ([`crate::generation::side_by_side`]) under `schedule`, for a program that `counts` or
    /// not: where the stages before the final round are eased; elsewhere the samples run as one
    /// batch, as the papers' tables were made.
    pub(super) fn side_by_side_under(schedule: Schedule, counts: bool) -> bool {
        Self::early_stages_eased(schedule, counts)
    }

    /// Whether the stages before the final round may run a cheaper sampler: under the
    /// until-met schedule, for a program without counts.
    fn early_stages_eased(schedule: Schedule, counts: bool) -> bool {
        schedule == Schedule::UntilMet && !counts
    }

    /// The retrieval settings that keep enough takes for the motions the stages start from.
    pub(super) fn retrieval_keeping_used(&self) -> RetrievalConfig {
        let top_k = self.retrieval.top_k.max(self.skip_retrieved + self.retrieved_motions);
        RetrievalConfig { top_k, ..self.retrieval.clone() }
    }

    /// The indices into the retrieved motions (best first, `retrieved` of them) that the stages
    /// start from: [`Self::retrieved_motions`] distinct ones after [`Self::skip_retrieved`],
    /// counted around past the last.
    pub(super) fn used_motions(&self, retrieved: usize) -> Vec<usize> {
        (0..self.retrieved_motions.min(retrieved)).map(|j| (self.skip_retrieved + j) % retrieved).collect()
    }
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
    fn the_early_stride_applies_under_the_until_met_schedule_to_programs_without_counts() {
        let config = RgDnoConfig::default();
        let under = |config: &RgDnoConfig, schedule, counts| config.early_stride_under(schedule, counts);
        assert_eq!(under(&config, Schedule::UntilMet, false), 2);
        assert_eq!(under(&config, Schedule::UntilMet, true), 1, "a counting program");
        assert_eq!(under(&config, Schedule::Paper, false), 1);
        assert_eq!(under(&RgDnoConfig { early_stride: 0, ..config }, Schedule::UntilMet, false), 1);
    }

    #[test]
    fn the_early_stages_go_unguided_where_the_early_stride_applies() {
        let config = RgDnoConfig::default();
        let guided = Guidance::default();
        let under = |config: &RgDnoConfig, schedule, counts| config.early_guidance_under(schedule, counts, guided);
        assert_eq!(under(&config, Schedule::UntilMet, false), Guidance::none());
        assert_eq!(under(&config, Schedule::UntilMet, true), guided, "a counting program");
        assert_eq!(under(&config, Schedule::Paper, false), guided);
        assert_eq!(under(&RgDnoConfig { early_unguided: false, ..config }, Schedule::UntilMet, false), guided);
    }

    #[test]
    fn used_motions_are_distinct_start_after_the_skipped_and_count_around() {
        let config = |retrieved_motions, skip_retrieved| RgDnoConfig {
            retrieved_motions,
            skip_retrieved,
            ..RgDnoConfig::default()
        };
        assert_eq!(config(1, 0).used_motions(5), [0]);
        assert_eq!(config(2, 0).used_motions(5), [0, 1]);
        assert_eq!(config(2, 2).used_motions(5), [2, 3]);
        assert_eq!(config(2, 4).used_motions(5), [4, 0]);
        assert_eq!(config(3, 1).used_motions(2), [1, 0]);
        assert_eq!(config(2, 4).retrieval_keeping_used().top_k, 6);
        assert_eq!(config(1, 0).retrieval_keeping_used(), RetrievalConfig::default());
        assert!(config(0, 0).validate(100).is_err());
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
