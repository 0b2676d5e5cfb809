//! Differentiable neural-network building blocks.
//!
//! Every layer has two paths:
//! - `forward`: primitive candle ops, so weights held as `Var`s get gradients (training);
//! - `forward_frozen` (and [`ops::softmax`], [`ops::gelu_erf`]): custom ops with hand-written
//!   backward passes that return only the input gradient. This is the path of the frozen
//!   prior inside diffusion-noise optimisation, where the only variable is the noise.
//!
//! The custom ops have CPU kernels (f32, f64); on other devices they fall back to the
//! primitive path, so a CUDA build works unchanged and can gain kernels later. Never use
//! candle's fused `LayerNorm`, `ops::layer_norm` or `softmax_last_dim` in a differentiable
//! path: they have no backward and drop gradients silently.

mod dropout;
pub mod isa;
pub(crate) mod kernels;
mod layer_norm;
mod linear;
mod matmul;
pub mod ops;

pub use dropout::dropout;
pub use isa::{Isa, IsaRequest, UnknownIsa};
pub use layer_norm::{LayerNorm, LAYER_NORM_EPS};
pub use linear::Linear;

/// `torch.nn.functional.normalize(x, p=2, dim=1)`: each row of `[n, k]` over
/// `max(‖row‖, 1e-12)`, so a zero row stays zero; differentiable.
pub fn unit_rows(x: &candle_core::Tensor) -> candle_core::Result<candle_core::Tensor> {
    let norms = x.sqr()?.sum_keepdim(1)?.sqrt()?.clamp(1e-12, f64::MAX)?;
    x.broadcast_div(&norms)
}

#[cfg(test)]
pub(crate) mod testing {
    use candle_core::{Device, Result, Tensor};
    use rand::{rngs::StdRng, SeedableRng};
    use rand_distr::{Distribution, StandardNormal};

    /// Seeded standard-normal f64 tensor.
    pub fn randn(shape: &[usize], seed: u64, dev: &Device) -> Result<Tensor> {
        let mut rng = StdRng::seed_from_u64(seed);
        let n = shape.iter().product();
        let v: Vec<f64> = (0..n).map(|_| StandardNormal.sample(&mut rng)).collect();
        Tensor::from_vec(v, shape, dev)
    }

    /// One `#[test]` per `case(dev: &Device) -> Result<()>` in the parent module, on the CPU.
    macro_rules! cpu_tests {
        ($($case:ident),* $(,)?) => {
            $(
                #[test]
                fn $case() -> candle_core::Result<()> {
                    super::$case(&candle_core::Device::Cpu)
                }
            )*
        };
    }
    pub(crate) use cpu_tests;
}
