//! Fuzzing the path of an LLM reply (issue 18): extraction → JSON Schema validation → typed
//! parse → meaning checks → compile, on replies made by mutating real ones (the recorded replies,
//! the malformed fixtures and the task library). No input may panic, abort or grow memory without
//! bound; each must end as a program or as a list of problems.
//!
//! CI runs a few thousand cases; the long run is
//! `MOGEN_FUZZ_CASES=1000000 cargo test --release -p agent --test fuzz_replies`.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::LazyLock;

use agent::llm::extract::answer;
use agent::llm::ChatResponse;
use agent::stages::check_program;
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};
use serde_json::{json, Value};

/// The seed replies: every answer text we have.
static CORPUS: LazyLock<Vec<String>> = LazyLock::new(|| {
    let fixtures = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fixtures");
    let mut texts = Vec::new();
    for folder in ["llm/recorded", "llm/malformed", "tasks"] {
        let mut paths: Vec<_> = std::fs::read_dir(fixtures.join(folder)).unwrap().flatten().map(|e| e.path()).collect();
        paths.sort();
        for path in paths {
            let text = std::fs::read_to_string(&path).unwrap();
            match serde_json::from_str::<Value>(&text) {
                // A recording: the reply's content.
                Ok(value) if value.get("response").is_some() => {
                    if let Some(content) = value["response"]["choices"][0]["message"]["content"].as_str() {
                        texts.push(content.to_owned());
                    }
                }
                _ => texts.push(text),
            }
        }
    }
    assert!(texts.len() > 40, "{} seed replies", texts.len());
    texts
});

/// Text fragments that matter to the parsers: JSON syntax, extremes, wrappers, control and
/// multi-byte characters, and the vocabulary's names in the wrong places.
const FRAGMENTS: &[&str] = &[
    "{",
    "}",
    "[",
    "]",
    ",",
    ":",
    "\"",
    "\\",
    "\\u0000",
    "\\ud800",
    "null",
    "true",
    "-0",
    "1e308",
    "-1e308",
    "1e-320",
    "NaN",
    "Infinity",
    "99999999999999999999",
    "4294967296",
    "-1",
    "0",
    "0.5",
    "10000",
    "\u{feff}",
    "\u{1b}[2J",
    "\u{0}",
    "é",
    "𝄞",
    "```json\n",
    "\n```",
    "<think>",
    "</think>",
    "\"frames\": ",
    "\"constraints\": []",
    "\"op\": \"and\", \"args\": [",
    "\"op\": \"not\", \"arg\": ",
    "\"kind\": \"gap\"",
    "\"joint\": \"pelvis\"",
    "\"keyframes\": [\"last\"]",
    "\"id\": \"c1\"",
    "{\"fraction\": 2}",
    "{\"frame\": 99999}",
];

/// One edit of a reply.
#[derive(Debug, Clone)]
enum Mutation {
    /// Insert a fragment at a relative position.
    Insert(f64, usize),
    /// Delete a relative range.
    Delete(f64, f64),
    /// Repeat a relative range `n` times.
    Repeat(f64, f64, usize),
    /// Replace the n-th number with a fragment.
    Number(usize, usize),
    /// Edit the JSON tree: set the n-th node to a value.
    Node(usize, usize),
    /// Wrap in prose, a fence or reasoning.
    Wrap(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let at = 0.0..1.0f64;
    prop_oneof![
        (at.clone(), 0..FRAGMENTS.len()).prop_map(|(a, f)| Mutation::Insert(a, f)),
        (at.clone(), 0.0..0.2f64).prop_map(|(a, l)| Mutation::Delete(a, l)),
        (at.clone(), 0.0..0.1f64, 2..50usize).prop_map(|(a, l, n)| Mutation::Repeat(a, l, n)),
        (0..200usize, 0..FRAGMENTS.len()).prop_map(|(n, f)| Mutation::Number(n, f)),
        (0..400usize, 0..NODE_VALUES).prop_map(|(n, v)| Mutation::Node(n, v)),
        (0..4usize).prop_map(Mutation::Wrap),
    ]
}

const NODE_VALUES: usize = 12;

/// The `v`-th replacement value for a JSON node.
fn node_value(v: usize, old: &Value) -> Value {
    match v {
        0 => Value::Null,
        1 => json!(-1),
        2 => json!(1e300),
        3 => json!(""),
        4 => json!([]),
        5 => json!({}),
        6 => json!("c99999"),
        7 => json!([old.clone(), old.clone(), old.clone()]),
        8 => json!({"op": "not", "arg": old.clone(), "margin": 0}),
        9 => json!("x".repeat(5000)),
        10 => json!(u32::MAX),
        _ => json!(0.0),
    }
}

fn char_index(text: &str, fraction: f64) -> usize {
    let target = (fraction * text.len() as f64) as usize;
    (0..=target.min(text.len())).rev().find(|&i| text.is_char_boundary(i)).unwrap_or(0)
}

/// Sets the n-th node (depth-first) of `value`; false when there are fewer nodes.
fn set_node(value: &mut Value, n: &mut usize, v: usize) -> bool {
    if *n == 0 {
        let new = node_value(v, value);
        *value = new;
        return true;
    }
    *n -= 1;
    match value {
        Value::Array(items) => items.iter_mut().any(|item| set_node(item, n, v)),
        Value::Object(map) => map.values_mut().any(|item| set_node(item, n, v)),
        _ => false,
    }
}

fn apply(text: &mut String, mutation: &Mutation) {
    match *mutation {
        Mutation::Insert(at, f) => {
            let i = char_index(text, at);
            text.insert_str(i, FRAGMENTS[f]);
        }
        Mutation::Delete(at, length) => {
            let (a, b) = (char_index(text, at), char_index(text, (at + length).min(1.0)));
            text.replace_range(a..b.max(a), "");
        }
        Mutation::Repeat(at, length, n) => {
            let (a, b) = (char_index(text, at), char_index(text, (at + length).min(1.0)));
            let piece = text[a..b.max(a)].to_owned();
            text.insert_str(b.max(a), &piece.repeat(n));
        }
        Mutation::Number(n, f) => {
            let starts: Vec<usize> = text
                .char_indices()
                .filter(|&(i, c)| c.is_ascii_digit() && !text[..i].ends_with(|p: char| p.is_ascii_digit() || p == '.'))
                .map(|(i, _)| i)
                .collect();
            if let Some(&start) = starts.get(n % starts.len().max(1)) {
                let end =
                    text[start..].find(|c: char| !(c.is_ascii_digit() || c == '.')).map_or(text.len(), |e| start + e);
                text.replace_range(start..end, FRAGMENTS[f]);
            }
        }
        Mutation::Node(n, v) => {
            if let Ok(mut value) = serde_json::from_str::<Value>(text) {
                let mut left = n;
                if set_node(&mut value, &mut left, v) {
                    *text = value.to_string();
                }
            }
        }
        Mutation::Wrap(kind) => {
            *text = match kind {
                0 => format!("Here is the program:\n{text}\nHope this helps {{ }}."),
                1 => format!("```json\n{text}\n```"),
                2 => format!("<think>the user wants {{\"a\": 1}}</think>{text}"),
                _ => format!("{text}</think>{text}"),
            }
        }
    }
}

/// Cases run, and programs that came through every check (the fuzzer must reach compile).
static CASES: AtomicUsize = AtomicUsize::new(0);
static VALID: AtomicUsize = AtomicUsize::new(0);

/// One reply through the whole path: never a panic; a valid program also compiles.
fn pipeline(text: &str, finish_reason: &str) {
    CASES.fetch_add(1, Ordering::Relaxed);
    let response: ChatResponse = serde_json::from_value(json!({
        "choices": [{"index": 0, "message": {"role": "assistant", "content": text}, "finish_reason": finish_reason}]
    }))
    .unwrap();
    let Ok(answer) = answer(&response) else { return };
    if let Ok(checked) = check_program(&answer, &candle_core::Device::Cpu) {
        VALID.fetch_add(1, Ordering::Relaxed);
        let program = checked.program();
        assert!(program.frames >= 1 && program.frames <= motion_core::program::MAX_FRAMES);
        assert_eq!(checked.compiled().frames(), program.frames as usize);
    }
}

/// Peak resident memory of this process, bytes (Linux).
fn peak_memory() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse::<u64>().ok().map(|kib| kib * 1024)
}

#[test]
fn mutated_replies_never_panic_and_stay_bounded() {
    let cases = std::env::var("MOGEN_FUZZ_CASES").ok().and_then(|n| n.parse().ok()).unwrap_or(3000);
    let mut runner = TestRunner::new(Config { cases, failure_persistence: None, ..Config::default() });
    let strategy =
        (0..CORPUS.len(), prop::collection::vec(mutation(), 0..6), prop_oneof![Just("stop"), Just("length")]);
    let start = std::time::Instant::now();
    runner
        .run(&strategy, |(seed, mutations, finish)| {
            let mut text = CORPUS[seed].clone();
            for m in &mutations {
                apply(&mut text, m);
            }
            pipeline(&text, finish);
            Ok(())
        })
        .unwrap();
    let (run, valid) = (CASES.load(Ordering::Relaxed), VALID.load(Ordering::Relaxed));
    let peak = peak_memory().unwrap_or(0);
    eprintln!(
        "{run} replies in {:.0} s, {valid} valid programs compiled, peak memory {} MiB",
        start.elapsed().as_secs_f64(),
        peak >> 20
    );
    assert!(valid > 0, "no mutated reply reached compile");
    assert!(peak < 2 << 30, "peak memory {peak} bytes");
}
