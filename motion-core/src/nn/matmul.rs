//! Matrix products on one thread through the `gemm` crate, for the kernels that split their
//! rows over the rayon pool themselves ([`gemm_into`]): the one place in this crate with
//! `unsafe`, a bounds-checked call of `gemm`.
//!
//! Under [`Isa::Avx2`] the product runs gemm's own AVX2/FMA microkernels (the ones `gemm::gemm`
//! picks on a CPU without AVX-512), called directly, so that a CPU with AVX-512 runs the same
//! code as one without; otherwise `gemm::gemm` picks the microkernels for this CPU.

use candle_core::{bail, Result, WithDType};

use super::isa::{avx2_fma, Isa};

/// A strided view of `batch` matrices `[rows, cols]` inside a flat buffer.
#[derive(Debug, Clone, Copy)]
pub(crate) struct MatView {
    pub offset: usize,
    pub batch: usize,
    pub rows: usize,
    pub cols: usize,
    /// Element strides of (batch, row, column).
    pub strides: [usize; 3],
}

impl MatView {
    /// `batch` row-major contiguous `[rows, cols]` matrices starting at `offset`.
    pub fn contiguous(offset: usize, batch: usize, rows: usize, cols: usize) -> Self {
        Self { offset, batch, rows, cols, strides: [rows * cols, cols, 1] }
    }

    /// The transpose of this view (no data moves).
    pub fn t(self) -> Self {
        Self { rows: self.cols, cols: self.rows, strides: [self.strides[0], self.strides[2], self.strides[1]], ..self }
    }

    /// One past the last element the view touches.
    fn end(&self) -> usize {
        if self.batch == 0 || self.rows == 0 || self.cols == 0 {
            return self.offset;
        }
        self.offset
            + (self.batch - 1) * self.strides[0]
            + (self.rows - 1) * self.strides[1]
            + (self.cols - 1) * self.strides[2]
            + 1
    }
}

/// gemm copies a product's left operand (its vector axis; our `B`, since gemm transposes
/// row-major products) into a packed layout when the product has more than this many × 6
/// columns (gemm's default: 8). Our operands are small, and a layer's weight stays in L2
/// between calls, so for operands already contiguous along that axis (the transposed weights,
/// the input gradient's weights) packing costs more than it saves: products of 51–202 rows of
/// the denoiser's shapes ran 5–30 % faster unpacked on one core (a standalone probe), and a
/// Task-1 DNO sample 0.6–0.8 s faster, with the same values (packing moves data, it does not
/// reorder sums). Operands strided along that axis, or whose length along it is not a multiple
/// of 16, are still packed. 256 is the largest value gemm takes.
const LHS_PACKING_THRESHOLD: usize = 256;

/// Applies [`LHS_PACKING_THRESHOLD`] once per process. The setting is gemm's global, so it also
/// holds for candle's single-threaded (small) products.
static LHS_PACKING: std::sync::Once = std::sync::Once::new();

/// `C = A·B`, or `C += A·B` when `accumulate`, for single matrices (`batch` 1) held in
/// slices, with `C` written through the strided view `cv` of `dst`, on the microkernels of
/// `isa`. The product runs on the calling thread only (the `gemm` crate without its own
/// threading): the fused layer splits its rows into blocks and runs the blocks on the rayon
/// pool, which keeps both cores busy where one small product per thread pair cost more than it
/// saved.
///
/// Errors when the shapes disagree or a view reaches past its slice; then nothing is
/// written.
#[allow(clippy::too_many_arguments)] // three operands, each a slice and its view
pub(crate) fn gemm_into<T: WithDType + Avx2Gemm>(
    isa: Isa,
    dst: &mut [T],
    cv: MatView,
    a: &[T],
    av: MatView,
    b: &[T],
    bv: MatView,
    accumulate: bool,
) -> Result<()> {
    if av.batch != 1 || bv.batch != 1 || cv.batch != 1 {
        bail!("gemm_into multiplies single matrices, got batches {} · {} → {}", av.batch, bv.batch, cv.batch);
    }
    if av.cols != bv.rows || cv.rows != av.rows || cv.cols != bv.cols {
        bail!("gemm_into shapes do not match: {av:?} · {bv:?} → {cv:?}");
    }
    if av.end() > a.len() || bv.end() > b.len() || cv.end() > dst.len() {
        bail!(
            "gemm_into view outside its buffer: {av:?} in {}, {bv:?} in {}, {cv:?} in {}",
            a.len(),
            b.len(),
            dst.len()
        );
    }
    let (m, n, k) = (av.rows, bv.cols, av.cols);
    if m == 0 || n == 0 {
        return Ok(());
    }
    let zero = T::from_f64(0.0);
    if k == 0 {
        if !accumulate {
            for i in 0..m {
                for j in 0..n {
                    dst[cv.offset + i * cv.strides[1] + j * cv.strides[2]] = zero;
                }
            }
        }
        return Ok(());
    }
    let stride = |s: usize| s as isize;
    let product = match (isa, avx2_fma()) {
        (Isa::Avx2, Some(_)) => T::AVX2,
        _ => gemm::gemm::<T>,
    };
    LHS_PACKING.call_once(|| gemm::set_lhs_packing_threshold_single_thread(LHS_PACKING_THRESHOLD));
    // SAFETY: every element the call reads or writes is `offset + i·row_stride +
    // j·col_stride` of its view with `i < rows`, `j < cols`: at most `end() − 1`, which the
    // checks above keep inside `a`, `b` and `dst`. `dst` is borrowed mutably and `a`, `b`
    // shared, so they cannot alias. `Parallelism::None` keeps the call on this thread.
    #[allow(unsafe_code)]
    unsafe {
        product(
            m,
            n,
            k,
            dst.as_mut_ptr().add(cv.offset),
            stride(cv.strides[2]),
            stride(cv.strides[1]),
            accumulate,
            a.as_ptr().add(av.offset),
            stride(av.strides[2]),
            stride(av.strides[1]),
            b.as_ptr().add(bv.offset),
            stride(bv.strides[2]),
            stride(bv.strides[1]),
            T::from_f64(1.0),
            T::from_f64(1.0),
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
    Ok(())
}

/// `gemm::gemm`'s signature for element type `T`: `dst = alpha·dst + beta·lhs·rhs`, with
/// `(m, n, k)`, then each operand's pointer and its column and row strides (elements).
type GemmFn<T> = unsafe fn(
    usize,
    usize,
    usize,
    *mut T,
    isize,
    isize,
    bool,
    *const T,
    isize,
    isize,
    *const T,
    isize,
    isize,
    T,
    T,
    bool,
    bool,
    bool,
    gemm::Parallelism,
);

/// Element types with the gemm crate's AVX2/FMA product.
pub(crate) trait Avx2Gemm: Sized + 'static {
    /// gemm's AVX2/FMA product for this type with `gemm::gemm`'s arguments: the microkernels
    /// `gemm::gemm` runs on a CPU without AVX-512. On a CPU without AVX2 and FMA (or off
    /// x86-64) it is `gemm::gemm` itself.
    const AVX2: GemmFn<Self>;
}

/// Implements [`Avx2Gemm`] for `$t` with the FMA microkernels of `$kernels` (`$lanes` per
/// 256-bit register), as gemm's private `fma::gemm_basic` does.
macro_rules! avx2_gemm {
    ($t:ty, $kernels:path, $lanes:literal) => {
        impl Avx2Gemm for $t {
            #[cfg(target_arch = "x86_64")]
            const AVX2: GemmFn<$t> = {
                #[allow(unsafe_code, clippy::too_many_arguments)]
                unsafe fn avx2(
                    m: usize,
                    n: usize,
                    k: usize,
                    dst: *mut $t,
                    dst_cs: isize,
                    dst_rs: isize,
                    read_dst: bool,
                    lhs: *const $t,
                    lhs_cs: isize,
                    lhs_rs: isize,
                    rhs: *const $t,
                    rhs_cs: isize,
                    rhs_rs: isize,
                    alpha: $t,
                    beta: $t,
                    conj_dst: bool,
                    conj_lhs: bool,
                    conj_rhs: bool,
                    parallelism: gemm::Parallelism,
                ) {
                    use $kernels as ukr;
                    let Some(simd) = gemm_common::simd::V3::try_new() else {
                        return gemm::gemm(
                            m,
                            n,
                            k,
                            dst,
                            dst_cs,
                            dst_rs,
                            read_dst,
                            lhs,
                            lhs_cs,
                            lhs_rs,
                            rhs,
                            rhs_cs,
                            rhs_rs,
                            alpha,
                            beta,
                            conj_dst,
                            conj_lhs,
                            conj_rhs,
                            parallelism,
                        );
                    };
                    gemm_common::gemm::gemm_basic_generic::<
                        _,
                        $t,
                        $lanes,
                        { ukr::MR_DIV_N * $lanes },
                        { ukr::NR },
                        { ukr::MR_DIV_N },
                        { ukr::H_M },
                        { ukr::H_N },
                    >(
                        simd,
                        m,
                        n,
                        k,
                        dst,
                        dst_cs,
                        dst_rs,
                        read_dst,
                        lhs,
                        lhs_cs,
                        lhs_rs,
                        rhs,
                        rhs_cs,
                        rhs_rs,
                        alpha,
                        beta,
                        conj_dst,
                        conj_lhs,
                        conj_rhs,
                        |a, b, c| a * b + c,
                        &ukr::UKR,
                        &ukr::H_UKR,
                        false,
                        parallelism,
                    )
                }
                avx2
            };
            #[cfg(not(target_arch = "x86_64"))]
            const AVX2: GemmFn<$t> = gemm::gemm::<$t>;
        }
    };
}
avx2_gemm!(f32, gemm_f32::microkernel::fma::f32, 8);
avx2_gemm!(f64, gemm_f64::microkernel::fma::f64, 4);

#[cfg(test)]
mod tests {
    use super::*;

    /// `C (+)= A·B` in f64 through the views, the reference for the kernels.
    fn reference(c: &mut [f64], cv: MatView, a: &[f32], av: MatView, b: &[f32], bv: MatView, accumulate: bool) {
        let at = |buf: &[f32], v: MatView, i: usize, j: usize| buf[v.offset + i * v.strides[1] + j * v.strides[2]];
        for i in 0..cv.rows {
            for j in 0..cv.cols {
                let dot: f64 = (0..av.cols).map(|p| at(a, av, i, p) as f64 * at(b, bv, p, j) as f64).sum();
                let slot = &mut c[cv.offset + i * cv.strides[1] + j * cv.strides[2]];
                *slot = if accumulate { *slot + dot } else { dot };
            }
        }
    }

    /// The AVX2 products against an f64 reference, to 1e-5 of the largest entry, on the fused
    /// layer's kinds of views: a linear layer's rows (`[rows, 128]·[128, 384]`, accumulating
    /// onto a bias), a head of the q/k/v buffer against a transposed head (`Q·Kᵀ`, written
    /// into one head of the probabilities), probabilities against a head (`P·V`), and a
    /// transposed block of probabilities (`Pᵀ·dO`); row counts off the microkernels' tiles.
    #[test]
    fn avx2_products_match_the_reference() -> Result<()> {
        if !Isa::Avx2.is_available() {
            return Ok(());
        }
        let (s, d, heads) = (37usize, 128usize, 4usize);
        let hd = d / heads;
        let fill = |n: usize, seed: usize| -> Vec<f32> {
            (0..n).map(|i| ((i * 7919 + seed * 104_729) % 1000) as f32 / 500.0 - 1.0).collect()
        };
        let qkv = fill(s * 3 * d, 1);
        let probs = fill(s * heads * s, 2);
        let w = fill(d * 3 * d, 3);
        let head = |part: usize, h: usize| MatView {
            offset: part * d + h * hd,
            batch: 1,
            rows: s,
            cols: hd,
            strides: [0, 3 * d, 1],
        };
        let prob_head = |h: usize| MatView { offset: h * s, batch: 1, rows: s, cols: s, strides: [0, heads * s, 1] };
        let out_head = |h: usize| MatView { offset: h * hd, batch: 1, rows: s, cols: hd, strides: [0, d, 1] };
        let keys = MatView { offset: 3 * s + 5, rows: 11, ..prob_head(3).t() };
        // (name, A, its view, B, its view, C's view, C's length, accumulate)
        let cases = [
            (
                "x·Wᵀ",
                &qkv,
                MatView::contiguous(0, 1, s, d),
                &w,
                MatView::contiguous(0, 1, d, 3 * d),
                MatView::contiguous(0, 1, s, 3 * d),
                s * 3 * d,
                true,
            ),
            ("Q·Kᵀ", &qkv, head(0, 2), &qkv, head(1, 2).t(), prob_head(2), s * heads * s, false),
            ("P·V", &probs, prob_head(1), &qkv, head(2, 1), out_head(1), s * d, false),
            ("Pᵀ·dO", &probs, keys, &qkv, head(0, 3), MatView { rows: 11, ..out_head(3) }, s * d, false),
        ];
        for (name, a, av, b, bv, cv, len, accumulate) in cases {
            let start = fill(len, 4);
            let mut want: Vec<f64> = start.iter().map(|&v| v as f64).collect();
            reference(&mut want, cv, a, av, b, bv, accumulate);
            let mut got = start.clone();
            gemm_into(Isa::Avx2, &mut got, cv, a, av, b, bv, accumulate)?;
            let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            let err = got.iter().zip(&want).map(|(&g, &w)| (g as f64 - w).abs()).fold(0.0, f64::max);
            assert!(err <= 1e-5 * scale, "{name}: error {err:e} of {scale}");
        }
        Ok(())
    }
}
