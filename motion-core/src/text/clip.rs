//! CLIP ViT-B/32 text encoder for official MDM checkpoints.
//!
//! MDM conditions on `clip_model.encode_text(clip.tokenize(text, context_length=22,
//! truncate=True))` (`reference/anchors.md` §1.4): SOT, at most 20 BPE tokens, EOT, zero-padded
//! to 77; a causal pre-LN transformer; `ln_final`; the feature at the EOT position; then
//! `@ text_projection`. The result is a 512-d vector per prompt, not normalised.
//!
//! Weights are user-supplied: a safetensors file with **OpenAI's key names** (the text tower of
//! `ViT-B-32.pt`, converted by `fixtures/clip/convert_openai_clip.py`), and the CLIP
//! `tokenizer.json` (see `fixtures/clip/README.md`). The transformer is candle-transformers'
//! [`ClipTextTransformer`]; this module renames OpenAI's keys to its names and splits the
//! fused attention projection.
//!
//! MDM runs CLIP in fp16 on the GPU; we run f32, so embeddings agree to about 1e-3.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{DType, Device, Tensor};
use candle_nn::VarBuilder;
pub use candle_transformers::models::clip::text_model::ClipTextConfig;
use candle_transformers::models::clip::text_model::ClipTextTransformer;
use tokenizers::Tokenizer;

use super::weights::{no_extra_layer, take_tensor, EncoderError, TensorProblem};

/// CLIP's start-of-text token.
pub const START_OF_TEXT: &str = "<|startoftext|>";
/// CLIP's end-of-text token.
pub const END_OF_TEXT: &str = "<|endoftext|>";
/// The tensor names a CLIP checkpoint must have.
const OPENAI_NAMES: &str = "OpenAI CLIP key names; see fixtures/clip/README.md";

/// The text tower's shape and MDM's tokenisation.
#[derive(Debug, Clone)]
pub struct ClipTextEncoderConfig {
    /// Transformer sizes; `projection_dim` is the width of `text_projection`'s output.
    pub text: ClipTextConfig,
    /// MDM's `clip.tokenize(..., context_length)`: SOT + at most `context_length − 2` BPE tokens
    /// + EOT. The ids are then zero-padded to `text.max_position_embeddings`.
    pub context_length: usize,
}

impl ClipTextEncoderConfig {
    /// ViT-B/32 as MDM uses it for HumanML3D: width 512, 12 layers, 8 heads, vocab 49408,
    /// 77 positions, projection 512, context length 22 (20 BPE tokens).
    pub fn mdm_vit_b32() -> Self {
        Self { text: ClipTextConfig::vit_base_patch32(), context_length: 22 }
    }
}

/// CLIP's text tower with MDM's tokenisation: prompts → `[N, projection_dim]` embeddings.
pub struct ClipTextEncoder {
    transformer: ClipTextTransformer,
    /// `[width, projection_dim]`, applied as `x @ P`.
    projection: Tensor,
    tokenizer: Tokenizer,
    sot: u32,
    eot: u32,
    config: ClipTextEncoderConfig,
    device: Device,
}

impl std::fmt::Debug for ClipTextEncoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClipTextEncoder").field("config", &self.config).field("device", &self.device).finish()
    }
}

impl ClipTextEncoder {
    /// Loads ViT-B/32 ([`ClipTextEncoderConfig::mdm_vit_b32`]) from OpenAI-named safetensors
    /// weights and a CLIP `tokenizer.json`.
    pub fn load(weights: &Path, tokenizer: &Path, device: &Device) -> Result<Self, EncoderError> {
        Self::load_with_config(weights, tokenizer, ClipTextEncoderConfig::mdm_vit_b32(), device)
    }

    /// [`ClipTextEncoder::load`] for any text-tower shape (tests use a tiny one).
    pub fn load_with_config(
        weights: &Path,
        tokenizer: &Path,
        config: ClipTextEncoderConfig,
        device: &Device,
    ) -> Result<Self, EncoderError> {
        let text = &config.text;
        if config.context_length < 2 || config.context_length > text.max_position_embeddings {
            return Err(EncoderError::Config(format!(
                "CLIP context length {} must be in 2..={} (the positions)",
                config.context_length, text.max_position_embeddings
            )));
        }
        if text.embed_dim.checked_rem(text.num_attention_heads) != Some(0) {
            return Err(EncoderError::Config(format!(
                "CLIP width {} is not divisible by {} heads",
                text.embed_dim, text.num_attention_heads
            )));
        }
        let tensors = candle_core::safetensors::load(weights, device)
            .map_err(|source| EncoderError::Weights { path: weights.to_path_buf(), source })?;
        let (renamed, projection) = rename_openai_keys(tensors, text).map_err(|e| e.at(weights, OPENAI_NAMES))?;
        let vb = VarBuilder::from_tensors(renamed, DType::F32, device);
        let transformer = ClipTextTransformer::new(vb, text)?;

        let (tokenizer, sot, eot) = load_tokenizer(tokenizer, text.vocab_size)?;
        Ok(Self { transformer, projection, tokenizer, sot, eot, config, device: device.clone() })
    }

    /// The configuration the encoder was loaded with.
    pub fn config(&self) -> &ClipTextEncoderConfig {
        &self.config
    }

    /// Width of an embedding (512 for ViT-B/32).
    pub fn embedding_dim(&self) -> usize {
        self.config.text.projection_dim
    }

    /// MDM's token ids for one prompt, unpadded: `[SOT, ≤ context_length − 2 BPE ids, EOT]`.
    /// Truncation keeps the first BPE tokens, as `clip.tokenize(..., truncate=True)` does.
    pub fn tokenize(&self, prompt: &str) -> Result<Vec<u32>, EncoderError> {
        self.tokenize_prompt(0, prompt)
    }

    fn tokenize_prompt(&self, index: usize, prompt: &str) -> Result<Vec<u32>, EncoderError> {
        let encoding = self
            .tokenizer
            .encode(prompt, false)
            .map_err(|e| EncoderError::Tokenize { index, message: e.to_string() })?;
        let keep = self.config.context_length - 2;
        let mut ids = Vec::with_capacity(self.config.context_length);
        ids.push(self.sot);
        ids.extend(encoding.get_ids().iter().take(keep));
        ids.push(self.eot);
        Ok(ids)
    }

    /// Encodes prompts: `[N, projection_dim]`, f32, one row per prompt (MDM's `encode_text`).
    pub fn encode(&self, prompts: &[&str]) -> Result<Tensor, EncoderError> {
        let positions = self.config.text.max_position_embeddings;
        if prompts.is_empty() {
            return Ok(Tensor::zeros((0, self.embedding_dim()), DType::F32, &self.device)?);
        }
        let mut ids = Vec::with_capacity(prompts.len() * positions);
        let mut eot_rows = Vec::with_capacity(prompts.len());
        for (index, prompt) in prompts.iter().enumerate() {
            let tokens = self.tokenize_prompt(index, prompt)?;
            // The EOT position is where OpenAI's `text.argmax(-1)` lands (EOT has the largest id).
            eot_rows.push((index * positions + tokens.len() - 1) as u32);
            ids.extend_from_slice(&tokens);
            ids.resize((index + 1) * positions, 0);
        }
        let ids = Tensor::from_vec(ids, (prompts.len(), positions), &self.device)?;
        let hidden = self.transformer.forward_with_mask(&ids, usize::MAX)?;
        let width = hidden.dim(2)?;
        let eot_rows = Tensor::from_vec(eot_rows, prompts.len(), &self.device)?;
        let pooled = hidden.reshape((prompts.len() * positions, width))?.index_select(&eot_rows, 0)?;
        Ok(pooled.matmul(&self.projection)?)
    }
}

/// Loads `tokenizer.json` with its own truncation and padding switched off (we apply MDM's),
/// checks that every id fits the embedding table, and returns the SOT and EOT ids.
fn load_tokenizer(path: &Path, vocab_size: usize) -> Result<(Tokenizer, u32, u32), EncoderError> {
    let err = |message: String| EncoderError::Tokenizer { path: path.to_path_buf(), message };
    let mut tokenizer = Tokenizer::from_file(path).map_err(|e| err(e.to_string()))?;
    tokenizer.with_truncation(None).map_err(|e| err(e.to_string()))?;
    tokenizer.with_padding(None);
    let mismatch = |message: String| EncoderError::TokenizerMismatch { path: path.to_path_buf(), message };
    let special = |token: &str| tokenizer.token_to_id(token).ok_or_else(|| mismatch(format!("no token `{token}`")));
    let (sot, eot) = (special(START_OF_TEXT)?, special(END_OF_TEXT)?);
    if let Some(max) = tokenizer.get_vocab(true).values().max().filter(|&&id| id as usize >= vocab_size) {
        return Err(mismatch(format!("token id {max} does not fit the embedding table of {vocab_size} rows")));
    }
    Ok((tokenizer, sot, eot))
}

/// Maps OpenAI's text-tower tensors to candle-transformers' names (f32), checking every shape;
/// returns them with `text_projection` `[width, projection_dim]`. Other keys (the vision
/// tower, `logit_scale`) are ignored.
///
/// | OpenAI | candle-transformers |
/// |---|---|
/// | `token_embedding.weight` | `embeddings.token_embedding.weight` |
/// | `positional_embedding` | `embeddings.position_embedding.weight` |
/// | `transformer.resblocks.N.ln_1` / `ln_2` | `encoder.layers.N.layer_norm1` / `layer_norm2` |
/// | `transformer.resblocks.N.attn.in_proj_{weight,bias}` (rows q, k, v) | `encoder.layers.N.self_attn.{q,k,v}_proj` |
/// | `transformer.resblocks.N.attn.out_proj` | `encoder.layers.N.self_attn.out_proj` |
/// | `transformer.resblocks.N.mlp.c_fc` / `c_proj` | `encoder.layers.N.mlp.fc1` / `fc2` |
/// | `ln_final` | `final_layer_norm` |
fn rename_openai_keys(
    mut src: HashMap<String, Tensor>,
    c: &ClipTextConfig,
) -> Result<(HashMap<String, Tensor>, Tensor), TensorProblem> {
    let (w, mlp) = (c.embed_dim, c.intermediate_size);
    let mut take = |key: &str, expected: &[usize]| take_tensor(&mut src, key, expected);
    let mut out = HashMap::new();
    out.insert("embeddings.token_embedding.weight".into(), take("token_embedding.weight", &[c.vocab_size, w])?);
    out.insert(
        "embeddings.position_embedding.weight".into(),
        take("positional_embedding", &[c.max_position_embeddings, w])?,
    );
    for n in 0..c.num_hidden_layers {
        let (from, to) = (format!("transformer.resblocks.{n}"), format!("encoder.layers.{n}"));
        for (a, b, shape_w, shape_b) in [
            ("ln_1", "layer_norm1", vec![w], w),
            ("ln_2", "layer_norm2", vec![w], w),
            ("attn.out_proj", "self_attn.out_proj", vec![w, w], w),
            ("mlp.c_fc", "mlp.fc1", vec![mlp, w], mlp),
            ("mlp.c_proj", "mlp.fc2", vec![w, mlp], w),
        ] {
            out.insert(format!("{to}.{b}.weight"), take(&format!("{from}.{a}.weight"), &shape_w)?);
            out.insert(format!("{to}.{b}.bias"), take(&format!("{from}.{a}.bias"), &[shape_b])?);
        }
        // nn.MultiheadAttention stacks the q, k and v projections row-wise.
        let in_w = take(&format!("{from}.attn.in_proj_weight"), &[3 * w, w])?;
        let in_b = take(&format!("{from}.attn.in_proj_bias"), &[3 * w])?;
        for (i, qkv) in ["q_proj", "k_proj", "v_proj"].iter().enumerate() {
            out.insert(format!("{to}.self_attn.{qkv}.weight"), in_w.narrow(0, i * w, w)?.contiguous()?);
            out.insert(format!("{to}.self_attn.{qkv}.bias"), in_b.narrow(0, i * w, w)?.contiguous()?);
        }
    }
    out.insert("final_layer_norm.weight".into(), take("ln_final.weight", &[w])?);
    out.insert("final_layer_norm.bias".into(), take("ln_final.bias", &[w])?);
    let projection = take("text_projection", &[w, c.projection_dim])?;
    no_extra_layer(&src, "transformer.resblocks.", c.num_hidden_layers)?;
    Ok((out, projection))
}

#[cfg(test)]
mod tests {
    use candle_transformers::models::clip::text_model::Activation;

    use std::path::PathBuf;

    use super::*;

    const WIDTH: usize = 32;
    const PROJ: usize = 16;
    const LAYERS: usize = 2;
    const VOCAB: usize = 64;

    fn tiny_config() -> ClipTextEncoderConfig {
        ClipTextEncoderConfig {
            text: ClipTextConfig {
                vocab_size: VOCAB,
                embed_dim: WIDTH,
                activation: Activation::QuickGelu,
                intermediate_size: 4 * WIDTH,
                max_position_embeddings: 12,
                pad_with: None,
                num_hidden_layers: LAYERS,
                num_attention_heads: 2,
                projection_dim: PROJ,
            },
            context_length: 8,
        }
    }

    /// Random text-tower weights under OpenAI's key names, plus a vision key to be ignored.
    fn openai_weights(dev: &Device) -> HashMap<String, Tensor> {
        let c = tiny_config().text;
        let (w, m) = (c.embed_dim, c.intermediate_size);
        let mut shapes: Vec<(String, Vec<usize>)> = vec![
            ("token_embedding.weight".into(), vec![VOCAB, w]),
            ("positional_embedding".into(), vec![c.max_position_embeddings, w]),
            ("ln_final.weight".into(), vec![w]),
            ("ln_final.bias".into(), vec![w]),
            ("text_projection".into(), vec![w, PROJ]),
            ("visual.proj".into(), vec![3, 3]),
        ];
        for n in 0..LAYERS {
            let p = format!("transformer.resblocks.{n}");
            for (k, s) in [
                ("ln_1.weight", vec![w]),
                ("ln_1.bias", vec![w]),
                ("ln_2.weight", vec![w]),
                ("ln_2.bias", vec![w]),
                ("attn.in_proj_weight", vec![3 * w, w]),
                ("attn.in_proj_bias", vec![3 * w]),
                ("attn.out_proj.weight", vec![w, w]),
                ("attn.out_proj.bias", vec![w]),
                ("mlp.c_fc.weight", vec![m, w]),
                ("mlp.c_fc.bias", vec![m]),
                ("mlp.c_proj.weight", vec![w, m]),
                ("mlp.c_proj.bias", vec![w]),
            ] {
                shapes.push((format!("{p}.{k}"), s));
            }
        }
        shapes
            .into_iter()
            .map(|(k, s)| {
                let t = Tensor::randn(0f32, 0.3, s, dev).unwrap();
                // Layer-norm gains near 1, as trained ones are.
                let t = if k.ends_with("ln_1.weight") || k.ends_with("ln_2.weight") || k == "ln_final.weight" {
                    (t + 1.0).unwrap()
                } else {
                    t
                };
                (k, t)
            })
            .collect()
    }

    /// A CLIP-like byte-pair tokenizer.json: letters, letters ending a word (`</w>`), a few
    /// merges, the two special tokens. 58 tokens.
    fn write_tokenizer(path: &Path) {
        let mut vocab = serde_json::Map::new();
        let mut add = |t: String| {
            let id = vocab.len();
            vocab.insert(t, id.into());
        };
        add(START_OF_TEXT.into());
        add(END_OF_TEXT.into());
        add("<unk>".into());
        for ch in 'a'..='z' {
            add(ch.to_string());
            add(format!("{ch}</w>"));
        }
        for t in ["wa", "wal", "walk</w>"] {
            add(t.into());
        }
        let special = |id: usize, content: &str| {
            serde_json::json!({"id": id, "content": content, "single_word": false, "lstrip": false,
                "rstrip": false, "normalized": false, "special": true})
        };
        let json = serde_json::json!({
            "version": "1.0",
            "truncation": null,
            "padding": null,
            "added_tokens": [special(0, START_OF_TEXT), special(1, END_OF_TEXT)],
            "normalizer": {"type": "Lowercase"},
            "pre_tokenizer": {"type": "Whitespace"},
            "post_processor": null,
            "decoder": null,
            "model": {"type": "BPE", "dropout": null, "unk_token": "<unk>", "continuing_subword_prefix": null,
                "end_of_word_suffix": "</w>", "fuse_unk": false, "byte_fallback": false,
                "vocab": vocab, "merges": ["w a", "wa l", "wal k</w>"]},
        });
        std::fs::write(path, serde_json::to_string(&json).unwrap()).unwrap();
    }

    fn files(weights: HashMap<String, Tensor>) -> (tempfile::TempDir, PathBuf, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let (w, t) = (dir.path().join("clip.safetensors"), dir.path().join("tokenizer.json"));
        candle_core::safetensors::save(&weights, &w).unwrap();
        write_tokenizer(&t);
        (dir, w, t)
    }

    fn max_abs_diff(a: &Tensor, b: &Tensor) -> f64 {
        crate::testing::max_abs_diff(a, b).unwrap()
    }

    fn loads_tiny_openai_checkpoint_and_encodes(dev: &Device) {
        let (_dir, w, t) = files(openai_weights(dev));
        let enc = ClipTextEncoder::load_with_config(&w, &t, tiny_config(), dev).unwrap();
        assert_eq!(enc.tokenize("Walk a").unwrap(), [0, 57, 4, 1], "SOT, walk</w>, a</w>, EOT");
        // 6 of 8 words kept (context 8 = SOT + 6 + EOT).
        assert_eq!(enc.tokenize("a b c d e f g h").unwrap().len(), 8);

        let e = enc.encode(&["walk", "a b c"]).unwrap();
        assert_eq!(e.dims(), [2, PROJ]);
        assert_eq!(e.dtype(), DType::F32);
        let again = enc.encode(&["a b c", "walk"]).unwrap();
        assert_eq!(max_abs_diff(&e.get(0).unwrap(), &again.get(1).unwrap()), 0.0, "deterministic, batch-independent");
        assert!(max_abs_diff(&e.get(0).unwrap(), &e.get(1).unwrap()) > 1e-3, "different prompts differ");
        // Truncation: prompts equal in their first 6 BPE tokens encode the same.
        let cut = enc.encode(&["a b c d e f g", "a b c d e f h i"]).unwrap();
        assert!(max_abs_diff(&cut.get(0).unwrap(), &cut.get(1).unwrap()) < 1e-6);
        assert_eq!(enc.encode(&[]).unwrap().dims(), [0, PROJ]);
    }

    #[test]
    fn loads_tiny_openai_checkpoint_and_encodes_cpu() {
        loads_tiny_openai_checkpoint_and_encodes(&Device::Cpu);
    }

    #[test]
    fn eot_feature_matches_a_hand_computed_model_without_layers() {
        // With zero layers the output is ln_final(tok_emb[EOT] + pos[k]) @ P: check the key
        // mapping of everything outside the blocks and the EOT pooling.
        let dev = Device::Cpu;
        let mut cfg = tiny_config();
        cfg.text.num_hidden_layers = 0;
        let mut weights = openai_weights(&dev);
        weights.retain(|k, _| !k.starts_with("transformer."));
        let (_dir, w, t) = files(weights.clone());
        let enc = ClipTextEncoder::load_with_config(&w, &t, cfg, &dev).unwrap();
        let got = enc.encode(&["a b"]).unwrap();
        let x = (weights["token_embedding.weight"].get(1).unwrap() + weights["positional_embedding"].get(3).unwrap())
            .unwrap();
        let mean = x.mean_all().unwrap();
        let xc = x.broadcast_sub(&mean).unwrap();
        let var = xc.sqr().unwrap().mean_all().unwrap();
        let ln = xc.broadcast_div(&(var + 1e-5).unwrap().sqrt().unwrap()).unwrap();
        let ln = ln.mul(&weights["ln_final.weight"]).unwrap().add(&weights["ln_final.bias"]).unwrap();
        let want = ln.unsqueeze(0).unwrap().matmul(&weights["text_projection"]).unwrap();
        assert!(max_abs_diff(&got, &want) < 1e-4, "{}", max_abs_diff(&got, &want));
    }

    /// OpenAI's `encode_text` written out on the OpenAI-named tensors, on the unpadded ids.
    fn reference_encode(wt: &HashMap<String, Tensor>, ids: &[u32], heads: usize) -> Tensor {
        let dev = Device::Cpu;
        let g = |k: &str| wt[k].clone();
        let ln = |x: &Tensor, p: &str| {
            let xc = x.broadcast_sub(&x.mean_keepdim(1).unwrap()).unwrap();
            let std = (xc.sqr().unwrap().mean_keepdim(1).unwrap() + 1e-5).unwrap().sqrt().unwrap();
            xc.broadcast_div(&std)
                .unwrap()
                .broadcast_mul(&g(&format!("{p}.weight")))
                .unwrap()
                .broadcast_add(&g(&format!("{p}.bias")))
                .unwrap()
        };
        let linear = |x: &Tensor, w: &Tensor, b: &Tensor| x.matmul(&w.t().unwrap()).unwrap().broadcast_add(b).unwrap();
        let t = ids.len();
        let ids_t = Tensor::from_slice(ids, t, &dev).unwrap();
        let mut x = (g("token_embedding.weight").index_select(&ids_t, 0).unwrap()
            + g("positional_embedding").narrow(0, 0, t).unwrap())
        .unwrap();
        let causal: Vec<f32> = (0..t * t).map(|i| if i % t > i / t { f32::NEG_INFINITY } else { 0.0 }).collect();
        let causal = Tensor::from_vec(causal, (t, t), &dev).unwrap();
        let d = WIDTH / heads;
        for n in 0..LAYERS {
            let p = format!("transformer.resblocks.{n}");
            let qkv = linear(
                &ln(&x, &format!("{p}.ln_1")),
                &g(&format!("{p}.attn.in_proj_weight")),
                &g(&format!("{p}.attn.in_proj_bias")),
            );
            let mut outs = Vec::new();
            for h in 0..heads {
                let part = |i: usize| qkv.narrow(1, i * WIDTH + h * d, d).unwrap();
                let scores =
                    ((part(0).matmul(&part(1).t().unwrap()).unwrap() / (d as f64).sqrt()).unwrap() + &causal).unwrap();
                let e = scores.exp().unwrap();
                let attn = e.broadcast_div(&e.sum_keepdim(1).unwrap()).unwrap();
                outs.push(attn.matmul(&part(2)).unwrap());
            }
            let attn = linear(
                &Tensor::cat(&outs, 1).unwrap(),
                &g(&format!("{p}.attn.out_proj.weight")),
                &g(&format!("{p}.attn.out_proj.bias")),
            );
            x = (x + attn).unwrap();
            let hdn = linear(
                &ln(&x, &format!("{p}.ln_2")),
                &g(&format!("{p}.mlp.c_fc.weight")),
                &g(&format!("{p}.mlp.c_fc.bias")),
            );
            let hdn = (&hdn * candle_nn::ops::sigmoid(&(&hdn * 1.702).unwrap()).unwrap()).unwrap();
            x = (x + linear(&hdn, &g(&format!("{p}.mlp.c_proj.weight")), &g(&format!("{p}.mlp.c_proj.bias")))).unwrap();
        }
        ln(&x, "ln_final").narrow(0, t - 1, 1).unwrap().matmul(&g("text_projection")).unwrap()
    }

    #[test]
    fn matches_openai_encode_text_written_out() {
        let dev = Device::Cpu;
        let weights = openai_weights(&dev);
        let (_dir, w, t) = files(weights.clone());
        let enc = ClipTextEncoder::load_with_config(&w, &t, tiny_config(), &dev).unwrap();
        let prompts = ["walk a b", "z y x w v u t s"];
        let got = enc.encode(&prompts).unwrap();
        for (i, p) in prompts.iter().enumerate() {
            let want = reference_encode(&weights, &enc.tokenize(p).unwrap(), 2);
            let diff = max_abs_diff(&got.narrow(0, i, 1).unwrap(), &want);
            assert!(diff < 1e-4, "prompt {i}: {diff}");
        }
    }

    #[test]
    fn bad_checkpoints_and_tokenizers_are_named() {
        let dev = Device::Cpu;
        let mut weights = openai_weights(&dev);
        weights.remove("transformer.resblocks.1.attn.in_proj_bias");
        let (dir, w, t) = files(weights);
        let e = ClipTextEncoder::load_with_config(&w, &t, tiny_config(), &dev).unwrap_err().to_string();
        assert!(e.contains("transformer.resblocks.1.attn.in_proj_bias") && e.contains("clip.safetensors"), "{e}");

        let mut weights = openai_weights(&dev);
        weights.insert("text_projection".into(), Tensor::zeros((WIDTH, 8), DType::F32, &dev).unwrap());
        candle_core::safetensors::save(&weights, &w).unwrap();
        let e = ClipTextEncoder::load_with_config(&w, &t, tiny_config(), &dev).unwrap_err().to_string();
        assert!(e.contains("text_projection") && e.contains("[32, 8]"), "{e}");

        let mut cfg = tiny_config();
        cfg.text.num_hidden_layers = 1;
        candle_core::safetensors::save(&openai_weights(&dev), &w).unwrap();
        let e = ClipTextEncoder::load_with_config(&w, &t, cfg, &dev).unwrap_err().to_string();
        assert!(e.contains("transformer.resblocks.1."), "{e}");

        std::fs::write(&w, b"not safetensors").unwrap();
        assert!(matches!(
            ClipTextEncoder::load_with_config(&w, &t, tiny_config(), &dev),
            Err(EncoderError::Weights { .. })
        ));

        candle_core::safetensors::save(&openai_weights(&dev), &w).unwrap();
        std::fs::write(&t, b"{}").unwrap();
        let e = ClipTextEncoder::load_with_config(&w, &t, tiny_config(), &dev).unwrap_err().to_string();
        assert!(e.contains("tokenizer.json"), "{e}");
        let missing = dir.path().join("nope.json");
        let e = ClipTextEncoder::load_with_config(&w, &missing, tiny_config(), &dev).unwrap_err().to_string();
        assert!(e.contains("nope.json"), "{e}");

        write_tokenizer(&t);
        let mut small = tiny_config();
        small.text.vocab_size = 40;
        let mut weights = openai_weights(&dev);
        weights.insert("token_embedding.weight".into(), Tensor::zeros((40, WIDTH), DType::F32, &dev).unwrap());
        candle_core::safetensors::save(&weights, &w).unwrap();
        let e = ClipTextEncoder::load_with_config(&w, &t, small, &dev).unwrap_err().to_string();
        assert!(e.contains("token id 57") && e.contains("40 rows"), "{e}");
    }
}
