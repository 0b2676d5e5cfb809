//! Matrix products on one thread through the `gemm` crate, for the kernels that split their
//! rows over the rayon pool themselves ([`gemm_into`]): the one place in this crate with
//! `unsafe`, a bounds-checked call of `gemm`.
//!
//! Under [`Isa::Avx2`] the product runs gemm's own AVX2/FMA microkernels (the ones `gemm::gemm`
//! picks on a CPU without AVX-512), called directly, so that a CPU with AVX-512 runs the same
//! code as one without; otherwise `gemm::gemm` picks the microkernels for this CPU.

use candle_core::{bail, Result};

use super::isa::{avx2_fma, Isa};
use super::kernels::Real;

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
pub(crate) fn gemm_into<T: Real>(
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
                            m, n, k, dst, dst_cs, dst_rs, read_dst, lhs, lhs_cs, lhs_rs, rhs, rhs_cs, rhs_rs, alpha,
                            beta, conj_dst, conj_lhs, conj_rhs, parallelism,
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

/// The rate of [`gemm_into`] on `isa` on a square f32 product `[side, side]·[side, side]`
/// (GFLOP/s, 2·side³ flops per product), its rows split into one block per thread of the
/// current rayon pool as the fused layer splits its own: the median of `reps` products after
/// one warm-up. Entries are small integers, so the rate does not depend on the values.
pub fn sgemm_gflops(isa: Isa, side: usize, reps: usize) -> Result<f64> {
    use super::kernels::{par_each, row_chunks, rows_of, split_rows};
    let a: Vec<f32> = (0..side * side).map(|i| (i % 7) as f32 - 3.0).collect();
    let b: Vec<f32> = (0..side * side).map(|i| (i % 5) as f32 - 2.0).collect();
    let mut c = vec![0f32; side * side];
    let chunks = row_chunks(side, rayon::current_num_threads());
    let mut times = Vec::with_capacity(reps);
    for rep in 0..=reps.max(1) {
        let tasks: Vec<_> = chunks.iter().copied().zip(split_rows(&mut c, side, chunks.iter().copied())).collect();
        let start = std::time::Instant::now();
        par_each(tasks, |(r, out)| {
            let rows = MatView::contiguous(0, 1, r.len, side);
            gemm_into(isa, out, rows, rows_of(&a, side, r), rows, &b, MatView::contiguous(0, 1, side, side), false)
        })?;
        if rep > 0 {
            times.push(start.elapsed().as_secs_f64());
        }
    }
    times.sort_by(f64::total_cmp);
    let median = times[times.len() / 2];
    Ok(2.0 * (side as f64).powi(3) / median / 1e9)
}
