//! The shipped model's deterministic text encoder: a bag of action and direction words.
//!
//! A prompt is lower-cased, split into words, each word reduced to its lemma ("walks",
//! "walking" → "walk"), and every lemma in the vocabulary sets its entry of a multi-hot vector,
//! which is then scaled to unit length. A prompt with no known word encodes to zeros, which is
//! exactly the unconditional branch of classifier-free guidance: the model then samples from
//! its whole distribution instead of guessing.

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

use super::encoder::TextEncoder;

/// Direction and manner words every vocabulary contains.
const DIRECTION_WORDS: [&str; 10] =
    ["forward", "backward", "left", "right", "around", "up", "down", "place", "slow", "fast"];

/// Words that carry no action: articles, the subject, linking words.
const STOP_WORDS: [&str; 22] = [
    "a", "an", "the", "person", "man", "woman", "someone", "human", "and", "then", "with", "on", "of", "from", "to",
    "in", "is", "his", "her", "their", "while", "at",
];

/// Irregular forms and synonyms mapped to the lemma used in labels.
const LEMMAS: [(&str, &str); 24] = [
    ("running", "run"),
    ("ran", "run"),
    ("jogs", "run"),
    ("jogging", "run"),
    ("jog", "run"),
    ("walked", "walk"),
    ("strolls", "walk"),
    ("stroll", "walk"),
    ("punches", "punch"),
    ("boxes", "box"),
    ("boxing", "box"),
    ("dancing", "dance"),
    ("spinning", "spin"),
    ("getting", "get"),
    ("gets", "get"),
    ("got", "get"),
    ("lying", "lie"),
    ("lies", "lie"),
    ("forwards", "forward"),
    ("backwards", "backward"),
    ("quickly", "fast"),
    ("slowly", "slow"),
    ("rolling", "roll"),
    ("climbing", "climb"),
];

/// Reduces a lower-case word to its lemma: the table first, then regular suffixes.
pub fn lemma(word: &str) -> String {
    if let Some((_, l)) = LEMMAS.iter().find(|(w, _)| *w == word) {
        return (*l).to_owned();
    }
    for suffix in ["ing", "es", "ed", "s"] {
        if let Some(stem) = word.strip_suffix(suffix) {
            if stem.len() >= 3 && !word.ends_with("ss") {
                // "crawls" → "crawl", "jumped" → "jump", "kicking" → "kick"
                return stem.to_owned();
            }
        }
    }
    word.to_owned()
}

/// Lemmas of the content words of a text, in order.
pub fn content_lemmas(text: &str) -> Vec<String> {
    text.to_lowercase()
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty() && !STOP_WORDS.contains(w))
        .map(lemma)
        .collect()
}

/// A bag-of-words encoder over a fixed, sorted vocabulary of lemmas.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct VocabularyEncoder {
    words: Vec<String>,
}

impl VocabularyEncoder {
    /// The vocabulary of a set of labels plus the direction words.
    pub fn from_labels<'a>(labels: impl IntoIterator<Item = &'a str>) -> Self {
        let mut words: Vec<String> = labels.into_iter().flat_map(content_lemmas).collect();
        words.extend(DIRECTION_WORDS.iter().map(|w| (*w).to_owned()));
        words.sort();
        words.dedup();
        Self { words }
    }

    /// The vocabulary, sorted.
    pub fn words(&self) -> &[String] {
        &self.words
    }

    /// Multi-hot vector of a prompt, unit length (all zeros when no word is known).
    pub fn encode_one(&self, prompt: &str) -> Vec<f32> {
        let mut v = vec![0f32; self.words.len()];
        for l in content_lemmas(prompt) {
            if let Ok(i) = self.words.binary_search(&l) {
                v[i] = 1.0;
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        if norm > 0.0 {
            v.iter_mut().for_each(|x| *x /= norm);
        }
        v
    }

    /// The words of a prompt that the vocabulary knows (what the model will "hear").
    pub fn known_words(&self, prompt: &str) -> Vec<String> {
        content_lemmas(prompt).into_iter().filter(|l| self.words.binary_search(l).is_ok()).collect()
    }
}

impl TextEncoder for VocabularyEncoder {
    fn dim(&self) -> usize {
        self.words.len()
    }

    fn encode(&self, prompts: &[&str], device: &Device) -> candle_core::Result<Tensor> {
        let data: Vec<f32> = prompts.iter().flat_map(|p| self.encode_one(p)).collect();
        Tensor::from_vec(data, (prompts.len(), self.dim()), device)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inflections_share_a_lemma() {
        for w in ["walks", "walking", "walked", "walk"] {
            assert_eq!(lemma(w), "walk");
        }
        assert_eq!(lemma("crawls"), "crawl");
        assert_eq!(lemma("running"), "run");
        assert_eq!(lemma("cartwheel"), "cartwheel");
        assert_eq!(content_lemmas("A person walks forwards."), vec!["walk", "forward"]);
    }

    #[test]
    fn encoding_is_unit_multi_hot_and_unknown_prompts_are_unconditional() {
        let enc = VocabularyEncoder::from_labels(["a person walks forward", "a person crawls on the ground"]);
        assert!(enc.words().contains(&"crawl".to_owned()));
        let v = enc.encode_one("The man is walking forward");
        let norm: f32 = v.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!((norm - 1.0).abs() < 1e-6);
        assert_eq!(v.iter().filter(|x| **x > 0.0).count(), 2);
        assert!(enc.encode_one("juggling torches").iter().all(|x| *x == 0.0));
        assert_eq!(enc.known_words("walk through a gap"), vec!["walk"]);
        let t = enc.encode(&["walk", "crawl"], &Device::Cpu).unwrap();
        assert_eq!(t.dims(), &[2, enc.dim()]);
    }
}
