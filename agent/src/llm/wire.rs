//! Wire types of the OpenAI chat-completions API (`POST {base}/chat/completions`), the subset every
//! OpenAI-compatible server (OpenAI, DeepSeek, vLLM, Ollama, llama.cpp) speaks.
//!
//! Requests never carry `null`: absent options are left out, as some servers reject `null` where
//! OpenAI ignores it. Responses accept what the servers add: `reasoning_content` (DeepSeek, vLLM,
//! llama.cpp), `reasoning` (Ollama, newer vLLM) and any unknown field.

use serde::{Deserialize, Serialize};
use serde_json::Value;

/// A chat-completions request body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChatRequest {
    /// Model name as the server knows it.
    pub model: String,
    /// The conversation so far.
    pub messages: Vec<Message>,
    /// Structured output: absent for a plain prompt.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub response_format: Option<ResponseFormat>,
    /// Sampling temperature (absent: the server's default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature: Option<f64>,
    /// Most tokens the reply may have (absent: the server's default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_tokens: Option<u32>,
}

/// Who wrote a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// Instructions.
    System,
    /// The user (the task, repair feedback).
    User,
    /// The model's earlier replies.
    Assistant,
}

/// One message of a conversation.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Message {
    /// Author.
    pub role: Role,
    /// Text.
    pub content: String,
}

impl Message {
    /// A system message.
    pub fn system(content: impl Into<String>) -> Self {
        Message { role: Role::System, content: content.into() }
    }

    /// A user message.
    pub fn user(content: impl Into<String>) -> Self {
        Message { role: Role::User, content: content.into() }
    }

    /// An assistant message.
    pub fn assistant(content: impl Into<String>) -> Self {
        Message { role: Role::Assistant, content: content.into() }
    }
}

/// `response_format`: JSON mode or a JSON Schema the server enforces.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ResponseFormat {
    /// Any JSON object (the schema then travels in the prompt).
    JsonObject,
    /// Output constrained to a JSON Schema.
    JsonSchema {
        /// The schema and its name.
        json_schema: JsonSchemaFormat,
    },
}

/// The `json_schema` member of [`ResponseFormat::JsonSchema`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct JsonSchemaFormat {
    /// Name of the schema (`[a-zA-Z0-9_-]`, at most 64 characters).
    pub name: String,
    /// The schema (sanitised for strict mode when `strict`).
    pub schema: Value,
    /// Ask the server to enforce the schema exactly.
    pub strict: bool,
}

/// A chat-completions response body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChatResponse {
    /// Server-assigned id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub id: Option<String>,
    /// The model that answered.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// The replies (we ask for one).
    pub choices: Vec<Choice>,
    /// Token counts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub usage: Option<Usage>,
}

/// One reply.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Choice {
    /// Position among the choices.
    #[serde(default)]
    pub index: u32,
    /// The reply.
    pub message: ReplyMessage,
    /// `stop`, `length` (cut off at the token limit), `content_filter`, ...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub finish_reason: Option<String>,
}

/// The message of a [`Choice`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ReplyMessage {
    /// `assistant`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub role: Option<String>,
    /// The answer (may be null or blank, e.g. when reasoning used up the token budget).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub content: Option<String>,
    /// Reasoning separated by the server (DeepSeek, vLLM, llama.cpp).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reasoning_content: Option<String>,
    /// Reasoning under Ollama's and newer vLLM's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reasoning: Option<String>,
    /// A refusal (OpenAI structured outputs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refusal: Option<String>,
}

/// Token counts of an exchange.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Usage {
    /// Prompt tokens.
    #[serde(default)]
    pub prompt_tokens: u32,
    /// Reply tokens (reasoning included).
    #[serde(default)]
    pub completion_tokens: u32,
    /// Their sum.
    #[serde(default)]
    pub total_tokens: u32,
}

impl ChatResponse {
    /// A response with one choice holding `content` (what a scripted or recorded server sends).
    pub fn with_content(model: &str, content: &str, finish_reason: &str) -> Self {
        ChatResponse {
            id: None,
            model: Some(model.to_owned()),
            choices: vec![Choice {
                index: 0,
                message: ReplyMessage {
                    role: Some("assistant".to_owned()),
                    content: Some(content.to_owned()),
                    ..ReplyMessage::default()
                },
                finish_reason: Some(finish_reason.to_owned()),
            }],
            usage: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    fn contains_null(value: &Value) -> bool {
        match value {
            Value::Null => true,
            Value::Array(items) => items.iter().any(contains_null),
            Value::Object(map) => map.values().any(contains_null),
            _ => false,
        }
    }

    #[test]
    fn request_with_strict_schema_has_the_wire_shape_and_round_trips() {
        let request = ChatRequest {
            model: "gpt-4.1".into(),
            messages: vec![Message::system("rules"), Message::user("walk forwards")],
            response_format: Some(ResponseFormat::JsonSchema {
                json_schema: JsonSchemaFormat {
                    name: "task_program".into(),
                    schema: json!({"type": "object", "properties": {}, "required": [], "additionalProperties": false}),
                    strict: true,
                },
            }),
            temperature: Some(0.0),
            max_tokens: None,
        };
        let value = serde_json::to_value(&request).unwrap();
        assert_eq!(
            value,
            json!({
                "model": "gpt-4.1",
                "messages": [{"role": "system", "content": "rules"}, {"role": "user", "content": "walk forwards"}],
                "response_format": {"type": "json_schema", "json_schema": {
                    "name": "task_program",
                    "schema": {"type": "object", "properties": {}, "required": [], "additionalProperties": false},
                    "strict": true}},
                "temperature": 0.0
            })
        );
        assert!(!contains_null(&value));
        assert_eq!(serde_json::from_value::<ChatRequest>(value).unwrap(), request);
    }

    #[test]
    fn plain_and_json_object_requests_leave_absent_fields_out() {
        let mut request = ChatRequest {
            model: "deepseek-chat".into(),
            messages: vec![Message::user("json please")],
            response_format: Some(ResponseFormat::JsonObject),
            temperature: None,
            max_tokens: Some(4096),
        };
        let value = serde_json::to_value(&request).unwrap();
        assert_eq!(value["response_format"], json!({"type": "json_object"}));
        assert_eq!(value["max_tokens"], 4096);
        assert!(value.get("temperature").is_none());
        request.response_format = None;
        let value = serde_json::to_value(&request).unwrap();
        assert!(value.get("response_format").is_none() && !contains_null(&value));
        assert_eq!(serde_json::from_value::<ChatRequest>(value).unwrap(), request);
    }

    #[test]
    fn responses_of_the_known_servers_parse() {
        // OpenAI, with fields we do not model.
        let openai = json!({"id": "chatcmpl-1", "object": "chat.completion", "created": 1, "model": "gpt-4.1",
            "system_fingerprint": "fp", "choices": [{"index": 0, "logprobs": null, "finish_reason": "stop",
            "message": {"role": "assistant", "content": "{}", "refusal": null, "annotations": []}}],
            "usage": {"prompt_tokens": 10, "completion_tokens": 2, "total_tokens": 12,
                      "prompt_tokens_details": {"cached_tokens": 0}}});
        let response: ChatResponse = serde_json::from_value(openai).unwrap();
        assert_eq!(response.choices[0].message.content.as_deref(), Some("{}"));
        assert_eq!(response.usage.unwrap().total_tokens, 12);
        // DeepSeek reasoner / vLLM with a reasoning parser.
        let deepseek = json!({"choices": [{"message": {"role": "assistant", "content": "{\"a\": 1}",
            "reasoning_content": "Let me think."}, "finish_reason": "stop"}]});
        let response: ChatResponse = serde_json::from_value(deepseek).unwrap();
        assert_eq!(response.choices[0].message.reasoning_content.as_deref(), Some("Let me think."));
        // Ollama: null content, answer in `reasoning`, cut off.
        let ollama = json!({"choices": [{"message": {"role": "assistant", "content": null,
            "reasoning": "{\"a\""}, "finish_reason": "length"}]});
        let response: ChatResponse = serde_json::from_value(ollama).unwrap();
        assert_eq!(response.choices[0].message.content, None);
        assert_eq!(response.choices[0].finish_reason.as_deref(), Some("length"));
    }

    #[test]
    fn response_round_trips_without_nulls() {
        let response = ChatResponse::with_content("m", "{\"x\": 1}", "stop");
        let value = serde_json::to_value(&response).unwrap();
        assert!(!contains_null(&value));
        assert_eq!(serde_json::from_value::<ChatResponse>(value).unwrap(), response);
    }
}
