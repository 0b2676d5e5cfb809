//! The JSON Schema for strict structured output: what schemars generates, rewritten into the
//! subset OpenAI's strict mode (and the grammar backends of vLLM, llama.cpp and Ollama) accept.
//!
//! OpenAI strict mode wants every object closed (`additionalProperties: false`) with every
//! property listed in `required`, and rejects `oneOf`, `default`, `format`, `uniqueItems`,
//! `minLength`/`maxLength`, `pattern` on some servers, and keywords beside a `$ref`. Optional
//! fields stay optional in meaning because schemars already types them `T | null` and serde reads
//! `null` as absent; fields with a serde default become required, which only asks the model to
//! write the default out. Numeric ranges and item counts are kept: they guide the model, and
//! servers that ignore them are caught by the full-schema validation that follows every reply.

use serde_json::{Map, Value};

/// Keywords strict mode does not accept (dropped; the full schema still validates the reply).
const DROPPED: [&str; 9] =
    ["$schema", "title", "default", "format", "uniqueItems", "minLength", "maxLength", "pattern", "examples"];

/// The schema rewritten for strict mode (see the module docs).
pub fn strict_schema(schema: &Value) -> Value {
    let mut schema = schema.clone();
    sanitise(&mut schema);
    schema
}

fn sanitise(node: &mut Value) {
    let Value::Object(map) = node else { return };
    if map.contains_key("$ref") {
        map.retain(|key, _| key == "$ref");
        return;
    }
    for keyword in DROPPED {
        map.remove(keyword);
    }
    if let Some(variants) = map.remove("oneOf") {
        map.insert("anyOf".to_owned(), variants);
    }
    for keyword in ["properties", "$defs"] {
        if let Some(Value::Object(children)) = map.get_mut(keyword) {
            children.values_mut().for_each(sanitise);
        }
    }
    for keyword in ["items", "additionalProperties"] {
        if let Some(child) = map.get_mut(keyword) {
            sanitise(child);
        }
    }
    if let Some(Value::Array(variants)) = map.get_mut("anyOf") {
        variants.iter_mut().for_each(sanitise);
    }
    if is_object_schema(map) {
        let names: Vec<Value> = match map.get("properties") {
            Some(Value::Object(properties)) => properties.keys().cloned().map(Value::String).collect(),
            _ => Vec::new(),
        };
        map.insert("required".to_owned(), Value::Array(names));
        map.insert("additionalProperties".to_owned(), Value::Bool(false));
    }
}

fn is_object_schema(map: &Map<String, Value>) -> bool {
    map.contains_key("properties") || map.get("type").is_some_and(|t| t == "object")
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    /// Every problem strict mode would have with `node`, as JSON pointers.
    fn strict_violations(node: &Value, at: &str, out: &mut Vec<String>) {
        match node {
            Value::Object(map) => {
                if map.contains_key("$ref") && map.len() > 1 {
                    out.push(format!("{at}: keywords beside $ref"));
                }
                for keyword in DROPPED.iter().chain(&["oneOf"]) {
                    if map.contains_key(*keyword) {
                        out.push(format!("{at}: {keyword}"));
                    }
                }
                if is_object_schema(map) {
                    let properties: Vec<&String> = map
                        .get("properties")
                        .and_then(Value::as_object)
                        .map(|p| p.keys().collect())
                        .unwrap_or_default();
                    let required: Vec<&str> = map
                        .get("required")
                        .and_then(Value::as_array)
                        .into_iter()
                        .flatten()
                        .filter_map(Value::as_str)
                        .collect();
                    if properties.len() != required.len() || properties.iter().any(|p| !required.contains(&p.as_str()))
                    {
                        out.push(format!("{at}: not every property is required"));
                    }
                    if map.get("additionalProperties") != Some(&Value::Bool(false)) {
                        out.push(format!("{at}: open object"));
                    }
                }
                for (key, child) in map {
                    // Property names are data, not keywords.
                    if key == "properties" || key == "$defs" {
                        for (name, schema) in child.as_object().unwrap() {
                            strict_violations(schema, &format!("{at}/{key}/{name}"), out);
                        }
                    } else {
                        strict_violations(child, &format!("{at}/{key}"), out);
                    }
                }
            }
            Value::Array(items) => {
                for (i, item) in items.iter().enumerate() {
                    strict_violations(item, &format!("{at}/{i}"), out);
                }
            }
            _ => {}
        }
    }

    #[test]
    fn the_task_program_schema_becomes_strict() {
        let full = motion_core::program::json_schema();
        let mut before = Vec::new();
        strict_violations(full, "", &mut before);
        assert!(!before.is_empty(), "the raw schema should need sanitising");
        let strict = strict_schema(full);
        let mut after = Vec::new();
        strict_violations(&strict, "", &mut after);
        assert_eq!(after, Vec::<String>::new());
        // Still the same vocabulary: every op, kind and joint survives.
        let text = strict.to_string();
        for needle in ["\"less_than\"", "\"overhead_barrier\"", "\"left_wrist\"", "\"keyframes\"", "\"maximum\""] {
            assert!(text.contains(needle), "{needle}");
        }
    }

    #[test]
    fn property_names_that_look_like_keywords_are_kept() {
        let schema = json!({"type": "object", "properties": {
            "pattern": {"type": "string", "pattern": "^a$"},
            "format": {"$ref": "#/$defs/F", "description": "dropped beside $ref"},
            "title": {"type": ["string", "null"], "default": null}
        }, "required": ["pattern"], "$defs": {"F": {"oneOf": [{"const": "a"}, {"type": "object", "properties": {}}]}}});
        let strict = strict_schema(&schema);
        assert_eq!(
            strict,
            json!({"type": "object", "additionalProperties": false,
                "properties": {"pattern": {"type": "string"}, "format": {"$ref": "#/$defs/F"},
                               "title": {"type": ["string", "null"]}},
                "required": ["format", "pattern", "title"],
                "$defs": {"F": {"anyOf": [{"const": "a"},
                    {"type": "object", "properties": {}, "required": [], "additionalProperties": false}]}}})
        );
    }
}
