//! DNO's noise decorrelation regulariser (`dno.py` `noise_regularize_1d`, anchors §2.1): a 1-D
//! version of the StyleGAN2 projector's noise regulariser (Karras et al., "Analyzing and
//! Improving the Image Quality of StyleGAN", CVPR 2020, §C.1), which keeps the optimised noise
//! looking like white noise along time at every scale.

use candle_core::{Result, Tensor, D};
use rand::Rng;

use crate::diffusion::noise::gaussian_from_rng;

/// Pooling stops once the time axis has at most this many frames (DNO's `stop_at`).
const STOP_AT: usize = 2;

/// The regulariser R(z) per sample, `[batch]`: the sum of [`decorrelation_terms`].
///
/// `z`: `[batch, frames, channels]` (time is axis 1). Differentiable in `z`; the padding noise
/// is drawn from `rng`, fresh on every call as in DNO, so the value is stochastic unless
/// `frames` is a power of two.
pub fn noise_regularize_1d<R: Rng + ?Sized>(z: &Tensor, rng: &mut R) -> Result<Tensor> {
    let terms = decorrelation_terms(z, rng)?;
    let mut total = terms[0].clone();
    for term in &terms[1..] {
        total = (total + term)?;
    }
    Ok(total)
}

/// The scale-by-scale terms of R(z), each `[batch]`, finest first.
///
/// 1. If `frames` is not a power of two, append fresh N(0, 1) frames (from `rng`) up to the
///    next power of two: 120 → 128, 196 → 256.
/// 2. Repeat: add (mean over non-batch elements of z ⊙ roll(z, 1, time))², the squared
///    circular lag-1 autocorrelation; stop when the time axis has ≤ 2 frames, otherwise
///    average-pool time by 2 (no renormalisation).
///
/// That gives log2(padded frames) terms (7 for 128, 8 for 256); at least one.
pub fn decorrelation_terms<R: Rng + ?Sized>(z: &Tensor, rng: &mut R) -> Result<Vec<Tensor>> {
    let (batch, frames, channels) = z.dims3()?;
    if frames == 0 {
        candle_core::bail!("noise_regularize_1d: z has no frames");
    }
    let padded = frames.next_power_of_two();
    let mut noise = if padded == frames {
        z.clone()
    } else {
        let pad = gaussian_from_rng((batch, padded - frames, channels), rng, z.device())?.to_dtype(z.dtype())?;
        Tensor::cat(&[z, &pad], 1)?
    };
    let mut size = padded;
    let mut terms = Vec::new();
    loop {
        let lagged = (&noise * noise.roll(1, 1)?)?;
        terms.push(lagged.flatten_from(1)?.mean(D::Minus1)?.sqr()?);
        if size <= STOP_AT {
            return Ok(terms);
        }
        size /= 2;
        noise = noise.reshape((batch, size, 2, channels))?.mean(2)?;
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, Var};
    use rand::rngs::StdRng;
    use rand::SeedableRng;

    use super::*;
    use crate::diffusion::noise::gaussian;
    use crate::testing::finite_difference_check;

    fn values(t: &Tensor) -> Vec<f64> {
        t.to_dtype(DType::F64).unwrap().to_vec1::<f64>().unwrap()
    }

    #[test]
    fn white_noise_scores_near_zero_and_smooth_signals_high() {
        let dev = Device::Cpu;
        let mut rng = StdRng::seed_from_u64(1);
        let white = gaussian((4, 128, 263), 3, &dev).unwrap();
        let r_white = values(&noise_regularize_1d(&white, &mut rng).unwrap());
        // Each term is the square of a mean of ~N products: about 1/N ≈ 3e-5 at full size.
        assert!(r_white.iter().all(|&r| r < 2e-3), "{r_white:?}");

        let constant = Tensor::ones((1, 128, 263), DType::F32, &dev).unwrap();
        let r_const = values(&noise_regularize_1d(&constant, &mut rng).unwrap());
        assert!((r_const[0] - 7.0).abs() < 1e-5, "one per scale: {r_const:?}");

        let t = Tensor::arange(0f32, 128.0, &dev).unwrap();
        let smooth = (t * (2.0 * std::f64::consts::PI / 128.0)).unwrap().sin().unwrap();
        let smooth = smooth.reshape((1, 128, 1)).unwrap().broadcast_as((1, 128, 263)).unwrap().contiguous().unwrap();
        let r_smooth = values(&noise_regularize_1d(&smooth, &mut rng).unwrap());
        assert!(r_smooth[0] > 0.1, "{r_smooth:?}");
    }

    #[test]
    fn pads_to_the_next_power_of_two_with_fresh_noise() {
        let dev = Device::Cpu;
        for (frames, padded, count) in [(120, 128, 7), (196, 256, 8), (128, 128, 7), (3, 4, 2), (2, 2, 1), (1, 1, 1)] {
            let z = gaussian((2, frames, 5), 9, &dev).unwrap();
            let mut rng = StdRng::seed_from_u64(4);
            let terms = decorrelation_terms(&z, &mut rng).unwrap();
            assert_eq!(terms.len(), count, "T = {frames}");
            assert!(terms.iter().all(|t| t.dims() == [2]));
            // The padding consumed exactly 2·(padded − frames)·5 normal draws.
            let mut reference = StdRng::seed_from_u64(4);
            gaussian_from_rng(2 * (padded - frames) * 5, &mut reference, &dev).unwrap();
            assert_eq!(rng.random::<u64>(), reference.random::<u64>(), "T = {frames}");
        }
        // Fresh padding on every call: the same z scores differently when padded.
        let z = gaussian((1, 120, 5), 9, &dev).unwrap();
        let mut rng = StdRng::seed_from_u64(4);
        let a = values(&noise_regularize_1d(&z, &mut rng).unwrap());
        let b = values(&noise_regularize_1d(&z, &mut rng).unwrap());
        assert_ne!(a, b);
    }

    #[test]
    fn terms_are_per_sample_and_match_a_hand_computation() {
        let dev = Device::Cpu;
        // One channel, 4 frames: terms at size 4 and 2.
        let z = Tensor::new(&[[[1f64], [2.], [3.], [4.]], [[1.], [-1.], [1.], [-1.]]], &dev).unwrap();
        let terms = decorrelation_terms(&z, &mut StdRng::seed_from_u64(0)).unwrap();
        let (t0, t1) = (values(&terms[0]), values(&terms[1]));
        // (1·4 + 2·1 + 3·2 + 4·3)/4 = 6 → 36; pooled (1.5, 3.5): (1.5·3.5·2)/2 = 5.25 → 27.5625.
        assert_eq!(t0, [36.0, 1.0]);
        assert_eq!(t1, [27.5625, 0.0]);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let z = gaussian((2, 16, 3), 5, &Device::Cpu).unwrap().to_dtype(DType::F64).unwrap();
        let f = |z: &Tensor| noise_regularize_1d(z, &mut StdRng::seed_from_u64(0))?.sum_all();
        finite_difference_check(&z, f, 1e-5, 1e-6).unwrap();
        let var = Var::from_tensor(&z).unwrap();
        assert!(f(var.as_tensor()).unwrap().backward().unwrap().get(var.as_tensor()).is_some());
    }
}
