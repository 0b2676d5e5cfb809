//! PyTorch's `nn.TransformerEncoderLayer(d, heads, ff, dropout, activation="gelu")`, post-LN,
//! with its parameter names, and the loader helpers that record every parameter by name.

use std::sync::OnceLock;

use candle_core::{Result, Shape, Tensor};
use candle_nn::{Init, VarBuilder};
use rand::RngCore;

use super::config::MdmConfig;
pub(crate) use super::fused_stack::{Ends, Epilogue};
use super::fused_stack::{FusedEncoderStack, LayerWeights};
use crate::nn::{self, Isa, LayerNorm, Linear, LAYER_NORM_EPS};

/// Parameters fetched from a [`VarBuilder`], each recorded with its full checkpoint name.
pub(crate) struct ParamLoader<'a> {
    pub named: &'a mut Vec<(String, Tensor)>,
}

impl ParamLoader<'_> {
    pub fn get(&mut self, vb: &VarBuilder, shape: impl Into<Shape>, name: &str, init: Init) -> Result<Tensor> {
        let t = vb.get_with_hints(shape, name, init)?;
        let prefix = vb.prefix();
        let full = if prefix.is_empty() { name.to_string() } else { format!("{prefix}.{name}") };
        self.named.push((full, t.clone()));
        Ok(t)
    }

    /// `nn.Linear(in_dim, out_dim)` with PyTorch's default init, U(±1/√in) for weight and bias.
    pub fn linear(&mut self, vb: &VarBuilder, in_dim: usize, out_dim: usize) -> Result<Linear> {
        let bound = 1.0 / (in_dim as f64).sqrt();
        let init = Init::Uniform { lo: -bound, up: bound };
        let w = self.get(vb, (out_dim, in_dim), "weight", init)?;
        let b = self.get(vb, out_dim, "bias", init)?;
        Linear::new(w, Some(b))
    }

    /// `nn.LayerNorm(d)`: weight 1, bias 0, eps 1e-5.
    pub fn layer_norm(&mut self, vb: &VarBuilder, d: usize) -> Result<LayerNorm> {
        let w = self.get(vb, d, "weight", Init::Const(1.0))?;
        let b = self.get(vb, d, "bias", Init::Const(0.0))?;
        LayerNorm::new(w, b, LAYER_NORM_EPS)
    }
}

/// Dropout state of one training forward pass: probability and mask RNG (`None`: eval mode).
pub(crate) struct Dropout<'a> {
    pub p: f64,
    pub rng: Option<&'a mut dyn RngCore>,
}

impl Dropout<'_> {
    pub fn apply(&mut self, x: &Tensor) -> Result<Tensor> {
        match self.rng.as_deref_mut() {
            Some(rng) if self.p > 0.0 => nn::dropout(x, self.p, rng),
            _ => Ok(x.clone()),
        }
    }
}

/// One post-LN encoder layer: `h1 = LN1(h + MHA(h))`, `out = LN2(h1 + W2·GELU(W1·h1 + b1) + b2)`.
#[derive(Debug, Clone)]
pub(crate) struct EncoderLayer {
    /// `self_attn.in_proj_{weight,bias}`: q, k, v stacked, `[3d, d]`.
    in_proj: Linear,
    out_proj: Linear,
    linear1: Linear,
    linear2: Linear,
    norm1: LayerNorm,
    norm2: LayerNorm,
    num_heads: usize,
    /// `Wᵀ` of in_proj, out_proj, linear1 and linear2 for the fused path, made on its first
    /// call and kept when the weights are constants (a trainable layer's weights change under
    /// the optimiser, so its transposes are made afresh on every call).
    transposed: OnceLock<[Tensor; 4]>,
}

impl EncoderLayer {
    /// Loads `{vb}.self_attn.*`, `linear1`, `linear2`, `norm1`, `norm2`.
    pub fn new(vb: &VarBuilder, cfg: &MdmConfig, loader: &mut ParamLoader) -> Result<Self> {
        let d = cfg.latent_dim;
        let attn = vb.pp("self_attn");
        // MultiheadAttention._reset_parameters: xavier_uniform in_proj, zero biases.
        let xavier = (6.0 / (d + 3 * d) as f64).sqrt();
        let in_w = loader.get(&attn, (3 * d, d), "in_proj_weight", Init::Uniform { lo: -xavier, up: xavier })?;
        let in_b = loader.get(&attn, 3 * d, "in_proj_bias", Init::Const(0.0))?;
        let out_vb = attn.pp("out_proj");
        let bound = 1.0 / (d as f64).sqrt();
        let out_w = loader.get(&out_vb, (d, d), "weight", Init::Uniform { lo: -bound, up: bound })?;
        let out_b = loader.get(&out_vb, d, "bias", Init::Const(0.0))?;
        Ok(Self {
            in_proj: Linear::new(in_w, Some(in_b))?,
            out_proj: Linear::new(out_w, Some(out_b))?,
            linear1: loader.linear(&vb.pp("linear1"), d, cfg.ff_size)?,
            linear2: loader.linear(&vb.pp("linear2"), cfg.ff_size, d)?,
            norm1: loader.layer_norm(&vb.pp("norm1"), d)?,
            norm2: loader.layer_norm(&vb.pp("norm2"), d)?,
            num_heads: cfg.num_heads,
            transposed: OnceLock::new(),
        })
    }

    /// Training path, `[batch, tokens, d] → [batch, tokens, d]`: every op with weights is a
    /// primitive candle op, so weight gradients flow; softmax and GELU (no weights) are the
    /// fused [`nn::ops`] kernels, which give the same input gradient at a quarter of the
    /// memory traffic. Dropout as PyTorch in training mode: on the attention probabilities,
    /// after attention, after the GELU and after the second linear.
    pub fn forward(&self, h: &Tensor, drop: &mut Dropout) -> Result<Tensor> {
        let a = self.attention(h, drop)?;
        let a = drop.apply(&a)?;
        let h1 = self.norm1.forward(&(h + a)?)?;
        let f = drop.apply(&nn::ops::gelu_erf(&self.linear1.forward(&h1)?)?)?;
        let f = drop.apply(&self.linear2.forward(&f)?)?;
        self.norm2.forward(&(h1 + f)?)
    }

    fn attention(&self, h: &Tensor, drop: &mut Dropout) -> Result<Tensor> {
        let (b, s, d) = h.dims3()?;
        let heads = self.num_heads;
        let hd = d / heads;
        let qkv = self.in_proj.forward(h)?;
        let split = |part: usize| -> Result<Tensor> {
            qkv.narrow(2, part * d, d)?.reshape((b, s, heads, hd))?.transpose(1, 2)?.contiguous()
        };
        let q = (split(0)? * (1.0 / (hd as f64).sqrt()))?;
        let (k, v) = (split(1)?, split(2)?);
        let probs = nn::ops::softmax(&q.matmul(&k.t()?)?)?;
        let probs = drop.apply(&probs)?;
        let ctx = probs.matmul(&v)?.transpose(1, 2)?.reshape((b, s, d))?;
        self.out_proj.forward(&ctx)
    }

    /// `Wᵀ` (contiguous `[in, out]`) of the four linears, cached when no weight is a variable.
    fn transposed_weights(&self) -> Result<[Tensor; 4]> {
        if let Some(t) = self.transposed.get() {
            return Ok(t.clone());
        }
        let linears = [&self.in_proj, &self.out_proj, &self.linear1, &self.linear2];
        let t = |l: &Linear| l.weight().detach().t()?.contiguous();
        let made = [t(linears[0])?, t(linears[1])?, t(linears[2])?, t(linears[3])?];
        if linears.iter().all(|l| !l.weight().is_variable()) {
            // Another thread may have filled it meanwhile with the same values.
            let _ = self.transposed.set(made.clone());
        }
        Ok(made)
    }

    fn frozen_weights(&self) -> Result<LayerWeights> {
        let bias = |l: &Linear| -> Result<Tensor> {
            l.bias().map(Tensor::detach).ok_or_else(|| candle_core::Error::Msg("encoder linear without bias".into()))
        };
        let [in_t, out_t, l1_t, l2_t] = self.transposed_weights()?;
        Ok(LayerWeights {
            in_proj_weight: self.in_proj.weight().detach(),
            in_proj_weight_t: in_t,
            in_proj_bias: bias(&self.in_proj)?,
            out_proj_weight: self.out_proj.weight().detach(),
            out_proj_weight_t: out_t,
            out_proj_bias: bias(&self.out_proj)?,
            linear1_weight: self.linear1.weight().detach(),
            linear1_weight_t: l1_t,
            linear1_bias: bias(&self.linear1)?,
            linear2_weight: self.linear2.weight().detach(),
            linear2_weight_t: l2_t,
            linear2_bias: bias(&self.linear2)?,
            norm1_weight: self.norm1.weight().detach(),
            norm1_bias: self.norm1.bias().detach(),
            norm2_weight: self.norm2.weight().detach(),
            norm2_bias: self.norm2.bias().detach(),
        })
    }
}

/// Frozen-weight path of a stack of layers, `[batch, tokens, d] → [batch, tokens, d]`, or with
/// `ends` a whole denoiser pass `[batch, frames, F] → [batch, frames, F]` (see [`Ends`]): one
/// fused custom op on the CPU (input gradient only, [`FusedEncoderStack`]) whose kernels run
/// on `isa`. Elsewhere the layers' primitive path without dropout (callers handle the ends
/// there). Errors on an empty stack.
pub(crate) fn frozen_stack(layers: &[EncoderLayer], h: &Tensor, ends: Option<Ends>, isa: Isa) -> Result<Tensor> {
    let Some(first) = layers.first() else {
        candle_core::bail!("an encoder stack needs at least one layer");
    };
    if !nn::ops::has_cpu_kernel(h) {
        if ends.is_some() {
            candle_core::bail!("the fused denoiser runs on the CPU only");
        }
        let mut h = h.clone();
        for layer in layers {
            h = layer.forward(&h, &mut Dropout { p: 0.0, rng: None })?;
        }
        return Ok(h);
    }
    let weights = layers.iter().map(EncoderLayer::frozen_weights).collect::<Result<Vec<_>>>()?;
    let keep_activations = h.track_op();
    h.contiguous()?.apply_op1(FusedEncoderStack::new(
        weights,
        ends,
        first.num_heads,
        first.norm1.eps(),
        isa,
        keep_activations,
    ))
}
