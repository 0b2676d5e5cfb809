//! Constrained generation methods in one harness: the prior's unconstrained samples, the IK and
//! IK+Reg baselines that optimise the motion directly (ProgMoGen's `task_configs_eval_others`),
//! and ProgMoGen+DNO, which optimises the start noise through the unrolled DDIM sampler.
//!
//! Every method starts from the same seeded noise `z0` `[B, T, 263]` and the same solver `G`
//! (K-step DDIM of the prior with the task's prompt and classifier-free guidance): the
//! unconstrained motion is `G(z0)`, IK starts from `G(z0)`, DNO optimises `z` from `z0`. Losses
//! are the compiled program's `Σ wᵢ·Eᵢ` on the joints recovered from the features; terms that
//! stay near "the initial motion" compare with `G(z0)` (ProgMoGen's `pred_res_0`).

mod direct;

use std::fmt;
use std::time::Instant;

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

pub use direct::DirectConfig;

use crate::constraints::{CompiledProgram, ConstraintError};
use crate::diffusion::noise::gaussian;
use crate::diffusion::Guidance;
use crate::dno::{optimize_with_restarts, DnoConfig, Solver, UnrolledDdim};
use crate::prior::Prior;
use crate::program::TaskProgram;
use crate::representation::FEATURE_DIM;

/// A generation method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// The prior's sample `G(z0)` for the prompt, ignoring the constraints.
    Unconstrained,
    /// Optimise the motion features directly from `G(z0)` (ProgMoGen's IK baseline).
    Ik,
    /// IK plus a smoothness term on consecutive frames (ProgMoGen's IK+reg baseline).
    IkReg,
    /// Optimise the start noise through the prior (ProgMoGen's programmable generation with
    /// DNO's optimiser).
    Dno,
}

impl Method {
    /// Every method, baselines first.
    pub const ALL: [Method; 4] = [Method::Unconstrained, Method::Ik, Method::IkReg, Method::Dno];

    /// The kebab-case name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Unconstrained => "unconstrained",
            Method::Ik => "ik",
            Method::IkReg => "ik-reg",
            Method::Dno => "dno",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Settings of a generation run (all serialisable into its report).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GenerationConfig {
    /// The method.
    pub method: Method,
    /// Motions generated together (the batch B).
    pub samples: usize,
    /// Seed of the start noise `z0` (and of DNO's restarts: restart r uses `seed + r`).
    pub seed: u64,
    /// Classifier-free guidance of the solver (default 2.5 with the task's prompt, as
    /// ProgMoGen).
    pub guidance: f64,
    /// DNO's optimiser (its `seed` is replaced by [`GenerationConfig::seed`]; its `ddim_steps`
    /// sets the solver of every method).
    pub dno: DnoConfig,
    /// The IK baselines' optimiser.
    pub direct: DirectConfig,
}

impl GenerationConfig {
    /// Defaults for `method`: one sample, seed 0, guidance 2.5, DNO's and ProgMoGen's settings.
    pub fn new(method: Method) -> Self {
        Self {
            method,
            samples: 1,
            seed: 0,
            guidance: Guidance::MDM_SCALE,
            dno: DnoConfig::default(),
            direct: DirectConfig::default(),
        }
    }
}

/// Why generation failed.
#[derive(Debug, thiserror::Error)]
pub enum GenerationError {
    /// The program does not compile.
    #[error(transparent)]
    Program(#[from] ConstraintError),
    /// A setting cannot be used.
    #[error("invalid setting: {0}")]
    Setting(String),
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
}

/// Progress of a running method.
#[derive(Debug, Clone)]
pub struct Progress {
    /// Restart index (DNO) or 0.
    pub round: usize,
    /// Step within the round.
    pub step: usize,
    /// Steps per round.
    pub steps: usize,
    /// Mean criterion loss over the samples at this step.
    pub loss: f64,
}

/// The outcome of [`generate`].
#[derive(Debug, Clone)]
pub struct Generated {
    /// Normalised features `[B, T, 263]`.
    pub features: Tensor,
    /// Joint positions `[B, T, 22, 3]` (m, y up).
    pub joints: Tensor,
    /// The unconstrained start `G(z0)` as joints, `[B, T, 22, 3]`.
    pub initial_joints: Tensor,
    /// Per sample, the criterion loss at every optimisation step (empty when unconstrained).
    pub loss_history: Vec<Vec<f64>>,
    /// Wall-clock seconds of the method (excluding loading the prior).
    pub seconds: f64,
}

/// Generates `config.samples` motions for `program` with `config.method`.
///
/// `progress` is called after every optimisation step.
pub fn generate(
    prior: &Prior,
    program: &TaskProgram,
    compiled: &CompiledProgram,
    config: &GenerationConfig,
    device: &Device,
    mut progress: impl FnMut(&Progress),
) -> Result<Generated, GenerationError> {
    if config.samples == 0 {
        return Err(GenerationError::Setting("samples must be at least 1".into()));
    }
    if !(config.guidance.is_finite() && config.guidance >= 0.0) {
        return Err(GenerationError::Setting(format!("guidance must be finite and ≥ 0, got {}", config.guidance)));
    }
    let start = Instant::now();
    let frames = compiled.frames();
    let shape = (config.samples, frames, FEATURE_DIM);
    let text = prior.encode_text(&vec![program.text.as_str(); config.samples], device)?;
    let guidance = Guidance { scale: config.guidance }.for_text(&text)?;
    let solver = UnrolledDdim::new(&prior.mdm, text, guidance, config.dno.ddim_steps)?;
    let z0 = gaussian(shape, config.seed, device)?;
    let x0 = solver.sampler.sample(solver.denoiser, &z0, &solver.text, solver.guidance)?;
    let initial_joints = prior.to_joints(&x0)?;
    let criterion = |x: &Tensor| -> candle_core::Result<Tensor> {
        let joints = prior.to_joints(x)?;
        Ok(compiled.evaluate(&joints, Some(&initial_joints)).map_err(candle_core::Error::wrap)?.total)
    };
    let (features, loss_history) = match config.method {
        Method::Unconstrained => (x0, vec![Vec::new(); config.samples]),
        Method::Ik | Method::IkReg => {
            let smoothness = if config.method == Method::IkReg { config.direct.smoothness_weight } else { 0.0 };
            direct::optimize_motion(&x0, &criterion, &config.direct, smoothness, |step, loss| {
                progress(&Progress { round: 0, step, steps: config.direct.steps, loss })
            })?
        }
        Method::Dno => {
            let dno = DnoConfig { seed: config.seed, ..config.dno.clone() };
            let run = optimize_with_restarts(&solver as &dyn Solver, criterion, shape, device, &dno, |round, s| {
                let loss = s.loss.iter().sum::<f64>() / s.loss.len().max(1) as f64;
                progress(&Progress { round, step: s.step, steps: s.steps, loss })
            })?;
            let history = run.best.history.into_iter().map(|h| h.loss).collect();
            (run.best.x, history)
        }
    };
    let joints = prior.to_joints(&features)?;
    Ok(Generated { features, joints, initial_joints, loss_history, seconds: start.elapsed().as_secs_f64() })
}
