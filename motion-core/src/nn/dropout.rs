//! Inverted dropout with masks drawn from a caller-supplied, seedable RNG (candle's own CPU
//! RNG cannot be seeded).

use candle_core::{bail, DType, Result, Tensor};
use rand::{Rng, RngCore};

/// Zeroes each element of `x` with probability `p` and scales the survivors by `1/(1 − p)`,
/// as PyTorch's `nn.Dropout` in training mode. Any shape; `p = 0` returns `x` unchanged.
///
/// The mask is a constant, so gradients flow to `x` through the multiplication.
pub fn dropout(x: &Tensor, p: f64, rng: &mut dyn RngCore) -> Result<Tensor> {
    if !(0.0..1.0).contains(&p) {
        bail!("dropout probability must be in [0, 1), got {p}");
    }
    if p == 0.0 {
        return Ok(x.clone());
    }
    let keep = 1.0 / (1.0 - p);
    let n = x.elem_count();
    let mask = match x.dtype() {
        DType::F64 => {
            let m: Vec<f64> = (0..n).map(|_| if rng.random::<f64>() < p { 0.0 } else { keep }).collect();
            Tensor::from_vec(m, x.shape(), x.device())?
        }
        dtype => {
            let keep = keep as f32;
            let m: Vec<f32> = (0..n).map(|_| if rng.random::<f64>() < p { 0.0 } else { keep }).collect();
            Tensor::from_vec(m, x.shape(), x.device())?.to_dtype(dtype)?
        }
    };
    x.mul(&mask)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};
    use rand::{rngs::StdRng, SeedableRng};

    fn masks_are_seeded_and_scaled(dev: &Device) -> Result<()> {
        let x = Tensor::ones((50, 40), DType::F32, dev)?;
        let a = dropout(&x, 0.25, &mut StdRng::seed_from_u64(3))?;
        let b = dropout(&x, 0.25, &mut StdRng::seed_from_u64(3))?;
        assert_eq!(a.flatten_all()?.to_vec1::<f32>()?, b.flatten_all()?.to_vec1::<f32>()?);
        let v = a.flatten_all()?.to_vec1::<f32>()?;
        let zeros = v.iter().filter(|&&e| e == 0.0).count() as f64 / v.len() as f64;
        assert!((zeros - 0.25).abs() < 0.05, "dropped fraction {zeros}");
        assert!(v.iter().all(|&e| e == 0.0 || (e - 1.0 / 0.75).abs() < 1e-6));
        let same = dropout(&x, 0.0, &mut StdRng::seed_from_u64(3))?;
        assert_eq!(same.sum_all()?.to_scalar::<f32>()?, 2000.0);
        assert!(dropout(&x, 1.0, &mut StdRng::seed_from_u64(3)).is_err());
        Ok(())
    }

    fn gradient_is_the_mask(dev: &Device) -> Result<()> {
        let x = Var::from_tensor(&Tensor::ones((4, 5), DType::F64, dev)?)?;
        let y = dropout(x.as_tensor(), 0.5, &mut StdRng::seed_from_u64(4))?;
        let grads = y.sum_all()?.backward()?;
        let g = grads.get(x.as_tensor()).expect("no grad for x");
        assert_eq!(g.flatten_all()?.to_vec1::<f64>()?, y.flatten_all()?.to_vec1::<f64>()?);
        Ok(())
    }

    mod cpu {
        crate::nn::testing::cpu_tests!(masks_are_seeded_and_scaled, gradient_is_the_mask);
    }
}
