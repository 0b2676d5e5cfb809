//! The JSON object inside an LLM reply, whatever the server and model wrapped around it.
//!
//! Pipeline (user-needs (c), "response pipeline"): cut off at the token limit → truncation; take
//! `content`, else `reasoning_content`, else `reasoning`; drop `<think>` reasoning (also when the
//! chat template swallowed the opening tag and only `</think>` appears); drop a code fence around
//! the whole message; take the first complete JSON object with a string-aware bracket scan, so
//! prose before or after it (even prose with braces) does not matter.

use serde_json::Value;

use super::wire::ChatResponse;

/// Why a reply holds no usable JSON object. The display form goes back to the model in a repair
/// round, so it says what to do.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReplyProblem {
    /// No choices, or nothing but whitespace.
    #[error("the reply was empty; answer with the JSON object")]
    Empty,
    /// The model refused.
    #[error("the model refused: {0}")]
    Refusal(String),
    /// `finish_reason: length`: cut off at the token limit.
    #[error(
        "the reply was truncated at the token limit (finish_reason: length) after {chars} characters; \
         answer with a shorter complete JSON object (leave out descriptions and defaults you do not need)"
    )]
    Truncated {
        /// Characters received.
        chars: usize,
    },
    /// Only reasoning: an unclosed `<think>`.
    #[error("the reply holds only reasoning (an unclosed <think> block) and no answer")]
    OnlyReasoning,
    /// No `{` at all.
    #[error("the reply contains no JSON object")]
    NoJson,
    /// An object that starts but never closes.
    #[error("the JSON object starting at character {at} is never closed (cut off?)")]
    Unclosed {
        /// Character offset of its `{` in the answer text.
        at: usize,
    },
    /// Balanced braces but not JSON.
    #[error("the JSON object is not valid JSON: {0}")]
    Syntax(String),
}

/// The usable answer of a reply.
#[derive(Debug, Clone, PartialEq)]
pub struct Answer {
    /// The reply text as received (what a repair round quotes back).
    pub raw: String,
    /// The JSON object found in it.
    pub json: Value,
}

/// The reply text of `response` as received: its first choice's `content`, else the server's
/// reasoning field when the content is blank. Empty when there is none.
pub fn reply_text(response: &ChatResponse) -> String {
    let Some(choice) = response.choices.first() else { return String::new() };
    let message = &choice.message;
    [&message.content, &message.reasoning_content, &message.reasoning]
        .into_iter()
        .flatten()
        .find(|text| !text.trim().is_empty())
        .cloned()
        .unwrap_or_default()
}

/// The JSON object of a reply, or why there is none.
pub fn answer(response: &ChatResponse) -> Result<Answer, ReplyProblem> {
    let raw = reply_text(response);
    let choice = response.choices.first();
    if let Some(refusal) = choice.and_then(|c| c.message.refusal.as_ref()).filter(|r| !r.trim().is_empty()) {
        return Err(ReplyProblem::Refusal(refusal.clone()));
    }
    let truncated = choice.and_then(|c| c.finish_reason.as_deref()) == Some("length");
    match json_object(&raw) {
        Ok(json) => {
            if truncated {
                tracing::warn!("the reply hit the token limit but holds a complete JSON object");
            }
            Ok(Answer { raw, json })
        }
        Err(_) if truncated => Err(ReplyProblem::Truncated { chars: raw.chars().count() }),
        Err(problem) => Err(problem),
    }
}

/// The first complete JSON object in `text` after removing reasoning and a surrounding fence.
pub fn json_object(text: &str) -> Result<Value, ReplyProblem> {
    let text = strip_fence(strip_reasoning(text)?);
    if text.trim().is_empty() {
        return Err(ReplyProblem::Empty);
    }
    let mut first_error = None;
    let mut from = 0;
    while let Some(offset) = text[from..].find('{') {
        let start = from + offset;
        // Everything after an unclosed `{` lies inside it: most likely a cut-off answer.
        let Some(end) = closing_brace(&text[start..]).map(|end| start + end) else {
            return Err(ReplyProblem::Unclosed { at: text[..start].chars().count() });
        };
        match serde_json::from_str::<Value>(&text[start..=end]) {
            Ok(value) => return Ok(value),
            // Not JSON (prose in braces, or a broken answer): look after it, never inside, so a
            // broken program does not yield one of its constraints. The first error is the one
            // to report.
            Err(error) => {
                first_error.get_or_insert(ReplyProblem::Syntax(error.to_string()));
                from = end + 1;
            }
        }
    }
    Err(first_error.unwrap_or(ReplyProblem::NoJson))
}

/// `text` without `<think>…</think>` reasoning: everything after the last `</think>` when there is
/// one (this also covers a missing opening tag), else everything before an unclosed `<think>`.
pub fn strip_reasoning(text: &str) -> Result<&str, ReplyProblem> {
    if let Some(at) = text.rfind("</think>") {
        return Ok(&text[at + "</think>".len()..]);
    }
    match text.find("<think>") {
        Some(at) if text[..at].trim().is_empty() => Err(ReplyProblem::OnlyReasoning),
        Some(at) => Ok(&text[..at]),
        None => Ok(text),
    }
}

/// `text` without a code fence that encloses the whole of it (` ```json … ``` `, the closing fence
/// optional); any other text is returned unchanged.
pub fn strip_fence(text: &str) -> &str {
    let trimmed = text.trim();
    let Some(rest) = trimmed.strip_prefix("```") else { return text };
    let body = rest.split_once('\n').map_or("", |(_, body)| body);
    body.trim_end().strip_suffix("```").unwrap_or(body)
}

/// Byte offset of the `}` closing the object that `text` starts with, skipping braces inside
/// strings; `None` when it never closes.
fn closing_brace(text: &str) -> Option<usize> {
    let mut depth = 0usize;
    let mut in_string = false;
    let mut escaped = false;
    for (i, byte) in text.bytes().enumerate() {
        if in_string {
            match byte {
                _ if escaped => escaped = false,
                b'\\' => escaped = true,
                b'"' => in_string = false,
                _ => {}
            }
            continue;
        }
        match byte {
            b'"' => in_string = true,
            b'{' | b'[' => depth += 1,
            b'}' | b']' => {
                depth = depth.checked_sub(1)?;
                if depth == 0 {
                    return Some(i);
                }
            }
            _ => {}
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;
    use crate::llm::wire::ReplyMessage;

    fn object(text: &str) -> Value {
        json_object(text).unwrap_or_else(|problem| panic!("{problem}: {text}"))
    }

    #[test]
    fn plain_fenced_and_prose_wrapped_json() {
        let expected = json!({"a": {"b": [1, 2]}});
        assert_eq!(object(r#"{"a": {"b": [1, 2]}}"#), expected);
        assert_eq!(object("```json\n{\"a\": {\"b\": [1, 2]}}\n```"), expected);
        assert_eq!(object("```\n{\"a\": {\"b\": [1, 2]}}\n"), expected, "missing closing fence");
        assert_eq!(object("Here is the program:\n{\"a\": {\"b\": [1, 2]}}\nIt walks {slowly}."), expected);
        assert_eq!(object("Sure! ```json\n{\"a\": {\"b\": [1, 2]}}\n``` Hope this helps."), expected);
        assert_eq!(object("Use sets like {c1, c2}. Answer: {\"a\": {\"b\": [1, 2]}}"), expected, "braces in prose");
        assert_eq!(object("```bash\necho hi\n```\n{\"a\": {\"b\": [1, 2]}}"), expected, "a shell fence first");
    }

    #[test]
    fn braces_inside_strings_do_not_count() {
        assert_eq!(object(r#"{"text": "a } and a { and \" quote"}"#), json!({"text": "a } and a { and \" quote"}));
    }

    #[test]
    fn think_blocks_are_dropped() {
        assert_eq!(object("<think>maybe {\"a\": 2}?</think>\n{\"a\": 1}"), json!({"a": 1}));
        assert_eq!(object("the template ate the opening tag {\"a\": 2}\n</think>\n\n{\"a\": 1}"), json!({"a": 1}));
        assert_eq!(object("{\"a\": 1}\n<think>afterthought"), json!({"a": 1}));
        assert_eq!(json_object("<think>still thinking about {\"a\": 1}"), Err(ReplyProblem::OnlyReasoning));
    }

    #[test]
    fn broken_replies_name_their_problem() {
        assert_eq!(json_object("  "), Err(ReplyProblem::Empty));
        assert_eq!(json_object("I cannot help with that."), Err(ReplyProblem::NoJson));
        assert_eq!(json_object("ok: {\"a\": [1, 2"), Err(ReplyProblem::Unclosed { at: 4 }));
        assert!(matches!(json_object("{\"a\": 1,}"), Err(ReplyProblem::Syntax(m)) if m.contains("trailing comma")));
        assert!(matches!(json_object("{\"a\": NaN}"), Err(ReplyProblem::Syntax(_))));
        let broken_outer = "{\"constraints\": [{\"id\": \"c1\"}], \"frames\": NaN}";
        assert!(
            matches!(json_object(broken_outer), Err(ReplyProblem::Syntax(m)) if m.contains("line 1")),
            "no inner object"
        );
    }

    fn response(message: ReplyMessage, finish_reason: &str) -> ChatResponse {
        let mut response = ChatResponse::with_content("m", "", finish_reason);
        response.choices[0].message = message;
        response
    }

    #[test]
    fn reasoning_fields_and_finish_reasons() {
        let content = |text: &str| ReplyMessage { content: Some(text.into()), ..ReplyMessage::default() };
        let ok = answer(&response(content("{\"a\": 1}"), "stop")).unwrap();
        assert_eq!((ok.raw.as_str(), ok.json), ("{\"a\": 1}", json!({"a": 1})));
        let cut = answer(&response(content("{\"a\": [1, 2"), "length"));
        assert_eq!(cut, Err(ReplyProblem::Truncated { chars: 11 }));
        let in_reasoning = ReplyMessage {
            content: Some("  ".into()),
            reasoning_content: Some("thinking… {\"a\": 1}".into()),
            ..ReplyMessage::default()
        };
        assert_eq!(answer(&response(in_reasoning, "stop")).unwrap().json, json!({"a": 1}));
        let ollama = ReplyMessage { reasoning: Some("{\"a\": 3}".into()), ..ReplyMessage::default() };
        assert_eq!(answer(&response(ollama, "stop")).unwrap().json, json!({"a": 3}));
        let refusal = ReplyMessage { refusal: Some("no".into()), ..ReplyMessage::default() };
        assert_eq!(answer(&response(refusal, "stop")), Err(ReplyProblem::Refusal("no".into())));
        let none = ChatResponse { choices: vec![], ..ChatResponse::with_content("m", "", "stop") };
        assert_eq!(answer(&none), Err(ReplyProblem::Empty));
    }
}
