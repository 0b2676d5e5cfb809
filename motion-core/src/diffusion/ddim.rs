//! Deterministic DDIM sampling and inversion for an x0-predicting denoiser, with MDM's
//! timestep respacing and classifier-free guidance.
//!
//! Song, Meng & Ermon, "Denoising Diffusion Implicit Models" (ICLR 2021), eq. 12 with σ_t = 0
//! (eta = 0), as in MDM's `GaussianDiffusion::ddim_sample` / `ddim_reverse_sample` and
//! `SpacedDiffusion` (anchors §1.5). DNO (Karunratanakul et al. 2024) optimises the start
//! noise through [`DdimSampler::sample_unrolled`] (anchors §2.2).
//!
//! All tensors are `[batch, frames, 263]` normalised features unless stated otherwise; text
//! conditions are `[batch, text_dim]`, encoded once by the caller.

use candle_core::{Result, Tensor};

pub(crate) use super::denoiser::timestep_tensor;
pub use super::denoiser::{guided_move, DdimMove};

use super::denoiser::Denoiser;
use super::error::DiffusionError;
use super::guidance::Guidance;
use super::schedule::NoiseSchedule;

/// MDM's timestep respacing "ddimK": the timesteps `range(0, T, s)` for the smallest integer
/// stride `s` in `1..T` with `len(range(0, T, s)) == steps` (`respace.py::space_timesteps`).
///
/// ddim10 → {0, 100, …, 900}; ddim50 → {0, 20, …, 980}; ddim100 → {0, 10, …, 990}. Ascending.
pub fn respaced_timesteps(num_timesteps: usize, steps: usize) -> std::result::Result<Vec<usize>, DiffusionError> {
    (1..num_timesteps)
        .find(|&stride| num_timesteps.div_ceil(stride) == steps)
        .map(|stride| (0..num_timesteps).step_by(stride).collect())
        .ok_or(DiffusionError::NoStride { timesteps: num_timesteps, steps })
}

/// What one sampling step produced, for progress displays.
#[derive(Debug)]
pub struct DdimProgress<'a> {
    /// Steps done so far, 1..=`steps`.
    pub step: usize,
    /// Total DDIM steps K.
    pub steps: usize,
    /// Original-scale timestep the denoiser was evaluated at.
    pub timestep: usize,
    /// The (guided) x̂0 predicted at this step, `[batch, frames, 263]`.
    pub x0_hat: &'a Tensor,
}

/// A K-step deterministic (eta = 0) DDIM sampler over a respaced schedule.
///
/// Spaced index k ∈ 0..K has original timestep `timesteps()[k]` and ᾱ_k =
/// `alphas_cumprod()[k]` = the original ᾱ at that timestep (MDM's `SpacedDiffusion`); the
/// denoiser is always fed the original timestep. Sampling starts at the last spaced timestep
/// (900 for ddim10, 990 for ddim100), not at T − 1.
#[derive(Debug, Clone, PartialEq)]
pub struct DdimSampler {
    timesteps: Vec<usize>,
    alphas_cumprod: Vec<f64>,
}

impl DdimSampler {
    /// The "ddim`steps`" sampler of `schedule` (see [`respaced_timesteps`]).
    pub fn new(schedule: &NoiseSchedule, steps: usize) -> std::result::Result<Self, DiffusionError> {
        let timesteps = respaced_timesteps(schedule.num_timesteps(), steps)?;
        let alphas_cumprod = timesteps.iter().map(|&t| schedule.alphas_cumprod()[t]).collect();
        Ok(Self { timesteps, alphas_cumprod })
    }

    /// The same sampler started later: only the spaced indices whose timestep is at most
    /// `max_timestep` (ddim10 from 550: timesteps 500, 400, …, 0). Index 0 is t = 0, so at
    /// least that one step is kept.
    pub fn starting_at(&self, max_timestep: usize) -> Self {
        let kept = self.timesteps.iter().take_while(|&&t| t <= max_timestep).count().max(1);
        Self { timesteps: self.timesteps[..kept].to_vec(), alphas_cumprod: self.alphas_cumprod[..kept].to_vec() }
    }

    /// The same sampler on every `stride`-th of its timesteps, counted down from the one it
    /// starts at (ddim10 by 2: timesteps 900, 700, 500, 300, 100, its last x̂0 taken at t =
    /// 100). It starts from the same latent, so a noise fitted through it means the same
    /// start for the whole sampler, at 1/`stride` of the denoiser passes (`stride` 0 or 1:
    /// unchanged).
    pub fn every(&self, stride: usize) -> Self {
        let stride = stride.max(1);
        let last = self.steps() - 1;
        let kept: Vec<usize> = (0..=last).filter(|k| (last - k) % stride == 0).collect();
        Self {
            timesteps: kept.iter().map(|&k| self.timesteps[k]).collect(),
            alphas_cumprod: kept.iter().map(|&k| self.alphas_cumprod[k]).collect(),
        }
    }

    /// Number of DDIM steps K (= denoiser evaluations per sample, without guidance).
    pub fn steps(&self) -> usize {
        self.timesteps.len()
    }

    /// Original timesteps of the spaced indices, ascending: `timesteps()[k]` for k ∈ 0..K.
    pub fn timesteps(&self) -> &[usize] {
        &self.timesteps
    }

    /// ᾱ of the spaced indices, `alphas_cumprod()[k]` for k ∈ 0..K.
    pub fn alphas_cumprod(&self) -> &[f64] {
        &self.alphas_cumprod
    }

    /// Samples x0 from the start noise `x_t` (x at the last spaced timestep), `[batch, frames,
    /// 263]`, conditioned on `text` (`[batch, text_dim]`, already encoded).
    ///
    /// Every step's result is detached, so no autograd graph survives a step even when the
    /// denoiser's weights or `x_t` are `Var`s. Returns x0, `[batch, frames, 263]`.
    pub fn sample<D: Denoiser + ?Sized>(
        &self,
        denoiser: &D,
        x_t: &Tensor,
        text: &Tensor,
        guidance: Guidance,
    ) -> Result<Tensor> {
        self.denoise(denoiser, x_t, text, guidance, false, None)
    }

    /// [`Self::sample`], calling `on_step` after every step with that step's x̂0.
    pub fn sample_with_progress<D: Denoiser + ?Sized>(
        &self,
        denoiser: &D,
        x_t: &Tensor,
        text: &Tensor,
        guidance: Guidance,
        mut on_step: impl FnMut(&DdimProgress<'_>),
    ) -> Result<Tensor> {
        self.denoise(denoiser, x_t, text, guidance, false, Some(&mut on_step))
    }

    /// [`Self::sample`] keeping the whole autograd graph (DNO's `ddim_loop_with_gradient`),
    /// so a loss on the returned x0 can be differentiated w.r.t. the start noise: pass
    /// `var.as_tensor()` of a `candle_core::Var` as `x_t`. Same values as `sample`; memory
    /// grows with K (every step's denoiser activations are kept until `backward`).
    pub fn sample_unrolled<D: Denoiser + ?Sized>(
        &self,
        denoiser: &D,
        x_t: &Tensor,
        text: &Tensor,
        guidance: Guidance,
    ) -> Result<Tensor> {
        self.denoise(denoiser, x_t, text, guidance, true, None)
    }

    /// Deterministic DDIM inversion of a clean motion `x0` (`[batch, frames, 263]`, taken as x
    /// at spaced index 0, t = 0) up to the latent at the LAST spaced timestep, the start noise
    /// that [`Self::sample`] expects.
    ///
    /// With `fixed_point_iterations` = 0 this is the classic inversion (DNO's `ddim_invert`):
    /// for k = 0..K−2, x_{k+1} = √ᾱ_{k+1}·x̂0(x_k, t_k) + √(1 − ᾱ_{k+1})·ε̂(x_k, t_k), K − 1
    /// denoiser calls. It reuses the prediction at t_k for the move to t_{k+1}, so
    /// `sample(invert(x0)) ≈ x0` only up to the DDIM (Euler) error, which falls as 1/K.
    ///
    /// With n > 0 iterations it inverts the *sampler itself*. Each move solves the sampler's
    /// step for its start, x_{k+1} = a·x_k + b·ε̂(x_{k+1}, t_{k+1}) with a = √(ᾱ_{k+1}/ᾱ_k) and
    /// b = √(1 − ᾱ_{k+1}) − a·√(1 − ᾱ_k), by fixed-point iteration from the classic guess.
    /// The map contracts because b is small and ε̂ varies slowly in x. Before the first move it
    /// solves x̂0(x_0, t_0) = x0 the same way (x_0 ← x_0 + x0 − x̂0(x_0, t_0)), because the
    /// sampler's last step returns the model's x̂0 rather than x_0. Cost: (K − 1)(n + 1) + n
    /// denoiser calls. Detached like `sample`.
    ///
    /// Deliberate difference from MDM's `ddim_reverse_sample_loop`: MDM also runs index K−1,
    /// where `alphas_cumprod_next` is padded with ᾱ = 0, and so returns ε̂(x_{K−1}), a latent
    /// for ᾱ = 0, one denoiser call later. The sampler however starts at ᾱ_{K−1} (0.0236 for
    /// ddim10), so that latent is off by about √ᾱ_{K−1}·x̂0. Stopping at K−1 returns exactly
    /// the DDIM state the sampler starts from.
    pub fn invert<D: Denoiser + ?Sized>(
        &self,
        denoiser: &D,
        x0: &Tensor,
        text: &Tensor,
        guidance: Guidance,
        fixed_point_iterations: usize,
    ) -> Result<Tensor> {
        let guidance = guidance.for_text(text)?;
        check_batch(x0, text)?;
        let predict = |x: &Tensor, t: usize| -> Result<Tensor> {
            Ok(guidance.predict_x0(denoiser, x, &timestep_tensor(t, x.dim(0)?, x.device())?, text)?.detach())
        };
        let target = x0.detach();
        let mut x = target.clone();
        for _ in 0..fixed_point_iterations {
            x = (&x + (&target - predict(&x, self.timesteps[0])?)?)?;
        }
        for k in 0..self.steps() - 1 {
            let (abar, abar_next) = (self.alphas_cumprod[k], self.alphas_cumprod[k + 1]);
            let mut next =
                denoiser.ddim_move(&x, text, guidance, DdimMove::new(self.timesteps[k], abar, abar_next))?.detach();
            let a = (abar_next / abar).sqrt();
            let b = (1.0 - abar_next).sqrt() - a * (1.0 - abar).sqrt();
            for _ in 0..fixed_point_iterations {
                let x0_hat = predict(&next, self.timesteps[k + 1])?;
                let eps =
                    (&next - x0_hat.affine(abar_next.sqrt(), 0.0)?)?.affine(1.0 / (1.0 - abar_next).sqrt(), 0.0)?;
                next = (x.affine(a, 0.0)? + eps.affine(b, 0.0)?)?;
            }
            x = next;
        }
        Ok(x)
    }

    /// The reverse loop k = K−1 … 0 shared by the samplers: each step one
    /// [`Denoiser::ddim_move`] (one fused op per step on MDM's CPU path), or with `on_step` the
    /// composed move, whose x̂0 the callback sees.
    fn denoise<D: Denoiser + ?Sized>(
        &self,
        denoiser: &D,
        x_t: &Tensor,
        text: &Tensor,
        guidance: Guidance,
        keep_graph: bool,
        mut on_step: Option<&mut dyn FnMut(&DdimProgress<'_>)>,
    ) -> Result<Tensor> {
        let guidance = guidance.for_text(text)?;
        check_batch(x_t, text)?;
        let detach = |t: Tensor| if keep_graph { t } else { t.detach() };
        let mut x = detach(x_t.clone());
        let steps = self.steps();
        for (k, (&t, &abar)) in self.timesteps.iter().zip(&self.alphas_cumprod).enumerate().rev() {
            let abar_prev = k.checked_sub(1).and_then(|j| self.alphas_cumprod.get(j)).copied().unwrap_or(1.0);
            let step = DdimMove::new(t, abar, abar_prev);
            x = detach(match on_step.as_mut() {
                None => denoiser.ddim_move(&x, text, guidance, step)?,
                Some(on_step) => {
                    let x0_hat =
                        detach(guidance.predict_x0(denoiser, &x, &timestep_tensor(t, x.dim(0)?, x.device())?, text)?);
                    on_step(&DdimProgress { step: steps - k, steps, timestep: t, x0_hat: &x0_hat });
                    step.apply(&x, &x0_hat)?
                }
            });
        }
        Ok(x)
    }
}

/// Errors unless `text` has one row per sample of `x`.
fn check_batch(x: &Tensor, text: &Tensor) -> Result<()> {
    let (batch, rows) = (x.dim(0)?, text.dim(0)?);
    if batch != rows {
        candle_core::bail!("text has {rows} rows for a batch of {batch} motions");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use candle_core::Var;

    use super::*;
    use crate::diffusion::test_denoiser::{start_noise, text, GaussianDenoiser, TEXT_DIM};
    use crate::testing::finite_difference_check;
    use crate::testing::max_abs_diff;

    #[test]
    fn respacing_matches_mdm() -> std::result::Result<(), DiffusionError> {
        let every = |s: usize, n: usize| (0..n).map(|i| i * s).collect::<Vec<_>>();
        assert_eq!(respaced_timesteps(1000, 10)?, every(100, 10));
        assert_eq!(respaced_timesteps(1000, 50)?, every(20, 50));
        assert_eq!(respaced_timesteps(1000, 100)?, every(10, 100));
        assert_eq!(respaced_timesteps(1000, 1000)?, every(1, 1000));
        assert_eq!(respaced_timesteps(1000, 30)?, every(34, 30));
        for bad in [0, 1, 400, 1001] {
            assert_eq!(respaced_timesteps(1000, bad), Err(DiffusionError::NoStride { timesteps: 1000, steps: bad }));
        }
        let s = NoiseSchedule::mdm();
        let ddim10 = DdimSampler::new(&s, 10)?;
        assert_eq!(ddim10.steps(), 10);
        assert_eq!(ddim10.alphas_cumprod()[9], s.alphas_cumprod()[900]);
        let late = ddim10.starting_at(550);
        assert_eq!(late.timesteps(), &[0, 100, 200, 300, 400, 500]);
        assert_eq!(late.alphas_cumprod(), &ddim10.alphas_cumprod()[..6]);
        assert_eq!(ddim10.starting_at(999), ddim10);
        assert_eq!(DdimSampler::new(&s, 2)?.starting_at(300).timesteps(), &[0]);
        assert_eq!(ddim10.every(2).timesteps(), &[100, 300, 500, 700, 900]);
        assert_eq!(ddim10.every(3).timesteps(), &[0, 300, 600, 900]);
        assert_eq!(ddim10.every(1), ddim10);
        assert_eq!(ddim10.every(20).timesteps(), &[900]);
        assert_eq!(ddim10.every(2).alphas_cumprod()[4], ddim10.alphas_cumprod()[9]);
        Ok(())
    }

    #[test]
    fn two_steps_match_a_hand_computation() -> Result<()> {
        let s = NoiseSchedule::mdm();
        let sampler = DdimSampler::new(&s, 2).map_err(candle_core::Error::wrap)?;
        assert_eq!(sampler.timesteps(), &[0, 500]);
        let d = GaussianDenoiser::new(0.4, 0.7, 0.0);
        let x_t = start_noise(1, 5)?;
        let out = sampler.sample(&d, &x_t, &text(&[[0.0; TEXT_DIM]])?, Guidance::default())?;
        let a = s.alphas_cumprod();
        let (a500, a0) = (a[500], a[0]);
        let hand = |x: f64| {
            let x0 = d.x0_hat(x, 500);
            let eps = (x / a500.sqrt() - x0) / (1.0 / a500 - 1.0).sqrt();
            let x_prev = a0.sqrt() * x0 + (1.0 - a0).sqrt() * eps;
            d.x0_hat(x_prev, 0)
        };
        let expected: Vec<f64> = x_t.flatten_all()?.to_vec1::<f64>()?.into_iter().map(hand).collect();
        let got = out.flatten_all()?.to_vec1::<f64>()?;
        for (g, e) in got.iter().zip(&expected) {
            assert!((g - e).abs() < 1e-12, "{g} vs {e}");
        }
        Ok(())
    }

    /// DDIM is the Euler method of the probability-flow ODE in (σ, x̄), so its error against
    /// the exact flow falls as 1/K: about 2% of the data std at ddim100, 0.2% at ddim1000.
    #[test]
    fn sampling_follows_the_exact_probability_flow_of_gaussian_data() -> Result<()> {
        let d = GaussianDenoiser::new(0.4, 0.7, 0.0);
        let no_text = text(&[[0.0; TEXT_DIM]; 2])?;
        let x_t = start_noise(2, 9)?;
        for (steps, tol) in [(100, 3e-2), (1000, 3e-3)] {
            let sampler = DdimSampler::new(&NoiseSchedule::mdm(), steps).map_err(candle_core::Error::wrap)?;
            let start = sampler.timesteps()[steps - 1];
            let out = sampler.sample(&d, &x_t, &no_text, Guidance::none())?;
            let exact = x_t.flatten_all()?.to_vec1::<f64>()?;
            let exact = exact.iter().map(|&x| d.x0_hat(d.exact_flow(x, start, 0), 0));
            let got = out.flatten_all()?.to_vec1::<f64>()?;
            let err = got.iter().zip(exact).map(|(g, e)| (g - e).abs()).fold(0.0, f64::max);
            assert!(err < tol, "ddim{steps}: max deviation from the exact flow {err}");
        }
        Ok(())
    }

    #[test]
    fn unrolled_and_detached_sampling_agree() -> Result<()> {
        let sampler = DdimSampler::new(&NoiseSchedule::mdm(), 10).map_err(candle_core::Error::wrap)?;
        let d = GaussianDenoiser::new(0.2, 0.5, 0.3);
        let cond = text(&[[0.5, -0.2, 1.0], [0.1, 0.0, 0.4]])?;
        let z = Var::from_tensor(&start_noise(2, 1)?)?;
        let detached = sampler.sample(&d, z.as_tensor(), &cond, Guidance::default())?;
        let unrolled = sampler.sample_unrolled(&d, z.as_tensor(), &cond, Guidance::default())?;
        assert_eq!(max_abs_diff(&detached, &unrolled)?, 0.0);
        // Only the unrolled result reaches back to the start noise.
        assert!(detached.sum_all()?.backward()?.get(z.as_tensor()).is_none());
        assert!(unrolled.sum_all()?.backward()?.get(z.as_tensor()).is_some());
        Ok(())
    }

    #[test]
    fn unrolled_gradient_matches_finite_differences() -> Result<()> {
        let sampler = DdimSampler::new(&NoiseSchedule::mdm(), 10).map_err(candle_core::Error::wrap)?;
        let d = GaussianDenoiser::new(0.2, 0.5, 0.3);
        let cond = text(&[[0.5, -0.2, 1.0], [0.1, 0.0, 0.4]])?;
        let target = start_noise(2, 2)?;
        let loss = |z: &Tensor| -> Result<Tensor> {
            let x = sampler.sample_unrolled(&d, z, &cond, Guidance::default())?;
            (x - &target)?.sqr()?.sum_all()
        };
        let z0 = start_noise(2, 1)?;
        finite_difference_check(&z0, loss, 1e-5, 1e-6)?;

        let z = Var::from_tensor(&z0)?;
        let grads = loss(z.as_tensor())?.backward()?;
        let g = grads
            .get(z.as_tensor())
            .ok_or_else(|| candle_core::Error::Msg("no gradient for x_T".into()))?
            .flatten_all()?
            .to_vec1::<f64>()?;
        assert!(g.iter().all(|v| v.is_finite()));
        assert!(g.iter().any(|&v| v.abs() > 1e-6));
        Ok(())
    }

    /// Round trip x0 → invert → sample; the Euler error of both directions falls as 1/K
    /// (DNO's README: ddim100 inversion "works in most cases", chained edits want 1000 steps).
    #[test]
    fn inversion_then_sampling_reproduces_the_motion() -> Result<()> {
        let d = GaussianDenoiser::new(0.4, 0.7, 0.0);
        let no_text = text(&[[0.0; TEXT_DIM]; 2])?;
        // Clean data drawn from the Gaussian the denoiser is exact for.
        let x0 = ((start_noise(2, 4)? * 0.7)? + 0.4)?;
        let mut previous = f64::INFINITY;
        for (steps, tol) in [(10, 0.7), (100, 8e-2), (1000, 8e-3)] {
            let sampler = DdimSampler::new(&NoiseSchedule::mdm(), steps).map_err(candle_core::Error::wrap)?;
            d.calls.borrow_mut().clear();
            let z = sampler.invert(&d, &x0, &no_text, Guidance::default(), 0)?;
            assert_eq!(d.calls.borrow().len(), steps - 1);
            let back = sampler.sample(&d, &z, &no_text, Guidance::default())?;
            let err = max_abs_diff(&back, &x0)?;
            assert!(err < tol, "ddim{steps}: round-trip error {err}");
            assert!(err < previous / 5.0, "ddim{steps}: error {err} did not fall with more steps");
            previous = err;
        }
        Ok(())
    }

    /// Fixed-point inversion inverts the discrete sampler, not the ODE: even ddim10 comes back
    /// to x0 almost exactly, and every iteration shrinks the error.
    #[test]
    fn fixed_point_inversion_reproduces_the_motion_with_few_steps() -> Result<()> {
        let d = GaussianDenoiser::new(0.4, 0.7, 0.0);
        let no_text = text(&[[0.0; TEXT_DIM]; 2])?;
        let x0 = ((start_noise(2, 4)? * 0.7)? + 0.4)?;
        let sampler = DdimSampler::new(&NoiseSchedule::mdm(), 10).map_err(candle_core::Error::wrap)?;
        let mut previous = f64::INFINITY;
        for n in [0, 1, 3, 8] {
            d.calls.borrow_mut().clear();
            let z = sampler.invert(&d, &x0, &no_text, Guidance::none(), n)?;
            assert_eq!(d.calls.borrow().len(), 9 * (n + 1) + n);
            let err = max_abs_diff(&sampler.sample(&d, &z, &no_text, Guidance::none())?, &x0)?;
            println!("{n} iterations: round-trip error {err}");
            assert!(err < previous / 5.0, "{n} iterations: round-trip error {err} after {previous}");
            previous = err;
        }
        assert!(previous < 1e-3, "8 iterations: round-trip error {previous}");
        Ok(())
    }

    #[test]
    fn inversion_follows_the_exact_probability_flow() -> Result<()> {
        let d = GaussianDenoiser::new(0.4, 0.7, 0.0);
        let x0 = ((start_noise(1, 6)? * 0.7)? + 0.4)?;
        for (steps, tol) in [(100, 4e-2), (1000, 4e-3)] {
            let sampler = DdimSampler::new(&NoiseSchedule::mdm(), steps).map_err(candle_core::Error::wrap)?;
            let end = sampler.timesteps()[steps - 1];
            let z = sampler.invert(&d, &x0, &text(&[[0.0; TEXT_DIM]])?, Guidance::none(), 0)?;
            let exact = x0.flatten_all()?.to_vec1::<f64>()?;
            let exact = exact.iter().map(|&x| d.exact_flow(x, 0, end));
            let got = z.flatten_all()?.to_vec1::<f64>()?;
            let err = got.iter().zip(exact).map(|(g, e)| (g - e).abs()).fold(0.0, f64::max);
            assert!(err < tol, "ddim{steps}: max deviation from the exact flow {err}");
        }
        Ok(())
    }

    #[test]
    fn sampling_skips_the_unconditional_half_when_it_cannot_matter() -> Result<()> {
        let sampler = DdimSampler::new(&NoiseSchedule::mdm(), 10).map_err(candle_core::Error::wrap)?;
        let d = GaussianDenoiser::new(0.2, 0.5, 0.3);
        let x = start_noise(2, 3)?;
        let cond = text(&[[0.5, -0.2, 1.0], [0.1, 0.0, 0.4]])?;
        let cases = [
            (cond.clone(), Guidance::default(), 4),
            (cond.clone(), Guidance::none(), 2),
            (cond.zeros_like()?, Guidance::default(), 2),
        ];
        for (txt, guidance, rows) in cases {
            d.calls.borrow_mut().clear();
            sampler.sample(&d, &x, &txt, guidance)?;
            let calls = d.calls.borrow();
            assert_eq!(calls.len(), 10, "one denoiser call per step");
            assert!(calls.iter().all(|c| c.rows == rows), "{guidance:?}: {calls:?}");
        }
        Ok(())
    }

    #[test]
    fn same_seed_same_sample_and_progress_reports_every_step() -> Result<()> {
        let sampler = DdimSampler::new(&NoiseSchedule::mdm(), 10).map_err(candle_core::Error::wrap)?;
        let d = GaussianDenoiser::new(0.2, 0.5, 0.3);
        let cond = text(&[[0.5, -0.2, 1.0]])?;
        let run = |seed| sampler.sample(&d, &start_noise(1, seed)?, &cond, Guidance::default());
        assert_eq!(max_abs_diff(&run(21)?, &run(21)?)?, 0.0);
        assert!(max_abs_diff(&run(21)?, &run(22)?)? > 1e-3);

        let mut seen = Vec::new();
        let last = sampler.sample_with_progress(&d, &start_noise(1, 21)?, &cond, Guidance::default(), |p| {
            seen.push((p.step, p.steps, p.timestep, p.x0_hat.clone()));
        })?;
        let timesteps: Vec<usize> = seen.iter().map(|s| s.2).collect();
        assert_eq!(timesteps, (0..10).rev().map(|i| i * 100).collect::<Vec<_>>());
        assert!(seen.iter().enumerate().all(|(i, s)| s.0 == i + 1 && s.1 == 10));
        // The final step returns exactly the x̂0 predicted at t = 0.
        let (_, _, _, final_x0) = seen.last().ok_or_else(|| candle_core::Error::Msg("no steps".into()))?;
        assert_eq!(max_abs_diff(final_x0, &last)?, 0.0);
        Ok(())
    }

    #[test]
    fn mismatched_text_rows_are_rejected() -> Result<()> {
        let sampler = DdimSampler::new(&NoiseSchedule::mdm(), 10).map_err(candle_core::Error::wrap)?;
        let d = GaussianDenoiser::new(0.0, 1.0, 0.0);
        let x = start_noise(2, 1)?;
        assert!(sampler.sample(&d, &x, &text(&[[1.0; TEXT_DIM]])?, Guidance::default()).is_err());
        assert!(sampler.invert(&d, &x, &text(&[[1.0; TEXT_DIM]])?, Guidance::default(), 0).is_err());
        Ok(())
    }
}
