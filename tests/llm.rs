//! The LLM path over real HTTP on 127.0.0.1: a scripted server plays an OpenAI-compatible
//! endpoint while `plan_task` runs both stages. Every fault ends in recovery or in a clear error
//! within a bounded time (short timeouts and backoff here; the defaults are minutes).

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::future::Future;
use std::io::Write;
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use agent::llm::wire::ReplyMessage;
use agent::llm::{ApiKey, ChatRequest, ChatResponse, ClientConfig, Llm, LlmSettings, ReplySource, RetryPolicy};
use agent::plan::{plan_task, PlanError, PlanSettings, PlannedTask};
use e2e_tests::llm_server::{hand_written_named, malformed, HandWritten, LlmServer, Received, Step};
use serde_json::Value;

/// A key distinctive enough to find anywhere it leaks.
const KEY: &str = "sk-test-7f3a9c0e-DO-NOT-LEAK";

/// No test may take longer than this, whatever the server does.
const BOUND: Duration = Duration::from_secs(20);

fn fast_client() -> ClientConfig {
    ClientConfig {
        request_timeout: Duration::from_millis(400),
        connect_timeout: Duration::from_millis(400),
        retry: RetryPolicy {
            max_retries: 2,
            initial_backoff: Duration::from_millis(20),
            max_backoff: Duration::from_millis(100),
            max_retry_after: Duration::from_secs(5),
        },
    }
}

fn settings(server: &LlmServer) -> LlmSettings {
    LlmSettings {
        base_url: Some(server.base_url.clone()),
        api_key: ApiKey::new(KEY),
        model: "gpt-4.1".into(),
        source: None,
        recordings: std::env::temp_dir().join("mogen-unused-recordings"),
        client: fast_client(),
        output: None,
        temperature: Some(0.0),
        max_tokens: None,
    }
}

fn gap() -> HandWritten {
    hand_written_named("gap_stop_5m")
}

async fn bounded<T>(future: impl Future<Output = T>) -> T {
    tokio::time::timeout(BOUND, future).await.expect("the test ran past its bound")
}

/// Plans the gap task against `server`; also returns the time it took.
async fn plan_with(settings: LlmSettings) -> (Result<PlannedTask, PlanError>, Duration) {
    let start = Instant::now();
    let llm = Llm::connect(settings).unwrap();
    let result = bounded(plan_task(&gap().task, &llm, &PlanSettings::default(), &candle_core::Device::Cpu)).await;
    (result, start.elapsed())
}

async fn plan(server: &LlmServer) -> (Result<PlannedTask, PlanError>, Duration) {
    plan_with(settings(server)).await
}

fn assert_planned(result: Result<PlannedTask, PlanError>) {
    let planned = result.unwrap_or_else(|error| panic!("{error}"));
    assert_eq!(planned.program.program(), &gap().planned_program());
    let groups = planned.groups.unwrap();
    assert_eq!(
        (groups.retrieval, groups.random_noise),
        (vec!["c1".into(), "c2".into()], vec!["c2".into(), "c3".into()])
    );
}

fn program() -> Step {
    Step::reply(&gap().program_reply())
}

fn parse() -> Step {
    Step::reply(&gap().parse_reply())
}

fn messages(request: &Received) -> Vec<(String, String)> {
    let messages = request.body["messages"].as_array().unwrap();
    messages.iter().map(|m| (m["role"].as_str().unwrap().into(), m["content"].as_str().unwrap().into())).collect()
}

fn contains_null(value: &Value) -> bool {
    match value {
        Value::Null => true,
        Value::Array(items) => items.iter().any(contains_null),
        Value::Object(map) => map.values().any(contains_null),
        _ => false,
    }
}

#[tokio::test]
async fn well_formed_replies_plan_the_task_with_chat_completion_requests() {
    let server = LlmServer::start(vec![program(), parse()]).await;
    let (result, _) = plan(&server).await;
    assert_planned(result);
    let received = server.received();
    assert_eq!(received.len(), 2);
    for (request, name) in received.iter().zip(["task_program", "relational_parse"]) {
        assert_eq!(request.request_line, "POST /v1/chat/completions HTTP/1.1");
        assert_eq!(request.header("authorization"), Some(format!("Bearer {KEY}").as_str()));
        assert_eq!(request.header("content-type"), Some("application/json"));
        let body = &request.body;
        assert_eq!(body["model"], "gpt-4.1");
        assert_eq!(body["temperature"], 0.0);
        assert_eq!(body["response_format"]["type"], "json_schema");
        let format = &body["response_format"]["json_schema"];
        assert_eq!((format["name"].as_str(), format["strict"].as_bool()), (Some(name), Some(true)));
        assert_eq!(format["schema"]["additionalProperties"], false);
        assert!(!contains_null(body), "no null fields on the wire");
        let roles: Vec<String> = messages(request).into_iter().map(|(role, _)| role).collect();
        assert_eq!(roles, ["system", "user"]);
        // The body is a chat-completions request, and nothing is lost in a round trip.
        let typed: ChatRequest = serde_json::from_value(body.clone()).unwrap();
        assert_eq!(&serde_json::to_value(&typed).unwrap(), body);
    }
    assert!(messages(&received[1])[1].1.contains("- c1: the body fits through a gap 0.4 m wide"));
}

#[tokio::test]
async fn rate_limit_then_success_honours_retry_after() {
    let limited = Step::status(429, "Rate limit reached").with_header("retry-after", "1");
    let server = LlmServer::start(vec![limited, program(), parse()]).await;
    // The waits of a request add up to at most its timeout: give the 1 s asked room.
    let client = ClientConfig { request_timeout: Duration::from_secs(2), ..fast_client() };
    let (result, took) = plan_with(LlmSettings { client, ..settings(&server) }).await;
    assert_planned(result);
    assert_eq!(server.received().len(), 3);
    // The backoff alone would have waited 20 ms.
    assert!(took >= Duration::from_secs(1) && took < Duration::from_secs(5), "{took:?}");
}

#[tokio::test]
async fn repeated_server_errors_end_in_a_clear_error() {
    let server = LlmServer::start(vec![Step::status(500, "internal error"); 3]).await;
    let (result, took) = plan(&server).await;
    let error = result.unwrap_err().to_string();
    assert!(error.starts_with("program generation: "), "{error}");
    assert!(error.contains("answered HTTP 500 on attempt 3") && error.contains("internal error"), "{error}");
    assert_eq!(server.received().len(), 3);
    assert!(took < Duration::from_secs(2), "{took:?}");
}

#[tokio::test]
async fn a_stalled_reply_times_out_and_is_retried() {
    let server = LlmServer::start(vec![Step::Stall, program(), parse()]).await;
    let (result, took) = plan(&server).await;
    assert_planned(result);
    assert!(took >= Duration::from_millis(400), "{took:?}");
}

#[tokio::test]
async fn a_server_that_never_answers_ends_in_a_timeout_error() {
    let server = LlmServer::start(vec![Step::Stall; 3]).await;
    let (result, took) = plan(&server).await;
    let error = result.unwrap_err().to_string();
    assert!(error.contains("no answer within 0.4 s on all 3 attempt(s)"), "{error}");
    assert!(took < Duration::from_secs(3), "{took:?}");
}

#[tokio::test]
async fn a_dropped_connection_is_retried() {
    let server = LlmServer::start(vec![Step::Drop, program(), parse()]).await;
    let (result, _) = plan(&server).await;
    assert_planned(result);
    let server = LlmServer::start(vec![Step::Drop; 3]).await;
    let (result, took) = plan(&server).await;
    let error = result.unwrap_err().to_string();
    assert!(error.contains("connection failed on all 3 attempt(s)"), "{error}");
    assert!(took < Duration::from_secs(2), "{took:?}");
}

#[tokio::test]
async fn truncated_json_is_reported_and_repaired() {
    let cut = malformed("truncated.txt");
    let server = LlmServer::start(vec![Step::reply_cut_off(&cut), program(), parse()]).await;
    let (result, _) = plan(&server).await;
    assert_planned(result);
    let repair = messages(&server.received()[1]);
    assert_eq!(repair.len(), 4);
    assert_eq!(repair[2], ("assistant".into(), cut.clone()));
    assert!(repair[3].1.contains("truncated at the token limit (finish_reason: length)"), "{}", repair[3].1);
    // Cut off every time: the error says so and quotes the reply.
    let server = LlmServer::start(vec![Step::reply_cut_off(&cut); 3]).await;
    let error = plan(&server).await.0.unwrap_err().to_string();
    assert!(error.contains("no valid answer in 3 attempt(s)") && error.contains("truncated"), "{error}");
    assert!(error.contains(cut.trim_end()), "{error}");
}

#[tokio::test]
async fn wrapped_json_is_accepted_without_repair() {
    for name in ["fenced.txt", "prose.txt", "think.txt", "think_no_opening_tag.txt"] {
        let server = LlmServer::start(vec![Step::reply(&malformed(name)), parse()]).await;
        let (result, _) = plan(&server).await;
        assert_planned(result);
        assert_eq!(server.received().len(), 2, "{name} needed a repair round");
    }
}

#[tokio::test]
async fn reasoning_fields_are_read() {
    let with_reasoning = |message: ReplyMessage| {
        let mut response = ChatResponse::with_content("deepseek-reasoner", "", "stop");
        response.choices[0].message = message;
        Step::completion(&response)
    };
    // DeepSeek / vLLM: reasoning in its own field, the answer in `content`.
    let separated = with_reasoning(ReplyMessage {
        content: Some(gap().program_reply()),
        reasoning_content: Some("The gap is {0.4 m} wide, so ...".into()),
        ..ReplyMessage::default()
    });
    // Ollama after the budget ran out of `content`: the answer in `reasoning`.
    let in_reasoning = with_reasoning(ReplyMessage {
        content: Some(String::new()),
        reasoning: Some(gap().parse_reply()),
        ..ReplyMessage::default()
    });
    let server = LlmServer::start(vec![separated, in_reasoning]).await;
    assert_planned(plan(&server).await.0);
}

/// A bad first answer, then good ones: the repair message names the problem.
async fn repaired(script: Vec<Step>, repaired_request: usize, needle: &str) {
    let server = LlmServer::start(script).await;
    let (result, _) = plan(&server).await;
    assert_planned(result);
    let repair = messages(&server.received()[repaired_request]);
    assert_eq!(repair.len(), 4, "one repair round");
    assert_eq!(repair[2].0, "assistant");
    assert!(repair[3].1.starts_with("Your answer cannot be used:") && repair[3].1.contains(needle), "{}", repair[3].1);
}

#[tokio::test]
async fn schema_invalid_answers_are_repaired_with_their_json_paths() {
    let bad = |name: &str| Step::reply(&malformed(name));
    let op = "constraints[0].expr.op: violates the JSON Schema: unknown op \"between\"";
    repaired(vec![bad("schema_invalid.json"), program(), parse()], 1, op).await;
    repaired(vec![bad("unknown_joint.json"), program(), parse()], 1, "constraints[1].expr.quantity.of.joint").await;
    repaired(vec![bad("nan.txt"), program(), parse()], 1, "not valid JSON").await;
    let late = "constraints[1].expr.frames.keyframes[0].frame: frame 100 is outside the clip";
    repaired(vec![bad("frame_outside_clip.json"), program(), parse()], 1, late).await;
    let unknown = "connected[0]: `c4` names no constraint of this program";
    repaired(vec![program(), bad("parse_unknown_id.json"), parse()], 2, unknown).await;
}

#[tokio::test]
async fn never_valid_ends_with_the_last_raw_reply() {
    let bad = malformed("schema_invalid.json");
    let server = LlmServer::start(vec![Step::reply(&bad); 3]).await;
    let (result, took) = plan(&server).await;
    let error = result.unwrap_err().to_string();
    assert!(error.starts_with("program generation: no valid answer in 3 attempt(s)"), "{error}");
    assert!(error.contains("constraints[0].expr.op") && error.contains(bad.trim_end()), "{error}");
    assert_eq!(server.received().len(), 3);
    assert!(took < Duration::from_secs(2), "{took:?}");
}

#[tokio::test]
async fn a_rejected_json_schema_steps_down_to_json_object() {
    let rejected = Step::status(400, "Invalid parameter: 'response_format' of type 'json_schema' is not supported");
    let server = LlmServer::start(vec![rejected, program(), parse()]).await;
    assert_planned(plan(&server).await.0);
    let received = server.received();
    let format = |i: usize| received[i].body["response_format"]["type"].as_str().unwrap().to_owned();
    assert_eq!([format(0), format(1), format(2)], ["json_schema", "json_object", "json_object"]);
    assert!(messages(&received[1])[0].1.contains("JSON Schema of the answer"));
    assert!(!messages(&received[0])[0].1.contains("JSON Schema of the answer"));
    // A 400 about something else is not a capability problem: no step down, a clear error.
    let server = LlmServer::start(vec![Step::status(400, "The model `gpt-9` does not exist")]).await;
    let error = plan(&server).await.0.unwrap_err().to_string();
    assert!(error.contains("HTTP 400") && error.contains("gpt-9"), "{error}");
    assert_eq!(server.received().len(), 1);
}

/// Log lines written by `tracing` while this binary's tests run.
#[derive(Clone, Default)]
struct Logs(Arc<Mutex<Vec<u8>>>);

/// The process-wide log capture. A global subscriber, not a scoped one: with `set_default`,
/// tests running in parallel threads raced on tracing's callsite interest cache and the capture
/// sometimes missed the events.
fn captured_logs() -> Logs {
    static LOGS: OnceLock<Logs> = OnceLock::new();
    LOGS.get_or_init(|| {
        let logs = Logs::default();
        let subscriber =
            tracing_subscriber::fmt().with_writer(logs.clone()).with_max_level(tracing::Level::TRACE).finish();
        tracing::subscriber::set_global_default(subscriber).unwrap();
        logs
    })
    .clone()
}

impl Write for Logs {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(bytes);
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl<'a> tracing_subscriber::fmt::MakeWriter<'a> for Logs {
    type Writer = Logs;
    fn make_writer(&'a self) -> Logs {
        self.clone()
    }
}

#[tokio::test]
async fn the_api_key_never_appears_in_logs_errors_or_recordings() {
    let logs = captured_logs();
    let recordings = tempfile::tempdir().unwrap();
    let recording = |server: &LlmServer| LlmSettings {
        source: Some(ReplySource::Record),
        recordings: recordings.path().to_owned(),
        ..settings(server)
    };
    // A server that echoes the key in its error, as some do.
    let echo = Step::status(401, &format!("Incorrect API key provided: {KEY}."));
    let server = LlmServer::start(vec![echo]).await;
    let error = plan_with(recording(&server)).await.0.unwrap_err();
    assert!(server.received()[0].header("authorization") == Some(format!("Bearer {KEY}").as_str()));
    let (shown, debug) = (error.to_string(), format!("{error:?}"));
    assert!(shown.contains("HTTP 401") && shown.contains("[REDACTED]"), "{shown}");
    // A recorded success, with the key echoed inside a reply.
    let mut answer = gap().program;
    answer.constraints[0].description = Some(format!("a gap; my key is {KEY}"));
    let server = LlmServer::start(vec![Step::reply(&answer.to_json_pretty().unwrap()), parse()]).await;
    plan_with(recording(&server)).await.0.unwrap();
    assert_eq!(server.received().len(), 2);
    let files: Vec<String> = std::fs::read_dir(recordings.path())
        .unwrap()
        .map(|entry| std::fs::read_to_string(entry.unwrap().path()).unwrap())
        .collect();
    assert_eq!(files.len(), 2);
    assert!(files.iter().any(|file| file.contains("my key is [REDACTED]")));
    let logged = String::from_utf8(logs.0.lock().unwrap().clone()).unwrap();
    assert!(logged.contains("chat completion request"), "tracing was captured: {logged}");
    let settings_debug = format!("{:?}", settings(&server));
    for (place, text) in
        [("error", &shown), ("error (debug)", &debug), ("logs", &logged), ("settings", &settings_debug)]
            .into_iter()
            .chain(files.iter().map(|file| ("recording", file)))
    {
        assert!(!text.contains(KEY), "the key leaked into the {place}: {text}");
    }
}
