//! The training captions nearest to each prompt of the prior's report (`Family::prompts`), by
//! the cosine similarity of their all-MiniLM-L6-v2 sentence embeddings: what a prompt sounds
//! like to the text encoder, next to what the prior was trained on.
//!
//! Usage: `cargo run --release -p motion-core --example caption_neighbours -- [CORPUS [TEXT_MODEL [K]]]`
//! (defaults: `fixtures/corpus/corpus.safetensors.gz`, `fixtures/text/all-MiniLM-L6-v2`, 5).
//! Encoding the train split's distinct captions takes about a minute on 2 cores.
use std::collections::BTreeSet;
use std::error::Error;
use std::path::Path;

use candle_core::Device;
use motion_core::corpus::family::Family;
use motion_core::corpus::{file, Split};
use motion_core::text::minilm::MiniLm;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let corpus_path = args.get(1).map_or("fixtures/corpus/corpus.safetensors.gz", String::as_str);
    let model = args.get(2).map_or("fixtures/text/all-MiniLM-L6-v2", String::as_str);
    let k: usize = args.get(3).map_or(Ok(5), |s| s.parse())?;
    let corpus = file::load(Path::new(corpus_path))?;
    let captions: Vec<String> = corpus
        .windows
        .iter()
        .filter(|w| corpus.clips[w.clip].split == Split::Train)
        .flat_map(|w| w.captions.iter().cloned())
        .collect::<BTreeSet<_>>()
        .into_iter()
        .collect();
    eprintln!("{} distinct train-split captions", captions.len());
    let encoder = MiniLm::load(Path::new(model), &Device::Cpu)?;
    let mut embeddings = Vec::with_capacity(captions.len());
    for chunk in captions.chunks(256) {
        let batch: Vec<&str> = chunk.iter().map(String::as_str).collect();
        embeddings.extend(encoder.encode(&batch)?.to_vec2::<f32>()?);
    }
    for family in Family::ALL {
        for prompt in family.prompts() {
            let e = encoder.encode(&[prompt])?.to_vec2::<f32>()?.remove(0);
            // Embeddings are unit length: the dot product is the cosine similarity.
            let mut nearest: Vec<(f32, &str)> = embeddings
                .iter()
                .zip(&captions)
                .map(|(c, caption)| (c.iter().zip(&e).map(|(a, b)| a * b).sum(), caption.as_str()))
                .collect();
            nearest.sort_by(|a, b| b.0.total_cmp(&a.0));
            println!("{} — {prompt}:", family.name());
            for (similarity, caption) in nearest.iter().take(k) {
                println!("    {similarity:.3}  {caption}");
            }
        }
    }
    Ok(())
}
