//! CPU kernels shared by the custom ops and the fused encoder layer: plain loops over
//! contiguous rows of f32/f64 compiled for the selected instruction set ([`Isa`]), and the
//! linear layers' products through [`gemm_into`] (`super::matmul`), on row blocks the caller
//! runs in parallel.

use candle_core::{bail, CpuStorage, Layout, Result, Storage, Tensor, WithDType};

use super::isa::Isa;
pub(crate) use super::matmul::{gemm_into, MatView};

/// The float types the custom ops run on: f32 for work, f64 for gradient tests.
pub(crate) trait Real: WithDType + super::matmul::Avx2Gemm {
    fn exp(self) -> Self;
    fn sqrt(self) -> Self;
    fn erf(self) -> Self;
    fn fmax(self, other: Self) -> Self;
}

impl Real for f32 {
    #[inline(always)]
    fn exp(self) -> Self {
        exp_f32(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn erf(self) -> Self {
        erf_f32(self)
    }
    #[inline(always)]
    fn fmax(self, other: Self) -> Self {
        if self > other {
            self
        } else {
            other
        }
    }
}

impl Real for f64 {
    #[inline(always)]
    fn exp(self) -> Self {
        f64::exp(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn erf(self) -> Self {
        candle_core::cpu::erf::erf_f64(self)
    }
    #[inline(always)]
    fn fmax(self, other: Self) -> Self {
        if self > other {
            self
        } else {
            other
        }
    }
}

/// Branch-free `e^x` for f32 (Cephes `expf`: range reduction by ln 2 and a degree-6
/// polynomial; relative error < 1e-7 on [−87, 88], inputs clamped to that range). Unlike
/// libm's `expf` it inlines and vectorises inside the row loops.
#[inline(always)]
pub(crate) fn exp_f32(x: f32) -> f32 {
    // 1.5·2^23: adding and subtracting it rounds to the nearest integer without SSE4.1.
    const ROUND: f32 = 12_582_912.0;
    let x = x.clamp(-87.3, 88.7);
    let n = (x * std::f32::consts::LOG2_E + ROUND) - ROUND;
    let r = x - n * 0.693_359_4 - n * -2.121_944_4e-4;
    let mut p = 1.987_569_1e-4_f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 0.166_666_65;
    p = p * r + 0.5;
    let poly = p * r * r + r + 1.0;
    // 2^n from the exponent bits: n + 127 sits in the low mantissa bits of 2^23 + n + 127
    // (an integer cast would saturate lane by lane and stop vectorisation).
    let biased = (n + (127.0 + 8_388_608.0)).to_bits() - 0x4B00_0000;
    poly * f32::from_bits(biased << 23)
}

/// Branch-free `erf(x)` for f32: the odd/even rational approximation on [−4, 4] used by
/// Eigen and XLA (beyond ±4, erf is ±1 in f32). Absolute error ≤ 5e-7 evaluated in f32
/// (6.5e-8 in exact arithmetic); vectorises, unlike libm's `erff`.
#[inline(always)]
pub(crate) fn erf_f32(x: f32) -> f32 {
    let x = x.clamp(-4.0, 4.0);
    let x2 = x * x;
    let mut p = -2.726_142_3e-10_f32;
    p = p * x2 + 2.770_681_4e-8;
    p = p * x2 + -2.101_024e-6;
    p = p * x2 + -5.692_506_3e-5;
    p = p * x2 + -7.349_906_3e-4;
    p = p * x2 + -2.954_600_6e-3;
    p = p * x2 + -1.609_603_3e-2;
    let mut q = -1.456_607_2e-5_f32;
    q = q * x2 + -2.133_740_6e-4;
    q = q * x2 + -1.682_827e-3;
    q = q * x2 + -7.373_329_3e-3;
    q = q * x2 + -1.426_473_9e-2;
    x * p / q
}

/// `Σ f(x_i)` with eight independent accumulators (vectorisable; no serial dependency).
#[inline(always)]
fn sum_map<T: Real>(x: &[T], f: impl Fn(T) -> T) -> T {
    let zero = T::from_f64(0.0);
    let mut acc = [zero; 8];
    let chunks = x.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for i in 0..8 {
            acc[i] += f(c[i]);
        }
    }
    let mut total = rest.iter().fold(zero, |s, &v| s + f(v));
    for a in acc {
        total += a;
    }
    total
}

/// `Σ a_i·b_i·c_i`-style reductions over two slices, eight accumulators.
#[inline(always)]
fn sum_zip<T: Real>(a: &[T], b: &[T], f: impl Fn(T, T) -> T) -> T {
    let zero = T::from_f64(0.0);
    let mut acc = [zero; 8];
    let n = a.len().min(b.len());
    let full = n / 8 * 8;
    for (ca, cb) in a[..full].chunks_exact(8).zip(b[..full].chunks_exact(8)) {
        for i in 0..8 {
            acc[i] += f(ca[i], cb[i]);
        }
    }
    let mut total = a[full..n].iter().zip(&b[full..n]).fold(zero, |s, (&x, &y)| s + f(x, y));
    for v in acc {
        total += v;
    }
    total
}

/// Maximum of a non-empty row, eight lanes.
#[inline(always)]
fn max_of<T: Real>(x: &[T]) -> T {
    let mut acc = [x[0]; 8];
    let chunks = x.chunks_exact(8);
    let rest = chunks.remainder();
    for c in chunks {
        for i in 0..8 {
            acc[i] = c[i].fmax(acc[i]);
        }
    }
    let m = rest.iter().fold(x[0], |m, &v| v.fmax(m));
    acc.iter().fold(m, |m, &v| v.fmax(m))
}

/// Runs `$body` with `$t` bound to the Rust float type of a [`candle_core::DType`] (f32 or f64).
macro_rules! dispatch_real {
    ($dtype:expr, $t:ident => $body:expr) => {
        match $dtype {
            candle_core::DType::F32 => {
                type $t = f32;
                $body
            }
            candle_core::DType::F64 => {
                type $t = f64;
                $body
            }
            other => candle_core::bail!("custom op supports f32 and f64 only, got {other:?}"),
        }
    };
}
pub(crate) use dispatch_real;

/// The elements a contiguous layout covers.
pub(crate) fn contiguous_slice<'a, T: WithDType>(s: &'a CpuStorage, l: &Layout) -> Result<&'a [T]> {
    let data = T::cpu_storage_as_slice(s)?;
    match l.contiguous_offsets() {
        Some((start, end)) => Ok(&data[start..end]),
        None => bail!("custom op needs a contiguous input, got strides {:?}", l.stride()),
    }
}

/// Calls `f` with the contiguous CPU data of `t` (which must be contiguous and on the CPU).
pub(crate) fn with_slice<T: WithDType, R>(t: &Tensor, f: impl FnOnce(&[T]) -> Result<R>) -> Result<R> {
    let (storage, layout) = t.storage_and_layout();
    match &*storage {
        Storage::Cpu(cs) => f(contiguous_slice(cs, layout)?),
        _ => bail!("custom op: tensor is not on the CPU (only a CPU kernel is implemented)"),
    }
}

/// A range of rows of a row-major buffer.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rows {
    pub first: usize,
    pub len: usize,
}

/// Splits `m` rows into `parts` contiguous ranges (fewer when there are fewer rows).
pub(crate) fn row_chunks(m: usize, parts: usize) -> Vec<Rows> {
    let chunks = parts.clamp(1, m.max(1));
    (0..chunks).map(|i| Rows { first: i * m / chunks, len: (i + 1) * m / chunks - i * m / chunks }).collect()
}

/// Cuts a row-major buffer of `width` columns into consecutive row ranges from its start.
pub(crate) fn split_rows<T>(mut buf: &mut [T], width: usize, ranges: impl IntoIterator<Item = Rows>) -> Vec<&mut [T]> {
    ranges
        .into_iter()
        .map(|r| {
            let mid = (r.len * width).min(buf.len());
            let (head, tail) = std::mem::take(&mut buf).split_at_mut(mid);
            buf = tail;
            head
        })
        .collect()
}

/// The rows of `r` in a row-major buffer of `width` columns.
pub(crate) fn rows_of<T>(buf: &[T], width: usize, r: Rows) -> &[T] {
    &buf[r.first * width..(r.first + r.len) * width]
}

/// Runs `f` on every item on the current rayon pool, returning the first error.
pub(crate) fn par_each<I: Send>(items: Vec<I>, f: impl Fn(I) -> Result<()> + Sync + Send) -> Result<()> {
    use rayon::prelude::*;
    items.into_par_iter().try_for_each(f)
}

/// How a linear layer's weight `W` (`y = x·Wᵀ`, `in = k` inputs, `out = n` outputs) lies in
/// memory.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Weight<'a, T> {
    /// Row-major `[n, k]`, PyTorch's `nn.Linear` layout, read transposed in place (the product
    /// then gathers `W`'s columns into gemm's packed layout on every call).
    OutIn(&'a [T]),
    /// Row-major `[k, n]`: `Wᵀ` stored contiguously (a frozen weight transposed once), which
    /// the product reads as it lies.
    InOut(&'a [T]),
}

impl<T> Weight<'_, T> {
    /// `Wᵀ [k, n]` as a view into the slice, and the slice.
    fn transposed_view(&self, k: usize) -> (&[T], MatView) {
        match *self {
            Weight::OutIn(w) => (w, MatView::contiguous(0, 1, w.len() / k.max(1), k).t()),
            Weight::InOut(w) => (w, MatView::contiguous(0, 1, k, w.len() / k.max(1))),
        }
    }
}

/// `dst [rows, n] = x [rows, k] · Wᵀ + bias` (bias broadcast over rows, or `dst` kept and
/// accumulated when `bias` is `None`).
pub(crate) fn linear_rows<T: Real>(
    isa: Isa,
    dst: &mut [T],
    x: &[T],
    rows: usize,
    k: usize,
    w: Weight<'_, T>,
    bias: Option<&[T]>,
) -> Result<()> {
    let (w, wt) = w.transposed_view(k);
    let n = wt.cols;
    if let Some(bias) = bias {
        for row in dst.chunks_exact_mut(n) {
            row.copy_from_slice(bias);
        }
    }
    gemm_into(isa, dst, MatView::contiguous(0, 1, rows, n), x, MatView::contiguous(0, 1, rows, k), w, wt, true)
}

/// `dst [rows, k] (+)= g [rows, n] · W` for a row-major `W [n, k]` (the input gradient of
/// `x·Wᵀ`).
pub(crate) fn linear_rows_bwd<T: Real>(
    isa: Isa,
    dst: &mut [T],
    g: &[T],
    rows: usize,
    w: &[T],
    k: usize,
    accumulate: bool,
) -> Result<()> {
    let n = w.len() / k.max(1);
    gemm_into(
        isa,
        dst,
        MatView::contiguous(0, 1, rows, k),
        g,
        MatView::contiguous(0, 1, rows, n),
        w,
        MatView::contiguous(0, 1, n, k),
        accumulate,
    )
}

/// `y = x·Wᵀ (+ b)` for `x` given as a strided view `[batch, m, k]` whose rows are
/// contiguous and `W` as a row-major `[n, k]` (PyTorch's Linear layout, read transposed in
/// place). Returns contiguous `[batch·m, n]`, computed in parallel row chunks.
pub(crate) fn linear<T: Real>(isa: Isa, x: &[T], xv: MatView, w: &[T], n: usize, bias: Option<&[T]>) -> Result<Vec<T>> {
    let k = xv.cols;
    if w.len() != n * k || xv.strides[2] != 1 || xv.strides[1] != k {
        bail!("linear: weight of {} elements for [{n}, {k}], or input rows not contiguous: {xv:?}", w.len());
    }
    if bias.is_some_and(|b| b.len() != n) {
        bail!("linear bias does not have {n} entries");
    }
    let m = xv.rows;
    let mut y = vec![T::from_f64(0.0); xv.batch * m * n];
    let tasks: Vec<_> = (0..xv.batch)
        .flat_map(|b| row_chunks(m, rayon::current_num_threads()).into_iter().map(move |r| (b, r)))
        .zip(split_rows(&mut y, n, (0..xv.batch).flat_map(|_| row_chunks(m, rayon::current_num_threads()))))
        .collect();
    par_each(tasks, |((b, r), out)| {
        let first = xv.offset + b * xv.strides[0] + r.first * k;
        let Some(rows) = x.get(first..first + r.len * k) else {
            bail!("linear: input view {xv:?} reaches past its {} elements", x.len());
        };
        linear_rows(isa, out, rows, r.len, k, Weight::OutIn(w), bias)
    })?;
    Ok(y)
}

/// `dx [m, k] = g [m, n] · W` for contiguous `g` and a row-major `W [n, k]` (the input
/// gradient of [`linear`]), in parallel row chunks.
pub(crate) fn linear_bwd<T: Real>(isa: Isa, g: &[T], w: &[T], n: usize, k: usize) -> Result<Vec<T>> {
    if w.len() != n * k || g.len() % n.max(1) != 0 {
        bail!("linear backward: weight of {} elements for [{n}, {k}], gradient of {}", w.len(), g.len());
    }
    let m = g.len() / n.max(1);
    let mut dx = vec![T::from_f64(0.0); m * k];
    let tasks: Vec<_> = row_chunks(m, rayon::current_num_threads())
        .into_iter()
        .zip(split_rows(&mut dx, k, row_chunks(m, rayon::current_num_threads())))
        .collect();
    par_each(tasks, |(r, out)| linear_rows_bwd(isa, out, rows_of(g, n, r), r.len, w, k, false))?;
    Ok(dx)
}

/// LayerNorm forward over rows of length `gamma.len()`:
/// `xhat = (x − mean)/sqrt(var + eps)`, `y = xhat·gamma + beta` (biased variance, as PyTorch).
/// Optionally keeps `xhat` and `1/sqrt(var + eps)` per row for the backward pass.
pub(crate) fn layer_norm_fwd<T: Real>(
    isa: Isa,
    x: &[T],
    gamma: &[T],
    beta: &[T],
    eps: f64,
    y: &mut [T],
    mut cache: Option<(&mut [T], &mut [T])>,
) {
    let d = gamma.len();
    let inv_d = T::from_f64(1.0 / d as f64);
    let eps = T::from_f64(eps);
    isa.vectorize(
        #[inline(always)]
        || {
            for (r, (xr, yr)) in x.chunks_exact(d).zip(y.chunks_exact_mut(d)).enumerate() {
                let mean = sum_map(xr, |v| v) * inv_d;
                let var = sum_map(xr, |v| (v - mean) * (v - mean)) * inv_d;
                let rstd = T::from_f64(1.0) / (var + eps).sqrt();
                match cache.as_mut() {
                    Some((xhat, rstds)) => {
                        let xh = &mut xhat[r * d..(r + 1) * d];
                        for i in 0..d {
                            xh[i] = (xr[i] - mean) * rstd;
                            yr[i] = xh[i] * gamma[i] + beta[i];
                        }
                        rstds[r] = rstd;
                    }
                    None => {
                        for i in 0..d {
                            yr[i] = (xr[i] - mean) * rstd * gamma[i] + beta[i];
                        }
                    }
                }
            }
        },
    )
}

/// LayerNorm input gradient (gamma, beta frozen), in place on `g`:
/// `dx = rstd·(g·γ − mean(g·γ) − xhat·mean(g·γ·xhat))`.
pub(crate) fn layer_norm_bwd<T: Real>(isa: Isa, g: &mut [T], xhat: &[T], rstd: &[T], gamma: &[T]) {
    let d = gamma.len();
    let inv_d = T::from_f64(1.0 / d as f64);
    isa.vectorize(
        #[inline(always)]
        || {
            for ((gr, xr), &rs) in g.chunks_exact_mut(d).zip(xhat.chunks_exact(d)).zip(rstd) {
                for i in 0..d {
                    gr[i] *= gamma[i];
                }
                let s1 = sum_map(gr, |v| v) * inv_d;
                let s2 = sum_zip(gr, xr, |a, b| a * b) * inv_d;
                for i in 0..d {
                    gr[i] = rs * (gr[i] - s1 - xr[i] * s2);
                }
            }
        },
    )
}

/// Probabilities and Gaussian densities below this are stored as exact zeros.
///
/// Sharp attention at low noise levels leaves many of a row's softmax probabilities near
/// `e^-87`; scaled, and multiplied by gradients, they become subnormal floats, which x86 cores
/// handle about a hundred times slower than normal ones (microcode assists). With them the
/// backward through the lowest-noise passes of a DNO step took up to 3.6 times as long as
/// through the others, and the whole step (batch 2) 1.45 times as long. A term this small
/// changes no output: a row's probabilities sum to 1, so f32 rounding of any weighted sum is
/// already about 1e-7 of its largest term.
const FLUSH_BELOW: f64 = 1e-12;

/// `v`, or exactly zero when it is below [`FLUSH_BELOW`] (for non-negative `v`).
#[inline(always)]
fn flush_tiny<T: Real>(v: T) -> T {
    if v < T::from_f64(FLUSH_BELOW) {
        T::from_f64(0.0)
    } else {
        v
    }
}

/// Softmax of `scale·x` over rows of length `d`, in place; probabilities below
/// [`FLUSH_BELOW`] are exact zeros.
pub(crate) fn softmax_fwd<T: Real>(isa: Isa, x: &mut [T], d: usize, scale: T) {
    isa.vectorize(
        #[inline(always)]
        || {
            for row in x.chunks_exact_mut(d) {
                let mx = max_of(row);
                for v in row.iter_mut() {
                    *v = ((*v - mx) * scale).exp();
                }
                let inv = T::from_f64(1.0) / sum_map(row, |v| v);
                for v in row.iter_mut() {
                    *v = flush_tiny(*v * inv);
                }
            }
        },
    )
}

/// Gradient through `y = softmax(scale·x)`, in place on `g`: `dx = scale·y·(g − Σ g·y)`.
pub(crate) fn softmax_bwd<T: Real>(isa: Isa, y: &[T], g: &mut [T], d: usize, scale: T) {
    isa.vectorize(
        #[inline(always)]
        || {
            for (yr, gr) in y.chunks_exact(d).zip(g.chunks_exact_mut(d)) {
                let dot = sum_zip(yr, gr, |a, b| a * b);
                for (gv, &yv) in gr.iter_mut().zip(yr) {
                    *gv = scale * yv * (*gv - dot);
                }
            }
        },
    )
}

/// Exact GELU, `0.5·x·(1 + erf(x/√2))`.
pub(crate) fn gelu_fwd<T: Real>(isa: Isa, x: &[T], y: &mut [T]) {
    let half = T::from_f64(0.5);
    let one = T::from_f64(1.0);
    let inv_sqrt2 = T::from_f64(std::f64::consts::FRAC_1_SQRT_2);
    isa.vectorize(
        #[inline(always)]
        || {
            for (o, &v) in y.iter_mut().zip(x) {
                *o = half * v * (one + (v * inv_sqrt2).erf());
            }
        },
    )
}

/// GELU gradient in place on `g`: `dx = g·(Φ(x) + x·φ(x))`, with `φ(x)` below
/// [`FLUSH_BELOW`] taken as zero (`|x|` > 7.3, where `x·φ(x)` < 1e-11).
pub(crate) fn gelu_bwd<T: Real>(isa: Isa, x: &[T], g: &mut [T]) {
    let half = T::from_f64(0.5);
    let one = T::from_f64(1.0);
    let inv_sqrt2 = T::from_f64(std::f64::consts::FRAC_1_SQRT_2);
    let neg_half = T::from_f64(-0.5);
    let inv_sqrt_2pi = T::from_f64(0.5 * std::f64::consts::FRAC_2_SQRT_PI * std::f64::consts::FRAC_1_SQRT_2);
    isa.vectorize(
        #[inline(always)]
        || {
            for (gv, &v) in g.iter_mut().zip(x) {
                let cdf = half * (one + (v * inv_sqrt2).erf());
                let pdf = flush_tiny(inv_sqrt_2pi * (neg_half * v * v).exp());
                *gv *= cdf + v * pdf;
            }
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn softmax_leaves_no_subnormal_probabilities() {
        // Scores 0, −1, …, −99 at scale 1: e^-k underflows past f32's normal range for k > 87.
        let mut row: Vec<f32> = (0..100).map(|k| -(k as f32)).collect();
        softmax_fwd(Isa::best(), &mut row, 100, 1.0);
        assert!(row.iter().all(|p| *p == 0.0 || p.is_normal()), "subnormal probability in {row:?}");
        assert!(row[..28].iter().all(|p| *p > 0.0), "a probability above 1e-12 was dropped");
        assert!(row[28..].iter().all(|p| *p == 0.0), "probabilities below 1e-12 are kept");
        assert!((row.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        let mut g = vec![1e-3f32; 100];
        softmax_bwd(Isa::best(), &row, &mut g, 100, 1.0);
        assert!(g.iter().all(|v| *v == 0.0 || v.is_normal()), "subnormal gradient in {g:?}");
    }

    #[test]
    fn fast_exp_and_erf_are_accurate() {
        let mut worst_exp: f64 = 0.0;
        let mut worst_erf: f64 = 0.0;
        for i in 0..=200_000 {
            let x = -87.0 + 175.0 * i as f64 / 200_000.0;
            let e = exp_f32(x as f32) as f64;
            worst_exp = worst_exp.max((e - (x as f32 as f64).exp()).abs() / (x as f32 as f64).exp());
            let x = -6.0 + 12.0 * i as f64 / 200_000.0;
            let xf = x as f32;
            worst_erf = worst_erf.max((erf_f32(xf) as f64 - candle_core::cpu::erf::erf_f64(xf as f64)).abs());
        }
        assert!(worst_exp < 2e-7, "exp relative error {worst_exp}");
        assert!(worst_erf < 5e-7, "erf absolute error {worst_erf}");
        assert_eq!(exp_f32(-1000.0), exp_f32(-87.3));
        assert_eq!(erf_f32(10.0), erf_f32(4.0));
    }

    /// The row loops compiled for AVX2/FMA against the same loops for the CPU's best set and
    /// against f64: LayerNorm, softmax and GELU, forward and backward, on rows of 128 and 101
    /// (a denoiser's width and its attention rows), to 1e-5.
    #[test]
    fn avx2_row_loops_match_the_reference() {
        let fill = |n: usize, seed: usize| -> Vec<f32> {
            (0..n).map(|i| ((i * 7919 + seed * 104_729) % 1000) as f32 / 250.0 - 2.0).collect()
        };
        let close = |name: &str, a: &[f32], b: &[f32]| {
            let scale = b.iter().fold(1.0f32, |m, v| m.max(v.abs()));
            let err = a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
            assert!(err <= 1e-5 * scale, "{name}: error {err:e} of {scale}");
        };
        let run = |isa: Isa| -> Vec<Vec<f32>> {
            let (d, rows) = (128, 5);
            let (x, gamma, beta, g) = (fill(rows * d, 1), fill(d, 2), fill(d, 3), fill(rows * d, 4));
            let (mut y, mut xhat, mut rstd) = (vec![0f32; rows * d], vec![0f32; rows * d], vec![0f32; rows]);
            layer_norm_fwd(isa, &x, &gamma, &beta, 1e-5, &mut y, Some((&mut xhat, &mut rstd)));
            let mut dx = g.clone();
            layer_norm_bwd(isa, &mut dx, &xhat, &rstd, &gamma);
            let mut p = fill(3 * 101, 5);
            softmax_fwd(isa, &mut p, 101, 0.7);
            let mut dp = fill(3 * 101, 6);
            softmax_bwd(isa, &p, &mut dp, 101, 0.7);
            let mut act = vec![0f32; rows * d];
            gelu_fwd(isa, &x, &mut act);
            let mut dact = g;
            gelu_bwd(isa, &x, &mut dact);
            vec![y, dx, p, dp, act, dact]
        };
        let names = ["LayerNorm", "LayerNorm backward", "softmax", "softmax backward", "GELU", "GELU backward"];
        let (avx2, best) = (run(Isa::Avx2), run(Isa::best()));
        for ((name, a), b) in names.iter().zip(&avx2).zip(&best) {
            close(name, a, b);
        }
        // GELU and softmax against f64 (the others are checked by the layers' own tests).
        let x = fill(5 * 128, 1);
        let gelu: Vec<f32> = x
            .iter()
            .map(|&v| (0.5 * v as f64 * (1.0 + candle_core::cpu::erf::erf_f64(v as f64 / 2f64.sqrt()))) as f32)
            .collect();
        close("GELU against f64", &avx2[4], &gelu);
        let mut soft = Vec::new();
        for row in fill(3 * 101, 5).chunks(101) {
            let m = row.iter().fold(f64::MIN, |m, &v| m.max(0.7 * v as f64));
            let e: Vec<f64> = row.iter().map(|&v| (0.7 * v as f64 - m).exp()).collect();
            let sum: f64 = e.iter().sum();
            soft.extend(e.iter().map(|v| (v / sum) as f32));
        }
        close("softmax against f64", &avx2[2], &soft);
    }
}
