//! The LLM as the stages see it: one [`Llm::ask`] that sends a [`Question`] live, records the
//! exchange, or replays it from the recordings, and walks the structured-output ladder when a
//! server rejects a `response_format`.

use std::cell::Cell;
use std::fmt;
use std::path::PathBuf;

use serde_json::Value;

use super::api_key::{ApiKey, REDACTED};
use super::base_url::BaseUrl;
use super::client::{ClientConfig, Endpoint, HttpClient, OPENAI_BASE_URL};
use super::error::LlmError;
use super::output::OutputMode;
use super::wire::{ChatRequest, ChatResponse, Message};
use crate::recording::{self, Exchange, Recordings};

/// The default model: what the shipped recordings were made for.
pub const DEFAULT_MODEL: &str = "gpt-4.1";

/// Where replies come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReplySource {
    /// Ask the endpoint.
    Live,
    /// Ask the endpoint and write every exchange to the recordings folder.
    Record,
    /// Answer from the recordings folder; no network.
    Replay,
}

/// What the command line (or a test) says about the LLM. Its `Debug` form redacts the secrets.
#[derive(Clone)]
pub struct LlmSettings {
    /// Base URL of an OpenAI-compatible API; `None` with a key means OpenAI's. User info and
    /// query values in it are secrets ([`BaseUrl`]).
    pub base_url: Option<String>,
    /// Bearer token.
    pub api_key: Option<ApiKey>,
    /// Model name.
    pub model: String,
    /// `None`: live when an endpoint is configured (a base URL or a key), else replay.
    pub source: Option<ReplySource>,
    /// The recordings folder.
    pub recordings: PathBuf,
    /// Timeouts and retries.
    pub client: ClientConfig,
    /// `None`: start from what the server is known to support and step down the ladder when it
    /// rejects a mode; `Some`: always this mode.
    pub output: Option<OutputMode>,
    /// Sampling temperature (`None`: the server's default).
    pub temperature: Option<f64>,
    /// Reply token limit (`None`: the server's default).
    pub max_tokens: Option<u32>,
}

impl fmt::Debug for LlmSettings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Redacted by `BaseUrl`; a URL that does not parse cannot be redacted part by part.
        let base_url =
            self.base_url.as_deref().map(|url| BaseUrl::parse(url).map_or(REDACTED.to_owned(), |url| url.to_string()));
        f.debug_struct("LlmSettings")
            .field("base_url", &base_url)
            .field("api_key", &self.api_key)
            .field("model", &self.model)
            .field("source", &self.source)
            .field("recordings", &self.recordings)
            .field("client", &self.client)
            .field("output", &self.output)
            .field("temperature", &self.temperature)
            .field("max_tokens", &self.max_tokens)
            .finish()
    }
}

/// A question for the model: the opening messages in every output mode and the reply's schema.
#[derive(Debug, Clone, PartialEq)]
pub struct Question {
    /// The task in words (names recordings and errors).
    pub task: String,
    /// The stage asking (`program`, `relational_parse`).
    pub stage: &'static str,
    /// Name of the schema in `response_format`.
    pub schema_name: &'static str,
    /// The reply's schema, sanitised for strict mode ([`super::strict_schema`]).
    pub schema: Value,
    /// The opening messages per mode, in the order of [`OutputMode::LADDER`].
    pub opening: [Vec<Message>; 3],
}

impl Question {
    /// The opening messages for `mode`.
    pub fn opening(&self, mode: OutputMode) -> &[Message] {
        let rung = OutputMode::LADDER.iter().position(|m| *m == mode).unwrap_or(0);
        &self.opening[rung]
    }
}

enum Transport {
    Live(HttpClient),
    Record(HttpClient, PathBuf),
    Replay(Recordings),
}

/// The LLM one command asks.
pub struct Llm {
    transport: Transport,
    model: String,
    temperature: Option<f64>,
    max_tokens: Option<u32>,
    /// The current rung of the ladder (it only goes down, for the rest of this `Llm`'s life).
    mode: Cell<OutputMode>,
    step_down: bool,
}

impl Llm {
    /// Sets up the LLM of `settings`: an HTTP client, or the recordings for replay.
    pub fn connect(settings: LlmSettings) -> Result<Llm, LlmError> {
        let base_url = match (&settings.base_url, &settings.api_key) {
            (Some(url), _) => Some(url.clone()),
            (None, Some(_)) => Some(OPENAI_BASE_URL.to_owned()),
            (None, None) => None,
        };
        let source =
            settings.source.unwrap_or(if base_url.is_some() { ReplySource::Live } else { ReplySource::Replay });
        let mode = settings
            .output
            .unwrap_or_else(|| base_url.as_deref().map_or(OutputMode::JsonSchema, OutputMode::for_base_url));
        let client = |base_url: Option<String>| {
            let base_url = BaseUrl::parse(&base_url.ok_or(LlmError::NoEndpoint)?)?;
            HttpClient::new(Endpoint { base_url, api_key: settings.api_key.clone() }, settings.client.clone())
        };
        let transport = match source {
            ReplySource::Live => Transport::Live(client(base_url)?),
            ReplySource::Record => Transport::Record(client(base_url)?, settings.recordings.clone()),
            ReplySource::Replay => Transport::Replay(Recordings::open(&settings.recordings)?),
        };
        Ok(Llm {
            transport,
            model: settings.model,
            temperature: settings.temperature,
            max_tokens: settings.max_tokens,
            mode: Cell::new(mode),
            step_down: settings.output.is_none(),
        })
    }

    /// The model name.
    pub fn model(&self) -> &str {
        &self.model
    }

    /// Where replies come from.
    pub fn source(&self) -> ReplySource {
        match self.transport {
            Transport::Live(_) => ReplySource::Live,
            Transport::Record(..) => ReplySource::Record,
            Transport::Replay(_) => ReplySource::Replay,
        }
    }

    /// One line saying where replies come from, for the user (the base URL redacted).
    pub fn describe(&self) -> String {
        match &self.transport {
            Transport::Live(client) => {
                format!("{} at {} ({})", self.model, client.endpoint().base_url, self.mode.get())
            }
            Transport::Record(client, dir) => format!(
                "{} at {} ({}), recording into {}",
                self.model,
                client.endpoint().base_url,
                self.mode.get(),
                dir.display()
            ),
            Transport::Replay(recordings) => format!(
                "recorded replies of {} in {} ({} exchanges; no network)",
                self.model,
                recordings.dir().display(),
                recordings.len()
            ),
        }
    }

    /// Asks `question` followed by `turns` (earlier replies and repair feedback). When the server
    /// rejects the output mode (HTTP 400 or 422 about the response format) and the mode was not
    /// fixed, steps down the ladder for the rest of this `Llm`'s life and asks again.
    pub async fn ask(&self, question: &Question, turns: &[Message]) -> Result<ChatResponse, LlmError> {
        loop {
            let mode = self.mode.get();
            let mut messages = question.opening(mode).to_vec();
            messages.extend_from_slice(turns);
            let request = ChatRequest {
                model: self.model.clone(),
                messages,
                response_format: mode.response_format(question.schema_name, &question.schema),
                temperature: self.temperature,
                max_tokens: self.max_tokens,
            };
            let result = self.exchange(question, request).await;
            let rejected =
                matches!(&result, Err(LlmError::Status { status: 400 | 422, body, .. }) if about_output_mode(body));
            match (result, mode.fallback().filter(|_| rejected && self.step_down)) {
                (Err(error), Some(next)) => {
                    tracing::warn!("the server rejected {mode}; asking again with {next}: {error}");
                    self.mode.set(next);
                }
                (result, _) => return result,
            }
        }
    }

    async fn exchange(&self, question: &Question, request: ChatRequest) -> Result<ChatResponse, LlmError> {
        let key = || recording::key(&request.model, &request.messages, &question.schema);
        match &self.transport {
            Transport::Live(client) => client.complete(&request).await,
            Transport::Record(client, dir) => {
                let response = client.complete(&request).await?;
                let exchange = Exchange {
                    key: key(),
                    task: question.task.clone(),
                    stage: question.stage.to_owned(),
                    request,
                    response,
                };
                let path = recording::record(dir, &exchange, client.endpoint().api_key.as_ref())?;
                tracing::info!("recorded {}", path.display());
                Ok(exchange.response)
            }
            Transport::Replay(recordings) => {
                let key = key();
                match recordings.get(&key) {
                    Some(exchange) => Ok(exchange.response.clone()),
                    None => Err(recordings.miss(&key, &question.task, question.stage)),
                }
            }
        }
    }
}

/// Whether an HTTP 400/422 body is about the structured-output request (`response_format`,
/// `json_schema`, a grammar) rather than something else (the model name, the temperature).
fn about_output_mode(body: &str) -> bool {
    let body = body.to_ascii_lowercase();
    ["response_format", "json_schema", "json_object", "schema", "grammar", "structured"]
        .iter()
        .any(|word| body.contains(word))
}
