//! The denoiser's ends around the encoder stack (input and output projections, condition
//! token, positional encoding) and the DDIM move folded into the pass ([`Epilogue`]).

use candle_core::{bail, Layout, Result, Storage, StorageRef, Tensor};

use super::plan::run;
use crate::nn::isa::Isa;
use crate::nn::kernels::{contiguous_slice, linear_rows, linear_rows_bwd, row_chunks, split_rows, Real, Rows, Weight};

/// The denoiser's ends around the stack: MDM's `input_process` (features → width), the
/// condition token prepended to the frames, the positional encoding added to every token and
/// `output_process` (width → features) over the frame tokens. With them one op covers a whole
/// denoiser pass, `x [batch, frames, F] → [batch, frames, F]`; the condition and the encoding
/// are constants of the pass (no gradient flows to them).
#[derive(Debug, Clone)]
pub(crate) struct Ends {
    /// `[d, F]` and `[d]`.
    pub input_weight: Tensor,
    pub input_bias: Tensor,
    /// `[F, d]` and `[F]`.
    pub output_weight: Tensor,
    pub output_bias: Tensor,
    /// `[batch, d]`: the timestep and text embedding of each element.
    pub cond: Tensor,
    /// `[frames + 1, d]`.
    pub pe: Tensor,
    /// A DDIM move folded into the pass: what the op returns instead of the output
    /// projection (`None`: the projection itself).
    pub step: Option<Epilogue>,
}

/// A guided DDIM move as the end of a whole denoiser pass: the op maps `x [batch, frames, F]`
/// to `x_coeff·x + out_coeff·ô`, where ô is the output projection `out`, or with guidance
/// scale s over the `2·batch` elements [x under `cond` rows 0..batch; x under rows
/// batch..2·batch (the empty text)], ô = out_u + s·(out_c − out_u) (the same f32 operations as
/// the composed [`crate::diffusion::guided_move`], so the same values).
///
/// For an x0-predicting denoiser `(x_coeff, out_coeff)` = the move's `(c_x, c_0)`.
/// Backward: ∂/∂out_c = s·out_coeff·g, ∂/∂out_u = (1 − s)·out_coeff·g, and the two
/// elements' input gradients are summed with x_coeff·g.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Epilogue {
    /// Classifier-free guidance scale, or `None` for one element per sample.
    pub guidance: Option<f64>,
    pub x_coeff: f64,
    pub out_coeff: f64,
}

impl Epilogue {
    /// Elements the stack runs per input sample.
    pub(super) fn copies(&self) -> usize {
        if self.guidance.is_some() {
            2
        } else {
            1
        }
    }

    /// The move from `x` (`n` values) and the elements' outputs `out` (`copies·n`).
    pub(super) fn forward<T: Real>(&self, x: &[T], out: &[T]) -> Vec<T> {
        let (a, c) = (T::from_f64(self.x_coeff), T::from_f64(self.out_coeff));
        match self.guidance {
            None => x.iter().zip(out).map(|(&x, &o)| x * a + o * c).collect(),
            Some(s) => {
                let s = T::from_f64(s);
                let (cond, uncond) = out.split_at(x.len());
                x.iter().zip(cond.iter().zip(uncond)).map(|(&x, (&oc, &ou))| x * a + (ou + (oc - ou) * s) * c).collect()
            }
        }
    }

    /// The gradient with respect to the elements' outputs (`copies·n`) from `g` (`n`).
    pub(super) fn out_grad<T: Real>(&self, g: &[T]) -> Vec<T> {
        let c = self.out_coeff;
        let weights = match self.guidance {
            None => vec![c],
            Some(s) => vec![s * c, (1.0 - s) * c],
        };
        weights.into_iter().flat_map(|w| g.iter().map(move |&g| g * T::from_f64(w))).collect()
    }

    /// The input gradient (`n`): the elements' input gradients `dx` (`copies·n`) summed, plus
    /// `x_coeff·g`.
    pub(super) fn input_grad<T: Real>(&self, g: &[T], dx: &[T]) -> Vec<T> {
        let a = T::from_f64(self.x_coeff);
        let mut out: Vec<T> = g.iter().zip(dx).map(|(&g, &d)| d + g * a).collect();
        for rest in dx.chunks_exact(g.len().max(1)).skip(1) {
            for (o, &d) in out.iter_mut().zip(rest) {
                *o += d;
            }
        }
        out
    }
}

impl Ends {
    pub(super) fn each(&self) -> [&Tensor; 6] {
        [&self.input_weight, &self.input_bias, &self.output_weight, &self.output_bias, &self.cond, &self.pe]
    }
}

/// [`Ends`] as CPU slices.
pub(super) struct EndSlices<'a, T> {
    pub(super) w_in: &'a [T],
    pub(super) b_in: &'a [T],
    pub(super) w_out: &'a [T],
    pub(super) b_out: &'a [T],
    pub(super) cond: &'a [T],
    pub(super) pe: &'a [T],
    /// Features per frame `F`.
    pub(super) feats: usize,
    /// The instruction set of the projections.
    pub(super) isa: Isa,
}

/// Tasks over the frame rows of `buf`, which holds elements of `element_rows` rows each
/// (`width` wide) whose `frames` frame rows start at row `skip`: `(element, frame chunk, its
/// rows)`, the frames of each element cut into `threads` chunks.
pub(super) fn frame_tasks<T>(
    buf: &mut [T],
    element_rows: usize,
    skip: usize,
    width: usize,
    frames: usize,
    threads: usize,
) -> Vec<(usize, Rows, &mut [T])> {
    let chunks = row_chunks(frames, threads);
    buf.chunks_mut((element_rows * width).max(1))
        .enumerate()
        .flat_map(|(i, element)| {
            let start = (skip * width).min(element.len());
            let rest = &mut element[start..];
            chunks.iter().copied().zip(split_rows(rest, width, chunks.iter().copied())).map(move |(r, o)| (i, r, o))
        })
        .collect()
}

impl<'a, T: Real> EndSlices<'a, T> {
    pub(super) fn new(g: &'a [(StorageRef<'_>, &'a Layout); 6], d: usize, isa: Isa) -> Result<Self> {
        let slice = |i: usize| -> Result<&'a [T]> {
            match &*g[i].0 {
                Storage::Cpu(storage) => contiguous_slice::<T>(storage, g[i].1),
                _ => bail!("fused denoiser: weights are not on the CPU"),
            }
        };
        let feats = slice(3)?.len();
        let ends = Self {
            w_in: slice(0)?,
            b_in: slice(1)?,
            w_out: slice(2)?,
            b_out: slice(3)?,
            cond: slice(4)?,
            pe: slice(5)?,
            feats,
            isa,
        };
        if ends.w_in.len() != d * feats
            || ends.b_in.len() != d
            || ends.w_out.len() != feats * d
            || ends.cond.len() % d.max(1) != 0
        {
            bail!("fused denoiser: input/output projections do not match width {d} and {feats} features");
        }
        Ok(ends)
    }

    /// Tokens `[count·(frames + 1), d]` of elements `first..first + count` of `x`
    /// `[batch, frames, F]`: the condition token, then `x·W_inᵀ + b_in`, each plus its
    /// positional encoding.
    pub(super) fn tokens(
        &self,
        x: &[T],
        first: usize,
        count: usize,
        frames: usize,
        d: usize,
        threads: usize,
    ) -> Result<Vec<T>> {
        let (f, s) = (self.feats, frames + 1);
        if self.pe.len() < s * d || self.cond.len() < (first + count) * d {
            bail!("fused denoiser: positional encoding or condition too short for {frames} frames");
        }
        let mut h = vec![T::from_f64(0.0); count * s * d];
        for (i, token) in h.chunks_mut(s * d).enumerate() {
            let cond = &self.cond[(first + i) * d..][..d];
            for ((t, &c), &p) in token[..d].iter_mut().zip(cond).zip(&self.pe[..d]) {
                *t = c + p;
            }
        }
        let tasks = frame_tasks(&mut h, s, 1, d, frames, threads);
        run(threads, tasks, |(i, r, out)| {
            for (t, row) in out.chunks_exact_mut(d).enumerate() {
                let pe = &self.pe[(1 + r.first + t) * d..][..d];
                for ((o, &b), &p) in row.iter_mut().zip(self.b_in).zip(pe) {
                    *o = b + p;
                }
            }
            let rows = &x[((first + i) * frames + r.first) * f..][..r.len * f];
            linear_rows(self.isa, out, rows, r.len, f, Weight::OutIn(self.w_in), None)
        })?;
        Ok(h)
    }

    /// `[count·frames, F]`: `h·W_outᵀ + b_out` over the frame tokens of `h` `[count·(frames + 1), d]`.
    pub(super) fn project_out(&self, h: &[T], count: usize, frames: usize, d: usize, threads: usize) -> Result<Vec<T>> {
        let (f, s) = (self.feats, frames + 1);
        let mut out = vec![T::from_f64(0.0); count * frames * f];
        let tasks = frame_tasks(&mut out, frames, 0, f, frames, threads);
        run(threads, tasks, |(i, r, o)| {
            let rows = &h[(i * s + 1 + r.first) * d..][..r.len * d];
            linear_rows(self.isa, o, rows, r.len, d, Weight::OutIn(self.w_out), Some(self.b_out))
        })
        .map(|()| out)
    }

    /// The gradient of [`Self::project_out`]: `[count·(frames + 1), d]` with zero rows for the
    /// condition tokens.
    pub(super) fn project_out_bwd(
        &self,
        g: &[T],
        count: usize,
        frames: usize,
        d: usize,
        threads: usize,
    ) -> Result<Vec<T>> {
        let (f, s) = (self.feats, frames + 1);
        let mut dh = vec![T::from_f64(0.0); count * s * d];
        let tasks = frame_tasks(&mut dh, s, 1, d, frames, threads);
        run(threads, tasks, |(i, r, o)| {
            linear_rows_bwd(self.isa, o, &g[(i * frames + r.first) * f..][..r.len * f], r.len, self.w_out, d, false)
        })
        .map(|()| dh)
    }

    /// The gradient of [`Self::tokens`] with respect to `x`: `[count·frames, F]`.
    pub(super) fn tokens_bwd(&self, dh: &[T], count: usize, frames: usize, d: usize, threads: usize) -> Result<Vec<T>> {
        let (f, s) = (self.feats, frames + 1);
        let mut dx = vec![T::from_f64(0.0); count * frames * f];
        let tasks = frame_tasks(&mut dx, frames, 0, f, frames, threads);
        run(threads, tasks, |(i, r, o)| {
            linear_rows_bwd(self.isa, o, &dh[(i * s + 1 + r.first) * d..][..r.len * d], r.len, self.w_in, f, false)
        })
        .map(|()| dx)
    }
}
