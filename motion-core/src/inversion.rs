//! Start noise that reproduces a given motion through the prior's sampler: what RG-DNO needs to
//! start optimising from a retrieved motion, and what editing a motion with DNO starts from.
//!
//! Two stages:
//! 1. [`DdimSampler::invert`] with fixed-point iterations, which inverts the discrete sampler
//!    rather than the ODE. Alone it leaves a residual, mostly in the root trajectory: the
//!    integrated root velocity turns small per-frame errors into decimetres;
//! 2. optional polishing: DNO ([`crate::dno::optimize`]) on the noise, minimising the mean
//!    world-frame joint error of the sampled motion to the target, which weighs the trajectory
//!    as the user sees it.

use candle_core::{Result, Tensor};

use crate::diffusion::Guidance;
use crate::dno::{self, DnoConfig, DnoStep, UnrolledDdim};
use crate::prior::Prior;

/// Settings of [`invert_motion`].
#[derive(Debug, Clone, PartialEq)]
pub struct InversionConfig {
    /// DDIM steps of the sampler the noise is for (default 10, DNO's).
    pub ddim_steps: usize,
    /// Fixed-point iterations per inversion step (default 8; 0 = classic DDIM inversion).
    pub fixed_point_iterations: usize,
    /// DNO steps polishing the noise against the joint error (default 100; 0 = none).
    pub polish_steps: usize,
    /// Peak Adam learning rate of the polish, decayed along a cosine (default 0.02).
    pub polish_lr: f64,
}

impl Default for InversionConfig {
    fn default() -> Self {
        Self { ddim_steps: 10, fixed_point_iterations: 8, polish_steps: 100, polish_lr: 0.02 }
    }
}

/// Result of [`invert_motion`].
#[derive(Debug, Clone)]
pub struct Inverted {
    /// Start noise `[batch, frames, 263]` for a `ddim_steps` sampler.
    pub z: Tensor,
    /// The motion the sampler makes from `z`, normalised features `[batch, frames, 263]`.
    pub x: Tensor,
}

/// Finds noise z with `sample(z) ≈ x0` for normalised features `x0` `[batch, frames, 263]`
/// conditioned on `text` `[batch, text_dim]` (no guidance, so the noise is valid for the
/// conditional model alone). `on_polish_step` reports the polish (its loss is the mean joint
/// error in metres per sample).
pub fn invert_motion(
    prior: &Prior,
    x0: &Tensor,
    text: &Tensor,
    config: &InversionConfig,
    on_polish_step: impl FnMut(&DnoStep),
) -> Result<Inverted> {
    let solver = UnrolledDdim::new(&prior.mdm, text.clone(), Guidance::none(), config.ddim_steps)?;
    let z = solver.sampler.invert(&prior.mdm, x0, text, Guidance::none(), config.fixed_point_iterations)?;
    if config.polish_steps == 0 {
        let x = solver.sampler.sample(&prior.mdm, &z, text, Guidance::none())?;
        return Ok(Inverted { z, x });
    }
    let target = prior.to_joints(&x0.detach())?.detach();
    let criterion = |x: &Tensor| mean_joint_distance(&prior.to_joints(x)?, &target);
    let polish = DnoConfig {
        steps: config.polish_steps,
        lr: config.polish_lr,
        lr_warmup_steps: 0,
        lr_decay_steps: Some(config.polish_steps),
        decorrelate_scale: 0.0,
        ddim_steps: config.ddim_steps,
        ..DnoConfig::default()
    };
    let result = dno::optimize(&solver, criterion, &z, &polish, on_polish_step)?;
    // The optimiser reports the motion before its last update; sample the final noise.
    let x = solver.sampler.sample(&prior.mdm, &result.z, text, Guidance::none())?;
    Ok(Inverted { z: result.z, x })
}

/// Mean over frames and joints of the Euclidean distance between joint sets `[B, T, 22, 3]`,
/// per sample `[B]`, m.
pub fn mean_joint_distance(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let (batch, ..) = a.dims4()?;
    // A small floor keeps the square root differentiable where a joint matches exactly.
    ((a - b)?.sqr()?.sum(3)? + 1e-12)?.sqrt()?.reshape((batch, ()))?.mean(1)
}
