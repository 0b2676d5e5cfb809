//! What can go wrong in a training run.

use std::path::PathBuf;

use crate::prior::PriorError;

/// Errors of a training run.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// Tensor computation failed.
    #[error("tensor error: {0}")]
    Tensor(#[from] candle_core::Error),
    /// The loss became NaN or infinite.
    #[error("step {step}: the loss is {loss}; lower the learning rate")]
    Diverged {
        /// Step.
        step: usize,
        /// Loss value.
        loss: f64,
    },
    /// Reading or writing a checkpoint, or reading a prior to start from (the caller says which).
    #[error("{path}: {message}")]
    Checkpoint {
        /// File.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// Writing the prior.
    #[error(transparent)]
    Prior(#[from] PriorError),
    /// The database cannot feed this configuration.
    #[error("{0}")]
    Data(String),
}
