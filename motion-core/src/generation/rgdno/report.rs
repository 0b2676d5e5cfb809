//! What RG-DNO reports: the groups, the retrieved motions, each stage's figures per sample and
//! seconds, and the progress of a running stage.

use serde::{Deserialize, Serialize};

use super::candidates::CandidateSource;
use super::config::RgDnoConfig;
use super::mask::MaskCandidate;
use super::retrieval::SoughtSkills;
use crate::dno;
use crate::generation::method::pick_rows;
use crate::numeric::mean;

/// A retrieved motion as the report gives it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RetrievedReport {
    /// Where it comes from.
    pub source: CandidateSource,
    /// `Σ w_i·E_i` over `C_R`.
    pub score: f64,
    /// `(id, E_i)` per constraint of `C_R`.
    pub per_constraint: Vec<(String, f64)>,
    /// The semantic score: cosine similarity of the sentence vectors (the prior's text encoder)
    /// of its window's sentence (the caption with its take's description) and of the program's
    /// text, which ranks the shortlist beside `C_R` ([`super::retrieval`]); none in reports
    /// written before it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub caption_similarity: Option<f64>,
}

/// A retrieved motion inverted to noise.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct InvertedReport {
    /// Its index in the report's `retrieved`.
    pub motion: usize,
    /// Mean joint distance of `G(z_R)` to `x_R`, m.
    pub error_m: f64,
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
    /// Its place in the order the candidates were scored (0: first; the paper's search scores
    /// them in [`MaskCandidate::all`]'s order, the until-met search in its cheap sampler's).
    #[serde(default)]
    pub place: usize,
}

/// Seconds per stage; of the stages every sample runs on its own, summed over the samples and
/// divided by the workers that ran them side by side
/// ([`crate::generation::side_by_side::workers`]).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StageSeconds {
    /// Retrieval: the semantic check, scoring every candidate, extracting the retrieved
    /// features.
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

/// Steps each stage ran, summed over the restarts (the masks: candidates scored through the
/// full sampler); of the stages every sample runs on its own, the most any sample ran. The
/// [`crate::generation::schedule::Schedule`] decides where a stage ends.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct StageSteps {
    /// The inversion's feature and joint polishes.
    pub inversion: usize,
    /// The branches (one batch for both).
    pub branches: usize,
    /// Mask candidates scored by eq. 13.
    pub masks: usize,
    /// The soft blend.
    pub soft_blend: usize,
    /// The final round.
    pub final_round: usize,
    /// Of the final round's steps, those on the coarser sampler of the stages before it
    /// ([`super::config::RgDnoConfig::early_stride`]; 0 where the round ran on one sampler).
    #[serde(default)]
    pub final_round_coarse: usize,
}

impl StageSteps {
    /// Counts one progress report: a step of a DNO stage, or the candidates done of the mask
    /// search (which counts up from the start of each restart).
    pub(super) fn record(&mut self, progress: &StageProgress, masks_done: &mut usize) {
        match progress.stage {
            Stage::Inversion => self.inversion += 1,
            Stage::Branches => self.branches += 1,
            Stage::Masks => {
                let before = if progress.step > *masks_done { *masks_done } else { 0 };
                self.masks += progress.step - before;
                *masks_done = progress.step;
            }
            Stage::SoftBlend => self.soft_blend += 1,
            Stage::FinalRound => self.final_round += 1,
            Stage::FinalRoundCoarse => {
                self.final_round += 1;
                self.final_round_coarse += 1;
            }
        }
    }

    /// Stage by stage, the most steps any of `runs` ran.
    pub(super) fn longest<'a>(runs: impl IntoIterator<Item = &'a StageSteps>) -> StageSteps {
        runs.into_iter().fold(StageSteps::default(), |a, b| a.zip_with(b, usize::max))
    }

    /// The steps of both runs, stage by stage.
    pub(super) fn plus(&self, other: &StageSteps) -> StageSteps {
        self.zip_with(other, |a, b| a + b)
    }

    /// `f` of both runs' steps, stage by stage.
    fn zip_with(&self, other: &StageSteps, f: impl Fn(usize, usize) -> usize) -> StageSteps {
        StageSteps {
            inversion: f(self.inversion, other.inversion),
            branches: f(self.branches, other.branches),
            masks: f(self.masks, other.masks),
            soft_blend: f(self.soft_blend, other.soft_blend),
            final_round: f(self.final_round, other.final_round),
            final_round_coarse: f(self.final_round_coarse, other.final_round_coarse),
        }
    }
}

impl StageSeconds {
    /// The seconds of both runs, stage by stage.
    pub(super) fn plus(&self, other: &StageSeconds) -> StageSeconds {
        self.zip_with(other, |a, b| a + b)
    }

    /// `f` of both runs' seconds, stage by stage.
    pub(super) fn zip_with(&self, other: &StageSeconds, f: impl Fn(f64, f64) -> f64) -> StageSeconds {
        StageSeconds {
            retrieval: f(self.retrieval, other.retrieval),
            inversion: f(self.inversion, other.inversion),
            branches: f(self.branches, other.branches),
            masks: f(self.masks, other.masks),
            soft_blend: f(self.soft_blend, other.soft_blend),
            final_round: f(self.final_round, other.final_round),
        }
    }
}

impl RgDnoReport {
    /// The retrieved motions the samples kept (indices into `retrieved`, first kept first) and
    /// how many samples kept each.
    pub fn kept_motions(&self) -> Vec<(usize, usize)> {
        let mut kept: Vec<(usize, usize)> = Vec::new();
        for &m in &self.motion {
            match kept.iter_mut().find(|(k, _)| *k == m) {
                Some((_, count)) => *count += 1,
                None => kept.push((m, 1)),
            }
        }
        kept
    }

    /// This report with the per-sample figures of `other` (another attempt at the same task)
    /// where `rows[b]` is `Some(i)`, as [`crate::generation::method::Generated::with_rows_from`];
    /// the seconds and steps add up and the inverted motions of both are listed.
    pub fn with_rows_from(self, other: RgDnoReport, rows: &[Option<usize>]) -> RgDnoReport {
        RgDnoReport {
            z1_error: pick_rows(self.z1_error, &other.z1_error, rows),
            z2_error: pick_rows(self.z2_error, &other.z2_error, rows),
            masks: pick_rows(self.masks, &other.masks, rows),
            soft_blend_objective: pick_rows(self.soft_blend_objective, &other.soft_blend_objective, rows),
            restart: pick_rows(self.restart, &other.restart, rows),
            motion: pick_rows(self.motion, &other.motion, rows),
            inverted: self.inverted.into_iter().chain(other.inverted).collect(),
            final_objective: pick_rows(self.final_objective, &other.final_objective, rows),
            seconds: self.seconds.plus(&other.seconds),
            steps: self.steps.plus(&other.steps),
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
    /// Candidate crops of the retrieval database for the task's frame count.
    pub candidates: usize,
    /// Those that passed the semantic check, all scored.
    #[serde(default)]
    pub consistent_candidates: usize,
    /// The actions the prompt names that no window of the database does, by their verb
    /// ("crawls"): the retrieved motion is a stand-in that the prompt's other actions accept.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub missing_actions: Vec<String>,
    /// The skills other than walking the prompt asks for, and how many consistent candidates do
    /// one (only they were scored when there were any); absent when it asks for none, and in
    /// reports written before retrieval looked for them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skills: Option<SoughtSkills>,
    /// The retrieved motions, best first, one per take; the stages started from those of
    /// `inverted`.
    pub retrieved: Vec<RetrievedReport>,
    /// The retrieved motions `x_R` the stages started from, each inverted to `z_R`, in the
    /// order they ran.
    #[serde(default)]
    pub inverted: Vec<InvertedReport>,
    /// Which retrieved motion (an index into `retrieved`) each sample's kept attempt started
    /// from.
    #[serde(default)]
    pub motion: Vec<usize>,
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
    /// Steps per stage.
    #[serde(default)]
    pub steps: StageSteps,
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
    /// The final DNO round's start on the coarser sampler of the stages before it.
    FinalRoundCoarse,
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
            Stage::FinalRoundCoarse => "final round (coarse sampler)",
        }
    }
}

/// Progress of a running stage.
#[derive(Debug, Clone)]
pub struct StageProgress {
    /// The stage.
    pub stage: Stage,
    /// The attempt: retrieved motion `j` (0 to `m` − 1) and restart `r` (0 to `N_S` − 1) make
    /// attempt `j·N_S + r`; the inversion of motion `j` is round `j`.
    pub round: usize,
    /// Steps done.
    pub step: usize,
    /// Steps of the stage.
    pub steps: usize,
    /// Mean loss over the samples (0 where a stage has none).
    pub loss: f64,
    /// The sample, where every sample runs the stages after the inversion on its own (the
    /// branches, the masks, the soft blend and the final round, side by side); `None` for a
    /// stage run once for every sample.
    pub sample: Option<usize>,
}

impl StageProgress {
    /// The progress of a DNO step of `stage` in restart `round`.
    pub(super) fn of_dno(stage: Stage, round: usize, step: &dno::DnoStep) -> Self {
        StageProgress { stage, round, step: step.step + 1, steps: step.steps, loss: mean(&step.loss), sample: None }
    }
}
