//! Which LLM stage, and why a stage produced no valid answer.

use std::fmt;

use crate::llm::{escape_controls, truncate, LlmError};
use crate::prompts::PromptError;

/// Longest raw reply quoted in an error (characters).
const MAX_REPLY_IN_ERROR: usize = 8000;

/// Which stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Task text → constraint program.
    Program,
    /// Constraints → relational parse.
    RelationalParse,
}

impl Stage {
    /// The name used in recordings.
    pub fn name(self) -> &'static str {
        match self {
            Stage::Program => "program",
            Stage::RelationalParse => "relational_parse",
        }
    }
}

impl fmt::Display for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Stage::Program => "program generation",
            Stage::RelationalParse => "relational parsing",
        })
    }
}

/// Why a stage produced no valid answer.
#[derive(Debug, thiserror::Error)]
pub enum StageError {
    /// The exchange itself failed (network, HTTP status, replay miss).
    #[error("{stage}: {source}")]
    Llm {
        /// The stage.
        stage: Stage,
        /// What failed.
        #[source]
        source: LlmError,
    },
    /// A prompt template did not render.
    #[error("{stage}: {source}")]
    Prompt {
        /// The stage.
        stage: Stage,
        /// What failed.
        #[source]
        source: PromptError,
    },
    /// Every attempt gave an unusable answer. The problems and the reply are shown with their
    /// control characters escaped.
    #[error(
        "{stage}: no valid answer in {attempts} attempt(s). Problems with the last answer:\n{}\nThe last raw reply:\n{}",
        bullet_list(problems),
        escape_controls(&truncate(last_reply, MAX_REPLY_IN_ERROR))
    )]
    Invalid {
        /// The stage.
        stage: Stage,
        /// Attempts made (1 + repair rounds).
        attempts: u32,
        /// The problems of the last answer.
        problems: Vec<String>,
        /// The last reply as received.
        last_reply: String,
    },
}

fn bullet_list(items: &[String]) -> String {
    items.iter().map(|item| format!("  - {}", escape_controls(item))).collect::<Vec<_>>().join("\n")
}
