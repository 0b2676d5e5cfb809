//! The denoiser itself: MDM's parameters, its two forward paths and its file.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{bail, DType, Device, Result, Tensor};
use candle_nn::{VarBuilder, VarMap};
use rand::rngs::StdRng;
use rand::{RngCore, SeedableRng};

use super::config::{MdmConfig, Prediction};
use super::init::SeededInit;
use super::layer::{self, Dropout, EncoderLayer, ParamLoader};
use super::positions::{sinusoidal_table, MAX_LEN};
use crate::diffusion::ddim::timestep_tensor;
use crate::diffusion::{guided_move, DdimMove, Denoiser, Guidance, NoiseSchedule};
use crate::nn::{Isa, Linear};

/// MDM with the text condition given as a vector (CLIP is run elsewhere).
#[derive(Debug, Clone)]
pub struct Mdm {
    cfg: MdmConfig,
    /// `input_process.poseEmbedding`: 263 → d.
    input_process: Linear,
    /// `embed_timestep.time_embed.0` and `.2` (SiLU between).
    time_embed: (Linear, Linear),
    /// `embed_text`: text_dim → d.
    embed_text: Linear,
    /// `seqTransEncoder.layers.{i}`.
    pub(super) layers: Vec<EncoderLayer>,
    /// `output_process.poseFinal`: d → 263.
    output_process: Linear,
    /// Recomputed sinusoidal table `[MAX_LEN, d]` in the model dtype (not a parameter).
    pe: Tensor,
    /// For [`Prediction::Velocity`]: MDM's schedule, whose ᾱ_t turns v̂ into x̂0.
    velocity_schedule: Option<NoiseSchedule>,
    params: Vec<(String, Tensor)>,
    /// The instruction set of the fused CPU pass.
    isa: Isa,
}

impl Mdm {
    /// Builds the model from `vb` with the official names (`input_process.poseEmbedding.weight`,
    /// `seqTransEncoder.layers.0.self_attn.in_proj_weight`, ...). The positional buffers
    /// (`*.pe`) are recomputed: absent is fine, present is ignored. A `VarMap`-backed builder
    /// creates missing parameters with PyTorch's default init (unseeded: see [`Self::init_seeded`]).
    pub fn new(cfg: MdmConfig, vb: VarBuilder) -> Result<Self> {
        cfg.validate()?;
        let d = cfg.latent_dim;
        let mut params = Vec::new();
        let mut loader = ParamLoader { named: &mut params };
        let input_process = loader.linear(&vb.pp("input_process").pp("poseEmbedding"), cfg.input_feats, d)?;
        let te = vb.pp("embed_timestep").pp("time_embed");
        let time_embed = (loader.linear(&te.pp("0"), d, d)?, loader.linear(&te.pp("2"), d, d)?);
        let embed_text = loader.linear(&vb.pp("embed_text"), cfg.text_dim, d)?;
        let layers = (0..cfg.num_layers)
            .map(|i| EncoderLayer::new(&vb.pp("seqTransEncoder").pp("layers").pp(i), &cfg, &mut loader))
            .collect::<Result<Vec<_>>>()?;
        let output_process = loader.linear(&vb.pp("output_process").pp("poseFinal"), d, cfg.input_feats)?;
        let pe = sinusoidal_table(MAX_LEN, d, vb.device())?.to_dtype(vb.dtype())?;
        let velocity_schedule = (cfg.prediction == Prediction::Velocity).then(NoiseSchedule::mdm);
        Ok(Self {
            cfg,
            input_process,
            time_embed,
            embed_text,
            layers,
            output_process,
            pe,
            velocity_schedule,
            params,
            isa: Isa::selected(),
        })
    }

    /// Loads a safetensors checkpoint by name (e.g. one converted from `model000475000.pt`).
    pub fn load(cfg: MdmConfig, path: impl AsRef<Path>, dtype: DType, device: &Device) -> Result<Self> {
        let tensors = candle_core::safetensors::load(path, device)?;
        Self::new(cfg, VarBuilder::from_tensors(tensors, dtype, device))
    }

    /// A trainable model: parameters missing from `varmap` are created as `Var`s with
    /// PyTorch's default init drawn from `StdRng::seed_from_u64(seed)`; existing ones are used.
    pub fn init_seeded(cfg: MdmConfig, varmap: &VarMap, dtype: DType, device: &Device, seed: u64) -> Result<Self> {
        let backend = SeededInit::new(varmap.clone(), StdRng::seed_from_u64(seed));
        Self::new(cfg, VarBuilder::from_backend(Box::new(backend), dtype, device.clone()))
    }

    /// A frozen model with seeded random weights (plain tensors, no `Var`s): tests, benchmarks.
    pub fn random(cfg: MdmConfig, dtype: DType, device: &Device, seed: u64) -> Result<Self> {
        let trained = Self::init_seeded(cfg.clone(), &VarMap::new(), dtype, device, seed)?;
        let tensors = trained.params.iter().map(|(n, t)| (n.clone(), t.detach())).collect();
        Self::new(cfg, VarBuilder::from_tensors(tensors, dtype, device))
    }

    /// The model running its fused CPU pass on `isa` instead of [`Isa::selected`] (the same
    /// values up to rounding; a set the CPU lacks runs the CPU's own choice).
    pub fn with_isa(self, isa: Isa) -> Self {
        Self { isa, ..self }
    }

    /// The instruction set of the fused CPU pass.
    pub fn isa(&self) -> Isa {
        self.isa
    }

    /// The sizes.
    pub fn config(&self) -> &MdmConfig {
        &self.cfg
    }

    /// Every parameter with its checkpoint name, in construction order.
    pub fn named_parameters(&self) -> &[(String, Tensor)] {
        &self.params
    }

    /// Writes the parameters to a safetensors file by their official names (no `pe` buffers).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let map: HashMap<String, Tensor> = self.params.iter().cloned().collect();
        candle_core::safetensors::save(&map, path)
    }

    /// Training forward pass with dropout `cfg.dropout` (masks from `rng`) at MDM's places:
    /// after adding the positional encoding and inside every encoder layer.
    ///
    /// `x_t [batch, frames, 263]`, `timesteps [batch]` (u32, 0..999), `text [batch, text_dim]`
    /// (all-zero rows = unconditional; masking the condition is the trainer's job).
    /// Returns x̂0 `[batch, frames, 263]`. Primitive ops: gradients reach every `Var`.
    pub fn forward_train(
        &self,
        x_t: &Tensor,
        timesteps: &Tensor,
        text: &Tensor,
        rng: &mut dyn RngCore,
    ) -> Result<Tensor> {
        self.forward_primitive(x_t, timesteps, text, &mut Dropout { p: self.cfg.dropout, rng: Some(rng) })
    }

    /// [`Self::forward_train`] in eval mode (no dropout); same shapes. Agrees with
    /// [`Denoiser::predict_x0`] but records weight gradients (slow in the DNO loop).
    pub fn forward_eval(&self, x_t: &Tensor, timesteps: &Tensor, text: &Tensor) -> Result<Tensor> {
        self.forward_primitive(x_t, timesteps, text, &mut Dropout { p: 0.0, rng: None })
    }

    fn forward_primitive(&self, x_t: &Tensor, timesteps: &Tensor, text: &Tensor, drop: &mut Dropout) -> Result<Tensor> {
        let frames = self.check_inputs(x_t, timesteps, text)?;
        let (te0, te2) = &self.time_embed;
        let t_emb = te2.forward(&te0.forward(&self.pe.index_select(timesteps, 0)?)?.silu()?)?;
        let cond = (t_emb + self.embed_text.forward(text)?)?;
        let mut h = drop.apply(&self.tokens(&cond, &self.input_process.forward(x_t)?, frames)?)?;
        for layer in &self.layers {
            h = layer.forward(&h, drop)?;
        }
        self.to_x0(self.output_process.forward(&h.narrow(1, 1, frames)?)?, x_t, timesteps)
    }

    /// The frozen-weight path behind [`Denoiser::predict_x0`]: on the CPU one fused op from
    /// the features to the output projection (the condition token computed here is a
    /// constant of the pass, so gradients flow to `x_t` only); elsewhere the primitive path.
    fn forward_frozen(&self, x_t: &Tensor, timesteps: &Tensor, text: &Tensor) -> Result<Tensor> {
        let frames = self.check_inputs(x_t, timesteps, text)?;
        if !crate::nn::ops::has_cpu_kernel(x_t) {
            return self.forward_eval(x_t, timesteps, text);
        }
        let out =
            layer::frozen_stack(&self.layers, x_t, Some(self.frozen_ends(frames, timesteps, text, None)?), self.isa)?;
        self.to_x0(out, x_t, timesteps)
    }

    /// The fused pass's [`layer::Ends`] for `frames` frames under condition rows `timesteps`
    /// `[rows]` and `text` `[rows, text_dim]`, ending in `step`.
    fn frozen_ends(
        &self,
        frames: usize,
        timesteps: &Tensor,
        text: &Tensor,
        step: Option<layer::Epilogue>,
    ) -> Result<layer::Ends> {
        let (te0, te2) = &self.time_embed;
        let t_emb = te2.forward_frozen(&te0.forward_frozen(&self.pe.index_select(timesteps, 0)?)?.silu()?)?;
        let cond = (t_emb + self.embed_text.forward_frozen(text)?)?.detach();
        let bias = |l: &Linear| -> Result<Tensor> {
            l.bias().map(Tensor::detach).ok_or_else(|| candle_core::Error::Msg("denoiser linear without bias".into()))
        };
        Ok(layer::Ends {
            input_weight: self.input_process.weight().detach(),
            input_bias: bias(&self.input_process)?,
            output_weight: self.output_process.weight().detach(),
            output_bias: bias(&self.output_process)?,
            cond: cond.contiguous()?,
            pe: self.pe.narrow(0, 0, frames + 1)?.contiguous()?.detach(),
            step,
        })
    }

    fn to_x0(&self, out: Tensor, x_t: &Tensor, timesteps: &Tensor) -> Result<Tensor> {
        let Some(schedule) = &self.velocity_schedule else { return Ok(out) };
        let signal = schedule.per_sample(timesteps, x_t, f64::sqrt)?;
        let noise = schedule.per_sample(timesteps, x_t, |abar| (1.0 - abar).sqrt())?;
        x_t.broadcast_mul(&signal)? - out.broadcast_mul(&noise)?
    }

    /// `[cond; frames] + pe[0..=frames]`: `cond [batch, d]`, `x [batch, frames, d]` →
    /// `[batch, frames + 1, d]` (the condition token gets `pe[0]`, as in MDM).
    fn tokens(&self, cond: &Tensor, x: &Tensor, frames: usize) -> Result<Tensor> {
        Tensor::cat(&[&cond.unsqueeze(1)?, x], 1)?.broadcast_add(&self.pe.narrow(0, 0, frames + 1)?)
    }

    /// Checks shapes and dtypes; returns the number of frames.
    fn check_inputs(&self, x_t: &Tensor, timesteps: &Tensor, text: &Tensor) -> Result<usize> {
        let (batch, frames, feats) = x_t.dims3()?;
        if feats != self.cfg.input_feats {
            bail!("x_t has {feats} features per frame, the model {}", self.cfg.input_feats);
        }
        if frames + 1 > MAX_LEN {
            bail!("{frames} frames exceed the positional table ({MAX_LEN} tokens)");
        }
        if timesteps.dims1()? != batch {
            bail!("timesteps {:?} do not match batch {batch}", timesteps.shape());
        }
        if text.dims2()? != (batch, self.cfg.text_dim) {
            bail!("text {:?} must be [{batch}, {}]", text.shape(), self.cfg.text_dim);
        }
        let dtype = self.pe.dtype();
        if x_t.dtype() != dtype || text.dtype() != dtype {
            bail!("inputs are {:?}/{:?}, the model {dtype:?}", x_t.dtype(), text.dtype());
        }
        Ok(frames)
    }
}

impl Denoiser for Mdm {
    /// Frozen-weight forward (no dropout); gradients flow to `x_t` (and `text`) only.
    fn predict_x0(&self, x_t: &Tensor, timesteps: &Tensor, text: &Tensor) -> Result<Tensor> {
        self.forward_frozen(x_t, timesteps, text)
    }

    /// On the CPU one fused op per move (the guidance branches, x̂0 and the update inside the
    /// pass); elsewhere the composed move.
    fn ddim_move(&self, x_t: &Tensor, text: &Tensor, guidance: Guidance, step: DdimMove) -> Result<Tensor> {
        if !crate::nn::ops::has_cpu_kernel(x_t) {
            return guided_move(self, x_t, text, guidance, step);
        }
        let (batch, frames) = (x_t.dim(0)?, x_t.dim(1)?);
        // Guidance runs each sample twice: under its text, then under the empty one.
        let copies = if guidance.is_active() { 2 } else { 1 };
        let timesteps = timestep_tensor(step.timestep, copies * batch, x_t.device())?;
        self.check_inputs(x_t, &timesteps.narrow(0, 0, batch)?, text)?;
        let (rows, scale) = if guidance.is_active() {
            (Tensor::cat(&[text, &text.zeros_like()?], 0)?, Some(guidance.scale))
        } else {
            (text.clone(), None)
        };
        // x̂0 = out (x0 prediction) or √ᾱ_t·x − √(1 − ᾱ_t)·out (velocity), folded into the move.
        let (x_coeff, out_coeff) = match &self.velocity_schedule {
            None => (step.c_x, step.c_0),
            Some(schedule) => {
                let abar = schedule.alphas_cumprod().get(step.timestep).copied().ok_or_else(|| {
                    candle_core::Error::Msg(format!("timestep {} outside the schedule", step.timestep))
                })?;
                (step.c_x + step.c_0 * abar.sqrt(), -step.c_0 * (1.0 - abar).sqrt())
            }
        };
        let epilogue = layer::Epilogue { guidance: scale, x_coeff, out_coeff };
        let ends = self.frozen_ends(frames, &timesteps, &rows, Some(epilogue))?;
        layer::frozen_stack(&self.layers, x_t, Some(ends), self.isa)
    }

    fn text_dim(&self) -> usize {
        self.cfg.text_dim
    }
}
