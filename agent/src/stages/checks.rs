//! Meaning checks: what a program that parses and fits the schema must still satisfy before the
//! optimiser sees it.
//!
//! [`MEANING_CHECKS`] runs in order on every program, from the LLM or from a task file:
//! [`rules`] covers joints, finite numbers in range, frames inside the clip and the ids of the
//! relational parse ([`TaskProgram::validate`]). The check that the compiled task loss has a
//! non-zero gradient with respect to the motion (ProgMoGen's GPT-written losses had none) joins
//! this list once the constraint compiler exists.

use motion_core::program::{ProgramError, TaskProgram};

/// A meaning check: the problems of `program`, empty when it passes.
pub type MeaningCheck = fn(&TaskProgram) -> Vec<ProgramError>;

/// Every meaning check, in order.
pub const MEANING_CHECKS: &[MeaningCheck] = &[rules];

/// The program's own rules ([`TaskProgram::validate`]).
pub fn rules(program: &TaskProgram) -> Vec<ProgramError> {
    program.validate().err().unwrap_or_default()
}

/// The problems found by every check of [`MEANING_CHECKS`].
pub fn meaning_problems(program: &TaskProgram) -> Vec<ProgramError> {
    MEANING_CHECKS.iter().flat_map(|check| check(program)).collect()
}
