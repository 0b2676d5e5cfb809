//! The training settings.

use serde::{Deserialize, Serialize};

/// Training settings; every default is documented on its field.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrainConfig {
    /// Optimiser steps; default 5000 (about 23 minutes on 2 cores with 2 shards).
    pub steps: usize,
    /// Windows per batch; default 24.
    pub batch_size: usize,
    /// Peak learning rate; default 6e-4.
    pub lr: f64,
    /// Linear warm-up steps; default 200. The rate then decays along a cosine to 10 %.
    pub warmup_steps: usize,
    /// Decoupled weight decay; default 0.0 (MDM's).
    pub weight_decay: f64,
    /// EMA decay of the weights that are shipped; default 0.999. The decay of step k is
    /// min(ema_decay, (1 + k)/(10 + k)) (the warm-up of timm's and diffusers' EMA), so the
    /// random initial weights do not linger: with a constant 0.999 they would still make up
    /// 0.999^1500 = 22 % of the EMA after 1,500 steps.
    pub ema_decay: f64,
    /// Probability of replacing a condition by zeros (unconditional), MDM's 0.1.
    pub cond_drop_prob: f64,
    /// Noise on the text conditions, relative to each condition's length: every row `c` becomes
    /// `‖c‖·(c + σ‖c‖n)/‖c + σ‖c‖n‖` with `n ~ N(0, I)` and σ drawn uniformly in
    /// `[0, text_noise]` per row, so its length stays. A 384-d sentence vector keeps a cosine of
    /// about `1/√(1 + 384σ²)` with its caption (0.71 at σ = 0.05), but any one direction moves
    /// by σ only: the two sideways captions (cosine 0.985) differ by 0.17 along theirs, so they
    /// stay apart at σ = 0.05. The denoiser then meets sentence vectors around its captions
    /// and learns to answer them alike; default 0 (off). Zero rows (blank captions) stay zero.
    pub text_noise: f64,
    /// Shortest crop, frames; default 40.
    pub min_frames: usize,
    /// Longest crop, frames; default 196.
    pub max_frames: usize,
    /// Sample a database's labels uniformly instead of by seconds of data; default true (its
    /// longest clips would otherwise dominate). The corpus is always drawn by seconds of data.
    pub balance_labels: bool,
    /// Draw a corpus's crops by skill family ([`Family`](crate::corpus::family::Family), from
    /// the family of the window centred nearest the crop's middle): a family with probability
    /// proportional to its frames to this power (1: as the data has them, 0: every family
    /// alike), then a crop centred in it; default `None` (crops uniformly over the data). At 0.5
    /// the rare skills (run, hop, crawl, one-leg balance) are drawn 4–12× as often as
    /// the data holds them. The validation loss always draws uniformly.
    pub family_balance: Option<f64>,
    /// Weight of the four root features (yaw velocity, x/z velocity, height) in the x0 MSE,
    /// relative to 1 for the others; default 1.0 (MDM's plain MSE). 25 matches HumanML3D's
    /// `feat_bias` = 5 on the root's std. The root velocity is integrated into the whole
    /// trajectory, so its errors cost more than any other feature's.
    pub root_weight: f64,
    /// Weight of the 63 `ric` features (root-relative joint positions, which the joints are
    /// recovered from) in the x0 MSE, relative to 1; default 1.0. The other 196 features
    /// (6-D rotations, local velocities, contacts) play no part in the joints but make up
    /// three quarters of the plain MSE.
    pub ric_weight: f64,
    /// Min-SNR-γ loss weighting (Hang et al. 2023): each sample's x0 MSE is weighted by
    /// min(SNR_t, γ) with SNR_t = ᾱ_t/(1 − ᾱ_t), which shifts the training signal from the
    /// nearly pure-noise steps to the low- and mid-noise steps that decide the details; 0 = off
    /// (the default: MDM's uniform weighting for x0 prediction; for
    /// [`Prediction::Velocity`](crate::model::Prediction::Velocity) the MSE of v, i.e. weight 1/(1 − ᾱ_t) = SNR_t + 1).
    pub snr_gamma: f64,
    /// Fraction of each batch's timesteps drawn from the noisiest 30 % of the schedule
    /// (t ≥ 0.7 T), the rest uniformly from 0..T; default 0 (MDM's uniform sampling). At high
    /// noise one frame says little about its pose, so these steps are the ones that teach the
    /// denoiser to tie frames together.
    pub high_noise_fraction: f64,
    /// Fraction of frames whose noisy input is replaced by pure noise while their target stays
    /// the clean frame (the token masking of Gao et al. 2023's Masked Diffusion Transformer):
    /// the denoiser must restore them from their neighbours, so it learns to use temporal
    /// context instead of denoising each frame on its own; default 0 (off).
    pub frame_corruption: f64,
    /// Weight of the joint-velocity term of [`GeometricLoss`](super::GeometricLoss) ((m/s)², added to the x0 MSE);
    /// default 0 (off).
    pub velocity_weight: f64,
    /// Weight of the planted-foot term of [`GeometricLoss`](super::GeometricLoss) ((m/s)²); default 0 (off: at 1.0 a
    /// fine-tune taught the walks to stand still).
    pub foot_contact_weight: f64,
    /// Steps between checkpoints; default 500.
    pub checkpoint_every: usize,
    /// Seed of initialisation, batches, noise and dropout; default 0.
    pub seed: u64,
    /// Shards of each batch whose forward and backward passes run in parallel, one per core,
    /// their gradients summed; default 2. The result depends on the shard count, not on the
    /// number of threads. The planted-foot term is normalised per shard.
    pub shards: usize,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            steps: 5000,
            batch_size: 24,
            lr: 6e-4,
            warmup_steps: 200,
            weight_decay: 0.0,
            ema_decay: 0.999,
            cond_drop_prob: 0.1,
            text_noise: 0.0,
            min_frames: 40,
            max_frames: 196,
            balance_labels: true,
            family_balance: None,
            root_weight: 1.0,
            ric_weight: 1.0,
            snr_gamma: 0.0,
            high_noise_fraction: 0.0,
            frame_corruption: 0.0,
            velocity_weight: 0.0,
            foot_contact_weight: 0.0,
            checkpoint_every: 500,
            seed: 0,
            shards: 2,
        }
    }
}

impl TrainConfig {
    /// Learning rate at `step` (0-based): linear warm-up, then cosine decay to 10 % of `lr`.
    pub fn lr_at(&self, step: usize) -> f64 {
        if step < self.warmup_steps {
            return self.lr * (step + 1) as f64 / self.warmup_steps as f64;
        }
        let span = (self.steps.saturating_sub(self.warmup_steps)).max(1) as f64;
        let progress = ((step - self.warmup_steps) as f64 / span).min(1.0);
        self.lr * (0.1 + 0.9 * 0.5 * (1.0 + (std::f64::consts::PI * progress).cos()))
    }
}
