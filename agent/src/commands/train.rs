//! `mogen train`: train the motion prior on the corpus (its train split, captions through the
//! sentence encoder, a validation loss on its validation split) or on a database of a user's
//! own labelled clips.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use motion_core::corpus::{file as corpus_file, Split};
use motion_core::database::MotionDatabase;
use motion_core::model::{MdmConfig, Prediction};
use motion_core::text::{ConditionEncoder, MINILM_NAME};
use motion_core::training::{saved_model_config, StepReport, TrainConfig, Trainer, TrainingSet};

use agent::paths;

#[derive(Debug, Args)]
pub struct TrainArgs {
    /// Motion corpus to train on: its train split, every window's captions encoded by the
    /// sentence encoder; the validation split gives the validation loss.
    #[arg(long, default_value_os_t = paths::default_corpus(), conflicts_with = "database")]
    corpus: PathBuf,
    /// Train on a database of your own labelled clips (built by `mogen data build`) instead of
    /// the corpus, conditioned on a vocabulary of the labels' words; no validation loss.
    #[arg(long)]
    database: Option<PathBuf>,
    /// Folder of the sentence encoders (one folder per encoder) for corpus training.
    #[arg(long, default_value_os_t = paths::text_models())]
    text_models: PathBuf,
    /// Train the text–motion evaluator (R-precision, FID) on the corpus's train split instead of
    /// the prior, and write it to this file; --steps, --batch-size, --lr, --max-frames and
    /// --seed apply. Reports its R-precision on the validation split at the end.
    #[arg(long, conflicts_with = "database")]
    evaluator: Option<PathBuf>,
    /// Steps between validation losses (EMA weights, fixed batches of the validation split).
    #[arg(long, default_value_t = 500)]
    validate_every: usize,
    /// Batches per validation loss.
    #[arg(long, default_value_t = 16)]
    validation_batches: usize,
    /// Where the trained prior (EMA weights, text encoder, Mean/Std) is written.
    #[arg(long, short, default_value = "out/prior.safetensors")]
    out: PathBuf,
    /// Resumable checkpoint file (written every --checkpoint-every steps; resumed if present).
    #[arg(long, default_value = "out/train_checkpoint.safetensors")]
    checkpoint: PathBuf,
    /// Fine-tune this prior (a file written by `mogen train`, e.g. the shipped one) instead of
    /// starting from random weights: its weights start the model and its EMA at step 0, at the
    /// sizes written in it (the model flags below may be left out). It must have been trained on
    /// the same data (its normalisation is checked). Only for a new run: with an existing
    /// --checkpoint, resume without it.
    #[arg(long)]
    init: Option<PathBuf>,
    /// Optimiser steps.
    #[arg(long, default_value_t = TrainConfig::default().steps)]
    steps: usize,
    /// Windows per batch.
    #[arg(long, default_value_t = TrainConfig::default().batch_size)]
    batch_size: usize,
    /// Peak learning rate.
    #[arg(long, default_value_t = TrainConfig::default().lr, value_parser = crate::cli::flags::learning_rate)]
    lr: f64,
    /// Longest crop in frames (20 fps).
    #[arg(long, default_value_t = TrainConfig::default().max_frames)]
    max_frames: usize,
    /// Corpus: draw crops by skill family (walk, run, turn, ..., crawl, or none), a family with
    /// probability proportional to its frames to this power (1: as the data has them; 0: every
    /// family alike; 0.5 draws the rare skills 4-12x as often), instead of uniformly over the
    /// data. The validation loss still draws uniformly.
    #[arg(long, value_parser = crate::cli::flags::weight)]
    family_balance: Option<f64>,
    /// EMA decay of the shipped weights (0.999 averages about the last 1,000 steps; small
    /// batches call for more).
    #[arg(long, default_value_t = TrainConfig::default().ema_decay, value_parser = crate::cli::flags::fraction)]
    ema_decay: f64,
    /// Weight of the root features (yaw velocity, x/z velocity, height) in the x0 MSE
    /// (1 = MDM's plain MSE; 25 = HumanML3D's feat_bias 5).
    #[arg(long, default_value_t = TrainConfig::default().root_weight, value_parser = crate::cli::flags::weight)]
    root_weight: f64,
    /// Weight of the ric features (root-relative joint positions, from which the joints are
    /// recovered) in the x0 MSE (1 = MDM's plain MSE).
    #[arg(long, default_value_t = TrainConfig::default().ric_weight, value_parser = crate::cli::flags::weight)]
    ric_weight: f64,
    /// Min-SNR-γ loss weighting: each sample's x0 MSE weighted by min(SNR_t, γ)
    /// (0 = off, MDM's uniform weighting; 5 is the paper's value).
    #[arg(long, default_value_t = TrainConfig::default().snr_gamma, value_parser = crate::cli::flags::weight)]
    snr_gamma: f64,
    /// Fraction of timesteps drawn from the noisiest 30 % of the schedule (0 = MDM's uniform
    /// sampling); high-noise steps teach the denoiser to tie frames together.
    #[arg(long, default_value_t = TrainConfig::default().high_noise_fraction, value_parser = crate::cli::flags::fraction)]
    high_noise_fraction: f64,
    /// Noise on the text conditions: per row, σ uniform in [0, TEXT_NOISE] times the row's
    /// length, then scaled back to that length (0.05 moves a 384-d sentence vector to cosine
    /// about 0.71 of its caption), so the denoiser learns the space between its captions where
    /// paraphrases lie (0 = off).
    #[arg(long, default_value_t = TrainConfig::default().text_noise, value_parser = crate::cli::flags::weight)]
    text_noise: f64,
    /// Fraction of frames whose noisy input is replaced by pure noise, target unchanged, so the
    /// denoiser learns to restore frames from their neighbours (0 = off).
    #[arg(long, default_value_t = TrainConfig::default().frame_corruption, value_parser = crate::cli::flags::fraction)]
    frame_corruption: f64,
    /// Weight of the joint-velocity loss on the recovered joints ((m/s)²; 0 = off).
    #[arg(long, default_value_t = TrainConfig::default().velocity_weight)]
    velocity_weight: f64,
    /// Weight of the planted-foot loss ((m/s)²; 0 = off).
    #[arg(long, default_value_t = TrainConfig::default().foot_contact_weight)]
    foot_contact_weight: f64,
    /// Stop after this step (a checkpoint is written there) while the learning-rate schedule
    /// stays --steps long: a long run done in pieces, each resumed from the checkpoint.
    #[arg(long)]
    stop_after: Option<usize>,
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
    /// Model width d (tokens), feed-forward width and layers. Defaults: those of the --checkpoint
    /// being resumed, else of the --init prior, else the small size (d = 128, 256, 4 layers).
    #[arg(long)]
    latent_dim: Option<usize>,
    #[arg(long)]
    ff_size: Option<usize>,
    #[arg(long)]
    layers: Option<usize>,
    /// Dropout inside the denoiser while training, in [0, 1). Default: the checkpoint's or the
    /// --init prior's, else MDM's 0.1.
    #[arg(long, value_parser = crate::cli::flags::fraction)]
    dropout: Option<f64>,
    /// What the network's output head predicts: `x0` (MDM) or `velocity` (v = √ᾱ·ε − √(1−ᾱ)·x0;
    /// x̂0 stays close to a lightly noised input). Default: the checkpoint's or the --init
    /// prior's, else `x0`.
    #[arg(long)]
    prediction: Option<Prediction>,
    /// Write the losses of every step as CSV
    /// (step,loss,velocity,foot_contact,lr,frames,seconds,validation; validation on its steps only).
    #[arg(long)]
    loss_csv: Option<PathBuf>,
}

impl TrainArgs {
    /// The training configuration the flags give (TrainConfig's defaults for the rest).
    fn train_config(&self) -> TrainConfig {
        TrainConfig {
            steps: self.steps,
            batch_size: self.batch_size,
            lr: self.lr,
            max_frames: self.max_frames,
            family_balance: self.family_balance,
            ema_decay: self.ema_decay,
            checkpoint_every: self.checkpoint_every,
            root_weight: self.root_weight,
            ric_weight: self.ric_weight,
            snr_gamma: self.snr_gamma,
            high_noise_fraction: self.high_noise_fraction,
            frame_corruption: self.frame_corruption,
            text_noise: self.text_noise,
            velocity_weight: self.velocity_weight,
            foot_contact_weight: self.foot_contact_weight,
            seed: self.seed,
            shards: self.shards,
            ..TrainConfig::default()
        }
    }

    /// The model's sizes: those the flags give, else those written in the checkpoint the run
    /// continues or the --init prior it starts from (flags given beside them must agree with
    /// them: resume and init_from_prior check), else the small model's.
    fn model_config(&self) -> anyhow::Result<MdmConfig> {
        let base = match (&self.init, self.checkpoint.exists()) {
            (_, true) => saved_model_config(&self.checkpoint).context("reading the checkpoint's model sizes")?,
            (Some(init), false) => {
                saved_model_config(init).with_context(|| format!("reading the model sizes of {}", init.display()))?
            }
            (None, false) => MdmConfig::small(),
        };
        Ok(MdmConfig {
            latent_dim: self.latent_dim.unwrap_or(base.latent_dim),
            ff_size: self.ff_size.unwrap_or(base.ff_size),
            num_layers: self.layers.unwrap_or(base.num_layers),
            prediction: self.prediction.unwrap_or(base.prediction),
            dropout: self.dropout.unwrap_or(base.dropout),
            ..base
        })
    }

    /// Whether step `r` is one with a validation loss: every --validate-every steps, the last,
    /// and the --stop-after step.
    fn validation_due(&self, r: &StepReport) -> bool {
        r.step % self.validate_every.max(1) == 0 || r.step == r.steps || Some(r.step) == self.stop_after
    }
}

pub fn run(args: TrainArgs) -> anyhow::Result<()> {
    one_candle_thread_per_shard(args.shards);
    let device = crate::cli::load::device()?;
    let (data, held_out) = match &args.database {
        Some(path) => (database_set(path, &device)?, None),
        None => corpus_sets(&args, &device)?,
    };
    if let Some(out) = &args.evaluator {
        let held_out = held_out.context("the evaluator is trained on the corpus")?;
        return train_evaluator(&args, out, &data, &held_out, &device);
    }
    let model = args.model_config()?;
    let config = args.train_config();
    let mut trainer = Trainer::new(data, model, config.clone(), &device).context("setting up training")?;
    resume_or_init(&args, &mut trainer)?;
    print_plan(&trainer, &config);
    let mut log = StepLog::new(config.steps, trainer.step(), args.loss_csv.as_deref())?;
    trainer
        .run(args.stop_after, Some(&args.checkpoint), |r, trainer| {
            log.show_progress(r);
            let validation = match &held_out {
                Some(set) if args.validation_due(r) => {
                    let loss = trainer.validation_loss(set, args.validation_batches, VALIDATION_SEED)?;
                    log.println(format!("step {}: validation loss {loss:.4}", r.step));
                    Some(loss)
                }
                _ => None,
            };
            log.write_row(r, validation);
            Ok(())
        })
        .with_context(|| format!("training (checkpoints to {})", args.checkpoint.display()))?;
    log.bar.finish();
    trainer.save_prior(&args.out).context("writing the prior")?;
    println!("wrote {} after {:.0} s", args.out.display(), log.start.elapsed().as_secs_f64());
    Ok(())
}

/// Each shard runs on a core of rayon's pool. Candle's own element-wise worker pool
/// (CANDLE_NUM_THREADS − 1 spinning threads, created on first use) would compete with the
/// shards for the same cores: 0.64 s per step against 0.28 s without it (2 cores, d = 128).
/// Called before anything has touched a tensor (only the command's idle rayon workers exist),
/// so the variable is read in time and by no other thread meanwhile.
fn one_candle_thread_per_shard(shards: usize) {
    if shards > 1 && std::env::var_os("CANDLE_NUM_THREADS").is_none() {
        std::env::set_var("CANDLE_NUM_THREADS", "1");
    }
}

/// The clips of a database built by `mogen data build`, labels as conditions.
fn database_set(path: &Path, device: &candle_core::Device) -> anyhow::Result<TrainingSet> {
    let db = MotionDatabase::load(path)
        .with_context(|| format!("reading {} (build it with `mogen data build`)", path.display()))?;
    let defaults = TrainConfig::default();
    Ok(TrainingSet::from_database(&db, defaults.min_frames, defaults.balance_labels, device)?)
}

/// Resumes from an existing --checkpoint (refusing --init beside it, and trimming the loss CSV
/// to the checkpoint's step), or starts from the --init prior when given.
fn resume_or_init(args: &TrainArgs, trainer: &mut Trainer) -> anyhow::Result<()> {
    if args.checkpoint.exists() {
        if let Some(init) = &args.init {
            anyhow::bail!(
                "--init {}: the checkpoint {} exists, so the run resumes from it; drop --init (or move the checkpoint away to start over)",
                init.display(),
                args.checkpoint.display()
            );
        }
        let state = trainer.resume(&args.checkpoint).context("resuming from the checkpoint")?;
        eprintln!("resumed {} at step {}", args.checkpoint.display(), state.step);
        if let Some(csv) = &args.loss_csv {
            drop_rows_after(csv, state.step)?;
        }
    } else if let Some(init) = &args.init {
        trainer.init_from_prior(init).with_context(|| format!("starting from the prior {}", init.display()))?;
        eprintln!("fine-tuning {} from step 0", init.display());
    }
    Ok(())
}

/// Prints what is trained on what, and with --family-balance each skill family's share of the
/// data and of the crops drawn.
fn print_plan(trainer: &Trainer, config: &TrainConfig) {
    eprintln!(
        "training {} parameters on {:.2} h of motion ({} sequences, {} captions), {} steps of batch {}",
        trainer.model_config().parameter_count(),
        trainer.data().seconds() / 3600.0,
        trainer.data().len(),
        trainer.data().captions(),
        config.steps,
        config.batch_size
    );
    if let Some(alpha) = config.family_balance {
        let shares: Vec<String> = trainer
            .data()
            .family_shares(alpha)
            .into_iter()
            .map(|(family, data, drawn)| {
                let name = family.map_or("none", |f| f.name());
                format!("{name} {:.1} % -> {:.1} %", 100.0 * data, 100.0 * drawn)
            })
            .collect();
        eprintln!("crops by skill family (frames of the data -> crops drawn): {}", shares.join(", "));
    }
}

/// What a training run shows and records per step: a progress bar (off a terminal, a plain
/// line every 100 steps instead), the smoothed loss, and the rows of the loss CSV.
struct StepLog {
    bar: ProgressBar,
    /// The --loss-csv file, appended to.
    csv: Option<std::fs::File>,
    /// When the steps began.
    start: Instant,
    /// Exponential moving average of the loss (weight 0.02 on each new step).
    smoothed: Option<f64>,
}

impl StepLog {
    /// A bar of `steps` at `position`, and the loss CSV opened for appending (its header written
    /// when the file is new).
    fn new(steps: usize, position: usize, loss_csv: Option<&Path>) -> anyhow::Result<Self> {
        let bar = ProgressBar::new(steps as u64).with_position(position as u64);
        bar.set_style(
            ProgressStyle::with_template("{bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}] {msg}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        let csv = match loss_csv {
            Some(p) => {
                let exists = p.exists();
                let mut f = std::fs::OpenOptions::new()
                    .create(true)
                    .append(true)
                    .open(p)
                    .with_context(|| format!("opening {}", p.display()))?;
                if !exists {
                    writeln!(f, "step,loss,velocity,foot_contact,lr,frames,seconds,validation")?;
                }
                Some(f)
            }
            None => None,
        };
        Ok(StepLog { bar, csv, start: Instant::now(), smoothed: None })
    }

    /// Moves the bar to step `r` with the smoothed loss.
    fn show_progress(&mut self, r: &StepReport) {
        let s = self.smoothed.map_or(r.loss, |s| 0.98 * s + 0.02 * r.loss);
        self.smoothed = Some(s);
        self.bar.set_position(r.step as u64);
        self.bar.set_message(format!("loss {s:.4} lr {:.1e} T={}", r.lr, r.frames));
        // Not a terminal: a plain line every 100 steps instead of the bar.
        if self.bar.is_hidden() && r.step % 100 == 0 {
            eprintln!(
                "step {}/{} loss {s:.4} velocity {:.4} foot contact {:.4} lr {:.1e} ({:.0} s)",
                r.step,
                r.steps,
                r.velocity,
                r.foot_contact,
                r.lr,
                self.start.elapsed().as_secs_f64()
            );
        }
    }

    /// A line above the bar (on standard error when there is no bar).
    fn println(&self, line: String) {
        if self.bar.is_hidden() {
            eprintln!("{line}");
        } else {
            self.bar.println(line);
        }
    }

    /// Step `r`'s row of the loss CSV, when one is written.
    fn write_row(&mut self, r: &StepReport, validation: Option<f64>) {
        if let Some(f) = self.csv.as_mut() {
            let _ = writeln!(
                f,
                "{},{},{},{},{},{},{:.2},{}",
                r.step,
                r.loss,
                r.velocity,
                r.foot_contact,
                r.lr,
                r.frames,
                self.start.elapsed().as_secs_f64(),
                validation.map(|v| v.to_string()).unwrap_or_default()
            );
        }
    }
}

/// Seed of the validation batches: the same crops, timesteps and noise at every step and in
/// every run, so validation losses compare across steps and model sizes.
const VALIDATION_SEED: u64 = 20_261_127;

/// The corpus's train split (with its captions encoded) and its validation split, normalised
/// with the train split's statistics.
fn corpus_sets(args: &TrainArgs, device: &candle_core::Device) -> anyhow::Result<(TrainingSet, Option<TrainingSet>)> {
    let corpus =
        corpus_file::load(&args.corpus).with_context(|| format!("reading the corpus {}", args.corpus.display()))?;
    let encoder = ConditionEncoder::sentence(MINILM_NAME, &args.text_models, device)
        .with_context(|| format!("loading the sentence encoder from {}", args.text_models.display()))?;
    let bar = ProgressBar::new(0);
    bar.set_style(
        ProgressStyle::with_template("{msg} {bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut sets = Vec::new();
    for split in [Split::Train, Split::Validation] {
        bar.set_message(format!("encoding the {} captions", split.name()));
        let mean_std = sets.first().map(TrainingSet::mean_std);
        let set = TrainingSet::from_corpus(&corpus, split, encoder.clone(), mean_std, device, |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        })?;
        sets.push(set);
    }
    bar.finish_and_clear();
    let held_out = sets.pop();
    let train = sets.pop().context("no train split")?;
    Ok((train, held_out))
}

/// Trains the evaluator on batches of the corpus's train split and reports its R-precision
/// (top 1 and 3 of 32) on the validation split.
fn train_evaluator(
    args: &TrainArgs,
    out: &std::path::Path,
    data: &TrainingSet,
    held_out: &TrainingSet,
    device: &candle_core::Device,
) -> anyhow::Result<()> {
    use motion_core::evaluator::{r_precision, EvaluatorConfig, EvaluatorTrainer};
    use rand::SeedableRng;
    let batches = TrainConfig {
        batch_size: args.batch_size,
        max_frames: args.max_frames,
        balance_labels: false,
        ..TrainConfig::default()
    };
    let mut trainer = EvaluatorTrainer::new(EvaluatorConfig::default(), data.mean_std().clone(), device, args.seed)?;
    let start = Instant::now();
    let (mut loss, mut accuracy) = (None::<f64>, 0.0);
    let schedule = TrainConfig { steps: args.steps, lr: args.lr, ..TrainConfig::default() };
    for step in 0..args.steps {
        let mut rng = rand::rngs::StdRng::seed_from_u64(args.seed.wrapping_mul(1_000_003).wrapping_add(step as u64));
        let batch = data.sample(&batches, &mut rng)?;
        let r = trainer.train_step(&batch.x0, &batch.text, schedule.lr_at(step))?;
        loss = Some(loss.map_or(r.loss, |l| 0.98 * l + 0.02 * r.loss));
        accuracy = 0.98 * accuracy + 0.02 * r.accuracy;
        if r.step % 100 == 0 || r.step == args.steps {
            eprintln!(
                "evaluator step {}/{}: InfoNCE {:.3}, in-batch top-1 {:.2} ({:.0} s)",
                r.step,
                args.steps,
                loss.unwrap_or(f64::NAN),
                accuracy,
                start.elapsed().as_secs_f64()
            );
        }
    }
    let evaluator = trainer.evaluator()?;
    evaluator.save(out)?;
    // R-precision on 256 validation crops of 120 frames: the pool's other texts are other crops'.
    let fixed = TrainConfig { batch_size: 256, min_frames: 120, max_frames: 120, ..batches };
    let batch = held_out.sample(&fixed, &mut rand::rngs::StdRng::seed_from_u64(VALIDATION_SEED))?;
    let r = r_precision(&evaluator.embed_motion(&batch.x0)?, &evaluator.embed_text(&batch.text)?, 32, &[1, 3], 0)?;
    println!(
        "wrote {} after {:.0} s; validation R-precision top-1 {:.3}, top-3 {:.3} (32 per pool, 256 crops)",
        out.display(),
        start.elapsed().as_secs_f64(),
        r[0],
        r[1]
    );
    Ok(())
}

/// Removes the rows of a loss CSV after `step` (the steps a stopped run did past its last
/// checkpoint, which the resumed run does again), keeping the header.
fn drop_rows_after(csv: &std::path::Path, step: usize) -> anyhow::Result<()> {
    let Ok(text) = std::fs::read_to_string(csv) else { return Ok(()) };
    let kept: Vec<&str> = text
        .lines()
        .filter(|line| line.split(',').next().and_then(|s| s.parse::<usize>().ok()).is_none_or(|s| s <= step))
        .collect();
    if kept.len() < text.lines().count() {
        motion_core::files::write_atomically(csv, (kept.join("\n") + "\n").as_bytes())
            .with_context(|| format!("trimming {} to step {step}", csv.display()))?;
    }
    Ok(())
}
