//! Text conditioning behind a small encoder seam: priors trained on the corpus condition on
//! [`minilm::MiniLm`] (all-MiniLM-L6-v2, 384-d unit sentence vectors, weights shipped in
//! `fixtures/text/`); priors trained on the 23 labelled clips on the deterministic
//! [`vocabulary::VocabularyEncoder`]; official MDM checkpoints on [`clip`].

pub mod caption_bank;
pub mod clip;
mod encoder;
pub mod minilm;
pub mod restatement;
pub mod vocabulary;
pub mod weights;
pub mod wordnet;

pub use encoder::TextEncoder;

use std::path::Path;
use std::sync::Arc;

use candle_core::{Device, Result, Tensor};

use minilm::MiniLm;
use vocabulary::VocabularyEncoder;
use weights::EncoderError;

/// Name of the shipped sentence encoder, as a prior file names it and as its folder under the
/// text models folder (`fixtures/text/all-MiniLM-L6-v2`) is called.
pub const MINILM_NAME: &str = "all-MiniLM-L6-v2";

/// The text encoder a prior conditions on.
#[derive(Debug, Clone)]
pub enum ConditionEncoder {
    /// Unit multi-hot vectors over the lemmas of the training labels.
    Vocabulary(VocabularyEncoder),
    /// all-MiniLM-L6-v2 sentence embeddings (384-d, unit length).
    MiniLm(Arc<MiniLm>),
}

impl ConditionEncoder {
    /// Loads the sentence encoder called `name` from `text_models` (the folder holding one folder
    /// per encoder, e.g. `fixtures/text`).
    pub fn sentence(name: &str, text_models: &Path, device: &Device) -> std::result::Result<Self, EncoderError> {
        if name != MINILM_NAME {
            return Err(EncoderError::Config(format!(
                "unknown sentence encoder {name:?}: only {MINILM_NAME:?} exists"
            )));
        }
        Ok(Self::MiniLm(Arc::new(MiniLm::load(&text_models.join(name), device)?)))
    }

    /// What the encoder hears of `prompt`: a vocabulary encoder the lemmas it knows (none: the
    /// condition is all zeros, an unconditional sample); `None` for a sentence encoder, which
    /// reads the whole sentence.
    pub fn heard_words(&self, prompt: &str) -> Option<Vec<String>> {
        match self {
            Self::Vocabulary(v) => Some(v.known_words(prompt)),
            Self::MiniLm(_) => None,
        }
    }
}

impl TextEncoder for ConditionEncoder {
    fn dim(&self) -> usize {
        match self {
            Self::Vocabulary(v) => v.dim(),
            Self::MiniLm(m) => m.dim(),
        }
    }

    fn encode(&self, prompts: &[&str], device: &Device) -> Result<Tensor> {
        match self {
            Self::Vocabulary(v) => v.encode(prompts, device),
            Self::MiniLm(m) => TextEncoder::encode(m.as_ref(), prompts, device),
        }
    }
}
