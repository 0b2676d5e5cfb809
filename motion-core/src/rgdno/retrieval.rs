//! Constraint-based retrieval (RG-DNO §4.3, eqs. 5–6; supp. A "Semantic Check"): the motion of
//! the database that best satisfies the retrieval set `C_R`, as the start of the retrieved-noise
//! branch.
//!
//! **Candidates.** Crops of every database sequence (all augmentations: mirrored copies and
//! time warps), starting every [`RetrievalConfig::crop_stride_frames`] frames, of
//! `T·f` frames for each resize factor `f` of [`RetrievalConfig::resize_factors`], each
//! temporally resized to the task's `T` frames by linear interpolation (the paper's temporal
//! resizing; velocity channels are scaled by the time ratio so that the motion covers the same
//! ground in its new length). A factor above 1 plays a crop faster: a 2.5 s crawl resized to
//! 1 s covers the ground that the task's walk covers. A sequence shorter than `T` is resized
//! whole.
//!
//! **No transform `H` (eq. 6).** The paper's representation is global, so a retrieved motion
//! is rotated and shifted in the horizontal plane to fit. Ours (HumanML3D's 263-d features)
//! starts every motion at x = z = 0 facing +z, as the generator does. A shifted candidate
//! would often satisfy `C_R` vacuously (a crawl moved to end at the target never passes under
//! the barrier between), so candidates are scored where the generator would put them; the
//! crop start (which sets the facing and position at the first frame) and the resize factor
//! are the search.
//!
//! **Score.** `Σ_i w_i·E_i` over `C_R`, with `w = 1` for the most difficult constraint `c_D`
//! and [`RetrievalConfig::related_weight`] for its connected ones (supp. C: "we set a smaller
//! weight for the target position constraint in order not to overshadow `c_D`"), evaluated in
//! batches on the candidates' joints.
//!
//! **Semantic check.** A crop is dropped when its label contradicts the prompt's direction words
//! (forward/backward, left/right) or its gait (a walk against a jump or a run; beyond the paper,
//! whose check left a walking task free to retrieve a two-footed jump and keep its hops) and, for
//! counting tasks, when it lacks the prompt's action verb.

use candle_core::{DType, Device, Tensor};
use serde::Serialize;

use crate::constraints::{CompiledProgram, ConstraintError};
use crate::database::{MotionDatabase, Window};
use crate::representation::{recover_from_ric, FEATURE_DIM, LOCAL_VEL, ROOT_LIN_VEL, ROOT_ROT_VEL};

/// Settings of [`retrieve`].
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RetrievalConfig {
    /// Frames between the starts of consecutive crops of one sequence (default 20: 1 s).
    pub crop_stride_frames: usize,
    /// Crop lengths as multiples of the task's frame count, each resized to it (default 1,
    /// 1.5, 2, 2.5: the crop played at 1–2.5× its speed).
    pub resize_factors: Vec<f64>,
    /// Weight of `C_R`'s constraints other than `c_D` in the score (default 0.1).
    pub related_weight: f64,
    /// Retrieved motions kept, best first (default 5).
    pub top_k: usize,
    /// A motion is kept only when its score is at most this (default `None`: no threshold).
    pub threshold: Option<f64>,
    /// Crops scored per batch (default 256).
    pub batch: usize,
    /// Candidates re-scored with body-surface points after ranking all on joint centres
    /// (default 64; at least `top_k`).
    pub exact_shortlist: usize,
}

impl Default for RetrievalConfig {
    fn default() -> Self {
        Self {
            crop_stride_frames: 20,
            resize_factors: vec![1.0, 1.5, 2.0, 2.5],
            related_weight: 0.1,
            top_k: 5,
            threshold: None,
            batch: 256,
            exact_shortlist: 64,
        }
    }
}

/// Where a candidate motion comes from.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct CandidateSource {
    /// Source clip name.
    pub clip: String,
    /// Its label (mirrored for mirrored copies).
    pub label: String,
    /// A left/right mirrored copy.
    pub mirrored: bool,
    /// Playback speed of the augmented copy.
    pub speed: f64,
    /// Index of the sequence in the database.
    pub sequence: usize,
    /// First frame of the crop in the sequence.
    pub start: usize,
    /// Frames taken from the sequence (resized to the task's frame count).
    pub frames: usize,
}

impl std::fmt::Display for CandidateSource {
    /// `"label" (clip [mirrored] ×speed, frames a..b)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:?} ({}{} ×{}, frames {}..{})",
            self.label,
            self.clip,
            if self.mirrored { " mirrored" } else { "" },
            self.speed,
            self.start,
            self.start + self.frames
        )
    }
}

/// Every candidate crop of a database for one frame count, with its joints for scoring.
#[derive(Debug, Clone)]
pub struct RetrievalCorpus {
    frames: usize,
    sources: Vec<CandidateSource>,
    /// Raw features of every sequence, flat `[frames, 263]` each.
    sequences: Vec<Vec<f32>>,
    /// Joints `[N, T, 22, 3]` (m, y up), f32.
    joints: Tensor,
}

/// Why retrieval failed.
#[derive(Debug, thiserror::Error)]
pub enum RetrievalError {
    /// The database has no sequence to crop.
    #[error("the retrieval database has no sequence of at least 2 frames")]
    Empty,
    /// A setting cannot be used.
    #[error("invalid retrieval setting: {0}")]
    Setting(String),
    /// The retrieval set could not be evaluated.
    #[error(transparent)]
    Constraint(#[from] ConstraintError),
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
}

/// A retrieved motion `x_R`.
#[derive(Debug, Clone)]
pub struct Retrieved {
    /// Where it comes from.
    pub source: CandidateSource,
    /// Its score `Σ w_i·E_i` over `C_R`.
    pub score: f64,
    /// `(id, E_i)` per constraint of `C_R` (unweighted).
    pub per_constraint: Vec<(String, f64)>,
    /// Raw features `[T, 263]`.
    pub features: Tensor,
}

impl RetrievalCorpus {
    /// The crops of `database` for motions of `frames` frames, on `device`.
    pub fn build(
        database: &MotionDatabase,
        frames: usize,
        config: &RetrievalConfig,
        device: &Device,
    ) -> Result<Self, RetrievalError> {
        if frames < 2 || config.crop_stride_frames == 0 {
            return Err(RetrievalError::Setting(format!(
                "frames ({frames}) must be ≥ 2 and crop_stride_frames ({}) ≥ 1",
                config.crop_stride_frames
            )));
        }
        if let Some(f) = config.resize_factors.iter().find(|f| !(f.is_finite() && **f > 0.0 && **f <= 10.0)) {
            return Err(RetrievalError::Setting(format!("resize factors must lie in (0, 10], got {f}")));
        }
        let mut sources = Vec::new();
        let mut sequences = Vec::with_capacity(database.sequences().len());
        for (index, sequence) in database.sequences().iter().enumerate() {
            let whole = Window { sequence: index, start: 0, frames: sequence.frames };
            let data = database.window_slice(&whole, 0, sequence.frames).map(<[f32]>::to_vec).unwrap_or_default();
            let available = data.len() / FEATURE_DIM;
            let mut push = |start: usize, taken: usize| {
                sources.push(CandidateSource {
                    clip: sequence.source.clone(),
                    label: sequence.label.clone(),
                    mirrored: sequence.mirrored,
                    speed: sequence.speed,
                    sequence: index,
                    start,
                    frames: taken,
                });
            };
            if (2..frames).contains(&available) {
                push(0, available);
            }
            for &factor in &config.resize_factors {
                let length = ((frames as f64 * factor).round() as usize).max(2);
                let mut start = 0;
                while start + length <= available {
                    push(start, length);
                    start += config.crop_stride_frames;
                }
            }
            sequences.push(data);
        }
        if sources.is_empty() {
            return Err(RetrievalError::Empty);
        }
        let mut corpus = Self { frames, sources, sequences, joints: Tensor::zeros(0, DType::F32, device)? };
        let mut joints = Vec::new();
        let step = config.batch.max(1);
        for start in (0..corpus.len()).step_by(step) {
            let rows: Vec<usize> = (start..(start + step).min(corpus.len())).collect();
            let features: Vec<f32> = rows.iter().flat_map(|&i| corpus.features_of(i)).collect();
            let features = Tensor::from_vec(features, (rows.len(), frames, FEATURE_DIM), device)?;
            joints.push(recover_from_ric(&features)?);
        }
        corpus.joints = Tensor::cat(&joints, 0)?;
        Ok(corpus)
    }

    /// Raw features of candidate `i`, resized to the corpus's frame count, flat `[T, 263]`.
    fn features_of(&self, i: usize) -> Vec<f32> {
        let s = &self.sources[i];
        let crop = &self.sequences[s.sequence][s.start * FEATURE_DIM..(s.start + s.frames) * FEATURE_DIM];
        if s.frames == self.frames {
            crop.to_vec()
        } else {
            resize_features(crop, s.frames, self.frames)
        }
    }

    /// Frames per candidate.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Number of candidates.
    pub fn len(&self) -> usize {
        self.sources.len()
    }

    /// Whether there is no candidate.
    pub fn is_empty(&self) -> bool {
        self.sources.is_empty()
    }

    /// Where candidate `i` comes from.
    pub fn source(&self, i: usize) -> Option<&CandidateSource> {
        self.sources.get(i)
    }
}

/// The task as retrieval sees it: the compiled `C_R`, its most difficult constraint and the
/// prompt that the semantic check reads.
#[derive(Debug, Clone, Copy)]
pub struct RetrievalQuery<'a> {
    /// `C_R`, compiled for the corpus's frame count.
    pub program: &'a CompiledProgram,
    /// Id of `c_D` (weight 1 in the score).
    pub most_difficult: &'a str,
    /// The task's text prompt.
    pub prompt: &'a str,
    /// Whether the task counts actions (its candidates must carry the prompt's action verb).
    pub counting: bool,
}

/// Eqs. 5–6: scores every candidate of `corpus` that passes the semantic check on `query` and
/// returns the best `top_k` under the threshold, best first (empty when none passes).
pub fn retrieve(
    corpus: &RetrievalCorpus,
    query: &RetrievalQuery<'_>,
    config: &RetrievalConfig,
) -> Result<Vec<Retrieved>, RetrievalError> {
    if query.program.frames() != corpus.frames {
        return Err(RetrievalError::Setting(format!(
            "C_R is compiled for {} frames, the corpus holds {}",
            query.program.frames(),
            corpus.frames
        )));
    }
    if !(config.related_weight.is_finite() && config.related_weight >= 0.0) {
        return Err(RetrievalError::Setting(format!("related_weight must be ≥ 0, got {}", config.related_weight)));
    }
    let kept: Vec<usize> = (0..corpus.len())
        .filter(|&i| semantically_consistent(query.prompt, &corpus.sources[i].label, query.counting))
        .collect();
    // Rank every candidate on the joint centres, then score the best exactly (surface points).
    let proxy = query.program.joints_only();
    let mut ranked = score(corpus, &proxy, &kept, query.most_difficult, config)?;
    ranked.sort_by(|a, b| a.1.total_cmp(&b.1));
    let shortlist: Vec<usize> =
        ranked.iter().take(config.exact_shortlist.max(config.top_k)).map(|(i, ..)| *i).collect();
    let mut scored = score(corpus, query.program, &shortlist, query.most_difficult, config)?;
    scored.retain(|(_, score, _)| score.is_finite() && config.threshold.is_none_or(|t| *score <= t));
    scored.sort_by(|a, b| a.1.total_cmp(&b.1));
    scored.truncate(config.top_k);
    scored
        .into_iter()
        .map(|(i, score, per_constraint)| {
            Ok(Retrieved {
                source: corpus.sources[i].clone(),
                score,
                per_constraint,
                features: Tensor::from_vec(
                    corpus.features_of(i),
                    (corpus.frames, FEATURE_DIM),
                    corpus.joints.device(),
                )?,
            })
        })
        .collect()
}

/// A candidate's score: `(candidate, Σ w_i·E_i, (id, E_i) per constraint)`.
type Scored = (usize, f64, Vec<(String, f64)>);

/// The scores of the candidates `rows` under `program`, in batches.
fn score(
    corpus: &RetrievalCorpus,
    program: &CompiledProgram,
    rows: &[usize],
    most_difficult: &str,
    config: &RetrievalConfig,
) -> Result<Vec<Scored>, RetrievalError> {
    let mut scored = Vec::with_capacity(rows.len());
    for chunk in rows.chunks(config.batch.max(1)) {
        let index =
            Tensor::from_vec(chunk.iter().map(|&i| i as u32).collect::<Vec<_>>(), chunk.len(), corpus.joints.device())?;
        let evaluation = program.evaluate(&corpus.joints.index_select(&index, 0)?, None)?;
        let mut per: Vec<(String, Vec<f64>)> = Vec::with_capacity(evaluation.per_constraint.len());
        for (id, error) in &evaluation.per_constraint {
            per.push((id.clone(), error.to_dtype(DType::F64)?.to_vec1::<f64>()?));
        }
        for (row, &i) in chunk.iter().enumerate() {
            let errors: Vec<(String, f64)> = per.iter().map(|(id, e)| (id.clone(), e[row])).collect();
            let total = errors
                .iter()
                .map(|(id, e)| if id == most_difficult { *e } else { config.related_weight * e })
                .sum::<f64>();
            scored.push((i, total, errors));
        }
    }
    Ok(scored)
}

/// Pairs of direction words that contradict each other (either way round).
const DIRECTION_CONTRADICTIONS: [(&str, &str); 3] = [("forward", "backward"), ("left", "right"), ("up", "down")];

/// Pairs of gaits that contradict each other (either way round): a walk always has a foot on
/// the ground, these have a flight phase. A crawl is not among them: the paper retrieves
/// crawling for walking prompts (RG-DNO Fig. 3), to pass under barriers.
const GAIT_CONTRADICTIONS: [(&str, &str); 5] =
    [("walk", "run"), ("walk", "jog"), ("walk", "jump"), ("walk", "hop"), ("walk", "leap")];

/// Action verbs the semantic check of a counting task looks for, by stem.
const ACTION_VERBS: [&str; 12] =
    ["walk", "run", "jog", "jump", "hop", "crawl", "clap", "kick", "punch", "wave", "step", "touch"];

/// The supplementary's keyword check: `false` when `label` holds a direction word or a gait
/// that contradicts one of `prompt`'s and that the prompt does not name itself ("backwards"
/// against "walks forwards", "jumps" against "walks", but not "turns right" against "turns
/// left, then right"), or when `counting` and the prompt names an action verb that `label`
/// lacks. Words match by stem ("walk" matches "walks" and "walking").
pub fn semantically_consistent(prompt: &str, label: &str, counting: bool) -> bool {
    let prompt_words = words(prompt);
    let label_words = words(label);
    let has = |ws: &[String], stem: &str| ws.iter().any(|w| w.starts_with(stem));
    let contradicts =
        |named: &str, other: &str| has(&prompt_words, named) && !has(&prompt_words, other) && has(&label_words, other);
    if DIRECTION_CONTRADICTIONS.iter().chain(&GAIT_CONTRADICTIONS).any(|&(a, b)| contradicts(a, b) || contradicts(b, a))
    {
        return false;
    }
    if counting {
        let verbs: Vec<&str> = ACTION_VERBS.iter().copied().filter(|v| has(&prompt_words, v)).collect();
        if !verbs.is_empty() && !verbs.iter().any(|v| has(&label_words, v)) {
            return false;
        }
    }
    true
}

fn words(text: &str) -> Vec<String> {
    text.split(|c: char| !c.is_alphanumeric()).filter(|w| !w.is_empty()).map(str::to_lowercase).collect()
}

/// Linear resampling of raw features `[from, 263]` (flat) to `to` frames. Velocity channels
/// (root rotation and linear velocity, local joint velocities; per frame) are scaled by
/// `(from − 1)/(to − 1)` so that the motion covers the same ground and turn in its new length.
pub fn resize_features(data: &[f32], from: usize, to: usize) -> Vec<f32> {
    let scale = if to > 1 { (from.max(1) - 1) as f32 / (to - 1) as f32 } else { 0.0 };
    // Velocities are per frame: a clip stretched by 1/scale moves 1/scale as far per frame.
    let factors: Vec<f32> = (0..FEATURE_DIM)
        .map(|c| match c == ROOT_ROT_VEL || ROOT_LIN_VEL.contains(&c) || LOCAL_VEL.contains(&c) {
            true => scale,
            false => 1.0,
        })
        .collect();
    let row = |t: usize| &data[t * FEATURE_DIM..(t + 1) * FEATURE_DIM];
    let mut out = Vec::with_capacity(to * FEATURE_DIM);
    for t in 0..to {
        let position = t as f32 * scale;
        let lower = (position.floor() as usize).min(from - 1);
        let upper = (lower + 1).min(from - 1);
        let w = position - lower as f32;
        let blended = row(lower).iter().zip(row(upper)).zip(&factors);
        out.extend(blended.map(|((&a, &b), &f)| ((1.0 - w) * a + w * b) * f));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_semantic_check_drops_contradicting_directions_gaits_and_missing_verbs() {
        assert!(!semantically_consistent("a man walks forwards", "a person walks backwards", false));
        assert!(semantically_consistent("a man walks forwards", "a person walks forward", false));
        assert!(semantically_consistent("a man walks forwards", "a person crawls forward on the ground", false));
        assert!(!semantically_consistent("a person walks and turns left", "a person walks and turns right", false));
        // A direction the prompt names both ways contradicts nothing.
        assert!(semantically_consistent("a person turns left, then right", "a person walks and turns right", false));
        // Gaits: a walk is not a jump or a run (either way round), but may be a crawl.
        assert!(!semantically_consistent("a man walks forwards", "a person jumps forward", false));
        assert!(!semantically_consistent("a man walks forwards", "a person runs forward", false));
        assert!(!semantically_consistent("a person jumps forward", "a person walks forward", false));
        assert!(semantically_consistent(
            "a man runs forwards and jumps over an obstacle",
            "a person jumps forward",
            false
        ));
        assert!(semantically_consistent("a man walks forwards and jumps", "a person jumps forward", false));
        // Counting tasks need the action verb.
        assert!(!semantically_consistent("a man walks six steps", "a person dances in place", true));
        assert!(semantically_consistent("a man walks six steps", "a person walks forward punching", true));
        assert!(semantically_consistent("a man walks six steps", "a person dances in place", false));
    }

    #[test]
    fn resizing_keeps_the_ends_and_scales_velocities() {
        let from = 5;
        let data: Vec<f32> = (0..from * FEATURE_DIM).map(|i| (i / FEATURE_DIM) as f32).collect();
        let out = resize_features(&data, from, 9);
        assert_eq!(out.len(), 9 * FEATURE_DIM);
        // A position channel (root height) goes 0, 0.5, …, 4; a velocity channel is halved.
        let at = |t: usize, c: usize| out[t * FEATURE_DIM + c];
        assert_eq!(at(0, 3), 0.0);
        assert!((at(1, 3) - 0.5).abs() < 1e-6);
        assert!((at(8, 3) - 4.0).abs() < 1e-6);
        assert!((at(8, ROOT_ROT_VEL) - 2.0).abs() < 1e-6);
    }
}
