//! LayerNorm over the last dimension that always propagates gradients.
//!
//! candle's `LayerNorm` and `ops::layer_norm` run a fused kernel without backward and cut the
//! graph silently (reference/candle-and-crates.md §1.3); this type is the one to use.

use candle_core::backend::BackendStorage;
use candle_core::{bail, CpuStorage, CustomOp1, Layout, Result, Shape, Tensor, WithDType, D};

use super::isa::Isa;
use super::kernels::{self, contiguous_slice, dispatch_real, with_slice};
use super::ops::has_cpu_kernel;

/// PyTorch's default LayerNorm epsilon.
pub const LAYER_NORM_EPS: f64 = 1e-5;

/// `nn.LayerNorm(d)`: `y = (x − mean)/sqrt(var + eps)·weight + bias` over the last dim
/// (biased variance), weight and bias `[d]`.
#[derive(Debug, Clone)]
pub struct LayerNorm {
    weight: Tensor,
    bias: Tensor,
    eps: f64,
}

impl LayerNorm {
    /// Wraps `weight` (γ) and `bias` (β), both `[d]`.
    pub fn new(weight: Tensor, bias: Tensor, eps: f64) -> Result<Self> {
        if weight.dims1()? != bias.dims1()? {
            bail!("layer norm weight {:?} and bias {:?} differ", weight.shape(), bias.shape());
        }
        Ok(Self { weight, bias, eps })
    }

    /// γ, `[d]`.
    pub fn weight(&self) -> &Tensor {
        &self.weight
    }

    /// β, `[d]`.
    pub fn bias(&self) -> &Tensor {
        &self.bias
    }

    /// The epsilon added to the variance.
    pub fn eps(&self) -> f64 {
        self.eps
    }

    /// Training path, written with primitive ops: gradients reach `x`, γ and β. `[.., d] → [.., d]`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mean = x.mean_keepdim(D::Minus1)?;
        let centred = x.broadcast_sub(&mean)?;
        let var = centred.sqr()?.mean_keepdim(D::Minus1)?;
        let normed = centred.broadcast_div(&(var + self.eps)?.sqrt()?)?;
        normed.broadcast_mul(&self.weight)?.broadcast_add(&self.bias)
    }

    /// Frozen-γ/β path: one custom op whose backward returns only the input gradient
    /// `dx = rstd·(g·γ − mean(g·γ) − x̂·mean(g·γ·x̂))`. `[.., d] → [.., d]`.
    pub fn forward_frozen(&self, x: &Tensor) -> Result<Tensor> {
        let op = LayerNormOp { weight: self.weight.detach(), bias: self.bias.detach(), eps: self.eps };
        if has_cpu_kernel(x) {
            x.contiguous()?.apply_op1(op)
        } else {
            LayerNorm::new(op.weight, op.bias, op.eps)?.forward(x)
        }
    }
}

struct LayerNormOp {
    weight: Tensor,
    bias: Tensor,
    eps: f64,
}

impl CustomOp1 for LayerNormOp {
    fn name(&self) -> &'static str {
        "motion-layer-norm"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        dispatch_real!(s.dtype(), T => {
            let x = contiguous_slice::<T>(s, l)?;
            let mut y = vec![T::from_f64(0.0); x.len()];
            with_slice::<T, _>(&self.weight, |gamma| {
                with_slice::<T, _>(&self.bias, |beta| {
                    kernels::layer_norm_fwd(Isa::selected(), x, gamma, beta, self.eps, &mut y, None);
                    Ok(())
                })
            })?;
            Ok((T::to_cpu_storage_owned(y), l.shape().clone()))
        })
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let grad = grad.contiguous()?;
        let d = arg.dim(D::Minus1)?;
        dispatch_real!(arg.dtype(), T => {
            let dx = with_slice::<T, _>(arg, |x| {
                with_slice::<T, _>(&self.weight, |gamma| {
                    with_slice::<T, _>(&self.bias, |beta| {
                        with_slice::<T, _>(&grad, |g| {
                            let rows = x.len() / d.max(1);
                            let (mut y, mut xhat) = (vec![T::from_f64(0.0); x.len()], vec![T::from_f64(0.0); x.len()]);
                            let mut rstd = vec![T::from_f64(0.0); rows];
                            kernels::layer_norm_fwd(Isa::selected(), x, gamma, beta, self.eps, &mut y, Some((&mut xhat, &mut rstd)));
                            y.copy_from_slice(g);
                            kernels::layer_norm_bwd(Isa::selected(), &mut y, &xhat, &rstd, gamma);
                            Ok(y)
                        })
                    })
                })
            })?;
            Ok(Some(Tensor::from_vec(dx, arg.shape(), arg.device())?))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::testing::randn;
    use crate::testing::finite_difference_check;
    use crate::testing::max_abs_diff;
    use candle_core::{DType, Device, Var};

    fn norm(dev: &Device) -> Result<LayerNorm> {
        LayerNorm::new(randn(&[6], 30, dev)?.affine(0.3, 1.0)?, randn(&[6], 31, dev)?, LAYER_NORM_EPS)
    }

    fn frozen_matches_primitive(dev: &Device) -> Result<()> {
        let ln = norm(dev)?;
        let x = randn(&[2, 3, 6], 32, dev)?.affine(2.0, 0.5)?;
        assert!(max_abs_diff(&ln.forward_frozen(&x)?, &ln.forward(&x)?)? < 1e-12);
        let ln32 = LayerNorm::new(ln.weight().to_dtype(DType::F32)?, ln.bias().to_dtype(DType::F32)?, ln.eps())?;
        let x32 = x.to_dtype(DType::F32)?;
        assert!(max_abs_diff(&ln32.forward_frozen(&x32)?, &ln32.forward(&x32)?)? < 1e-5);
        Ok(())
    }

    fn frozen_gradient(dev: &Device) -> Result<()> {
        let ln = norm(dev)?;
        let x = randn(&[4, 6], 33, dev)?;
        let w = randn(&[4, 6], 34, dev)?;
        finite_difference_check(&x, |x| ln.forward_frozen(x)?.mul(&w)?.sum_all(), 1e-6, 1e-6)
    }

    fn primitive_gradient(dev: &Device) -> Result<()> {
        let ln = norm(dev)?;
        let x = randn(&[4, 6], 35, dev)?;
        let w = randn(&[4, 6], 36, dev)?;
        finite_difference_check(&x, |x| ln.forward(x)?.mul(&w)?.sum_all(), 1e-6, 1e-6)
    }

    fn frozen_and_primitive_input_gradients_agree(dev: &Device) -> Result<()> {
        let gamma = Var::from_tensor(&(randn(&[6], 37, dev)? + 1.0)?)?;
        let ln = LayerNorm::new(gamma.as_tensor().clone(), randn(&[6], 38, dev)?, LAYER_NORM_EPS)?;
        let x = Var::from_tensor(&randn(&[3, 6], 39, dev)?)?;
        let w = randn(&[3, 6], 40, dev)?;
        let frozen = ln.forward_frozen(x.as_tensor())?.mul(&w)?.sum_all()?.backward()?;
        assert!(frozen.get(gamma.as_tensor()).is_none());
        let prim = ln.forward(x.as_tensor())?.mul(&w)?.sum_all()?.backward()?;
        assert!(prim.get(gamma.as_tensor()).is_some());
        let a = frozen.get(x.as_tensor()).expect("no grad (frozen)");
        let b = prim.get(x.as_tensor()).expect("no grad (primitive)");
        assert!(max_abs_diff(a, b)? < 1e-12);
        Ok(())
    }

    mod cpu {
        crate::nn::testing::cpu_tests!(
            frozen_matches_primitive,
            frozen_gradient,
            primitive_gradient,
            frozen_and_primitive_input_gradients_agree,
        );
    }
}
