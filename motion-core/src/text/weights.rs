//! What the network text encoders (CLIP, MiniLM) share when they load their files: one error
//! type, and the checked taking of a tensor out of a checkpoint before the file's path is known.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use candle_core::{DType, Tensor};

/// Errors loading or running a network text encoder; each names the file, the tensor or the
/// prompt.
#[derive(Debug, thiserror::Error)]
pub enum EncoderError {
    /// The weights file could not be read as safetensors.
    #[error("{path}: cannot read the text encoder's weights: {source}")]
    Weights {
        /// The weights file.
        path: PathBuf,
        /// candle's error.
        source: candle_core::Error,
    },
    /// A tensor the network needs is absent.
    #[error("{path}: missing tensor `{key}` (expected {names})")]
    MissingTensor {
        /// The weights file.
        path: PathBuf,
        /// The tensor's name.
        key: String,
        /// The naming the encoder expects, and where to read about it.
        names: &'static str,
    },
    /// A tensor whose shape does not fit the configuration.
    #[error("{path}: tensor `{key}` has shape {found:?}; the configuration needs {expected:?}")]
    WrongShape {
        /// The weights file.
        path: PathBuf,
        /// The tensor's name.
        key: String,
        /// Shape in the file.
        found: Vec<usize>,
        /// Shape the configuration implies.
        expected: Vec<usize>,
    },
    /// A tensor that is not floating point.
    #[error("{path}: tensor `{key}` is {dtype:?}; expected f32, f16 or bf16")]
    WrongDType {
        /// The weights file.
        path: PathBuf,
        /// The tensor's name.
        key: String,
        /// Its element type.
        dtype: DType,
    },
    /// The file has more layers than the configuration (wrong configuration or wrong file).
    #[error("{path}: tensor `{key}` belongs to a layer beyond the configured {layers}")]
    ExtraLayer {
        /// The weights file.
        path: PathBuf,
        /// The tensor's name.
        key: String,
        /// Configured layers.
        layers: usize,
    },
    /// The tokenizer file could not be loaded.
    #[error("{path}: cannot load tokenizer: {message}")]
    Tokenizer {
        /// The tokenizer file.
        path: PathBuf,
        /// The tokenizers crate's message.
        message: String,
    },
    /// The tokenizer lacks a special token, has ids outside the embedding table, or is not the
    /// one the network expects.
    #[error("{path}: {message}")]
    TokenizerMismatch {
        /// The tokenizer file.
        path: PathBuf,
        /// What does not fit.
        message: String,
    },
    /// Tokenising a prompt failed.
    #[error("prompt {index}: {message}")]
    Tokenize {
        /// Index of the prompt.
        index: usize,
        /// What went wrong.
        message: String,
    },
    /// A configuration that cannot work (e.g. a context longer than the positions).
    #[error("text encoder configuration: {0}")]
    Config(String),
    /// A tensor operation failed.
    #[error("text encoder forward pass: {0}")]
    Tensor(#[from] candle_core::Error),
}

/// A problem with one tensor of a checkpoint, before the file's path is attached.
pub(super) enum TensorProblem {
    Missing(String),
    Shape { key: String, found: Vec<usize>, expected: Vec<usize> },
    DType(String, DType),
    ExtraLayer(String, usize),
    Tensor(candle_core::Error),
}

impl TensorProblem {
    /// The error of this problem in the file `path`, whose tensors follow `names`.
    pub(super) fn at(self, path: &Path, names: &'static str) -> EncoderError {
        let path = path.to_path_buf();
        match self {
            TensorProblem::Missing(key) => EncoderError::MissingTensor { path, key, names },
            TensorProblem::Shape { key, found, expected } => EncoderError::WrongShape { path, key, found, expected },
            TensorProblem::DType(key, dtype) => EncoderError::WrongDType { path, key, dtype },
            TensorProblem::ExtraLayer(key, layers) => EncoderError::ExtraLayer { path, key, layers },
            TensorProblem::Tensor(source) => EncoderError::Weights { path, source },
        }
    }
}

impl From<candle_core::Error> for TensorProblem {
    fn from(e: candle_core::Error) -> Self {
        TensorProblem::Tensor(e)
    }
}

/// Takes tensor `key` out of `src`, checking that it is floating point (f32, f16 or bf16) of
/// shape `expected`, as f32.
pub(super) fn take_tensor(
    src: &mut HashMap<String, Tensor>,
    key: &str,
    expected: &[usize],
) -> Result<Tensor, TensorProblem> {
    let t = src.remove(key).ok_or_else(|| TensorProblem::Missing(key.to_owned()))?;
    if !matches!(t.dtype(), DType::F32 | DType::F16 | DType::BF16) {
        return Err(TensorProblem::DType(key.to_owned(), t.dtype()));
    }
    if t.dims() != expected {
        return Err(TensorProblem::Shape {
            key: key.to_owned(),
            found: t.dims().to_vec(),
            expected: expected.to_vec(),
        });
    }
    Ok(t.to_dtype(DType::F32)?)
}

/// The first key of `src` under `prefix` (a layer the configuration does not have), as a
/// problem.
pub(super) fn no_extra_layer(src: &HashMap<String, Tensor>, prefix: &str, layers: usize) -> Result<(), TensorProblem> {
    match src.keys().filter(|k| k.starts_with(prefix)).min() {
        Some(extra) => Err(TensorProblem::ExtraLayer(extra.clone(), layers)),
        None => Ok(()),
    }
}
