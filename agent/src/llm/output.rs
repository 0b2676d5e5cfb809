//! Structured output by server capability: the ladder `json_schema` (strict) → `json_object` with
//! the schema in the prompt → the prompt alone (user-needs (c), support table).

use std::fmt;

use serde_json::Value;

use super::wire::{JsonSchemaFormat, ResponseFormat};

/// How the reply's shape is asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, clap::ValueEnum)]
pub enum OutputMode {
    /// `response_format: json_schema` with `strict: true`: the server enforces the schema
    /// (OpenAI, vLLM, llama.cpp, recent Ollama).
    JsonSchema,
    /// `response_format: json_object` and the schema in the prompt (DeepSeek, older servers).
    JsonObject,
    /// No `response_format`; the schema in the prompt only.
    PromptOnly,
}

impl OutputMode {
    /// Every mode, most capable first.
    pub const LADDER: [OutputMode; 3] = [OutputMode::JsonSchema, OutputMode::JsonObject, OutputMode::PromptOnly];

    /// The mode to start with for a server: DeepSeek offers `json_object` only; every other known
    /// server accepts `json_schema`.
    pub fn for_base_url(base_url: &str) -> OutputMode {
        if base_url.contains("deepseek.com") {
            OutputMode::JsonObject
        } else {
            OutputMode::JsonSchema
        }
    }

    /// The next rung down, for a server that rejected this one.
    pub fn fallback(self) -> Option<OutputMode> {
        match self {
            OutputMode::JsonSchema => Some(OutputMode::JsonObject),
            OutputMode::JsonObject => Some(OutputMode::PromptOnly),
            OutputMode::PromptOnly => None,
        }
    }

    /// Whether the prompt must carry the schema (the server does not see it).
    pub fn schema_in_prompt(self) -> bool {
        self != OutputMode::JsonSchema
    }

    /// The `response_format` of a request for `strict_schema` named `name`.
    pub fn response_format(self, name: &str, strict_schema: &Value) -> Option<ResponseFormat> {
        match self {
            OutputMode::JsonSchema => Some(ResponseFormat::JsonSchema {
                json_schema: JsonSchemaFormat { name: name.to_owned(), schema: strict_schema.clone(), strict: true },
            }),
            OutputMode::JsonObject => Some(ResponseFormat::JsonObject),
            OutputMode::PromptOnly => None,
        }
    }
}

impl fmt::Display for OutputMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            OutputMode::JsonSchema => "json_schema (strict)",
            OutputMode::JsonObject => "json_object",
            OutputMode::PromptOnly => "prompt only",
        })
    }
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    #[test]
    fn the_ladder_steps_down_to_the_prompt() {
        let mut rungs = vec![OutputMode::JsonSchema];
        while let Some(next) = rungs.last().and_then(|mode| mode.fallback()) {
            rungs.push(next);
        }
        assert_eq!(rungs, OutputMode::LADDER);
        assert_eq!(OutputMode::for_base_url("https://api.deepseek.com/v1"), OutputMode::JsonObject);
        assert_eq!(OutputMode::for_base_url("http://localhost:11434/v1"), OutputMode::JsonSchema);
        let schema = json!({"type": "object"});
        assert!(matches!(
            OutputMode::JsonSchema.response_format("p", &schema),
            Some(ResponseFormat::JsonSchema { json_schema }) if json_schema.strict && json_schema.name == "p"
        ));
        assert_eq!(OutputMode::JsonObject.response_format("p", &schema), Some(ResponseFormat::JsonObject));
        assert_eq!(OutputMode::PromptOnly.response_format("p", &schema), None);
        assert!(!OutputMode::JsonSchema.schema_in_prompt() && OutputMode::PromptOnly.schema_in_prompt());
    }
}
