//! The recorded LLM replies of `fixtures/llm/recorded/`: every hand-written task replays offline
//! to its answer, the same replies served over HTTP plan the same programs from the same
//! requests, and an ignored test regenerates the recordings through the real HTTP client.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;
use std::time::Duration;

use agent::llm::{ClientConfig, Llm, LlmError, LlmSettings, ReplySource, DEFAULT_MODEL};
use agent::plan::{plan_task, PlanError, PlanSettings};
use agent::recording::Exchange;
use agent::stages::StageError;
use e2e_tests::llm_server::{hand_written, llm_fixtures, HandWritten, LlmServer, Step};

const REGENERATE: &str = "cargo test -p e2e-tests --test llm_recordings -- --ignored record_fixtures";

fn recorded_dir() -> PathBuf {
    llm_fixtures().join("recorded")
}

fn settings(base_url: Option<String>, source: ReplySource) -> LlmSettings {
    LlmSettings {
        base_url,
        api_key: None,
        model: DEFAULT_MODEL.into(),
        source: Some(source),
        recordings: recorded_dir(),
        client: ClientConfig { request_timeout: Duration::from_secs(5), ..ClientConfig::default() },
        output: None,
        temperature: Some(0.0),
        max_tokens: None,
    }
}

fn exchanges() -> Vec<Exchange> {
    std::fs::read_dir(recorded_dir())
        .unwrap()
        .map(|entry| serde_json::from_str(&std::fs::read_to_string(entry.unwrap().path()).unwrap()).unwrap())
        .collect()
}

fn recorded(task: &HandWritten, stage: &str) -> Exchange {
    let found: Vec<Exchange> =
        exchanges().into_iter().filter(|exchange| exchange.task == task.task && exchange.stage == stage).collect();
    assert_eq!(found.len(), 1, "{} / {stage}: expected one recording; regenerate with `{REGENERATE}`", task.name);
    found.into_iter().next().unwrap()
}

#[tokio::test]
async fn every_hand_written_task_replays_offline() {
    let tasks = hand_written();
    assert!(tasks.len() >= 16, "only {} recorded tasks", tasks.len());
    let llm = Llm::connect(settings(None, ReplySource::Replay)).unwrap();
    for task in &tasks {
        let planned = match plan_task(&task.task, &llm, &PlanSettings::default(), &candle_core::Device::Cpu).await {
            Ok(planned) => planned,
            Err(PlanError::Stage(error))
                if matches!(*error, StageError::Llm { source: LlmError::ReplayMiss { .. }, .. }) =>
            {
                panic!(
                    "{}: the recordings are stale (a prompt template, the constraint types or the default model \
                     changed): regenerate them with `{REGENERATE}` and review the diff.\n{error}",
                    task.name
                )
            }
            Err(error) => panic!("{}: {error}", task.name),
        };
        assert_eq!(planned.program.program(), &task.planned_program(), "{}", task.name);
        assert!(planned.groups.is_some() && planned.analysis.is_some(), "{}", task.name);
    }
    assert_eq!(exchanges().len(), 2 * tasks.len(), "leftover recordings: regenerate with `{REGENERATE}`");
}

#[tokio::test]
async fn recorded_replies_served_over_http_plan_the_same_programs() {
    for task in hand_written() {
        let [program, parse] = ["program", "relational_parse"].map(|stage| recorded(&task, stage));
        let server =
            LlmServer::start(vec![Step::completion(&program.response), Step::completion(&parse.response)]).await;
        let llm = Llm::connect(settings(Some(server.base_url.clone()), ReplySource::Live)).unwrap();
        let planned = plan_task(&task.task, &llm, &PlanSettings::default(), &candle_core::Device::Cpu).await.unwrap();
        assert_eq!(planned.program.program(), &task.planned_program(), "{}", task.name);
        let sent: Vec<serde_json::Value> = server.received().into_iter().map(|request| request.body).collect();
        let recorded = [program, parse].map(|exchange| serde_json::to_value(exchange.request).unwrap());
        assert_eq!(
            sent, recorded,
            "{}: the requests drifted from the recordings; regenerate with `{REGENERATE}`",
            task.name
        );
    }
}

#[tokio::test]
#[ignore = "rewrites fixtures/llm/recorded/: run after changing a prompt template, the program types or the default model"]
async fn record_fixtures() {
    let dir = recorded_dir();
    if dir.exists() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            std::fs::remove_file(entry.unwrap().path()).unwrap();
        }
    }
    for task in hand_written() {
        let server = LlmServer::start(vec![Step::reply(&task.program_reply()), Step::reply(&task.parse_reply())]).await;
        let llm = Llm::connect(settings(Some(server.base_url.clone()), ReplySource::Record)).unwrap();
        let planned = plan_task(&task.task, &llm, &PlanSettings::default(), &candle_core::Device::Cpu).await.unwrap();
        assert_eq!(planned.program.program(), &task.planned_program(), "{}", task.name);
    }
}
