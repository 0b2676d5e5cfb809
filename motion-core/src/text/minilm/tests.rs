use std::path::PathBuf;
use std::sync::OnceLock;

use serde::Deserialize;

use super::*;
use crate::testing::max_abs_diff;

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/text")
}

fn shipped_dir() -> PathBuf {
    fixtures().join("all-MiniLM-L6-v2")
}

/// The shipped f16 encoder, loaded once for all tests (45 MB).
fn shipped() -> &'static MiniLm {
    static ENCODER: OnceLock<MiniLm> = OnceLock::new();
    ENCODER.get_or_init(|| MiniLm::load(&shipped_dir(), &Device::Cpu).unwrap())
}

/// `fixtures/text/minilm_reference.json`, written by `parity_minilm.py` with sentence-transformers.
#[derive(Deserialize)]
struct Reference {
    sentences: Vec<String>,
    input_ids: Vec<Vec<u32>>,
    embeddings: Vec<Vec<f32>>,
}

fn reference() -> Reference {
    let text = std::fs::read_to_string(fixtures().join("minilm_reference.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn rows(t: &Tensor) -> Vec<Vec<f32>> {
    t.to_vec2::<f32>().unwrap()
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

#[test]
fn preset_matches_the_shipped_upstream_config_files() {
    let config: BertConfig =
        serde_json::from_str(&std::fs::read_to_string(shipped_dir().join("config.json")).unwrap()).unwrap();
    let preset = MiniLmConfig::all_minilm_l6_v2();
    assert_eq!(config, preset.bert);
    let st: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(shipped_dir().join("sentence_bert_config.json")).unwrap())
            .unwrap();
    assert_eq!(st["max_seq_length"], preset.max_seq_length);
}

#[test]
fn shipped_encoder_matches_sentence_transformers() {
    let reference = reference();
    let enc = shipped();
    assert_eq!(enc.dim(), 384);
    let prompts: Vec<&str> = reference.sentences.iter().map(String::as_str).collect();
    for (prompt, ids) in prompts.iter().zip(&reference.input_ids) {
        assert_eq!(&enc.tokenize(prompt).unwrap(), ids, "ids of {prompt:?}");
    }
    // Two prompts of different lengths, in one batch: 1e-3 is the f16 weights' budget.
    let (a, b) = (0, 3);
    let got = enc.encode(&[prompts[a], prompts[b]]).unwrap();
    for (row, i) in [a, b].into_iter().enumerate() {
        let want = Tensor::new(reference.embeddings[i].as_slice(), &Device::Cpu).unwrap();
        let diff = max_abs_diff(&got.get(row).unwrap(), &want).unwrap();
        assert!(diff <= 1e-3, "{:?}: max |Δ| {diff}", prompts[i]);
    }
}

#[test]
fn similar_prompts_are_closer_than_unrelated_ones() {
    let e =
        rows(&shipped().encode(&["a person walks forward", "someone strolls ahead", "a person sits down"]).unwrap());
    let (walk_stroll, walk_sit, stroll_sit) = (dot(&e[0], &e[1]), dot(&e[0], &e[2]), dot(&e[1], &e[2]));
    assert!(walk_stroll > walk_sit && walk_stroll > stroll_sit, "{walk_stroll} {walk_sit} {stroll_sit}");
}

#[test]
fn rows_have_unit_length_even_for_empty_prompts() {
    let e = rows(&shipped().encode(&["a woman skips forward", "", "   ", "一个人向前走"]).unwrap());
    for row in &e {
        assert!((dot(row, row).sqrt() - 1.0).abs() < 1e-5, "{}", dot(row, row));
    }
}

#[test]
fn padding_does_not_change_a_prompt() {
    let enc = shipped();
    let prompts = ["a", "a man tiptoes sideways to his right", "walk 3.5 m forward, turn 90 degrees left"];
    let batch = enc.encode(&prompts).unwrap();
    for (row, prompt) in prompts.into_iter().enumerate() {
        let alone = enc.encode(&[prompt]).unwrap();
        let diff = max_abs_diff(&batch.get(row).unwrap(), &alone.get(0).unwrap()).unwrap();
        assert!(diff < 1e-5, "{prompt:?}: {diff}");
    }
}

#[test]
fn long_prompts_keep_their_first_254_word_pieces() {
    let enc = shipped();
    let long = "a person walks forward and then turns around ".repeat(40);
    let ids = enc.tokenize(&long).unwrap();
    let (cls, sep) = (enc.tokenizer.token_to_id(CLS).unwrap(), enc.tokenizer.token_to_id(SEP).unwrap());
    assert_eq!((ids.len(), ids[0], ids[255]), (256, cls, sep));
    assert_eq!(ids[1..255], enc.tokenize(&format!("{long} and sits")).unwrap()[1..255]);
}

#[test]
fn empty_prompt_list_gives_zero_rows_and_the_trait_moves_to_the_device() {
    let enc = shipped();
    assert_eq!(MiniLm::encode(enc, &[]).unwrap().dims(), [0, 384]);
    let e = TextEncoder::encode(enc, &["a person walks forward"], &Device::Cpu).unwrap();
    assert_eq!((e.dims(), e.dtype()), ([1, 384].as_slice(), DType::F32));
}

#[test]
fn mean_pool_averages_unmasked_tokens_then_normalise_scales_to_unit_length() {
    let dev = Device::Cpu;
    // Row 0 keeps tokens 0 and 1 of [1,2], [3,4], [100,100]; row 1 keeps token 0 only.
    let hidden = Tensor::new(&[[[1f32, 2.], [3., 4.], [100., 100.]], [[3., 4.], [9., 9.], [9., 9.]]], &dev).unwrap();
    let mask = Tensor::new(&[[1u32, 1, 0], [1, 0, 0]], &dev).unwrap();
    let pooled = mean_pool(&hidden, &mask).unwrap();
    assert_eq!(rows(&pooled), [[2., 3.], [3., 4.]]);
    assert_eq!(rows(&unit_rows(&pooled.narrow(0, 1, 1).unwrap()).unwrap()), [[0.6, 0.8]]);
}

// ---- loading errors, on a tiny BERT (hidden 8, 2 heads, 1 layer) with the real tokenizer ----

fn tiny_config() -> MiniLmConfig {
    let mut c = MiniLmConfig::all_minilm_l6_v2();
    c.bert.hidden_size = 8;
    c.bert.num_attention_heads = 2;
    c.bert.intermediate_size = 16;
    c.bert.num_hidden_layers = 1;
    c.bert.max_position_embeddings = 32;
    c.max_seq_length = 16;
    c
}

fn tiny_weights(dtype: DType) -> HashMap<String, Tensor> {
    let mut w: HashMap<String, Tensor> = expected_shapes(&tiny_config().bert)
        .into_iter()
        .map(|(k, s)| (k, Tensor::randn(0f32, 0.3, s, &Device::Cpu).unwrap().to_dtype(dtype).unwrap()))
        .collect();
    // Upstream extras that must be ignored.
    w.insert("pooler.dense.bias".into(), Tensor::zeros(8, dtype, &Device::Cpu).unwrap());
    w.insert("embeddings.position_ids".into(), Tensor::zeros((1, 32), DType::I64, &Device::Cpu).unwrap());
    w
}

/// A folder with `weights` and the shipped tokenizer.
fn tiny_dir(weights: &HashMap<String, Tensor>) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    candle_core::safetensors::save(weights, dir.path().join(WEIGHTS_FILE)).unwrap();
    std::fs::copy(shipped_dir().join(TOKENIZER_FILE), dir.path().join(TOKENIZER_FILE)).unwrap();
    dir
}

fn load_error(dir: &Path, config: MiniLmConfig) -> String {
    MiniLm::load_with_config(dir, config, &Device::Cpu).unwrap_err().to_string()
}

#[test]
fn tiny_f16_and_f32_checkpoints_load_and_encode_alike() {
    let w32 = tiny_weights(DType::F32);
    let w16: HashMap<String, Tensor> = w32.iter().map(|(k, t)| (k.clone(), t.to_dtype(DType::F16).unwrap())).collect();
    let w16_as_32: HashMap<String, Tensor> =
        w16.iter().map(|(k, t)| (k.clone(), t.to_dtype(DType::F32).unwrap())).collect();
    let (d16, d32) = (tiny_dir(&w16), tiny_dir(&w16_as_32));
    let e16 = MiniLm::load_with_config(d16.path(), tiny_config(), &Device::Cpu).unwrap();
    let e32 = MiniLm::load_with_config(d32.path(), tiny_config(), &Device::Cpu).unwrap();
    let prompts = ["a person walks forward", "a person sits down"];
    let (a, b) = (rows(&e16.encode(&prompts).unwrap()), rows(&e32.encode(&prompts).unwrap()));
    assert_eq!(a, b, "f16 weights are computed in f32");
    assert_eq!(e16.tokenize(&"walk ".repeat(40)).unwrap().len(), 16, "truncated at max_seq_length");
}

#[test]
fn bad_checkpoints_and_tokenizers_are_named() {
    let mut w = tiny_weights(DType::F32);
    w.remove("encoder.layer.0.attention.self.key.bias");
    let dir = tiny_dir(&w);
    let e = load_error(dir.path(), tiny_config());
    assert!(e.contains("encoder.layer.0.attention.self.key.bias") && e.contains("model.safetensors"), "{e}");

    let mut w = tiny_weights(DType::F32);
    w.insert(
        "encoder.layer.0.intermediate.dense.weight".into(),
        Tensor::zeros((8, 16), DType::F32, &Device::Cpu).unwrap(),
    );
    let e = load_error(tiny_dir(&w).path(), tiny_config());
    assert!(e.contains("intermediate.dense.weight") && e.contains("[8, 16]") && e.contains("[16, 8]"), "{e}");

    let mut w = tiny_weights(DType::F32);
    w.insert("embeddings.LayerNorm.bias".into(), Tensor::zeros(8, DType::I64, &Device::Cpu).unwrap());
    let e = load_error(tiny_dir(&w).path(), tiny_config());
    assert!(e.contains("embeddings.LayerNorm.bias") && e.contains("I64"), "{e}");

    let mut two = tiny_config();
    two.bert.num_hidden_layers = 2;
    let w = expected_shapes(&two.bert)
        .into_iter()
        .map(|(k, s)| (k, Tensor::zeros(s, DType::F32, &Device::Cpu).unwrap()))
        .collect::<HashMap<_, _>>();
    let e = load_error(tiny_dir(&w).path(), tiny_config());
    assert!(e.contains("encoder.layer.1.") && e.contains("beyond the configured 1"), "{e}");

    let dir = tiny_dir(&tiny_weights(DType::F32));
    std::fs::write(dir.path().join(WEIGHTS_FILE), b"not safetensors").unwrap();
    assert!(matches!(
        MiniLm::load_with_config(dir.path(), tiny_config(), &Device::Cpu),
        Err(EncoderError::Weights { .. })
    ));

    let dir = tiny_dir(&tiny_weights(DType::F32));
    std::fs::write(dir.path().join(TOKENIZER_FILE), b"{}").unwrap();
    let e = load_error(dir.path(), tiny_config());
    assert!(e.contains("tokenizer.json"), "{e}");
    std::fs::remove_file(dir.path().join(TOKENIZER_FILE)).unwrap();
    let e = load_error(dir.path(), tiny_config());
    assert!(e.contains("tokenizer.json"), "{e}");

    let mut small = tiny_config();
    small.bert.vocab_size = 1000;
    let dir = tiny_dir(
        &expected_shapes(&small.bert)
            .into_iter()
            .map(|(k, s)| (k, Tensor::zeros(s, DType::F32, &Device::Cpu).unwrap()))
            .collect(),
    );
    let e = load_error(dir.path(), small);
    assert!(e.contains("token id 30521") && e.contains("1000 rows"), "{e}");

    let mut long = tiny_config();
    long.max_seq_length = 33;
    assert!(load_error(dir.path(), long).contains("max_seq_length 33"));
}
