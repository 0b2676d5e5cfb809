//! Constraint-based retrieval (RG-DNO §4.3, eqs. 5–6; supp. A "Semantic Check"): the motion of
//! the retrieval database that best satisfies the retrieval set `C_R`, as the start of the
//! retrieved-noise branch.
//!
//! **Candidates.** Crops of every clip of the retrieval database (by default the corpus's train
//! split with mirrored copies), starting every [`RetrievalConfig::crop_stride_frames`] frames,
//! of `T·f` frames for each resize factor `f` of [`RetrievalConfig::resize_factors`], each
//! resized in joint space to the task's `T` frames (the paper's temporal resizing); a factor
//! above 1 plays a crop faster. [`super::candidates`] holds the joints once and makes a crop's
//! joints only while its batch is scored.
//!
//! **No transform `H` (eq. 6).** The paper's representation is global, so a retrieved motion
//! is rotated and shifted in the horizontal plane to fit. Ours (HumanML3D's 263-d features)
//! starts every motion at x = z = 0 facing +z, as the generator does. A shifted candidate
//! would often satisfy `C_R` vacuously (a crawl moved to end at the target never passes under
//! the barrier between), so candidates are scored where the generator would put them; the
//! crop start (which sets the facing and position at the first frame) and the resize factor
//! are the search.
//!
//! **Semantic check** ([`super::semantic`]), before anything is scored: a crop is dropped when
//! its window contradicts the prompt's direction words (forward/backward, left/right) or its
//! gait (a walk against a jump or a run; beyond the paper, whose check left a walking task free
//! to retrieve a two-footed jump and keep its hops) and, for counting tasks, when it lacks the
//! prompt's action verb. When the prompt names skills other than walking ([`Heard::skills`]: a
//! crawl, a sit, a jump, …) and some consistent crop's window does one of them by measurement
//! ([`crate::corpus::family::Family::happens_in`]), only those crops are scored: of a walk that
//! fits `C_R` a little better and a sit that fits it a little worse, a prompt that sits gets the
//! sit; of those, one that turns half round unasked is passed over ([`Heard::turns_unasked`]).
//! When none does, every consistent crop is scored and the outcome says so
//! ([`SoughtSkills::candidates`] 0).
//!
//! **Score.** `Σ_i w_i·E_i` over `C_R`, with `w = 1` for the most difficult constraint `c_D`
//! and [`RetrievalConfig::related_weight`] for its connected ones (supp. C: "we set a smaller
//! weight for the target position constraint in order not to overshadow `c_D`"), evaluated in
//! batches on the candidates' joints: every candidate on a proxy (the joint centres only, every
//! [`RetrievalConfig::proxy_frame_step`]-th frame), then the best
//! [`RetrievalConfig::exact_shortlist`] exactly (body-surface points, every frame). Features
//! (`[T, 263]`, for the inversion) are extracted for the retrieved few only.
//!
//! **Caption similarity** (beyond the paper, which ranks by `C_R` alone): with a sentence
//! encoder, each exactly scored candidate's sentence (its window's caption with the take's
//! description, [`RetrievalDatabase`]'s words for it) is compared with the prompt and reported,
//! and the shortlist is ranked by `Σ_i w_i·E_i + λ·(1 − cos(prompt, sentence))`, `λ`
//! [`RetrievalConfig::caption_weight`] (0 by default: the paper's ranking), or
//! [`RetrievalConfig::skill_caption_weight`] (0.05) when only the crops that do the prompt's
//! skill are scored. With `λ > 0`, of two
//! motions that fit `C_R` about equally the one whose take does what the sentence says wins (at
//! 0.05, "a person carries a box forward" retrieves "walk carrying a box" over a plain walk that
//! fits 0.004 better). Only the shortlist is read, so meaning re-ranks good fits and never lifts
//! a poor one.

use candle_core::{DType, Device, Tensor};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::candidates::{CandidateSource, Crop, RetrievalDatabase};
use super::config::RetrievalConfig;
use super::error::RetrievalError;
use super::semantic::Heard;
use crate::constraints::CompiledProgram;
use crate::corpus::caption::Action;
use crate::skeleton::NUM_JOINTS;
use crate::text::TextEncoder;

/// A retrieved motion `x_R`.
#[derive(Debug, Clone)]
pub struct Retrieved {
    /// Where it comes from.
    pub source: CandidateSource,
    /// Its score `Σ w_i·E_i` over `C_R`.
    pub score: f64,
    /// `(id, E_i)` per constraint of `C_R` (unweighted).
    pub per_constraint: Vec<(String, f64)>,
    /// Cosine similarity of its sentence to the prompt's (both as the sentence encoder gives
    /// them); `None` without an encoder.
    pub caption_similarity: Option<f64>,
    /// Raw features `[T, 263]`.
    pub features: Tensor,
}

/// What [`retrieve`] found, and among how many.
#[derive(Debug, Clone)]
pub struct RetrievalOutcome {
    /// The best motions under the threshold, best first (empty when none passes).
    pub retrieved: Vec<Retrieved>,
    /// Candidate crops of the database for the task's frame count.
    pub candidates: usize,
    /// Those that passed the semantic check, all scored.
    pub consistent: usize,
    /// The actions the prompt names ([`super::semantic::named_actions`]) that no window of the database does:
    /// the retrieved motion, if any, is a stand-in the prompt's other actions accept.
    pub missing_actions: Vec<Action>,
    /// The skills the prompt asks for ([`Heard::skills`]), if any, and how many consistent
    /// crops do one.
    pub skills: Option<SoughtSkills>,
}

/// The skills retrieval looked for first, as reports name them.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SoughtSkills {
    /// Their families' names ([`crate::corpus::family::Family::name`]), the most specific
    /// first.
    pub families: Vec<String>,
    /// Consistent crops whose window does one: the only ones scored when there are any; with
    /// none, every consistent crop was scored and the retrieved motion is a stand-in.
    pub candidates: usize,
}

impl std::fmt::Display for SoughtSkills {
    /// "the prompt asks for a jump or a run: 1662 consistent candidates do one, only they were
    /// scored".
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "the prompt asks for a {}: ", self.families.join(" or a "))?;
        match self.candidates {
            0 => write!(f, "no consistent candidate does it, so every one was scored and the motion is a stand-in"),
            n => write!(f, "{n} consistent candidates do it, only they were scored"),
        }
    }
}

/// The task as retrieval sees it: the compiled `C_R`, its most difficult constraint and the
/// prompt that the semantic check reads.
#[derive(Clone, Copy)]
pub struct RetrievalQuery<'a> {
    /// `C_R`, compiled for the task's frame count.
    pub program: &'a CompiledProgram,
    /// Id of `c_D` (weight 1 in the score).
    pub most_difficult: &'a str,
    /// The task's text prompt.
    pub prompt: &'a str,
    /// Whether the task counts actions (its candidates must carry the prompt's action verb).
    pub counting: bool,
    /// The sentence encoder that caption similarity reads with (the prior's); `None` ranks by
    /// `C_R` alone and reports no similarity.
    pub encoder: Option<&'a dyn TextEncoder>,
}

/// Eqs. 5–6: scores every crop of `database` that passes the semantic check on `query` and
/// returns the best `top_k` under the threshold, one per take, best first, with their features
/// on `device`.
pub fn retrieve(
    database: &RetrievalDatabase,
    query: &RetrievalQuery<'_>,
    config: &RetrievalConfig,
    device: &Device,
) -> Result<RetrievalOutcome, RetrievalError> {
    if !(config.related_weight.is_finite() && config.related_weight >= 0.0) {
        return Err(RetrievalError::Setting(format!("related_weight must be ≥ 0, got {}", config.related_weight)));
    }
    for (name, weight) in
        [("caption_weight", config.caption_weight), ("skill_caption_weight", config.skill_caption_weight)]
    {
        if !(weight.is_finite() && weight >= 0.0) {
            return Err(RetrievalError::Setting(format!("{name} must be ≥ 0, got {weight}")));
        }
    }
    let frames = query.program.frames();
    let crops = database.crops(frames, config)?;
    let heard = Heard::new(query.prompt, query.counting);
    let windows = database.consistent_windows(&heard);
    let kept: Vec<Crop> = crops.iter().filter(|c| database.crop_is_consistent(c, &windows)).copied().collect();
    let missing_actions = heard.actions().iter().copied().filter(|a| !database.actions_done().contains(a)).collect();
    let does_a_skill = |c: &Crop| {
        let (families, turn_deg) = database.crop_skills(c);
        heard.skills().iter().any(|&f| families.contains(f)) && !heard.turns_unasked(turn_deg)
    };
    let skilled: Vec<Crop> = kept.iter().filter(|c| does_a_skill(c)).copied().collect();
    let skills = (!heard.skills().is_empty()).then(|| SoughtSkills {
        families: heard.skills().iter().map(|f| f.name().to_owned()).collect(),
        candidates: skilled.len(),
    });
    let (pool, caption_weight) = match skilled.is_empty() {
        true => (&kept, config.caption_weight),
        false => (&skilled, config.skill_caption_weight),
    };
    // Rank every candidate on the proxy (joint centres, 5 Hz), then score the best exactly;
    // counts by their soft form throughout, a ranking of near misses rather than a judgement.
    let program = query.program.soft_counts();
    let proxy = program.joints_only().thinned(config.proxy_frame_step, device)?;
    let mut ranked = score(database, &proxy, pool, query.most_difficult, config, device)?;
    ranked.sort_by(|a, b| a.total.total_cmp(&b.total));
    let shortlist: Vec<Crop> = ranked.iter().take(config.exact_shortlist.max(config.top_k)).map(|s| s.crop).collect();
    let mut scored = score(database, &program, &shortlist, query.most_difficult, config, device)?;
    scored.retain(|s| s.total.is_finite() && config.threshold.is_none_or(|t| s.total <= t));
    if caption_weight == 0.0 {
        // Ranked by C_R alone: only the kept few need their similarity, for the report.
        scored.sort_by(|a, b| a.total.total_cmp(&b.total));
        scored = one_per_take(database, scored, config.top_k, |s| &s.crop);
    }
    let similarity = match query.encoder {
        Some(encoder) => caption_similarities(database, encoder, query.prompt, &scored, device)?,
        None => vec![None; scored.len()],
    };
    let rank = |(s, sim): &(Scored, Option<f64>)| s.total + caption_weight * (1.0 - sim.unwrap_or(1.0)).max(0.0);
    let mut ranked: Vec<(Scored, Option<f64>)> = scored.into_iter().zip(similarity).collect();
    ranked.sort_by(|a, b| rank(a).total_cmp(&rank(b)));
    let ranked = one_per_take(database, ranked, config.top_k, |(s, _)| &s.crop);
    let ids: Vec<&str> = query.program.ids().collect();
    let retrieved = ranked
        .into_iter()
        .map(|(s, caption_similarity)| {
            Ok(Retrieved {
                source: database.source(&s.crop, frames),
                score: s.total,
                per_constraint: ids.iter().map(|id| (*id).to_owned()).zip(s.errors).collect(),
                caption_similarity,
                features: database.features(&s.crop, frames, device)?,
            })
        })
        .collect::<Result<_, RetrievalError>>()?;
    Ok(RetrievalOutcome { retrieved, candidates: crops.len(), consistent: kept.len(), missing_actions, skills })
}

/// The first `top_k` of `ranked` (best first) whose takes differ: a take's neighbouring crops
/// and its mirror image fit `C_R` alike and start the same motion, so only its best one counts.
fn one_per_take<T>(database: &RetrievalDatabase, ranked: Vec<T>, top_k: usize, crop: impl Fn(&T) -> &Crop) -> Vec<T> {
    let mut takes: Vec<&str> = Vec::with_capacity(top_k);
    let mut kept = Vec::with_capacity(top_k);
    for item in ranked {
        if kept.len() == top_k {
            break;
        }
        let take = database.take(crop(&item));
        if !takes.contains(&take) {
            takes.push(take);
            kept.push(item);
        }
    }
    kept
}

/// The cosine similarity of each candidate's sentence ([`RetrievalDatabase::sentence`]) to the
/// prompt's, each distinct sentence encoded once; `None` for a candidate without one.
fn caption_similarities(
    database: &RetrievalDatabase,
    encoder: &dyn TextEncoder,
    prompt: &str,
    scored: &[Scored],
    device: &Device,
) -> Result<Vec<Option<f64>>, RetrievalError> {
    let sentences: Vec<&str> = scored.iter().map(|s| database.sentence(&s.crop)).collect();
    let mut distinct: Vec<&str> = sentences.iter().copied().filter(|t| !t.is_empty()).collect();
    distinct.sort_unstable();
    distinct.dedup();
    if distinct.is_empty() {
        return Ok(vec![None; scored.len()]);
    }
    let unit = |v: Tensor| -> candle_core::Result<Tensor> { v.broadcast_div(&v.sqr()?.sum_keepdim(1)?.sqrt()?) };
    let prompt = unit(encoder.encode(&[prompt], device)?.to_dtype(DType::F32)?)?;
    let vectors = unit(encoder.encode(&distinct, device)?.to_dtype(DType::F32)?)?;
    let cosine = vectors.matmul(&prompt.t()?)?.flatten_all()?.to_dtype(DType::F64)?.to_vec1::<f64>()?;
    Ok(sentences.iter().map(|t| distinct.binary_search(t).ok().map(|k| cosine[k]).filter(|c| c.is_finite())).collect())
}

/// A candidate's score: `Σ w_i·E_i` (infinite for a crop that cannot be placed) and `E_i` in
/// program order.
struct Scored {
    crop: Crop,
    total: f64,
    errors: Vec<f64>,
}

/// The scores of `crops` under `program`, in batches spread over the rayon pool: each batch's
/// joints placed as the generator places a motion (a crop right after its mirror twin is the
/// twin's placement reflected), then evaluated. The batches are small enough that candle runs
/// their element-wise ops inline on the worker that owns the batch.
fn score(
    database: &RetrievalDatabase,
    program: &CompiledProgram,
    crops: &[Crop],
    most_difficult: &str,
    config: &RetrievalConfig,
    device: &Device,
) -> Result<Vec<Scored>, RetrievalError> {
    let frames = program.frames();
    let size = frames * 3 * NUM_JOINTS;
    let weights: Vec<f64> =
        program.ids().map(|id| if id == most_difficult { 1.0 } else { config.related_weight }).collect();
    let batches = crops
        .par_chunks(config.batch.max(1))
        .map(|chunk| {
            let mut joints = Vec::with_capacity(chunk.len() * size);
            let mut placed = vec![false; chunk.len()];
            for (k, crop) in chunk.iter().enumerate() {
                placed[k] = match k.checked_sub(1) {
                    Some(twin) if placed[twin] && chunk[twin].is_mirror_of(crop) => {
                        joints.extend_from_within(twin * size..k * size);
                        database.reflect(&mut joints[k * size..]);
                        true
                    }
                    _ => database.place(crop, frames, &mut joints),
                };
            }
            let joints = Tensor::from_vec(joints, (chunk.len(), frames, NUM_JOINTS, 3), device)?;
            let evaluation = program.evaluate(&joints, None)?;
            let errors = evaluation
                .per_constraint
                .iter()
                .map(|(_, e)| e.to_dtype(DType::F64)?.to_vec1::<f64>())
                .collect::<candle_core::Result<Vec<_>>>()?;
            let scored = chunk.iter().zip(placed).enumerate().map(|(row, (&crop, placed))| {
                let errors: Vec<f64> = errors.iter().map(|e| e[row]).collect();
                let total = match placed {
                    true => errors.iter().zip(&weights).map(|(e, w)| w * e).sum(),
                    false => f64::INFINITY,
                };
                Scored { crop, total, errors }
            });
            Ok(scored.collect::<Vec<_>>())
        })
        .collect::<Result<Vec<_>, RetrievalError>>()?;
    Ok(batches.into_iter().flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::super::candidates::tests::tiny_corpus;
    use super::*;
    use crate::corpus::Split;
    use crate::generation::rgdno::error::RgDnoError;
    use crate::motion::test_support::walking_poses;
    use crate::program::TaskProgram;
    use crate::representation::{extract_features, recover_from_ric, FEATURE_DIM};
    use crate::skeleton::Pose;
    use crate::testing::pinned_program_json;

    const FRAMES: usize = 40;

    /// `C_R` pinning the pelvis and the wrists, at four keyframes, where the feature path puts
    /// `poses` (`FRAMES + 1` of them): the joints the generator would start from.
    fn pins(poses: &[Pose]) -> CompiledProgram {
        let features: Vec<f32> = extract_features(poses).unwrap().features.into_iter().flatten().collect();
        let features = Tensor::from_vec(features, (1, FRAMES, FEATURE_DIM), &Device::Cpu).unwrap();
        let joints = recover_from_ric(&features).unwrap().squeeze(0).unwrap();
        let text = pinned_program_json(&joints, "a person walks", false).unwrap();
        CompiledProgram::compile(&TaskProgram::from_json_validated(&text).unwrap(), &Device::Cpu).unwrap()
    }

    fn query<'a>(program: &'a CompiledProgram, prompt: &'a str) -> RetrievalQuery<'a> {
        RetrievalQuery { program, most_difficult: "c1", prompt, counting: false, encoder: None }
    }

    #[test]
    fn the_crop_that_the_pins_were_made_from_wins() {
        let turn = walking_poses(200, 0.8);
        let corpus = tiny_corpus(vec![
            ("straight", Split::Train, walking_poses(200, 0.0)),
            ("turn", Split::Train, turn.clone()),
        ]);
        let database = RetrievalDatabase::from_corpus(&corpus).unwrap();
        // Frames 40..81 of the turning walk, played as captured.
        let program = pins(&turn[40..=40 + FRAMES]);
        let config = RetrievalConfig { related_weight: 1.0, ..RetrievalConfig::default() };
        let found = retrieve(&database, &query(&program, "a person walks"), &config, &Device::Cpu).unwrap();
        let best = &found.retrieved[0];
        assert_eq!((best.source.clip.as_str(), best.source.start, best.source.frames), ("turn", 40, FRAMES + 1));
        assert!(!best.source.mirrored && best.score < 1e-6, "{} {}", best.source, best.score);
        assert_eq!(best.features.dims(), [FRAMES, FEATURE_DIM]);
        // One crop per take, mirror images included: the two clips, best first.
        let takes: Vec<&str> = found.retrieved.iter().map(|r| r.source.clip.as_str()).collect();
        assert_eq!(takes, ["turn", "straight"]);
        assert!(found.retrieved.windows(2).all(|w| w[0].score <= w[1].score));
        assert_eq!(found.candidates, found.consistent);
        // The turning walk turns left: a prompt that turns right drops it, not its mirror.
        let right = retrieve(&database, &query(&program, "a person walks and turns right"), &config, &Device::Cpu);
        let right = right.unwrap();
        assert!(right.consistent < right.candidates);
        assert!(
            right.retrieved.iter().all(|r| r.source.clip != "turn" || r.source.mirrored),
            "{}",
            right.retrieved[0].source
        );
        // A threshold below every score keeps nothing.
        let strict = RetrievalConfig { threshold: Some(-1.0), ..config };
        assert!(retrieve(&database, &query(&program, "a person walks"), &strict, &Device::Cpu)
            .unwrap()
            .retrieved
            .is_empty());
    }

    /// Hears one thing: whether a text speaks of a box (`[1, 0]`) or not (`[0, 1]`).
    struct BoxEars;

    impl TextEncoder for BoxEars {
        fn dim(&self) -> usize {
            2
        }

        fn encode(&self, prompts: &[&str], device: &Device) -> candle_core::Result<Tensor> {
            let rows: Vec<f32> =
                prompts.iter().flat_map(|p| if p.contains("box") { [1.0, 0.0] } else { [0.0, 1.0] }).collect();
            Tensor::from_vec(rows, (prompts.len(), 2), device)
        }
    }

    /// Of two walks that fit `C_R` almost equally, the one whose take carries a box wins for a
    /// prompt about a box; a box-carrying take that fits badly does not, and with a caption
    /// weight of 0 the ranking is `C_R`'s alone.
    #[test]
    fn caption_similarity_ranks_near_equal_fits_by_what_the_take_does() {
        let plain = walking_poses(200, 0.0);
        let mut boxed = plain.clone();
        for pose in &mut boxed {
            for wrist in [crate::skeleton::Joint::LeftWrist, crate::skeleton::Joint::RightWrist] {
                pose[wrist.index()].y += 0.02;
            }
        }
        let mut corpus = tiny_corpus(vec![
            ("plain", Split::Train, plain.clone()),
            ("boxed", Split::Train, boxed),
            ("turning box", Split::Train, walking_poses(200, 0.8)),
        ]);
        for (k, window) in corpus.windows.iter_mut().enumerate() {
            if window.clip > 0 {
                window.captions = crate::corpus::caption::captions(&window.tags, "walk carrying a box", k);
            }
        }
        let database = RetrievalDatabase::from_corpus(&corpus).unwrap();
        let program = pins(&plain[40..=40 + FRAMES]);
        // "Holding" names no skill ("carries" would score only the takes that carry).
        let prompt = "a person walks holding a box";
        let config = RetrievalConfig { related_weight: 1.0, caption_weight: 0.05, ..RetrievalConfig::default() };
        let heard = RetrievalQuery { encoder: Some(&BoxEars), ..query(&program, prompt) };
        let found = retrieve(&database, &heard, &config, &Device::Cpu).unwrap();
        let best = &found.retrieved[0];
        assert_eq!((best.source.clip.as_str(), best.caption_similarity), ("boxed", Some(1.0)), "{}", best.source);
        assert!(best.score > 1e-6 && best.score < config.caption_weight, "{}", best.score);
        let plain_fit = found.retrieved.iter().find(|r| r.source.clip == "plain").unwrap();
        assert_eq!(plain_fit.caption_similarity, Some(0.0));
        assert!(plain_fit.score < best.score);
        // The box-carrying take that fits badly ranks last of the three takes, whatever its words.
        let takes: Vec<&str> = found.retrieved.iter().map(|r| r.source.clip.as_str()).collect();
        assert_eq!(takes, ["boxed", "plain", "turning box"]);
        let by_fit = RetrievalConfig { caption_weight: 0.0, ..config.clone() };
        let found = retrieve(&database, &heard, &by_fit, &Device::Cpu).unwrap();
        assert_eq!(found.retrieved[0].source.clip, "plain");
        let negative = RetrievalConfig { caption_weight: -1.0, ..config };
        assert!(retrieve(&database, &heard, &negative, &Device::Cpu).is_err());
    }

    /// A prompt that asks for a carry scores only the takes that carry, even against a plain
    /// walk that fits `C_R` exactly; a prompt that asks for a walk, or for a skill that no take
    /// does, scores every consistent crop and says so.
    #[test]
    fn a_prompt_that_asks_for_a_skill_retrieves_a_take_that_does_it() {
        let plain = walking_poses(200, 0.0);
        let mut corpus =
            tiny_corpus(vec![("plain", Split::Train, plain.clone()), ("boxed", Split::Train, walking_poses(200, 0.3))]);
        corpus.clips[1].description = "walk carrying a box".into();
        let database = RetrievalDatabase::from_corpus(&corpus).unwrap();
        let program = pins(&plain[40..=40 + FRAMES]);
        let config = RetrievalConfig { related_weight: 1.0, ..RetrievalConfig::default() };
        let found = |prompt| retrieve(&database, &query(&program, prompt), &config, &Device::Cpu).unwrap();
        let carry = found("a person carries a box forward");
        let takes: Vec<&str> = carry.retrieved.iter().map(|r| r.source.clip.as_str()).collect();
        assert_eq!(takes, ["boxed"]);
        let skills = carry.skills.as_ref().unwrap();
        assert_eq!(skills.families, ["carry"]);
        assert!(skills.candidates > 0 && skills.candidates < carry.consistent, "{skills:?}");
        assert!(skills.to_string().ends_with("consistent candidates do it, only they were scored"), "{skills}");
        let walk = found("a person walks forward");
        assert!(walk.skills.is_none());
        assert_eq!(walk.retrieved[0].source.clip, "plain");
        let sideways = found("a person side-steps to the left");
        assert_eq!(sideways.skills.as_ref().map(|s| s.candidates), Some(0));
        assert!(sideways.skills.unwrap().to_string().contains("no consistent candidate does it"));
        assert_eq!(sideways.retrieved[0].source.clip, "plain");
        let negative = RetrievalConfig { skill_caption_weight: -0.1, ..config.clone() };
        assert!(retrieve(&database, &query(&program, "a person carries a box"), &negative, &Device::Cpu).is_err());
    }

    #[test]
    fn a_prompt_whose_action_no_window_does_retrieves_nothing_and_says_which() {
        let walk = walking_poses(200, 0.0);
        let database =
            RetrievalDatabase::from_corpus(&tiny_corpus(vec![("walk", Split::Train, walk.clone())])).unwrap();
        let program = pins(&walk[40..=40 + FRAMES]);
        let config = RetrievalConfig::default();
        let crawl = retrieve(&database, &query(&program, "a person crawls forward"), &config, &Device::Cpu).unwrap();
        assert!(crawl.retrieved.is_empty() && crawl.consistent == 0, "{} consistent", crawl.consistent);
        assert_eq!(crawl.missing_actions, [Action::Crawl]);
        let error = RgDnoError::NothingRetrieved { missing: crawl.missing_actions };
        assert!(error.to_string().ends_with("(no window of the database crawls)"), "{error}");
        let walked = retrieve(&database, &query(&program, "a person walks"), &config, &Device::Cpu).unwrap();
        assert!(walked.missing_actions.is_empty() && !walked.retrieved.is_empty());
    }

    #[test]
    fn a_held_out_clip_is_never_retrieved_however_well_it_fits() {
        let held = walking_poses(200, 1.2);
        let program = pins(&held[20..=20 + FRAMES]);
        let config = RetrievalConfig { related_weight: 1.0, top_k: 64, ..RetrievalConfig::default() };
        let clips = |split| vec![("straight", Split::Train, walking_poses(200, 0.0)), ("held", split, held.clone())];
        for split in [Split::Validation, Split::Test] {
            let database = RetrievalDatabase::from_corpus(&tiny_corpus(clips(split))).unwrap();
            let found = retrieve(&database, &query(&program, "a person walks"), &config, &Device::Cpu).unwrap();
            assert!(found.retrieved.iter().all(|r| r.source.clip == "straight") && found.retrieved[0].score > 0.01);
        }
        // In the train split it would have won.
        let database = RetrievalDatabase::from_corpus(&tiny_corpus(clips(Split::Train))).unwrap();
        let found = retrieve(&database, &query(&program, "a person walks"), &config, &Device::Cpu).unwrap();
        assert_eq!(found.retrieved[0].source.clip, "held");
    }
}
