//! Tests of the DNO loop on toy problems and on a tiny random MDM.

use candle_core::{DType, Device, Result, Tensor, D};

use super::*;
use crate::diffusion::noise::gaussian;
use crate::diffusion::Guidance;
use crate::model::{Mdm, MdmConfig};
use crate::representation::{recover_from_ric, MeanStd, FEATURE_DIM};
use crate::testing::max_abs_diff;

const FRAMES: usize = 8;

fn identity(z: &Tensor) -> Result<Tensor> {
    Ok(z.clone())
}

/// Σ over frames and channels 0..3 of (x − target_b)², per sample: `[batch]`.
fn reach(targets: &[f32], scales: &[f32]) -> impl Fn(&Tensor) -> Result<Tensor> {
    let (targets, scales) = (targets.to_vec(), scales.to_vec());
    move |x: &Tensor| {
        let b = x.dim(0)?;
        let target = Tensor::from_vec(targets[..b].to_vec(), (b, 1, 1), x.device())?;
        let scale = Tensor::from_vec(scales[..b].to_vec(), b, x.device())?;
        let d = x.narrow(D::Minus1, 0, 3)?.broadcast_sub(&target)?;
        d.sqr()?.flatten_from(1)?.sum(D::Minus1)? * scale
    }
}

fn rows(t: &Tensor) -> Vec<Vec<f32>> {
    t.flatten_from(1).unwrap().to_vec2::<f32>().unwrap()
}

#[test]
fn toy_problems_converge_a_hundredfold_in_200_steps() {
    let dev = Device::Cpu;
    let z0 = gaussian((2, FRAMES, FEATURE_DIM), 1, &dev).unwrap();
    let w = (gaussian((FEATURE_DIM, FEATURE_DIM), 2, &dev).unwrap() / (FEATURE_DIM as f64).sqrt()).unwrap();
    let linear = move |z: &Tensor| z.broadcast_matmul(&w);
    let criterion = reach(&[1.5, -2.0], &[1.0, 1.0]);
    for decorrelate_scale in [0.0, 1000.0] {
        let config = DnoConfig { steps: 200, decorrelate_scale, ..DnoConfig::default() };
        let mut seen = Vec::new();
        let run = optimize(&identity, &criterion, &z0, &config, |s| seen.push(s.clone())).unwrap();
        assert_eq!(seen.len(), 200);
        assert!(seen.iter().all(|s| s.lr == config.learning_rate(s.step) && s.grad_norm.iter().all(|&g| g > 0.0)));
        let first = &run.history;
        for (b, h) in first.iter().enumerate() {
            assert!(h.loss[199] * 100.0 <= h.loss[0], "identity, R×{decorrelate_scale}, sample {b}: {:?}", h.loss);
        }
        assert_eq!(run.loss, seen[199].loss, "the loss of the returned x");
        let lin = optimize(&linear, &criterion, &z0, &config, |_| {}).unwrap();
        for (b, h) in lin.history.iter().enumerate() {
            assert!(h.loss[199] * 100.0 <= h.loss[0], "linear, R×{decorrelate_scale}, sample {b}: {:?}", h.loss);
        }
    }
}

#[test]
fn samples_in_a_batch_do_not_interact() {
    let dev = Device::Cpu;
    // FRAMES is a power of two, so the regulariser draws no padding noise and is exact per sample.
    let z0 = gaussian((2, FRAMES, FEATURE_DIM), 3, &dev).unwrap();
    let config = DnoConfig { steps: 30, lr_warmup_steps: 5, ..DnoConfig::default() };
    let both = optimize(&identity, reach(&[1.0, -1.0], &[1.0, 1.0]), &z0, &config, |_| {}).unwrap();
    let second = z0.narrow(0, 1, 1).unwrap();
    let alone = optimize(&identity, reach(&[-1.0], &[1.0]), &second, &config, |_| {}).unwrap();
    assert!(max_abs_diff(&both.z.narrow(0, 1, 1).unwrap(), &alone.z).unwrap() < 1e-6);
    assert!((both.loss[1] - alone.loss[0]).abs() < 1e-6 * alone.loss[0].max(1.0));
}

#[test]
fn each_sample_steps_the_same_whatever_its_loss_scale() {
    let dev = Device::Cpu;
    let one = gaussian((1, FRAMES, FEATURE_DIM), 4, &dev).unwrap();
    let z0 = Tensor::cat(&[&one, &one], 0).unwrap();
    // Without the regulariser, whose gradient does not scale with the loss.
    let config = DnoConfig { steps: 40, lr_warmup_steps: 5, decorrelate_scale: 0.0, ..DnoConfig::default() };
    let mut ratios = Vec::new();
    let run = optimize(&identity, reach(&[0.7, 0.7], &[1.0, 1000.0]), &z0, &config, |s| {
        ratios.push(s.grad_norm[1] / s.grad_norm[0]);
    })
    .unwrap();
    assert!(ratios.iter().all(|r| (r - 1000.0).abs() < 1e-2), "norms are reported before normalisation: {ratios:?}");
    let r = rows(&run.z);
    let worst = r[0].iter().zip(&r[1]).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-6, "rows differ by {worst}");
    assert!(max_abs_diff(&run.z, &z0).unwrap() > 0.1, "z moved");
}

#[test]
fn diff_penalty_keeps_z_near_its_start_and_perturbation_is_seeded() {
    let dev = Device::Cpu;
    let z0 = gaussian((1, FRAMES, FEATURE_DIM), 5, &dev).unwrap();
    let base = DnoConfig { steps: 30, lr_warmup_steps: 5, ..DnoConfig::default() };
    let free = optimize(&identity, reach(&[2.0], &[1.0]), &z0, &base, |_| {}).unwrap();
    let held = DnoConfig { diff_penalty_scale: 100.0, ..base.clone() };
    let mut diffs = Vec::new();
    let near = optimize(&identity, reach(&[2.0], &[1.0]), &z0, &held, |s| diffs.push(s.diff_norm[0])).unwrap();
    assert!(diffs[0] < 1e-5, "z starts at z_start");
    assert!(max_abs_diff(&near.z, &z0).unwrap() < 0.5 * max_abs_diff(&free.z, &z0).unwrap());

    let shaky = DnoConfig { perturb_scale: 0.1, ..base };
    let a = optimize(&identity, reach(&[2.0], &[1.0]), &z0, &shaky, |_| {}).unwrap();
    let b = optimize(&identity, reach(&[2.0], &[1.0]), &z0, &shaky, |_| {}).unwrap();
    assert_eq!(rows(&a.z), rows(&b.z));
    assert!(max_abs_diff(&a.z, &free.z).unwrap() > 1e-3);
}

#[test]
fn restarts_keep_the_best_run_per_sample() {
    let dev = Device::Cpu;
    let criterion = reach(&[1.0, -1.0], &[1.0, 1.0]);
    let config = DnoConfig { steps: 5, lr_warmup_steps: 0, restarts: 3, seed: 11, ..DnoConfig::default() };
    let mut calls = vec![0; 3];
    let out = optimize_with_restarts(
        &identity,
        &criterion,
        (2, FRAMES, FEATURE_DIM),
        &dev,
        &config,
        |r, _| calls[r] += 1,
        |_, s, _| Ok(vec![false; s.loss.len()]),
    )
    .unwrap();
    assert_eq!(calls, [5, 5, 5]);
    for b in 0..2 {
        let best = (0..3).map(|r| out.final_loss[r][b]).fold(f64::INFINITY, f64::min);
        assert_eq!(out.best.loss[b], best);
        assert_eq!(out.final_loss[out.chosen[b]][b], best);
        assert_eq!(out.best.history[b].loss[4], best);
    }
    // x and its loss come from the same run.
    let again = criterion(&out.best.x).unwrap().to_vec1::<f32>().unwrap();
    for (a, b) in again.iter().zip(&out.best.loss) {
        assert!((f64::from(*a) - b).abs() < 1e-4 * b.max(1.0));
    }
    // Restart 0 is a plain run from gaussian(shape, seed).
    let single = DnoConfig { restarts: 1, ..config };
    let z0 = gaussian((2, FRAMES, FEATURE_DIM), 11, &dev).unwrap();
    let plain = optimize(&identity, &criterion, &z0, &single, |_| {}).unwrap();
    assert_eq!(plain.loss, out.final_loss[0]);
}

/// A tiny random MDM: 20 DNO steps through ddim10 with guidance lower the pelvis height error
/// at the last frame, and a seeded run repeats exactly.
#[test]
fn real_sampler_lowers_a_joint_space_loss_and_is_reproducible() {
    let dev = Device::Cpu;
    let cfg = MdmConfig { latent_dim: 16, ff_size: 32, num_layers: 1, num_heads: 2, text_dim: 4, ..MdmConfig::small() };
    let mdm = Mdm::random(cfg, DType::F32, &dev, 7).unwrap();
    let mut mean = vec![0f32; FEATURE_DIM];
    mean[3] = 0.5;
    let mean_std = MeanStd::from_vecs(mean, vec![0.2; FEATURE_DIM], &dev).unwrap();
    let text = gaussian((2, 4), 8, &dev).unwrap();
    let solver = UnrolledDdim::from_config(&mdm, text, Guidance::default(), &DnoConfig::default()).unwrap();
    let pelvis_height_error = |x: &Tensor| -> Result<Tensor> {
        let joints = recover_from_ric(&mean_std.denormalize(x)?)?; // [B, T, 22, 3]
        let y = joints.narrow(1, FRAMES - 1, 1)?.narrow(2, 0, 1)?.narrow(3, 1, 1)?.flatten_all()?;
        // Weighted so that its gradient, which a random prior makes tiny, is not drowned by
        // the decorrelation term at DNO's weight 1000.
        (y - 0.5)?.sqr()? * 1000.0
    };
    let config = DnoConfig { steps: 20, lr_warmup_steps: 5, seed: 3, ..DnoConfig::default() };
    let z0 = gaussian((2, FRAMES, FEATURE_DIM), 3, &dev).unwrap();
    let run = optimize(&solver, pelvis_height_error, &z0, &config, |_| {}).unwrap();
    for (b, h) in run.history.iter().enumerate() {
        assert!(h.loss[19] < 0.2 * h.loss[0], "sample {b}: {:?}", h.loss);
    }
    assert_eq!(run.x.dims(), [2, FRAMES, FEATURE_DIM]);
    let again = optimize(&solver, pelvis_height_error, &z0, &config, |_| {}).unwrap();
    assert_eq!(rows(&run.z), rows(&again.z));
    assert_eq!(run.loss, again.loss);
}

#[test]
fn bad_inputs_are_errors() {
    let dev = Device::Cpu;
    let z0 = gaussian((2, FRAMES, FEATURE_DIM), 1, &dev).unwrap();
    let config = DnoConfig { steps: 2, ..DnoConfig::default() };
    let scalar = |x: &Tensor| x.sum_all();
    assert!(optimize(&identity, scalar, &z0, &config, |_| {}).is_err());
    let none = DnoConfig { steps: 0, ..config };
    assert!(optimize(&identity, reach(&[0.0, 0.0], &[1.0, 1.0]), &z0, &none, |_| {}).is_err());
}

/// A late-started solver runs only the DDIM steps from its start timestep on x_init noised by
/// z, keeps the graph back to z, and its start is x_init's SDEdit noising.
#[test]
fn a_late_start_denoises_the_noised_initial_motion_from_there() {
    let dev = Device::Cpu;
    let cfg = MdmConfig { latent_dim: 16, ff_size: 32, num_layers: 1, num_heads: 2, text_dim: 4, ..MdmConfig::small() };
    let mdm = Mdm::random(cfg, DType::F32, &dev, 7).unwrap();
    let text = gaussian((2, 4), 8, &dev).unwrap();
    let full = UnrolledDdim::new(&mdm, text.clone(), Guidance::none(), 10).unwrap();
    let x_init = gaussian((2, FRAMES, FEATURE_DIM), 4, &dev).unwrap();
    let late = full.clone().starting_late(450, &x_init).unwrap();
    assert_eq!(late.sampler.timesteps(), &[0, 100, 200, 300, 400]);
    let abar = full.sampler.alphas_cumprod()[4];
    let z = gaussian((2, FRAMES, FEATURE_DIM), 5, &dev).unwrap();
    let start = ((&x_init * abar.sqrt()).unwrap() + (&z * (1.0 - abar).sqrt()).unwrap()).unwrap();
    let expected = late.sampler.sample(&mdm, &start, &text, Guidance::none()).unwrap();
    let z_var = candle_core::Var::from_tensor(&z).unwrap();
    let got = late.solve(z_var.as_tensor()).unwrap();
    assert!(max_abs_diff(&got, &expected).unwrap() < 1e-5);
    let grads = got.sqr().unwrap().sum_all().unwrap().backward().unwrap();
    let g = grads.get(z_var.as_tensor()).expect("a gradient reaches z");
    assert!(g.abs().unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap() > 0.0);
}

#[test]
fn keep_best_returns_each_samples_lowest_iterate_and_its_noise() {
    let dev = Device::Cpu;
    let z0 = gaussian((2, FRAMES, FEATURE_DIM), 5, &dev).unwrap();
    // An lr far too high for this quadratic: Adam overshoots, so the last loss is not the lowest.
    let config = DnoConfig {
        steps: 40,
        lr: 3.0,
        lr_warmup_steps: 0,
        lr_decay_steps: Some(0),
        decorrelate_scale: 0.0,
        ..DnoConfig::default()
    };
    let criterion = reach(&[0.5, -0.5], &[1.0, 1.0]);
    let last = optimize(&identity, &criterion, &z0, &config, |_| {}).unwrap();
    let best = optimize(&identity, &criterion, &z0, &DnoConfig { keep_best: true, ..config }, |_| {}).unwrap();
    assert_eq!(best.history, last.history, "keeping the best changes what is returned, not the run");
    for (b, h) in last.history.iter().enumerate() {
        let lowest = h.loss.iter().copied().fold(f64::INFINITY, f64::min);
        assert_eq!(last.loss[b], h.loss[39], "without it: the last forward");
        assert_eq!(best.loss[b], lowest, "sample {b}: {:?}", h.loss);
    }
    assert!(last.history.iter().any(|h| h.loss[39] > h.loss.iter().copied().fold(f64::INFINITY, f64::min)));
    // The returned noise is the returned motion's (the solver is the identity) and its loss.
    assert_eq!(max_abs_diff(&best.z, &best.x).unwrap(), 0.0);
    let again: Vec<f64> = criterion(&best.x).unwrap().to_dtype(DType::F64).unwrap().to_vec1().unwrap();
    for (a, l) in again.iter().zip(&best.loss) {
        assert!((a - l).abs() <= 1e-6 * l.max(1.0), "{a} against {l}");
    }
}

#[test]
fn a_run_ends_where_done_says_with_that_steps_motion() {
    let dev = Device::Cpu;
    let z0 = gaussian((1, FRAMES, FEATURE_DIM), 3, &dev).unwrap();
    let config = DnoConfig { steps: 20, lr_warmup_steps: 0, ..DnoConfig::default() };
    let mut motions = Vec::new();
    let run = optimize_until(
        &identity,
        reach(&[2.0], &[1.0]),
        &z0,
        &config,
        |_| {},
        |s, x| {
            motions.push(x.clone());
            Ok(vec![s.step == 3])
        },
    )
    .unwrap();
    assert_eq!(motions.len(), 4, "asked after steps 0 to 3, then ended");
    assert_eq!(run.history[0].loss.len(), 4);
    assert_eq!(run.loss[0], run.history[0].loss[3]);
    let same = (&run.x - &motions[3]).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
    assert_eq!(same, 0.0, "the result is the motion of the step it ended on");
    let full = optimize_until(&identity, reach(&[2.0], &[1.0]), &z0, &config, |_| {}, |_, _| Ok(vec![false])).unwrap();
    assert_eq!(full.history[0].loss.len(), 20, "never done: the whole budget");
}

#[test]
fn a_done_row_is_held_at_its_step_and_solved_no_more() {
    let dev = Device::Cpu;
    let z0 = gaussian((3, FRAMES, FEATURE_DIM), 5, &dev).unwrap();
    let config = DnoConfig { steps: 20, lr_warmup_steps: 0, ..DnoConfig::default() };
    // The identity, recording how many rows it was asked to solve at each step.
    let solved = std::cell::RefCell::new(Vec::new());
    let counting = |z: &Tensor| {
        solved.borrow_mut().push(z.dim(0)?);
        identity(z)
    };
    let mut motions = Vec::new();
    let run = optimize_until(
        &counting,
        reach(&[2.0, -1.0, 0.5], &[1.0, 1.0, 1.0]),
        &z0,
        &config,
        |_| {},
        |s, x| {
            motions.push(x.clone());
            // Row 1 is done after step 2, row 0 after step 5, row 2 after step 7.
            Ok(vec![s.step >= 5, s.step >= 2, s.step == 7])
        },
    )
    .unwrap();
    assert_eq!(*solved.borrow(), [3, 3, 3, 2, 2, 2, 1, 1], "a done row is no longer solved");
    assert_eq!(run.history[0].loss.len(), 8, "the run ends once every row is done");
    let row = |t: &Tensor, b: usize| t.get(b).unwrap();
    // Each row's result is its motion of the step it was done on, and a held row's noise is
    // that motion's (the solver is the identity; the last step's rows keep its update).
    for (b, step) in [(0, 5), (1, 2), (2, 7)] {
        assert_eq!(max_abs_diff(&row(&run.x, b), &row(&motions[step], b)).unwrap(), 0.0, "row {b}");
        if step < 7 {
            assert_eq!(max_abs_diff(&row(&run.z, b), &row(&motions[step], b)).unwrap(), 0.0, "row {b}'s noise");
        }
        assert_eq!(run.loss[b], run.history[b].loss[step]);
        // A held row's loss stays where it was done.
        assert!(run.history[b].loss[step..].iter().all(|&l| l == run.history[b].loss[step]), "row {b}");
    }
    // The rows still running move on: row 2 between steps 2 and 7.
    assert!(max_abs_diff(&row(&motions[7], 2), &row(&motions[2], 2)).unwrap() > 0.0);
}
