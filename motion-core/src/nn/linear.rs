//! Affine layer `y = x·Wᵀ + b` with PyTorch's `[out, in]` weight layout.

use candle_core::{bail, CpuStorage, CustomOp1, Layout, Result, Shape, Tensor};

use super::isa::Isa;
use super::kernels::{self, dispatch_real, with_slice, MatView, Real};
use super::ops::has_cpu_kernel;

/// `nn.Linear`: weight `[out, in]`, optional bias `[out]`.
#[derive(Debug, Clone)]
pub struct Linear {
    weight: Tensor,
    bias: Option<Tensor>,
}

impl Linear {
    /// Wraps a weight `[out, in]` and an optional bias `[out]`.
    pub fn new(weight: Tensor, bias: Option<Tensor>) -> Result<Self> {
        let (out_dim, _) = weight.dims2()?;
        if let Some(b) = &bias {
            if b.dims1()? != out_dim {
                bail!("linear bias {:?} does not match weight {:?}", b.shape(), weight.shape());
            }
        }
        Ok(Self { weight, bias })
    }

    /// The weight, `[out, in]`.
    pub fn weight(&self) -> &Tensor {
        &self.weight
    }

    /// The bias, `[out]`.
    pub fn bias(&self) -> Option<&Tensor> {
        self.bias.as_ref()
    }

    /// Training path: `[.., in] → [.., out]` with candle's matmul and broadcast add, so weights
    /// held as `Var`s receive gradients.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (out_dim, in_dim) = self.weight.dims2()?;
        let mut dims = x.dims().to_vec();
        let rows = x.elem_count() / in_dim.max(1);
        let y = x.reshape((rows, in_dim))?.matmul(&self.weight.t()?)?;
        let y = match &self.bias {
            Some(b) => y.broadcast_add(b)?,
            None => y,
        };
        if let Some(last) = dims.last_mut() {
            *last = out_dim;
        }
        y.reshape(dims)
    }

    /// Frozen-weight path: `[.., in] → [.., out]` as one custom op whose backward returns only
    /// `dx = g·W` (no weight or bias gradient, hence no wasted `xᵀ·g` product).
    ///
    /// Inputs whose rows are contiguous (a contiguous tensor, or a `narrow` along dim 1 of a
    /// `[batch, tokens, in]` tensor) are read in place. Off the CPU this is [`Self::forward`]
    /// on detached weights.
    pub fn forward_frozen(&self, x: &Tensor) -> Result<Tensor> {
        let op = FrozenLinearOp { weight: self.weight.detach(), bias: self.bias.as_ref().map(Tensor::detach) };
        if !has_cpu_kernel(x) {
            return Linear::new(op.weight, op.bias)?.forward(x);
        }
        let in_dim = self.weight.dim(1)?;
        if row_view(x.layout(), in_dim).is_some() {
            x.apply_op1(op)
        } else {
            x.contiguous()?.apply_op1(op)
        }
    }
}

/// The input of a linear layer as `[batch, rows, k]` matrices with unit column stride.
pub(crate) fn row_view(l: &Layout, k: usize) -> Option<MatView> {
    let dims = l.dims();
    let stride = l.stride();
    if dims.last() != Some(&k) {
        return None;
    }
    if l.is_contiguous() {
        return Some(MatView::contiguous(l.start_offset(), 1, l.shape().elem_count() / k.max(1), k));
    }
    match (dims, stride) {
        ([b, m, _], [sb, sm, 1]) if *sm == k => {
            Some(MatView { offset: l.start_offset(), batch: *b, rows: *m, cols: k, strides: [*sb, k, 1] })
        }
        _ => None,
    }
}

struct FrozenLinearOp {
    weight: Tensor,
    bias: Option<Tensor>,
}

impl FrozenLinearOp {
    fn fwd<T: Real>(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let (n, k) = self.weight.dims2()?;
        let Some(xv) = row_view(l, k) else {
            bail!("frozen linear: input {:?} with strides {:?} is not row-contiguous", l.dims(), l.stride());
        };
        let x = T::cpu_storage_as_slice(s)?;
        let y = with_slice::<T, _>(&self.weight, |w| match &self.bias {
            Some(b) => with_slice::<T, _>(b, |bias| kernels::linear(Isa::selected(), x, xv, w, n, Some(bias))),
            None => kernels::linear(Isa::selected(), x, xv, w, n, None),
        })?;
        let mut dims = l.dims().to_vec();
        if let Some(last) = dims.last_mut() {
            *last = n;
        }
        Ok((T::to_cpu_storage_owned(y), Shape::from(dims)))
    }

    fn bwd_impl<T: Real>(&self, arg: &Tensor, grad: &Tensor) -> Result<Tensor> {
        let (n, k) = self.weight.dims2()?;
        let grad = grad.contiguous()?;
        let dx = with_slice::<T, _>(&grad, |g| {
            with_slice::<T, _>(&self.weight, |w| kernels::linear_bwd(Isa::selected(), g, w, n, k))
        })?;
        Tensor::from_vec(dx, arg.shape(), arg.device())
    }
}

impl CustomOp1 for FrozenLinearOp {
    fn name(&self) -> &'static str {
        "motion-frozen-linear"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        use candle_core::backend::BackendStorage;
        dispatch_real!(s.dtype(), T => self.fwd::<T>(s, l))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        if !has_cpu_kernel(grad) {
            return Ok(Some(grad.matmul(&self.weight)?));
        }
        dispatch_real!(arg.dtype(), T => Ok(Some(self.bwd_impl::<T>(arg, grad)?)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::testing::randn;
    use crate::testing::finite_difference_check;
    use crate::testing::max_abs_diff;
    use candle_core::{DType, Device, IndexOp, Var};

    fn layer(dev: &Device, bias: bool) -> Result<Linear> {
        let b = if bias { Some(randn(&[5], 11, dev)?) } else { None };
        Linear::new(randn(&[5, 4], 10, dev)?, b)
    }

    fn frozen_matches_primitive(dev: &Device) -> Result<()> {
        let x = randn(&[2, 3, 4], 12, dev)?;
        for bias in [true, false] {
            let lin = layer(dev, bias)?;
            for dtype in [DType::F32, DType::F64] {
                let lin =
                    Linear::new(lin.weight().to_dtype(dtype)?, lin.bias().map(|b| b.to_dtype(dtype)).transpose()?)?;
                let x = x.to_dtype(dtype)?;
                assert!(max_abs_diff(&lin.forward_frozen(&x)?, &lin.forward(&x)?)? < 1e-5);
            }
        }
        Ok(())
    }

    fn frozen_reads_narrowed_rows(dev: &Device) -> Result<()> {
        let lin = layer(dev, true)?;
        let x = randn(&[2, 6, 4], 13, dev)?.narrow(1, 1, 4)?;
        assert!(row_view(x.layout(), 4).is_some_and(|v| v.batch == 2));
        assert!(max_abs_diff(&lin.forward_frozen(&x)?, &lin.forward(&x)?)? < 1e-12);
        let xt = randn(&[4, 3], 14, dev)?.t()?;
        assert!(max_abs_diff(&lin.forward_frozen(&xt)?, &lin.forward(&xt)?)? < 1e-12);
        Ok(())
    }

    fn frozen_gradient(dev: &Device) -> Result<()> {
        let lin = layer(dev, true)?;
        let w = randn(&[2, 3, 5], 15, dev)?;
        let x = randn(&[2, 3, 4], 16, dev)?;
        finite_difference_check(&x, |x| lin.forward_frozen(x)?.mul(&w)?.sum_all(), 1e-6, 1e-7)?;
        let x = randn(&[2, 5, 4], 17, dev)?;
        let w = randn(&[2, 3, 5], 18, dev)?;
        finite_difference_check(&x, |x| lin.forward_frozen(&x.narrow(1, 1, 3)?)?.mul(&w)?.sum_all(), 1e-6, 1e-7)
    }

    fn frozen_gives_no_weight_gradient(dev: &Device) -> Result<()> {
        let wv = Var::from_tensor(&randn(&[5, 4], 19, dev)?)?;
        let lin = Linear::new(wv.as_tensor().clone(), None)?;
        let x = Var::from_tensor(&randn(&[3, 4], 20, dev)?)?;
        let grads = lin.forward_frozen(x.as_tensor())?.sqr()?.sum_all()?.backward()?;
        assert!(grads.get(wv.as_tensor()).is_none());
        let frozen_dx = grads.get(x.as_tensor()).expect("no grad for x").clone();
        let grads = lin.forward(x.as_tensor())?.sqr()?.sum_all()?.backward()?;
        assert!(grads.get(wv.as_tensor()).is_some());
        let dx = grads.get(x.as_tensor()).expect("no grad for x");
        assert!(max_abs_diff(&frozen_dx, dx)? < 1e-12);
        assert!(frozen_dx.i(0)?.abs()?.sum_all()?.to_scalar::<f64>()? > 0.0);
        Ok(())
    }

    mod cpu {
        crate::nn::testing::cpu_tests!(
            frozen_matches_primitive,
            frozen_reads_narrowed_rows,
            frozen_gradient,
            frozen_gives_no_weight_gradient,
        );
    }
}
