//! The `mogen` library: talking to an LLM through any OpenAI-compatible endpoint, with recorded
//! replies.

pub mod llm;
pub mod paths;
pub mod recording;
