//! Constrained generation: every [`Method`] dispatched from one function, [`generate`]: the
//! prior's unconstrained samples, the IK and IK+Reg baselines that optimise the motion directly
//! (ProgMoGen's `task_configs_eval_others`, `direct`), ProgMoGen+DNO, which optimises the
//! start noise through the unrolled DDIM sampler, and RG-DNO ([`crate::generation::rgdno`]), which starts
//! DNO from a retrieved motion's noise blended with random noise.
//!
//! Every method starts from the same seeded noise `z0` `[B, T, 263]` and the same solver `G`
//! (K-step DDIM of the prior with the task's prompt and classifier-free guidance): the
//! unconstrained motion is `G(z0)`, IK starts from `G(z0)`, DNO optimises `z` from `z0`. Losses
//! are the compiled program's `Σ wᵢ·Eᵢ` on the joints recovered from the features
//! ([`crate::generation::objective`]); terms that stay near "the initial motion" compare with `G(z0)`
//! (ProgMoGen's `pred_res_0`).
//!
//! Every method's motion then goes through the finishing stages ([`crate::generation::postprocess`]): the
//! kinematic refinement against the program's geometric constraints ([`crate::generation::refine`],
//! switchable off with [`GenerationConfig::refine`]) and the contact-aware clean-up
//! ([`fn@crate::cleanup::foot_lock`], switchable off with [`GenerationConfig::foot_lock`]): the
//! returned joints are the finished ones, the network's joints are kept beside them so that a
//! report can give every figure before and after both.
//!
//! RG-DNO needs the program's relational parse and a retrieval database; without them, or when
//! no database motion passes the retrieval, it falls back to DNO and says why
//! ([`Generation::fallback`]).

mod direct;
pub mod inversion;
pub mod method;
pub mod objective;
pub mod postprocess;
pub mod refine;
pub mod rgdno;
pub mod schedule;
pub mod side_by_side;
pub mod stall;

use std::time::Instant;

use candle_core::{Device, Tensor};

use crate::diffusion::noise::gaussian;
use crate::diffusion::Guidance;
use crate::dno::{optimize_with_restarts, DnoConfig, Solver, UnrolledDdim};
use crate::numeric::mean;
use crate::prior::Prior;
use crate::representation::FEATURE_DIM;
use method::{Generated, GenerationConfig, GenerationError, Method, Task};
use objective::{program_objective, Guards};
use postprocess::{finish, finishing_foot_lock, Unfinished};
use rgdno::candidates::RetrievalDatabase;
use rgdno::config::RgDnoConfig;
use rgdno::error::{RetrievalError, RgDnoError};
use rgdno::report::RgDnoReport;
use rgdno::{generate_rg_dno, RgDnoTask};
use schedule::StageEnd;

/// What RG-DNO retrieves from and how it runs its stages.
#[derive(Debug, Clone, Copy)]
pub struct Retrieval<'a> {
    /// The motions retrieval crops (by default the corpus's train split).
    pub database: &'a RetrievalDatabase,
    /// RG-DNO's stages.
    pub rg_dno: &'a RgDnoConfig,
}

/// What a running method reports.
#[derive(Debug, Clone)]
pub enum Event<'a> {
    /// An optimisation step of a stage (`round` is the restart).
    Step {
        /// The method or RG-DNO stage.
        stage: &'a str,
        /// The restart.
        round: usize,
        /// Steps done.
        step: usize,
        /// Steps of the stage.
        steps: usize,
        /// Mean loss over the samples.
        loss: f64,
        /// The sample, where each runs the stage on its own (RG-DNO's stages after the
        /// inversion, side by side); `None` where the stage runs for every sample.
        sample: Option<usize>,
    },
    /// Something the user should read: the retrieval database opened, a fallback and its reason.
    Note(String),
}

/// The outcome of [`generate`].
#[derive(Debug, Clone)]
pub struct Generation {
    /// The motions.
    pub generated: Generated,
    /// The method that ran: the configured one, or DNO where RG-DNO fell back.
    pub method: Method,
    /// What each RG-DNO stage did (RG-DNO runs only).
    pub rg_dno: Option<RgDnoReport>,
    /// Why the method that ran is not the one asked for (RG-DNO falling back to DNO).
    pub fallback: Option<String>,
}

/// Why [`generate`] failed.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    /// A method failed or a setting is unusable.
    #[error(transparent)]
    Method(#[from] GenerationError),
    /// RG-DNO's retrieval failed (a reason to fall back to DNO never reaches the caller).
    #[error(transparent)]
    Retrieval(#[from] RetrievalError),
}

/// Generates `config.samples` motions for `task` with `config.method`; RG-DNO retrieves with
/// `retrieval` and falls back to DNO (telling `on` why) without a relational parse, without a
/// retrieval database, or when nothing is retrieved.
///
/// `on` gets every optimisation step.
pub fn generate(
    prior: &Prior,
    task: Task<'_>,
    retrieval: Option<Retrieval<'_>>,
    config: &GenerationConfig,
    device: &Device,
    mut on: impl FnMut(Event<'_>),
) -> Result<Generation, GenerateError> {
    let start = match config.method {
        Method::Unconstrained => FromSample::Unconstrained,
        Method::Ik => FromSample::Direct { smoothness: 0.0 },
        Method::IkReg => FromSample::Direct { smoothness: config.direct.smoothness_weight },
        Method::Dno => FromSample::Dno,
        Method::RgDno => {
            let why = match rg_dno(prior, task, retrieval, config, device, &mut on) {
                Ok((generated, report)) => {
                    return Ok(Generation { generated, method: Method::RgDno, rg_dno: Some(report), fallback: None })
                }
                Err(RgDnoError::Retrieval(e)) => return Err(e.into()),
                Err(RgDnoError::Generation(e)) => return Err(e.into()),
                Err(reason) => reason.to_string(),
            };
            on(Event::Note(format!("RG-DNO falls back to DNO: {why}")));
            let dno = GenerationConfig { method: Method::Dno, ..config.clone() };
            let generated = from_sample(prior, task, FromSample::Dno, &dno, device, &mut on)?;
            return Ok(Generation { generated, method: Method::Dno, rg_dno: None, fallback: Some(why) });
        }
    };
    let generated = from_sample(prior, task, start, config, device, &mut on)?;
    Ok(Generation { generated, method: config.method, rg_dno: None, fallback: None })
}

/// RG-DNO on the database of `retrieval`.
fn rg_dno(
    prior: &Prior,
    Task { program, compiled }: Task<'_>,
    retrieval: Option<Retrieval<'_>>,
    config: &GenerationConfig,
    device: &Device,
    on: &mut impl FnMut(Event<'_>),
) -> Result<(Generated, RgDnoReport), RgDnoError> {
    if program.relational_parse.is_none() {
        return Err(RgDnoError::NoParse);
    }
    let Retrieval { database, rg_dno } = retrieval.ok_or(RgDnoError::NoDatabase)?;
    generate_rg_dno(prior, RgDnoTask { program, compiled, database }, config, rg_dno, device, |p| {
        on(Event::Step {
            stage: p.stage.name(),
            round: p.round,
            step: p.step,
            steps: p.steps,
            loss: p.loss,
            sample: p.sample,
        })
    })
}

/// The methods that start from the prior's sample `G(z0)`.
#[derive(Debug, Clone, Copy)]
enum FromSample {
    /// `G(z0)` itself.
    Unconstrained,
    /// IK (`smoothness` 0) or IK+Reg: Adam on the features from `G(z0)`.
    Direct { smoothness: f64 },
    /// DNO: the noise optimised from `z0`, with `config.dno.restarts` restarts.
    Dno,
}

/// Runs `method` from the seeded noise `z0` of `config` and finishes its motion.
fn from_sample(
    prior: &Prior,
    task: Task<'_>,
    method: FromSample,
    config: &GenerationConfig,
    device: &Device,
    on: &mut impl FnMut(Event<'_>),
) -> Result<Generated, GenerationError> {
    let Task { program, compiled } = task;
    let frames = compiled.frames();
    config.check(frames)?;
    let start = Instant::now();
    let stage = config.method.to_string();
    let mut progress = |round: usize, step: usize, steps: usize, loss: f64| {
        on(Event::Step { stage: &stage, round, step: step + 1, steps, loss, sample: None })
    };
    let shape = (config.samples, frames, FEATURE_DIM);
    let text = prior.encode_text(&vec![program.text.as_str(); config.samples], device)?;
    let guidance = Guidance { scale: config.guidance }.for_text(&text)?;
    let mut solver = UnrolledDdim::new(&prior.mdm, text, guidance, config.dno.ddim_steps)?;
    let z0 = gaussian(shape, config.seed, device)?;
    let x0 = solver.sampler.sample(solver.denoiser, &z0, &solver.text, solver.guidance)?;
    if let Some(start) = config.dno.start_timestep {
        solver = solver.starting_late(start, &x0)?;
    }
    let initial_joints = prior.to_joints(&x0)?;
    let (features, loss_history): (Tensor, Vec<Vec<f64>>) = match method {
        FromSample::Unconstrained => (x0, vec![Vec::new(); config.samples]),
        FromSample::Direct { smoothness } => {
            let plain = program_objective(prior, compiled, &initial_joints, Guards::NONE);
            direct::optimize_motion(&x0, &plain, &config.direct, smoothness, |step, loss| {
                progress(0, step, config.direct.steps, loss)
            })?
        }
        FromSample::Dno => {
            let dno = DnoConfig { seed: config.seed, ..config.dno.clone() };
            let guarded = program_objective(prior, compiled, &initial_joints, config.guards);
            let lock = finishing_foot_lock(program, config);
            let mut stage_end =
                StageEnd::shown(config.schedule, prior, compiled, &initial_joints, dno.lr_warmup_steps, &lock);
            let run = optimize_with_restarts(
                &solver as &dyn Solver,
                guarded,
                shape,
                device,
                &dno,
                |round, s| progress(round, s.step, s.steps, mean(&s.loss)),
                |round, s, x| stage_end.done(round, s, x),
            )?;
            let history = run.best.history.into_iter().map(|h| h.loss).collect();
            (run.best.x, history)
        }
    };
    finish(prior, task, config, Unfinished { features, initial_joints, loss_history }, start)
}

/// The shipped prior (`fixtures/model/prior.safetensors`, with the text encoder of
/// `fixtures/text/`), for the tests of the stages.
#[cfg(test)]
pub(crate) fn shipped_prior(device: &candle_core::Device) -> Prior {
    let fixtures = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures");
    Prior::load(&fixtures.join("model/prior.safetensors"), &fixtures.join("text"), device).unwrap()
}
