//! One frozen post-LN encoder layer as a single custom op with a hand-written backward.
//!
//! In the DNO loop every layer of every unrolled denoiser pass is a graph node, and candle's
//! backward allocates a zero tensor plus a sum for each gradient edge. Fusing the layer
//! (attention, both residual LayerNorms and the GELU feed-forward block) leaves one node per
//! layer, keeps exactly the activations the input gradient needs (q/k/v, attention
//! probabilities, normalised residuals, pre-activation) and never forms weight gradients.
//! The per-layer maths are the kernels of [`crate::nn`], shared with the single-op versions.

use std::sync::Mutex;

use candle_core::backend::BackendStorage;
use candle_core::{bail, CpuStorage, CustomOp1, Error, Layout, Result, Shape, Storage, StorageRef, Tensor};

use crate::nn::kernels::{self, contiguous_slice, dispatch_real, MatView, Real};

/// The frozen weights of one layer (detached tensors: reading them never records a graph).
#[derive(Debug, Clone)]
pub(crate) struct LayerWeights {
    pub in_proj_weight: Tensor,
    pub in_proj_bias: Tensor,
    pub out_proj_weight: Tensor,
    pub out_proj_bias: Tensor,
    pub linear1_weight: Tensor,
    pub linear1_bias: Tensor,
    pub linear2_weight: Tensor,
    pub linear2_bias: Tensor,
    pub norm1_weight: Tensor,
    pub norm1_bias: Tensor,
    pub norm2_weight: Tensor,
    pub norm2_bias: Tensor,
}

impl LayerWeights {
    fn each(&self) -> [&Tensor; 12] {
        [
            &self.in_proj_weight,
            &self.in_proj_bias,
            &self.out_proj_weight,
            &self.out_proj_bias,
            &self.linear1_weight,
            &self.linear1_bias,
            &self.linear2_weight,
            &self.linear2_bias,
            &self.norm1_weight,
            &self.norm1_bias,
            &self.norm2_weight,
            &self.norm2_bias,
        ]
    }
}

/// `h [batch, tokens, d] → LN2(h1 + FF(h1))` with `h1 = LN1(h + MHA(h))`.
pub(crate) struct FusedEncoderLayer {
    weights: LayerWeights,
    num_heads: usize,
    eps: f64,
    cache: Mutex<Option<Cache>>,
}

/// Activations kept from the forward pass for the input gradient.
struct Cache {
    /// `[batch·tokens, 3d]`, the fused q/k/v projection.
    qkv: CpuStorage,
    /// Per batch element, `[heads, tokens, tokens]` softmax probabilities.
    probs: Vec<CpuStorage>,
    /// `[batch·tokens, d]` normalised first residual, and its `1/std` per row.
    xhat1: CpuStorage,
    rstd1: CpuStorage,
    /// `[batch·tokens, ff]` feed-forward pre-activation.
    pre_gelu: CpuStorage,
    xhat2: CpuStorage,
    rstd2: CpuStorage,
}

/// A weight matrix `[out, in]` in CPU memory.
#[derive(Clone, Copy)]
struct Mat<'a> {
    storage: &'a CpuStorage,
    layout: &'a Layout,
}

impl Mat<'_> {
    /// The matrix itself as a one-batch view (for `dx = g·W`).
    fn view(&self) -> Result<MatView> {
        let (n, k) = match self.layout.dims() {
            [n, k] => (*n, *k),
            dims => bail!("weight must be 2-d, got {dims:?}"),
        };
        if self.layout.contiguous_offsets().is_none() {
            bail!("fused layer weights must be contiguous");
        }
        Ok(MatView::contiguous(self.layout.start_offset(), 1, n, k))
    }
}

struct Params<'a, T> {
    in_w: Mat<'a>,
    in_b: &'a [T],
    out_w: Mat<'a>,
    out_b: &'a [T],
    l1_w: Mat<'a>,
    l1_b: &'a [T],
    l2_w: Mat<'a>,
    l2_b: &'a [T],
    n1_w: &'a [T],
    n1_b: &'a [T],
    n2_w: &'a [T],
    n2_b: &'a [T],
}

fn cpu<'a>(guard: &'a (StorageRef<'_>, &'a Layout)) -> Result<Mat<'a>> {
    match &*guard.0 {
        Storage::Cpu(storage) => Ok(Mat { storage, layout: guard.1 }),
        _ => bail!("fused encoder layer: weights are not on the CPU"),
    }
}

impl<'a, T: Real> Params<'a, T> {
    fn new(g: &'a [(StorageRef<'_>, &'a Layout); 12]) -> Result<Self> {
        let slice = |i: usize| -> Result<&'a [T]> {
            let m = cpu(&g[i])?;
            contiguous_slice::<T>(m.storage, m.layout)
        };
        Ok(Self {
            in_w: cpu(&g[0])?,
            in_b: slice(1)?,
            out_w: cpu(&g[2])?,
            out_b: slice(3)?,
            l1_w: cpu(&g[4])?,
            l1_b: slice(5)?,
            l2_w: cpu(&g[6])?,
            l2_b: slice(7)?,
            n1_w: slice(8)?,
            n1_b: slice(9)?,
            n2_w: slice(10)?,
            n2_b: slice(11)?,
        })
    }
}

/// `y = x·Wᵀ + b` for contiguous `x [m, k]`.
fn linear<T: Real>(x: &CpuStorage, m: usize, k: usize, w: Mat, b: &[T]) -> Result<Vec<T>> {
    kernels::linear(x, MatView::contiguous(0, 1, m, k), w.storage, w.layout, Some(b))
}

/// `dx = g·W` for contiguous `g [m, n]` and `W [n, k]`.
fn linear_bwd<T: Real>(g: &CpuStorage, m: usize, w: Mat) -> Result<Vec<T>> {
    let wv = w.view()?;
    T::cpu_storage_data(kernels::matmul(g, MatView::contiguous(0, 1, m, wv.rows), w.storage, wv)?)
}

impl FusedEncoderLayer {
    pub(crate) fn new(weights: LayerWeights, num_heads: usize, eps: f64) -> Self {
        Self { weights, num_heads, eps, cache: Mutex::new(None) }
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, Option<Cache>>> {
        self.cache.lock().map_err(|_| Error::Msg("fused encoder layer: cache lock poisoned".into()))
    }

    fn fwd<T: Real>(&self, x_storage: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, s, d) = match l.dims() {
            [b, s, d] => (*b, *s, *d),
            dims => bail!("fused encoder layer expects [batch, tokens, d], got {dims:?}"),
        };
        let x = contiguous_slice::<T>(x_storage, l)?;
        let guards = self.weights.each().map(|t| t.storage_and_layout());
        let p = Params::<T>::new(&guards)?;
        let (m, h) = (b * s, self.num_heads);
        let hd = d / h;
        let ff = p.l1_b.len();
        if p.in_b.len() != 3 * d || d % h != 0 {
            bail!("fused encoder layer: width {d} does not match in_proj {} / {h} heads", p.in_b.len());
        }
        let scale = T::from_f64(1.0 / (hd as f64).sqrt());
        let zero = T::from_f64(0.0);

        // Self-attention: one q/k/v projection, then per batch element all heads at once.
        let x_rows = MatView::contiguous(l.start_offset(), 1, m, d);
        let qkv = kernels::linear(x_storage, x_rows, p.in_w.storage, p.in_w.layout, Some(p.in_b))?;
        let qkv = T::to_cpu_storage_owned(qkv);
        let mut ctx = vec![zero; m * d];
        let mut probs = Vec::with_capacity(b);
        for bi in 0..b {
            let head = |part: usize| MatView {
                offset: bi * s * 3 * d + part * d,
                batch: h,
                rows: s,
                cols: hd,
                strides: [hd, 3 * d, 1],
            };
            let mut scores = T::cpu_storage_data(kernels::matmul(&qkv, head(0), &qkv, head(1).t())?)?;
            kernels::softmax_fwd(&mut scores, s, scale);
            let prob = T::to_cpu_storage_owned(scores);
            let out = kernels::matmul(&prob, MatView::contiguous(0, h, s, s), &qkv, head(2))?;
            let out = T::cpu_storage_as_slice(&out)?;
            for hi in 0..h {
                for si in 0..s {
                    let src = &out[(hi * s + si) * hd..][..hd];
                    ctx[(bi * s + si) * d + hi * hd..][..hd].copy_from_slice(src);
                }
            }
            probs.push(prob);
        }
        let ctx = T::to_cpu_storage_owned(ctx);
        let mut r1 = linear(&ctx, m, d, p.out_w, p.out_b)?;
        for (r, &xv) in r1.iter_mut().zip(x) {
            *r += xv;
        }
        let mut h1 = vec![zero; m * d];
        let (mut xhat1, mut rstd1) = (vec![zero; m * d], vec![zero; m]);
        kernels::layer_norm_fwd(&r1, p.n1_w, p.n1_b, self.eps, &mut h1, Some((&mut xhat1, &mut rstd1)));

        // Feed-forward block.
        let h1 = T::to_cpu_storage_owned(h1);
        let pre = linear(&h1, m, d, p.l1_w, p.l1_b)?;
        let mut act = vec![zero; m * ff];
        kernels::gelu_fwd(&pre, &mut act);
        let mut r2 = linear(&T::to_cpu_storage_owned(act), m, ff, p.l2_w, p.l2_b)?;
        for (r, &hv) in r2.iter_mut().zip(T::cpu_storage_as_slice(&h1)?) {
            *r += hv;
        }
        let mut y = vec![zero; m * d];
        let (mut xhat2, mut rstd2) = (vec![zero; m * d], vec![zero; m]);
        kernels::layer_norm_fwd(&r2, p.n2_w, p.n2_b, self.eps, &mut y, Some((&mut xhat2, &mut rstd2)));

        *self.lock()? = Some(Cache {
            qkv,
            probs,
            xhat1: T::to_cpu_storage_owned(xhat1),
            rstd1: T::to_cpu_storage_owned(rstd1),
            pre_gelu: T::to_cpu_storage_owned(pre),
            xhat2: T::to_cpu_storage_owned(xhat2),
            rstd2: T::to_cpu_storage_owned(rstd2),
        });
        Ok((T::to_cpu_storage_owned(y), l.shape().clone()))
    }

    fn bwd_impl<T: Real>(&self, arg: &Tensor, grad: &Tensor) -> Result<Tensor> {
        let (b, s, d) = arg.dims3()?;
        let guards = self.weights.each().map(|t| t.storage_and_layout());
        let p = Params::<T>::new(&guards)?;
        let cache = self.lock()?;
        let Some(c) = cache.as_ref() else {
            bail!("fused encoder layer: backward without a forward cache");
        };
        let (m, h) = (b * s, self.num_heads);
        let hd = d / h;
        let scale = T::from_f64(1.0 / (hd as f64).sqrt());

        // Second LayerNorm and the feed-forward block.
        let grad = grad.contiguous()?;
        let mut dr2 = kernels::with_slice::<T, _>(&grad, |g| Ok(g.to_vec()))?;
        kernels::layer_norm_bwd(
            &mut dr2,
            T::cpu_storage_as_slice(&c.xhat2)?,
            T::cpu_storage_as_slice(&c.rstd2)?,
            p.n2_w,
        );
        let dr2 = T::to_cpu_storage_owned(dr2);
        let mut dact = linear_bwd::<T>(&dr2, m, p.l2_w)?;
        kernels::gelu_bwd(T::cpu_storage_as_slice(&c.pre_gelu)?, &mut dact);
        let mut dr1 = linear_bwd::<T>(&T::to_cpu_storage_owned(dact), m, p.l1_w)?;
        for (a, &g) in dr1.iter_mut().zip(T::cpu_storage_as_slice(&dr2)?) {
            *a += g;
        }
        kernels::layer_norm_bwd(
            &mut dr1,
            T::cpu_storage_as_slice(&c.xhat1)?,
            T::cpu_storage_as_slice(&c.rstd1)?,
            p.n1_w,
        );
        let dr1 = T::to_cpu_storage_owned(dr1);

        // Attention: dV = Pᵀ·dO, dP = dO·Vᵀ, dS = softmax'(dP), dQ = dS·K, dK = dSᵀ·Q.
        let dctx = T::to_cpu_storage_owned(linear_bwd::<T>(&dr1, m, p.out_w)?);
        let mut dqkv = vec![T::from_f64(0.0); m * 3 * d];
        for bi in 0..b {
            let head = |part: usize| MatView {
                offset: bi * s * 3 * d + part * d,
                batch: h,
                rows: s,
                cols: hd,
                strides: [hd, 3 * d, 1],
            };
            let d_out = MatView { offset: bi * s * d, batch: h, rows: s, cols: hd, strides: [hd, d, 1] };
            let prob = &c.probs[bi];
            let pv = MatView::contiguous(0, h, s, s);
            let dv = kernels::matmul(prob, pv.t(), &dctx, d_out)?;
            let mut dp = T::cpu_storage_data(kernels::matmul(&dctx, d_out, &c.qkv, head(2).t())?)?;
            kernels::softmax_bwd(T::cpu_storage_as_slice(prob)?, &mut dp, s, scale);
            let ds = T::to_cpu_storage_owned(dp);
            let dq = kernels::matmul(&ds, pv, &c.qkv, head(1))?;
            let dk = kernels::matmul(&ds, pv.t(), &c.qkv, head(0))?;
            for (part, st) in [(0, &dq), (1, &dk), (2, &dv)] {
                let src = T::cpu_storage_as_slice(st)?;
                for hi in 0..h {
                    for si in 0..s {
                        let from = &src[(hi * s + si) * hd..][..hd];
                        dqkv[(bi * s + si) * 3 * d + part * d + hi * hd..][..hd].copy_from_slice(from);
                    }
                }
            }
        }
        let mut dx = linear_bwd::<T>(&T::to_cpu_storage_owned(dqkv), m, p.in_w)?;
        for (a, &g) in dx.iter_mut().zip(T::cpu_storage_as_slice(&dr1)?) {
            *a += g;
        }
        Tensor::from_vec(dx, arg.shape(), arg.device())
    }
}

impl CustomOp1 for FusedEncoderLayer {
    fn name(&self) -> &'static str {
        "motion-fused-encoder-layer"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        dispatch_real!(s.dtype(), T => self.fwd::<T>(s, l))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        dispatch_real!(arg.dtype(), T => Ok(Some(self.bwd_impl::<T>(arg, grad)?)))
    }
}
