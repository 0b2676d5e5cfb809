//! Errors of talking to an LLM: transport, HTTP status, unusable bodies, recordings.
//!
//! Server text in these errors (bodies, reqwest messages) is scrubbed of the endpoint's secrets
//! and has its control characters escaped before it is stored here; URLs are stored redacted
//! ([`super::base_url::redacted`]).

use std::path::PathBuf;

use motion_core::limits::LimitExceeded;

/// Why an exchange with the LLM (live, recorded or replayed) failed.
#[derive(Debug, thiserror::Error)]
pub enum LlmError {
    /// The HTTP client could not be set up (TLS backend, invalid settings).
    #[error("cannot set up the HTTP client: {0}")]
    Client(String),
    /// Live or record mode without an endpoint.
    #[error(
        "no LLM endpoint configured: give --base-url (or OPENAI_BASE_URL) for a local or compatible server, \
         or --api-key (or OPENAI_API_KEY) for OpenAI"
    )]
    NoEndpoint,
    /// The base URL does not parse or is not an HTTP URL.
    #[error("--base-url (or OPENAI_BASE_URL) is not a usable base URL: {reason}")]
    BaseUrl {
        /// Why (the URL itself is not repeated: it may hold a key).
        reason: String,
    },
    /// Could not connect, or the connection broke, on every attempt.
    #[error("{url}: connection failed on all {attempts} attempt(s): {message}")]
    Connection {
        /// The endpoint.
        url: String,
        /// Attempts made.
        attempts: u32,
        /// The last transport error.
        message: String,
    },
    /// No complete answer within the request timeout, on every attempt.
    #[error("{url}: no answer within {timeout_s} s on all {attempts} attempt(s)")]
    Timeout {
        /// The endpoint.
        url: String,
        /// Attempts made.
        attempts: u32,
        /// The per-request timeout (s).
        timeout_s: f64,
    },
    /// The server answered with an error status (after retries for 429 and 5xx).
    #[error("{url} answered HTTP {status} on attempt {attempts}: {body}")]
    Status {
        /// The endpoint.
        url: String,
        /// HTTP status code.
        status: u16,
        /// Attempts made.
        attempts: u32,
        /// The server's reply text (truncated, key scrubbed).
        body: String,
    },
    /// The server asked to wait longer than the time left for waiting.
    #[error(
        "{url} answered HTTP {status} and asked to wait {wait_s:.0} s before retrying, more than the {left_s:.1} s \
         of waiting left: the waits of one request add up to at most its timeout (--timeout, {timeout_s} s here) \
         and each is at most {cap_s:.0} s"
    )]
    RetryAfterTooLong {
        /// The endpoint.
        url: String,
        /// HTTP status code.
        status: u16,
        /// The wait asked for (s).
        wait_s: f64,
        /// The wait that was left (s).
        left_s: f64,
        /// The request timeout, which bounds all waits of a request together (s).
        timeout_s: f64,
        /// The longest single `Retry-After` honoured (s).
        cap_s: f64,
    },
    /// The reply is larger than [`motion_core::limits::LLM_REPLY_BYTES`].
    #[error(transparent)]
    TooLarge(#[from] LimitExceeded),
    /// HTTP 200 with a body that is not a chat completion.
    #[error("{url} answered HTTP 200 with a body that is not a chat completion ({message}): {body}")]
    BadBody {
        /// The endpoint.
        url: String,
        /// The parse error.
        message: String,
        /// The body (truncated, key scrubbed).
        body: String,
    },
    /// Replay found no recording for this exchange.
    #[error(
        "no recorded reply for this exchange (task {task:?}, stage {stage}, key {key}) in {dir}: \
         the prompt, the schema or the model differ from every recording. Configure an endpoint \
         (--base-url / OPENAI_BASE_URL, --api-key / OPENAI_API_KEY) to ask a live model, with --record to \
         add the reply to the recordings.{known}"
    )]
    ReplayMiss {
        /// The recording key that was looked up.
        key: String,
        /// The task of the exchange.
        task: String,
        /// The stage of the exchange.
        stage: String,
        /// The recordings folder.
        dir: String,
        /// The recorded tasks, as a sentence (empty when there are none).
        known: String,
    },
    /// A recording could not be read or written.
    #[error("recording {}: {message}", path.display())]
    Recording {
        /// The file or folder.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
}

/// At most `max` characters of `text`, marked when cut.
pub(crate) fn truncate(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        Some((at, _)) => format!("{}… [{} more characters]", &text[..at], text[at..].chars().count()),
        None => text.to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truncate_marks_what_it_cuts() {
        assert_eq!(truncate("abc", 3), "abc");
        assert_eq!(truncate("abcdé", 3), "abc… [2 more characters]");
    }
}
