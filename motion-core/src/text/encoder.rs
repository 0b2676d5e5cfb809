//! What a text encoder is: prompts in, condition vectors out.

use candle_core::{Device, Result, Tensor};

/// Turns prompts into condition vectors. Encode once per run, never inside a sampling loop.
pub trait TextEncoder {
    /// Width of the condition vectors.
    fn dim(&self) -> usize;
    /// `[prompts.len(), dim]` condition vectors.
    fn encode(&self, prompts: &[&str], device: &Device) -> Result<Tensor>;
}
