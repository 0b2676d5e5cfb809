//! Gaussian diffusion over normalised 263-d features: the denoiser contract, the cosine
//! schedule, DDIM sampling and inversion.

use candle_core::{Result, Tensor};

pub mod ddim;
pub mod guidance;
pub mod noise;
pub mod schedule;
#[cfg(test)]
mod test_denoiser;

pub use ddim::{guided_move, respaced_timesteps, DdimMove, DdimProgress, DdimSampler};
pub use guidance::Guidance;
pub use schedule::NoiseSchedule;

/// Errors configuring a noise schedule or a respaced sampler.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DiffusionError {
    /// A schedule with zero timesteps.
    #[error("a noise schedule needs at least one timestep")]
    EmptySchedule,
    /// No integer stride `s` gives `len(range(0, timesteps, s)) == steps` (MDM's "ddimN" rule).
    #[error("cannot respace {timesteps} timesteps into exactly {steps} DDIM steps with an integer stride")]
    NoStride {
        /// Timesteps of the original schedule.
        timesteps: usize,
        /// Requested DDIM steps.
        steps: usize,
    },
}

/// A network that predicts the clean sample x̂0 from a noisy one (MDM predicts x0, not ε).
pub trait Denoiser {
    /// - `x_t`: `[batch, frames, 263]`, normalised features at diffusion step `timesteps`;
    /// - `timesteps`: `[batch]` u32 on the original 0..999 scale (also under respacing);
    /// - `text`: `[batch, text_dim]` condition vectors; an all-zero row is the unconditional
    ///   branch of classifier-free guidance (MDM replaces the text embedding by zeros).
    ///
    /// Returns x̂0, `[batch, frames, 263]`. Inference mode: no dropout.
    fn predict_x0(&self, x_t: &Tensor, timesteps: &Tensor, text: &Tensor) -> Result<Tensor>;

    /// One DDIM move of `x_t` (`[batch, frames, 263]`, at `step.timestep`) with the guided
    /// x̂0: `step.c_x·x_t + step.c_0·x̂0`, `guidance` already resolved by
    /// [`Guidance::for_text`]. Differentiable in `x_t`. The default composes
    /// [`Self::predict_x0`] and the update ([`guided_move`]); MDM's CPU path overrides it with
    /// one fused op, so an unrolled sampler records one autograd node per step.
    fn ddim_move(&self, x_t: &Tensor, text: &Tensor, guidance: Guidance, step: DdimMove) -> Result<Tensor> {
        guided_move(self, x_t, text, guidance, step)
    }

    /// Width of the condition vectors.
    fn text_dim(&self) -> usize;
}
