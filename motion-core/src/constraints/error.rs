//! Why a program cannot be compiled or evaluated.

use crate::program::ProgramError;

/// Why a program cannot be compiled or evaluated.
#[derive(Debug, thiserror::Error)]
pub enum ConstraintError {
    /// The program is invalid (each error names the JSON path).
    #[error("invalid program:\n{}", .0.iter().map(|e| format!("  - {e}")).collect::<Vec<_>>().join("\n"))]
    Invalid(Vec<ProgramError>),
    /// The motion does not fit the program.
    #[error("motion of shape {shape:?} does not fit the program: expected [batch, {frames}, 22, 3]")]
    Shape {
        /// Shape given.
        shape: Vec<usize>,
        /// The program's frame count.
        frames: usize,
    },
    /// A program with `stay_near_initial` was evaluated without an initial motion.
    #[error("constraint {0} (stay_near_initial) needs the initial motion")]
    NoInitialMotion(String),
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
}
