//! The map z → x that DNO differentiates through: normally the unrolled DDIM sampler of the
//! frozen prior (DNO's `ddim_loop_with_gradient`, anchors §2.2).

use candle_core::{Result, Tensor};

use super::config::DnoConfig;
use crate::diffusion::{DdimSampler, Denoiser, Guidance, NoiseSchedule};

/// A differentiable map from start noise z to a motion x, both `[batch, frames, 263]`
/// (normalised features). Any `Fn(&Tensor) -> Result<Tensor>` is one.
pub trait Solver {
    /// x = G(z), keeping the autograd graph back to `z`.
    fn solve(&self, z: &Tensor) -> Result<Tensor>;

    /// x of some rows of the batch: `z_rows` `[R, frames, 263]` are the rows `rows` (`[R]`,
    /// u32) of the batch's noise. A solver that maps each row on its own (a closure) solves
    /// them as they are; one with inputs per row picks those rows of them.
    fn solve_rows(&self, z_rows: &Tensor, rows: &Tensor) -> Result<Tensor> {
        let _ = rows;
        self.solve(z_rows)
    }
}

impl<F: Fn(&Tensor) -> Result<Tensor>> Solver for F {
    fn solve(&self, z: &Tensor) -> Result<Tensor> {
        self(z)
    }
}

/// The normal solver: K-step DDIM (eta = 0) of a denoiser from z = x at the last spaced
/// timestep, with the whole graph kept ([`DdimSampler::sample_unrolled`]).
///
/// Cost per DNO step: K guided denoiser calls forward and backward (2·batch rows each when
/// guidance is active). DNO optimises with the empty text and guidance 2.5; ProgMoGen with the
/// task's prompt.
#[derive(Debug, Clone)]
pub struct UnrolledDdim<'a, D: Denoiser + ?Sized> {
    /// The respaced sampler.
    pub sampler: DdimSampler,
    /// The frozen prior, e.g. `&prior.mdm`.
    pub denoiser: &'a D,
    /// Condition vectors `[batch, text_dim]`, one row per sample of z.
    pub text: Tensor,
    /// Classifier-free guidance.
    pub guidance: Guidance,
    /// A late start ([`Self::starting_late`]): z is then the noise added to a fixed motion at
    /// the sampler's first timestep, not the whole start latent.
    pub late_start: Option<LateStart>,
}

/// Where a late-started solver begins: x_s = `signal` + `noise_scale`·z, with `signal` =
/// √ᾱ_s·x_init (`[batch, frames, 263]`) and `noise_scale` = √(1 − ᾱ_s) at the start timestep s
/// (SDEdit's noising of x_init, Meng et al. 2022).
#[derive(Debug, Clone)]
pub struct LateStart {
    /// √ᾱ_s·x_init, detached.
    pub signal: Tensor,
    /// √(1 − ᾱ_s).
    pub noise_scale: f64,
}

impl<'a, D: Denoiser + ?Sized> UnrolledDdim<'a, D> {
    /// DDIM with `ddim_steps` steps over MDM's cosine schedule (ddim10: timesteps 900, …, 0).
    pub fn new(denoiser: &'a D, text: Tensor, guidance: Guidance, ddim_steps: usize) -> Result<Self> {
        let sampler = DdimSampler::new(&NoiseSchedule::mdm(), ddim_steps).map_err(candle_core::Error::wrap)?;
        Ok(Self { sampler, denoiser, text, guidance, late_start: None })
    }

    /// This solver started at timestep `max_timestep` (the sampler's last spaced timestep at
    /// or below it) from `x_init` noised by z: x = G(√ᾱ_s·x_init + √(1 − ᾱ_s)·z). DNO then
    /// optimises the noise of an existing motion where the denoiser keeps more of what it is
    /// given, instead of the start latent at t = 900 (`x_init` `[batch, frames, 263]`).
    pub fn starting_late(mut self, max_timestep: usize, x_init: &Tensor) -> Result<Self> {
        self.sampler = self.sampler.starting_at(max_timestep);
        let abar = self.sampler.alphas_cumprod().last().copied().unwrap_or(1.0);
        let signal = x_init.detach().affine(abar.sqrt(), 0.0)?;
        self.late_start = Some(LateStart { signal, noise_scale: (1.0 - abar).sqrt() });
        Ok(self)
    }

    /// This solver on every `stride`-th timestep of its sampler, counted down from its start
    /// ([`DdimSampler::every`]): the same start noise at 1/`stride` of the denoiser passes.
    pub fn every(&self, stride: usize) -> Self {
        Self {
            sampler: self.sampler.every(stride),
            denoiser: self.denoiser,
            text: self.text.clone(),
            guidance: self.guidance,
            late_start: self.late_start.clone(),
        }
    }

    /// [`Self::new`] with `config.ddim_steps`.
    pub fn from_config(denoiser: &'a D, text: Tensor, guidance: Guidance, config: &DnoConfig) -> Result<Self> {
        Self::new(denoiser, text, guidance, config.ddim_steps)
    }
}

impl<D: Denoiser + ?Sized> Solver for UnrolledDdim<'_, D> {
    fn solve(&self, z: &Tensor) -> Result<Tensor> {
        let x_start = match &self.late_start {
            None => z.clone(),
            Some(start) => (&start.signal + z.affine(start.noise_scale, 0.0)?)?,
        };
        self.sampler.sample_unrolled(self.denoiser, &x_start, &self.text, self.guidance)
    }

    fn solve_rows(&self, z_rows: &Tensor, rows: &Tensor) -> Result<Tensor> {
        // The text and the late start's signal of those rows (one row serves every sample).
        let pick = |t: &Tensor| if t.dim(0)? == 1 { Ok(t.clone()) } else { t.index_select(rows, 0) };
        let late_start = match &self.late_start {
            None => None,
            Some(start) => Some(LateStart { signal: pick(&start.signal)?, noise_scale: start.noise_scale }),
        };
        let part = Self {
            sampler: self.sampler.clone(),
            denoiser: self.denoiser,
            text: pick(&self.text)?,
            guidance: self.guidance,
            late_start,
        };
        part.solve(z_rows)
    }
}
