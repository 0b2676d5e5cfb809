//! How every report draws its samples from the prior, and reads their joints.

use candle_core::Tensor;

use crate::diffusion::Guidance;
use crate::motion::tensor_to_poses;
use crate::prior::{Prior, Sampling};
use crate::skeleton::Pose;

/// How every report draws a sample from the prior: DDIM with classifier-free guidance, from
/// seeded start noise.
#[derive(Debug, Clone, Copy)]
pub struct Denoising {
    /// DDIM steps (default 50).
    pub ddim_steps: usize,
    /// Guidance scale (default 2.5, MDM's).
    pub guidance: f64,
    /// The first seed; each report says how it derives the others.
    pub seed: u64,
}

impl Denoising {
    /// The sampling request for `batch` motions of `frames` frames of `prompt`, from the noise
    /// of seed [`Self::seed`] + `seed_offset`.
    pub fn request<'a>(&self, prompt: &'a str, frames: usize, batch: usize, seed_offset: u64) -> Sampling<'a> {
        Sampling {
            prompt,
            frames,
            batch,
            seed: self.seed + seed_offset,
            steps: self.ddim_steps,
            guidance: Guidance { scale: self.guidance },
        }
    }
}

impl Default for Denoising {
    fn default() -> Self {
        Self { ddim_steps: 50, guidance: Guidance::MDM_SCALE, seed: 0 }
    }
}

/// How the prior's per-label and per-family reports draw their unconstrained samples.
#[derive(Debug, Clone, Copy)]
pub struct ReportSampling {
    /// Samples per label or per family (default 32).
    pub samples: usize,
    /// Frames per sample (default 120, 6 s: a corpus window).
    pub frames: usize,
    /// Steps, guidance and the seed of the first label's or family's noise.
    pub denoising: Denoising,
}

impl Default for ReportSampling {
    fn default() -> Self {
        Self { samples: 32, frames: 120, denoising: Denoising::default() }
    }
}

/// Joint positions of normalised features `[batch, frames, 263]` as per-sample pose lists.
pub fn joints_of(prior: &Prior, normalized: &Tensor) -> candle_core::Result<Vec<Vec<Pose>>> {
    let joints = prior.to_joints(normalized)?;
    tensor_to_poses(&joints)
}
