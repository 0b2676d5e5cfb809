//! The HTTP client of the chat-completions endpoint: one POST per attempt, with timeouts, and
//! bounded retries on 429, 5xx, connection errors and timeouts that honour `Retry-After`.

use std::time::Duration;

use reqwest::StatusCode;

use super::api_key::{scrub, ApiKey};
use super::error::{truncate, LlmError};
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
    pub base_url: String,
    /// Bearer token; none for local servers.
    pub api_key: Option<ApiKey>,
}

impl Endpoint {
    /// `{base_url}/chat/completions`.
    pub fn chat_completions_url(&self) -> String {
        format!("{}/chat/completions", self.base_url.trim_end_matches('/'))
    }
}

/// Timeouts and retries of the HTTP client.
#[derive(Debug, Clone, PartialEq)]
pub struct ClientConfig {
    /// Limit for one attempt, from connecting to the last byte of the reply.
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
        Ok(HttpClient { http, endpoint, config })
    }

    /// The endpoint.
    pub fn endpoint(&self) -> &Endpoint {
        &self.endpoint
    }

    /// Sends `request`, retrying transient failures (429, 5xx, connection errors, timeouts) up to
    /// [`RetryPolicy::max_retries`] times.
    pub async fn complete(&self, request: &ChatRequest) -> Result<ChatResponse, LlmError> {
        let url = self.endpoint.chat_completions_url();
        let retry = &self.config.retry;
        let mut attempt = 1;
        loop {
            tracing::debug!(%url, model = %request.model, attempt, "chat completion request");
            let (error, wait_asked, status) = match self.attempt(&url, request, attempt).await {
                Ok(response) => return Ok(response),
                Err(Failure::Fatal(error)) => return Err(error),
                Err(Failure::Retry { error, retry_after, status }) => (error, retry_after, status),
            };
            if attempt > retry.max_retries {
                return Err(error);
            }
            let wait = retry.wait(attempt - 1, wait_asked).map_err(|wait| LlmError::RetryAfterTooLong {
                url: url.clone(),
                status: status.unwrap_or(0),
                wait_s: wait.as_secs_f64(),
                max_s: retry.max_retry_after.as_secs_f64(),
            })?;
            tracing::warn!("attempt {attempt} failed: {error}; retrying in {:.1} s", wait.as_secs_f64());
            tokio::time::sleep(wait).await;
            attempt += 1;
        }
    }

    async fn attempt(&self, url: &str, request: &ChatRequest, attempts: u32) -> Result<ChatResponse, Failure> {
        let key = self.endpoint.api_key.as_ref();
        let mut builder = self.http.post(url).json(request);
        if let Some(key) = key {
            builder = builder.bearer_auth(key.expose());
        }
        let transport = |error: reqwest::Error| {
            let error = if error.is_timeout() {
                LlmError::Timeout {
                    url: url.to_owned(),
                    attempts,
                    timeout_s: self.config.request_timeout.as_secs_f64(),
                }
            } else {
                LlmError::Connection { url: url.to_owned(), attempts, message: scrub(key, &error_chain(&error)) }
            };
            Failure::Retry { error, retry_after: None, status: None }
        };
        let response = builder.send().await.map_err(transport)?;
        let status = response.status();
        let wait_asked = retry_after(response.headers());
        let body = response.text().await.map_err(transport)?;
        let body = scrub(key, &body);
        tracing::debug!(status = status.as_u16(), bytes = body.len(), "chat completion response");
        if status.is_success() {
            return serde_json::from_str(&body).map_err(|error| {
                Failure::Fatal(LlmError::BadBody {
                    url: url.to_owned(),
                    message: error.to_string(),
                    body: truncate(&body, MAX_BODY_IN_ERROR),
                })
            });
        }
        let error = LlmError::Status {
            url: url.to_owned(),
            status: status.as_u16(),
            attempts,
            body: truncate(&body, MAX_BODY_IN_ERROR),
        };
        if status == StatusCode::TOO_MANY_REQUESTS || status.is_server_error() {
            Err(Failure::Retry { error, retry_after: wait_asked, status: Some(status.as_u16()) })
        } else {
            Err(Failure::Fatal(error))
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn url_joins_without_double_slashes() {
        let endpoint = |base: &str| Endpoint { base_url: base.into(), api_key: None };
        assert_eq!(
            endpoint("http://localhost:8000/v1/").chat_completions_url(),
            "http://localhost:8000/v1/chat/completions"
        );
        assert_eq!(endpoint(OPENAI_BASE_URL).chat_completions_url(), "https://api.openai.com/v1/chat/completions");
    }
}
