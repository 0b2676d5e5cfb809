//! A misbehaving LLM endpoint meets bounds (issue 18, items 5 to 7): an endless or huge reply is
//! cut off at `LLM_REPLY_BYTES`, repair prompts quote at most `REPAIR_QUOTE_CHARS` of a bad
//! reply, waits on `Retry-After` stay within the request timeout, secrets in the base URL or
//! echoed in any case never reach a message, and control characters of replies are escaped.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::future::Future;
use std::time::{Duration, Instant};

use agent::llm::{ApiKey, ClientConfig, Llm, LlmSettings, RetryPolicy};
use agent::plan::{plan_task, PlanError, PlanSettings, PlannedTask};
use e2e_tests::llm_server::{hand_written_named, LlmServer, Step};
use motion_core::limits::{LLM_REPLY_BYTES, REPAIR_QUOTE_CHARS};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpListener;

/// The API key, with upper-case letters so that an echo in lower case is a different string.
const KEY: &str = "sk-test-7f3a9c0e-DO-NOT-LEAK";

/// No test may take longer than this, whatever the server does.
const BOUND: Duration = Duration::from_secs(15);

fn settings(base_url: &str, request_timeout: Duration, max_retries: u32) -> LlmSettings {
    LlmSettings {
        base_url: Some(base_url.to_owned()),
        api_key: ApiKey::new(KEY),
        model: "gpt-4.1".into(),
        source: None,
        recordings: std::env::temp_dir().join("mogen-unused-recordings"),
        client: ClientConfig {
            request_timeout,
            connect_timeout: Duration::from_secs(1),
            retry: RetryPolicy { max_retries, initial_backoff: Duration::from_millis(20), ..RetryPolicy::default() },
        },
        output: None,
        temperature: Some(0.0),
        max_tokens: None,
    }
}

async fn bounded<T>(future: impl Future<Output = T>) -> T {
    tokio::time::timeout(BOUND, future).await.expect("the test ran past its bound")
}

/// Plans the gap task with `settings`; also returns the time it took.
async fn plan_with(settings: LlmSettings) -> (Result<PlannedTask, PlanError>, Duration) {
    let start = Instant::now();
    let llm = Llm::connect(settings).unwrap();
    let task = hand_written_named("gap_stop_5m").task;
    let result = bounded(plan_task(&task, &llm, &PlanSettings::default(), &candle_core::Device::Cpu)).await;
    (result, start.elapsed())
}

/// A server on 127.0.0.1 that answers every request with HTTP 200, the header `extra` and then
/// 16 KiB of body every millisecond, for ever (the throttle keeps a client without a bound from
/// filling the test machine's memory before its timeout). Returns the base URL.
async fn endless_server(extra: &'static str) -> String {
    let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
    let base_url = format!("http://{}/v1", listener.local_addr().unwrap());
    tokio::spawn(async move {
        while let Ok((mut stream, _)) = listener.accept().await {
            tokio::spawn(async move {
                // The request head is enough; the body stays in the socket buffer.
                let mut head = Vec::new();
                let mut buffer = [0u8; 8192];
                while !head.windows(4).any(|w| w == b"\r\n\r\n") {
                    match stream.read(&mut buffer).await {
                        Ok(0) | Err(_) => return,
                        Ok(n) => head.extend_from_slice(&buffer[..n]),
                    }
                }
                let head =
                    format!("HTTP/1.1 200 OK\r\ncontent-type: application/json\r\n{extra}connection: close\r\n\r\n");
                if stream.write_all(head.as_bytes()).await.is_err() {
                    return;
                }
                let chunk = vec![b' '; 16 << 10];
                while stream.write_all(&chunk).await.is_ok() {
                    tokio::time::sleep(Duration::from_millis(1)).await;
                }
            });
        }
    });
    base_url
}

/// The error of planning against [`endless_server`] with header `extra` (3 s timeout, no
/// retries), the time it took, and the phrase every reply-size error holds.
async fn too_large(extra: &'static str) -> (String, Duration, String) {
    let base_url = endless_server(extra).await;
    let (result, took) = plan_with(settings(&base_url, Duration::from_secs(3), 0)).await;
    let over = format!("over the limit of {} bytes (LLM reply size)", LLM_REPLY_BYTES.max);
    (result.unwrap_err().to_string(), took, over)
}

#[tokio::test]
async fn an_endless_reply_stops_at_the_reply_limit() {
    let (error, took, over) = too_large("").await;
    assert!(error.contains(&over) && error.contains("/v1/chat/completions: the reply is at least"), "{error}");
    assert!(took < Duration::from_secs(3), "the reply was read until the timeout: {took:?}");
}

#[tokio::test]
async fn a_declared_huge_reply_is_refused_before_its_body() {
    let (error, took, over) = too_large("content-length: 10000000000\r\n").await;
    assert!(error.contains(&over) && error.contains("the reply is 10000000000 bytes"), "{error}");
    assert!(took < Duration::from_secs(1), "{took:?}");
}

#[tokio::test]
async fn repair_prompts_quote_a_bounded_part_of_the_bad_reply() {
    // 600,000 characters (over 900 kB: under the reply limit, far over the quote limit), with
    // two-byte characters so that a cut on a byte count would split one.
    let bad = "no JSON here, só prosa. ".repeat(25_000);
    let server = LlmServer::start(vec![Step::reply(&bad); 3]).await;
    let (result, _) = plan_with(settings(&server.base_url, Duration::from_secs(5), 0)).await;
    let error = result.unwrap_err().to_string();
    assert!(error.contains("no valid answer in 3 attempt(s)"), "{error}");
    let received = server.received();
    assert_eq!(received.len(), 3);
    let size = |i: usize| serde_json::to_string(&received[i].body).unwrap().len();
    let quote_bytes = 4 * REPAIR_QUOTE_CHARS.max_usize();
    assert!(size(1) < size(0) + quote_bytes + 4096, "first repair request: {} bytes", size(1));
    assert!(size(2) <= size(1) + 256, "the repair requests grow: {} then {} bytes", size(1), size(2));
    let messages = received[2].body["messages"].as_array().unwrap();
    let quoted = messages[messages.len() - 2]["content"].as_str().unwrap();
    assert!(quoted.starts_with("no JSON here, só prosa."), "{quoted}");
    let cut = 600_000 - REPAIR_QUOTE_CHARS.max_usize();
    assert!(quoted.ends_with(&format!("… [{cut} more characters]")), "{quoted}");
}

#[tokio::test]
async fn a_retry_after_longer_than_the_timeout_fails_at_once() {
    let timeout = Duration::from_secs(3);
    let limited = Step::status(429, "Rate limit reached").with_header("retry-after", "100");
    let server = LlmServer::start(vec![limited]).await;
    let (result, took) = plan_with(settings(&server.base_url, timeout, 3)).await;
    let error = result.unwrap_err().to_string();
    assert!(error.contains("asked to wait 100 s") && error.contains("--timeout"), "{error}");
    assert!(took < Duration::from_secs(1), "{took:?}");
    assert_eq!(server.received().len(), 1);
    // Waits that each fit but together do not: the second one is refused.
    let limited = || Step::status(503, "busy").with_header("retry-after", "2");
    let server = LlmServer::start(vec![limited(), limited(), limited()]).await;
    let (result, took) = plan_with(settings(&server.base_url, timeout, 3)).await;
    let error = result.unwrap_err().to_string();
    assert!(error.contains("asked to wait 2 s") && error.contains("--timeout"), "{error}");
    assert!(took < timeout + Duration::from_millis(500), "{took:?}");
    assert_eq!(server.received().len(), 2);
    // A wait that fits is honoured.
    let gap = hand_written_named("gap_stop_5m");
    let limited = Step::status(429, "Rate limit reached").with_header("retry-after", "1");
    let server =
        LlmServer::start(vec![limited, Step::reply(&gap.program_reply()), Step::reply(&gap.parse_reply())]).await;
    let (result, took) = plan_with(settings(&server.base_url, timeout, 3)).await;
    assert_eq!(result.unwrap_or_else(|error| panic!("{error}")).program.program().constraints, gap.program.constraints);
    assert!(took >= Duration::from_secs(1), "{took:?}");
}

#[tokio::test]
async fn secrets_in_the_base_url_or_echoed_in_any_case_are_redacted() {
    let (user_key, query_key) = ("sk-userinfo-4b1d-SECRET", "sk-query-9e2c-SECRET");
    let echo = format!("Incorrect API key provided: bearer {}; query {query_key}", KEY.to_lowercase());
    let server = LlmServer::start(vec![Step::status(401, &echo)]).await;
    let address = server.base_url.trim_start_matches("http://");
    let base_url = format!("http://user:{user_key}@{address}?api_key={query_key}");
    let settings = settings(&base_url, Duration::from_secs(3), 0);
    let described = Llm::connect(settings.clone()).unwrap().describe();
    let settings_debug = format!("{settings:?}");
    let error = plan_with(settings).await.0.unwrap_err();
    // The query string stays a query string after the joined path.
    let request_line = &server.received()[0].request_line;
    assert_eq!(request_line, &format!("POST /v1/chat/completions?api_key={query_key} HTTP/1.1"));
    let (shown, debug) = (error.to_string(), format!("{error:?}"));
    assert!(shown.contains("HTTP 401") && shown.contains("[REDACTED]"), "{shown}");
    assert!(described.contains(&format!("gpt-4.1 at http://[REDACTED]@{address}?api_key=[REDACTED]")), "{described}");
    let places =
        [("description", &described), ("settings", &settings_debug), ("error", &shown), ("error (debug)", &debug)];
    for (place, text) in places {
        let lower = text.to_lowercase();
        for secret in [KEY, user_key, query_key] {
            assert!(!lower.contains(&secret.to_lowercase()), "{secret} leaked into the {place}: {text}");
        }
    }
}

#[tokio::test]
async fn control_characters_of_replies_are_escaped_in_errors() {
    let bad = "\u{1b}[2J\u{1b}[31mno JSON\u{1b}[0m\r\tstill\u{7}\nnext line";
    let server = LlmServer::start(vec![Step::reply(bad); 3]).await;
    let error = plan_with(settings(&server.base_url, Duration::from_secs(3), 0)).await.0.unwrap_err().to_string();
    assert!(error.contains(r"\u{1b}[2J\u{1b}[31mno JSON\u{1b}[0m\r	still\u{7}"), "{error}");
    assert!(error.contains("\nnext line"), "newlines stay readable: {error}");
    // An error body that is not JSON, raw control characters included.
    let body = "\u{1b}]0;pwned\u{7} teapot\u{9b}31m".to_owned();
    let server = LlmServer::start(vec![Step::Respond { status: 418, headers: Vec::new(), body }]).await;
    let status = plan_with(settings(&server.base_url, Duration::from_secs(3), 0)).await.0.unwrap_err().to_string();
    assert!(status.contains(r"\u{1b}]0;pwned\u{7} teapot\u{9b}31m"), "{status}");
    for text in [&error, &status] {
        assert!(!text.chars().any(|c| c.is_control() && c != '\n' && c != '\t'), "{text:?}");
    }
}
