//! Seeded standard-normal noise tensors.
//!
//! candle's CPU `randn` draws from an unseedable thread RNG (candle #2651, #3297), so every
//! random tensor of the diffusion code comes from here: a `rand::rngs::StdRng` and
//! `rand_distr::StandardNormal`, filled in row-major order and copied to the device, which
//! makes a seed reproduce the same tensor on every device.

use candle_core::{Device, Result, Shape, Tensor};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// An f32 tensor of i.i.d. N(0, 1) samples drawn from `StdRng::seed_from_u64(seed)`.
///
/// For diffusion start noise x_T the shape is `[batch, frames, 263]`.
pub fn gaussian(shape: impl Into<Shape>, seed: u64, device: &Device) -> Result<Tensor> {
    gaussian_from_rng(shape, &mut StdRng::seed_from_u64(seed), device)
}

/// An f32 tensor of i.i.d. N(0, 1) samples drawn from `rng`, in row-major order.
///
/// Use this form to draw several tensors from one seeded stream (for example the noise of
/// each training step).
pub fn gaussian_from_rng<R: Rng + ?Sized>(shape: impl Into<Shape>, rng: &mut R, device: &Device) -> Result<Tensor> {
    let shape = shape.into();
    let values: Vec<f32> = (0..shape.elem_count()).map(|_| rng.sample(StandardNormal)).collect();
    Tensor::from_vec(values, shape, device)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_gives_the_same_tensor() -> Result<()> {
        let dev = Device::Cpu;
        let a = gaussian((2, 5, 263), 7, &dev)?.flatten_all()?.to_vec1::<f32>()?;
        let b = gaussian((2, 5, 263), 7, &dev)?.flatten_all()?.to_vec1::<f32>()?;
        let c = gaussian((2, 5, 263), 8, &dev)?.flatten_all()?.to_vec1::<f32>()?;
        assert_eq!(a, b);
        assert_ne!(a, c);
        Ok(())
    }

    #[test]
    fn a_shared_stream_gives_fresh_draws_in_order() -> Result<()> {
        let dev = Device::Cpu;
        let mut rng = StdRng::seed_from_u64(3);
        let first = gaussian_from_rng(4, &mut rng, &dev)?.to_vec1::<f32>()?;
        let second = gaussian_from_rng(4, &mut rng, &dev)?.to_vec1::<f32>()?;
        let both = gaussian(8, 3, &dev)?.to_vec1::<f32>()?;
        assert_ne!(first, second);
        assert_eq!([first, second].concat(), both);
        Ok(())
    }

    #[test]
    fn samples_are_standard_normal() -> Result<()> {
        let v = gaussian(20_000, 11, &Device::Cpu)?.to_vec1::<f32>()?;
        let n = v.len() as f64;
        let mean = v.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
        let var = v.iter().map(|&x| (f64::from(x) - mean).powi(2)).sum::<f64>() / n;
        assert!(mean.abs() < 0.03, "mean {mean}");
        assert!((var - 1.0).abs() < 0.05, "variance {var}");
        Ok(())
    }
}
