//! Timing of the denoiser in the diffusion-noise-optimisation hot loop.
//!
//! A DNO step unrolls K denoiser passes from the optimised noise z and backpropagates a loss
//! on the result to z (Karunratanakul et al., "Optimizing Diffusion Noise Can Serve As
//! Universal Motion Priors", CVPR 2024). Run the sweep with
//! `CANDLE_NUM_THREADS=1 RAYON_NUM_THREADS=2 cargo test --release -p motion-core bench_sweep -- --ignored --nocapture`.

use std::time::Instant;

use candle_core::{DType, Device, Result, Tensor, Var};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use serde::Serialize;

use super::config::MdmConfig;
use super::mdm::Mdm;
use crate::diffusion::Denoiser;
use crate::nn::isa::Isa;
use crate::nn::kernels::{gemm_into, par_each, row_chunks, rows_of, split_rows, MatView};

/// Frames per motion in the benchmark (5 s at 20 fps).
pub const BENCH_FRAMES: usize = 100;
/// Unrolled denoiser passes per DNO step.
pub const BENCH_STEPS_K: usize = 10;

/// Which forward implementation to time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum DenoiserPath {
    /// [`Denoiser::predict_x0`]: fused custom ops, input gradient only.
    Frozen,
    /// [`Mdm::forward_eval`]: primitive candle ops (the training path without dropout).
    Primitive,
}

/// Median seconds of one DNO step at one batch size.
#[derive(Debug, Clone, Serialize)]
pub struct StepTiming {
    /// Motions optimised together (classifier-free guidance doubles it).
    pub batch: usize,
    /// K denoiser passes with graph recording, plus the loss.
    pub forward_s: f64,
    /// `loss.backward()`.
    pub backward_s: f64,
    /// Forward, backward and freeing the graph (the median step, not the sum of medians).
    pub step_s: f64,
    /// Fastest and slowest step seen.
    pub step_range_s: (f64, f64),
}

/// Timings of one configuration and path.
#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    /// Model sizes.
    pub config: MdmConfig,
    /// Implementation timed.
    pub path: DenoiserPath,
    /// One denoiser pass at batch 1, [`BENCH_FRAMES`] frames, no graph (median seconds).
    pub forward_no_graph_s: f64,
    /// DNO steps (K = [`BENCH_STEPS_K`]) per batch size.
    pub steps: Vec<StepTiming>,
}

fn randn(shape: &[usize], rng: &mut StdRng) -> Result<Tensor> {
    let n = shape.iter().product();
    let v: Vec<f32> = (0..n).map(|_| StandardNormal.sample(&mut *rng)).collect();
    Tensor::from_vec(v, shape, &Device::Cpu)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

fn predict(model: &Mdm, path: DenoiserPath, x: &Tensor, t: &Tensor, text: &Tensor) -> Result<Tensor> {
    match path {
        DenoiserPath::Frozen => model.predict_x0(x, t, text),
        DenoiserPath::Primitive => model.forward_eval(x, t, text),
    }
}

/// x̂0 after K unrolled steps `x_{k−1} = a_k·x̂0(x_k, t_k) + b_k·x_k` from `z`.
fn unrolled(model: &Mdm, path: DenoiserPath, z: &Tensor, text: &Tensor) -> Result<Tensor> {
    let batch = z.dim(0)?;
    let mut x = z.clone();
    let mut x0 = z.clone();
    for k in (0..BENCH_STEPS_K).rev() {
        let t = Tensor::from_vec(vec![(k * 100) as u32; batch], batch, z.device())?;
        x0 = predict(model, path, &x, &t, text)?;
        let a = 1.0 - k as f64 / BENCH_STEPS_K as f64;
        x = ((&x0 * a)? + (&x * (1.0 - a).sqrt())?)?;
    }
    Ok(x0)
}

/// Times `cfg` on the CPU in f32 with seeded random weights: one no-graph pass, then DNO
/// steps (K=10, 100 frames, mean-square loss, backward to a `Var` z) for each batch size;
/// medians over `reps` runs after one warm-up.
pub fn bench_denoiser(cfg: &MdmConfig, path: DenoiserPath, batches: &[usize], reps: usize) -> Result<BenchReport> {
    let dev = Device::Cpu;
    let model = Mdm::random(cfg.clone(), DType::F32, &dev, 7)?;
    let mut rng = StdRng::seed_from_u64(11);
    let reps = reps.max(1);

    let x = randn(&[1, BENCH_FRAMES, cfg.input_feats], &mut rng)?;
    let text = randn(&[1, cfg.text_dim], &mut rng)?;
    let t = Tensor::from_vec(vec![500u32], 1, &dev)?;
    let mut fwd = Vec::new();
    for i in 0..=reps {
        let start = Instant::now();
        predict(&model, path, &x, &t, &text)?.sum_all()?.to_scalar::<f32>()?;
        if i > 0 {
            fwd.push(start.elapsed().as_secs_f64());
        }
    }

    let mut steps = Vec::new();
    for &batch in batches {
        let z = Var::from_tensor(&randn(&[batch, BENCH_FRAMES, cfg.input_feats], &mut rng)?)?;
        let text = randn(&[batch, cfg.text_dim], &mut rng)?;
        let (mut f, mut b, mut s) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..=reps {
            let start = Instant::now();
            let loss = unrolled(&model, path, z.as_tensor(), &text)?.sqr()?.mean_all()?;
            let forward_done = Instant::now();
            let grads = loss.backward()?;
            let backward_done = Instant::now();
            if grads.get(z.as_tensor()).is_none() {
                candle_core::bail!("no gradient reached z");
            }
            drop(grads);
            drop(loss);
            if i > 0 {
                f.push((forward_done - start).as_secs_f64());
                b.push((backward_done - forward_done).as_secs_f64());
                s.push(start.elapsed().as_secs_f64());
            }
        }
        let range = (s.iter().copied().fold(f64::INFINITY, f64::min), s.iter().copied().fold(0.0, f64::max));
        steps.push(StepTiming {
            batch,
            forward_s: median(&mut f),
            backward_s: median(&mut b),
            step_s: median(&mut s),
            step_range_s: range,
        });
    }
    Ok(BenchReport { config: cfg.clone(), path, forward_no_graph_s: median(&mut fwd), steps })
}

/// Median seconds of one training step (seeded `Var` weights, [`Mdm::forward_train`] with
/// dropout, mean-square loss against a target, `backward`; no optimiser update) on the CPU.
pub fn bench_train_step(cfg: &MdmConfig, batch: usize, frames: usize, reps: usize) -> Result<f64> {
    let dev = Device::Cpu;
    let model = Mdm::init_seeded(cfg.clone(), &candle_nn::VarMap::new(), DType::F32, &dev, 7)?;
    let mut rng = StdRng::seed_from_u64(12);
    let x = randn(&[batch, frames, cfg.input_feats], &mut rng)?;
    let target = randn(&[batch, frames, cfg.input_feats], &mut rng)?;
    let text = randn(&[batch, cfg.text_dim], &mut rng)?;
    let t = Tensor::from_vec((0..batch).map(|i| (i * 997 % 1000) as u32).collect::<Vec<_>>(), batch, &dev)?;
    let mut times = Vec::new();
    for i in 0..=reps.max(1) {
        let start = Instant::now();
        let loss = (model.forward_train(&x, &t, &text, &mut rng)? - &target)?.sqr()?.mean_all()?;
        let grads = loss.backward()?;
        drop(grads);
        if i > 0 {
            times.push(start.elapsed().as_secs_f64());
        }
    }
    Ok(median(&mut times))
}

/// The rate of `gemm_into` on `isa` on a square f32 product `[side, side]·[side, side]`
/// (GFLOP/s, 2·side³ flops per product), its rows split into one block per thread of the
/// current rayon pool as the fused layer splits its own: the median of `reps` products after
/// one warm-up. Entries are small integers, so the rate does not depend on the values.
pub fn sgemm_gflops(isa: Isa, side: usize, reps: usize) -> Result<f64> {
    let a: Vec<f32> = (0..side * side).map(|i| (i % 7) as f32 - 3.0).collect();
    let b: Vec<f32> = (0..side * side).map(|i| (i % 5) as f32 - 2.0).collect();
    let mut c = vec![0f32; side * side];
    let chunks = row_chunks(side, rayon::current_num_threads());
    let mut times = Vec::with_capacity(reps);
    for rep in 0..=reps.max(1) {
        let tasks: Vec<_> = chunks.iter().copied().zip(split_rows(&mut c, side, chunks.iter().copied())).collect();
        let start = std::time::Instant::now();
        par_each(tasks, |(r, out)| {
            let rows = MatView::contiguous(0, 1, r.len, side);
            gemm_into(isa, out, rows, rows_of(&a, side, r), rows, &b, MatView::contiguous(0, 1, side, side), false)
        })?;
        if rep > 0 {
            times.push(start.elapsed().as_secs_f64());
        }
    }
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    Ok(2.0 * (side as f64).powi(3) / median / 1e9)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The size sweep; `MDM_BENCH_SIZES="128/256/4,256/512/4"` and `MDM_BENCH_REPS` override.
    #[test]
    #[ignore = "timing run; use --release and --ignored"]
    fn bench_sweep() -> Result<()> {
        let sizes =
            std::env::var("MDM_BENCH_SIZES").unwrap_or_else(|_| "128/256/4,128/512/4,192/384/4,256/512/4".into());
        let reps = std::env::var("MDM_BENCH_REPS").ok().and_then(|r| r.parse().ok()).unwrap_or(5);
        let paths = match std::env::var("MDM_BENCH_PATHS").as_deref() {
            Ok("frozen") => vec![DenoiserPath::Frozen],
            _ => vec![DenoiserPath::Frozen, DenoiserPath::Primitive],
        };
        for size in sizes.split(',') {
            let v: Vec<usize> = size.split('/').map(|p| p.trim().parse().expect("latent/ff/layers")).collect();
            let cfg = MdmConfig { latent_dim: v[0], ff_size: v[1], num_layers: v[2], ..MdmConfig::small() };
            for &path in &paths {
                let r = bench_denoiser(&cfg, path, &[1, 2, 8], reps)?;
                println!("{}", serde_json::to_string(&r).expect("json"));
            }
            if std::env::var("MDM_BENCH_TRAIN").is_ok() {
                let train = bench_train_step(&cfg, 32, BENCH_FRAMES, reps)?;
                println!(
                    "{{\"config\": {}, \"train_step_b32_t100_s\": {train}}}",
                    serde_json::to_string(&cfg).expect("json")
                );
            }
        }
        Ok(())
    }

    #[test]
    fn bench_runs_on_a_tiny_config() -> Result<()> {
        let cfg = MdmConfig { latent_dim: 16, ff_size: 32, num_layers: 1, num_heads: 2, ..MdmConfig::small() };
        let r = bench_denoiser(&cfg, DenoiserPath::Frozen, &[1], 1)?;
        assert!(r.forward_no_graph_s > 0.0 && r.steps[0].step_s > 0.0);
        Ok(())
    }
}
