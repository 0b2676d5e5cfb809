//! `mogen bench prior`: speed of the shipped prior on this machine.
//!
//! The CPU kernels run the best vector instruction set the CPU has; `MOGEN_SIMD=avx2` keeps
//! them on AVX2/FMA on a CPU with AVX-512 (the path a CPU without AVX-512 runs).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use candle_core::{Tensor, Var};
use clap::Args;
use motion_core::diffusion::noise::gaussian;
use motion_core::diffusion::{DdimSampler, Denoiser, Guidance, NoiseSchedule};
use motion_core::export::write_atomically;
use motion_core::model::bench::sgemm_gflops;
use motion_core::nn::Isa;
use motion_core::npy::npy_bytes;
use motion_core::optim::AdamW;
use motion_core::prior::Prior;
use motion_core::representation::FEATURE_DIM;
use serde::Serialize;

use crate::cli::load;
use crate::cli::measure::{median, peak_rss_mib};
use agent::paths;

/// Timings of the shipped prior's DNO step. The CPU kernels run the best vector instruction
/// set of this CPU; set `MOGEN_SIMD=avx2` to keep them on AVX2/FMA on a CPU with AVX-512 (what
/// a CPU without AVX-512 runs). Every row names the set it ran.
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
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
    /// Print one JSON object per batch size instead of the table.
    #[arg(long)]
    json: bool,
    /// Also write one batch-1 step (z, joints, loss, gradient as .npy) into this folder, for
    /// the PyTorch mirror's parity check (`benches/pytorch/`).
    #[arg(long)]
    dump: Option<PathBuf>,
    /// Instead of the prior, time the kernels' f32 product on a square `[SIDE, SIDE]` matrix
    /// (rows split over the threads, as in the denoiser): the machine's sgemm rate that the
    /// step's GFLOP/s are measured against.
    #[arg(long, value_name = "SIDE")]
    sgemm: Option<usize>,
}

pub fn run(args: BenchArgs) -> anyhow::Result<()> {
    match args.threads {
        // A pool of its own for another thread count (the command's worker waits meanwhile).
        Some(threads) => rayon::ThreadPoolBuilder::new().num_threads(threads).build()?.install(|| run_in_pool(args)),
        None => run_in_pool(args),
    }
}

/// Median timings of one batch size (seconds), printed as a table row or a JSON line.
#[derive(Debug, Serialize)]
struct Row {
    batch: usize,
    threads: usize,
    /// The instruction set of the CPU kernels (`avx512`, `avx2`, `baseline`).
    simd: String,
    forward_s: f64,
    sample_s: f64,
    dno_step_s: f64,
    peak_rss_mib: f64,
}

/// The sgemm rate of the kernels on this machine, printed as a line or a JSON object.
#[derive(Debug, Serialize)]
struct SgemmRow {
    sgemm: usize,
    threads: usize,
    simd: String,
    gflops: f64,
}

fn run_in_pool(args: BenchArgs) -> anyhow::Result<()> {
    let isa = Isa::for_request(Isa::request_from_env()?);
    if let Some(side) = args.sgemm {
        let gflops = sgemm_gflops(isa, side, args.reps)?;
        let row = SgemmRow { sgemm: side, threads: rayon::current_num_threads(), simd: isa.to_string(), gflops };
        if args.json {
            println!("{}", serde_json::to_string(&row)?);
        } else {
            println!("sgemm {side}×{side}, {} threads, {isa}: {gflops:.1} GFLOP/s", row.threads);
        }
        return Ok(());
    }
    let device = load::device()?;
    let prior = load::load_prior(&args.prior, &device)?;
    let cfg = prior.mdm.config();
    let sampler = DdimSampler::new(&NoiseSchedule::mdm(), args.ddim_steps)?;
    if let Some(dir) = &args.dump {
        dump_step(&prior, &sampler, args.frames, dir)?;
    }
    if !args.json {
        println!(
            "prior: d={} ff={} layers={} heads={} ({} parameters); {} frames; {} threads; {}",
            cfg.latent_dim,
            cfg.ff_size,
            cfg.num_layers,
            cfg.num_heads,
            cfg.parameter_count(),
            args.frames,
            rayon::current_num_threads(),
            prior.mdm.isa(),
        );
        println!("| batch | denoiser forward (s) | ddim{k} sample, no graph (s) | DNO step: ddim{k} unrolled, joints, loss, backward to the noise, Adam (s) | 500 DNO steps (s) | peak RSS (MiB) |", k = args.ddim_steps);
        println!("|---|---|---|---|---|---|");
    }
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
        let mut adam = AdamW::new(vec![z.clone()], 0.0)?;
        let step = time(&mut || {
            let (_, grads) = step_loss(&prior, &sampler, &z, &text)?;
            adam.step(&grads, DNO_LR)?;
            Ok(())
        })?;
        let row = Row {
            batch: b,
            threads: rayon::current_num_threads(),
            simd: prior.mdm.isa().to_string(),
            forward_s: forward,
            sample_s: sample,
            dno_step_s: step,
            peak_rss_mib: peak_rss_mib(),
        };
        if args.json {
            println!("{}", serde_json::to_string(&row)?);
        } else {
            println!(
                "| {b} | {forward:.4} | {sample:.3} | {step:.3} | {:.0} | {:.0} |",
                step * 500.0,
                row.peak_rss_mib
            );
        }
    }
    Ok(())
}

/// DNO's learning rate (the Adam step of the timed loop).
const DNO_LR: f64 = 0.05;

/// The timed DNO step's loss: DDIM unrolled from the noise `z`, joints on the rest skeleton,
/// and the mean joint height (m) standing in for a task's constraint loss; its gradients.
fn step_loss(
    prior: &Prior,
    sampler: &DdimSampler,
    z: &Var,
    text: &Tensor,
) -> anyhow::Result<(Tensor, candle_core::backprop::GradStore)> {
    let out = sampler.sample_unrolled(&prior.mdm, z.as_tensor(), text, Guidance::none())?;
    let loss = prior.to_joints(&out)?.narrow(3, 1, 1)?.mean_all()?;
    let grads = loss.backward()?;
    anyhow::ensure!(grads.get(z.as_tensor()).is_some(), "no gradient reached the noise");
    Ok((loss, grads))
}

/// Writes one batch-1 step for a mirror to check its maths against: the empty prompt's
/// condition `text.npy` `[1, text_dim]`, the noise `z.npy` `[1, frames, 263]`, the unrolled
/// sample's joints `joints.npy` `[1, frames, 22, 3]`, the loss `loss.npy` `[1]` and its
/// gradient `grad.npy` with respect to `z`.
fn dump_step(prior: &Prior, sampler: &DdimSampler, frames: usize, dir: &Path) -> anyhow::Result<()> {
    let device = load::device()?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let text = prior.encode_text(&[""], &device)?;
    let z = Var::from_tensor(&gaussian((1, frames, FEATURE_DIM), 7, &device)?)?;
    let out = sampler.sample(&prior.mdm, z.as_tensor(), &text, Guidance::none())?;
    let (loss, grads) = step_loss(prior, sampler, &z, &text)?;
    let grad = grads.get(z.as_tensor()).context("no gradient reached the noise")?;
    for (name, tensor) in [
        ("text", text.clone()),
        ("z", z.as_tensor().clone()),
        ("joints", prior.to_joints(&out)?),
        ("loss", loss.reshape(1)?),
        ("grad", grad.clone()),
    ] {
        let bytes = npy_bytes(&tensor).map_err(anyhow::Error::msg)?;
        let path = dir.join(format!("{name}.npy"));
        write_atomically(&path, &bytes).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
