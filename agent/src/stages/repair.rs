//! Validation with bounded repair: ask, check, and while the answer is unusable and rounds are
//! left, show the model its own answer and the problems found, then ask again.

use super::{Stage, StageError};
use crate::llm::extract::{answer, reply_text, Answer};
use crate::llm::{Llm, Message, Question};
use crate::prompts::Prompts;

/// Most problems listed in one repair message (the rest are counted).
const MAX_PROBLEMS_SHOWN: usize = 20;

/// Asks `question` until `check` accepts the answer, with at most `max_repairs` repair rounds.
/// `check` returns the value or the problems (as the model should read them, with JSON paths).
pub(crate) async fn ask_until_valid<T>(
    llm: &Llm,
    prompts: &Prompts,
    stage: Stage,
    question: &Question,
    max_repairs: u32,
    check: impl Fn(&Answer) -> Result<T, Vec<String>>,
) -> Result<T, StageError> {
    let attempts = max_repairs + 1;
    let mut turns = Vec::new();
    let mut attempt = 1;
    loop {
        tracing::info!("{stage}: asking {} (attempt {attempt} of {attempts})", llm.model());
        let response = llm.ask(question, &turns).await.map_err(|source| StageError::Llm { stage, source })?;
        let mut problems = match answer(&response) {
            Ok(answer) => match check(&answer) {
                Ok(value) => return Ok(value),
                Err(problems) => problems,
            },
            Err(problem) => vec![problem.to_string()],
        };
        for problem in &problems {
            tracing::warn!("{stage}, attempt {attempt}: {problem}");
        }
        let raw = reply_text(&response);
        if attempt >= attempts {
            return Err(StageError::Invalid { stage, attempts, problems, last_reply: raw });
        }
        if problems.len() > MAX_PROBLEMS_SHOWN {
            let more = problems.len() - MAX_PROBLEMS_SHOWN;
            problems.truncate(MAX_PROBLEMS_SHOWN);
            problems.push(format!("... and {more} more problems"));
        }
        let feedback = prompts.repair(&problems).map_err(|source| StageError::Prompt { stage, source })?;
        turns.push(Message::assistant(if raw.trim().is_empty() { "(empty reply)".to_owned() } else { raw }));
        turns.push(Message::user(feedback));
        attempt += 1;
    }
}
