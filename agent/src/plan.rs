//! A task, planned: the validated constraint program with its relational parse and the
//! constraint groups of RG-DNO's Algorithm 1, from words through the LLM stages or from a task
//! file written by hand.

use std::path::{Path, PathBuf};

use candle_core::Device;
use motion_core::constraints::checked::CheckedProgram;
use motion_core::program::{ConstraintGroups, TaskProgram};

use crate::llm::Llm;
use crate::prompts::Prompts;
use crate::stages::{self, Stage, StageError};

/// How to plan.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanSettings {
    /// Repair rounds per stage after the first answer.
    pub max_repairs: u32,
    /// RG-DNO's retrieval confidence `s` in [0, 1] (Rule 4: below 0.5, `c_D` also stays in `C1`).
    pub retrieval_confidence: f64,
}

impl Default for PlanSettings {
    /// 2 repair rounds; confident retrieval (`s = 1`, as in the paper's experiments).
    fn default() -> Self {
        PlanSettings { max_repairs: 2, retrieval_confidence: 1.0 }
    }
}

/// A checked program ready for the generator.
#[derive(Debug, Clone)]
pub struct PlannedTask {
    /// The task in words (for a task file, its path).
    pub task: String,
    /// The program, with its relational parse when it has one, checked and compiled.
    pub program: CheckedProgram,
    /// Algorithm 1's groups; `None` without a relational parse (all constraints fitted together).
    pub groups: Option<ConstraintGroups>,
    /// The model's reasoning for the relational parse.
    pub analysis: Option<String>,
}

/// Why a task could not be planned.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// An LLM stage failed (boxed: it carries the last reply).
    #[error(transparent)]
    Stage(Box<StageError>),
    /// The prompt templates do not compile.
    #[error(transparent)]
    Prompt(#[from] crate::prompts::PromptError),
    /// A task file could not be read.
    #[error("cannot read the task file: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        message: String,
    },
    /// A task file is not a valid program.
    #[error("the task file {} is not a valid program:\n{}", path.display(), problems.join("\n"))]
    InvalidFile {
        /// The file.
        path: PathBuf,
        /// The problems, with JSON paths.
        problems: Vec<String>,
    },
}

impl From<StageError> for PlanError {
    fn from(error: StageError) -> Self {
        PlanError::Stage(Box::new(error))
    }
}

/// Plans `task` (words) through the two LLM stages: program generation, then relational parsing;
/// the program is checked and compiled on `device`, the generator's.
pub async fn plan_task(
    task: &str,
    llm: &Llm,
    settings: &PlanSettings,
    device: &Device,
) -> Result<PlannedTask, PlanError> {
    let prompts = Prompts::new()?;
    let checked = stages::generate_program(llm, &prompts, task, settings.max_repairs, device).await?;
    let program = checked.program();
    tracing::info!("{}: {} constraints, {} frames", Stage::Program, program.constraints.len(), program.frames);
    let answer =
        stages::parse_relations(llm, &prompts, task, program, settings.retrieval_confidence, settings.max_repairs)
            .await?;
    // Stage 2 checked the parse against the program's ids already.
    let program = checked.with_relational_parse(Some(answer.parse)).map_err(|problems| StageError::Invalid {
        stage: Stage::RelationalParse,
        attempts: 1,
        problems: problems.iter().map(ToString::to_string).collect(),
        last_reply: String::new(),
    })?;
    let groups = program.program().constraint_groups();
    Ok(PlannedTask { task: task.to_owned(), program, groups, analysis: answer.analysis })
}

/// Plans from a task file (a [`TaskProgram`] as JSON, e.g. `fixtures/tasks/*.json`), with its
/// own relational parse when it has one; the same checks as an LLM answer, compiled on `device`.
pub fn plan_from_file(path: &Path, device: &Device) -> Result<PlannedTask, PlanError> {
    let text = motion_core::files::read_text(path, &motion_core::limits::PROGRAM_FILE_BYTES)
        .map_err(|error| PlanError::File { path: path.to_owned(), message: error.to_string() })?;
    let invalid = |problems: Vec<String>| PlanError::InvalidFile { path: path.to_owned(), problems };
    let program = TaskProgram::from_json(&text).map_err(|error| invalid(vec![error.to_string()]))?;
    let program = CheckedProgram::check(program, device)
        .map_err(|problems| invalid(problems.iter().map(ToString::to_string).collect()))?;
    let groups = program.program().constraint_groups();
    Ok(PlannedTask { task: path.display().to_string(), program, groups, analysis: None })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn task(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fixtures/tasks").join(name)
    }

    #[test]
    fn task_files_plan_with_their_own_parse() {
        let planned = plan_from_file(&task("rgdno_task2_low_barrier.json"), &Device::Cpu).unwrap();
        let groups = planned.groups.unwrap();
        assert_eq!(groups.retrieval, ["c1", "c2"]);
        assert_eq!(groups.retrieved_noise, ["c1", "c2"]);
        let without = plan_from_file(&task("progmogen_hsi3_inside_square.json"), &Device::Cpu).unwrap();
        assert_eq!(without.groups, None);
    }

    #[test]
    fn bad_task_files_are_clear_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.json");
        std::fs::write(&path, r#"{"text": "", "frames": 0, "constraints": []}"#).unwrap();
        let error = plan_from_file(&path, &Device::Cpu).unwrap_err().to_string();
        assert!(error.contains("bad.json") && error.contains("frames"), "{error}");
        let missing = plan_from_file(&dir.path().join("none.json"), &Device::Cpu).unwrap_err().to_string();
        assert!(missing.contains("cannot read"), "{missing}");
    }
}
