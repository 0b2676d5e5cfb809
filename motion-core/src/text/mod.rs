//! Text conditioning behind a small encoder seam: the shipped model uses the deterministic
//! [`vocabulary::VocabularyEncoder`]; official MDM checkpoints use [`clip`];
//! [`minilm::MiniLm`] is the all-MiniLM-L6-v2 sentence encoder (384-d unit vectors, weights
//! shipped in `fixtures/text/`), not yet wired into a prior.

pub mod clip;
pub mod minilm;
pub mod vocabulary;

use candle_core::{Device, Result, Tensor};

/// Turns prompts into condition vectors. Encode once per run, never inside a sampling loop.
pub trait TextEncoder {
    /// Width of the condition vectors.
    fn dim(&self) -> usize;
    /// `[prompts.len(), dim]` condition vectors.
    fn encode(&self, prompts: &[&str], device: &Device) -> Result<Tensor>;
}
