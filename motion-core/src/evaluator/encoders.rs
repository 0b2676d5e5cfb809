//! The text–motion contrastive pair: its sizes, its two encoders and its file.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{DType, Device, Result, Tensor, D};
use candle_nn::{VarBuilder, VarMap};
use rand::rngs::StdRng;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};

use super::error::EvaluatorError;
use crate::model::init::SeededInit;
use crate::model::layer::{Dropout, EncoderLayer, ParamLoader};
use crate::model::{sinusoidal_table, MdmConfig, MAX_LEN};
use crate::nn::{unit_rows, Linear};
use crate::representation::{MeanStd, FEATURE_DIM};
use crate::tensor_file::{read_metadata, write_safetensors};

/// Sizes of the evaluator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvaluatorConfig {
    /// Token width of the motion encoder (default 128).
    pub width: usize,
    /// Feed-forward width of its layers (default 256).
    pub ff_size: usize,
    /// Encoder layers (default 2).
    pub layers: usize,
    /// Attention heads (default 4).
    pub heads: usize,
    /// Width of the shared embedding space (default 128).
    pub embedding: usize,
    /// Width of the sentence embeddings the text head reads (384: all-MiniLM-L6-v2).
    pub text_dim: usize,
    /// InfoNCE temperature τ (default 0.1, TMR's).
    pub temperature: f64,
}

impl Default for EvaluatorConfig {
    fn default() -> Self {
        Self { width: 128, ff_size: 256, layers: 2, heads: 4, embedding: 128, text_dim: 384, temperature: 0.1 }
    }
}

impl EvaluatorConfig {
    /// The denoiser configuration whose encoder layers have these sizes.
    fn layer_config(&self) -> MdmConfig {
        MdmConfig {
            latent_dim: self.width,
            ff_size: self.ff_size,
            num_layers: self.layers,
            num_heads: self.heads,
            text_dim: self.text_dim,
            dropout: 0.0,
            ..MdmConfig::small()
        }
    }
}

/// The text–motion contrastive pair; see the [module doc](super).
#[derive(Debug, Clone)]
pub struct Evaluator {
    config: EvaluatorConfig,
    input: Linear,
    layers: Vec<EncoderLayer>,
    motion_out: Linear,
    text_hidden: Linear,
    text_out: Linear,
    /// Sinusoidal positions `[MAX_LEN, width]`.
    pe: Tensor,
    /// The normalisation of the features it reads (its training data's).
    mean_std: MeanStd,
    params: Vec<(String, Tensor)>,
}

const CONFIG_KEY: &str = "evaluator_config";
const MEAN_KEY: &str = "normalization.mean";
const STD_KEY: &str = "normalization.std";

impl Evaluator {
    /// Builds the evaluator from `vb` (names `input`, `layers.{i}.*`, `motion_out`,
    /// `text_hidden`, `text_out`) for features normalised by `mean_std`; a `VarMap` backend
    /// creates missing parameters.
    pub fn new(config: EvaluatorConfig, mean_std: MeanStd, vb: VarBuilder) -> Result<Self> {
        let layer_config = config.layer_config();
        layer_config.validate()?;
        let mut params = Vec::new();
        let mut loader = ParamLoader { named: &mut params };
        let input = loader.linear(&vb.pp("input"), FEATURE_DIM, config.width)?;
        let layers = (0..config.layers)
            .map(|i| EncoderLayer::new(&vb.pp("layers").pp(i), &layer_config, &mut loader))
            .collect::<Result<Vec<_>>>()?;
        let motion_out = loader.linear(&vb.pp("motion_out"), config.width, config.embedding)?;
        let text_hidden = loader.linear(&vb.pp("text_hidden"), config.text_dim, config.width)?;
        let text_out = loader.linear(&vb.pp("text_out"), config.width, config.embedding)?;
        let pe = sinusoidal_table(MAX_LEN, config.width, vb.device())?;
        Ok(Self { config, input, layers, motion_out, text_hidden, text_out, pe, mean_std, params })
    }

    /// A trainable evaluator: missing parameters are created in `varmap` as `Var`s with
    /// PyTorch's default init drawn from `StdRng::seed_from_u64(seed)`.
    pub fn init_seeded(
        config: EvaluatorConfig,
        mean_std: MeanStd,
        varmap: &VarMap,
        device: &Device,
        seed: u64,
    ) -> Result<Self> {
        let backend = SeededInit::new(varmap.clone(), StdRng::seed_from_u64(seed));
        Self::new(config, mean_std, VarBuilder::from_backend(Box::new(backend), DType::F32, device.clone()))
    }

    /// Loads an evaluator file written by [`Evaluator::save`].
    pub fn load(path: &Path, device: &Device) -> std::result::Result<Self, EvaluatorError> {
        let err = |message: String| EvaluatorError::File { path: path.into(), message };
        let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
        let meta = read_metadata(&bytes).map_err(err)?;
        let config: EvaluatorConfig = serde_json::from_str(
            meta.get(CONFIG_KEY).ok_or_else(|| err(format!("no `{CONFIG_KEY}` in the header metadata")))?,
        )
        .map_err(|e| err(format!("bad {CONFIG_KEY}: {e}")))?;
        let tensors = candle_core::safetensors::load_buffer(&bytes, device).map_err(|e| err(e.to_string()))?;
        let stat = |key: &str| -> std::result::Result<Vec<f32>, EvaluatorError> {
            tensors
                .get(key)
                .ok_or_else(|| err(format!("missing tensor `{key}`")))?
                .to_vec1::<f32>()
                .map_err(|e| err(format!("tensor `{key}`: {e}")))
        };
        let mean_std = MeanStd::from_vecs(stat(MEAN_KEY)?, stat(STD_KEY)?, device).map_err(|e| err(e.to_string()))?;
        Self::new(config, mean_std, VarBuilder::from_tensors(tensors, DType::F32, device))
            .map_err(|e| err(e.to_string()))
    }

    /// Writes the parameters and the configuration as one safetensors file.
    pub fn save(&self, path: &Path) -> std::result::Result<(), EvaluatorError> {
        let err = |message: String| EvaluatorError::File { path: path.into(), message };
        let metadata = HashMap::from([(
            CONFIG_KEY.to_owned(),
            serde_json::to_string(&self.config).map_err(|e| err(e.to_string()))?,
        )]);
        let mut tensors: Vec<(String, Tensor)> = self.params.iter().map(|(n, t)| (n.clone(), t.detach())).collect();
        tensors.push((MEAN_KEY.into(), self.mean_std.mean().clone()));
        tensors.push((STD_KEY.into(), self.mean_std.std().clone()));
        write_safetensors(path, &tensors, metadata).map_err(err)
    }

    /// The sizes.
    pub fn config(&self) -> &EvaluatorConfig {
        &self.config
    }

    /// The normalisation of the features [`Evaluator::embed_motion`] reads (its training
    /// data's): normalise raw features with it.
    pub fn mean_std(&self) -> &MeanStd {
        &self.mean_std
    }

    /// Every parameter with its name.
    pub fn named_parameters(&self) -> &[(String, Tensor)] {
        &self.params
    }

    /// Unit motion embeddings `[batch, embedding]` of features `[batch, frames, 263]` normalised
    /// with [`Evaluator::mean_std`] (at most 5,000 frames).
    pub fn embed_motion(&self, x: &Tensor) -> Result<Tensor> {
        let (_, frames, _) = x.dims3()?;
        let mut h = self.input.forward(x)?.broadcast_add(&self.pe.narrow(0, 0, frames)?.unsqueeze(0)?)?;
        let mut no_dropout = Dropout { p: 0.0, rng: None };
        for layer in &self.layers {
            h = layer.forward(&h, &mut no_dropout)?;
        }
        unit_rows(&self.motion_out.forward(&h.mean(1)?)?)
    }

    /// Unit text embeddings `[batch, embedding]` of sentence embeddings `[batch, text_dim]`.
    pub fn embed_text(&self, text: &Tensor) -> Result<Tensor> {
        let h = crate::nn::ops::gelu_erf(&self.text_hidden.forward(text)?)?;
        unit_rows(&self.text_out.forward(&h)?)
    }

    /// Symmetric InfoNCE of a batch (scalar): rows `i` of `motion` and `text` (unit
    /// embeddings `[batch, embedding]`) are the positive pairs; pairs whose captions `same` as
    /// row `i`'s (`same[i][j]`, true on the diagonal) are not negatives.
    pub fn contrastive_loss(&self, motion: &Tensor, text: &Tensor, same: &[Vec<bool>]) -> Result<Tensor> {
        let b = motion.dim(0)?;
        let logits = (motion.matmul(&text.t()?)? / self.config.temperature)?;
        // −∞ (a large negative) where a pair shares the caption but is not the diagonal.
        let mask: Vec<f32> = (0..b)
            .flat_map(|i| (0..b).map(move |j| (i, j)))
            .map(|(i, j)| if i != j && same[i][j] { -1e4 } else { 0.0 })
            .collect();
        let logits = (logits + Tensor::from_vec(mask, (b, b), motion.device())?)?;
        let eye = Tensor::eye(b, DType::F32, motion.device())?;
        let nll = |l: &Tensor| -> Result<Tensor> {
            let log_probs = candle_nn::ops::log_softmax(l, D::Minus1)?;
            (log_probs * &eye)?.sum_all()?.neg()? / b as f64
        };
        (nll(&logits)? + nll(&logits.t()?)?)? * 0.5
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    pub(crate) fn unit() -> MeanStd {
        MeanStd::from_vecs(vec![0.0; FEATURE_DIM], vec![1.0; FEATURE_DIM], &Device::Cpu).unwrap()
    }

    fn tiny() -> EvaluatorConfig {
        EvaluatorConfig { width: 16, ff_size: 32, layers: 1, heads: 2, embedding: 8, text_dim: 6, temperature: 0.1 }
    }

    #[test]
    fn embeddings_are_unit_rows_of_the_embedding_width_and_survive_a_file() {
        let dev = Device::Cpu;
        let varmap = VarMap::new();
        let e = Evaluator::init_seeded(tiny(), unit(), &varmap, &dev, 3).unwrap();
        let x = crate::diffusion::noise::gaussian((3, 20, FEATURE_DIM), 1, &dev).unwrap();
        let m = e.embed_motion(&x).unwrap();
        assert_eq!(m.dims(), &[3, 8]);
        let norms: Vec<f32> = m.sqr().unwrap().sum(1).unwrap().to_vec1().unwrap();
        assert!(norms.iter().all(|n| (n - 1.0).abs() < 1e-5), "{norms:?}");
        let t = e.embed_text(&Tensor::ones((3, 6), DType::F32, &dev).unwrap()).unwrap();
        assert_eq!(t.dims(), &[3, 8]);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("evaluator.safetensors");
        e.save(&path).unwrap();
        let back = Evaluator::load(&path, &dev).unwrap();
        assert_eq!(back.config(), e.config());
        assert_eq!(back.mean_std().std().to_vec1::<f32>().unwrap(), vec![1.0; FEATURE_DIM]);
        assert_eq!(crate::testing::max_abs_diff(&back.embed_motion(&x).unwrap(), &m).unwrap(), 0.0);
        std::fs::write(&path, b"junk").unwrap();
        assert!(Evaluator::load(&path, &dev).unwrap_err().to_string().contains("evaluator.safetensors"));
    }

    #[test]
    fn the_loss_is_low_for_matched_pairs_and_ignores_repeated_captions() {
        let dev = Device::Cpu;
        let e = Evaluator::init_seeded(tiny(), unit(), &VarMap::new(), &dev, 3).unwrap();
        let basis = Tensor::eye(8, DType::F32, &dev).unwrap().narrow(0, 0, 3).unwrap();
        let distinct = vec![vec![true, false, false], vec![false, true, false], vec![false, false, true]];
        let matched = e.contrastive_loss(&basis, &basis, &distinct).unwrap().to_scalar::<f32>().unwrap();
        let swapped = basis.index_select(&Tensor::new(&[1u32, 0, 2], &dev).unwrap(), 0).unwrap();
        let crossed = e.contrastive_loss(&basis, &swapped, &distinct).unwrap().to_scalar::<f32>().unwrap();
        assert!(matched < 0.01 && crossed > 5.0, "matched {matched}, crossed {crossed}");
        // Rows 0 and 1 share a caption: swapping them is no longer a mistake about a negative.
        let shared = vec![vec![true, true, false], vec![true, true, false], vec![false, false, true]];
        let lenient = e.contrastive_loss(&basis, &swapped, &shared).unwrap().to_scalar::<f32>().unwrap();
        assert!(lenient < crossed, "{lenient} against {crossed}");
    }
}
