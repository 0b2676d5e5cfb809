//! Test-only denoisers and helpers for the diffusion tests.

use std::cell::RefCell;

use candle_core::{DType, Device, Result, Tensor};

use super::denoiser::Denoiser;
use super::noise::gaussian;
use super::schedule::NoiseSchedule;

/// Width of the test condition vectors.
pub const TEXT_DIM: usize = 3;

/// One recorded denoiser call: rows given, and which text rows were all zero.
#[derive(Debug, Clone, PartialEq)]
pub struct Call {
    pub rows: usize,
    pub zero_text_rows: Vec<bool>,
}

/// The exact posterior-mean denoiser of data x0 ~ N(μ, s²I), plus a text-dependent shift:
/// x̂0 = μ + g_t·(x_t − √ᾱ_t·μ) + shift·Σ text, with g_t = √ᾱ_t·s²/(ᾱ_t·s² + 1 − ᾱ_t).
/// Records every call.
pub struct GaussianDenoiser {
    mean: f64,
    std: f64,
    text_shift: f64,
    alphas_cumprod: Vec<f64>,
    pub calls: RefCell<Vec<Call>>,
}

impl GaussianDenoiser {
    pub fn new(mean: f64, std: f64, text_shift: f64) -> Self {
        Self {
            mean,
            std,
            text_shift,
            alphas_cumprod: NoiseSchedule::mdm().alphas_cumprod().to_vec(),
            calls: RefCell::new(Vec::new()),
        }
    }

    fn gain(&self, t: usize) -> f64 {
        let a = self.alphas_cumprod[t];
        let var = self.std * self.std;
        a.sqrt() * var / (a * var + 1.0 - a)
    }

    /// The exact probability-flow ODE in x̄ = x/√ᾱ, σ = √(1/ᾱ − 1):
    /// x̄ − μ ∝ √(s² + σ²). Maps x at timestep `from` to timestep `to`.
    pub fn exact_flow(&self, x: f64, from: usize, to: usize) -> f64 {
        let (a_from, a_to) = (self.alphas_cumprod[from], self.alphas_cumprod[to]);
        let var = self.std * self.std;
        let spread = |a: f64| (var + 1.0 / a - 1.0).sqrt();
        let xbar = self.mean + (x / a_from.sqrt() - self.mean) * spread(a_to) / spread(a_from);
        a_to.sqrt() * xbar
    }

    pub fn x0_hat(&self, x: f64, t: usize) -> f64 {
        self.mean + self.gain(t) * (x - self.alphas_cumprod[t].sqrt() * self.mean)
    }
}

impl Denoiser for GaussianDenoiser {
    fn predict_x0(&self, x_t: &Tensor, timesteps: &Tensor, text: &Tensor) -> Result<Tensor> {
        let text_rows = text.to_dtype(DType::F64)?.to_vec2::<f64>()?;
        self.calls.borrow_mut().push(Call {
            rows: x_t.dim(0)?,
            zero_text_rows: text_rows.iter().map(|r| r.iter().all(|&v| v == 0.0)).collect(),
        });
        let ts = timesteps.to_vec1::<u32>()?;
        let gains: Vec<f64> = ts.iter().map(|&t| self.gain(t as usize)).collect();
        let offsets: Vec<f64> = ts
            .iter()
            .zip(&text_rows)
            .map(|(&t, row)| {
                let g = self.gain(t as usize);
                let a = self.alphas_cumprod[t as usize];
                self.mean * (1.0 - g * a.sqrt()) + self.text_shift * row.iter().sum::<f64>()
            })
            .collect();
        let b = ts.len();
        let gains = Tensor::from_vec(gains, (b, 1, 1), x_t.device())?.to_dtype(x_t.dtype())?;
        let offsets = Tensor::from_vec(offsets, (b, 1, 1), x_t.device())?.to_dtype(x_t.dtype())?;
        x_t.broadcast_mul(&gains)?.broadcast_add(&offsets)
    }

    fn text_dim(&self) -> usize {
        TEXT_DIM
    }
}

/// A `[rows, TEXT_DIM]` f64 condition tensor.
pub fn text(rows: &[[f64; TEXT_DIM]]) -> Result<Tensor> {
    let flat: Vec<f64> = rows.iter().flatten().copied().collect();
    Tensor::from_vec(flat, (rows.len(), TEXT_DIM), &Device::Cpu)
}

/// Seeded f64 start noise `[batch, 5 frames, 4 features]`.
pub fn start_noise(batch: usize, seed: u64) -> Result<Tensor> {
    gaussian((batch, 5, 4), seed, &Device::Cpu)?.to_dtype(DType::F64)
}
