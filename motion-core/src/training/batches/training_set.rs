//! The training set and the batches drawn from it, and the captioned sequences it is encoded
//! from.

use std::collections::BTreeMap;

use candle_core::{Device, Tensor};
use rand::Rng;

use super::family_balance::{FamilyDraw, FamilyStretches};
use super::sequence::{Sequence, Stretch};

use crate::corpus::family::Family;
use crate::corpus::{Corpus, Split};
use crate::database::{mirror_label, MotionDatabase};
use crate::motion::mirror;
use crate::representation::{extract_features, FeatureFrame, MeanStd, RestSkeleton, FEATURE_DIM};
use crate::skeleton::rest_bone_lengths;
use crate::text::caption_bank::CaptionBank;
use crate::text::vocabulary::VocabularyEncoder;
use crate::text::{ConditionEncoder, TextEncoder};
use crate::training::config::TrainConfig;
use crate::training::error::TrainError;

/// Captions encoded per call of the text encoder.
const ENCODE_BATCH: usize = 256;

/// A batch of normalised crops with their condition vectors.
#[derive(Debug, Clone)]
pub struct Batch {
    /// `[batch, frames, 263]`, normalised.
    pub x0: Tensor,
    /// `[batch, text_dim]`, the captions encoded.
    pub text: Tensor,
}

/// What the trainer learns from; see the module doc (`batches`).
#[derive(Debug, Clone)]
pub struct TrainingSet {
    sequences: Vec<Sequence>,
    /// Condition vectors `[rows, text_dim]`.
    text: Tensor,
    encoder: ConditionEncoder,
    mean_std: MeanStd,
    rest: Option<RestSkeleton>,
    /// Sequence indices per balancing group (groups with no sequence left out).
    groups: Vec<Vec<usize>>,
    /// The stretches of each skill family (and of none), for [`TrainConfig::family_balance`].
    families: Vec<FamilyStretches>,
    /// Draw groups uniformly (a database's labels) instead of crops uniformly (the corpus).
    balance: bool,
    /// Seconds of motion, mirrored copies included.
    seconds: f64,
    /// The captions with their rows of `text`, for a sentence encoder's set (what a prior
    /// trained on it conditions prompts on).
    bank: Option<CaptionBank>,
}

impl TrainingSet {
    /// Every window of `db` of at least `min_frames` frames, labelled, normalised with the
    /// database's statistics; batches are label-balanced when `balance`.
    pub fn from_database(
        db: &MotionDatabase,
        min_frames: usize,
        balance: bool,
        device: &Device,
    ) -> Result<Self, TrainError> {
        let labels = db.labels();
        let vocabulary = VocabularyEncoder::from_labels(labels.iter().map(String::as_str));
        let text = vocabulary.encode(&labels.iter().map(String::as_str).collect::<Vec<_>>(), device)?;
        let mean_std = db.mean_std().to_device(device)?;
        let mut sequences = Vec::new();
        for w in db.windows().iter().filter(|w| w.frames >= min_frames) {
            let label = labels
                .binary_search_by(|l| l.as_str().cmp(db.label(w)))
                .map_err(|_| TrainError::Data(format!("window {w:?} has a label missing from the label list")))?;
            let features = mean_std.normalize(&db.window_tensor(w, device)?)?;
            let stretches = vec![Stretch { start: 0, rows: vec![label as u32], family: None }];
            sequences.push(Sequence { features, stretches, group: label });
        }
        let seconds = db.total_frames() as f64 / crate::skeleton::FPS;
        Self::assemble(
            sequences,
            text,
            ConditionEncoder::Vocabulary(vocabulary),
            mean_std,
            db.rest_skeleton()?,
            balance,
            seconds,
        )
    }

    /// The clips of `split` and their mirrored copies, each window's captions encoded by
    /// `encoder`; normalised with `mean_std` or, when `None`, with the statistics of these clips
    /// (give the training set's for a validation set). `progress(done, total)` follows the
    /// encoding of the captions, the slow part (about 1 ms per caption on 2 cores).
    pub fn from_corpus(
        corpus: &Corpus,
        split: Split,
        encoder: ConditionEncoder,
        mean_std: Option<&MeanStd>,
        device: &Device,
        progress: impl FnMut(usize, usize),
    ) -> Result<Self, TrainError> {
        CaptionedSequences::from_corpus(corpus, split, mean_std, device)?.encode(encoder, progress)
    }

    pub(super) fn assemble(
        sequences: Vec<Sequence>,
        text: Tensor,
        encoder: ConditionEncoder,
        mean_std: MeanStd,
        rest: Option<RestSkeleton>,
        balance: bool,
        seconds: f64,
    ) -> Result<Self, TrainError> {
        if sequences.is_empty() {
            return Err(TrainError::Data("no sequence to train on".into()));
        }
        let mut groups: Vec<Vec<usize>> = vec![Vec::new(); sequences.iter().map(|s| s.group + 1).max().unwrap_or(0)];
        for (i, s) in sequences.iter().enumerate() {
            groups[s.group].push(i);
        }
        groups.retain(|g| !g.is_empty());
        let families = FamilyStretches::of(&sequences);
        Ok(Self { sequences, text, encoder, mean_std, rest, groups, families, balance, seconds, bank: None })
    }

    /// The text encoder whose vectors the condition table holds.
    pub fn encoder(&self) -> &ConditionEncoder {
        &self.encoder
    }

    /// Normalisation statistics of the features.
    pub fn mean_std(&self) -> &MeanStd {
        &self.mean_std
    }

    /// Bone lengths of the motions.
    pub fn rest(&self) -> Option<&RestSkeleton> {
        self.rest.as_ref()
    }

    /// Number of sequences.
    pub fn len(&self) -> usize {
        self.sequences.len()
    }

    /// Whether there is no sequence (never true of a built set).
    pub fn is_empty(&self) -> bool {
        self.sequences.is_empty()
    }

    /// Distinct captions (rows of the condition table).
    pub fn captions(&self) -> usize {
        self.text.dims()[0]
    }

    /// The captions and their condition vectors, for a corpus set encoded by a sentence
    /// encoder (`None` for a vocabulary encoder's set, whose words a prompt is matched by).
    pub fn caption_bank(&self) -> Option<&CaptionBank> {
        self.bank.as_ref()
    }

    /// Seconds of motion, mirrored copies included.
    pub fn seconds(&self) -> f64 {
        self.seconds
    }

    /// One batch: a crop length uniform in `[min_frames, max_frames]` (shortened to the longest
    /// sequence when none is long enough), then `batch_size` crops of sequences at least that
    /// long, each with one of the phrasings of its middle frame's stretch. A crop is drawn
    /// - with label balancing (a database): a group uniformly, then a sequence of it, then an
    ///   offset uniformly;
    /// - with [`TrainConfig::family_balance`] = α: a skill family with probability proportional
    ///   to its frames^α, then a middle frame uniformly over that family's stretches (in
    ///   sequences long enough; any stretch when none is), the crop centred on it (moved
    ///   inside the sequence at its ends);
    /// - otherwise uniformly among all crops of that length.
    pub fn sample(&self, config: &TrainConfig, rng: &mut impl Rng) -> Result<Batch, TrainError> {
        if config.min_frames > config.max_frames || config.batch_size == 0 || config.min_frames < 2 {
            return Err(TrainError::Data("need batch_size > 0 and 2 <= min_frames <= max_frames".into()));
        }
        if let Some(alpha) = config.family_balance {
            if self.balance {
                return Err(TrainError::Data(
                    "family balance draws a corpus's crops; a database balances labels".into(),
                ));
            }
            if !(alpha.is_finite() && alpha >= 0.0) {
                return Err(TrainError::Data(format!("family balance {alpha}: need a finite power >= 0")));
            }
        }
        let longest = self.sequences.iter().map(Sequence::frames).max().unwrap_or(0);
        if longest < config.min_frames {
            return Err(TrainError::Data(format!("no sequence has at least {} frames", config.min_frames)));
        }
        let frames = rng.random_range(config.min_frames..=config.max_frames).min(longest);
        let by_family = config.family_balance.map(|alpha| self.family_draw(alpha, frames));
        let (pools, cumulative) = if by_family.is_some() { (Vec::new(), Vec::new()) } else { self.pools(frames) };
        let mut crops = Vec::with_capacity(config.batch_size);
        let mut rows = Vec::with_capacity(config.batch_size);
        for _ in 0..config.batch_size {
            let (i, offset) = if let Some(draw) = &by_family {
                draw.crop(&self.sequences, frames, rng)
            } else {
                let i = if self.balance {
                    let pool = &pools[rng.random_range(0..pools.len())];
                    pool[rng.random_range(0..pool.len())]
                } else {
                    let crop = rng.random_range(0..*cumulative.last().unwrap_or(&1));
                    pools[0][cumulative.partition_point(|&c| c <= crop)]
                };
                (i, rng.random_range(0..=self.sequences[i].frames() - frames))
            };
            let sequence = &self.sequences[i];
            crops.push(sequence.features.narrow(0, offset, frames)?);
            let phrasings = sequence.captions_at(offset + frames / 2);
            rows.push(phrasings[rng.random_range(0..phrasings.len())]);
        }
        let ids = Tensor::from_vec(rows, config.batch_size, self.text.device())?;
        Ok(Batch { x0: Tensor::stack(&crops, 0)?, text: self.text.index_select(&ids, 0)? })
    }

    /// The sequences at least `frames` long, per balancing group (groups without one left
    /// out) when balancing, else in one pool; and the cumulative crop counts of the first
    /// pool's sequences, for drawing crops uniformly.
    fn pools(&self, frames: usize) -> (Vec<Vec<usize>>, Vec<usize>) {
        let long_enough = |i: &usize| self.sequences[*i].frames() >= frames;
        let mut pools: Vec<Vec<usize>> = if self.balance {
            self.groups.iter().map(|g| g.iter().copied().filter(long_enough).collect()).collect()
        } else {
            vec![(0..self.sequences.len()).filter(long_enough).collect()]
        };
        pools.retain(|p| !p.is_empty());
        let cumulative = pools
            .first()
            .into_iter()
            .flatten()
            .scan(0, |sum, &i| {
                *sum += self.sequences[i].frames() - frames + 1;
                Some(*sum)
            })
            .collect();
        (pools, cumulative)
    }
}

/// The captioned stretches of windows given as stretches starting at their centre frames: each
/// window's stretch starts halfway between the previous window's centre and its own (the first
/// at frame 0), so the stretch holding a frame is the window centred nearest it.
fn nearest_centre_stretches(mut windows: Vec<Stretch>) -> Vec<Stretch> {
    windows.sort_by_key(|w| w.start);
    let centres: Vec<usize> = windows.iter().map(|w| w.start).collect();
    for (i, window) in windows.iter_mut().enumerate() {
        window.start = if i == 0 { 0 } else { (centres[i - 1] + centres[i]).div_ceil(2) };
    }
    windows
}

/// A corpus split ready to train on before its captions are encoded: every clip and its
/// mirrored copy as normalised features, each window's phrasings as rows of a caption table and
/// its skill family.
/// [`CaptionedSequences::encode`] makes the [`TrainingSet`]; the arrays are also what the
/// PyTorch mirror of the trainer reads (`motion-core/examples/export_training_set.rs`), with the
/// captions encoded where the sentence encoder is.
#[derive(Debug, Clone)]
pub struct CaptionedSequences {
    sequences: Vec<Sequence>,
    /// The distinct captions, in row order.
    captions: Vec<String>,
    mean_std: MeanStd,
    /// Seconds of motion, mirrored copies included.
    seconds: f64,
}

impl CaptionedSequences {
    /// The clips of `split` and their mirrored copies, normalised with `mean_std` or, when
    /// `None`, with the statistics of these clips.
    pub fn from_corpus(
        corpus: &Corpus,
        split: Split,
        mean_std: Option<&MeanStd>,
        device: &Device,
    ) -> Result<Self, TrainError> {
        let mut windows_of: Vec<Vec<usize>> = vec![Vec::new(); corpus.clips.len()];
        for (i, w) in corpus.windows.iter().enumerate() {
            windows_of[w.clip].push(i);
        }
        let mut rows: BTreeMap<String, u32> = BTreeMap::new();
        // Each copy's feature frames and captioned stretches.
        let mut raw: Vec<(Vec<FeatureFrame>, Vec<Stretch>)> = Vec::new();
        for (index, clip) in corpus.clips.iter().enumerate().filter(|(_, c)| c.split == split) {
            let poses = corpus.clip_joints(clip);
            for mirrored in [false, true] {
                let poses = if mirrored { mirror(poses) } else { poses.to_vec() };
                let extracted = extract_features(&poses)
                    .map_err(|e| TrainError::Data(format!("corpus clip {}: {e}", clip.name)))?;
                let mut captions = Vec::new();
                for &w in &windows_of[index] {
                    let window = &corpus.windows[w];
                    let tags = if mirrored { window.tags.mirrored() } else { window.tags.clone() };
                    let window_poses = &poses[window.start..window.start + window.frames];
                    let family = Family::of(window_poses, &tags, &clip.description);
                    let rows = window
                        .captions
                        .iter()
                        .map(|c| {
                            let caption = if mirrored { mirror_label(c) } else { c.clone() };
                            let next = rows.len() as u32;
                            *rows.entry(caption).or_insert(next)
                        })
                        .collect();
                    captions.push(Stretch { start: window.start + window.frames / 2, rows, family });
                }
                if !captions.is_empty() {
                    raw.push((extracted.features, nearest_centre_stretches(captions)));
                }
            }
        }
        if raw.is_empty() {
            return Err(TrainError::Data(format!("the corpus has no {} clip", split.name())));
        }
        let mean_std = match mean_std {
            Some(m) => m.to_device(device)?,
            None => MeanStd::from_frames(raw.iter().flat_map(|(f, _)| f))
                .map_err(|e| TrainError::Data(e.to_string()))?
                .to_device(device)?,
        };
        let frames: usize = raw.iter().map(|(f, _)| f.len()).sum();
        let mut sequences = Vec::with_capacity(raw.len());
        for (features, captions) in raw {
            let n = features.len();
            let flat: Vec<f32> = features.into_iter().flatten().collect();
            let features = mean_std.normalize(&Tensor::from_vec(flat, (n, FEATURE_DIM), device)?)?;
            sequences.push(Sequence { features, stretches: captions, group: 0 });
        }
        let mut texts: Vec<(u32, String)> = rows.into_iter().map(|(caption, row)| (row, caption)).collect();
        texts.sort_by_key(|(row, _)| *row);
        let captions = texts.into_iter().map(|(_, caption)| caption).collect();
        Ok(Self { sequences, captions, mean_std, seconds: frames as f64 / crate::skeleton::FPS })
    }

    /// The distinct captions, in the row order of the caption table.
    pub fn captions(&self) -> &[String] {
        &self.captions
    }

    /// Normalisation statistics of the features.
    pub fn mean_std(&self) -> &MeanStd {
        &self.mean_std
    }

    /// Each sequence: its normalised features `[frames, 263]` and its captioned stretches, by
    /// first frame, the first at frame 0.
    pub fn sequences(&self) -> impl Iterator<Item = (&Tensor, &[Stretch])> {
        self.sequences.iter().map(|s| (&s.features, s.stretches.as_slice()))
    }

    /// The training set: the captions encoded by `encoder` (`progress(done, total)` follows
    /// it), the corpus's rest skeleton, batches drawn uniformly over all crops.
    pub fn encode(
        self,
        encoder: ConditionEncoder,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<TrainingSet, TrainError> {
        let device = self.mean_std.mean().device().clone();
        let mut encoded = Vec::with_capacity(self.captions.len().div_ceil(ENCODE_BATCH));
        for (k, chunk) in self.captions.chunks(ENCODE_BATCH).enumerate() {
            progress(k * ENCODE_BATCH, self.captions.len());
            encoded.push(encoder.encode(&chunk.iter().map(String::as_str).collect::<Vec<_>>(), &device)?);
        }
        progress(self.captions.len(), self.captions.len());
        let text = Tensor::cat(&encoded, 0)?;
        let rest = Some(RestSkeleton { bone_lengths_m: rest_bone_lengths() });
        let sentence = matches!(encoder, ConditionEncoder::MiniLm(_));
        let mut set = TrainingSet::assemble(self.sequences, text, encoder, self.mean_std, rest, false, self.seconds)?;
        if sentence {
            set.bank = Some(CaptionBank::new(self.captions, set.text.clone()).map_err(TrainError::Data)?);
        }
        Ok(set)
    }
}

impl TrainingSet {
    /// Each skill family of the stretches (`None`: no family) with its share of the frames,
    /// and its share of the crops drawn with [`TrainConfig::family_balance`] = `alpha`
    /// (proportional to its frames to the power `alpha`).
    pub fn family_shares(&self, alpha: f64) -> Vec<(Option<Family>, f64, f64)> {
        let frames: f64 = self.families.iter().map(|f| f.frames as f64).sum();
        let drawn = self.family_probabilities(alpha);
        self.families.iter().zip(drawn).map(|(f, p)| (f.family, f.frames as f64 / frames, p)).collect()
    }

    /// Each family's probability of being drawn: its frames^`alpha`, normalised.
    fn family_probabilities(&self, alpha: f64) -> Vec<f64> {
        let weights: Vec<f64> = self.families.iter().map(|f| (f.frames as f64).powf(alpha)).collect();
        let total: f64 = weights.iter().sum();
        weights.into_iter().map(|w| w / total).collect()
    }

    /// The family draw of one batch's crops of `frames` frames: each family's weight
    /// (frames^`alpha`) and its stretches in sequences at least `frames` long, by cumulative
    /// frames (a family with none of them draws from every such stretch).
    pub(super) fn family_draw(&self, alpha: f64, frames: usize) -> FamilyDraw {
        let long_enough = |&&(i, _): &&(usize, usize)| self.sequences[i].frames() >= frames;
        let cumulative = |stretches: &mut dyn Iterator<Item = &(usize, usize)>| -> Vec<((usize, usize), usize)> {
            stretches
                .scan(0, |sum, &(i, k)| {
                    *sum += self.sequences[i].stretch_frames(k);
                    Some(((i, k), *sum))
                })
                .collect()
        };
        let any: Vec<_> = cumulative(&mut self.families.iter().flat_map(|f| f.stretches.iter()).filter(long_enough));
        let pools = self
            .families
            .iter()
            .map(|family| {
                let pool = cumulative(&mut family.stretches.iter().filter(long_enough));
                if pool.is_empty() {
                    any.clone()
                } else {
                    pool
                }
            })
            .collect();
        let cumulative_weights = self.family_probabilities(alpha).into_iter().scan(0.0, |sum, p| {
            *sum += p;
            Some(*sum)
        });
        FamilyDraw { cumulative_weights: cumulative_weights.collect(), pools }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::corpus::tags::MotionTags;
    use crate::corpus::{CorpusClip, CorpusWindow, Source};
    use crate::skeleton::{rest_pose, Pose};
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    /// A corpus of two 200-frame clips (the first sways while drifting to +x, the second sways
    /// in place) in the given splits, windows every 40 frames captioned
    /// "person <start> walks to the left" and "person <start> walks slowly".
    pub(crate) fn two_clip_corpus(splits: [Split; 2]) -> Corpus {
        let mut corpus =
            Corpus { clips: Vec::new(), joints: Vec::new(), windows: Vec::new(), drops: Default::default() };
        for (c, split) in splits.into_iter().enumerate() {
            let offset = corpus.joints.len();
            let poses: Vec<Pose> = (0..200)
                .map(|t| {
                    let step = 0.02 * (t as f64) * (1 - c) as f64;
                    let swing = 0.1 * (t as f64 * 0.3).sin();
                    rest_pose().map(|v| glam::DVec3::new(v.x + step, v.y, v.z + swing * v.y))
                })
                .collect();
            for (start, frames) in crate::corpus::window_starts(poses.len()) {
                corpus.windows.push(CorpusWindow {
                    clip: c,
                    start,
                    frames,
                    tags: MotionTags::measure(&poses[start..start + frames]),
                    captions: vec![format!("person {start} walks to the left"), format!("person {start} walks slowly")],
                });
            }
            corpus.joints.extend(poses);
            corpus.clips.push(CorpusClip {
                name: format!("clip{c}"),
                source: Source::Cmu,
                take: format!("0{c}_01"),
                subject: format!("0{c}"),
                description: String::new(),
                split,
                take_frame: 0,
                offset,
                frames: 200,
            });
        }
        corpus
    }

    pub(crate) fn vocabulary() -> ConditionEncoder {
        ConditionEncoder::Vocabulary(VocabularyEncoder::from_labels(["walk left right"]))
    }

    #[test]
    fn a_corpus_split_gives_its_clips_and_their_mirrored_copies_with_every_phrasing() {
        let corpus = two_clip_corpus([Split::Train, Split::Test]);
        let set = TrainingSet::from_corpus(&corpus, Split::Train, vocabulary(), None, &Device::Cpu, |_, _| {}).unwrap();
        assert_eq!(set.len(), 2, "clip 0 and its mirror; the test clip is left out");
        // Windows at 0, 40 and 80 (the last ending at frame 200) × 2 phrasings × (as is,
        // mirrored), the phrasing without a side shared by both copies.
        let windows = crate::corpus::window_starts(200).len();
        assert_eq!(set.captions(), windows * 3);
        assert_eq!(set.sequences[0].frames(), 199, "features have one frame fewer than poses");
        assert!((set.seconds() - 2.0 * 199.0 / 20.0).abs() < 1e-9);
        // A crop's captions are those of the window centred nearest its middle frame: windows
        // [0, 120), [40, 160), [80, 200) have centres 60, 100, 140, so a crop of frames 0-119
        // (middle 60) is described by the first, one of 30-149 (middle 90) by the second.
        let window = |i: usize| set.sequences[0].stretches[i].rows.as_slice();
        assert_eq!(set.sequences[0].stretches.iter().map(|s| s.start).collect::<Vec<_>>(), [0, 80, 120]);
        for (middle, nearest) in [(0, 0), (60, 0), (79, 0), (80, 1), (90, 1), (119, 1), (120, 2), (198, 2)] {
            assert_eq!(set.sequences[0].captions_at(middle), window(nearest), "middle frame {middle}");
        }
        // The mirrored copy's "left" caption is the original's with "right".
        let original = &set.sequences[0].stretches[0].rows;
        let mirrored = &set.sequences[1].stretches[0].rows;
        assert_ne!(original[0], mirrored[0]);
        assert_eq!(original[1], mirrored[1]);
        let validation =
            TrainingSet::from_corpus(&corpus, Split::Test, vocabulary(), Some(set.mean_std()), &Device::Cpu, |_, _| {})
                .unwrap();
        assert_eq!(
            validation.mean_std().std().to_vec1::<f32>().unwrap(),
            set.mean_std().std().to_vec1::<f32>().unwrap(),
            "a held-out set is normalised with the training set's statistics"
        );
        let err = TrainingSet::from_corpus(&corpus, Split::Validation, vocabulary(), None, &Device::Cpu, |_, _| {})
            .unwrap_err();
        assert!(err.to_string().contains("no validation clip"), "{err}");
    }

    /// What the PyTorch mirror reads: the caption table encoded elsewhere, row by row in the
    /// order of `captions()`, is the training set's table; the sequences are its sequences.
    #[test]
    fn captioned_sequences_are_the_training_set_before_encoding() {
        let corpus = two_clip_corpus([Split::Train, Split::Test]);
        let sequences = CaptionedSequences::from_corpus(&corpus, Split::Train, None, &Device::Cpu).unwrap();
        let captions: Vec<&str> = sequences.captions().iter().map(String::as_str).collect();
        assert!(captions.iter().any(|c| c.contains("right")) && captions.iter().any(|c| c.contains("left")));
        let table = vocabulary().encode(&captions, &Device::Cpu).unwrap();
        let stretches: Vec<usize> = sequences.sequences().map(|(_, s)| s.len()).collect();
        let set = sequences.encode(vocabulary(), |_, _| {}).unwrap();
        assert_eq!(table.to_vec2::<f32>().unwrap(), set.text.to_vec2::<f32>().unwrap());
        assert_eq!(stretches, set.sequences.iter().map(|s| s.stretches.len()).collect::<Vec<_>>());
    }

    #[test]
    fn batches_have_one_crop_length_and_encoded_captions() {
        let corpus = two_clip_corpus([Split::Train, Split::Train]);
        let set = TrainingSet::from_corpus(&corpus, Split::Train, vocabulary(), None, &Device::Cpu, |_, _| {}).unwrap();
        let config = TrainConfig { batch_size: 5, min_frames: 40, max_frames: 300, ..TrainConfig::default() };
        let mut rng = StdRng::seed_from_u64(1);
        for _ in 0..5 {
            let batch = set.sample(&config, &mut rng).unwrap();
            let (b, frames, f) = batch.x0.dims3().unwrap();
            assert_eq!((b, f), (5, FEATURE_DIM));
            assert!((40..=199).contains(&frames));
            assert_eq!(batch.text.dims(), &[5, set.encoder().dim()]);
            let norms: Vec<f32> = batch.text.sqr().unwrap().sum(1).unwrap().to_vec1().unwrap();
            assert!(norms.iter().all(|n| (n - 1.0).abs() < 1e-5), "every crop has a caption: {norms:?}");
        }
        let bad = TrainConfig { min_frames: 250, ..config };
        assert!(set.sample(&bad, &mut rng).unwrap_err().to_string().contains("250 frames"));
    }
}
