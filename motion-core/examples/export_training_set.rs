//! Exports what `mogen train` trains on, for the PyTorch mirror of the trainer
//! (`fixtures/model/gpu/train_mdm.py`, used for recipe sweeps on a GPU):
//!
//! - `x` `[rows, 263]`: the normalised features of every sequence of the database, one after
//!   the other;
//! - `windows` `[n, 3]` (i64): each window's first row in `x`, its frames and its label id;
//! - `label_text` `[labels, vocabulary]`: the condition vector of each label (sorted labels);
//! - `mean`, `std` `[263]`: the normalisation;
//!
//! and beside it `OUT.vocab.json` (the vocabulary, as stored in a prior file's header).
//!
//! Usage: `cargo run --release --example export_training_set -p motion-core -- DB OUT`
use std::collections::HashMap;
use std::error::Error;
use std::path::Path;

use candle_core::{Device, Tensor};
use motion_core::database::{MotionDatabase, Window};
use motion_core::text::vocabulary::VocabularyEncoder;
use motion_core::text::TextEncoder;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, db_path, out] = args.as_slice() else {
        return Err("usage: export_training_set DATABASE OUT.safetensors".into());
    };
    let db = MotionDatabase::load(Path::new(db_path))?;
    let dev = Device::Cpu;
    let labels = db.labels();
    let encoder = VocabularyEncoder::from_labels(labels.iter().map(String::as_str));
    let label_text = encoder.encode(&labels.iter().map(String::as_str).collect::<Vec<_>>(), &dev)?;
    let mean_std = db.mean_std();
    let mut sequences = Vec::new();
    let mut first_row = Vec::new();
    let mut row = 0usize;
    for (i, seq) in db.sequences().iter().enumerate() {
        let whole = Window { sequence: i, start: 0, frames: seq.frames };
        sequences.push(mean_std.normalize(&db.window_tensor(&whole, &dev)?)?);
        first_row.push(row);
        row += seq.frames;
    }
    let mut table = Vec::new();
    for w in db.windows() {
        let label = labels
            .binary_search_by(|l| l.as_str().cmp(db.label(w)))
            .map_err(|_| format!("window {w:?} has no label in the label list"))?;
        table.extend([(first_row[w.sequence] + w.start) as i64, w.frames as i64, label as i64]);
    }
    let n = db.windows().len();
    let tensors = HashMap::from([
        ("x".to_owned(), Tensor::cat(&sequences, 0)?),
        ("windows".to_owned(), Tensor::from_vec(table, (n, 3), &dev)?),
        ("label_text".to_owned(), label_text),
        ("mean".to_owned(), mean_std.mean().clone()),
        ("std".to_owned(), mean_std.std().clone()),
    ]);
    candle_core::safetensors::save(&tensors, out)?;
    std::fs::write(format!("{out}.vocab.json"), serde_json::to_string(&encoder)?)?;
    println!("{out}: {n} windows of {row} frames, {} labels, {} vocabulary words", labels.len(), encoder.words().len());
    Ok(())
}
