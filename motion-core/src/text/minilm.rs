//! all-MiniLM-L6-v2 sentence encoder: prompts → 384-d unit vectors.
//!
//! The sentence-transformers pipeline of `sentence-transformers/all-MiniLM-L6-v2` (Wang et al.
//! 2020, "MiniLM", fine-tuned on 1B sentence pairs), written out in three steps:
//!
//! 1. **Transformer**: WordPiece ids `[CLS] … [SEP]` (lower-cased, at most
//!    [`MiniLmConfig::max_seq_length`] = 256 ids *including* the two special tokens, as
//!    sentence-transformers' `max_seq_length` counts them), a batch right-padded to its longest
//!    prompt, through a 6-layer BERT (candle-transformers' [`BertModel`]): `[N, T, 384]`.
//! 2. **Pooling (mean)**: the mean of the token states over the attention mask, padding
//!    excluded: `[N, 384]`.
//! 3. **Normalize**: each row divided by its L2 norm.
//!
//! Weights and tokenizer ship in `fixtures/text/all-MiniLM-L6-v2/` (f16, see its `PROVENANCE.md`);
//! [`MiniLm::load`] reads f32, f16 or bf16 safetensors with the Hugging Face `BertModel` names
//! and always computes in f32.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
pub use candle_transformers::models::bert::Config as BertConfig;
use candle_transformers::models::bert::{BertModel, HiddenAct, PositionEmbeddingType};
use tokenizers::{Tokenizer, TruncationParams};

use crate::nn::unit_rows;

use super::encoder::TextEncoder;
use super::weights::{no_extra_layer, take_tensor, EncoderError, TensorProblem};

/// The weights file [`MiniLm::load`] reads from its folder.
pub const WEIGHTS_FILE: &str = "model.safetensors";
/// The tokenizer file [`MiniLm::load`] reads from its folder.
pub const TOKENIZER_FILE: &str = "tokenizer.json";
/// BERT's classification token, first in every sequence.
pub const CLS: &str = "[CLS]";
/// BERT's separator token, last in every sequence.
pub const SEP: &str = "[SEP]";
/// The tensor names a MiniLM checkpoint must have.
const BERT_NAMES: &str = "Hugging Face BertModel names; see fixtures/text/convert_minilm.py";

/// The encoder's shape and its tokenisation.
#[derive(Debug, Clone, PartialEq)]
pub struct MiniLmConfig {
    /// The BERT sizes (the upstream `config.json`).
    pub bert: BertConfig,
    /// sentence-transformers' `max_seq_length` (the upstream `sentence_bert_config.json`): ids
    /// kept per prompt, `[CLS]` and `[SEP]` included; longer prompts lose their last word pieces.
    pub max_seq_length: usize,
}

impl MiniLmConfig {
    /// all-MiniLM-L6-v2: 6 layers, hidden 384, 12 heads, intermediate 1536 (exact-erf GELU),
    /// vocabulary 30522, 512 positions, 2 token types, layer-norm ε 1e-12, padding id 0; at most
    /// 256 ids per prompt. Equal to the upstream `config.json` and `sentence_bert_config.json`
    /// (shipped beside the weights; a test checks they agree).
    pub fn all_minilm_l6_v2() -> Self {
        Self {
            bert: BertConfig {
                vocab_size: 30522,
                hidden_size: 384,
                num_hidden_layers: 6,
                num_attention_heads: 12,
                intermediate_size: 1536,
                hidden_act: HiddenAct::Gelu,
                hidden_dropout_prob: 0.1,
                max_position_embeddings: 512,
                type_vocab_size: 2,
                initializer_range: 0.02,
                layer_norm_eps: 1e-12,
                pad_token_id: 0,
                position_embedding_type: PositionEmbeddingType::Absolute,
                use_cache: true,
                classifier_dropout: None,
                model_type: Some("bert".to_owned()),
            },
            max_seq_length: 256,
        }
    }
}

/// all-MiniLM-L6-v2: prompts → `[N, 384]` L2-normalised sentence embeddings, f32.
pub struct MiniLm {
    bert: BertModel,
    tokenizer: Tokenizer,
    config: MiniLmConfig,
    device: Device,
}

impl std::fmt::Debug for MiniLm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MiniLm").field("config", &self.config).field("device", &self.device).finish()
    }
}

impl MiniLm {
    /// Loads all-MiniLM-L6-v2 ([`MiniLmConfig::all_minilm_l6_v2`]) from a folder holding
    /// [`WEIGHTS_FILE`] and [`TOKENIZER_FILE`], e.g. `fixtures/text/all-MiniLM-L6-v2`, or the
    /// unzipped upstream model (its extra `pooler.*` and `embeddings.position_ids` are ignored).
    pub fn load(dir: &Path, device: &Device) -> Result<Self, EncoderError> {
        Self::load_with_config(dir, MiniLmConfig::all_minilm_l6_v2(), device)
    }

    /// [`MiniLm::load`] for any BERT shape (tests use a tiny one).
    pub fn load_with_config(dir: &Path, config: MiniLmConfig, device: &Device) -> Result<Self, EncoderError> {
        let bert = &config.bert;
        if config.max_seq_length < 2 || config.max_seq_length > bert.max_position_embeddings {
            return Err(EncoderError::Config(format!(
                "MiniLM max_seq_length {} must be in 2..={} (the positions)",
                config.max_seq_length, bert.max_position_embeddings
            )));
        }
        if bert.hidden_size.checked_rem(bert.num_attention_heads) != Some(0) {
            return Err(EncoderError::Config(format!(
                "MiniLM hidden size {} is not divisible by {} heads",
                bert.hidden_size, bert.num_attention_heads
            )));
        }
        if bert.pad_token_id >= bert.vocab_size {
            return Err(EncoderError::Config(format!(
                "MiniLM padding id {} is outside the vocabulary of {}",
                bert.pad_token_id, bert.vocab_size
            )));
        }
        let weights = dir.join(WEIGHTS_FILE);
        let tensors = candle_core::safetensors::load(&weights, device)
            .map_err(|source| EncoderError::Weights { path: weights.clone(), source })?;
        let tensors = bert_tensors(tensors, bert).map_err(|e| e.at(&weights, BERT_NAMES))?;
        let vb = VarBuilder::from_tensors(tensors, DType::F32, device);
        let model = BertModel::load(vb, bert)?;
        let tokenizer = load_tokenizer(&dir.join(TOKENIZER_FILE), &config)?;
        Ok(Self { bert: model, tokenizer, config, device: device.clone() })
    }

    /// The configuration the encoder was loaded with.
    pub fn config(&self) -> &MiniLmConfig {
        &self.config
    }

    /// Width of an embedding (384).
    pub fn embedding_dim(&self) -> usize {
        self.config.bert.hidden_size
    }

    /// The device the weights live on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The ids of one prompt, unpadded: `[CLS, word pieces…, SEP]`, at most
    /// [`MiniLmConfig::max_seq_length`] long (the first word pieces are kept).
    pub fn tokenize(&self, prompt: &str) -> Result<Vec<u32>, EncoderError> {
        self.tokenize_prompt(0, prompt)
    }

    fn tokenize_prompt(&self, index: usize, prompt: &str) -> Result<Vec<u32>, EncoderError> {
        let encoding = self
            .tokenizer
            .encode(prompt, true)
            .map_err(|e| EncoderError::Tokenize { index, message: e.to_string() })?;
        Ok(encoding.get_ids().to_vec())
    }

    /// Encodes prompts: `[N, 384]`, f32, each row of unit length (an empty list gives `[0, 384]`).
    /// The batch is padded to its longest prompt; padding changes no row beyond float rounding.
    pub fn encode(&self, prompts: &[&str]) -> Result<Tensor, EncoderError> {
        let n = prompts.len();
        if n == 0 {
            return Ok(Tensor::zeros((0, self.embedding_dim()), DType::F32, &self.device)?);
        }
        let sequences =
            prompts.iter().enumerate().map(|(i, p)| self.tokenize_prompt(i, p)).collect::<Result<Vec<_>, _>>()?;
        let len = sequences.iter().map(Vec::len).max().unwrap_or(0);
        let (mut ids, mut mask) = (Vec::with_capacity(n * len), Vec::with_capacity(n * len));
        for (row, seq) in sequences.iter().enumerate() {
            ids.extend_from_slice(seq);
            ids.resize((row + 1) * len, self.config.bert.pad_token_id as u32);
            mask.resize(mask.len() + seq.len(), 1u32);
            mask.resize((row + 1) * len, 0);
        }
        let ids = Tensor::from_vec(ids, (n, len), &self.device)?;
        let mask = Tensor::from_vec(mask, (n, len), &self.device)?;
        let token_types = ids.zeros_like()?;
        let hidden = self.bert.forward(&ids, &token_types, Some(&mask))?;
        Ok(unit_rows(&mean_pool(&hidden, &mask)?)?)
    }
}

impl TextEncoder for MiniLm {
    fn dim(&self) -> usize {
        self.embedding_dim()
    }

    fn encode(&self, prompts: &[&str], device: &Device) -> candle_core::Result<Tensor> {
        MiniLm::encode(self, prompts).map_err(candle_core::Error::wrap)?.to_device(device)
    }
}

/// sentence-transformers' mean pooling: `Σ_t mask[n,t] · hidden[n,t,:] / max(Σ_t mask[n,t], 1e-9)`.
/// `hidden` `[N, T, H]`, `mask` `[N, T]` of 0/1 (any dtype) → `[N, H]`.
fn mean_pool(hidden: &Tensor, mask: &Tensor) -> candle_core::Result<Tensor> {
    let mask = mask.to_dtype(hidden.dtype())?;
    let summed = hidden.broadcast_mul(&mask.unsqueeze(2)?)?.sum(1)?;
    let counts = mask.sum_keepdim(1)?.clamp(1e-9, f64::MAX)?;
    summed.broadcast_div(&counts)
}

/// Loads `tokenizer.json` with sentence-transformers' truncation (`max_seq_length` ids, special
/// tokens included) and without its own padding (the file pads to 128; we pad to the batch),
/// and checks that it is BERT's: `[CLS] … [SEP]` around every prompt, every id in the table.
fn load_tokenizer(path: &Path, config: &MiniLmConfig) -> Result<Tokenizer, EncoderError> {
    let err = |message: String| EncoderError::Tokenizer { path: path.to_path_buf(), message };
    let mut tokenizer = Tokenizer::from_file(path).map_err(|e| err(e.to_string()))?;
    tokenizer
        .with_truncation(Some(TruncationParams { max_length: config.max_seq_length, ..Default::default() }))
        .map_err(|e| err(e.to_string()))?;
    tokenizer.with_padding(None);
    let mismatch = |message: String| EncoderError::TokenizerMismatch { path: path.to_path_buf(), message };
    let special = |token: &str| tokenizer.token_to_id(token).ok_or_else(|| mismatch(format!("no token `{token}`")));
    let (cls, sep) = (special(CLS)?, special(SEP)?);
    let empty = tokenizer.encode("", true).map_err(|e| err(e.to_string()))?;
    if empty.get_ids() != [cls, sep] {
        return Err(mismatch(format!(
            "the empty prompt tokenises to {:?}, not [{CLS}, {SEP}] = [{cls}, {sep}] (not a BERT post-processor)",
            empty.get_ids()
        )));
    }
    let vocab_size = config.bert.vocab_size;
    if let Some(max) = tokenizer.get_vocab(true).values().max().filter(|&&id| id as usize >= vocab_size) {
        return Err(mismatch(format!("token id {max} does not fit the embedding table of {vocab_size} rows")));
    }
    Ok(tokenizer)
}

/// The tensors [`BertModel`] reads, under its names, with the shape `c` implies:
/// `embeddings.{word,position,token_type}_embeddings.weight`, `embeddings.LayerNorm.{weight,bias}`
/// and per layer N `encoder.layer.N.` + `attention.self.{query,key,value}`,
/// `attention.output.{dense,LayerNorm}`, `intermediate.dense`, `output.{dense,LayerNorm}`
/// (`.weight` `[out, in]` and `.bias` `[out]`; 16 per layer).
fn expected_shapes(c: &BertConfig) -> Vec<(String, Vec<usize>)> {
    let (h, i) = (c.hidden_size, c.intermediate_size);
    let mut shapes = vec![
        ("embeddings.word_embeddings.weight".to_owned(), vec![c.vocab_size, h]),
        ("embeddings.position_embeddings.weight".to_owned(), vec![c.max_position_embeddings, h]),
        ("embeddings.token_type_embeddings.weight".to_owned(), vec![c.type_vocab_size, h]),
        ("embeddings.LayerNorm.weight".to_owned(), vec![h]),
        ("embeddings.LayerNorm.bias".to_owned(), vec![h]),
    ];
    for n in 0..c.num_hidden_layers {
        for (name, out, inp) in [
            ("attention.self.query", h, h),
            ("attention.self.key", h, h),
            ("attention.self.value", h, h),
            ("attention.output.dense", h, h),
            ("intermediate.dense", i, h),
            ("output.dense", h, i),
        ] {
            shapes.push((format!("encoder.layer.{n}.{name}.weight"), vec![out, inp]));
            shapes.push((format!("encoder.layer.{n}.{name}.bias"), vec![out]));
        }
        for name in ["attention.output.LayerNorm", "output.LayerNorm"] {
            shapes.push((format!("encoder.layer.{n}.{name}.weight"), vec![h]));
            shapes.push((format!("encoder.layer.{n}.{name}.bias"), vec![h]));
        }
    }
    shapes
}

/// Picks BERT's tensors out of a checkpoint, checking each name, shape and float type, as f32.
/// Others (BERT's `pooler.*`, the `embeddings.position_ids` buffer) are ignored; a layer beyond
/// the configured ones is an error.
fn bert_tensors(mut src: HashMap<String, Tensor>, c: &BertConfig) -> Result<HashMap<String, Tensor>, TensorProblem> {
    let mut out = HashMap::new();
    for (key, expected) in expected_shapes(c) {
        let t = take_tensor(&mut src, &key, &expected)?;
        out.insert(key, t);
    }
    no_extra_layer(&src, "encoder.layer.", c.num_hidden_layers)?;
    Ok(out)
}

#[cfg(test)]
mod tests;
