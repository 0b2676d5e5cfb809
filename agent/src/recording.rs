//! Record and replay of LLM exchanges: one human-readable JSON file per exchange, keyed by a
//! stable hash of the model, the messages and the schema the reply must follow.
//!
//! Replay answers from the recordings with no network and fails loudly on a miss, printing the
//! key. Because the key hashes the rendered prompt, a change to a template, to the constraint
//! types (the schema and the generated vocabulary) or to the model name makes the recordings
//! stale; that shows up as a miss, and their regeneration as a reviewable diff. Nothing secret is
//! stored: requests are kept without headers and every file is scrubbed of the API key.

use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::llm::api_key::{scrub, ApiKey};
use crate::llm::wire::{ChatRequest, ChatResponse, Message};
use crate::llm::LlmError;

/// One recorded exchange.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Exchange {
    /// [`key`] of the request.
    pub key: String,
    /// The task in words the exchange belongs to.
    pub task: String,
    /// The stage that asked (`program`, `relational_parse`).
    pub stage: String,
    /// The request body as sent (no headers).
    pub request: ChatRequest,
    /// The response body as received.
    pub response: ChatResponse,
}

/// The recording key: SHA-256 (hex) of the canonical JSON of `{model, messages, schema}`, with
/// object keys sorted so the key does not depend on serialisation order.
pub fn key(model: &str, messages: &[Message], schema: &Value) -> String {
    let document = json!({ "model": model, "messages": messages, "schema": schema });
    let mut canonical = String::new();
    write_canonical(&document, &mut canonical);
    motion_core::files::sha256_hex(canonical.as_bytes())
}

fn write_canonical(value: &Value, out: &mut String) {
    match value {
        Value::Object(map) => {
            let mut entries: Vec<(&String, &Value)> = map.iter().collect();
            entries.sort_by_key(|(name, _)| *name);
            out.push('{');
            for (i, (name, child)) in entries.into_iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                out.push_str(&Value::from(name.as_str()).to_string());
                out.push(':');
                write_canonical(child, out);
            }
            out.push('}');
        }
        Value::Array(items) => {
            out.push('[');
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                write_canonical(item, out);
            }
            out.push(']');
        }
        scalar => out.push_str(&scalar.to_string()),
    }
}

/// The recordings of a folder, by key.
#[derive(Debug, Clone)]
pub struct Recordings {
    dir: PathBuf,
    exchanges: HashMap<String, Exchange>,
}

impl Recordings {
    /// Reads every `*.json` of `dir` (none when the folder does not exist). A file that is not an
    /// exchange is an error: a broken recording must not turn into a silent miss.
    pub fn open(dir: &Path) -> Result<Self, LlmError> {
        let failed = |path: &Path, message: String| LlmError::Recording { path: path.to_owned(), message };
        let mut exchanges = HashMap::new();
        if dir.is_dir() {
            let entries = std::fs::read_dir(dir).map_err(|error| failed(dir, error.to_string()))?;
            for entry in entries {
                let path = entry.map_err(|error| failed(dir, error.to_string()))?.path();
                if path.extension().is_none_or(|ext| ext != "json") {
                    continue;
                }
                let text = std::fs::read_to_string(&path).map_err(|error| failed(&path, error.to_string()))?;
                let exchange: Exchange =
                    serde_json::from_str(&text).map_err(|error| failed(&path, format!("not an exchange: {error}")))?;
                exchanges.insert(exchange.key.clone(), exchange);
            }
        }
        Ok(Recordings { dir: dir.to_owned(), exchanges })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The exchange recorded under `key`.
    pub fn get(&self, key: &str) -> Option<&Exchange> {
        self.exchanges.get(key)
    }

    /// Number of exchanges.
    pub fn len(&self) -> usize {
        self.exchanges.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.exchanges.is_empty()
    }

    /// The tasks with recordings, sorted.
    pub fn tasks(&self) -> BTreeSet<&str> {
        self.exchanges.values().map(|exchange| exchange.task.as_str()).collect()
    }

    /// The error for a miss of `key`, listing the recorded tasks.
    pub fn miss(&self, key: &str, task: &str, stage: &str) -> LlmError {
        let tasks = self.tasks();
        let known = if tasks.is_empty() {
            String::new()
        } else {
            let lines: Vec<String> = tasks.iter().map(|task| format!("\n  {task}")).collect();
            format!("\nRecorded tasks:{}", lines.concat())
        };
        LlmError::ReplayMiss {
            key: key.to_owned(),
            task: task.to_owned(),
            stage: stage.to_owned(),
            dir: self.dir.display().to_string(),
            known,
        }
    }
}

/// Writes `exchange` into `dir` as `<task slug>.<stage>.<key prefix>.json`, scrubbed of `api_key`;
/// returns the path.
pub fn record(dir: &Path, exchange: &Exchange, api_key: Option<&ApiKey>) -> Result<PathBuf, LlmError> {
    let key_prefix = exchange.key.get(..12).unwrap_or(&exchange.key);
    let path = dir.join(format!("{}.{}.{key_prefix}.json", slug(&exchange.task), exchange.stage));
    let failed = |message: String| LlmError::Recording { path: path.clone(), message };
    let text = serde_json::to_string_pretty(exchange).map_err(|error| failed(error.to_string()))?;
    std::fs::create_dir_all(dir).map_err(|error| failed(error.to_string()))?;
    std::fs::write(&path, scrub(api_key, &text) + "\n").map_err(|error| failed(error.to_string()))?;
    Ok(path)
}

/// A file-name form of a task: lowercase ASCII words joined by `-`, at most 60 characters.
pub fn slug(task: &str) -> String {
    let words: Vec<String> = task
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|word| !word.is_empty())
        .map(str::to_ascii_lowercase)
        .collect();
    let mut slug = String::new();
    for word in words {
        if slug.len() + word.len() + 1 > 60 {
            break;
        }
        if !slug.is_empty() {
            slug.push('-');
        }
        slug.push_str(&word);
    }
    if slug.is_empty() {
        "task".to_owned()
    } else {
        slug
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn messages() -> Vec<Message> {
        vec![Message::system("rules"), Message::user("walk forwards")]
    }

    #[test]
    fn key_is_stable_and_sensitive_to_what_it_hashes() {
        let schema = json!({"type": "object", "properties": {"b": {}, "a": {}}});
        let k = key("gpt-4.1", &messages(), &schema);
        // Pinned: a change of the key function makes every recording stale (regenerate them on purpose).
        assert_eq!(k, "ad30e0f517c17042b26ac9cc46f4c284c5dd981650b2eec4f89d33097f4b0c78");
        assert_eq!(k, key("gpt-4.1", &messages(), &json!({"properties": {"a": {}, "b": {}}, "type": "object"})));
        assert_ne!(k, key("gpt-4o", &messages(), &schema));
        assert_ne!(k, key("gpt-4.1", &messages()[..1], &schema));
        assert_ne!(k, key("gpt-4.1", &messages(), &json!({"type": "object"})));
        let mut canonical = String::new();
        write_canonical(&json!({"b": [1, {"d": "x", "c": null}], "a": true}), &mut canonical);
        assert_eq!(canonical, r#"{"a":true,"b":[1,{"c":null,"d":"x"}]}"#);
    }

    #[test]
    fn record_then_open_finds_the_exchange_and_scrubs_the_key() {
        let dir = tempfile::tempdir().unwrap();
        let api_key = ApiKey::new("sk-unit-test-key").unwrap();
        let request = ChatRequest {
            model: "m".into(),
            messages: vec![Message::user("my key is sk-unit-test-key")],
            response_format: None,
            temperature: Some(0.0),
            max_tokens: None,
        };
        let exchange = Exchange {
            key: key("m", &request.messages, &json!({})),
            task: "Walk 5 m, then stop!".into(),
            stage: "program".into(),
            request,
            response: ChatResponse::with_content("m", "{}", "stop"),
        };
        let path = record(dir.path(), &exchange, Some(&api_key)).unwrap();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        assert!(name.starts_with("walk-5-m-then-stop.program.") && name.ends_with(".json"), "{name}");
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(!text.contains("sk-unit-test-key") && text.contains("[REDACTED]"));
        let recordings = Recordings::open(dir.path()).unwrap();
        assert_eq!(recordings.len(), 1);
        assert_eq!(recordings.get(&exchange.key).unwrap().task, "Walk 5 m, then stop!");
        let miss = recordings.miss("abc", "jump", "program").to_string();
        assert!(miss.contains("key abc") && miss.contains("Walk 5 m, then stop!"), "{miss}");
    }

    #[test]
    fn missing_folder_is_empty_and_broken_files_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        assert!(Recordings::open(&dir.path().join("none")).unwrap().is_empty());
        std::fs::write(dir.path().join("bad.json"), "{}").unwrap();
        let error = Recordings::open(dir.path()).unwrap_err().to_string();
        assert!(error.contains("bad.json") && error.contains("not an exchange"), "{error}");
    }

    #[test]
    fn slugs_are_short_file_names() {
        assert_eq!(slug("walk forwards through a 0.4 m wide gap"), "walk-forwards-through-a-0-4-m-wide-gap");
        assert_eq!(slug("¿?"), "task");
        assert!(slug(&"step ".repeat(40)).len() <= 60);
    }
}
