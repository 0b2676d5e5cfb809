//! What every generation method shares: its name ([`Method`]), its settings
//! ([`GenerationConfig`]), the task it takes ([`Task`]), its errors and its outcome
//! ([`Generated`]). The methods themselves are dispatched by [`crate::generation::generate`].

use std::fmt;

use candle_core::Tensor;
use serde::{Deserialize, Serialize};

use crate::cleanup::{FootLockConfig, FootLockError, FootLockReport};
use crate::constraints::{CompiledProgram, ConstraintError};
use crate::diffusion::Guidance;
use crate::dno::DnoConfig;
use crate::generation::objective::Guards;
use crate::generation::refine::{RefineConfig, RefineReport};
use crate::generation::schedule::Schedule;
use crate::limits;
use crate::program::TaskProgram;

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
    /// Retrieval-guided DNO ([`crate::generation::rgdno`]): [`crate::generation::generate`] runs it with the
    /// task's retrieval corpus, and falls back to DNO without a relational parse or a corpus.
    RgDno,
}

impl Method {
    /// Every method, baselines first.
    pub const ALL: [Method; 5] = [Method::Unconstrained, Method::Ik, Method::IkReg, Method::Dno, Method::RgDno];

    /// DDIM steps `K` of the sampler DNO differentiates through, where a run of this method
    /// under `schedule` does not set them: the papers' 10, or 5 under [`Schedule::UntilMet`]
    /// for every method but RG-DNO, half the denoiser passes of every step. RG-DNO keeps 10
    /// under it: at 5 its inversion and mask choice on the README's main command gave a motion
    /// that skates 0.111 against 0.081 (0.020 at 10), while DNO's motions keep their look at 5
    /// (`fixtures/results/issue59-fast-default/`, `fixtures/results/issue59-patience/`).
    pub fn ddim_steps(self, schedule: Schedule) -> usize {
        match (schedule, self) {
            (Schedule::UntilMet, method) if method != Method::RgDno => 5,
            _ => DnoConfig::default().ddim_steps,
        }
    }

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
    /// The guards added to the criterion of DNO and RG-DNO's stages ([`Guards`]: no one-frame
    /// glitches, no flight longer than 0.7 s, free fall in flight, no joint under the floor).
    /// Ours, not DNO's or ProgMoGen's. Default: [`Guards::DEFAULT`].
    #[serde(default)]
    pub guards: Guards,
    /// The contact-aware clean-up of every method's output (foot locking with leg IK; on by
    /// default). Its `plant_on_floor` is switched off for programs whose scene holds a raised
    /// support (a balance beam, a ground away from y = 0), and its `keep_above_floor` for those
    /// whose ground lies below y = 0.
    #[serde(default)]
    pub foot_lock: FootLockConfig,
    /// The kinematic refinement of every method's output against the program's geometric
    /// constraints ([`crate::generation::refine`]; on by default), before the foot clean-up.
    #[serde(default)]
    pub refine: RefineConfig,
    /// When DNO's stages end ([`Schedule`]; default: the papers' fixed budgets). Always
    /// written; a report without it was made when the papers' schedule was the default and
    /// went unwritten, so it reads as [`Schedule::Paper`].
    #[serde(default = "schedule_of_older_reports")]
    pub schedule: Schedule,
}

/// The schedule of a report that does not name one.
fn schedule_of_older_reports() -> Schedule {
    Schedule::Paper
}

impl GenerationConfig {
    /// Whether the kinematic refinement runs: when switched on, for every method but
    /// [`Method::Unconstrained`], whose motion ignores the program by definition.
    pub fn refines(&self) -> bool {
        self.refine.enabled && self.method != Method::Unconstrained
    }

    /// Settings a run of `frames` frames can use: at least one sample, within
    /// [`limits::BATCH_SAMPLES`] and [`limits::BATCH_ATTENTION`] (checked before any tensor is
    /// made), a finite guidance ≥ 0 and finite guard weights ≥ 0.
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
        self.guards.check().map_err(GenerationError::Setting)?;
        self.refine.validate().map_err(GenerationError::Setting)
    }
}

/// Settings of the direct (IK) optimisation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DirectConfig {
    /// Adam steps (ProgMoGen: 100).
    pub steps: usize,
    /// Constant Adam learning rate on the normalised features (ProgMoGen: 1e-2).
    pub lr: f64,
    /// Weight of the smoothness term of IK+Reg: mean over samples' frames of
    /// `‖x[t+1] − x[t]‖²` on the root + ric + rotation features (normalised), per sample.
    pub smoothness_weight: f64,
}

impl Default for DirectConfig {
    fn default() -> Self {
        Self { steps: 100, lr: 1e-2, smoothness_weight: 1.0 }
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
            guards: Guards::DEFAULT,
            foot_lock: FootLockConfig::default(),
            refine: RefineConfig::default(),
            schedule: Schedule::Paper,
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

/// A task as every method takes it: the program and its compiled loss terms.
#[derive(Debug, Clone, Copy)]
pub struct Task<'a> {
    /// The program (its prompt, scene and relational parse).
    pub program: &'a TaskProgram,
    /// The program compiled.
    pub compiled: &'a CompiledProgram,
}

/// The outcome of a method (of [`crate::generation::generate`]).
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

#[cfg(test)]
mod tests {
    use candle_core::Device;

    use super::*;
    use crate::representation::FEATURE_DIM;

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
        config.guards.jitter = f64::INFINITY;
        assert!(config.check(40).unwrap_err().to_string().contains("jitter guard's weight"));
        config.guards = Guards { flight: -1.0, ..Guards::DEFAULT };
        assert!(config.check(40).unwrap_err().to_string().contains("flight guard's weight"));
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
                steps: 0,
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
}
