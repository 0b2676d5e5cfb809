//! Family balance ([`TrainConfig::family_balance`](crate::training::TrainConfig::family_balance)):
//! a corpus's crops drawn by skill family instead of uniformly, so that the rare skills (run,
//! hop, crawl, one-leg balance: under 1 % of the frames each) are seen several times
//! as often. A family is drawn with probability proportional to its frames to a power α, then a
//! middle frame uniformly over its stretches; the crop is centred on that frame and so takes
//! that stretch's captions. The PyTorch mirror (`fixtures/model/gpu/train_mdm.py
//! --family-balance`) draws the same way.

use rand::Rng;

use super::sequence::Sequence;
use crate::corpus::family::Family;

/// The stretches of one skill family (`None`: of no family) and their frames.
#[derive(Debug, Clone)]
pub(super) struct FamilyStretches {
    pub(super) family: Option<Family>,
    /// `(sequence, stretch)` indices.
    pub(super) stretches: Vec<(usize, usize)>,
    pub(super) frames: usize,
}

/// How one batch draws its crops by family
/// ([`TrainingSet::family_draw`](super::training_set::TrainingSet::family_draw)).
pub(super) struct FamilyDraw {
    /// Cumulative probability of each family.
    pub(super) cumulative_weights: Vec<f64>,
    /// Per family, its usable `(sequence, stretch)` indices with their cumulative frames.
    pub(super) pools: Vec<Vec<((usize, usize), usize)>>,
}

impl FamilyDraw {
    /// `(sequence, offset)` of one crop of `frames` frames.
    pub(super) fn crop(&self, sequences: &[Sequence], frames: usize, rng: &mut impl Rng) -> (usize, usize) {
        let u: f64 = rng.random();
        let family = self.cumulative_weights.partition_point(|&c| c <= u).min(self.pools.len() - 1);
        let pool = &self.pools[family];
        let total = pool.last().map_or(1, |(_, c)| *c);
        let middle = rng.random_range(0..total);
        let ((i, k), end) = pool[pool.partition_point(|(_, c)| *c <= middle)];
        let sequence = &sequences[i];
        // The drawn frame counted from the stretch's first frame.
        let frame = sequence.stretches[k].start + sequence.stretch_frames(k) - (end - middle);
        (i, frame.saturating_sub(frames / 2).min(sequence.frames() - frames))
    }
}

impl FamilyStretches {
    /// The stretches of `sequences` grouped by family, in order of first appearance.
    pub(super) fn of(sequences: &[Sequence]) -> Vec<Self> {
        let mut families: Vec<Self> = Vec::new();
        for (i, sequence) in sequences.iter().enumerate() {
            for (k, stretch) in sequence.stretches.iter().enumerate() {
                let pool = match families.iter().position(|f| f.family == stretch.family) {
                    Some(p) => p,
                    None => {
                        families.push(Self { family: stretch.family, stretches: Vec::new(), frames: 0 });
                        families.len() - 1
                    }
                };
                families[pool].stretches.push((i, k));
                families[pool].frames += sequence.stretch_frames(k);
            }
        }
        families
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    use super::super::tests::vocabulary;
    use super::super::training_set::TrainingSet;
    use super::super::Stretch;
    use super::*;
    use crate::representation::{MeanStd, FEATURE_DIM};
    use crate::training::TrainConfig;

    /// One 400-frame sequence: frames 0-299 of no family (caption row 0), 300-399 a run
    /// (row 1).
    fn run_after_a_long_stretch() -> TrainingSet {
        let features = Tensor::zeros((400, FEATURE_DIM), candle_core::DType::F32, &Device::Cpu).unwrap();
        let stretches = vec![
            Stretch { start: 0, rows: vec![0], family: None },
            Stretch { start: 300, rows: vec![1], family: Some(Family::Run) },
        ];
        let text = Tensor::new(&[[1f32, 0.0], [0.0, 1.0]], &Device::Cpu).unwrap();
        let mean_std = MeanStd::from_vecs(vec![0.0; FEATURE_DIM], vec![1.0; FEATURE_DIM], &Device::Cpu).unwrap();
        let sequences = vec![Sequence { features, stretches, group: 0 }];
        TrainingSet::assemble(sequences, text, vocabulary(), mean_std, None, false, 20.0).unwrap()
    }

    /// Share of `batches` batches of 40-frame crops captioned as the run.
    fn run_share(set: &TrainingSet, family_balance: Option<f64>, batches: usize) -> f64 {
        let config =
            TrainConfig { batch_size: 50, min_frames: 40, max_frames: 40, family_balance, ..TrainConfig::default() };
        let mut rng = StdRng::seed_from_u64(3);
        let mut runs = 0.0;
        for _ in 0..batches {
            let batch = set.sample(&config, &mut rng).unwrap();
            runs += batch.text.narrow(1, 1, 1).unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap() as f64;
        }
        runs / (50 * batches) as f64
    }

    #[test]
    fn family_balance_draws_a_family_by_its_frames_to_a_power() {
        let set = run_after_a_long_stretch();
        let shares = set.family_shares(0.5);
        assert_eq!(shares.len(), 2);
        let (family, data, drawn) = shares[1];
        assert_eq!(family, Some(Family::Run));
        assert!((data - 0.25).abs() < 1e-12 && (drawn - 10.0 / (10.0 + 300f64.sqrt())).abs() < 1e-12, "{shares:?}");
        // Uniform crops: a crop's middle frame lies in [20, 380), 80 of its 360 frames in the run.
        assert!((run_share(&set, None, 40) - 80.0 / 360.0).abs() < 0.03);
        // By frames (power 1): the run's 100 of 400 frames; every family alike (power 0): half.
        assert!((run_share(&set, Some(1.0), 40) - 0.25).abs() < 0.03);
        assert!((run_share(&set, Some(0.0), 40) - 0.5).abs() < 0.03);
        assert!((run_share(&set, Some(0.5), 40) - drawn).abs() < 0.03);
        let bad = TrainConfig { family_balance: Some(f64::NAN), ..TrainConfig::default() };
        let err = set.sample(&bad, &mut StdRng::seed_from_u64(0)).unwrap_err();
        assert!(err.to_string().contains("family balance NaN"), "{err}");
    }
}
