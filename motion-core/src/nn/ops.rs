//! Softmax and exact GELU as custom ops with hand-written backward passes.
//!
//! Both run as one fused CPU loop each way (candle's `softmax_last_dim` has no backward and
//! its `gelu_erf` backward builds about ten temporaries). On other devices they fall back to
//! candle's primitive ops, which are differentiable everywhere.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, CustomOp1, DType, Layout, Result, Shape, Tensor, WithDType, D};

use super::isa::Isa;
use super::kernels::{self, contiguous_slice, dispatch_real, with_slice};

/// Whether the CPU custom ops can run on `x` (CPU device, f32 or f64).
pub(crate) fn has_cpu_kernel(x: &Tensor) -> bool {
    x.device().is_cpu() && matches!(x.dtype(), DType::F32 | DType::F64)
}

/// Softmax over the last dimension, differentiable: `[.., d] → [.., d]`.
///
/// Backward: `dx = y·(g − Σ g·y)` per row.
pub fn softmax(x: &Tensor) -> Result<Tensor> {
    if has_cpu_kernel(x) {
        x.contiguous()?.apply_op1(SoftmaxOp)
    } else {
        candle_nn::ops::softmax(x, D::Minus1)
    }
}

/// Exact (erf) GELU, `0.5·x·(1 + erf(x/√2))`, as PyTorch's `nn.GELU()`; any shape.
///
/// Backward: `dx = g·(Φ(x) + x·φ(x))`.
pub fn gelu_erf(x: &Tensor) -> Result<Tensor> {
    if has_cpu_kernel(x) {
        x.contiguous()?.apply_op1(GeluOp)
    } else {
        x.gelu_erf()
    }
}

struct SoftmaxOp;

impl CustomOp1 for SoftmaxOp {
    fn name(&self) -> &'static str {
        "motion-softmax-last-dim"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let d = l.dims().last().copied().unwrap_or(1).max(1);
        dispatch_real!(s.dtype(), T => {
            let mut y = contiguous_slice::<T>(s, l)?.to_vec();
            kernels::softmax_fwd(Isa::selected(), &mut y, d, T::from_f64(1.0));
            Ok((T::to_cpu_storage_owned(y), l.shape().clone()))
        })
    }

    fn bwd(&self, _arg: &Tensor, res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let d = res.dim(D::Minus1)?;
        let grad = grad.contiguous()?;
        dispatch_real!(res.dtype(), T => {
            let dx = with_slice::<T, _>(res, |y| {
                with_slice::<T, _>(&grad, |g| {
                    let mut dx = g.to_vec();
                    kernels::softmax_bwd(Isa::selected(), y, &mut dx, d, T::from_f64(1.0));
                    Ok(dx)
                })
            })?;
            Ok(Some(Tensor::from_vec(dx, res.shape(), res.device())?))
        })
    }
}

struct GeluOp;

impl CustomOp1 for GeluOp {
    fn name(&self) -> &'static str {
        "motion-gelu-erf"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        dispatch_real!(s.dtype(), T => {
            let x = contiguous_slice::<T>(s, l)?;
            let mut y = vec![T::from_f64(0.0); x.len()];
            kernels::gelu_fwd(Isa::selected(), x, &mut y);
            Ok((T::to_cpu_storage_owned(y), l.shape().clone()))
        })
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let grad = grad.contiguous()?;
        dispatch_real!(arg.dtype(), T => {
            let dx = with_slice::<T, _>(arg, |x| {
                with_slice::<T, _>(&grad, |g| {
                    let mut dx = g.to_vec();
                    kernels::gelu_bwd(Isa::selected(), x, &mut dx);
                    Ok(dx)
                })
            })?;
            Ok(Some(Tensor::from_vec(dx, arg.shape(), arg.device())?))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::finite_difference_check;
    use candle_core::{Device, Var};

    use crate::nn::testing::randn;
    use crate::testing::max_abs_diff;

    fn softmax_matches_primitive(dev: &Device) -> Result<()> {
        let x = (randn(&[2, 3, 7], 1, dev)? * 3.0)?.to_dtype(DType::F32)?;
        let ours = softmax(&x)?;
        let reference = candle_nn::ops::softmax(&x, D::Minus1)?;
        assert!(max_abs_diff(&ours, &reference)? < 1e-6);
        Ok(())
    }

    fn softmax_gradient(dev: &Device) -> Result<()> {
        let x = randn(&[3, 5], 2, dev)?;
        let w = randn(&[3, 5], 3, dev)?;
        finite_difference_check(&x, |x| softmax(x)?.mul(&w)?.sum_all(), 1e-6, 1e-6)
    }

    fn softmax_non_contiguous_input(dev: &Device) -> Result<()> {
        let x = randn(&[4, 6], 4, dev)?.t()?;
        let ours = softmax(&x)?;
        let reference = candle_nn::ops::softmax(&x, D::Minus1)?;
        assert!(max_abs_diff(&ours, &reference)? < 1e-12);
        Ok(())
    }

    fn gelu_matches_primitive(dev: &Device) -> Result<()> {
        let x = (randn(&[4, 9], 5, dev)? * 3.0)?;
        for dtype in [DType::F32, DType::F64] {
            let x = x.to_dtype(dtype)?;
            assert!(max_abs_diff(&gelu_erf(&x)?, &x.gelu_erf()?)? < 1e-6);
        }
        Ok(())
    }

    fn gelu_gradient(dev: &Device) -> Result<()> {
        let x = (randn(&[3, 8], 6, dev)? * 2.0)?;
        let w = randn(&[3, 8], 7, dev)?;
        finite_difference_check(&x, |x| gelu_erf(x)?.mul(&w)?.sum_all(), 1e-6, 1e-6)
    }

    fn gradients_match_primitive(dev: &Device) -> Result<()> {
        let x = Var::from_tensor(&randn(&[2, 5], 8, dev)?)?;
        let w = randn(&[2, 5], 9, dev)?;
        let ours = softmax(&gelu_erf(x.as_tensor())?)?.mul(&w)?.sum_all()?.backward()?;
        let prim = candle_nn::ops::softmax(&x.as_tensor().gelu_erf()?, D::Minus1)?.mul(&w)?.sum_all()?.backward()?;
        let a = ours.get(x.as_tensor()).expect("no grad (custom)");
        let b = prim.get(x.as_tensor()).expect("no grad (primitive)");
        // candle's gelu_erf backward rounds 1/sqrt(2π) to 0.398942 (relative error 1e-6).
        assert!(max_abs_diff(a, b)? < 1e-6);
        Ok(())
    }

    mod cpu {
        crate::nn::testing::cpu_tests!(
            softmax_matches_primitive,
            softmax_gradient,
            softmax_non_contiguous_input,
            gelu_matches_primitive,
            gelu_gradient,
            gradients_match_primitive,
        );
    }
}
