//! Parity of [`MiniLm`] with sentence-transformers: encodes the sentences of
//! `fixtures/text/minilm_reference.json` (written by `fixtures/text/parity_minilm.py` from the
//! original f32 weights) in one batch and prints, per sentence and overall, whether the ids
//! agree and the largest absolute difference of an embedding component.
//!
//! Usage: `cargo run -p motion-core --example minilm_parity -- MODEL_DIR [REFERENCE]`,
//! MODEL_DIR holding `model.safetensors` and `tokenizer.json`: the shipped f16
//! `fixtures/text/all-MiniLM-L6-v2`, or the unzipped f32 upstream model (see
//! `fixtures/text/extract.sh`). Exits non-zero when ids differ.
use std::error::Error;
use std::path::{Path, PathBuf};

use candle_core::Device;
use motion_core::text::minilm::MiniLm;
use serde::Deserialize;

#[derive(Deserialize)]
struct Reference {
    sentences: Vec<String>,
    input_ids: Vec<Vec<u32>>,
    embeddings: Vec<Vec<f32>>,
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let Some(dir) = args.get(1) else {
        return Err("usage: minilm_parity MODEL_DIR [REFERENCE]".into());
    };
    let reference_path = args
        .get(2)
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/text/minilm_reference.json"));
    let reference: Reference = serde_json::from_str(&std::fs::read_to_string(&reference_path)?)?;
    let encoder = MiniLm::load(Path::new(dir), &Device::Cpu)?;
    let prompts: Vec<&str> = reference.sentences.iter().map(String::as_str).collect();
    let got = encoder.encode(&prompts)?.to_vec2::<f32>()?;

    let (mut worst, mut ids_differ) = (0f32, 0);
    for (i, prompt) in prompts.iter().enumerate() {
        let ids = encoder.tokenize(prompt)?;
        let same_ids = ids == reference.input_ids[i];
        ids_differ += usize::from(!same_ids);
        let diff = got[i].iter().zip(&reference.embeddings[i]).map(|(a, b)| (a - b).abs()).fold(0f32, f32::max);
        worst = worst.max(diff);
        let shown: String = prompt.chars().take(48).collect();
        println!("{diff:9.2e}  {:3} ids{}  {shown:?}", ids.len(), if same_ids { "" } else { " DIFFER" });
    }
    println!("max |Δ| over {} sentences × 384 components: {worst:.2e} ({dir})", prompts.len());
    if ids_differ > 0 {
        return Err(format!("{ids_differ} sentences tokenise differently").into());
    }
    Ok(())
}
