//! A scripted OpenAI-compatible server on 127.0.0.1 for the LLM tests, and the hand-written
//! answers of `fixtures/llm/answers/`.
//!
//! Each request, in arrival order, gets the next [`Step`] of the script: a reply, an error
//! status with headers, a stall or a dropped connection. The server speaks just enough HTTP/1.1
//! for a client that sends `Content-Length` bodies, and closes every connection after one
//! exchange. Nothing leaves the loopback interface.

// Test support: a failed unwrap here is the test failing, with the panic message as its report.
#![allow(clippy::unwrap_used, clippy::panic)]

use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use agent::llm::ChatResponse;
use motion_core::program::TaskProgram;
use serde_json::Value;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::task::JoinHandle;

/// What the server does with one request.
#[derive(Debug, Clone)]
pub enum Step {
    /// Answer with this status, extra headers and body.
    Respond {
        /// HTTP status.
        status: u16,
        /// Extra headers.
        headers: Vec<(String, String)>,
        /// The body.
        body: String,
    },
    /// Read the request, then never answer.
    Stall,
    /// Read the request, then close the connection without a word.
    Drop,
}

impl Step {
    /// HTTP 200 with `response`.
    pub fn completion(response: &ChatResponse) -> Step {
        Step::Respond { status: 200, headers: Vec::new(), body: serde_json::to_string(response).unwrap() }
    }

    /// HTTP 200 with one choice holding `content`, finished normally.
    pub fn reply(content: &str) -> Step {
        Step::completion(&ChatResponse::with_content("gpt-4.1", content, "stop"))
    }

    /// HTTP 200 with `content` cut off at the token limit.
    pub fn reply_cut_off(content: &str) -> Step {
        Step::completion(&ChatResponse::with_content("gpt-4.1", content, "length"))
    }

    /// An error status with a JSON error body.
    pub fn status(status: u16, message: &str) -> Step {
        let body = serde_json::json!({"error": {"message": message}}).to_string();
        Step::Respond { status, headers: Vec::new(), body }
    }

    /// This step with one more header.
    pub fn with_header(self, name: &str, value: &str) -> Step {
        match self {
            Step::Respond { status, mut headers, body } => {
                headers.push((name.to_owned(), value.to_owned()));
                Step::Respond { status, headers, body }
            }
            other => other,
        }
    }
}

/// A request as the server saw it.
#[derive(Debug, Clone)]
pub struct Received {
    /// Request line, e.g. `POST /v1/chat/completions HTTP/1.1`.
    pub request_line: String,
    /// Headers, names lowercased.
    pub headers: Vec<(String, String)>,
    /// The JSON body.
    pub body: Value,
}

impl Received {
    /// The value of header `name` (lowercase).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.iter().find(|(n, _)| n == name).map(|(_, v)| v.as_str())
    }
}

/// The running server; stops when dropped.
pub struct LlmServer {
    /// `http://127.0.0.1:<port>/v1`.
    pub base_url: String,
    received: Arc<Mutex<Vec<Received>>>,
    task: JoinHandle<()>,
}

impl LlmServer {
    /// Starts a server answering with `script`, then with HTTP 500 "script exhausted".
    pub async fn start(script: Vec<Step>) -> LlmServer {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let base_url = format!("http://{}/v1", listener.local_addr().unwrap());
        let received = Arc::new(Mutex::new(Vec::new()));
        let script = Arc::new(Mutex::new(VecDeque::from(script)));
        let log = received.clone();
        let task = tokio::spawn(async move {
            while let Ok((stream, _)) = listener.accept().await {
                tokio::spawn(serve(stream, script.clone(), log.clone()));
            }
        });
        LlmServer { base_url, received, task }
    }

    /// Every request so far, in order.
    pub fn received(&self) -> Vec<Received> {
        self.received.lock().unwrap().clone()
    }
}

impl Drop for LlmServer {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn serve(mut stream: TcpStream, script: Arc<Mutex<VecDeque<Step>>>, log: Arc<Mutex<Vec<Received>>>) {
    let Some(request) = read_request(&mut stream).await else { return };
    log.lock().unwrap().push(request);
    let step = script.lock().unwrap().pop_front().unwrap_or_else(|| Step::status(500, "script exhausted"));
    match step {
        Step::Respond { status, headers, body } => {
            let mut head = format!(
                "HTTP/1.1 {status} Scripted\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\n",
                body.len()
            );
            for (name, value) in headers {
                head.push_str(&format!("{name}: {value}\r\n"));
            }
            head.push_str("\r\n");
            let _ = stream.write_all(head.as_bytes()).await;
            let _ = stream.write_all(body.as_bytes()).await;
            let _ = stream.shutdown().await;
        }
        Step::Stall => std::future::pending::<()>().await,
        Step::Drop => drop(stream),
    }
}

async fn read_request(stream: &mut TcpStream) -> Option<Received> {
    let mut data = Vec::new();
    let mut buffer = [0u8; 8192];
    let head_end = loop {
        if let Some(at) = data.windows(4).position(|w| w == b"\r\n\r\n") {
            break at;
        }
        let n = stream.read(&mut buffer).await.ok()?;
        if n == 0 {
            return None;
        }
        data.extend_from_slice(&buffer[..n]);
    };
    let head = String::from_utf8_lossy(&data[..head_end]).into_owned();
    let mut lines = head.split("\r\n");
    let request_line = lines.next()?.to_owned();
    let headers: Vec<(String, String)> = lines
        .filter_map(|line| line.split_once(':'))
        .map(|(name, value)| (name.trim().to_ascii_lowercase(), value.trim().to_owned()))
        .collect();
    let length: usize = headers.iter().find(|(n, _)| n == "content-length").and_then(|(_, v)| v.parse().ok())?;
    let mut body = data[head_end + 4..].to_vec();
    while body.len() < length {
        let n = stream.read(&mut buffer).await.ok()?;
        if n == 0 {
            return None;
        }
        body.extend_from_slice(&buffer[..n]);
    }
    Some(Received { request_line, headers, body: serde_json::from_slice(&body).ok()? })
}

/// A hand-written answer of `fixtures/llm/answers/`: a task and what a strong LLM answers.
#[derive(Debug, Clone)]
pub struct HandWritten {
    /// File name without `.json`.
    pub name: String,
    /// The task in words.
    pub task: String,
    /// The stage-1 answer.
    pub program: TaskProgram,
    /// The stage-2 answer (with `analysis`, without `retrieval_confidence`).
    pub relational_parse: Value,
}

impl HandWritten {
    /// The stage-1 reply text, as the model writes it (tag keys first).
    pub fn program_reply(&self) -> String {
        self.program.to_json_pretty().unwrap()
    }

    /// The stage-2 reply text.
    pub fn parse_reply(&self) -> String {
        serde_json::to_string_pretty(&self.relational_parse).unwrap()
    }

    /// The planned program: the answer with its parse at retrieval confidence 1.
    pub fn planned_program(&self) -> TaskProgram {
        let mut parse = self.relational_parse.clone();
        let object = parse.as_object_mut().unwrap();
        object.remove("analysis");
        object.insert("retrieval_confidence".into(), 1.0.into());
        let mut program = self.program.clone();
        program.relational_parse = Some(serde_json::from_value(parse).unwrap());
        program
    }
}

/// `fixtures/llm/`.
pub fn llm_fixtures() -> PathBuf {
    crate::fixtures().join("llm")
}

/// Every hand-written answer, sorted by name.
pub fn hand_written() -> Vec<HandWritten> {
    let mut answers: Vec<HandWritten> = std::fs::read_dir(llm_fixtures().join("answers"))
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.extension().is_some_and(|ext| ext == "json"))
        .map(|path| {
            let value: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
            HandWritten {
                name: path.file_stem().unwrap().to_string_lossy().into_owned(),
                task: value["task"].as_str().unwrap().to_owned(),
                program: TaskProgram::from_json(&value["program"].to_string())
                    .unwrap_or_else(|error| panic!("{}: {error}", path.display())),
                relational_parse: value["relational_parse"].clone(),
            }
        })
        .collect();
    answers.sort_by(|a, b| a.name.cmp(&b.name));
    answers
}

/// The hand-written answer called `name`.
pub fn hand_written_named(name: &str) -> HandWritten {
    hand_written().into_iter().find(|answer| answer.name == name).unwrap()
}

/// A malformed reply of `fixtures/llm/malformed/`.
pub fn malformed(name: &str) -> String {
    std::fs::read_to_string(llm_fixtures().join("malformed").join(name)).unwrap()
}
