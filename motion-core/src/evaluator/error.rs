//! What can go wrong with the evaluator's files.

/// Errors of the evaluator's files.
#[derive(Debug, thiserror::Error)]
pub enum EvaluatorError {
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
    /// An unreadable or incomplete evaluator file.
    #[error("{path}: {message}")]
    File {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong.
        message: String,
    },
}
