//! Quality per skill family against held-out capture (issue 40, item 4): for each
//! [`Family`], samples of its prompts beside the corpus's held-out (test-split) windows that do
//! the same thing ([`Family::held_out`]), decoded the same way, on the motion metrics
//! ([`MetricMeans`]) and on the family's action detector ([`Family::detect`]). The test split's
//! subjects were never trained on.

use candle_core::{DType, Device, Tensor};
use serde::Serialize;

use super::distances::{descriptors, mean_pairwise, nearest_distances};
use super::sampling::ReportSampling;
use crate::cleanup::{foot_lock, FootLockConfig};
use crate::corpus::family::Family;
use crate::corpus::{Corpus, CorpusWindow, Split};
use crate::metrics::MetricMeans;
use crate::motion::tensor_to_poses;
use crate::prior::{Prior, PriorError};
use crate::representation::{extract_features, FEATURE_DIM, RIC};
use crate::skeleton::Pose;

/// Share of motions passing a detector (`None` without motions).
pub(super) fn detected_share(family: Family, motions: &[Vec<Pose>]) -> Option<f64> {
    share_passing(motions.iter().map(|m| family.detect(m)))
}

/// Share of `true` among the detector outcomes (`None`: no motion).
fn share_passing(outcomes: impl Iterator<Item = bool>) -> Option<f64> {
    let hits: Vec<bool> = outcomes.collect();
    (!hits.is_empty()).then(|| hits.iter().filter(|h| **h).count() as f64 / hits.len() as f64)
}

/// Settings of [`family_report`].
#[derive(Debug, Clone)]
pub struct FamilyConfig {
    /// The samples per family, split evenly between its prompts; family i's noise from
    /// seed + 100·i (+ the prompt's index).
    pub sampling: ReportSampling,
    /// Held-out windows per family, at most (default 64), the first in corpus order.
    pub max_held_out: usize,
    /// Only these families (all when empty).
    pub families: Vec<Family>,
}

impl Default for FamilyConfig {
    fn default() -> Self {
        Self { sampling: ReportSampling::default(), max_held_out: 64, families: Vec::new() }
    }
}

/// One family's row of the report.
#[derive(Debug, Clone, Serialize)]
pub struct FamilyQuality {
    /// The family.
    pub family: Family,
    /// Its prompts.
    pub prompts: Vec<String>,
    /// The samples as the network made them.
    pub samples: MetricMeans,
    /// The samples after the foot clean-up (what `mogen sample` writes).
    pub cleaned: MetricMeans,
    /// The family's held-out windows, through the same decode (`count` 0: the test split has
    /// none).
    pub held_out: MetricMeans,
    /// Shares passing the detector: samples, cleaned samples, held-out windows.
    pub detected: [Option<f64>; 3],
    /// Share of each prompt's samples (the network's output) passing the detector, in
    /// `prompts` order: the caption-like prompt, then the paraphrase in words the captions do
    /// not use.
    pub detected_per_prompt: Vec<Option<f64>>,
    /// The prompt (an index into `prompts`) each sample was drawn for, in sample order.
    pub sample_prompts: Vec<usize>,
    /// Mean over samples of the RMS joint distance (root-relative, heading-free, over their
    /// first frames) to the nearest training-split window, m. Near 0 would mean copying.
    pub nearest_training_m: f64,
    /// The same distance for the held-out windows: how far unseen real motion lies from the
    /// training data, the scale the samples' figure is read against, m.
    pub held_out_nearest_training_m: f64,
    /// Mean RMS joint distance between the family's samples, m: how different seeds are.
    pub sample_diversity_m: f64,
}

/// `map` of the raw features `[frames, 263]` (the poses through feature extraction) of
/// `windows` (`map` giving `None` drops a window).
fn window_features<'a>(
    corpus: &Corpus,
    windows: impl Iterator<Item = &'a CorpusWindow>,
    map: impl Fn(Tensor) -> candle_core::Result<Option<Tensor>>,
    device: &Device,
) -> candle_core::Result<Vec<Tensor>> {
    let mut out = Vec::new();
    for window in windows {
        let Ok(extracted) = extract_features(corpus.window_joints(window)) else { continue };
        let n = extracted.features.len();
        let flat: Vec<f32> = extracted.features.into_iter().flatten().collect();
        out.extend(map(Tensor::from_vec(flat, (n, FEATURE_DIM), device)?)?);
    }
    Ok(out)
}

/// Descriptors ([`descriptors`]) `[n, frames·63]` of the first `frames` frames of each motion at
/// least that long.
fn descriptors_of(features: &[Tensor], frames: usize, device: &Device) -> candle_core::Result<Tensor> {
    let crops: Vec<Tensor> =
        features.iter().filter(|f| f.dims()[0] >= frames).map(|f| f.narrow(0, 0, frames)).collect::<Result<_, _>>()?;
    if crops.is_empty() {
        return Tensor::zeros((0, frames * RIC.len()), DType::F32, device);
    }
    descriptors(&crops)
}

/// Runs the report over the families of `config` (all when empty); `on_family` is called after
/// each with its row and its cleaned samples (for pictures).
pub fn family_report(
    prior: &Prior,
    corpus: &Corpus,
    config: &FamilyConfig,
    device: &Device,
    mut on_family: impl FnMut(&FamilyQuality, &[Vec<Pose>]),
) -> Result<Vec<FamilyQuality>, PriorError> {
    let fail = |message: String| PriorError::Compute { what: "the family report", message };
    let tensor = |e: candle_core::Error| fail(e.to_string());
    let families = if config.families.is_empty() { Family::ALL.to_vec() } else { config.families.clone() };
    // Descriptors compare the first frames that every motion has: samples have
    // `config.frames`, windows one frame fewer than their poses.
    let sampling = config.sampling;
    let compared = sampling.frames.min(crate::corpus::WINDOW_FRAMES - 1);
    // Each training window's descriptor as it is read (its features would take 1 GB at once).
    let descriptor_row = |f: Tensor| -> candle_core::Result<Option<Tensor>> {
        if f.dims()[0] < compared {
            return Ok(None);
        }
        Ok(Some(descriptors_of(&[f], compared, device)?.squeeze(0)?))
    };
    let train_windows = corpus.windows.iter().filter(|w| corpus.clips[w.clip].split == Split::Train);
    let training = window_features(corpus, train_windows, descriptor_row, device).map_err(tensor)?;
    let training = if training.is_empty() {
        Tensor::zeros((0, compared * RIC.len()), DType::F32, device).map_err(tensor)?
    } else {
        Tensor::stack(&training, 0).map_err(tensor)?
    };
    let mut rows = Vec::new();
    for (i, family) in families.into_iter().enumerate() {
        let prompts = family.prompts();
        let mut samples = Vec::new();
        let mut sample_prompts = Vec::new();
        let mut sample_features = Vec::new();
        for (k, prompt) in prompts.iter().enumerate() {
            let batch = sampling.samples / prompts.len() + usize::from(k < sampling.samples % prompts.len());
            if batch == 0 {
                continue;
            }
            let request = sampling.denoising.request(prompt, sampling.frames, batch, 100 * i as u64 + k as u64);
            let x = prior.sample(&request, device)?;
            let raw = prior.to_features(&x).map_err(tensor)?;
            samples.extend(tensor_to_poses(&prior.joints_of(&raw).map_err(tensor)?).map_err(tensor)?);
            sample_prompts.extend(std::iter::repeat_n(k, batch));
            for b in 0..batch {
                sample_features.push(raw.get(b).map_err(tensor)?);
            }
        }
        let cleaned: Vec<Vec<Pose>> = samples
            .iter()
            .map(|m| foot_lock(m, None, &FootLockConfig::default()).map(|c| c.poses))
            .collect::<Result<_, _>>()
            .map_err(|e| fail(e.to_string()))?;
        let held_out_features =
            window_features(corpus, family.held_out(corpus).take(config.max_held_out), |f| Ok(Some(f)), device)
                .map_err(tensor)?;
        let mut held_out = Vec::new();
        for features in &held_out_features {
            // The data's root goes through the same decode as the samples'.
            let decoded = prior.root_decode.apply(&features.unsqueeze(0).map_err(tensor)?).map_err(tensor)?;
            held_out.extend(tensor_to_poses(&prior.joints_of(&decoded).map_err(tensor)?).map_err(tensor)?);
        }
        let sample_descriptors = descriptors_of(&sample_features, compared, device).map_err(tensor)?;
        let held_out_descriptors = descriptors_of(&held_out_features, compared, device).map_err(tensor)?;
        let nearest = |d: &Tensor| -> Result<f64, PriorError> {
            if d.dims()[0] == 0 || training.dims()[0] == 0 {
                return Ok(f64::NAN);
            }
            nearest_distances(d, &training, |_, _| true).map_err(tensor)
        };
        let sample_hits: Vec<bool> = samples.iter().map(|m| family.detect(m)).collect();
        let row = FamilyQuality {
            family,
            prompts: prompts.iter().map(|p| (*p).to_owned()).collect(),
            samples: MetricMeans::of(&samples),
            cleaned: MetricMeans::of(&cleaned),
            held_out: MetricMeans::of(&held_out),
            detected: [
                share_passing(sample_hits.iter().copied()),
                detected_share(family, &cleaned),
                detected_share(family, &held_out),
            ],
            detected_per_prompt: (0..prompts.len())
                .map(|k| {
                    share_passing(sample_hits.iter().zip(&sample_prompts).filter(|(_, &p)| p == k).map(|(h, _)| *h))
                })
                .collect(),
            sample_prompts,
            nearest_training_m: nearest(&sample_descriptors)?,
            held_out_nearest_training_m: nearest(&held_out_descriptors)?,
            sample_diversity_m: mean_pairwise(&sample_descriptors).map_err(tensor)?,
        };
        on_family(&row, &cleaned);
        rows.push(row);
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::corpus::tags::MotionTags;
    use crate::quality::test_fixtures::{corpus_of, moving};
    use crate::quality::Denoising;
    use crate::skeleton::FPS;
    use glam::DVec3;

    #[test]
    fn detectors_measure_direction_height_and_held_hands() {
        let sideways = moving(120, DVec3::new(0.8, 0.0, 0.0), 0.0);
        assert!(Family::Sideways.detect(&sideways));
        let forwards = moving(120, DVec3::new(0.0, 0.0, 1.2), 0.0);
        assert!(!Family::Sideways.detect(&forwards));
        let low = moving(120, DVec3::new(0.0, 0.0, 0.8), 0.25);
        assert!(Family::Sneak.detect(&low));
        assert!(!Family::Sneak.detect(&forwards));
        assert!(!Family::Jump.detect(&forwards), "never off the ground");
        assert!(!Family::Carry.detect(&forwards), "hands at the sides, not ahead of the body");
        assert_eq!(detected_share(Family::Sideways, &[sideways, forwards.clone()]), Some(0.5));
        assert_eq!(detected_share(Family::Carry, &[forwards]), Some(0.0));
        assert_eq!(detected_share(Family::Walk, &[]), None);
    }

    /// The whole report on a tiny random prior: samples of both prompts, the test split's
    /// forward walk as the held-out reference (a training-split walk is not), the detector on
    /// both.
    #[test]
    fn the_report_measures_samples_against_test_split_windows_only() {
        let walk = moving(120, DVec3::new(0.0, 0.0, 1.2), 0.0);
        let tags = MotionTags::measure(&walk);
        assert!(Family::Walk.holds(&walk, &tags, "walk"), "{tags:?}");
        let corpus = corpus_of(vec![(Split::Train, walk.clone(), "walk"), (Split::Test, walk, "walk")]);
        let prior = Prior::tiny(&["a person walks forward"]);
        let config = FamilyConfig {
            sampling: ReportSampling {
                samples: 3,
                frames: 40,
                denoising: Denoising { ddim_steps: 2, ..Denoising::default() },
            },
            families: vec![Family::Walk],
            ..FamilyConfig::default()
        };
        let mut seen = 0;
        let rows = family_report(&prior, &corpus, &config, &Device::Cpu, |row, cleaned| {
            seen += 1;
            assert_eq!(cleaned.len(), row.samples.count);
        })
        .unwrap();
        assert_eq!((seen, rows.len()), (1, 1));
        let row = &rows[0];
        assert_eq!(row.samples.count, 3, "2 + 1 samples of the two prompts");
        assert_eq!(row.sample_prompts, [0, 0, 1]);
        assert_eq!(row.detected_per_prompt.len(), 2);
        for (k, share) in row.detected_per_prompt.iter().enumerate() {
            let n = if k == 0 { 2.0 } else { 1.0 };
            let hits = share.expect("the walk has a detector") * n;
            assert!((hits - hits.round()).abs() < 1e-9, "prompt {k}: {share:?} is not a share of {n} samples");
        }
        assert_eq!(row.held_out.count, 1, "only the test split's window");
        assert_eq!(row.detected[2], Some(1.0), "the held-out walk walks forwards");
        assert!((row.held_out.travel_m - 1.2 * 118.0 / FPS).abs() < 0.05, "decoded travel {}", row.held_out.travel_m);
        // The held-out walk is the training walk's twin: its nearest training window is at 0.
        assert!(row.held_out_nearest_training_m < 1e-4, "{}", row.held_out_nearest_training_m);
        assert!(row.nearest_training_m > 0.0 && row.sample_diversity_m > 0.0);
    }
}
