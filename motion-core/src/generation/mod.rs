//! Constrained generation methods in one harness: the prior's unconstrained samples, the IK and
//! IK+Reg baselines that optimise the motion directly (ProgMoGen's `task_configs_eval_others`),
//! and ProgMoGen+DNO, which optimises the start noise through the unrolled DDIM sampler.
//!
//! Every method starts from the same seeded noise `z0` `[B, T, 263]` and the same solver `G`
//! (K-step DDIM of the prior with the task's prompt and classifier-free guidance): the
//! unconstrained motion is `G(z0)`, IK starts from `G(z0)`, DNO optimises `z` from `z0`. Losses
//! are the compiled program's `Σ wᵢ·Eᵢ` on the joints recovered from the features; terms that
//! stay near "the initial motion" compare with `G(z0)` (ProgMoGen's `pred_res_0`).
//!
//! Every method's motion then goes through the kinematic refinement against the program's
//! geometric constraints ([`crate::refine`], a bounded smooth offset layer on a rigid skeleton,
//! switchable off with [`GenerationConfig::refine`]) and the contact-aware clean-up
//! ([`crate::cleanup::foot_lock`], switchable off with [`GenerationConfig::foot_lock`]): the
//! returned joints are the finished ones, the network's joints are kept beside them so that a
//! report can give every figure before and after both.

mod direct;

use std::fmt;
use std::time::Instant;

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

pub use direct::DirectConfig;

use crate::cleanup::{foot_lock, FootLockConfig, FootLockError, FootLockReport};
use crate::constraints::{CompiledProgram, ConstraintError};
use crate::diffusion::noise::gaussian;
use crate::diffusion::Guidance;
use crate::dno::{optimize_with_restarts, DnoConfig, Solver, UnrolledDdim};
use crate::limits;
use crate::prior::Prior;
use crate::program::{Primitive, TaskProgram};
use crate::quality::{poses_to_tensor, tensor_to_poses};
use crate::refine::{refine, RefineConfig, RefineReport};
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
    /// Retrieval-guided DNO ([`crate::rgdno`]): needs a retrieval corpus, so it runs through
    /// [`crate::rgdno::generate_rg_dno`], not [`generate`].
    RgDno,
}

impl Method {
    /// Every method, baselines first.
    pub const ALL: [Method; 5] = [Method::Unconstrained, Method::Ik, Method::IkReg, Method::Dno, Method::RgDno];

    /// The kebab-case name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Unconstrained => "unconstrained",
            Method::Ik => "ik",
            Method::IkReg => "ik-reg",
            Method::Dno => "dno",
            Method::RgDno => "rg-dno",
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
    /// Weight λ of the jitter guard added to DNO's criterion: `λ·Σ_{t,j} relu(‖a_tj‖ − A)²`
    /// with `a` the joints' second differences (m/frame²) and `A` = [`JITTER_LIMIT`]. Ours, not
    /// DNO's or ProgMoGen's: without it, DNO through our small prior satisfies keyframe
    /// constraints with one-frame glitches (max acceleration 5–12× the unconstrained samples'
    /// on HSI-2/3). 0 switches it off. Default 1.
    #[serde(default = "default_jitter_weight")]
    pub jitter_weight: f64,
    /// The contact-aware clean-up of every method's output (foot locking with leg IK; on by
    /// default). Its `plant_on_floor` is switched off for programs whose scene holds a raised
    /// support (a balance beam, a ground away from y = 0), and its `keep_above_floor` for those
    /// whose ground lies below y = 0.
    #[serde(default)]
    pub foot_lock: FootLockConfig,
    /// The kinematic refinement of every method's output against the program's geometric
    /// constraints ([`crate::refine`]; on by default), before the foot clean-up.
    #[serde(default)]
    pub refine: RefineConfig,
}

impl GenerationConfig {
    /// Whether the kinematic refinement runs: when switched on, for every method but
    /// [`Method::Unconstrained`], whose motion ignores the program by definition.
    pub fn refines(&self) -> bool {
        self.refine.enabled && self.method != Method::Unconstrained
    }

    /// Settings a run of `frames` frames can use: at least one sample, within
    /// [`limits::BATCH_SAMPLES`] and [`limits::BATCH_ATTENTION`] (checked before any tensor is
    /// made), a finite guidance ≥ 0 and a finite jitter weight ≥ 0.
    pub fn check(&self, frames: usize) -> Result<(), GenerationError> {
        if self.samples == 0 {
            return Err(GenerationError::Setting("samples must be at least 1".into()));
        }
        limits::BATCH_SAMPLES.check(self.samples as u64, "the batch")?;
        let pairs = (self.samples as u64).saturating_mul((frames as u64).saturating_pow(2));
        limits::BATCH_ATTENTION.check(pairs, format_args!("{} samples of {frames} frames", self.samples))?;
        if !(self.guidance.is_finite() && self.guidance >= 0.0) {
            return Err(GenerationError::Setting(format!("guidance must be finite and ≥ 0, got {}", self.guidance)));
        }
        if !(self.jitter_weight.is_finite() && self.jitter_weight >= 0.0) {
            return Err(GenerationError::Setting(format!(
                "the jitter weight must be finite and ≥ 0, got {}",
                self.jitter_weight
            )));
        }
        self.refine.validate().map_err(GenerationError::Setting)
    }
}

fn default_jitter_weight() -> f64 {
    1.0
}

/// Joint acceleration above which the jitter guard acts, m/frame² (0.15 m/frame² = 60 m/s²;
/// our training walks peak at 0.13).
pub const JITTER_LIMIT: f64 = 0.15;

/// The jitter guard `Σ_{t,j} relu(‖a_tj‖ − limit)²` per sample `[B]` of joints `[B, T, 22, 3]`,
/// with `a` the second time difference (m/frame²); 0 for fewer than 3 frames.
pub fn jitter_penalty(joints: &Tensor, limit: f64) -> candle_core::Result<Tensor> {
    let (batch, frames, _, _) = joints.dims4()?;
    if frames < 3 {
        return Tensor::zeros(batch, joints.dtype(), joints.device());
    }
    let a = crate::constraints::second_difference(joints)?;
    let norm = (a.sqr()?.sum(candle_core::D::Minus1)? + crate::constraints::NORM_EPS)?.sqrt()?;
    (norm - limit)?.relu()?.sqr()?.reshape((batch, ()))?.sum(candle_core::D::Minus1)
}

/// The criterion every noise-optimising method minimises: per sample `[B]`, the program's
/// `Σ wᵢ·Eᵢ` on the joints of normalised features `x` `[B, T, 263]`, plus `jitter_weight ×`
/// [`jitter_penalty`]. `initial` `[B or 1, T, 22, 3]` is what `stay_near_initial` terms compare
/// with.
pub fn program_objective<'a>(
    prior: &'a Prior,
    compiled: &'a CompiledProgram,
    initial: &'a Tensor,
    jitter_weight: f64,
) -> impl Fn(&Tensor) -> candle_core::Result<Tensor> + 'a {
    let on_joints = joints_objective(compiled, initial, jitter_weight);
    move |x: &Tensor| on_joints(&prior.to_joints(x)?)
}

/// [`program_objective`] on joints `[B, T, 22, 3]` (m) instead of features.
pub fn joints_objective<'a>(
    compiled: &'a CompiledProgram,
    initial: &'a Tensor,
    jitter_weight: f64,
) -> impl Fn(&Tensor) -> candle_core::Result<Tensor> + 'a {
    move |joints: &Tensor| {
        let error = compiled.evaluate(joints, Some(initial)).map_err(candle_core::Error::wrap)?.total;
        if jitter_weight > 0.0 {
            error + (jitter_penalty(joints, JITTER_LIMIT)? * jitter_weight)?
        } else {
            Ok(error)
        }
    }
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
            jitter_weight: default_jitter_weight(),
            foot_lock: FootLockConfig::default(),
            refine: RefineConfig::default(),
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
    /// The clean-up refused a motion (one with NaN joints).
    #[error("foot clean-up of sample {sample}: {source}")]
    FootLock {
        /// The sample's index in the batch.
        sample: usize,
        /// What was wrong.
        source: FootLockError,
    },
    /// A result holds NaN or infinite values: the prior, the text or a setting is broken.
    #[error(
        "{what} of sample {sample} is not finite (frame {frame}, {count} values NaN or infinite); nothing was \
         written. Check the prior file (`mogen sample` with it), the prompt and the numeric settings"
    )]
    NonFinite {
        /// Which result (e.g. `DNO's motion features`).
        what: String,
        /// The first bad sample.
        sample: usize,
        /// Its first bad frame.
        frame: usize,
        /// Bad values in the whole tensor.
        count: usize,
    },
    /// The batch is over one of the [`limits`].
    #[error(transparent)]
    Limit(#[from] limits::LimitExceeded),
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
}

/// `Ok` when every value of `batch` `[B, T, ...]` is finite; otherwise [`GenerationError::NonFinite`]
/// naming `what`, the first bad sample and frame.
pub fn ensure_finite(batch: &Tensor, what: &str) -> Result<(), GenerationError> {
    let dims = batch.dims();
    let per_frame = dims.iter().skip(2).product::<usize>().max(1);
    let frames = dims.get(1).copied().unwrap_or(1).max(1);
    let values = batch.to_dtype(candle_core::DType::F32)?.flatten_all()?.to_vec1::<f32>()?;
    let count = values.iter().filter(|v| !v.is_finite()).count();
    match values.iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(first) => Err(GenerationError::NonFinite {
            what: what.to_owned(),
            sample: first / (per_frame * frames),
            frame: first / per_frame % frames,
            count,
        }),
    }
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
    /// Joint positions `[B, T, 22, 3]` (m, y up) after the clean-up: the output.
    pub joints: Tensor,
    /// The joints of `features` before the refinement and the clean-up, `[B, T, 22, 3]` (the
    /// same tensor as `joints` when both are off).
    pub raw_joints: Tensor,
    /// Per sample, what the kinematic refinement did (its error before and after, the largest
    /// joint offset).
    pub refine: Vec<RefineReport>,
    /// Per sample, what the clean-up did (with the foot skate before and after).
    pub foot_lock: Vec<FootLockReport>,
    /// The unconstrained start `G(z0)` as joints, `[B, T, 22, 3]`.
    pub initial_joints: Tensor,
    /// Per sample, the criterion loss at every optimisation step (empty when unconstrained;
    /// for DNO it includes the jitter guard).
    pub loss_history: Vec<Vec<f64>>,
    /// Wall-clock seconds of the method (excluding loading the prior).
    pub seconds: f64,
}

impl Generated {
    /// These motions with rows taken from `other` (another attempt at the same program): row
    /// `b` becomes `other`'s row `i` where `rows[b]` is `Some(i)`. The seconds add up.
    pub fn with_rows_from(self, other: Generated, rows: &[Option<usize>]) -> candle_core::Result<Generated> {
        let n = rows.len();
        let index: Vec<u32> = rows.iter().enumerate().map(|(b, row)| row.map_or(b, |i| n + i) as u32).collect();
        let index = Tensor::new(index, self.joints.device())?;
        let pick = |own: &Tensor, theirs: &Tensor| Tensor::cat(&[own, theirs], 0)?.index_select(&index, 0);
        Ok(Generated {
            features: pick(&self.features, &other.features)?,
            joints: pick(&self.joints, &other.joints)?,
            raw_joints: pick(&self.raw_joints, &other.raw_joints)?,
            initial_joints: pick(&self.initial_joints, &other.initial_joints)?,
            refine: pick_rows(self.refine, &other.refine, rows),
            foot_lock: pick_rows(self.foot_lock, &other.foot_lock, rows),
            loss_history: pick_rows(self.loss_history, &other.loss_history, rows),
            seconds: self.seconds + other.seconds,
        })
    }
}

/// `own` (one entry per sample) with entry `b` replaced by `other[i]` where `rows[b]` is
/// `Some(i)`; entries without a row in `rows` are kept.
pub fn pick_rows<T: Clone>(own: Vec<T>, other: &[T], rows: &[Option<usize>]) -> Vec<T> {
    own.into_iter()
        .enumerate()
        .map(|(b, entry)| match rows.get(b).copied().flatten().and_then(|i| other.get(i)) {
            Some(replacement) => replacement.clone(),
            None => entry,
        })
        .collect()
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
    let frames = compiled.frames();
    config.check(frames)?;
    let start = Instant::now();
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
    let (features, loss_history) = match config.method {
        Method::RgDno => {
            return Err(GenerationError::Setting(
                "RG-DNO needs a retrieval corpus: run it with rgdno::generate_rg_dno".into(),
            ))
        }
        Method::Unconstrained => (x0, vec![Vec::new(); config.samples]),
        Method::Ik | Method::IkReg => {
            let smoothness = if config.method == Method::IkReg { config.direct.smoothness_weight } else { 0.0 };
            let plain = program_objective(prior, compiled, &initial_joints, 0.0);
            direct::optimize_motion(&x0, &plain, &config.direct, smoothness, |step, loss| {
                progress(&Progress { round: 0, step, steps: config.direct.steps, loss })
            })?
        }
        Method::Dno => {
            let dno = DnoConfig { seed: config.seed, ..config.dno.clone() };
            let guarded = program_objective(prior, compiled, &initial_joints, config.jitter_weight);
            let run = optimize_with_restarts(&solver as &dyn Solver, guarded, shape, device, &dno, |round, s| {
                let loss = s.loss.iter().sum::<f64>() / s.loss.len().max(1) as f64;
                progress(&Progress { round, step: s.step, steps: s.steps, loss })
            })?;
            let history = run.best.history.into_iter().map(|h| h.loss).collect();
            (run.best.x, history)
        }
    };
    finish(prior, program, compiled, config, features, initial_joints, loss_history, start)
}

/// What every method ends with: the joints of `features`, the kinematic refinement against
/// the program, the clean-up (with its floor planting off for programs on a raised support)
/// and the [`Generated`] record, timed from `start`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn finish(
    prior: &Prior,
    program: &TaskProgram,
    compiled: &CompiledProgram,
    config: &GenerationConfig,
    features: Tensor,
    initial_joints: Tensor,
    loss_history: Vec<Vec<f64>>,
    start: Instant,
) -> Result<Generated, GenerationError> {
    ensure_finite(&features, &format!("{}'s motion features", config.method))?;
    let raw_joints = prior.to_joints(&features)?;
    ensure_finite(&raw_joints, &format!("{}'s joint positions", config.method))?;
    let refine_config = RefineConfig { enabled: config.refines(), ..config.refine.clone() };
    let (refined, refine) = refine_in_parallel(&raw_joints, compiled, &initial_joints, &refine_config)?;
    ensure_finite(&refined, "the refinement's joint positions")?;
    let mut lock = config.foot_lock.clone();
    lock.plant_on_floor &= !has_raised_support(program);
    lock.keep_above_floor &= !has_sunk_ground(program);
    let (joints, foot_lock) = clean_up(&refined, &lock)?;
    ensure_finite(&joints, "the foot clean-up's joint positions")?;
    Ok(Generated {
        features,
        joints,
        raw_joints,
        refine,
        foot_lock,
        initial_joints,
        loss_history,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// [`refine`] with the batch cut into one contiguous group per rayon worker, the groups
/// refined in parallel. Every sample's refinement is its own (its loss, its Adam moments,
/// its keep-or-drop verdict); the rest skeleton each group measures is the prior's, the
/// same for every sample.
fn refine_in_parallel(
    joints: &Tensor,
    compiled: &CompiledProgram,
    initial: &Tensor,
    config: &RefineConfig,
) -> Result<(Tensor, Vec<RefineReport>), GenerationError> {
    use rayon::prelude::*;
    let batch = joints.dim(0)?;
    let groups = rayon::current_num_threads().clamp(1, batch.max(1));
    if groups == 1 || initial.dim(0)? != batch {
        return Ok(refine(joints, compiled, Some(initial), config)?);
    }
    let parts = (0..groups)
        .into_par_iter()
        .map(|g| {
            let (first, end) = (g * batch / groups, (g + 1) * batch / groups);
            let (joints, initial) = (joints.narrow(0, first, end - first)?, initial.narrow(0, first, end - first)?);
            refine(&joints, compiled, Some(&initial), config)
        })
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let (tensors, reports): (Vec<Tensor>, Vec<Vec<RefineReport>>) = parts.into_iter().unzip();
    Ok((Tensor::cat(&tensors, 0)?, reports.concat()))
}

/// [`foot_lock`] on every sample of `joints` `[B, T, 22, 3]` (samples in parallel): the
/// cleaned joints (same shape, dtype and device) and each sample's report.
pub fn clean_up(joints: &Tensor, config: &FootLockConfig) -> Result<(Tensor, Vec<FootLockReport>), GenerationError> {
    use rayon::prelude::*;
    let motions = tensor_to_poses(joints)?;
    let locked = motions
        .par_iter()
        .enumerate()
        .map(|(sample, poses)| {
            foot_lock(poses, None, config).map_err(|source| GenerationError::FootLock { sample, source })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (cleaned, reports): (Vec<_>, Vec<_>) = locked.into_iter().map(|l| (l.poses, l.report)).unzip();
    if !config.enabled {
        return Ok((joints.clone(), reports));
    }
    Ok((poses_to_tensor(&cleaned, joints.dtype(), joints.device())?, reports))
}

/// Whether the scene's ground lies more than 1 cm below y = 0 (a pit), where legs may go below
/// y = 0.
fn has_sunk_ground(program: &TaskProgram) -> bool {
    program.scene_primitives().iter().any(|p| matches!(p, Primitive::Ground(ground) if ground.height_m < -0.01))
}

/// Whether the scene holds a support more than 1 cm above or below the floor y = 0 (a raised
/// balance beam, a raised or sunk ground), on which feet must not be planted at y = 0.
fn has_raised_support(program: &TaskProgram) -> bool {
    program.scene_primitives().iter().any(|p| match p {
        Primitive::BalanceBeam(beam) => beam.point_m[1].abs() > 0.01,
        Primitive::Ground(ground) => ground.height_m.abs() > 0.01,
        _ => false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_batch_over_the_memory_limit_is_refused_before_any_tensor() {
        let mut config = GenerationConfig::new(Method::Dno);
        config.samples = 5;
        assert!(config.check(800).is_ok());
        let err = config.check(1000).unwrap_err().to_string();
        assert!(err.contains("5 samples of 1000 frames is 5000000 frame pairs, over the limit of 4000000"), "{err}");
        config.samples = 65;
        assert!(config.check(40).unwrap_err().to_string().contains("samples per run"));
        config.samples = 1;
        config.jitter_weight = f64::INFINITY;
        assert!(config.check(40).unwrap_err().to_string().contains("jitter weight"));
    }

    #[test]
    fn rows_from_another_attempt_replace_only_the_named_samples() {
        let device = Device::Cpu;
        // Sample b of an attempt is filled with `base + b` everywhere.
        let attempt = |base: f32, samples: usize| -> Generated {
            let rows = |shape: &[usize]| {
                let per: usize = shape[1..].iter().product();
                let data: Vec<f32> = (0..samples).flat_map(|b| vec![base + b as f32; per]).collect();
                Tensor::from_vec(data, shape, &device).unwrap()
            };
            let report = |b: usize| RefineReport {
                applied: true,
                error_before: f64::from(base) + b as f64,
                error_after: 0.0,
                max_offset_m: 0.0,
                mean_offset_m: 0.0,
            };
            Generated {
                features: rows(&[samples, 2, FEATURE_DIM]),
                joints: rows(&[samples, 2, 22, 3]),
                raw_joints: rows(&[samples, 2, 22, 3]),
                initial_joints: rows(&[samples, 2, 22, 3]),
                refine: (0..samples).map(report).collect(),
                foot_lock: Vec::new(),
                loss_history: (0..samples).map(|b| vec![f64::from(base) + b as f64]).collect(),
                seconds: 1.5,
            }
        };
        // Three samples; the retry made two, and sample 2 takes the retry's second.
        let merged = attempt(0.0, 3).with_rows_from(attempt(10.0, 2), &[None, None, Some(1)]).unwrap();
        let first = |t: &Tensor| -> Vec<f32> {
            (0..3).map(|b| t.get(b).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap()[0]).collect()
        };
        for t in [&merged.features, &merged.joints, &merged.raw_joints, &merged.initial_joints] {
            assert_eq!(first(t), vec![0.0, 1.0, 11.0]);
        }
        assert_eq!(merged.joints.dims(), &[3, 2, 22, 3]);
        assert_eq!(merged.refine.iter().map(|r| r.error_before).collect::<Vec<_>>(), vec![0.0, 1.0, 11.0]);
        assert_eq!(merged.loss_history, vec![vec![0.0], vec![1.0], vec![11.0]]);
        assert_eq!(merged.seconds, 3.0, "the seconds of both attempts");
        // An empty per-sample list stays empty; a row past the other's end keeps its own entry.
        assert!(merged.foot_lock.is_empty());
        assert_eq!(pick_rows(vec![1, 2], &[7], &[Some(3), Some(0)]), vec![1, 7]);
    }

    #[test]
    fn a_non_finite_result_names_its_sample_and_frame() {
        let mut data = vec![0f32; 3 * 4 * 5];
        data[2 * 20 + 3 * 5 + 1] = f32::NAN;
        data[2 * 20 + 3 * 5 + 2] = f32::INFINITY;
        let batch = Tensor::from_vec(data, (3, 4, 5), &Device::Cpu).unwrap();
        let err = ensure_finite(&batch, "DNO's motion features").unwrap_err().to_string();
        assert!(err.starts_with("DNO's motion features of sample 2 is not finite (frame 3, 2 values"), "{err}");
        assert!(ensure_finite(&batch.narrow(0, 0, 2).unwrap(), "x").is_ok());
    }

    #[test]
    fn jitter_penalty_by_hand_and_its_gradient() {
        // One joint jumps 0.5 m up on frame 2 of 5: second differences 0.5, −1.0, 0.5 m/frame².
        let mut data = vec![0f64; 5 * 22 * 3];
        data[2 * 66 + 3 * 15 + 1] = 0.5;
        let joints = Tensor::from_vec(data, (1, 5, 22, 3), &Device::Cpu).unwrap();
        let expected = 2.0 * (0.5 - JITTER_LIMIT).powi(2) + (1.0 - JITTER_LIMIT).powi(2);
        let got = jitter_penalty(&joints, JITTER_LIMIT).unwrap().to_vec1::<f64>().unwrap();
        assert!((got[0] - expected).abs() < 1e-9, "{got:?} vs {expected}");
        let smooth = Tensor::zeros((2, 5, 22, 3), candle_core::DType::F64, &Device::Cpu).unwrap();
        assert_eq!(jitter_penalty(&smooth, JITTER_LIMIT).unwrap().to_vec1::<f64>().unwrap(), vec![0.0, 0.0]);
        crate::testing::finite_difference_check(&joints, |j| jitter_penalty(j, JITTER_LIMIT)?.sum_all(), 1e-6, 1e-5)
            .unwrap();
    }
}
