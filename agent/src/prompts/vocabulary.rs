//! The constraint vocabulary in words, generated from the JSON Schema of the program types: every
//! op, kind, field, range, default and joint the validator accepts, with the doc comments of the
//! types as explanations. Because it is generated, the prompt cannot drift from the code.
//!
//! Output, one block per type reachable from the root (breadth first):
//! ```text
//! Expr: A constraint expression; JSON objects tagged by `op`. One of:
//!   {"op": "less_than", ...}: "<": per frame `Σ_c relu(q_c − max)` ...
//!     quantity: Quantity. The measured quantity.
//!     frames?: FrameSelection = "all". Frames the constraint applies to (default: all).
//! ```

use std::collections::{BTreeSet, VecDeque};

use serde_json::{Map, Value};

/// The vocabulary of `schema` (a schemars schema with `$defs`); `root_name` names the root type.
pub fn describe(schema: &Value, root_name: &str) -> String {
    let empty = Map::new();
    let defs = schema.get("$defs").and_then(Value::as_object).unwrap_or(&empty);
    let mut blocks = vec![block(root_name, schema)];
    let mut seen = BTreeSet::new();
    let mut queue: VecDeque<String> = refs_in(schema).into();
    while let Some(name) = queue.pop_front() {
        if !seen.insert(name.clone()) {
            continue;
        }
        if let Some(def) = defs.get(&name) {
            blocks.push(block(&name, def));
            queue.extend(refs_in(def));
        }
    }
    blocks.join("\n")
}

/// Names of the `$defs` a schema node refers to, in order of appearance (not entering `$defs`).
fn refs_in(node: &Value) -> Vec<String> {
    let mut names = Vec::new();
    collect_refs(node, &mut names);
    names
}

fn collect_refs(node: &Value, names: &mut Vec<String>) {
    match node {
        Value::Object(map) => {
            if let Some(name) = map.get("$ref").and_then(Value::as_str).and_then(ref_name) {
                names.push(name.to_owned());
            }
            for (key, child) in map {
                if key != "$defs" {
                    collect_refs(child, names);
                }
            }
        }
        Value::Array(items) => items.iter().for_each(|item| collect_refs(item, names)),
        _ => {}
    }
}

fn ref_name(reference: &str) -> Option<&str> {
    reference.strip_prefix("#/$defs/")
}

/// One type: its description, then its variants or fields.
fn block(name: &str, node: &Value) -> String {
    let mut out = format!("{name}: {}", description(node));
    if let Some(variants) = node.get("oneOf").or_else(|| node.get("anyOf")).and_then(Value::as_array) {
        out.push_str(" One of:\n");
        for variant in variants {
            out.push_str(&format!("  {}: {}\n", variant_head(variant), description(variant)));
            out.push_str(&fields(variant, "    ", true));
        }
    } else if let Some(values) = node.get("enum").and_then(Value::as_array) {
        let values: Vec<String> = values.iter().map(Value::to_string).collect();
        out.push_str(&format!(" One of: {}.\n", values.join(", ")));
    } else if node.get("properties").is_some() {
        out.push('\n');
        out.push_str(&fields(node, "  ", false));
    } else {
        out.push_str(&format!(" A {}.\n", type_text(node)));
    }
    out
}

/// How a variant is written: `"first"`, `{"op": "equal", ...}` or `{"joint": Joint}`.
fn variant_head(variant: &Value) -> String {
    if let Some(constant) = variant.get("const") {
        return constant.to_string();
    }
    let properties = variant.get("properties").and_then(Value::as_object);
    if let Some((tag, value)) = properties.and_then(tag_of) {
        return format!("{{\"{tag}\": {value}, ...}}");
    }
    match properties.map(|p| p.iter().collect::<Vec<_>>()).as_deref() {
        Some([(key, schema)]) => format!("{{\"{key}\": {}}}", type_text(schema)),
        _ => type_text(variant),
    }
}

/// The tag property of an internally tagged variant: a property whose schema is a string `const`.
fn tag_of(properties: &Map<String, Value>) -> Option<(&String, &Value)> {
    properties.iter().find_map(|(key, schema)| schema.get("const").filter(|c| c.is_string()).map(|c| (key, c)))
}

/// Field lines of an object schema; for a variant, without its tag or its single key.
fn fields(node: &Value, indent: &str, variant: bool) -> String {
    let Some(properties) = node.get("properties").and_then(Value::as_object) else { return String::new() };
    let tag = tag_of(properties).map(|(key, _)| key.clone());
    if variant && tag.is_none() && properties.len() == 1 {
        return String::new();
    }
    let required: BTreeSet<&str> =
        node.get("required").and_then(Value::as_array).into_iter().flatten().filter_map(Value::as_str).collect();
    let mut out = String::new();
    for (key, schema) in properties {
        if Some(key) == tag.as_ref() {
            continue;
        }
        let optional = if required.contains(key.as_str()) { "" } else { "?" };
        let default = schema.get("default").map(|d| format!(" = {d}")).unwrap_or_default();
        out.push_str(&format!("{indent}{key}{optional}: {}{default}. {}\n", type_text(schema), description(schema)));
    }
    out
}

/// A type in words: `Quantity`, `number in [0, 100]`, `[number; 3]`, `list of Joint (at least 1)`.
fn type_text(node: &Value) -> String {
    if let Some(name) = node.get("$ref").and_then(Value::as_str).and_then(ref_name) {
        return name.to_owned();
    }
    if let Some(constant) = node.get("const") {
        return constant.to_string();
    }
    if let Some(values) = node.get("enum").and_then(Value::as_array) {
        return values.iter().map(Value::to_string).collect::<Vec<_>>().join(" | ");
    }
    if let Some(variants) = node.get("anyOf").or_else(|| node.get("oneOf")).and_then(Value::as_array) {
        return variants.iter().map(type_text).collect::<Vec<_>>().join(" or ");
    }
    match node.get("type") {
        Some(Value::String(kind)) => simple_type(kind, node),
        Some(Value::Array(kinds)) => {
            kinds.iter().filter_map(Value::as_str).map(|kind| simple_type(kind, node)).collect::<Vec<_>>().join(" or ")
        }
        _ => "any JSON value".to_owned(),
    }
}

fn simple_type(kind: &str, node: &Value) -> String {
    let number = |key: &str| node.get(key).and_then(Value::as_f64);
    let count = |key: &str| node.get(key).and_then(Value::as_u64);
    match kind {
        "integer" | "number" => match (number("minimum"), number("maximum")) {
            (Some(lo), Some(hi)) => format!("{kind} in [{lo}, {hi}]"),
            (Some(lo), None) => format!("{kind} ≥ {lo}"),
            (None, Some(hi)) => format!("{kind} ≤ {hi}"),
            (None, None) => kind.to_owned(),
        },
        "string" => match node.get("pattern").and_then(Value::as_str) {
            Some(pattern) => format!("string matching {pattern}"),
            None => "string".to_owned(),
        },
        "array" => {
            let item = node.get("items").map_or_else(|| "any JSON value".to_owned(), type_text);
            match (count("minItems"), count("maxItems")) {
                (Some(lo), Some(hi)) if lo == hi => format!("[{item}; {lo}]"),
                (Some(lo), Some(hi)) => format!("list of {lo} to {hi} {item}"),
                (Some(lo), None) => format!("list of {item} (at least {lo})"),
                (None, Some(hi)) => format!("list of {item} (at most {hi})"),
                (None, None) => format!("list of {item}"),
            }
        }
        "null" => "null".to_owned(),
        other => other.to_owned(),
    }
}

/// The description on one line, intra-doc links (`` [`Expr`] ``) as plain code.
fn description(node: &Value) -> String {
    let text = node.get("description").and_then(Value::as_str).unwrap_or("");
    text.split_whitespace().collect::<Vec<_>>().join(" ").replace("[`", "`").replace("`]", "`")
}

#[cfg(test)]
mod tests {
    use serde_json::json;

    use super::*;

    #[test]
    fn small_schema_reads_naturally() {
        let schema = json!({
            "description": "A task.", "type": "object", "required": ["shape"],
            "properties": {
                "shape": {"$ref": "#/$defs/Shape", "description": "The shape."},
                "size": {"type": ["number", "null"], "minimum": 0.0, "maximum": 2.5, "description": "Size (m)."}
            },
            "$defs": {
                "Shape": {"description": "A shape.", "oneOf": [
                    {"const": "dot", "description": "A point."},
                    {"type": "object", "description": "A box.", "required": ["kind", "sides"], "properties": {
                        "kind": {"const": "box", "type": "string"},
                        "sides": {"type": "array", "items": {"type": "number"}, "minItems": 3, "maxItems": 3,
                                  "description": "Sides."},
                        "open": {"type": "boolean", "default": false, "description": "Open [`Shape`]."}}},
                    {"type": "object", "description": "Named.", "required": ["name"],
                     "properties": {"name": {"$ref": "#/$defs/Name"}}}
                ]},
                "Name": {"description": "A name.", "enum": ["a", "b"]},
                "Unused": {"description": "Never referenced.", "type": "string"}
            }
        });
        assert_eq!(
            describe(&schema, "Task"),
            "Task: A task.\n  shape: Shape. The shape.\n  size?: number in [0, 2.5] or null. Size (m).\n\n\
             Shape: A shape. One of:\n  \"dot\": A point.\n  {\"kind\": \"box\", ...}: A box.\n    \
             open?: boolean = false. Open `Shape`.\n    sides: [number; 3]. Sides.\n  {\"name\": Name}: Named.\n\n\
             Name: A name. One of: \"a\", \"b\".\n"
        );
    }

    #[test]
    fn the_program_vocabulary_names_every_op_kind_and_joint() {
        let text = describe(motion_core::program::json_schema(), "TaskProgram");
        for op in ["equal", "less_than", "greater_than", "and", "or", "not", "count", "scene", "bone_direction"] {
            assert!(text.contains(&format!("{{\"op\": \"{op}\", ...}}")), "op {op}");
        }
        for kind in ["foot_contact", "self_collision", "com_in_support", "stay_near_initial"] {
            assert!(text.contains(&format!("\"{kind}\"")), "op {kind}");
        }
        for kind in ["position", "distance_to_plane", "gap", "overhead_barrier", "hurdle", "balance_beam", "inside_box"]
        {
            assert!(text.contains(&format!("{{\"kind\": \"{kind}\", ...}}")), "kind {kind}");
        }
        for joint in motion_core::skeleton::Joint::ALL {
            assert!(text.contains(&format!("\"{}\"", joint.name())), "joint {}", joint.name());
        }
        for needle in ["frames: integer in [1, 1000]", "{\"fixed_m\": [number in [-100, 100]; 3]}", "Frame 0."] {
            assert!(text.contains(needle), "{needle}\n{text}");
        }
    }
}
