//! The captions a prior was trained on, with their condition vectors, for conditioning a prompt
//! on the nearest of them.
//!
//! A prior trained on captions made by rules (`corpus::caption`: a few thousand distinct
//! sentences) learns what each of those points of the sentence encoder's space means, and
//! little about the space between them: a paraphrase in other words ("a woman ambles along at
//! an easy pace", cosine 0.57 to its nearest training caption) lands where the prior has never
//! been trained and samples something else. Conditioning a prompt farther than
//! [`KEEP_OWN_SIMILARITY`] from every training caption on the nearest one instead (cosine
//! similarity of the unit sentence vectors) keeps it on the trained points, and says which one it
//! took ([`CaptionBank::nearest`]), so a user sees how the prompt was understood. Prompts that
//! close to a training caption, and blank prompts, keep their own vector.
//!
//! The nearest caption must not name a side the prompt does not: MiniLM hardly tells left from
//! right ("a person walks sideways to the left" and "... to the right" are 0.985 apart), and
//! the corpus holds every window mirrored, so a caption of the asked side is always there.
//! Without that rule, with the shipped weights banked on the captions of the rebuilt corpus,
//! "someone ambles and veers off to their right" is heard as "upset: a person stands in place,
//! turning to the left" and its samples turn right in 12 % (44 % with the rule; 50 % heard as
//! "... turns right" on the shipped bank). Nor may it name one foot where the prompt names both,
//! or both where it names one: MiniLM hears "someone jumps onward with both feet" as "someone
//! jumps along on one foot" (0.89), and its samples leave the ground in 38 % (88 % with the
//! rule). Both measurements are in `fixtures/model/training/README.md` (the caption bank on the
//! take descriptions, and the feet rule).
//!
//! A bank loaded with WordNet ([`CaptionBank::with_wordnet`]) first restates a prompt's verbs
//! that no caption uses in verbs the captions do ([`super::restatement`]); the prompt is encoded
//! as restated.

use std::sync::Arc;

use candle_core::{DType, Device, Result, Tensor};

use super::restatement::{Restated, Restatement};
use super::wordnet::WordNet;

/// Cosine similarity to its nearest training caption from which a prompt keeps its own vector.
/// Measured on the shipped prior (16 samples per prompt, `fixtures/model/training/README.md`): "a
/// person walks and turns left" (0.96 to "a person walks forward and turns left") turned 45° or
/// more in 94 % of its samples on its own vector and in 62 % on the caption's, which holds the
/// smaller turns; the paraphrases, 0.45-0.78 from theirs, passed their detectors in 0-12 % of
/// their samples on their own vectors (walk, run, jump, sideways) and in 50-100 % on the
/// captions'.
pub const KEEP_OWN_SIMILARITY: f32 = 0.95;

/// The distinct training captions and their unit condition vectors `[len, dim]` (f32).
#[derive(Debug, Clone)]
pub struct CaptionBank {
    captions: Vec<String>,
    named: Vec<Named>,
    vectors: Tensor,
    restatement: Option<Restatement>,
}

/// Which of two values a sentence encoder hardly tells apart a text names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Pair {
    first: bool,
    second: bool,
}

impl Pair {
    /// Whether a caption naming these may stand for a prompt naming `prompt`'s: a prompt naming
    /// neither takes any caption, one naming a value only captions naming no other.
    fn fit(self, prompt: Pair) -> bool {
        prompt == Pair::default() || ((!self.first || prompt.first) && (!self.second || prompt.second))
    }
}

/// What a text names of the pairs MiniLM hardly tells apart, in whole words of any case: the
/// sides ("left", "right") and the feet (one: "one", "single", "left" or "right" before
/// "foot", "leg" or "legged"; both: "both" or "two" before "feet" or "legs", or "feet"/"legs"
/// before "together").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Named {
    sides: Pair,
    feet: Pair,
}

impl Named {
    fn of(text: &str) -> Self {
        let words: Vec<String> =
            text.split(|c: char| !c.is_alphanumeric()).filter(|w| !w.is_empty()).map(str::to_lowercase).collect();
        let has = |word: &str| words.iter().any(|w| w == word);
        let pair = |first: &[&str], second: &[&str]| {
            words.windows(2).any(|w| first.contains(&w[0].as_str()) && second.contains(&w[1].as_str()))
        };
        let one = pair(&["one", "single", "left", "right"], &["foot", "leg", "legged"]);
        let both = pair(&["both", "two"], &["feet", "legs"]) || pair(&["feet", "legs"], &["together"]);
        Named { sides: Pair { first: has("left"), second: has("right") }, feet: Pair { first: one, second: both } }
    }

    fn fit(self, prompt: Named) -> bool {
        self.sides.fit(prompt.sides) && self.feet.fit(prompt.feet)
    }
}

/// The training caption nearest a prompt.
#[derive(Debug, Clone, PartialEq)]
pub struct NearestCaption {
    /// Its row in the bank.
    pub row: usize,
    /// The caption.
    pub caption: String,
    /// Cosine similarity of the two sentence vectors (1 for the same sentence).
    pub similarity: f32,
}

impl NearestCaption {
    /// Whether the prompt is conditioned on this caption's vector rather than its own: it is
    /// farther than [`KEEP_OWN_SIMILARITY`] from it.
    pub fn replaces_prompt(&self) -> bool {
        self.similarity < KEEP_OWN_SIMILARITY
    }
}

impl CaptionBank {
    /// A bank of `captions` and their vectors `[captions.len(), dim]` (unit rows, as the
    /// sentence encoder gives them; stored at any float precision, kept as f32).
    pub fn new(captions: Vec<String>, vectors: Tensor) -> std::result::Result<Self, String> {
        let (rows, _) = vectors.dims2().map_err(|e| format!("caption vectors: {e}"))?;
        if rows != captions.len() || rows == 0 {
            return Err(format!("{} captions but {rows} caption vectors", captions.len()));
        }
        let vectors = vectors.to_dtype(DType::F32).map_err(|e| format!("caption vectors: {e}"))?;
        let named = captions.iter().map(|c| Named::of(c)).collect();
        Ok(Self { captions, named, vectors, restatement: None })
    }

    /// The bank restating prompts in its captions' verbs through `wordnet` ([`Self::restate`]).
    pub fn with_wordnet(self, wordnet: Arc<WordNet>) -> Self {
        let restatement = Some(Restatement::new(wordnet, &self.captions));
        Self { restatement, ..self }
    }

    /// `prompt` restated in the captions' verbs ([`super::restatement`]); as it is without
    /// WordNet.
    pub fn restate(&self, prompt: &str) -> Restated {
        match &self.restatement {
            Some(r) => r.restate(prompt),
            None => Restated::unchanged(prompt),
        }
    }

    /// The captions, in row order.
    pub fn captions(&self) -> &[String] {
        &self.captions
    }

    /// The condition vectors `[len, dim]`.
    pub fn vectors(&self) -> &Tensor {
        &self.vectors
    }

    /// The nearest caption of each of `prompts`, whose unit sentence vectors are the rows of
    /// `condition` `[prompts.len(), dim]`, among the captions naming no side and no number of
    /// feet the prompt does not name (the module's note), or among all when none does.
    pub fn nearest(&self, condition: &Tensor, prompts: &[&str]) -> Result<Vec<NearestCaption>> {
        let device = self.vectors.device();
        let similarity = condition.to_device(device)?.to_dtype(DType::F32)?.matmul(&self.vectors.t()?)?;
        let similarity = similarity.to_vec2::<f32>()?;
        if similarity.len() != prompts.len() {
            candle_core::bail!("{} condition rows for {} prompts", similarity.len(), prompts.len());
        }
        Ok(similarity
            .iter()
            .zip(prompts)
            .map(|(row, prompt)| {
                let asked = Named::of(prompt);
                let best = |fitting: bool| {
                    row.iter()
                        .enumerate()
                        .filter(|&(k, _)| !fitting || self.named[k].fit(asked))
                        .max_by(|a, b| a.1.total_cmp(b.1))
                        .map(|(k, &s)| (k, s))
                };
                let (row, similarity) = best(true).or_else(|| best(false)).unwrap_or((0, f32::NAN));
                NearestCaption { row, caption: self.captions[row].clone(), similarity }
            })
            .collect())
    }

    /// `condition` `[prompts.len(), dim]` with each row of a non-blank prompt farther than
    /// [`KEEP_OWN_SIMILARITY`] from every caption replaced by the vector of its nearest caption,
    /// on `device`.
    pub fn snap(&self, condition: &Tensor, prompts: &[&str], device: &Device) -> Result<Tensor> {
        let nearest = self.nearest(condition, prompts)?;
        let rows = prompts
            .iter()
            .zip(&nearest)
            .enumerate()
            .map(|(i, (prompt, n))| {
                if prompt.trim().is_empty() || !n.replaces_prompt() {
                    condition.get(i)?.to_dtype(DType::F32)?.to_device(device)
                } else {
                    self.vectors.get(n.row)?.to_device(device)
                }
            })
            .collect::<Result<Vec<_>>>()?;
        Tensor::stack(&rows, 0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(v: [f32; 3]) -> [f32; 3] {
        let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        v.map(|x| x / n)
    }

    fn bank() -> CaptionBank {
        let rows = [unit([1.0, 0.0, 0.0]), unit([0.0, 1.0, 0.0]), unit([0.0, 0.6, 0.8])];
        let vectors = Tensor::new(&rows, &Device::Cpu).unwrap().to_dtype(DType::F16).unwrap();
        CaptionBank::new(vec!["walks".into(), "turns left".into(), "turns right".into()], vectors).unwrap()
    }

    #[test]
    fn far_prompts_take_their_nearest_caption_and_near_or_blank_ones_keep_their_vector() {
        let bank = bank();
        let prompts = [unit([0.9, 0.4, 0.0]), unit([0.3, 0.2, 0.9]), unit([0.2, 0.2, 0.2]), unit([1.0, 0.01, 0.0])];
        let condition = Tensor::new(&prompts, &Device::Cpu).unwrap();
        let nearest = bank.nearest(&condition, &["a", "b", "c", "d"]).unwrap();
        let captions: Vec<&str> = nearest.iter().map(|n| n.caption.as_str()).collect();
        assert_eq!(captions, ["walks", "turns right", "turns right", "walks"]);
        let expected = (0.2f32 * 0.6 + 0.9 * 0.8) / (0.3f32 * 0.3 + 0.2 * 0.2 + 0.9 * 0.9).sqrt();
        assert!((nearest[1].similarity - expected).abs() < 1e-3, "{nearest:?}");
        assert!(nearest[0].replaces_prompt() && !nearest[3].replaces_prompt(), "{nearest:?}");
        let prompts_text = ["a", "b", "  ", "d"];
        let snapped = bank.snap(&condition, &prompts_text, &Device::Cpu).unwrap().to_vec2::<f32>().unwrap();
        assert_eq!(snapped[0], bank.vectors().get(0).unwrap().to_vec1::<f32>().unwrap());
        assert_eq!(snapped[1], bank.vectors().get(2).unwrap().to_vec1::<f32>().unwrap());
        // Blank, and within KEEP_OWN_SIMILARITY of a caption: their own vectors.
        assert_eq!(snapped[2], prompts[2].to_vec());
        assert_eq!(snapped[3], prompts[3].to_vec());
    }

    #[test]
    fn a_prompt_naming_a_side_is_not_heard_as_the_other_side() {
        let bank = bank();
        // Nearest "turns right" by its vector, but it asks for the left.
        let condition =
            Tensor::new(&[unit([0.0, 0.5, 0.8]), unit([0.0, 0.5, 0.8]), unit([0.0, 0.5, 0.8])], &Device::Cpu).unwrap();
        let prompts = ["someone veers off to their LEFT", "someone veers off", "veers right, then left"];
        let nearest = bank.nearest(&condition, &prompts).unwrap();
        let captions: Vec<&str> = nearest.iter().map(|n| n.caption.as_str()).collect();
        assert_eq!(captions, ["turns left", "turns right", "turns right"]);
        let expected = 0.5 / (0.5f32 * 0.5 + 0.8 * 0.8).sqrt();
        assert!((nearest[0].similarity - expected).abs() < 1e-3, "{nearest:?}");
        // A caption naming no side fits every prompt; whole words only.
        assert!(Named::of("walks forward").fit(Named::of("turns left")));
        assert_eq!(Named::of("Reach_Left002 (leftover)"), Named::default());
        assert!(bank.nearest(&condition, &prompts[..2]).is_err());
    }

    #[test]
    fn a_prompt_naming_one_foot_or_both_is_not_heard_as_the_other() {
        let one = Pair { first: true, second: false };
        let both = Pair { first: false, second: true };
        for (text, feet) in [
            ("someone jumps along on one foot", one),
            ("a girl hops on her LEFT leg", one),
            ("a one-legged stance", one),
            ("someone bounds onward with both feet", both),
            ("a standing jump with her feet together", both),
            ("someone jumps off two legs", both),
            ("a person jumps forward", Pair::default()),
            ("someone walks a foot to the left", Pair::default()),
        ] {
            assert_eq!(Named::of(text).feet, feet, "{text}");
        }
        let rows = [unit([1.0, 0.0, 0.0]), unit([0.9, 0.1, 0.0])];
        let vectors = Tensor::new(&rows, &Device::Cpu).unwrap();
        let captions = vec!["someone jumps along on one foot".into(), "a person jumps forward".into()];
        let bank = CaptionBank::new(captions, vectors).unwrap();
        let condition = Tensor::new(&[unit([1.0, 0.0, 0.0]), unit([1.0, 0.0, 0.0])], &Device::Cpu).unwrap();
        let nearest = bank.nearest(&condition, &["someone jumps with both feet", "someone jumps on one leg"]).unwrap();
        assert_eq!(nearest[0].caption, "a person jumps forward");
        assert_eq!(nearest[1].caption, "someone jumps along on one foot");
    }

    #[test]
    fn a_bank_needs_one_vector_per_caption() {
        let vectors = Tensor::zeros((2, 3), DType::F32, &Device::Cpu).unwrap();
        let err = CaptionBank::new(vec!["one".into()], vectors).unwrap_err();
        assert!(err.contains("1 captions but 2"), "{err}");
    }
}
