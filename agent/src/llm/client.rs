//! The HTTP client of the chat-completions endpoint: one POST per attempt, with timeouts, a
//! bounded reply size ([`LLM_REPLY_BYTES`]), and bounded retries on 429, 5xx, connection errors
//! and timeouts that honour `Retry-After` within the request timeout.

use std::time::Duration;

use motion_core::limits::LLM_REPLY_BYTES;
use reqwest::{StatusCode, Url};

use super::api_key::{ApiKey, Secrets};
use super::base_url::{redacted, BaseUrl};
use super::error::{truncate, LlmError};
use super::escape::escape_controls;
use super::retry::{retry_after, RetryPolicy};
use super::wire::{ChatRequest, ChatResponse};

/// OpenAI's endpoint, used when only an API key is given.
pub const OPENAI_BASE_URL: &str = "https://api.openai.com/v1";

/// Longest server text kept in an error (characters).
const MAX_BODY_IN_ERROR: usize = 2000;

/// Where the model lives.
#[derive(Debug, Clone, PartialEq)]
pub struct Endpoint {
    /// Base URL up to the API version, e.g. `https://api.openai.com/v1`,
    /// `http://localhost:11434/v1` (Ollama), `http://localhost:8000/v1` (vLLM).
    pub base_url: BaseUrl,
    /// Bearer token; none for local servers.
    pub api_key: Option<ApiKey>,
}

/// Timeouts and retries of the HTTP client.
#[derive(Debug, Clone, PartialEq)]
pub struct ClientConfig {
    /// Limit for one attempt, from connecting to the last byte of the reply; also the most that
    /// the waits between the attempts of one request add up to.
    pub request_timeout: Duration,
    /// Limit for establishing the connection.
    pub connect_timeout: Duration,
    /// Retries and backoff.
    pub retry: RetryPolicy,
}

impl Default for ClientConfig {
    /// 180 s per request (reasoning models are slow), 10 s to connect, [`RetryPolicy::default`].
    fn default() -> Self {
        ClientConfig {
            request_timeout: Duration::from_secs(180),
            connect_timeout: Duration::from_secs(10),
            retry: RetryPolicy::default(),
        }
    }
}

/// A chat-completions client for one endpoint.
#[derive(Debug)]
pub struct HttpClient {
    http: reqwest::Client,
    endpoint: Endpoint,
    config: ClientConfig,
    /// `{base_url}/chat/completions`.
    url: Url,
    /// [`Self::url`] redacted, for messages.
    shown_url: String,
    /// What to scrub from server text.
    secrets: Secrets,
}

/// How one attempt failed.
enum Failure {
    /// Worth another attempt after `retry_after` (or the backoff).
    Retry { error: LlmError, retry_after: Option<Duration>, status: Option<u16> },
    /// Final.
    Fatal(LlmError),
}

impl HttpClient {
    /// A client for `endpoint`.
    pub fn new(endpoint: Endpoint, config: ClientConfig) -> Result<Self, LlmError> {
        let http = reqwest::Client::builder()
            .timeout(config.request_timeout)
            .connect_timeout(config.connect_timeout)
            .user_agent(concat!("mogen/", env!("CARGO_PKG_VERSION")))
            .build()
            .map_err(|error| LlmError::Client(error.to_string()))?;
        let url = endpoint.base_url.chat_completions();
        let shown_url = redacted(&url);
        let secrets = Secrets::new(endpoint.api_key.as_ref(), endpoint.base_url.secrets());
        Ok(HttpClient { http, endpoint, config, url, shown_url, secrets })
    }

    /// The endpoint.
    pub fn endpoint(&self) -> &Endpoint {
        &self.endpoint
    }

    /// Sends `request`, retrying transient failures (429, 5xx, connection errors, timeouts) up to
    /// [`RetryPolicy::max_retries`] times, waiting in all at most the request timeout.
    pub async fn complete(&self, request: &ChatRequest) -> Result<ChatResponse, LlmError> {
        let retry = &self.config.retry;
        let mut waited = Duration::ZERO;
        let mut attempt = 1;
        loop {
            tracing::debug!(url = %self.shown_url, model = %request.model, attempt, "chat completion request");
            let (error, wait_asked, status) = match self.attempt(request, attempt).await {
                Ok(response) => return Ok(response),
                Err(Failure::Fatal(error)) => return Err(error),
                Err(Failure::Retry { error, retry_after, status }) => (error, retry_after, status),
            };
            if attempt > retry.max_retries {
                return Err(error);
            }
            let left = self.config.request_timeout.saturating_sub(waited);
            let wait = retry.wait(attempt - 1, wait_asked, left).map_err(|wait| LlmError::RetryAfterTooLong {
                url: self.shown_url.clone(),
                status: status.unwrap_or(0),
                wait_s: wait.as_secs_f64(),
                left_s: left.min(retry.max_retry_after).as_secs_f64(),
                timeout_s: self.config.request_timeout.as_secs_f64(),
                cap_s: retry.max_retry_after.as_secs_f64(),
            })?;
            tracing::warn!("attempt {attempt} failed: {error}; retrying in {:.1} s", wait.as_secs_f64());
            tokio::time::sleep(wait).await;
            waited += wait;
            attempt += 1;
        }
    }

    async fn attempt(&self, request: &ChatRequest, attempts: u32) -> Result<ChatResponse, Failure> {
        let url = &self.shown_url;
        let mut builder = self.http.post(self.url.clone()).json(request);
        if let Some(key) = &self.endpoint.api_key {
            builder = builder.bearer_auth(key.expose());
        }
        let transport = |error: reqwest::Error| {
            let error = if error.is_timeout() {
                LlmError::Timeout { url: url.clone(), attempts, timeout_s: self.config.request_timeout.as_secs_f64() }
            } else {
                // The URL is in the message already, redacted; reqwest's copy is not.
                LlmError::Connection {
                    url: url.clone(),
                    attempts,
                    message: for_error(&self.secrets.scrub(&error_chain(&error.without_url()))),
                }
            };
            Failure::Retry { error, retry_after: None, status: None }
        };
        let mut response = builder.send().await.map_err(transport)?;
        let status = response.status();
        let wait_asked = retry_after(response.headers());
        let too_large = |error| Failure::Fatal(LlmError::TooLarge(error));
        if let Some(length) = response.content_length() {
            LLM_REPLY_BYTES.check(length, format!("{url}: the reply")).map_err(too_large)?;
        }
        let mut bytes = Vec::new();
        while let Some(chunk) = response.chunk().await.map_err(transport)? {
            bytes.extend_from_slice(&chunk);
            LLM_REPLY_BYTES.check_stream(bytes.len() as u64, format!("{url}: the reply")).map_err(too_large)?;
        }
        let body = self.secrets.scrub(&String::from_utf8_lossy(&bytes));
        tracing::debug!(status = status.as_u16(), bytes = body.len(), "chat completion response");
        if status.is_success() {
            return serde_json::from_str(&body).map_err(|error| {
                Failure::Fatal(LlmError::BadBody {
                    url: url.clone(),
                    message: error.to_string(),
                    body: for_error(&body),
                })
            });
        }
        let error = LlmError::Status { url: url.clone(), status: status.as_u16(), attempts, body: for_error(&body) };
        if status == StatusCode::TOO_MANY_REQUESTS || status.is_server_error() {
            Err(Failure::Retry { error, retry_after: wait_asked, status: Some(status.as_u16()) })
        } else {
            Err(Failure::Fatal(error))
        }
    }
}

/// Server text (scrubbed already) as an error keeps it: cut to [`MAX_BODY_IN_ERROR`] characters,
/// control characters escaped.
fn for_error(text: &str) -> String {
    escape_controls(&truncate(text, MAX_BODY_IN_ERROR)).into_owned()
}

/// The error and its causes, `a: b: c` (reqwest's own message hides the cause, e.g. "connection
/// closed before message completed").
fn error_chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text
}
