//! Start noise that reproduces a given motion through the prior's sampler: what RG-DNO needs to
//! start optimising from a retrieved motion, and what editing a motion with DNO starts from.
//!
//! Three stages:
//! 1. [`crate::diffusion::DdimSampler::invert`] with fixed-point iterations, which inverts the discrete sampler
//!    rather than the ODE;
//! 2. when polishing, each sample's noise is first rescaled to unit RMS, the shell where
//!    Gaussian start noise lies. A denoiser whose x̂0 at t ≈ 0 does not reproduce a clean
//!    input exactly is inverted to noise far off that shell (RMS 183 for a 9,000-step prior
//!    that uses temporal context), from which the polish cannot recover. Then the feature
//!    polish: DNO ([`crate::dno::optimize`]) on the noise, minimising the
//!    MSE of the sampled motion's normalised features to the target's. It is well conditioned
//!    (no integrated trajectory) and brings the motion close from any start;
//! 3. the joint polish: DNO on the mean world-frame joint error, which weighs the
//!    trajectory as the user sees it.
//!
//! Under [`Schedule::UntilMet`] each polish ends once its loss stalls, the joint polish also at
//! a check within [`INVERSION_TOLERANCE_M`] of the target; with
//! [`InversionConfig::stop_within_tolerance`] the feature polish also ends within that distance
//! (the joint polish is then skipped) and the joint polish at any step within it.

use candle_core::{DType, Result, Tensor};

use crate::diffusion::Guidance;
use crate::dno::{self, DnoConfig, DnoStep, UnrolledDdim};
use crate::generation::schedule::{Schedule, INVERSION_TOLERANCE_M};
use crate::generation::stall::Stall;
use crate::numeric::mean;
use crate::prior::Prior;

/// Settings of [`invert_motion`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InversionConfig {
    /// DDIM steps of the sampler the noise is for (default 10, DNO's).
    pub ddim_steps: usize,
    /// The noise is for every `sampler_stride`-th timestep of that sampler, counted down
    /// from its start ([`crate::diffusion::DdimSampler::every`]; default 1: every one).
    pub sampler_stride: usize,
    /// Fixed-point iterations per inversion step (default 8; 0 = classic DDIM inversion).
    pub fixed_point_iterations: usize,
    /// DNO steps polishing the noise against the normalised-feature MSE (default 100; 0 =
    /// none).
    pub feature_polish_steps: usize,
    /// Peak Adam learning rate of the feature polish, decayed along a cosine (default 0.05).
    pub feature_polish_lr: f64,
    /// DNO steps polishing the noise against the world-frame joint error, after the feature
    /// polish (default 100; 0 = none).
    pub polish_steps: usize,
    /// Peak Adam learning rate of the joint polish, decayed along a cosine (default 0.02).
    pub polish_lr: f64,
    /// Classifier-free guidance scale of the sampler the noise is for (default 1: the
    /// conditional model alone). RG-DNO inverts for the guided sampler it then optimises
    /// through.
    pub guidance: f64,
    /// When each polish ends (default [`Schedule::Paper`]: its whole budget; RG-DNO passes its
    /// run's schedule). Under [`Schedule::UntilMet`] a polish ends once its loss has stalled
    /// ([`Stall`]), the joint polish also at a check within [`INVERSION_TOLERANCE_M`] of the
    /// target.
    pub schedule: Schedule,
    /// Under [`Schedule::UntilMet`], also end the feature polish at a check within
    /// [`INVERSION_TOLERANCE_M`] (then skipping the joint polish) and the joint polish at any
    /// step within it, each handing on the iterate judged (default false; RG-DNO sets it for a
    /// program without counts, whose counted extrema a mean joint distance does not judge).
    pub stop_within_tolerance: bool,
}

impl InversionConfig {
    /// DDIM inversion alone (`fixed_point_iterations` per step, 0 = classic), no polish.
    pub fn unpolished(ddim_steps: usize, fixed_point_iterations: usize) -> Self {
        Self { ddim_steps, fixed_point_iterations, feature_polish_steps: 0, polish_steps: 0, ..Self::default() }
    }
}

impl Default for InversionConfig {
    fn default() -> Self {
        Self {
            ddim_steps: 10,
            sampler_stride: 1,
            fixed_point_iterations: 8,
            feature_polish_steps: 100,
            feature_polish_lr: 0.05,
            polish_steps: 100,
            polish_lr: 0.02,
            guidance: 1.0,
            schedule: Schedule::Paper,
            stop_within_tolerance: false,
        }
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
/// conditioned on `text` `[batch, text_dim]`, for the sampler with `config.guidance` (1 by
/// default: no guidance, so the noise is valid for the conditional model alone).
/// `on_polish_step` reports both polishes in turn (the feature polish's loss is the
/// normalised-feature MSE, the joint polish's the mean joint error in metres, per sample).
pub fn invert_motion(
    prior: &Prior,
    x0: &Tensor,
    text: &Tensor,
    config: &InversionConfig,
    mut on_polish_step: impl FnMut(&DnoStep),
) -> Result<Inverted> {
    let guidance = Guidance { scale: config.guidance }.for_text(text)?;
    let solver = UnrolledDdim::new(&prior.mdm, text.clone(), guidance, config.ddim_steps)?.every(config.sampler_stride);
    let z = solver.sampler.invert(&prior.mdm, x0, text, guidance, config.fixed_point_iterations)?;
    if config.feature_polish_steps == 0 && config.polish_steps == 0 {
        let x = solver.sampler.sample(&prior.mdm, &z, text, guidance)?;
        return Ok(Inverted { z, x });
    }
    let rms = z.sqr()?.mean_keepdim((1, 2))?.sqrt()?;
    let mut z = z.broadcast_div(&rms)?;
    let fast = config.schedule == Schedule::UntilMet;
    // With `stop_within_tolerance` both polishes end once the motion is within the tolerance
    // of the target: the feature polish at its checks, the joint polish at any step (its
    // criterion is that distance), so that it is skipped when the feature polish got there.
    // Each then hands on its best iterate, the one judged, not the noise one update past it.
    let within = fast && config.stop_within_tolerance;
    let polish = |steps: usize, lr: f64| DnoConfig {
        steps,
        lr,
        lr_warmup_steps: 0,
        lr_decay_steps: Some(steps),
        decorrelate_scale: 0.0,
        ddim_steps: config.ddim_steps,
        keep_best: within,
        ..DnoConfig::default()
    };
    let target = x0.detach();
    let joints = prior.to_joints(&target)?.detach();
    let mut reproduced = false;
    if config.feature_polish_steps > 0 {
        let criterion = |x: &Tensor| (x - &target)?.sqr()?.mean((1, 2));
        let settings = polish(config.feature_polish_steps, config.feature_polish_lr);
        let mut stall = Stall::default();
        let done = |s: &DnoStep, x: &Tensor| {
            let stalled = stall.stalled_after(mean(&s.loss), 0);
            if within && stall.at_check(0) {
                let error_m = mean_joint_distance(&prior.to_joints(x)?, &joints)?.to_dtype(DType::F64)?.to_vec1()?;
                reproduced = mean(&error_m) <= INVERSION_TOLERANCE_M;
            }
            Ok(vec![fast && (stalled || reproduced); s.loss.len()])
        };
        z = dno::optimize_until(&solver, criterion, &z, &settings, &mut on_polish_step, done)?.z;
    }
    if config.polish_steps > 0 && !reproduced {
        let criterion = |x: &Tensor| mean_joint_distance(&prior.to_joints(x)?, &joints);
        let settings = polish(config.polish_steps, config.polish_lr);
        let mut stall = Stall::default();
        let done = |s: &DnoStep, _: &Tensor| {
            let error_m = mean(&s.loss);
            let ended = fast
                && (stall.stalled_after(error_m, 0)
                    || ((within || stall.at_check(0)) && error_m <= INVERSION_TOLERANCE_M));
            Ok(vec![ended; s.loss.len()])
        };
        z = dno::optimize_until(&solver, criterion, &z, &settings, &mut on_polish_step, done)?.z;
    }
    // The optimiser reports the motion before its last update; sample the final noise.
    let x = solver.sampler.sample(&prior.mdm, &z, text, guidance)?;
    Ok(Inverted { z, x })
}

/// Mean over frames and joints of the Euclidean distance between joint sets `[B, T, 22, 3]`,
/// per sample `[B]`, m.
pub fn mean_joint_distance(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let (batch, ..) = a.dims4()?;
    // A small floor keeps the square root differentiable where a joint matches exactly.
    ((a - b)?.sqr()?.sum(3)? + 1e-12)?.sqrt()?.reshape((batch, ()))?.mean(1)
}
