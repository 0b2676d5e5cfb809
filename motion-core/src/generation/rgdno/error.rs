//! Why RG-DNO or its retrieval did not run: [`RgDnoError`] (a reason to fall back to DNO, or a
//! failure) and [`RetrievalError`].

use super::semantic::missing_actions_note;
use crate::constraints::ConstraintError;
use crate::corpus::caption::Action;
use crate::database::DatabaseError;
use crate::files::FileError;
use crate::generation::method::GenerationError;
use crate::MotionError;

/// Why RG-DNO did not run ([`RgDnoError::falls_back`]: the caller falls back to DNO and says
/// why).
#[derive(Debug, thiserror::Error)]
pub enum RgDnoError {
    /// The program has no relational parse.
    #[error("the program has no relational parse, so there is nothing to retrieve")]
    NoParse,
    /// No database motion passed the semantic check and the threshold; `missing` are the
    /// prompt's actions that no window of the database does.
    #[error(
        "no database motion passed the semantic check and the retrieval threshold{}",
        missing_actions_note(missing.iter().map(|a| a.verb())).map_or(String::new(), |note| format!(" ({note})"))
    )]
    NothingRetrieved {
        /// The prompt's actions that no window does.
        missing: Vec<Action>,
    },
    /// The caller gave no retrieval database.
    #[error("no retrieval database was given")]
    NoDatabase,
    /// Retrieval failed.
    #[error(transparent)]
    Retrieval(#[from] RetrievalError),
    /// Generation failed.
    #[error(transparent)]
    Generation(#[from] GenerationError),
}

impl From<candle_core::Error> for RgDnoError {
    fn from(error: candle_core::Error) -> Self {
        RgDnoError::Generation(GenerationError::Tensor(error))
    }
}

impl RgDnoError {
    /// Whether this is a reason to fall back to DNO (nothing to retrieve, or no database to
    /// retrieve from) rather than a failure.
    pub fn falls_back(&self) -> bool {
        matches!(self, RgDnoError::NoParse | RgDnoError::NothingRetrieved { .. } | RgDnoError::NoDatabase)
    }
}

/// Why retrieval failed.
#[derive(Debug, thiserror::Error)]
pub enum RetrievalError {
    /// The database has no clip to crop.
    #[error("the retrieval database has no clip of at least 2 frames")]
    Empty,
    /// A setting cannot be used.
    #[error("invalid retrieval setting: {0}")]
    Setting(String),
    /// The corpus file could not be read (the error names it).
    #[error(transparent)]
    Corpus(#[from] FileError),
    /// The motion database could not be opened.
    #[error("the retrieval database ({source_name}): {error}")]
    Database {
        /// Where it was looked for.
        source_name: String,
        /// What went wrong.
        error: Box<DatabaseError>,
    },
    /// A retrieved crop's features could not be extracted.
    #[error("retrieved crop {crop}: {error}")]
    Features {
        /// The crop.
        crop: String,
        /// What went wrong.
        error: MotionError,
    },
    /// The retrieval set could not be evaluated.
    #[error(transparent)]
    Constraint(#[from] ConstraintError),
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
}
