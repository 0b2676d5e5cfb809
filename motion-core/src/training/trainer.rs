//! A training run: the model, its optimiser, EMA weights and data, and one step of it.

use std::path::Path;

use candle_core::backprop::GradStore;
use candle_core::{DType, Device, Tensor, Var};
use candle_nn::VarMap;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use super::batches::TrainingSet;
use super::config::TrainConfig;
use super::error::TrainError;
use super::geometric::GeometricLoss;
use crate::diffusion::noise::gaussian_from_rng;
use crate::diffusion::NoiseSchedule;
use crate::model::{Mdm, MdmConfig, Prediction};
use crate::nn::unit_rows;
use crate::optim::AdamW;
use crate::prior::Prior;
use crate::representation::{FEATURE_DIM, RIC, ROOT_Y};
use crate::text::TextEncoder;

/// What the trainer reports after each step.
#[derive(Debug, Clone, Copy)]
pub struct StepReport {
    /// 1-based step just done.
    pub step: usize,
    /// Total steps.
    pub steps: usize,
    /// Mean squared error of x̂0 in normalised feature space.
    pub loss: f64,
    /// Joint-velocity term, (m/s)² (0 when its weight is 0).
    pub velocity: f64,
    /// Planted-foot term, (m/s)² (0 when its weight is 0).
    pub foot_contact: f64,
    /// Learning rate used.
    pub lr: f64,
    /// Frames of this batch's crops.
    pub frames: usize,
}

/// A training run: model, optimiser, EMA and data, resumable from a checkpoint.
pub struct Trainer {
    pub(super) config: TrainConfig,
    pub(super) model_config: MdmConfig,
    model: Mdm,
    pub(super) vars: Vec<(String, Var)>,
    pub(super) ema: Vec<Tensor>,
    pub(super) optimizer: AdamW,
    pub(super) data: TrainingSet,
    /// The geometric terms, absent when both of their weights are 0.
    geometric: Option<GeometricLoss>,
    /// Per-feature MSE weights `[263]`, absent when all are 1.
    feature_weights: Option<Tensor>,
    schedule: NoiseSchedule,
    pub(super) step: usize,
    pub(super) device: Device,
}

impl Trainer {
    /// A fresh run on `data`. The model's `text_dim` is set to the width of its text encoder.
    pub fn new(
        data: TrainingSet,
        model_config: MdmConfig,
        config: TrainConfig,
        device: &Device,
    ) -> Result<Self, TrainError> {
        let model_config = MdmConfig { text_dim: data.encoder().dim(), ..model_config };
        let varmap = VarMap::new();
        let model = Mdm::init_seeded(model_config.clone(), &varmap, DType::F32, device, config.seed)?;
        let vars = crate::model::init::named_vars(&varmap, model.named_parameters())?;
        let ema =
            vars.iter().map(|(_, v)| Ok(v.as_tensor().copy()?.detach())).collect::<candle_core::Result<Vec<_>>>()?;
        let optimizer = AdamW::new(vars.iter().map(|(_, v)| v.clone()).collect(), config.weight_decay)?;
        let geometric = if config.velocity_weight > 0.0 || config.foot_contact_weight > 0.0 {
            Some(GeometricLoss::new(data.mean_std().to_device(device)?)?)
        } else {
            None
        };
        let feature_weights = if config.root_weight == 1.0 && config.ric_weight == 1.0 {
            None
        } else {
            let weight = |i: usize| match i {
                i if i <= ROOT_Y => config.root_weight,
                i if RIC.contains(&i) => config.ric_weight,
                _ => 1.0,
            };
            let w: Vec<f32> = (0..FEATURE_DIM).map(|i| weight(i) as f32).collect();
            Some(Tensor::from_vec(w, FEATURE_DIM, device)?)
        };
        Ok(Self {
            feature_weights,
            config,
            model_config,
            model,
            vars,
            ema,
            optimizer,
            data,
            geometric,
            schedule: NoiseSchedule::mdm(),
            step: 0,
            device: device.clone(),
        })
    }

    /// Steps done so far.
    pub fn step(&self) -> usize {
        self.step
    }

    /// The model configuration (with the vocabulary's `text_dim`).
    pub fn model_config(&self) -> &MdmConfig {
        &self.model_config
    }

    /// The data it trains on.
    pub fn data(&self) -> &TrainingSet {
        &self.data
    }

    /// Runs until `config.steps`, or until step `pause` when that comes first (the learning-rate
    /// schedule stays `config.steps` long, so a paused run resumes as if never stopped), calling
    /// `on_step` with the trainer after each step (e.g. for a validation loss) and writing a
    /// checkpoint to `checkpoint` every `checkpoint_every` steps and where it stops; an error of
    /// `on_step` stops the run.
    pub fn run(
        &mut self,
        pause: Option<usize>,
        checkpoint: Option<&Path>,
        mut on_step: impl FnMut(&StepReport, &Self) -> Result<(), TrainError>,
    ) -> Result<(), TrainError> {
        let stop = pause.map_or(self.config.steps, |p| p.min(self.config.steps));
        while self.step < stop {
            let report = self.train_step()?;
            on_step(&report, self)?;
            let due = self.step % self.config.checkpoint_every.max(1) == 0 || self.step == stop;
            if let (Some(path), true) = (checkpoint, due) {
                self.save_checkpoint(path)?;
            }
        }
        Ok(())
    }

    /// One optimiser step.
    pub fn train_step(&mut self) -> Result<StepReport, TrainError> {
        // Every random draw of a step comes from a generator seeded by (seed, step), so a
        // resumed run continues exactly as an uninterrupted one.
        let mut rng = StdRng::seed_from_u64(self.config.seed.wrapping_mul(1_000_003).wrapping_add(self.step as u64));
        let batch = self.data.sample(&self.config, &mut rng)?;
        let (b, frames) = (batch.x0.dim(0)?, batch.x0.dim(1)?);
        let keep: Vec<f32> =
            (0..b).map(|_| if rng.random::<f64>() < self.config.cond_drop_prob { 0.0 } else { 1.0 }).collect();
        let keep = Tensor::from_vec(keep, (b, 1), &self.device)?;
        let text = if self.config.text_noise > 0.0 {
            perturb_conditions(&batch.text, self.config.text_noise, &mut rng)?
        } else {
            batch.text
        };
        let text = text.broadcast_mul(&keep)?;
        let t = self.schedule.sample_timesteps(b, self.config.high_noise_fraction, &mut rng, &self.device)?;
        let noise = gaussian_from_rng(batch.x0.shape(), &mut rng, &self.device)?;
        let x_t = self.schedule.q_sample(&batch.x0, &t, &noise)?;
        let x_t = if self.config.frame_corruption > 0.0 {
            let p = self.config.frame_corruption;
            let keep: Vec<f32> = (0..b * frames).map(|_| if rng.random::<f64>() < p { 0.0 } else { 1.0 }).collect();
            let keep = Tensor::from_vec(keep, (b, frames, 1), &self.device)?;
            let replacement = gaussian_from_rng(batch.x0.shape(), &mut rng, &self.device)?;
            (x_t.broadcast_mul(&keep)? + replacement.broadcast_mul(&(1.0 - &keep)?)?)?
        } else {
            x_t
        };
        // The batch is cut into shards whose losses and gradients are computed in parallel
        // (rayon) and summed in shard order, so the result depends on the shard count but not
        // on how many threads run them.
        let shards = self.config.shards.clamp(1, b);
        let parts: Vec<(usize, usize, u64)> = (0..shards)
            .map(|k| {
                let (start, end) = (k * b / shards, (k + 1) * b / shards);
                (start, end - start, rng.random::<u64>())
            })
            .collect();
        let objective = Objective {
            model: &self.model,
            config: &self.config,
            schedule: &self.schedule,
            feature_weights: self.feature_weights.as_ref(),
            geometric: self.geometric.as_ref(),
        };
        let losses = parts
            .par_iter()
            .map(|&(start, len, seed)| {
                let rows = |x: &Tensor| x.narrow(0, start, len);
                let shard = Shard { x0: rows(&batch.x0)?, x_t: rows(&x_t)?, t: rows(&t)?, text: rows(&text)? };
                objective.loss(&shard, len as f64 / b as f64, &mut StdRng::seed_from_u64(seed))
            })
            .collect::<candle_core::Result<Vec<ShardLoss>>>()?;
        let mut losses = losses.into_iter();
        let Some(mut sum) = losses.next() else {
            return Err(TrainError::Data("empty batch".into()));
        };
        for part in losses {
            sum.absorb(part, self.vars.iter().map(|(_, v)| v))?;
        }
        let ShardLoss { grads, mse: loss_value, velocity, foot_contact, total } = sum;
        if !total.is_finite() {
            return Err(TrainError::Diverged { step: self.step + 1, loss: total });
        }
        let lr = self.config.lr_at(self.step);
        self.optimizer.step(&grads, lr)?;
        let d = self.config.ema_decay.min((1 + self.step) as f64 / (10 + self.step) as f64);
        for (ema, (_, var)) in self.ema.iter_mut().zip(&self.vars) {
            // Detached: an EMA computed from a Var would otherwise chain every past step's
            // graph and grow without bound.
            *ema = ((&*ema * d)? + (var.as_tensor().detach() * (1.0 - d))?)?;
        }
        self.step += 1;
        Ok(StepReport {
            step: self.step,
            steps: self.config.steps,
            loss: loss_value,
            velocity,
            foot_contact,
            lr,
            frames,
        })
    }

    /// The EMA weights with their checkpoint names.
    fn ema_parameters(&self) -> Vec<(String, Tensor)> {
        self.vars.iter().zip(&self.ema).map(|((name, _), ema)| (name.clone(), ema.clone())).collect()
    }

    /// Writes the EMA weights as a shippable prior.
    pub fn save_prior(&self, path: &Path) -> Result<(), TrainError> {
        let data = &self.data;
        let (params, config) = (self.ema_parameters(), &self.model_config);
        Prior::write(path, &params, config, data.encoder(), data.mean_std(), data.rest(), data.caption_bank())?;
        Ok(())
    }

    /// The plain x0 MSE (normalised feature space) of the EMA weights on `batches` batches of
    /// `held_out` (normalised with the training set's statistics), without dropout or condition
    /// dropout. The batches, timesteps and noise come from `seed` alone, so the figure is
    /// comparable across steps, runs and model sizes with the same batch settings.
    pub fn validation_loss(&self, held_out: &TrainingSet, batches: usize, seed: u64) -> Result<f64, TrainError> {
        let tensors = self.ema_parameters().into_iter().collect();
        let vb = candle_nn::VarBuilder::from_tensors(tensors, DType::F32, &self.device);
        let model = Mdm::new(self.model_config.clone(), vb)?;
        let mut rng = StdRng::seed_from_u64(seed);
        let uniform = TrainConfig { family_balance: None, ..self.config.clone() };
        let mut sum = 0.0;
        for _ in 0..batches.max(1) {
            let batch = held_out.sample(&uniform, &mut rng)?;
            let t = self.schedule.sample_timesteps(batch.x0.dim(0)?, 0.0, &mut rng, &self.device)?;
            let noise = gaussian_from_rng(batch.x0.shape(), &mut rng, &self.device)?;
            let x_t = self.schedule.q_sample(&batch.x0, &t, &noise)?;
            let x0_hat = model.forward_eval(&x_t, &t, &batch.text)?;
            sum += f64::from((x0_hat - &batch.x0)?.sqr()?.mean_all()?.to_scalar::<f32>()?);
        }
        Ok(sum / batches.max(1) as f64)
    }
}

/// One shard of a batch: rows of the clean target, the denoiser's input, timesteps `[rows]`
/// and (possibly dropped) text condition `[rows, text_dim]`.
struct Shard {
    x0: Tensor,
    x_t: Tensor,
    t: Tensor,
    text: Tensor,
}

/// A shard's share of the batch loss: the gradients of `weight ×` its loss and the values of
/// its terms, each already multiplied by `weight` (its fraction of the batch's rows), so the
/// shards' values sum to the batch's.
struct ShardLoss {
    grads: GradStore,
    mse: f64,
    velocity: f64,
    foot_contact: f64,
    total: f64,
}

impl ShardLoss {
    /// Adds `other`'s values and its gradients of `vars` to this one's.
    fn absorb<'v>(&mut self, other: ShardLoss, vars: impl Iterator<Item = &'v Var>) -> candle_core::Result<()> {
        self.mse += other.mse;
        self.velocity += other.velocity;
        self.foot_contact += other.foot_contact;
        self.total += other.total;
        for var in vars {
            if let (Some(sum), Some(g)) = (self.grads.get(var.as_tensor()), other.grads.get(var.as_tensor())) {
                let added = (sum + g)?;
                self.grads.insert(var.as_tensor(), added);
            }
        }
        Ok(())
    }
}

/// The training loss: the (weighted) x0 MSE plus the optional geometric terms.
struct Objective<'a> {
    model: &'a Mdm,
    config: &'a TrainConfig,
    schedule: &'a NoiseSchedule,
    feature_weights: Option<&'a Tensor>,
    geometric: Option<&'a GeometricLoss>,
}

impl Objective<'_> {
    /// Forward and backward pass on one shard; `dropout` drives the denoiser's dropout.
    fn loss(&self, shard: &Shard, weight: f64, dropout: &mut StdRng) -> candle_core::Result<ShardLoss> {
        let Shard { x0, x_t, t, text } = shard;
        let x0_hat = self.model.forward_train(x_t, t, text, dropout)?;
        let squared = (&x0_hat - x0)?.sqr()?;
        let mse_value = f64::from(squared.mean_all()?.to_scalar::<f32>()?);
        let squared = match self.feature_weights {
            Some(w) => squared.broadcast_mul(w)?,
            None => squared,
        };
        let mse = if self.config.snr_gamma > 0.0 {
            let gamma = self.config.snr_gamma;
            let weights = self.schedule.per_sample(t, &squared, |abar| (abar / (1.0 - abar)).min(gamma))?;
            squared.broadcast_mul(&weights)?.mean_all()?
        } else if self.model.config().prediction == Prediction::Velocity {
            // ‖x̂0 − x0‖² = (1 − ᾱ)·‖v̂ − v‖²: the v-MSE, whose weight does not vanish at low noise.
            let weights = self.schedule.per_sample(t, &squared, |abar| 1.0 / (1.0 - abar))?;
            squared.broadcast_mul(&weights)?.mean_all()?
        } else {
            squared.mean_all()?
        };
        let (loss, velocity, foot_contact) = match self.geometric {
            Some(geometric) => {
                let signal = self.schedule.per_sample(t, x0, |abar| abar)?.flatten_all()?;
                let terms = geometric.terms(&x0_hat, x0, &signal)?;
                let loss = ((mse + (&terms.velocity * self.config.velocity_weight)?)?
                    + (&terms.foot_contact * self.config.foot_contact_weight)?)?;
                let value = |t: &Tensor| t.to_scalar::<f32>().map(f64::from);
                (loss, value(&terms.velocity)?, value(&terms.foot_contact)?)
            }
            None => (mse, 0.0, 0.0),
        };
        let loss = (loss * weight)?;
        Ok(ShardLoss {
            total: f64::from(loss.to_scalar::<f32>()?),
            grads: loss.backward()?,
            mse: mse_value * weight,
            velocity: velocity * weight,
            foot_contact: foot_contact * weight,
        })
    }
}

/// [`TrainConfig::text_noise`] on conditions `[rows, text_dim]`: each row moved by Gaussian noise
/// of standard deviation σ·‖row‖ (σ uniform in `[0, max_sigma]` per row) and scaled back to
/// its own length; zero rows stay zero.
pub(super) fn perturb_conditions(text: &Tensor, max_sigma: f64, rng: &mut StdRng) -> candle_core::Result<Tensor> {
    let rows = text.dim(0)?;
    let sigma: Vec<f32> = (0..rows).map(|_| (rng.random::<f64>() * max_sigma) as f32).collect();
    let sigma = Tensor::from_vec(sigma, (rows, 1), text.device())?.to_dtype(text.dtype())?;
    let norm = text.sqr()?.sum_keepdim(1)?.sqrt()?;
    let noise = gaussian_from_rng(text.shape(), rng, text.device())?.to_dtype(text.dtype())?;
    let moved = (text + noise.broadcast_mul(&sigma.broadcast_mul(&norm)?)?)?;
    unit_rows(&moved)?.broadcast_mul(&norm)
}
