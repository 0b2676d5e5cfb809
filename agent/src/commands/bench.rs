//! `mogen bench prior`: speed of the shipped prior on this machine.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use candle_core::{Tensor, Var};
use clap::Args;
use motion_core::diffusion::noise::gaussian;
use motion_core::diffusion::{DdimSampler, Denoiser, Guidance, NoiseSchedule};
use motion_core::prior::Prior;
use motion_core::representation::FEATURE_DIM;

use crate::paths;

#[derive(Debug, Args)]
pub struct BenchArgs {
    /// Trained prior file.
    #[arg(long, default_value_os_t = paths::default_prior())]
    prior: PathBuf,
    /// Frames per motion.
    #[arg(long, default_value_t = 100)]
    frames: usize,
    /// DDIM steps unrolled in one DNO step.
    #[arg(long, default_value_t = 10)]
    ddim_steps: usize,
    /// Batch sizes to time.
    #[arg(long, value_delimiter = ',', default_values_t = [1usize, 8])]
    batches: Vec<usize>,
    /// Timed repetitions (after one warm-up); the median is printed.
    #[arg(long, default_value_t = 10)]
    reps: usize,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Peak resident memory of this process so far, MiB (Linux; NaN elsewhere).
fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kib| kib / 1024.0)
}

pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    rayon::ThreadPoolBuilder::new().build()?.install(|| run_in_pool(args))
}

fn run_in_pool(args: BenchArgs) -> anyhow::Result<()> {
    let device = candle_core::Device::Cpu;
    let prior = Prior::load(&args.prior, &device).with_context(|| format!("loading {}", args.prior.display()))?;
    let cfg = prior.mdm.config();
    println!(
        "prior: d={} ff={} layers={} heads={} ({} parameters); {} frames; threads: RAYON_NUM_THREADS={} CANDLE_NUM_THREADS={}",
        cfg.latent_dim,
        cfg.ff_size,
        cfg.num_layers,
        cfg.num_heads,
        cfg.parameter_count(),
        args.frames,
        std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "unset".into()),
        std::env::var("CANDLE_NUM_THREADS").unwrap_or_else(|_| "unset".into()),
    );
    let sampler = DdimSampler::new(&NoiseSchedule::mdm(), args.ddim_steps)?;
    println!("| batch | denoiser forward (s) | ddim{k} sample, no graph (s) | DNO step: ddim{k} unrolled fwd+bwd to the noise (s) | 500 DNO steps (s) | peak RSS (MiB) |", k = args.ddim_steps);
    println!("|---|---|---|---|---|---|");
    for &b in &args.batches {
        // The DNO loop runs unconditionally (empty prompt), as DNO does.
        let text = prior.encode_text(&vec![""; b], &device)?;
        let t = Tensor::from_vec(vec![500u32; b], b, &device)?;
        let x = gaussian((b, args.frames, FEATURE_DIM), 0, &device)?;
        let time = |f: &mut dyn FnMut() -> anyhow::Result<()>| -> anyhow::Result<f64> {
            f()?;
            let mut v = Vec::with_capacity(args.reps);
            for _ in 0..args.reps {
                let start = Instant::now();
                f()?;
                v.push(start.elapsed().as_secs_f64());
            }
            Ok(median(v))
        };
        let forward = time(&mut || {
            prior.mdm.predict_x0(&x, &t, &text)?;
            Ok(())
        })?;
        let sample = time(&mut || {
            sampler.sample(&prior.mdm, &x, &text, Guidance::none())?;
            Ok(())
        })?;
        let z = Var::from_tensor(&x)?;
        let step = time(&mut || {
            let out = sampler.sample_unrolled(&prior.mdm, z.as_tensor(), &text, Guidance::none())?;
            let loss = prior.to_joints(&out)?.narrow(3, 1, 1)?.mean_all()?;
            let grads = loss.backward()?;
            anyhow::ensure!(grads.get(z.as_tensor()).is_some(), "no gradient reached the noise");
            Ok(())
        })?;
        println!("| {b} | {forward:.4} | {sample:.3} | {step:.3} | {:.0} | {:.0} |", step * 500.0, peak_rss_mib());
    }
    Ok(())
}
