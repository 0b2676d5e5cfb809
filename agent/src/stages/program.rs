//! Stage 1, program generation: task text → [`TaskProgram`] (without its relational parse, which
//! stage 2 writes).

use candle_core::Device;
use motion_core::constraints::checked::CheckedProgram;
use motion_core::program::{json_schema, validate_json, TaskProgram};
use motion_core::skeleton::{Joint, FPS};
use serde_json::{json, Value};

use super::repair::ask_until_valid;
use super::stage::{Stage, StageError};
use crate::llm::extract::Answer;
use crate::llm::{strict_schema, Llm, Message, OutputMode, Question};
use crate::prompts::vocabulary::describe;
use crate::prompts::{PromptError, Prompts};

/// Clip lengths of HumanML3D, which the prior was trained on (frames at 20 fps: 2 to 9.8 s).
const PRIOR_FRAMES: [u32; 2] = [40, 196];

/// Worked examples of the prompt: a task in words and its program from the task library.
const EXAMPLES: [(&str, &str); 3] = [
    (
        "walk forwards through a gap 0.4 m wide from 0.5 m to 3.5 m ahead, keeping the arms 0.2 m clear of the \
         spine, and stop 5 m ahead",
        include_str!("../../../fixtures/tasks/rgdno_task1_narrow_gap.json"),
    ),
    (
        "walk forwards and duck under a bar 0.8 m high between 2 m and 3 m ahead, walking upright before and after it",
        include_str!("../../../fixtures/tasks/progmogen_hsi4_overhead_barrier.json"),
    ),
    (
        "walk 4 m forwards in exactly 6 steps while raising the hands, standing still at the start and the end",
        include_str!("../../../fixtures/tasks/rgdno_task3_six_steps.json"),
    ),
];

/// The schema of a stage-1 answer: [`json_schema`] without `relational_parse`.
pub fn program_schema() -> Value {
    let mut schema = json_schema().clone();
    if let Some(properties) = schema.get_mut("properties").and_then(Value::as_object_mut) {
        properties.remove("relational_parse");
    }
    schema
}

/// The stage-1 question for `task`.
pub fn program_question(prompts: &Prompts, task: &str) -> Result<Question, PromptError> {
    let schema = program_schema();
    let examples = EXAMPLES
        .iter()
        .map(|(task, program)| {
            let mut program = TaskProgram::from_json(program)
                .map_err(|error| PromptError { name: "example".into(), message: format!("{task}: {error}") })?;
            program.relational_parse = None;
            let program = serde_json::to_string(&program)
                .map_err(|error| PromptError { name: "example".into(), message: error.to_string() })?;
            Ok(json!({ "task": task, "program": program }))
        })
        .collect::<Result<Vec<_>, PromptError>>()?;
    let joints: Vec<&str> = Joint::ALL.iter().map(|joint| joint.name()).collect();
    let vocabulary = describe(&schema, "TaskProgram");
    let user = prompts.render("program.user.j2", json!({ "task": task }))?;
    let opening = OutputMode::LADDER.map(|mode| {
        let system = prompts.render(
            "program.system.j2",
            json!({
                "joints": joints,
                "fps": FPS.to_string(),
                "min_frames": PRIOR_FRAMES[0],
                "max_prior_frames": PRIOR_FRAMES[1],
                "vocabulary": vocabulary,
                "examples": examples,
                "schema": mode.schema_in_prompt().then(|| schema.to_string()),
            }),
        )?;
        Ok::<_, PromptError>(vec![Message::system(system), Message::user(user.clone())])
    });
    let [a, b, c] = opening;
    Ok(Question {
        task: task.to_owned(),
        stage: Stage::Program.name(),
        schema_name: "task_program",
        schema: strict_schema(&schema),
        opening: [a?, b?, c?],
    })
}

/// Asks for the program of `task`, with at most `max_repairs` repair rounds; the program is
/// checked and compiled on `device`.
pub async fn generate_program(
    llm: &Llm,
    prompts: &Prompts,
    task: &str,
    max_repairs: u32,
    device: &Device,
) -> Result<CheckedProgram, StageError> {
    let stage = Stage::Program;
    let question = program_question(prompts, task).map_err(|source| StageError::Prompt { stage, source })?;
    ask_until_valid(llm, prompts, stage, &question, max_repairs, |answer| check_program(answer, device)).await
}

/// A stage-1 answer as a program: JSON Schema (paths), types, then the meaning checks, which
/// compile it on `device` ([`CheckedProgram::check`]).
pub fn check_program(answer: &Answer, device: &Device) -> Result<CheckedProgram, Vec<String>> {
    let mut value = answer.json.clone();
    // Written by stage 2; a model that adds one anyway (JSON mode) is not wrong, just early.
    if let Some(parse) = value.as_object_mut().and_then(|object| object.remove("relational_parse")) {
        tracing::debug!("ignoring a relational_parse in the program answer: {parse}");
    }
    let to_strings = |errors: Vec<motion_core::program::ProgramError>| errors.iter().map(ToString::to_string).collect();
    validate_json(&value).map_err(to_strings)?;
    let program = TaskProgram::from_json(&value.to_string()).map_err(|error| vec![error.to_string()])?;
    CheckedProgram::check(program, device).map_err(to_strings)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn answer(json: Value) -> Answer {
        Answer { raw: json.to_string(), json }
    }

    fn small_program() -> Value {
        json!({"text": "a man walks forwards", "frames": 100, "constraints": [
            {"id": "c1", "description": "pelvis 5 m ahead at the end", "weight": null, "expr": {
                "op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"},
                "target": [5.0], "frames": {"keyframes": ["last"]}, "when": null}}]})
    }

    #[test]
    fn valid_answers_pass_with_nulls_for_absent_fields() {
        let program = check_program(&answer(small_program()), &Device::Cpu).unwrap();
        assert_eq!(program.program().constraints[0].id, "c1");
        let mut with_parse = small_program();
        with_parse["relational_parse"] = json!({"most_difficult": "c1"});
        assert!(check_program(&answer(with_parse), &Device::Cpu).is_ok());
    }

    #[test]
    fn problems_carry_json_paths() {
        let mut bad = small_program();
        bad["constraints"][0]["expr"]["quantity"]["of"]["joint"] = json!("left_hand");
        let problems = check_program(&answer(bad), &Device::Cpu).unwrap_err();
        assert!(problems.iter().any(|p| p.starts_with("constraints[0].expr.quantity.of.joint")), "{problems:?}");
        let mut late = small_program();
        late["constraints"][0]["expr"]["frames"] = json!({"keyframes": [{"frame": 100}]});
        let problems = check_program(&answer(late), &Device::Cpu).unwrap_err();
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(problems[0].contains("frames.keyframes[0].frame") && problems[0].contains("0..=99"), "{problems:?}");
    }

    #[test]
    fn the_question_carries_the_vocabulary_and_the_schema_only_where_needed() {
        let prompts = Prompts::new().unwrap();
        let question = program_question(&prompts, "walk 3 m").unwrap();
        let strict = question.opening(OutputMode::JsonSchema);
        assert_eq!(strict.len(), 2);
        assert_eq!(strict[1].content, "Task: walk 3 m");
        let system = &strict[0].content;
        for needle in
            ["{\"op\": \"count\", ...}", "left_wrist", "Task: walk 4 m forwards in exactly 6 steps", "20 frames"]
        {
            assert!(system.contains(needle), "{needle}");
        }
        assert!(!system.contains("JSON Schema of the answer") && !system.contains("relational_parse"));
        let json_mode = &question.opening(OutputMode::JsonObject)[0].content;
        assert!(json_mode.contains("JSON Schema of the answer") && json_mode.contains("\"$defs\""));
        assert!(!question.schema.to_string().contains("relational_parse"));
    }
}
