//! The map z → x that DNO differentiates through: normally the unrolled DDIM sampler of the
//! frozen prior (DNO's `ddim_loop_with_gradient`, anchors §2.2).

use candle_core::{Result, Tensor};

use super::DnoConfig;
use crate::diffusion::{DdimSampler, Denoiser, Guidance, NoiseSchedule};

/// A differentiable map from start noise z to a motion x, both `[batch, frames, 263]`
/// (normalised features). Any `Fn(&Tensor) -> Result<Tensor>` is one.
pub trait Solver {
    /// x = G(z), keeping the autograd graph back to `z`.
    fn solve(&self, z: &Tensor) -> Result<Tensor>;
}

impl<F: Fn(&Tensor) -> Result<Tensor>> Solver for F {
    fn solve(&self, z: &Tensor) -> Result<Tensor> {
        self(z)
    }
}

/// The normal solver: K-step DDIM (eta = 0) of a denoiser from z = x at the last spaced
/// timestep, with the whole graph kept ([`DdimSampler::sample_unrolled`]).
///
/// Cost per DNO step: K guided denoiser calls forward and backward (2·batch rows each when
/// guidance is active). DNO optimises with the empty text and guidance 2.5; ProgMoGen with the
/// task's prompt.
#[derive(Debug, Clone)]
pub struct UnrolledDdim<'a, D: Denoiser + ?Sized> {
    /// The respaced sampler.
    pub sampler: DdimSampler,
    /// The frozen prior, e.g. `&prior.mdm`.
    pub denoiser: &'a D,
    /// Condition vectors `[batch, text_dim]`, one row per sample of z.
    pub text: Tensor,
    /// Classifier-free guidance.
    pub guidance: Guidance,
}

impl<'a, D: Denoiser + ?Sized> UnrolledDdim<'a, D> {
    /// DDIM with `ddim_steps` steps over MDM's cosine schedule (ddim10: timesteps 900, …, 0).
    pub fn new(denoiser: &'a D, text: Tensor, guidance: Guidance, ddim_steps: usize) -> Result<Self> {
        let sampler = DdimSampler::new(&NoiseSchedule::mdm(), ddim_steps).map_err(candle_core::Error::wrap)?;
        Ok(Self { sampler, denoiser, text, guidance })
    }

    /// [`Self::new`] with `config.ddim_steps`.
    pub fn from_config(denoiser: &'a D, text: Tensor, guidance: Guidance, config: &DnoConfig) -> Result<Self> {
        Self::new(denoiser, text, guidance, config.ddim_steps)
    }
}

impl<D: Denoiser + ?Sized> Solver for UnrolledDdim<'_, D> {
    fn solve(&self, z: &Tensor) -> Result<Tensor> {
        self.sampler.sample_unrolled(self.denoiser, z, &self.text, self.guidance)
    }
}
