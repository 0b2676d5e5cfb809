//! Talking to an LLM through any OpenAI-compatible chat-completions endpoint (OpenAI, DeepSeek,
//! vLLM, Ollama, llama.cpp server), or offline from recorded replies.
//!
//! - [`wire`]: the request and response bodies;
//! - [`client`]: HTTP with timeouts and bounded retries ([`retry`]) honouring `Retry-After`;
//! - [`output`]: structured output by server capability, [`strict`]: the strict-mode schema;
//! - [`extract`]: the JSON object inside whatever the model wrapped around it;
//! - [`session`]: [`Llm`], which asks live, records or replays ([`crate::recording`]);
//! - [`api_key`]: the key, which never reaches a log, an error or a recording, and the other
//!   [`api_key::Secrets`] of an endpoint; [`base_url`]: the base URL, printed redacted;
//! - [`escape`]: reply text made safe to print.

pub mod api_key;
pub mod base_url;
pub mod client;
mod error;
pub mod escape;
pub mod extract;
pub mod output;
pub mod retry;
pub mod session;
pub mod strict;
pub mod wire;

pub use api_key::ApiKey;
pub use base_url::BaseUrl;
pub use client::{ClientConfig, Endpoint, HttpClient, OPENAI_BASE_URL};
pub(crate) use error::truncate;
pub use error::LlmError;
pub use escape::escape_controls;
pub use extract::{Answer, ReplyProblem};
pub use output::OutputMode;
pub use retry::RetryPolicy;
pub use session::{Llm, LlmSettings, Question, ReplySource, DEFAULT_MODEL};
pub use strict::strict_schema;
pub use wire::{ChatRequest, ChatResponse, Message, Role};
