//! The frozen post-LN encoder stack, and with its [`Ends`] a whole denoiser pass, as a single
//! custom op with a hand-written backward.
//!
//! In the DNO loop every layer of every unrolled denoiser pass would be a graph node, and
//! candle's backward allocates a zero tensor plus a sum for each gradient edge. Fusing the
//! pass (the input projection, the condition token and positional encoding, per layer
//! attention, both residual LayerNorms and the GELU feed-forward block, then the output
//! projection; with an [`Epilogue`] also both guidance branches, x̂0 and the DDIM update)
//! leaves one node per pass, keeps exactly the activations the input gradient
//! needs (q/k/v, attention probabilities, normalised residuals, pre-activation) and never
//! forms weight gradients. The per-layer maths are the kernels of [`crate::nn`], shared with
//! the single-op versions.
//!
//! **Threads.** The work runs on the current rayon pool in one of two ways, picked per call
//! by [`Plan`]: with at least as many batch elements as threads, groups of elements go
//! through the whole pass as one task each (no synchronisation between layers: a worker that
//! waits for its partner at every phase sleeps, and waking it costs more than a small phase);
//! with fewer, every layer runs in phases over row chunks and attention blocks of the batch.
//! The arithmetic of a row does not depend on the split beyond rounding (the gemm kernels'
//! blocking depends on the number of rows), so the result is the same either way.

mod ends;
mod plan;

use std::sync::Mutex;

use candle_core::backend::BackendStorage;
use candle_core::{bail, CpuStorage, CustomOp1, Error, Layout, Result, Shape, Storage, StorageRef, Tensor};

use ends::EndSlices;
pub(crate) use ends::{Ends, Epilogue};
use plan::{attention_blocks, run, Plan};

use crate::nn::isa::Isa;
use crate::nn::kernels::{
    self, contiguous_slice, dispatch_real, linear_rows, linear_rows_bwd, row_chunks, rows_of, split_rows, MatView,
    Real, Weight,
};

/// The frozen weights of one layer (detached tensors: reading them never records a graph).
/// The four linear weights come twice: as loaded (`[out, in]`, which the input gradient
/// reads as it lies) and transposed once into contiguous `[in, out]` (`*_t`, which the forward
/// products read as they lie, instead of gathering `[out, in]`'s columns on every call).
#[derive(Debug, Clone)]
pub(crate) struct LayerWeights {
    pub in_proj_weight: Tensor,
    pub in_proj_weight_t: Tensor,
    pub in_proj_bias: Tensor,
    pub out_proj_weight: Tensor,
    pub out_proj_weight_t: Tensor,
    pub out_proj_bias: Tensor,
    pub linear1_weight: Tensor,
    pub linear1_weight_t: Tensor,
    pub linear1_bias: Tensor,
    pub linear2_weight: Tensor,
    pub linear2_weight_t: Tensor,
    pub linear2_bias: Tensor,
    pub norm1_weight: Tensor,
    pub norm1_bias: Tensor,
    pub norm2_weight: Tensor,
    pub norm2_bias: Tensor,
}

impl LayerWeights {
    fn each(&self) -> [&Tensor; 16] {
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
            &self.in_proj_weight_t,
            &self.out_proj_weight_t,
            &self.linear1_weight_t,
            &self.linear2_weight_t,
        ]
    }
}

/// `h [batch, tokens, d] → h` through every layer, each `h ← LN2(h1 + FF(h1))` with
/// `h1 = LN1(h + MHA(h))`.
pub(crate) struct FusedEncoderStack {
    layers: Vec<LayerWeights>,
    ends: Option<Ends>,
    num_heads: usize,
    eps: f64,
    /// The instruction set of every kernel of the pass.
    isa: Isa,
    /// Whether the forward pass keeps its activations for a backward pass (false when the
    /// input records no graph, so no gradient can reach this op: then each layer's
    /// activations are dropped as soon as the next layer has its input).
    keep_activations: bool,
    cache: Mutex<Option<Saved>>,
}

/// What the forward pass keeps for the backward: how it split the work, and each group's
/// activations.
struct Saved {
    plan: Plan,
    groups: Vec<Group>,
}

/// The batch elements `[first, first + count)` and their activations in every layer.
struct Group {
    first: usize,
    count: usize,
    layers: Vec<Cache>,
}

/// Activations of one layer kept from the forward pass for the input gradient (over the
/// rows of one group).
struct Cache {
    /// `[batch·tokens, 3d]`, the fused q/k/v projection.
    qkv: CpuStorage,
    /// `[batch, tokens (query), heads, tokens (key)]` softmax probabilities (query-major, so
    /// a block of query rows is one contiguous range).
    probs: CpuStorage,
    /// `[batch·tokens, d]` normalised first residual, and its `1/std` per row.
    xhat1: CpuStorage,
    rstd1: CpuStorage,
    /// `[batch·tokens, ff]` feed-forward pre-activation.
    pre_gelu: CpuStorage,
    xhat2: CpuStorage,
    rstd2: CpuStorage,
}

/// One layer's forward buffers over the rows of a group: the activations a backward pass
/// reads ([`Cache`]) and the attention context. Every kernel that fills them overwrites every
/// element, so a forward-only pass hands one layer's buffers to the next instead of
/// allocating and zeroing them again.
struct Activations<T> {
    qkv: Vec<T>,
    probs: Vec<T>,
    ctx: Vec<T>,
    xhat1: Vec<T>,
    rstd1: Vec<T>,
    pre: Vec<T>,
    xhat2: Vec<T>,
    rstd2: Vec<T>,
}

impl<T: Real> Activations<T> {
    /// Buffers for `m` rows of width `d`, `probs` probabilities and feed-forward width `ff`.
    fn zeros(m: usize, d: usize, probs: usize, ff: usize) -> Self {
        let zeros = |n: usize| vec![T::from_f64(0.0); n];
        Self {
            qkv: zeros(m * 3 * d),
            probs: zeros(probs),
            ctx: zeros(m * d),
            xhat1: zeros(m * d),
            rstd1: zeros(m),
            pre: zeros(m * ff),
            xhat2: zeros(m * d),
            rstd2: zeros(m),
        }
    }

    /// Whether these buffers have the sizes of [`Activations::zeros`] with the same arguments.
    fn fits(&self, m: usize, d: usize, probs: usize, ff: usize) -> bool {
        self.qkv.len() == m * 3 * d
            && self.probs.len() == probs
            && self.ctx.len() == m * d
            && self.xhat1.len() == m * d
            && self.rstd1.len() == m
            && self.pre.len() == m * ff
            && self.xhat2.len() == m * d
            && self.rstd2.len() == m
    }

    /// What the backward pass keeps (the context is not needed).
    fn into_cache(self) -> Cache {
        Cache {
            qkv: T::to_cpu_storage_owned(self.qkv),
            probs: T::to_cpu_storage_owned(self.probs),
            xhat1: T::to_cpu_storage_owned(self.xhat1),
            rstd1: T::to_cpu_storage_owned(self.rstd1),
            pre_gelu: T::to_cpu_storage_owned(self.pre),
            xhat2: T::to_cpu_storage_owned(self.xhat2),
            rstd2: T::to_cpu_storage_owned(self.rstd2),
        }
    }
}

/// The frozen weights of one layer as CPU slices, with their sizes.
struct Params<'a, T> {
    /// `[3d, d]`, `[d, d]`, `[ff, d]`, `[d, ff]` row-major (`[out, in]`), and each transposed
    /// (`*_wt`, row-major `[in, out]`).
    in_w: &'a [T],
    in_wt: &'a [T],
    out_wt: &'a [T],
    l1_wt: &'a [T],
    l2_wt: &'a [T],
    in_b: &'a [T],
    out_w: &'a [T],
    out_b: &'a [T],
    l1_w: &'a [T],
    l1_b: &'a [T],
    l2_w: &'a [T],
    l2_b: &'a [T],
    n1_w: &'a [T],
    n1_b: &'a [T],
    n2_w: &'a [T],
    n2_b: &'a [T],
}

impl<'a, T: Real> Params<'a, T> {
    fn new(g: &'a [(StorageRef<'_>, &'a Layout); 16], d: usize) -> Result<Self> {
        let slice = |i: usize, len: usize| -> Result<&'a [T]> {
            let data = match &*g[i].0 {
                Storage::Cpu(storage) => contiguous_slice::<T>(storage, g[i].1)?,
                _ => bail!("fused encoder layer: weights are not on the CPU"),
            };
            if data.len() != len {
                bail!("fused encoder layer: weight {i} has {} elements, expected {len} for width {d}", data.len());
            }
            Ok(data)
        };
        let ff = match g[5].1.dims() {
            [ff] => *ff,
            dims => bail!("fused encoder layer: linear1 bias must be 1-d, got {dims:?}"),
        };
        Ok(Self {
            in_w: slice(0, 3 * d * d)?,
            in_wt: slice(12, 3 * d * d)?,
            out_wt: slice(13, d * d)?,
            l1_wt: slice(14, ff * d)?,
            l2_wt: slice(15, d * ff)?,
            in_b: slice(1, 3 * d)?,
            out_w: slice(2, d * d)?,
            out_b: slice(3, d)?,
            l1_w: slice(4, ff * d)?,
            l1_b: slice(5, ff)?,
            l2_w: slice(6, d * ff)?,
            l2_b: slice(7, d)?,
            n1_w: slice(8, d)?,
            n1_b: slice(9, d)?,
            n2_w: slice(10, d)?,
            n2_b: slice(11, d)?,
        })
    }

    fn ff(&self) -> usize {
        self.l1_b.len()
    }
}

/// Sizes of one layer call.
#[derive(Clone, Copy)]
struct Dims {
    tokens: usize,
    d: usize,
    heads: usize,
}

impl Dims {
    fn head_dim(&self) -> usize {
        self.d / self.heads
    }

    /// Head `h` of part `part` (0 q, 1 k, 2 v) of element `b` in the `[·, 3d]` projection, as
    /// a `[tokens, head_dim]` view.
    fn qkv_head(&self, b: usize, part: usize, h: usize) -> MatView {
        let offset = b * self.tokens * 3 * self.d + part * self.d + h * self.head_dim();
        MatView { offset, batch: 1, rows: self.tokens, cols: self.head_dim(), strides: [0, 3 * self.d, 1] }
    }

    /// Head `h` of the probabilities of element `b` as a `[tokens (query), tokens (key)]` view.
    fn prob_head(&self, b: usize, h: usize) -> MatView {
        let s = self.tokens;
        MatView { offset: b * s * self.heads * s + h * s, batch: 1, rows: s, cols: s, strides: [0, self.heads * s, 1] }
    }

    /// Head `h` of a block's own `[rows, heads, tokens]` probabilities (or score gradients).
    fn block_prob_head(&self, rows: usize, h: usize) -> MatView {
        let s = self.tokens;
        MatView { offset: h * s, batch: 1, rows, cols: s, strides: [0, self.heads * s, 1] }
    }

    /// Head `h` of `rows` rows of a buffer `width` wide whose first head starts at element
    /// `start` (a column of the first row, or further rows in).
    fn block_head(&self, rows: usize, width: usize, start: usize, h: usize) -> MatView {
        MatView { offset: start + h * self.head_dim(), batch: 1, rows, cols: self.head_dim(), strides: [0, width, 1] }
    }
}

impl FusedEncoderStack {
    pub(crate) fn new(
        layers: Vec<LayerWeights>,
        ends: Option<Ends>,
        num_heads: usize,
        eps: f64,
        isa: Isa,
        keep_activations: bool,
    ) -> Self {
        Self { layers, ends, num_heads, eps, isa, keep_activations, cache: Mutex::new(None) }
    }

    fn lock(&self) -> Result<std::sync::MutexGuard<'_, Option<Saved>>> {
        self.cache.lock().map_err(|_| Error::Msg("fused encoder stack: cache lock poisoned".into()))
    }

    fn dims(&self, d: usize, tokens: usize) -> Result<Dims> {
        let heads = self.num_heads;
        if heads == 0 || d % heads != 0 {
            bail!("fused encoder stack: width {d} does not split into {heads} heads");
        }
        Ok(Dims { tokens, d, heads })
    }

    /// Every layer's weights and the ends as CPU slices (the guards keep the storages readable).
    fn with_params<T: Real, R>(
        &self,
        d: usize,
        f: impl FnOnce(&[Params<T>], Option<&EndSlices<T>>) -> Result<R>,
    ) -> Result<R> {
        let guards: Vec<_> = self.layers.iter().map(|w| w.each().map(|t| t.storage_and_layout())).collect();
        let params = guards.iter().map(|g| Params::<T>::new(g, d)).collect::<Result<Vec<_>>>()?;
        let end_guards = self.ends.as_ref().map(|e| e.each().map(|t| t.storage_and_layout()));
        let ends = end_guards.as_ref().map(|g| EndSlices::<T>::new(g, d, self.isa)).transpose()?;
        f(&params, ends.as_ref())
    }

    /// The DDIM move folded into the pass, if any.
    fn step(&self) -> Option<Epilogue> {
        self.ends.as_ref().and_then(|e| e.step)
    }

    /// Width `d` of the stack (from the first layer's LayerNorm).
    fn width(&self) -> Result<usize> {
        match self.layers.first() {
            Some(w) => Ok(w.norm1_bias.dims1()?),
            None => bail!("fused encoder stack without layers"),
        }
    }

    fn fwd<T: Real>(&self, x_storage: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let (b, rows, cols) = match l.dims() {
            [b, rows, cols] => (*b, *rows, *cols),
            dims => bail!("fused encoder stack expects [batch, tokens, width], got {dims:?}"),
        };
        let x_in = contiguous_slice::<T>(x_storage, l)?;
        let d = self.width()?;
        // With the ends the input is [batch, frames, F] and the stack sees frames + 1 tokens;
        // with a guided move each sample runs as two elements.
        let s = if self.ends.is_some() { rows + 1 } else { rows };
        let dims = self.dims(d, s)?;
        let step = self.step();
        let elements = b * step.map_or(1, |e| e.copies());
        let x = if elements == b { std::borrow::Cow::Borrowed(x_in) } else { x_in.repeat(elements / b).into() };
        let x = &*x;
        let plan = Plan::new(elements);
        let in_width = rows * cols;
        let (y, groups) = self.with_params::<T, _>(d, |params, ends| {
            if ends.is_none() && cols != d {
                bail!("fused encoder stack: input width {cols}, layers {d}");
            }
            if ends.is_some_and(|e| e.feats != cols) {
                bail!("fused denoiser: input has {cols} features per frame");
            }
            let forward = |(first, count): (usize, usize)| -> Result<(Vec<T>, Group)> {
                let mut h = match ends {
                    Some(e) => e.tokens(x, first, count, rows, d, plan.threads())?,
                    None => x[first * in_width..(first + count) * in_width].to_vec(),
                };
                let mut layers = Vec::with_capacity(params.len());
                let mut spare = None;
                for p in params {
                    let (next, activations) = self.layer_fwd(p, dims, &h, count, plan.threads(), spare.take())?;
                    h = next;
                    if self.keep_activations {
                        layers.push(activations.into_cache());
                    } else {
                        spare = Some(activations);
                    }
                }
                let out = match ends {
                    Some(e) => e.project_out(&h, count, rows, d, plan.threads())?,
                    None => h,
                };
                Ok((out, Group { first, count, layers }))
            };
            let outputs: Vec<(Vec<T>, Group)> = match plan {
                Plan::Elements { .. } => {
                    use rayon::prelude::*;
                    plan.groups(elements).into_par_iter().map(forward).collect::<Result<_>>()?
                }
                Plan::Rows { .. } => plan.groups(elements).into_iter().map(forward).collect::<Result<_>>()?,
            };
            let mut y = Vec::with_capacity(elements * in_width);
            let mut groups = Vec::with_capacity(outputs.len());
            for (h, group) in outputs {
                y.extend_from_slice(&h);
                groups.push(group);
            }
            Ok((y, groups))
        })?;
        if self.keep_activations {
            *self.lock()? = Some(Saved { plan, groups });
        }
        let y = match step {
            Some(e) => e.forward(x_in, &y),
            None => y,
        };
        Ok((T::to_cpu_storage_owned(y), l.shape().clone()))
    }

    fn bwd_impl<T: Real>(&self, arg: &Tensor, grad: &Tensor) -> Result<Tensor> {
        let (b, rows, cols) = arg.dims3()?;
        let d = self.width()?;
        let s = if self.ends.is_some() { rows + 1 } else { rows };
        let dims = self.dims(d, s)?;
        let cache = self.lock()?;
        let Some(Saved { plan, groups }) = cache.as_ref() else {
            bail!("fused encoder stack: backward without a forward cache");
        };
        let threads = plan.threads();
        let in_width = rows * cols;
        let grad = grad.contiguous()?;
        let step = self.step();
        let dx = kernels::with_slice::<T, _>(&grad, |g_in| {
            let g_out = step.map(|e| e.out_grad(g_in));
            let g = g_out.as_deref().unwrap_or(g_in);
            let dx = self.with_params::<T, _>(d, |params, ends| {
                let backward = |group: &Group| -> Result<Vec<T>> {
                    let g = &g[group.first * in_width..(group.first + group.count) * in_width];
                    let mut dh = match ends {
                        Some(e) => e.project_out_bwd(g, group.count, rows, d, threads)?,
                        None => g.to_vec(),
                    };
                    for (p, c) in params.iter().zip(&group.layers).rev() {
                        dh = self.layer_bwd(p, dims, c, &dh, group.count, threads)?;
                    }
                    match ends {
                        Some(e) => e.tokens_bwd(&dh, group.count, rows, d, threads),
                        None => Ok(dh),
                    }
                };
                let parts: Vec<Vec<T>> = match plan {
                    Plan::Elements { .. } => {
                        use rayon::prelude::*;
                        groups.par_iter().map(backward).collect::<Result<_>>()?
                    }
                    Plan::Rows { .. } => groups.iter().map(backward).collect::<Result<_>>()?,
                };
                Ok(parts.concat())
            })?;
            Ok(match step {
                Some(e) => e.input_grad(g_in, &dx),
                None => dx,
            })
        })?;
        if dx.len() != b * in_width {
            bail!("fused encoder stack: gradient of {} elements for [{b}, {rows}, {cols}]", dx.len());
        }
        Tensor::from_vec(dx, arg.shape(), arg.device())
    }

    /// One layer's forward over `b` elements in three phases (in parallel when `threads > 1`): the q/k/v projection over row chunks; attention
    /// over blocks of query rows (each against all keys of its element); then the output
    /// projection, both LayerNorms and the feed-forward block over row chunks.
    fn layer_fwd<T: Real>(
        &self,
        p: &Params<T>,
        dims: Dims,
        x: &[T],
        b: usize,
        threads: usize,
        reuse: Option<Activations<T>>,
    ) -> Result<(Vec<T>, Activations<T>)> {
        let (s, d) = (dims.tokens, dims.d);
        let (m, h, ff) = (b * s, dims.heads, p.ff());
        let scale = T::from_f64(1.0 / (dims.head_dim() as f64).sqrt());
        let zero = T::from_f64(0.0);
        let (chunks, blocks) = (row_chunks(m, threads), attention_blocks(b, s, threads));

        let Activations { mut qkv, mut probs, mut ctx, mut xhat1, mut rstd1, mut pre, mut xhat2, mut rstd2 } =
            match reuse {
                Some(a) if a.fits(m, d, b * s * h * s, ff) => a,
                _ => Activations::zeros(m, d, b * s * h * s, ff),
            };
        let tasks: Vec<_> = chunks.iter().copied().zip(split_rows(&mut qkv, 3 * d, chunks.iter().copied())).collect();
        run(threads, tasks, |(r, out)| {
            linear_rows(self.isa, out, rows_of(x, d, r), r.len, d, Weight::InOut(p.in_wt), Some(p.in_b))
        })?;

        let rows = blocks.iter().map(|blk| blk.rows);
        let tasks: Vec<_> =
            blocks.iter().zip(split_rows(&mut probs, h * s, rows.clone())).zip(split_rows(&mut ctx, d, rows)).collect();
        let qkv_ref = &qkv;
        run(threads, tasks, |((blk, probs), ctx)| {
            let n = blk.rows.len;
            for hh in 0..h {
                let q = MatView {
                    offset: blk.rows.first * 3 * d + hh * dims.head_dim(),
                    rows: n,
                    ..dims.qkv_head(0, 0, hh)
                };
                let k_t = dims.qkv_head(blk.batch, 1, hh).t();
                kernels::gemm_into(self.isa, probs, dims.block_prob_head(n, hh), qkv_ref, q, qkv_ref, k_t, false)?;
            }
            kernels::softmax_fwd(self.isa, probs, s, scale);
            for hh in 0..h {
                let v = dims.qkv_head(blk.batch, 2, hh);
                kernels::gemm_into(
                    self.isa,
                    ctx,
                    dims.block_head(n, d, 0, hh),
                    probs,
                    dims.block_prob_head(n, hh),
                    qkv_ref,
                    v,
                    false,
                )?;
            }
            Ok(())
        })?;

        let mut y = vec![zero; m * d];
        let cs = || chunks.iter().copied();
        let tasks: Vec<_> = cs()
            .zip(split_rows(&mut y, d, cs()))
            .zip(split_rows(&mut xhat1, d, cs()).into_iter().zip(split_rows(&mut rstd1, 1, cs())))
            .zip(split_rows(&mut pre, ff, cs()))
            .zip(split_rows(&mut xhat2, d, cs()).into_iter().zip(split_rows(&mut rstd2, 1, cs())))
            .collect();
        let ctx_ref = &ctx;
        run(threads, tasks, |((((r, y), (xhat1, rstd1)), pre), (xhat2, rstd2))| {
            let n = r.len;
            // r1 = x + ctx·W_outᵀ + b_out, h1 = LN1(r1).
            let mut r1: Vec<T> =
                rows_of(x, d, r).iter().zip(p.out_b.iter().cycle()).map(|(&xv, &bv)| xv + bv).collect();
            linear_rows(self.isa, &mut r1, rows_of(ctx_ref, d, r), n, d, Weight::InOut(p.out_wt), None)?;
            let mut h1 = vec![zero; n * d];
            kernels::layer_norm_fwd(self.isa, &r1, p.n1_w, p.n1_b, self.eps, &mut h1, Some((xhat1, rstd1)));
            // r2 = h1 + GELU(h1·W1ᵀ + b1)·W2ᵀ + b2, y = LN2(r2).
            linear_rows(self.isa, pre, &h1, n, d, Weight::InOut(p.l1_wt), Some(p.l1_b))?;
            let mut act = vec![zero; n * ff];
            kernels::gelu_fwd(self.isa, pre, &mut act);
            let mut r2 = r1;
            for ((r, &hv), &bv) in r2.iter_mut().zip(&h1).zip(p.l2_b.iter().cycle()) {
                *r = hv + bv;
            }
            linear_rows(self.isa, &mut r2, &act, n, ff, Weight::InOut(p.l2_wt), None)?;
            kernels::layer_norm_fwd(self.isa, &r2, p.n2_w, p.n2_b, self.eps, y, Some((xhat2, rstd2)));
            Ok(())
        })?;

        Ok((y, Activations { qkv, probs, ctx, xhat1, rstd1, pre, xhat2, rstd2 }))
    }

    /// One layer's input gradient over `b` elements in four phases (in parallel when
    /// `threads > 1`): the row-local chain from the output back to
    /// `dO = dr1·W_out` over row chunks; per block of query rows `dS = softmax'(dO·Vᵀ)` and
    /// `dQ = dS·K`; per block of key rows `dK = dSᵀ·Q` and `dV = Pᵀ·dO` (sums over every
    /// query row of the element); then `dx = dqkv·W_in + dr1` over row chunks.
    fn layer_bwd<T: Real>(
        &self,
        p: &Params<T>,
        dims: Dims,
        c: &Cache,
        g: &[T],
        b: usize,
        threads: usize,
    ) -> Result<Vec<T>> {
        let (s, d) = (dims.tokens, dims.d);
        let (m, h, ff) = (b * s, dims.heads, p.ff());
        let scale = T::from_f64(1.0 / (dims.head_dim() as f64).sqrt());
        let zero = T::from_f64(0.0);
        let (chunks, blocks) = (row_chunks(m, threads), attention_blocks(b, s, threads));
        let qkv = T::cpu_storage_as_slice(&c.qkv)?;
        let probs = T::cpu_storage_as_slice(&c.probs)?;
        let (xhat1, rstd1) = (T::cpu_storage_as_slice(&c.xhat1)?, T::cpu_storage_as_slice(&c.rstd1)?);
        let (xhat2, rstd2) = (T::cpu_storage_as_slice(&c.xhat2)?, T::cpu_storage_as_slice(&c.rstd2)?);
        let pre = T::cpu_storage_as_slice(&c.pre_gelu)?;

        // Second LayerNorm, the feed-forward block, the first LayerNorm and W_out.
        let mut dr1 = vec![zero; m * d];
        let mut dctx = vec![zero; m * d];
        let cs = || chunks.iter().copied();
        {
            let tasks: Vec<_> = cs().zip(split_rows(&mut dr1, d, cs())).zip(split_rows(&mut dctx, d, cs())).collect();
            run(threads, tasks, |((r, dr1), dctx)| {
                let n = r.len;
                let mut dr2 = rows_of(g, d, r).to_vec();
                kernels::layer_norm_bwd(self.isa, &mut dr2, rows_of(xhat2, d, r), rows_of(rstd2, 1, r), p.n2_w);
                let mut dact = vec![zero; n * ff];
                linear_rows_bwd(self.isa, &mut dact, &dr2, n, p.l2_w, ff, false)?;
                kernels::gelu_bwd(self.isa, rows_of(pre, ff, r), &mut dact);
                dr1.copy_from_slice(&dr2);
                linear_rows_bwd(self.isa, dr1, &dact, n, p.l1_w, d, true)?;
                kernels::layer_norm_bwd(self.isa, dr1, rows_of(xhat1, d, r), rows_of(rstd1, 1, r), p.n1_w);
                linear_rows_bwd(self.isa, dctx, dr1, n, p.out_w, d, false)
            })?;
        }

        // Per block of query rows: dP = dO·Vᵀ, dS = softmax'(dP), dQ = dS·K.
        let mut ds = vec![zero; b * s * h * s];
        let mut dqkv = vec![zero; m * 3 * d];
        let rows = || blocks.iter().map(|blk| blk.rows);
        let tasks: Vec<_> =
            blocks.iter().zip(split_rows(&mut ds, h * s, rows())).zip(split_rows(&mut dqkv, 3 * d, rows())).collect();
        let dctx = &dctx;
        run(threads, tasks, |((blk, ds), dqkv)| {
            let n = blk.rows.len;
            let d_out = rows_of(dctx, d, blk.rows);
            for hh in 0..h {
                let v_t = dims.qkv_head(blk.batch, 2, hh).t();
                kernels::gemm_into(
                    self.isa,
                    ds,
                    dims.block_prob_head(n, hh),
                    d_out,
                    dims.block_head(n, d, 0, hh),
                    qkv,
                    v_t,
                    false,
                )?;
            }
            kernels::softmax_bwd(self.isa, rows_of(probs, h * s, blk.rows), ds, s, scale);
            for hh in 0..h {
                let k = dims.qkv_head(blk.batch, 1, hh);
                kernels::gemm_into(
                    self.isa,
                    dqkv,
                    dims.block_head(n, 3 * d, 0, hh),
                    ds,
                    dims.block_prob_head(n, hh),
                    qkv,
                    k,
                    false,
                )?;
            }
            Ok(())
        })?;

        // Per block of key rows: dK = dSᵀ·Q, dV = Pᵀ·dO over all query rows of the element.
        let ds = &ds;
        let tasks: Vec<_> = blocks.iter().zip(split_rows(&mut dqkv, 3 * d, rows())).collect();
        run(threads, tasks, |(blk, dqkv)| {
            let n = blk.rows.len;
            for hh in 0..h {
                // The block's key rows of the transposed [query, key] matrices.
                let key_rows = |v: MatView| MatView { offset: v.offset + blk.start, rows: n, ..v.t() };
                let prob_t = key_rows(dims.prob_head(blk.batch, hh));
                let q = dims.qkv_head(blk.batch, 0, hh);
                kernels::gemm_into(self.isa, dqkv, dims.block_head(n, 3 * d, d, hh), ds, prob_t, qkv, q, false)?;
                let d_out = dims.block_head(s, d, blk.batch * s * d, hh);
                kernels::gemm_into(
                    self.isa,
                    dqkv,
                    dims.block_head(n, 3 * d, 2 * d, hh),
                    probs,
                    prob_t,
                    dctx,
                    d_out,
                    false,
                )?;
            }
            Ok(())
        })?;

        // dx = dqkv·W_in + dr1.
        let mut dx = dr1;
        let (dqkv, tasks): (&[T], Vec<_>) = (&dqkv, cs().zip(split_rows(&mut dx, d, cs())).collect());
        run(threads, tasks, |(r, dx)| linear_rows_bwd(self.isa, dx, rows_of(dqkv, 3 * d, r), r.len, p.in_w, d, true))?;
        Ok(dx)
    }
}

impl CustomOp1 for FusedEncoderStack {
    fn name(&self) -> &'static str {
        "motion-fused-encoder-stack"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        dispatch_real!(s.dtype(), T => self.fwd::<T>(s, l))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        dispatch_real!(arg.dtype(), T => Ok(Some(self.bwd_impl::<T>(arg, grad)?)))
    }
}
