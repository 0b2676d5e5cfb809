//! The `mogen` library: a motion task in words → a validated constraint program, through any
//! OpenAI-compatible chat-completions endpoint or offline from recorded replies.
//!
//! [`plan::plan_task`] runs the pipeline: [`stages`] ask the [`llm`] for a constraint program and
//! then for RG-DNO's relational parse, each answer checked against the schema and the program's
//! rules and repaired in a bounded number of rounds; [`recording`] records and replays the
//! exchanges; [`prompts`] renders the templates of the repository's `prompts/` folder.

pub mod llm;
pub mod paths;
pub mod plan;
pub mod prompts;
pub mod recording;
pub mod stages;
