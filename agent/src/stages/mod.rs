//! The two LLM stages of a task and the validation-and-repair loop they share.
//!
//! 1. [`generate_program`]: task text → constraint program (ProgMoGen's motion programming, but
//!    the program is typed data, never code);
//! 2. [`parse_relations`]: constraints → RG-DNO's relational task parse (supp. Fig. 9), which
//!    Algorithm 1 ([`motion_core::program::TaskProgram::constraint_groups`]) turns into the
//!    retrieval set and the fitting sets.
//!
//! Every reply goes through extraction, JSON Schema validation with paths, deserialisation and
//! the meaning checks ([`motion_core::constraints::checked::CheckedProgram::check`]); the problems go back to the model for a bounded number of repair
//! rounds (`repair`).

mod program;
mod relational;
mod repair;
mod stage;

pub use program::{check_program, generate_program, program_question, program_schema};
pub use relational::{parse_question, parse_relations, parse_schema, RelationalAnswer};
pub use stage::{Stage, StageError};
