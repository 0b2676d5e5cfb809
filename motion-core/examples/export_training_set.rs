//! Exports what `mogen train` trains on, for the PyTorch mirror of the trainer
//! (`fixtures/model/gpu/train_mdm.py`, for training on a GPU). Three modes:
//!
//! - `captions CORPUS TEXT_MODELS OUT`: the caption tables of the corpus's train and validation
//!   splits (mirrored copies' captions included, in the trainer's row order), encoded with
//!   all-MiniLM-L6-v2: `train.text`, `validation.text` `[rows, 384]` (f16, so that the file
//!   travels to a lent GPU within its 64 MiB: about 5e-4 off per component of the unit-length
//!   embeddings), the captions themselves in the header metadata. Run where the sentence
//!   encoder is (17 MB out of 45).
//! - `corpus CORPUS CAPTIONS OUT`: the normalised features of both splits with their captioned
//!   stretches, the caption tables copied from CAPTIONS (checked against the corpus's captions,
//!   row by row): per split `S` in `train`, `validation`, `S.x` `[rows, 263]` (the sequences one
//!   after the other, normalised with the train split's statistics), `S.sequences` `[n, 2]`
//!   (first row, frames), `S.stretches` `[m, 4]` (sequence, first frame, first phrasing, number
//!   of phrasings), `S.phrasings` `[p]` (caption rows), `S.text` `[rows, 384]` (back to f32),
//!   `S.families` `[m]` (each stretch's skill family, `training::Stretch::family`, as its index
//!   in `Family::ALL` or -1 for none, so a trainer can balance the skills); and `mean`, `std`
//!   `[263]`; all f32, with the rest skeleton as JSON in the header metadata. Run where the
//!   training runs (the features of 11.6 h are 0.9 GB).
//! - `database DB OUT`: a motion database's windows with label ids and a vocabulary (`x`,
//!   `windows` `[n, 3]` = first row, frames, label; `label_text`, `mean`, `std`, and
//!   `OUT.vocab.json`).
//!
//! Usage: `cargo run --release --example export_training_set -p motion-core -- MODE ARGS...`
use std::collections::HashMap;
use std::error::Error;
use std::path::Path;

use candle_core::{DType, Device, Tensor};
use motion_core::corpus::family::Family;
use motion_core::corpus::{file as corpus_file, Corpus, Split};
use motion_core::database::{MotionDatabase, Window};
use motion_core::representation::RestSkeleton;
use motion_core::skeleton::rest_bone_lengths;
use motion_core::text::vocabulary::VocabularyEncoder;
use motion_core::text::{ConditionEncoder, TextEncoder, MINILM_NAME};
use motion_core::training::CaptionedSequences;

const SPLITS: [(Split, &str); 2] = [(Split::Train, "train"), (Split::Validation, "validation")];

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    match args.iter().map(String::as_str).collect::<Vec<_>>().as_slice() {
        [_, "captions", corpus, text_models, out] => captions(corpus, text_models, out),
        [_, "corpus", corpus, captions, out] => corpus_arrays(corpus, captions, out),
        [_, "database", db, out] => database(db, out),
        _ => Err("usage: export_training_set captions CORPUS TEXT_MODELS OUT | corpus CORPUS CAPTIONS OUT | \
                  database DB OUT"
            .into()),
    }
}

/// Both splits' sequences, the validation split normalised with the train split's statistics.
fn splits(corpus: &Corpus) -> Result<Vec<CaptionedSequences>, Box<dyn Error>> {
    let train = CaptionedSequences::from_corpus(corpus, Split::Train, None, &Device::Cpu)?;
    let validation = CaptionedSequences::from_corpus(corpus, Split::Validation, Some(train.mean_std()), &Device::Cpu)?;
    Ok(vec![train, validation])
}

fn captions(corpus: &str, text_models: &str, out: &str) -> Result<(), Box<dyn Error>> {
    let encoder = ConditionEncoder::sentence(MINILM_NAME, Path::new(text_models), &Device::Cpu)?;
    let mut tensors = Vec::new();
    let mut metadata = HashMap::new();
    for (sequences, (_, name)) in splits(&corpus_file::load(Path::new(corpus))?)?.iter().zip(SPLITS) {
        let captions: Vec<&str> = sequences.captions().iter().map(String::as_str).collect();
        let mut rows = Vec::new();
        for (k, chunk) in captions.chunks(256).enumerate() {
            eprintln!("{name}: {}/{} captions", k * 256, captions.len());
            rows.push(encoder.encode(chunk, &Device::Cpu)?);
        }
        tensors.push((format!("{name}.text"), Tensor::cat(&rows, 0)?.to_dtype(DType::F16)?));
        metadata.insert(format!("{name}.captions"), serde_json::to_string(&captions)?);
        println!("{name}: {} captions", captions.len());
    }
    motion_core::tensor_file::write_safetensors(Path::new(out), &tensors, metadata)?;
    Ok(())
}

fn corpus_arrays(corpus: &str, captions: &str, out: &str) -> Result<(), Box<dyn Error>> {
    let bytes = std::fs::read(captions)?;
    let meta = motion_core::tensor_file::read_metadata(&bytes)?;
    let tables = candle_core::safetensors::load_buffer(&bytes, &Device::Cpu)?;
    let corpus = corpus_file::load(Path::new(corpus))?;
    let splits = splits(&corpus)?;
    let mut tensors = vec![
        ("mean".to_owned(), splits[0].mean_std().mean().clone()),
        ("std".to_owned(), splits[0].mean_std().std().clone()),
    ];
    for (sequences, (_, name)) in splits.iter().zip(SPLITS) {
        let stored: Vec<String> =
            serde_json::from_str(meta.get(&format!("{name}.captions")).ok_or("no captions in the captions file")?)?;
        if stored != sequences.captions() {
            return Err(format!("{captions}: the {name} captions are not this corpus's (made from another?)").into());
        }
        let text = tables.get(&format!("{name}.text")).ok_or("no caption table")?;
        let (mut x, mut rows, mut stretches, mut phrasings) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut families = Vec::new();
        let mut first_row = 0i64;
        for (i, (features, captioned)) in sequences.sequences().enumerate() {
            let frames = features.dim(0)? as i64;
            rows.extend([first_row, frames]);
            for stretch in captioned {
                stretches.extend([i as i64, stretch.start as i64, phrasings.len() as i64, stretch.rows.len() as i64]);
                phrasings.extend(stretch.rows.iter().map(|&id| i64::from(id)));
                let family = stretch.family.and_then(|f| Family::ALL.iter().position(|g| *g == f));
                families.push(family.map_or(-1, |f| f as i64));
            }
            x.push(features.clone());
            first_row += frames;
        }
        let (n, m, p) = (rows.len() / 2, stretches.len() / 4, phrasings.len());
        tensors.push((format!("{name}.x"), Tensor::cat(&x, 0)?));
        tensors.push((format!("{name}.sequences"), Tensor::from_vec(rows, (n, 2), &Device::Cpu)?));
        tensors.push((format!("{name}.families"), Tensor::from_vec(families, m, &Device::Cpu)?));
        tensors.push((format!("{name}.stretches"), Tensor::from_vec(stretches, (m, 4), &Device::Cpu)?));
        tensors.push((format!("{name}.phrasings"), Tensor::from_vec(phrasings, p, &Device::Cpu)?));
        tensors.push((format!("{name}.text"), text.to_dtype(DType::F32)?));
        println!("{name}: {n} sequences, {first_row} frames, {m} captioned stretches, {} captions", stored.len());
    }
    // Every tensor is stored as f32 (the indices too: exact below 2^24 rows), with the rest
    // skeleton of the corpus (the prior's) in the header.
    let rest = RestSkeleton { bone_lengths_m: rest_bone_lengths() };
    let metadata = HashMap::from([("rest_skeleton".to_owned(), serde_json::to_string(&rest)?)]);
    motion_core::tensor_file::write_safetensors(Path::new(out), &tensors, metadata)?;
    Ok(())
}

fn database(db_path: &str, out: &str) -> Result<(), Box<dyn Error>> {
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
