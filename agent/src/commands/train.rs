//! `mogen train`: train the motion prior on a database.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use motion_core::database::MotionDatabase;
use motion_core::model::{MdmConfig, Prediction};
use motion_core::training::{TrainConfig, Trainer};

use crate::paths;

#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Database built by `mogen data build`.
    #[arg(long, default_value_os_t = paths::default_database())]
    database: PathBuf,
    /// Where the trained prior (EMA weights, vocabulary, Mean/Std) is written.
    #[arg(long, short, default_value = "out/prior.safetensors")]
    out: PathBuf,
    /// Resumable checkpoint file (written every --checkpoint-every steps; resumed if present).
    #[arg(long, default_value = "out/train_checkpoint.safetensors")]
    checkpoint: PathBuf,
    /// Optimiser steps.
    #[arg(long, default_value_t = TrainConfig::default().steps)]
    steps: usize,
    /// Windows per batch.
    #[arg(long, default_value_t = TrainConfig::default().batch_size)]
    batch_size: usize,
    /// Peak learning rate.
    #[arg(long, default_value_t = TrainConfig::default().lr, value_parser = super::flags::learning_rate)]
    lr: f64,
    /// Longest crop in frames (20 fps).
    #[arg(long, default_value_t = TrainConfig::default().max_frames)]
    max_frames: usize,
    /// Weight of the root features (yaw velocity, x/z velocity, height) in the x0 MSE
    /// (1 = MDM's plain MSE; 25 = HumanML3D's feat_bias 5).
    #[arg(long, default_value_t = TrainConfig::default().root_weight, value_parser = super::flags::weight)]
    root_weight: f64,
    /// Weight of the ric features (root-relative joint positions, from which the joints are
    /// recovered) in the x0 MSE (1 = MDM's plain MSE).
    #[arg(long, default_value_t = TrainConfig::default().ric_weight, value_parser = super::flags::weight)]
    ric_weight: f64,
    /// Min-SNR-γ loss weighting: each sample's x0 MSE weighted by min(SNR_t, γ)
    /// (0 = off, MDM's uniform weighting; 5 is the paper's value).
    #[arg(long, default_value_t = TrainConfig::default().snr_gamma, value_parser = super::flags::weight)]
    snr_gamma: f64,
    /// Fraction of timesteps drawn from the noisiest 30 % of the schedule (0 = MDM's uniform
    /// sampling); high-noise steps teach the denoiser to tie frames together.
    #[arg(long, default_value_t = TrainConfig::default().high_noise_fraction, value_parser = super::flags::fraction)]
    high_noise_fraction: f64,
    /// Fraction of frames whose noisy input is replaced by pure noise, target unchanged, so the
    /// denoiser learns to restore frames from their neighbours (0 = off).
    #[arg(long, default_value_t = TrainConfig::default().frame_corruption, value_parser = super::flags::fraction)]
    frame_corruption: f64,
    /// Weight of the joint-velocity loss on the recovered joints ((m/s)²; 0 = off).
    #[arg(long, default_value_t = TrainConfig::default().velocity_weight)]
    velocity_weight: f64,
    /// Weight of the planted-foot loss ((m/s)²; 0 = off).
    #[arg(long, default_value_t = TrainConfig::default().foot_contact_weight)]
    foot_contact_weight: f64,
    /// Steps between checkpoints.
    #[arg(long, default_value_t = TrainConfig::default().checkpoint_every)]
    checkpoint_every: usize,
    /// Seed of initialisation, batches, noise and dropout.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Shards of each batch computed in parallel (one per core) and summed; the result depends
    /// on this number, not on the cores. Set RAYON_NUM_THREADS to the cores to use.
    #[arg(long, default_value_t = TrainConfig::default().shards)]
    shards: usize,
    /// Model width d (tokens), feed-forward width and layers; defaults: the shipped small size.
    #[arg(long)]
    latent_dim: Option<usize>,
    #[arg(long)]
    ff_size: Option<usize>,
    #[arg(long)]
    layers: Option<usize>,
    /// Dropout inside the denoiser while training, in [0, 1) (MDM's 0.1; the shipped prior was
    /// trained with 0, which let it learn the turning labels: see the model card).
    #[arg(long, default_value_t = MdmConfig::small().dropout, value_parser = super::flags::fraction)]
    dropout: f64,
    /// What the network's output head predicts: `x0` (MDM) or `velocity` (v = √ᾱ·ε − √(1−ᾱ)·x0;
    /// x̂0 stays close to a lightly noised input).
    #[arg(long, default_value_t = MdmConfig::small().prediction)]
    prediction: Prediction,
    /// Write the losses of every step as CSV (step,loss,velocity,foot_contact,lr,frames,seconds).
    #[arg(long)]
    loss_csv: Option<PathBuf>,
}

pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    // Each shard runs on a core of rayon's pool. Candle's own element-wise worker pool
    // (CANDLE_NUM_THREADS − 1 spinning threads, created on first use) would compete with the
    // shards for the same cores: 0.64 s per step against 0.28 s without it (2 cores, d = 128).
    // Nothing has touched a tensor yet (only the command's idle rayon workers exist), so the
    // variable is read in time and by no other thread meanwhile.
    if args.shards > 1 && std::env::var_os("CANDLE_NUM_THREADS").is_none() {
        std::env::set_var("CANDLE_NUM_THREADS", "1");
    }
    let db = MotionDatabase::load(&args.database)
        .with_context(|| format!("reading {} (build it with `mogen data build`)", args.database.display()))?;
    let small = MdmConfig::small();
    let model = MdmConfig {
        latent_dim: args.latent_dim.unwrap_or(small.latent_dim),
        ff_size: args.ff_size.unwrap_or(small.ff_size),
        num_layers: args.layers.unwrap_or(small.num_layers),
        prediction: args.prediction,
        dropout: args.dropout,
        ..small
    };
    let config = TrainConfig {
        steps: args.steps,
        batch_size: args.batch_size,
        lr: args.lr,
        max_frames: args.max_frames,
        checkpoint_every: args.checkpoint_every,
        root_weight: args.root_weight,
        ric_weight: args.ric_weight,
        snr_gamma: args.snr_gamma,
        high_noise_fraction: args.high_noise_fraction,
        frame_corruption: args.frame_corruption,
        velocity_weight: args.velocity_weight,
        foot_contact_weight: args.foot_contact_weight,
        seed: args.seed,
        shards: args.shards,
        ..TrainConfig::default()
    };
    let device = candle_core::Device::Cpu;
    let mut trainer = Trainer::new(&db, model, config.clone(), &device).context("setting up training")?;
    if args.checkpoint.exists() {
        let state = trainer.resume(&args.checkpoint).context("resuming from the checkpoint")?;
        eprintln!("resumed {} at step {}", args.checkpoint.display(), state.step);
    }
    eprintln!(
        "training {} parameters on {} windows ({} labels), {} steps of batch {}",
        trainer.model_config().parameter_count(),
        db.windows().len(),
        db.labels().len(),
        config.steps,
        config.batch_size
    );
    let bar = ProgressBar::new(config.steps as u64).with_position(trainer.step() as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}] {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut csv = match &args.loss_csv {
        Some(p) => {
            let exists = p.exists();
            let mut f = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(p)
                .with_context(|| format!("opening {}", p.display()))?;
            if !exists {
                use std::io::Write;
                writeln!(f, "step,loss,velocity,foot_contact,lr,frames,seconds")?;
            }
            Some(f)
        }
        None => None,
    };
    let start = Instant::now();
    let mut smoothed: Option<f64> = None;
    trainer.run(Some(&args.checkpoint), |r| {
        let s = smoothed.map_or(r.loss, |s| 0.98 * s + 0.02 * r.loss);
        smoothed = Some(s);
        bar.set_position(r.step as u64);
        bar.set_message(format!("loss {s:.4} lr {:.1e} T={}", r.lr, r.frames));
        // Not a terminal: a plain line every 100 steps instead of the bar.
        if bar.is_hidden() && r.step % 100 == 0 {
            eprintln!(
                "step {}/{} loss {s:.4} velocity {:.4} foot contact {:.4} lr {:.1e} ({:.0} s)",
                r.step,
                r.steps,
                r.velocity,
                r.foot_contact,
                r.lr,
                start.elapsed().as_secs_f64()
            );
        }
        if let Some(f) = csv.as_mut() {
            use std::io::Write;
            let _ = writeln!(
                f,
                "{},{},{},{},{},{},{:.2}",
                r.step,
                r.loss,
                r.velocity,
                r.foot_contact,
                r.lr,
                r.frames,
                start.elapsed().as_secs_f64()
            );
        }
    })?;
    bar.finish();
    trainer.save_prior(&args.out, &db).context("writing the prior")?;
    println!("wrote {} after {:.0} s", args.out.display(), start.elapsed().as_secs_f64());
    Ok(())
}
