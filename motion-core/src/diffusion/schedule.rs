//! MDM's cosine noise schedule and the forward noising process q(x_t | x_0).
//!
//! Cosine schedule of Nichol & Dhariwal, "Improved Denoising Diffusion Probabilistic Models"
//! (2021), eq. 17, as built by MDM's `get_named_beta_schedule("cosine", 1000)` →
//! `betas_for_alpha_bar`: the betas are derived from ᾱ(s) = cos²(((s + 0.008)/1.008)·π/2),
//! clipped at 0.999, and ᾱ_t = Π_{i≤t}(1 − β_i) is recomputed from them, all in f64.

use candle_core::{DType, Device, Result, Tensor};
use rand::Rng;

use super::error::DiffusionError;

/// Number of diffusion timesteps MDM is trained with.
pub const MDM_TIMESTEPS: usize = 1000;

/// Offset `s` of the cosine schedule (Nichol & Dhariwal 2021, eq. 17).
const COSINE_OFFSET: f64 = 0.008;

/// Upper clip on β that keeps the last step from being singular.
const MAX_BETA: f64 = 0.999;

/// A discrete Gaussian diffusion schedule over timesteps `0..num_timesteps`.
#[derive(Debug, Clone, PartialEq)]
pub struct NoiseSchedule {
    betas: Vec<f64>,
    alphas_cumprod: Vec<f64>,
}

impl NoiseSchedule {
    /// The cosine schedule with `num_timesteps` steps.
    pub fn cosine(num_timesteps: usize) -> std::result::Result<Self, DiffusionError> {
        if num_timesteps == 0 {
            return Err(DiffusionError::EmptySchedule);
        }
        Ok(Self::cosine_unchecked(num_timesteps))
    }

    /// MDM's schedule: cosine over [`MDM_TIMESTEPS`] = 1000 steps.
    pub fn mdm() -> Self {
        Self::cosine_unchecked(MDM_TIMESTEPS)
    }

    fn cosine_unchecked(num_timesteps: usize) -> Self {
        let alpha_bar =
            |s: f64| ((s + COSINE_OFFSET) / (1.0 + COSINE_OFFSET) * std::f64::consts::FRAC_PI_2).cos().powi(2);
        let n = num_timesteps as f64;
        let betas: Vec<f64> = (0..num_timesteps)
            .map(|i| {
                let (t1, t2) = (i as f64 / n, (i + 1) as f64 / n);
                (1.0 - alpha_bar(t2) / alpha_bar(t1)).min(MAX_BETA)
            })
            .collect();
        let alphas_cumprod = betas
            .iter()
            .scan(1.0, |acc, beta| {
                *acc *= 1.0 - beta;
                Some(*acc)
            })
            .collect();
        Self { betas, alphas_cumprod }
    }

    /// Number of timesteps T; valid timesteps are `0..T`.
    pub fn num_timesteps(&self) -> usize {
        self.betas.len()
    }

    /// β_t for t in `0..T`.
    pub fn betas(&self) -> &[f64] {
        &self.betas
    }

    /// ᾱ_t = Π_{i≤t}(1 − β_i) for t in `0..T` (decreasing from ≈1 to ≈0).
    pub fn alphas_cumprod(&self) -> &[f64] {
        &self.alphas_cumprod
    }

    /// Forward noising (Ho et al. 2020, eq. 4): x_t = √ᾱ_t·x0 + √(1 − ᾱ_t)·ε.
    ///
    /// - `x0`: `[batch, ...]` (normally `[batch, frames, 263]`), any float dtype;
    /// - `timesteps`: `[batch]` integer timesteps in `0..T`, one per sample;
    /// - `noise`: ε, same shape as `x0`.
    ///
    /// Returns x_t with the shape and dtype of `x0`; differentiable in `x0` and `noise`.
    pub fn q_sample(&self, x0: &Tensor, timesteps: &Tensor, noise: &Tensor) -> Result<Tensor> {
        if noise.shape() != x0.shape() {
            candle_core::bail!("q_sample: noise shape {:?} differs from x0 shape {:?}", noise.shape(), x0.shape());
        }
        let signal = self.per_sample(timesteps, x0, f64::sqrt)?;
        let sigma = self.per_sample(timesteps, x0, |abar| (1.0 - abar).sqrt())?;
        x0.broadcast_mul(&signal)? + noise.broadcast_mul(&sigma)?
    }

    /// `batch` training timesteps as a `[batch]` u32 tensor: uniform over `0..T` (MDM's
    /// `UniformSampler`), except that each is drawn from the noisiest 30 % of the schedule
    /// (t ≥ 0.7 T) with probability `high_noise_fraction` (0 = uniform, draws no extra numbers).
    pub fn sample_timesteps<R: Rng + ?Sized>(
        &self,
        batch: usize,
        high_noise_fraction: f64,
        rng: &mut R,
        device: &Device,
    ) -> Result<Tensor> {
        let max = u32::try_from(self.num_timesteps())
            .map_err(|_| candle_core::Error::Msg("schedule too long for u32 timesteps".into()))?;
        let high = max - max * 3 / 10;
        let values: Vec<u32> = (0..batch)
            .map(|_| {
                let noisy = high_noise_fraction > 0.0 && rng.random::<f64>() < high_noise_fraction;
                rng.random_range(if noisy { high } else { 0 }..max)
            })
            .collect();
        Tensor::from_vec(values, batch, device)
    }

    /// `f(ᾱ_t)` per sample as a `[batch, 1, …, 1]` tensor that broadcasts against `like`.
    pub(crate) fn per_sample(&self, timesteps: &Tensor, like: &Tensor, f: impl Fn(f64) -> f64) -> Result<Tensor> {
        let ts = timesteps.to_dtype(DType::U32)?.to_vec1::<u32>()?;
        let batch = like.dim(0)?;
        if ts.len() != batch {
            candle_core::bail!("{} timesteps for a batch of {batch}", ts.len());
        }
        let values = ts
            .iter()
            .map(|&t| match self.alphas_cumprod.get(t as usize) {
                Some(&abar) => Ok(f(abar)),
                None => candle_core::bail!("timestep {t} outside the schedule's 0..{}", self.num_timesteps()),
            })
            .collect::<Result<Vec<f64>>>()?;
        let mut shape = vec![1; like.rank()];
        shape[0] = batch;
        Tensor::from_vec(values, shape, like.device())?.to_dtype(like.dtype())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    /// Asserts `|actual − expected| ≤ tol`.
    fn assert_near(what: &str, actual: f64, expected: f64, tol: f64) {
        assert!((actual - expected).abs() <= tol, "{what}: {actual} is not within {tol} of {expected}");
    }

    #[test]
    fn cosine_schedule_matches_the_reference_numbers() {
        let s = NoiseSchedule::mdm();
        let (b, a) = (s.betas(), s.alphas_cumprod());
        assert_eq!(s.num_timesteps(), 1000);
        // anchors.md §1.5, each to half a unit of its last printed digit.
        assert_near("beta_0", b[0], 4.13e-5, 0.005e-5);
        assert_near("abar_0", a[0], 0.999959, 0.5e-6);
        assert_near("abar_99", a[99], 0.9721, 0.5e-4);
        assert_near("abar_500", a[500], 0.4923, 0.5e-4);
        assert_near("abar_900", a[900], 0.02362, 0.5e-5);
        assert_near("abar_980", a[980], 8.77e-4, 0.005e-4);
        assert_near("abar_990", a[990], 1.967e-4, 0.0005e-4);
        assert_near("abar_999", a[999], 2.43e-9, 0.005e-9);
    }

    #[test]
    fn only_the_last_beta_is_clipped() {
        let s = NoiseSchedule::mdm();
        let clipped: Vec<usize> = (0..1000).filter(|&i| s.betas()[i] >= MAX_BETA).collect();
        assert_eq!(clipped, vec![999]);
        assert!(s.alphas_cumprod().windows(2).all(|w| w[1] < w[0]));
    }

    #[test]
    fn an_empty_schedule_is_rejected() {
        assert_eq!(NoiseSchedule::cosine(0), Err(DiffusionError::EmptySchedule));
    }

    #[test]
    fn q_sample_mixes_signal_and_noise_per_sample() -> Result<()> {
        let dev = Device::Cpu;
        let s = NoiseSchedule::mdm();
        let x0 = Tensor::new(&[[[1.0f64, -2.0]], [[0.5, 3.0]]], &dev)?;
        let eps = Tensor::new(&[[[0.3f64, 0.7]], [[-1.0, 2.0]]], &dev)?;
        let t = Tensor::new(&[0u32, 500], &dev)?;
        let xt = s.q_sample(&x0, &t, &eps)?.to_vec3::<f64>()?;
        let a = s.alphas_cumprod();
        let expect = |abar: f64, x: f64, e: f64| abar.sqrt() * x + (1.0 - abar).sqrt() * e;
        assert_near("b0", xt[0][0][0], expect(a[0], 1.0, 0.3), 1e-12);
        assert_near("b0", xt[0][0][1], expect(a[0], -2.0, 0.7), 1e-12);
        assert_near("b1", xt[1][0][0], expect(a[500], 0.5, -1.0), 1e-12);
        assert_near("b1", xt[1][0][1], expect(a[500], 3.0, 2.0), 1e-12);
        Ok(())
    }

    #[test]
    fn q_sample_rejects_bad_timesteps_and_shapes() -> Result<()> {
        let dev = Device::Cpu;
        let s = NoiseSchedule::mdm();
        let x0 = Tensor::zeros((2, 3, 4), DType::F32, &dev)?;
        assert!(s.q_sample(&x0, &Tensor::new(&[0u32, 1000], &dev)?, &x0).is_err());
        assert!(s.q_sample(&x0, &Tensor::new(&[0u32], &dev)?, &x0).is_err());
        let other = Tensor::zeros((2, 3, 5), DType::F32, &dev)?;
        assert!(s.q_sample(&x0, &Tensor::new(&[0u32, 1], &dev)?, &other).is_err());
        Ok(())
    }

    #[test]
    fn training_timesteps_are_seeded_and_in_range() -> Result<()> {
        let dev = Device::Cpu;
        let s = NoiseSchedule::mdm();
        let draw = |seed, high| s.sample_timesteps(400, high, &mut StdRng::seed_from_u64(seed), &dev)?.to_vec1::<u32>();
        let (a, b, c) = (draw(1, 0.0)?, draw(1, 0.0)?, draw(2, 0.0)?);
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert!(a.iter().all(|&t| t < 1000));
        let noisy = |ts: &[u32]| ts.iter().filter(|&&t| t >= 700).count() as f64 / ts.len() as f64;
        // Uniform: 30 % land in the noisiest 30 %; with half the draws forced there, 65 %.
        assert!((noisy(&a) - 0.3).abs() < 0.08, "{}", noisy(&a));
        let h = draw(1, 0.5)?;
        assert!((noisy(&h) - 0.65).abs() < 0.08, "{}", noisy(&h));
        assert!(h.iter().all(|&t| t < 1000));
        assert_eq!(noisy(&draw(1, 1.0)?), 1.0);
        Ok(())
    }
}
