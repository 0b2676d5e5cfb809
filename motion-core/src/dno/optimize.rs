//! The DNO loop (Karunratanakul et al., "Optimizing Diffusion Noise Can Serve As Universal
//! Motion Priors", CVPR 2024; `dno.py` `DNO.__call__`, anchors §2.1) and a driver that keeps
//! the best of several random restarts.

use candle_core::{DType, Device, Result, Tensor, Var, D};
use rand::rngs::StdRng;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use super::config::DnoConfig;
use super::regularizer::noise_regularize_1d;
use super::solver::Solver;
use crate::diffusion::noise::{gaussian, gaussian_from_rng};
use crate::optim::AdamW;

/// Floor under the norms that are divided by or differentiated (DNO has none): keeps a sample
/// whose gradient is exactly zero, or z at z_start, from producing NaN.
const NORM_FLOOR: f64 = 1e-12;

/// What one optimisation step did, per sample (vectors have one entry per batch row).
#[derive(Debug, Clone, PartialEq)]
pub struct DnoStep {
    /// 0-based step index.
    pub step: usize,
    /// Total steps N.
    pub steps: usize,
    /// Learning rate used by this step's update.
    pub lr: f64,
    /// Criterion loss of this step's forward x.
    pub loss: Vec<f64>,
    /// Decorrelation regulariser R(z), unweighted (0 when `decorrelate_scale` is 0).
    pub decorrelation: Vec<f64>,
    /// ‖z − z_start‖₂ before the update.
    pub diff_norm: Vec<f64>,
    /// ‖∂total/∂z_b‖₂ before normalisation.
    pub grad_norm: Vec<f64>,
}

/// One sample's curves, one entry per step (the lr curve is `DnoConfig::learning_rate`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SampleHistory {
    /// Criterion loss.
    pub loss: Vec<f64>,
    /// Unweighted decorrelation term.
    pub decorrelation: Vec<f64>,
    /// Gradient norm before normalisation.
    pub grad_norm: Vec<f64>,
}

/// The outcome of [`optimize`].
#[derive(Debug, Clone)]
pub struct DnoResult {
    /// Optimised noise after the last update, `[batch, frames, 263]` (with
    /// [`DnoConfig::keep_best`]: each sample's best iterate, the noise of `x`).
    pub z: Tensor,
    /// Motion of the LAST forward (before the last update, as DNO returns it; with
    /// `keep_best`, of each sample's lowest loss), detached, `[batch, frames, 263]` normalised
    /// features.
    pub x: Tensor,
    /// Criterion loss of `x`, per sample.
    pub loss: Vec<f64>,
    /// Curves per sample.
    pub history: Vec<SampleHistory>,
}

/// The outcome of [`optimize_with_restarts`].
#[derive(Debug, Clone)]
pub struct RestartsResult {
    /// Per sample, the restart with the lowest final loss (z, x, loss, history all from it).
    pub best: DnoResult,
    /// Winning restart index per sample.
    pub chosen: Vec<usize>,
    /// Final criterion loss `[restart][sample]`.
    pub final_loss: Vec<Vec<f64>>,
}

/// Optimises the start noise z so that `criterion(solver(z))` falls (DNO).
///
/// - `solver`: z → x, `[batch, frames, 263]` → `[batch, frames, 263]`, differentiable;
/// - `criterion`: x → per-sample loss `[batch]`; the batch is summed, so samples are optimised
///   jointly but independently;
/// - `z0`: start noise `[batch, frames, channels]` (time is axis 1), e.g. N(0, I) or a DDIM
///   inversion;
/// - `on_step`: called after every step (progress bars, logs).
///
/// Each step s, as DNO:
/// 1. lr = `config.learning_rate(s)`; x = solver(z);
/// 2. total = Σ_b criterion(x)_b + diff_penalty_scale·Σ_b ‖z_b − z0_b‖₂
///    + decorrelate_scale·Σ_b R(z)_b;
/// 3. backward, then g_b ← g_b/‖g_b‖₂ per sample (if `normalize_gradient`);
/// 4. Adam step on z, then the optional perturbation z += N(0, I)·perturb_scale·lr factor.
///
/// Only z is updated: the solver's weights stay frozen. The loop's noise comes from a stream
/// derived from `config.seed`, so a run is reproducible. Every run takes its whole budget of
/// `config.steps` (the paper's schedule; [`optimize_until`] may end sooner).
pub fn optimize<S: Solver + ?Sized>(
    solver: &S,
    criterion: impl Fn(&Tensor) -> Result<Tensor>,
    z0: &Tensor,
    config: &DnoConfig,
    on_step: impl FnMut(&DnoStep),
) -> Result<DnoResult> {
    optimize_until(solver, criterion, z0, config, on_step, |s, _| Ok(vec![false; s.loss.len()]))
}

/// [`optimize`], asking `done` after every step which samples are done before the budget:
/// `done` gets the step's figures and the motion `x` `[batch, frames, 263]` the result returns
/// when the run ends there (the forward of that step, or with `keep_best` the best iterate's),
/// and answers per row (`[batch]`, true: done).
///
/// A row once done is held: its noise and motion stay those of the step it was done on, the
/// solver no longer runs it ([`Solver::solve_rows`]: a done sample costs no more denoiser
/// passes), and the criterion sees its held motion. The run ends when every row is done.
pub fn optimize_until<S: Solver + ?Sized>(
    solver: &S,
    criterion: impl Fn(&Tensor) -> Result<Tensor>,
    z0: &Tensor,
    config: &DnoConfig,
    mut on_step: impl FnMut(&DnoStep),
    mut done: impl FnMut(&DnoStep, &Tensor) -> Result<Vec<bool>>,
) -> Result<DnoResult> {
    config.validate()?;
    let (batch, _, _) = z0.dims3()?;
    let z_start = z0.detach();
    let z = Var::from_tensor(&z_start)?;
    let mut adam = AdamW::new(vec![z.clone()], 0.0)?;
    let mut rng = loop_rng(config.seed);
    let mut history = vec![SampleHistory::default(); batch];
    let mut last: Option<(Tensor, Vec<f64>)> = None;
    // With `keep_best`: per sample, the iterate with the lowest loss so far (z, x, loss).
    let mut best: Option<(Tensor, Tensor, Vec<f64>)> = None;
    // Rows done, and the noise and motion `[batch, ...]` they are held at (other rows unused).
    let mut held_rows = vec![false; batch];
    let mut held: Option<(Tensor, Tensor)> = None;
    for step in 0..config.steps {
        let lr_factor = config.lr_factor(step);
        let lr = config.lr * lr_factor;

        let x = match &held {
            None => solver.solve(z.as_tensor())?,
            Some((_, x_held)) => solve_unheld(solver, z.as_tensor(), x_held, &held_rows)?,
        };
        // A copy: a solver may return z's own storage, which the update below overwrites.
        let x_out = x.detach().copy()?;
        let loss = criterion(&x)?;
        if loss.dims() != [batch] {
            candle_core::bail!("DNO criterion returned shape {:?}, expected [{batch}]", loss.dims());
        }
        let mut total = loss.sum_all()?.to_dtype(z.dtype())?;

        let diff_norm = per_sample_norm(&(z.as_tensor() - &z_start)?)?;
        if config.diff_penalty_scale > 0.0 {
            total = (total + (diff_norm.sum_all()? * config.diff_penalty_scale)?)?;
        }
        let decorrelation = if config.decorrelate_scale > 0.0 {
            let r = noise_regularize_1d(z.as_tensor(), &mut rng)?;
            total = (total + (r.sum_all()? * config.decorrelate_scale)?)?;
            r
        } else {
            Tensor::zeros(batch, z.dtype(), z.device())?
        };

        let loss_now = to_f64(&loss)?;
        // The noise of this step's motion (the update below moves z past it).
        let z_now = z.as_tensor().detach().copy()?;
        if config.keep_best {
            let z_now = z_now.clone();
            best = Some(match best {
                None => (z_now, x_out.clone(), loss_now.clone()),
                Some((z_best, x_best, loss_best)) => {
                    let take: Vec<bool> = loss_now.iter().zip(&loss_best).map(|(&n, &o)| beats(n, o)).collect();
                    let loss = loss_now
                        .iter()
                        .zip(&loss_best)
                        .zip(&take)
                        .map(|((&n, &o), &t)| if t { n } else { o })
                        .collect();
                    (take_rows(&take, &z_now, &z_best)?, take_rows(&take, &x_out, &x_best)?, loss)
                }
            });
        }

        let mut grads = total.backward()?;
        let grad =
            grads.remove(z.as_tensor()).ok_or_else(|| candle_core::Error::Msg("DNO: no gradient reached z".into()))?;
        let grad_norm = per_sample_norm(&grad)?;
        let grad =
            if config.normalize_gradient { grad.broadcast_div(&grad_norm.reshape((batch, 1, 1))?)? } else { grad };
        grads.insert(z.as_tensor(), grad);
        adam.step(&grads, lr)?;
        if config.perturb_scale > 0.0 {
            let noise = gaussian_from_rng(z.shape(), &mut rng, z.device())?.to_dtype(z.dtype())?;
            z.set(&(z.as_tensor() + (noise * (config.perturb_scale * lr_factor))?)?)?;
        }
        if let Some((z_held, _)) = &held {
            // Held rows stay where they were done (the regulariser still reaches them).
            z.set(&take_rows(&held_rows, z_held, z.as_tensor())?)?;
        }

        let report = DnoStep {
            step,
            steps: config.steps,
            lr,
            loss: loss_now,
            decorrelation: to_f64(&decorrelation)?,
            diff_norm: to_f64(&diff_norm)?,
            grad_norm: to_f64(&grad_norm)?,
        };
        for (b, h) in history.iter_mut().enumerate() {
            h.loss.push(report.loss[b]);
            h.decorrelation.push(report.decorrelation[b]);
            h.grad_norm.push(report.grad_norm[b]);
        }
        on_step(&report);
        // The motion the run hands on were it to end here: the best iterate with `keep_best`.
        let handed_on = best.as_ref().map_or(&x_out, |(_, x, _)| x);
        let rows_done = done(&report, handed_on)?;
        if rows_done.len() != batch {
            candle_core::bail!("DNO: done answered {} rows, expected {batch}", rows_done.len());
        }
        let newly: Vec<bool> = rows_done.iter().zip(&held_rows).map(|(&d, &h)| d && !h).collect();
        let all_done = rows_done.iter().zip(&held_rows).all(|(&d, &h)| d || h);
        if newly.iter().any(|&n| n) && !all_done {
            // Newly done rows are held at this step's noise and motion.
            held = Some(match held {
                None => (z_now.clone(), x_out.clone()),
                Some((z_held, x_held)) => (take_rows(&newly, &z_now, &z_held)?, take_rows(&newly, &x_out, &x_held)?),
            });
            for (h, &n) in held_rows.iter_mut().zip(&newly) {
                *h |= n;
            }
            z.set(&take_rows(&newly, &z_now, z.as_tensor())?)?;
        }
        last = Some((x_out, report.loss));
        if all_done {
            break;
        }
    }
    let (x, loss) = last.ok_or_else(|| candle_core::Error::Msg("DNO ran no steps".into()))?;
    Ok(match best {
        Some((z, x, loss)) => DnoResult { z, x, loss, history },
        None => DnoResult { z: z.as_tensor().detach(), x, loss, history },
    })
}

/// Runs `config.restarts` independent DNO runs from seeded random noise and keeps, per sample,
/// the run with the lowest final criterion loss (RG-DNO's "N_S random-noise searches").
///
/// Restart r starts from `gaussian(shape, seed + r)` (f32 N(0, I), `shape` = `[batch, frames,
/// 263]`) and runs [`optimize_until`] with seed `seed + r`; `on_step` and `done` get the restart
/// index. A NaN loss never wins over a number.
pub fn optimize_with_restarts<S: Solver + ?Sized>(
    solver: &S,
    criterion: impl Fn(&Tensor) -> Result<Tensor>,
    shape: (usize, usize, usize),
    device: &Device,
    config: &DnoConfig,
    mut on_step: impl FnMut(usize, &DnoStep),
    mut done: impl FnMut(usize, &DnoStep, &Tensor) -> Result<Vec<bool>>,
) -> Result<RestartsResult> {
    config.validate()?;
    let mut best: Option<DnoResult> = None;
    let mut chosen = vec![0; shape.0];
    let mut final_loss = Vec::with_capacity(config.restarts);
    for r in 0..config.restarts {
        let seed = config.seed.wrapping_add(r as u64);
        let run_config = DnoConfig { seed, ..config.clone() };
        let z0 = gaussian(shape, seed, device)?;
        let run = optimize_until(solver, &criterion, &z0, &run_config, |s| on_step(r, s), |s, x| done(r, s, x))?;
        final_loss.push(run.loss.clone());
        best = Some(match best {
            None => run,
            Some(old) => {
                let wins: Vec<bool> = run.loss.iter().zip(&old.loss).map(|(&new, &old)| beats(new, old)).collect();
                for (c, &w) in chosen.iter_mut().zip(&wins) {
                    if w {
                        *c = r;
                    }
                }
                merge_rows(old, run, &wins)?
            }
        });
    }
    let best = best.ok_or_else(|| candle_core::Error::Msg("DNO ran no restarts".into()))?;
    Ok(RestartsResult { best, chosen, final_loss })
}

/// The motion `[batch, frames, 263]` of noise `z`: the solver's on the rows not `held`, and
/// the rows of `x_held` on the others (no gradient reaches their noise through it).
fn solve_unheld<S: Solver + ?Sized>(solver: &S, z: &Tensor, x_held: &Tensor, held: &[bool]) -> Result<Tensor> {
    let running: Vec<u32> = (0..held.len()).filter(|&b| !held[b]).map(|b| b as u32).collect();
    let rows = Tensor::new(running.as_slice(), z.device())?;
    let x_running = solver.solve_rows(&z.index_select(&rows, 0)?, &rows)?;
    // Row b of the result: its place among the running rows, or its row of `x_held` after them.
    let mut place = 0u32;
    let order: Vec<u32> = held
        .iter()
        .enumerate()
        .map(|(b, &h)| {
            if h {
                (running.len() + b) as u32
            } else {
                place += 1;
                place - 1
            }
        })
        .collect();
    Tensor::cat(&[&x_running, &x_held.detach()], 0)?.index_select(&Tensor::new(order.as_slice(), z.device())?, 0)
}

/// Whether loss `new` should replace `old`: lower, or a number against NaN.
pub(crate) fn beats(new: f64, old: f64) -> bool {
    new < old || (old.is_nan() && !new.is_nan())
}

/// `old` `[B, ...]` with the rows (samples) of `new` where `take` (length B) is true.
pub(crate) fn take_rows(take: &[bool], new: &Tensor, old: &Tensor) -> Result<Tensor> {
    let mask: Vec<u8> = take.iter().map(|&t| u8::from(t)).collect();
    let mut shape = vec![1; old.rank()];
    shape[0] = take.len();
    let mask = Tensor::from_vec(mask, shape, old.device())?;
    mask.broadcast_as(old.shape())?.where_cond(new, old)
}

/// `old` with the rows of `new` where `take` is true.
fn merge_rows(old: DnoResult, new: DnoResult, take: &[bool]) -> Result<DnoResult> {
    let pick = |new: &Tensor, old: &Tensor| take_rows(take, new, old);
    let rows = old.loss.into_iter().zip(old.history).zip(new.loss.into_iter().zip(new.history)).zip(take);
    let (loss, history) = rows.map(|(((lo, ho), (ln, hn)), &t)| if t { (ln, hn) } else { (lo, ho) }).unzip();
    Ok(DnoResult { z: pick(&new.z, &old.z)?, x: pick(&new.x, &old.x)?, loss, history })
}

/// ‖t_b‖₂ over all non-batch elements, floored at [`NORM_FLOOR`], `[batch]`. The floor is
/// applied before the square root, so the gradient at t_b = 0 is 0, not NaN.
pub(crate) fn per_sample_norm(t: &Tensor) -> Result<Tensor> {
    t.sqr()?.flatten_from(1)?.sum(D::Minus1)?.maximum(NORM_FLOOR * NORM_FLOOR)?.sqrt()
}

fn to_f64(t: &Tensor) -> Result<Vec<f64>> {
    t.to_dtype(DType::F64)?.to_vec1::<f64>()
}

/// The loop's random stream (padding noise, perturbation) for `seed`: a `StdRng` keyed by the
/// seed and a stream tag, so it never replays the start noise `gaussian(_, seed)`.
fn loop_rng(seed: u64) -> StdRng {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    key[8..16].copy_from_slice(b"dno-loop");
    StdRng::from_seed(key)
}
