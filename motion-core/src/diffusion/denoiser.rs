//! The denoiser a sampler drives, and one move of it: the guided x̂0 prediction and the DDIM
//! move that composes it.

use candle_core::{Result, Tensor};

use super::guidance::Guidance;

/// A network that predicts the clean sample x̂0 from a noisy one (MDM predicts x0, not ε).
pub trait Denoiser {
    /// - `x_t`: `[batch, frames, 263]`, normalised features at diffusion step `timesteps`;
    /// - `timesteps`: `[batch]` u32 on the original 0..999 scale (also under respacing);
    /// - `text`: `[batch, text_dim]` condition vectors; an all-zero row is the unconditional
    ///   branch of classifier-free guidance (MDM replaces the text embedding by zeros).
    ///
    /// Returns x̂0, `[batch, frames, 263]`. Inference mode: no dropout.
    fn predict_x0(&self, x_t: &Tensor, timesteps: &Tensor, text: &Tensor) -> Result<Tensor>;

    /// One DDIM move of `x_t` (`[batch, frames, 263]`, at `step.timestep`) with the guided
    /// x̂0: `step.c_x·x_t + step.c_0·x̂0`, `guidance` already resolved by
    /// [`Guidance::for_text`]. Differentiable in `x_t`. The default composes
    /// [`Self::predict_x0`] and the update ([`guided_move`]); MDM's CPU path overrides it with
    /// one fused op, so an unrolled sampler records one autograd node per step.
    fn ddim_move(&self, x_t: &Tensor, text: &Tensor, guidance: Guidance, step: DdimMove) -> Result<Tensor> {
        guided_move(self, x_t, text, guidance, step)
    }

    /// Width of the condition vectors.
    fn text_dim(&self) -> usize;
}

impl Guidance {
    /// Guided x̂0 for `x_t` (`[batch, ...]`) at `timesteps` (`[batch]` u32, original scale).
    ///
    /// When active, makes ONE denoiser call on `2·batch` rows, the inputs concatenated as
    /// `[x_t; x_t]`, `[t; t]`, `[text; 0]`, and splits the output into (cond, uncond); with
    /// scale 1 it is one call on `batch` rows. Differentiable in `x_t`.
    pub fn predict_x0<D: Denoiser + ?Sized>(
        &self,
        denoiser: &D,
        x_t: &Tensor,
        timesteps: &Tensor,
        text: &Tensor,
    ) -> Result<Tensor> {
        if !self.is_active() {
            return denoiser.predict_x0(x_t, timesteps, text);
        }
        let batch = x_t.dim(0)?;
        let x2 = Tensor::cat(&[x_t, x_t], 0)?;
        let t2 = Tensor::cat(&[timesteps, timesteps], 0)?;
        let text2 = Tensor::cat(&[text, &text.zeros_like()?], 0)?;
        let out = denoiser.predict_x0(&x2, &t2, &text2)?;
        let cond = out.narrow(0, 0, batch)?;
        let uncond = out.narrow(0, batch, batch)?;
        &uncond + ((&cond - &uncond)? * self.scale)?
    }
}

/// One deterministic (eta = 0) DDIM move of x from spaced timestep `timestep` (ᾱ_from) to
/// ᾱ_to, given the guided prediction x̂0 there: ε̂ = (x/√ᾱ_from − x̂0)/√(1/ᾱ_from − 1) and
/// x_next = √ᾱ_to·x̂0 + √(1 − ᾱ_to)·ε̂, folded into x_next = `c_x`·x + `c_0`·x̂0 with
/// c_x = √(1−ᾱ_to)/√(1−ᾱ_from) and c_0 = √ᾱ_to − c_x·√ᾱ_from. Denoising moves to ᾱ_{k−1}
/// (ᾱ_{−1} := 1: c_x = 0, c_0 = 1, the last move returns x̂0), inversion to ᾱ_{k+1}.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DdimMove {
    /// Original-scale timestep of x, where the denoiser is evaluated.
    pub timestep: usize,
    /// Coefficient of x.
    pub c_x: f64,
    /// Coefficient of x̂0.
    pub c_0: f64,
}

impl DdimMove {
    /// The move from ᾱ_from (at `timestep`) to ᾱ_to.
    pub fn new(timestep: usize, abar_from: f64, abar_to: f64) -> Self {
        if abar_to == 1.0 {
            return Self { timestep, c_x: 0.0, c_0: 1.0 };
        }
        let c_x = ((1.0 - abar_to) / (1.0 - abar_from)).sqrt();
        Self { timestep, c_x, c_0: abar_to.sqrt() - c_x * abar_from.sqrt() }
    }

    /// x_next from x and x̂0 (x̂0 itself when c_x = 0 and c_0 = 1).
    pub fn apply(&self, x: &Tensor, x0_hat: &Tensor) -> Result<Tensor> {
        if self.c_x == 0.0 && self.c_0 == 1.0 {
            return Ok(x0_hat.clone());
        }
        x.affine(self.c_x, 0.0)? + x0_hat.affine(self.c_0, 0.0)?
    }
}

/// The move composed from its parts for any denoiser: x̂0 by [`Guidance::predict_x0`]
/// (`guidance` already resolved by [`Guidance::for_text`]), then [`DdimMove::apply`].
/// The default of [`Denoiser::ddim_move`]. Differentiable in `x`.
pub fn guided_move<D: Denoiser + ?Sized>(
    denoiser: &D,
    x: &Tensor,
    text: &Tensor,
    guidance: Guidance,
    step: DdimMove,
) -> Result<Tensor> {
    step.apply(x, &guidance.predict_x0(denoiser, x, &timestep_tensor(step.timestep, x.dim(0)?, x.device())?, text)?)
}

/// `[rows]` u32 tensor filled with timestep `t`, on `device`.
pub(crate) fn timestep_tensor(t: usize, rows: usize, device: &candle_core::Device) -> Result<Tensor> {
    let t = u32::try_from(t).map_err(|_| candle_core::Error::Msg(format!("timestep {t} overflows u32")))?;
    Tensor::full(t, rows, device)
}
