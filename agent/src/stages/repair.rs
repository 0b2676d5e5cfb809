//! Validation with bounded repair: ask, check, and while the answer is unusable and rounds are
//! left, show the model its own answer and the problems found, then ask again.
//!
//! A repair request carries the opening messages and the latest round only (the last answer,
//! quoted up to [`REPAIR_QUOTE_CHARS`], and its problems): the model needs nothing older, and a
//! conversation that kept every round would make each request larger than the last.

use motion_core::limits::REPAIR_QUOTE_CHARS;

use super::stage::{Stage, StageError};
use crate::llm::extract::{answer, reply_text, Answer};
use crate::llm::{escape_controls, truncate, Llm, Message, Question};
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
        let problems = match answer(&response) {
            Ok(answer) => match check(&answer) {
                Ok(value) => return Ok(value),
                Err(problems) => problems,
            },
            Err(problem) => vec![problem.to_string()],
        };
        for problem in &problems {
            tracing::warn!("{stage}, attempt {attempt}: {}", escape_controls(problem));
        }
        let raw = reply_text(&response);
        if attempt >= attempts {
            return Err(StageError::Invalid { stage, attempts, problems, last_reply: raw });
        }
        let feedback =
            prompts.repair(&problems_to_show(problems)).map_err(|source| StageError::Prompt { stage, source })?;
        turns = vec![Message::assistant(quote(&raw)), Message::user(feedback)];
        attempt += 1;
    }
}

/// The bad reply as a repair round quotes it back: at most [`REPAIR_QUOTE_CHARS`] characters,
/// cut on a character boundary with a note of how many more there were.
fn quote(raw: &str) -> String {
    if raw.trim().is_empty() {
        "(empty reply)".to_owned()
    } else {
        truncate(raw, REPAIR_QUOTE_CHARS.max_usize())
    }
}

/// At most [`MAX_PROBLEMS_SHOWN`] problems (the rest counted), each cut to its share of
/// [`REPAIR_QUOTE_CHARS`]: problems may quote the reply (a schema error shows the bad value), and
/// the list as a whole must not outgrow the quote of the reply itself.
fn problems_to_show(mut problems: Vec<String>) -> Vec<String> {
    if problems.len() > MAX_PROBLEMS_SHOWN {
        let more = problems.len() - MAX_PROBLEMS_SHOWN;
        problems.truncate(MAX_PROBLEMS_SHOWN);
        problems.push(format!("... and {more} more problems"));
    }
    let share = REPAIR_QUOTE_CHARS.max_usize() / MAX_PROBLEMS_SHOWN;
    problems.iter().map(|problem| truncate(problem, share)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_reply_is_quoted_up_to_the_limit_on_a_character_boundary() {
        let max = REPAIR_QUOTE_CHARS.max_usize();
        assert_eq!(quote(" \n"), "(empty reply)");
        assert_eq!(quote("{\"a\": 1}"), "{\"a\": 1}");
        let long = "é".repeat(max + 5);
        let quoted = quote(&long);
        assert!(quoted.starts_with(&"é".repeat(max)), "cut after {max} characters");
        assert!(quoted.ends_with("é… [5 more characters]"), "{}", &quoted[quoted.len() - 40..]);
    }

    #[test]
    fn problems_are_counted_and_cut() {
        let problems: Vec<String> = (0..25).map(|i| format!("problem {i}: {}", "x".repeat(5000))).collect();
        let shown = problems_to_show(problems);
        assert_eq!(shown.len(), MAX_PROBLEMS_SHOWN + 1);
        assert_eq!(shown[MAX_PROBLEMS_SHOWN], "... and 5 more problems");
        let total: usize = shown.iter().map(|problem| problem.chars().count()).sum();
        assert!(total < REPAIR_QUOTE_CHARS.max_usize() + 1000, "{total} characters");
    }
}
