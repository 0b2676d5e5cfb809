//! The field's text–motion metrics on our own evaluator (issue 40, item 3), in the protocol of
//! Guo et al. 2022: held-out (test-split) windows of real capture with one of their captions
//! each; the prior makes one motion per caption; both sets, and as many train-split windows, go
//! through the same decode and into the evaluator ([`crate::evaluator`]).
//!
//! - **R-precision** (top 1, 2, 3 of a pool of 32): for each motion, its caption and 31 others
//!   drawn from the set are ranked by distance in the evaluator's space. The samples and the
//!   held-out capture are ranked against the same captions with the same pools, so their ratio
//!   is the claim; a published value is on another evaluator and other data.
//! - **FID**: the Fréchet distance of a set's embeddings to the held-out capture's. The train
//!   split's distance is the scale a model is read against (real capture of other subjects).
//!
//! **The same decode.** Every motion, real or sampled, is features → joints through the prior's
//! root decode and rest skeleton → features again; samples are one frame shorter than a window's
//! poses so that both end with the same number of feature frames.

use candle_core::{Device, Tensor};
use rand::rngs::StdRng;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use serde::Serialize;

use super::sampling::Denoising;
use crate::cleanup::{foot_lock, FootLockConfig};
use crate::corpus::{Corpus, Split, WINDOW_FRAMES};
use crate::diffusion::Guidance;
use crate::evaluator::{frechet_distance, r_precision, Evaluator};
use crate::motion::tensor_to_poses;
use crate::prior::{Prior, PriorError};
use crate::representation::{extract_features, FEATURE_DIM};
use crate::skeleton::Pose;
use crate::text::{ConditionEncoder, TextEncoder};

/// Motions embedded or sampled per call.
const CHUNK: usize = 32;

/// Settings of [`text_motion_report`].
#[derive(Debug, Clone)]
pub struct TextMotionConfig {
    /// Held-out windows (and samples, and train-split windows) compared (default 256).
    pub pairs: usize,
    /// Captions per R-precision pool (default 32, the field's).
    pub pool: usize,
    /// How the samples are drawn; its seed also chooses the windows, captions and pools.
    pub denoising: Denoising,
}

impl Default for TextMotionConfig {
    fn default() -> Self {
        Self { pairs: 256, pool: 32, denoising: Denoising::default() }
    }
}

/// One set of motions on the text–motion metrics.
#[derive(Debug, Clone, Serialize)]
pub struct TextMotionRow {
    /// What the motions are.
    pub motions: &'static str,
    /// R-precision top 1, 2 and 3 against the set's captions.
    pub r_precision: [f64; 3],
    /// Fréchet distance of the set's embeddings to the held-out capture's (`None` for the
    /// held-out set itself).
    pub fid: Option<f64>,
}

/// The text–motion metrics of a prior: held-out capture, train-split capture, samples and
/// cleaned samples, in that order.
#[derive(Debug, Clone, Serialize)]
pub struct TextMotionReport {
    /// Motions per set.
    pub pairs: usize,
    /// Captions per R-precision pool.
    pub pool: usize,
    /// The rows.
    pub rows: Vec<TextMotionRow>,
}

impl TextMotionReport {
    /// The row of `motions`.
    pub fn row(&self, motions: &str) -> Option<&TextMotionRow> {
        self.rows.iter().find(|r| r.motions == motions)
    }
}

/// The held-out capture's row name.
pub const HELD_OUT: &str = "held-out capture";
/// The train split's row name.
pub const TRAIN: &str = "train-split capture";
/// The samples' row name.
pub const SAMPLES: &str = "samples";
/// The cleaned samples' row name.
pub const CLEANED: &str = "samples after the clean-up";

/// Runs the metrics: `sentences` encodes captions for the evaluator's text side (MiniLM, which
/// it was trained on); the prior hears them through its own encoder. `progress(done, total)`
/// follows the sampling.
pub fn text_motion_report(
    prior: &Prior,
    evaluator: &Evaluator,
    sentences: &ConditionEncoder,
    corpus: &Corpus,
    config: &TextMotionConfig,
    device: &Device,
    mut progress: impl FnMut(usize, usize),
) -> Result<TextMotionReport, PriorError> {
    let fail = |message: String| PriorError::Compute { what: "the text-motion metrics", message };
    let tensor = |e: candle_core::Error| fail(e.to_string());
    if config.pairs < config.pool || config.pool == 0 {
        return Err(fail(format!("{} pairs cannot fill pools of {}", config.pairs, config.pool)));
    }
    let Denoising { ddim_steps, guidance, seed } = config.denoising;
    let mut rng = StdRng::seed_from_u64(seed);
    let held_out = windows(corpus, Split::Test, config.pairs, &mut rng);
    let train = windows(corpus, Split::Train, config.pairs, &mut rng);
    if held_out.len() < config.pairs || train.len() < config.pairs {
        return Err(fail(format!(
            "{} held-out and {} train-split windows; {} of each are needed",
            held_out.len(),
            train.len(),
            config.pairs
        )));
    }
    let captions: Vec<&str> = held_out.iter().map(|(_, c)| c.as_str()).collect();
    let embed_text = |captions: &[&str]| -> candle_core::Result<Tensor> {
        let rows = captions
            .chunks(CHUNK)
            .map(|chunk| evaluator.embed_text(&sentences.encode(chunk, device)?))
            .collect::<candle_core::Result<Vec<_>>>()?;
        Tensor::cat(&rows, 0)
    };
    let decode_real = |poses: &[Pose]| -> Result<Vec<Pose>, PriorError> {
        let features = features_of(&[poses.to_vec()], device).map_err(fail)?;
        let decoded = prior.root_decode.apply(&features).map_err(tensor)?;
        Ok(tensor_to_poses(&prior.joints_of(&decoded).map_err(tensor)?).map_err(tensor)?.remove(0))
    };
    let held_out_motions: Vec<Vec<Pose>> = held_out.iter().map(|(p, _)| decode_real(p)).collect::<Result<_, _>>()?;
    let train_motions: Vec<Vec<Pose>> = train.iter().map(|(p, _)| decode_real(p)).collect::<Result<_, _>>()?;

    let mut samples = Vec::with_capacity(config.pairs);
    for (k, chunk) in captions.chunks(CHUNK).enumerate() {
        progress(samples.len(), config.pairs);
        let text = prior.caption_conditions(chunk, device).map_err(tensor)?;
        let guidance = Guidance { scale: guidance };
        let x = prior.sample_conditioned(&text, WINDOW_FRAMES - 1, seed + k as u64, ddim_steps, guidance)?;
        samples.extend(tensor_to_poses(&prior.to_joints(&x).map_err(tensor)?).map_err(tensor)?);
    }
    progress(samples.len(), config.pairs);
    let cleaned: Vec<Vec<Pose>> = samples
        .iter()
        .map(|m| foot_lock(m, None, &FootLockConfig::default()).map(|c| c.poses))
        .collect::<Result<_, _>>()
        .map_err(|e| fail(e.to_string()))?;

    let held_out_text = embed_text(&captions).map_err(tensor)?;
    let train_captions: Vec<&str> = train.iter().map(|(_, c)| c.as_str()).collect();
    let train_text = embed_text(&train_captions).map_err(tensor)?;
    let reference = embed_motions(evaluator, &held_out_motions, device)?;
    let mut rows = Vec::new();
    for (name, motions, text) in [
        (HELD_OUT, &held_out_motions, &held_out_text),
        (TRAIN, &train_motions, &train_text),
        (SAMPLES, &samples, &held_out_text),
        (CLEANED, &cleaned, &held_out_text),
    ] {
        let embedded = if name == HELD_OUT { reference.clone() } else { embed_motions(evaluator, motions, device)? };
        let r = r_precision(&embedded, text, config.pool, &[1, 2, 3], seed).map_err(tensor)?;
        let fid = (name != HELD_OUT).then(|| frechet_distance(&embedded, &reference)).transpose().map_err(tensor)?;
        rows.push(TextMotionRow { motions: name, r_precision: [r[0], r[1], r[2]], fid });
    }
    Ok(TextMotionReport { pairs: config.pairs, pool: config.pool, rows })
}

/// `count` full-length windows of `split` (seeded choice) with one of their captions each.
fn windows(corpus: &Corpus, split: Split, count: usize, rng: &mut StdRng) -> Vec<(Vec<Pose>, String)> {
    let mut chosen: Vec<_> = corpus
        .windows
        .iter()
        .filter(|w| corpus.clips[w.clip].split == split && w.frames == WINDOW_FRAMES && !w.captions.is_empty())
        .collect();
    chosen.shuffle(rng);
    chosen
        .into_iter()
        .take(count)
        .map(|w| (corpus.window_joints(w).to_vec(), w.captions[rng.random_range(0..w.captions.len())].clone()))
        .collect()
}

/// Raw features `[n, frames − 1, 263]` of motions of one length.
fn features_of(motions: &[Vec<Pose>], device: &Device) -> Result<Tensor, String> {
    let mut flat = Vec::new();
    let mut frames = None;
    for poses in motions {
        let extracted = extract_features(poses).map_err(|e| e.to_string())?;
        if *frames.get_or_insert(extracted.features.len()) != extracted.features.len() {
            return Err("motions of different lengths".into());
        }
        flat.extend(extracted.features.into_iter().flatten());
    }
    Tensor::from_vec(flat, (motions.len(), frames.unwrap_or(0), FEATURE_DIM), device).map_err(|e| e.to_string())
}

/// Unit evaluator embeddings `[n, e]` of motions of one length.
fn embed_motions(evaluator: &Evaluator, motions: &[Vec<Pose>], device: &Device) -> Result<Tensor, PriorError> {
    let fail = |message: String| PriorError::Compute { what: "the text-motion metrics", message };
    let rows = motions
        .chunks(CHUNK)
        .map(|chunk| {
            let features = features_of(chunk, device).map_err(fail)?;
            let x = evaluator.mean_std().normalize(&features).map_err(|e| fail(e.to_string()))?;
            evaluator.embed_motion(&x).map_err(|e| fail(e.to_string()))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Tensor::cat(&rows, 0).map_err(|e| fail(e.to_string()))
}

#[cfg(test)]
mod tests {
    use candle_nn::VarMap;
    use glam::DVec3;

    use super::*;
    use crate::evaluator::EvaluatorConfig;
    use crate::quality::test_fixtures::{corpus_of, moving};
    use crate::representation::MeanStd;
    use crate::text::MINILM_NAME;

    /// Four glides in each split, the train split's the held-out split's twins: the report has
    /// its four rows in order, the train split's FID to held-out is 0 (same embeddings), the
    /// samples' is not, every R-precision is a share; asking for more pairs than windows is an
    /// error that says how many there are.
    #[test]
    fn the_report_ranks_every_set_against_the_held_out_captions() {
        let glides: Vec<(Vec<Pose>, &str)> = [
            (DVec3::new(0.0, 0.0, 1.2), "a person walks forward"),
            (DVec3::new(0.9, 0.0, 0.0), "a person steps sideways to the left"),
            (DVec3::new(0.0, 0.0, -0.8), "a person walks backwards"),
            (DVec3::ZERO, "a person stands still"),
        ]
        .into_iter()
        .map(|(v, caption)| (moving(WINDOW_FRAMES, v, 0.0), caption))
        .collect();
        let corpus = corpus_of(
            [Split::Train, Split::Test]
                .into_iter()
                .flat_map(|split| glides.iter().map(move |(poses, caption)| (split, poses.clone(), *caption)))
                .collect(),
        );
        let device = Device::Cpu;
        let prior = Prior::tiny(&["a person walks forward", "a person stands still"]);
        let mean_std = MeanStd::from_vecs(vec![0.0; FEATURE_DIM], vec![1.0; FEATURE_DIM], &device).unwrap();
        let evaluator =
            Evaluator::init_seeded(EvaluatorConfig::default(), mean_std, &VarMap::new(), &device, 3).unwrap();
        let text_models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/text");
        let sentences = ConditionEncoder::sentence(MINILM_NAME, &text_models, &device).unwrap();
        let config =
            TextMotionConfig { pairs: 4, pool: 4, denoising: Denoising { ddim_steps: 2, ..Denoising::default() } };
        let mut calls = 0;
        let report =
            text_motion_report(&prior, &evaluator, &sentences, &corpus, &config, &device, |_, _| calls += 1).unwrap();
        assert!(calls >= 2, "progress before and after sampling");
        let names: Vec<&str> = report.rows.iter().map(|r| r.motions).collect();
        assert_eq!(names, [HELD_OUT, TRAIN, SAMPLES, CLEANED]);
        assert!(report.row(HELD_OUT).unwrap().fid.is_none());
        let train_fid = report.row(TRAIN).unwrap().fid.unwrap();
        assert!(train_fid.abs() < 1e-3, "twins: {train_fid}");
        assert!(report.row(SAMPLES).unwrap().fid.unwrap() > 1e-3);
        for row in &report.rows {
            let [r1, r2, r3] = row.r_precision;
            assert!((0.0..=1.0).contains(&r1) && r1 <= r2 && r2 <= r3 && r3 <= 1.0, "{row:?}");
        }
        let config = TextMotionConfig { pairs: 5, ..config };
        let err = text_motion_report(&prior, &evaluator, &sentences, &corpus, &config, &device, |_, _| {})
            .unwrap_err()
            .to_string();
        assert!(err.contains("4 held-out and 4 train-split windows; 5 of each"), "{err}");
    }
}
