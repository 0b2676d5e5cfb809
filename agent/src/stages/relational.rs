//! Stage 2, relational task parsing (RG-DNO §4.2 with the instruction of supp. Fig. 9): the
//! program's constraints → the most difficult constraint `c_D` and the constraints connected to
//! and conflicting with it. The retrieval confidence `s` is the user's (the paper specifies it by
//! hand), so the model is not asked for it.

use motion_core::program::{validate_json, ProgramError, RelationalParse, TaskProgram};
use serde_json::{json, Value};

use super::repair::ask_until_valid;
use super::stage::{Stage, StageError};
use crate::llm::extract::Answer;
use crate::llm::{strict_schema, Llm, Message, OutputMode, Question};
use crate::prompts::{PromptError, Prompts};

/// The field of a program that holds the parse.
const FIELD: &str = "relational_parse";

/// A stage-2 answer.
#[derive(Debug, Clone, PartialEq)]
pub struct RelationalAnswer {
    /// The parse, with the user's retrieval confidence.
    pub parse: RelationalParse,
    /// The model's reasoning (Fig. 9's step-by-step analysis), when it gave one.
    pub analysis: Option<String>,
}

/// The schema of a stage-2 answer: [`RelationalParse`] without `retrieval_confidence`, with an
/// optional `analysis` string (first in key order, so a model following the schema's order
/// reasons before it answers; strict mode makes it required).
pub fn parse_schema() -> Value {
    let mut schema = schemars::schema_for!(RelationalParse).to_value();
    if let Some(properties) = schema.get_mut("properties").and_then(Value::as_object_mut) {
        properties.remove("retrieval_confidence");
        properties.insert(
            "analysis".to_owned(),
            json!({"type": "string", "description": "Brief reasoning: the difficulty of each constraint, then the \
                   relation (connected, conflicting or none) of each other constraint to the most difficult one."}),
        );
    }
    if let Some(required) = schema.get_mut("required").and_then(Value::as_array_mut) {
        required.retain(|name| name != "retrieval_confidence");
    }
    schema
}

/// The stage-2 question for the constraints of `program`.
pub fn parse_question(prompts: &Prompts, task: &str, program: &TaskProgram) -> Result<Question, PromptError> {
    let schema = parse_schema();
    let constraints = program
        .constraints
        .iter()
        .map(|constraint| {
            let expr = serde_json::to_string(&constraint.expr)
                .map_err(|error| PromptError { name: "constraint".into(), message: error.to_string() })?;
            let description = constraint.description.as_deref().unwrap_or("(no description)");
            Ok(json!({ "id": constraint.id, "description": description, "expr": expr }))
        })
        .collect::<Result<Vec<_>, PromptError>>()?;
    let user = prompts.render("relational_parse.user.j2", json!({ "task": task, "constraints": constraints }))?;
    let opening = OutputMode::LADDER.map(|mode| {
        let schema_text = mode.schema_in_prompt().then(|| schema.to_string());
        let system = prompts.render("relational_parse.system.j2", json!({ "schema": schema_text }))?;
        Ok::<_, PromptError>(vec![Message::system(system), Message::user(user.clone())])
    });
    let [a, b, c] = opening;
    Ok(Question {
        task: task.to_owned(),
        stage: Stage::RelationalParse.name(),
        schema_name: FIELD,
        schema: strict_schema(&schema),
        opening: [a?, b?, c?],
    })
}

/// Asks for the relational parse of `program`'s constraints, with at most `max_repairs` repair
/// rounds; `retrieval_confidence` is `s` of Algorithm 1, in [0, 1].
pub async fn parse_relations(
    llm: &Llm,
    prompts: &Prompts,
    task: &str,
    program: &TaskProgram,
    retrieval_confidence: f64,
    max_repairs: u32,
) -> Result<RelationalAnswer, StageError> {
    let stage = Stage::RelationalParse;
    let question = parse_question(prompts, task, program).map_err(|source| StageError::Prompt { stage, source })?;
    let check = |answer: &Answer| check_parse(program, retrieval_confidence, answer);
    ask_until_valid(llm, prompts, stage, &question, max_repairs, check).await
}

/// A stage-2 answer as a parse of `program`: checked inside the program, so the schema and the
/// id rules are the program's own; problems are reported relative to the answer.
fn check_parse(
    program: &TaskProgram,
    retrieval_confidence: f64,
    answer: &Answer,
) -> Result<RelationalAnswer, Vec<String>> {
    let mut value = answer.json.clone();
    let Some(object) = value.as_object_mut() else { return Err(vec!["the answer must be a JSON object".into()]) };
    let analysis = match object.remove("analysis") {
        Some(Value::String(text)) => Some(text),
        None | Some(Value::Null) => None,
        Some(other) => return Err(vec![format!("analysis: must be a string, not {other}")]),
    };
    object.insert("retrieval_confidence".to_owned(), json!(retrieval_confidence));
    let mut whole = serde_json::to_value(program).map_err(|error| vec![error.to_string()])?;
    whole[FIELD] = value.clone();
    validate_json(&whole).map_err(relative)?;
    let parse: RelationalParse = serde_json::from_value(value).map_err(|error| vec![error.to_string()])?;
    let mut parsed = program.clone();
    parsed.relational_parse = Some(parse.clone());
    parsed.validate().map_err(relative)?;
    Ok(RelationalAnswer { parse, analysis })
}

/// The problems about the parse, with paths relative to the answer (`connected[0]`).
fn relative(errors: Vec<ProgramError>) -> Vec<String> {
    errors
        .into_iter()
        .filter_map(|error| {
            let path = match error.path.strip_prefix(FIELD)? {
                "" => String::new(),
                rest => rest.strip_prefix('.').unwrap_or(rest).to_owned(),
            };
            Some(ProgramError::new(path, error.problem).to_string())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn program() -> TaskProgram {
        let text = include_str!("../../../fixtures/tasks/rgdno_task2_low_barrier.json");
        let mut program = TaskProgram::from_json(text).unwrap();
        program.relational_parse = None;
        program
    }

    fn check(json: Value) -> Result<RelationalAnswer, Vec<String>> {
        check_parse(&program(), 1.0, &Answer { raw: json.to_string(), json })
    }

    #[test]
    fn a_good_answer_becomes_the_parse_with_the_users_confidence() {
        let answer = check(json!({"analysis": "c1 is hardest", "most_difficult": "c1", "connected": ["c2"],
            "conflicting": ["c3", "c4"]}))
        .unwrap();
        assert_eq!(answer.analysis.as_deref(), Some("c1 is hardest"));
        assert_eq!(answer.parse.connected, ["c2"]);
        assert_eq!(answer.parse.retrieval_confidence, 1.0);
        let no_analysis = check(json!({"most_difficult": "c1", "connected": [], "conflicting": []})).unwrap();
        assert_eq!(no_analysis.analysis, None);
    }

    #[test]
    fn bad_ids_and_shapes_are_reported_relative_to_the_answer() {
        let problems = check(json!({"most_difficult": "c9", "connected": [], "conflicting": []})).unwrap_err();
        assert_eq!(problems, ["most_difficult: `c9` names no constraint of this program"]);
        let problems = check(json!({"most_difficult": "c1", "connected": ["c1"], "conflicting": []})).unwrap_err();
        assert!(problems.iter().any(|p| p.starts_with("connected[0]") && p.contains("most difficult")), "{problems:?}");
        let problems = check(json!({"most_difficult": "c1", "connected": "c2", "conflicting": []})).unwrap_err();
        assert!(problems.iter().any(|p| p.starts_with("connected")), "{problems:?}");
        let problems = check(json!({"most_difficult": "c1", "conflicting": []})).unwrap_err();
        assert!(problems.iter().any(|p| p.contains("connected")), "{problems:?}");
        let problems = check(json!({"analysis": 3, "most_difficult": "c1", "connected": [], "conflicting": []}));
        assert_eq!(problems.unwrap_err(), ["analysis: must be a string, not 3"]);
    }

    #[test]
    fn the_question_lists_every_constraint_and_asks_no_confidence() {
        let prompts = Prompts::new().unwrap();
        let question = parse_question(&prompts, "duck under a bar", &program()).unwrap();
        let user = &question.opening(OutputMode::JsonSchema)[1].content;
        for id in ["- c1: very low barrier", "- c4: pelvis 0.9 m high on the last frame", "\"overhead_barrier\""] {
            assert!(user.contains(id), "{id}\n{user}");
        }
        let schema = question.schema.to_string();
        assert!(schema.contains("analysis") && !schema.contains("retrieval_confidence"), "{schema}");
        assert!(question.opening(OutputMode::PromptOnly)[0].content.contains("JSON Schema of the answer"));
    }
}
