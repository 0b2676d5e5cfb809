//! The task program itself: its named constraints and RG-DNO's relational parse, read from JSON.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::error::{Problem, ProgramError};
use super::expr::{Carry, Expr};
use super::limits::{MAX_CONSTRAINTS, MAX_FRAMES, MAX_TEXT_CHARS};
use super::scene::Primitive;
use super::serde_util;

/// Retrieval confidence from which RG-DNO's Algorithm 1 treats retrieval as confident (`s = 1`).
pub const CONFIDENT_RETRIEVAL: f64 = 0.5;

/// A motion generation task: the prompt, the clip length and the constraints.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct TaskProgram {
    /// Text prompt for the motion prior (may be empty for unconditional generation).
    #[schemars(length(max = MAX_TEXT_CHARS))]
    pub text: String,
    /// Clip length in frames at 20 fps.
    #[schemars(range(min = 1, max = MAX_FRAMES))]
    pub frames: u32,
    /// The constraints; the task's error is `Σ weight × error`.
    #[schemars(length(min = 1, max = MAX_CONSTRAINTS))]
    pub constraints: Vec<NamedConstraint>,
    /// RG-DNO's relational task parse (§4.2), for retrieval-guided optimisation.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relational_parse: Option<RelationalParse>,
}

/// One constraint of a task, named for the relational parse.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NamedConstraint {
    /// `c1`, `c2`, ... (unique within the program).
    #[schemars(regex(pattern = r"^c[1-9][0-9]{0,3}$"))]
    pub id: String,
    /// What the constraint means, in words (given to the LLM for relational parsing).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(length(max = MAX_TEXT_CHARS))]
    pub description: Option<String>,
    /// Weight of its error in the sum (≥ 0; default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schemars(range(min = 0.0, max = 1000000.0))]
    pub weight: Option<f64>,
    /// The constraint.
    pub expr: Expr,
}

impl NamedConstraint {
    /// The weight, 1 when absent.
    pub fn weight(&self) -> f64 {
        self.weight.unwrap_or(1.0)
    }
}

/// RG-DNO relational task parse (§4.2, Algorithm 1; supp. Fig. 9): the most difficult constraint
/// `c_D`, the constraints tightly connected to it and those conflicting with it, by id.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RelationalParse {
    /// Id of `c_D`.
    pub most_difficult: String,
    /// Ids retrieved together with `c_D` (Rule 2).
    #[schemars(extend("uniqueItems" = true))]
    pub connected: Vec<String>,
    /// Ids removed from the retrieved-noise set `C2` (Rule 3).
    #[schemars(extend("uniqueItems" = true))]
    pub conflicting: Vec<String>,
    /// Confidence `s` in the retrieval, in [0, 1]; the paper's `s ∈ {0, 1}` is
    /// `s ≥` [`CONFIDENT_RETRIEVAL`] (Rule 4: when not confident, `c_D` stays in `C1`).
    #[schemars(range(min = 0.0, max = 1.0))]
    pub retrieval_confidence: f64,
}

/// Constraint ids grouped by RG-DNO's Algorithm 1.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConstraintGroups {
    /// `C_R`: fitted by retrieval (`c_D` and its connected constraints).
    pub retrieval: Vec<String>,
    /// `C1`: fitted from random noise.
    pub random_noise: Vec<String>,
    /// `C2`: fitted from the retrieved noise.
    pub retrieved_noise: Vec<String>,
}

impl TaskProgram {
    /// The scene primitives of every scene constraint, in program order (under `and`, `or` and
    /// `not` too): what a picture of the task draws.
    pub fn scene_primitives(&self) -> Vec<Primitive> {
        let mut out = Vec::new();
        for constraint in &self.constraints {
            constraint.expr.walk("", &mut |expr, _| {
                if let Expr::Scene(scene) = expr {
                    out.push(scene.primitive.clone());
                }
            });
        }
        out
    }

    /// The objects of every `carry` constraint, in program order (under `and`, `or` and `not`
    /// too): what a picture of the task draws between the hands.
    pub fn carried_objects(&self) -> Vec<Carry> {
        let mut out = Vec::new();
        for constraint in &self.constraints {
            constraint.expr.walk("", &mut |expr, _| {
                if let Expr::Carry(carry) = expr {
                    out.push(carry.clone());
                }
            });
        }
        out
    }

    /// Parses a program from JSON text (types only; see [`TaskProgram::validate`]). The error names
    /// the path of the first bad field, and for an unknown name lists the valid ones.
    /// A leading byte-order mark (which some editors write) is skipped, as RFC 8259 allows.
    pub fn from_json(text: &str) -> Result<TaskProgram, ProgramError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        if let Some(first) = text.trim_start().chars().next().filter(|&c| c != '{') {
            let found = match first {
                '[' => "an array".to_owned(),
                '"' => "a string".to_owned(),
                c if c.is_ascii_digit() || c == '-' => "a number".to_owned(),
                c => format!("'{}'", c.escape_debug()),
            };
            return Err(ProgramError::new(
                String::new(),
                Problem::Shape(format!(
                    "a program is a JSON object {{\"text\": ..., \"frames\": ..., \"constraints\": [...]}}; \
                     this document starts with {found}"
                )),
            ));
        }
        let mut deserializer = serde_json::Deserializer::from_str(text);
        let program: TaskProgram =
            serde_path_to_error::deserialize(&mut deserializer).map_err(|error| parse_error(&error))?;
        deserializer.end().map_err(|error| parse_error_at(String::new(), &error))?;
        Ok(program)
    }

    /// [`TaskProgram::from_json`] then [`TaskProgram::validate`]: every problem found.
    pub fn from_json_validated(text: &str) -> Result<TaskProgram, Vec<ProgramError>> {
        let program = TaskProgram::from_json(text).map_err(|error| vec![error])?;
        program.validate()?;
        Ok(program)
    }

    /// The program as pretty-printed JSON.
    pub fn to_json_pretty(&self) -> Result<String, ProgramError> {
        serde_json::to_string_pretty(self)
            .map_err(|error| ProgramError::new(String::new(), Problem::Shape(error.to_string())))
    }

    /// The constraint with this id.
    pub fn constraint(&self, id: &str) -> Option<&NamedConstraint> {
        self.constraints.iter().find(|constraint| constraint.id == id)
    }

    /// Groups the constraints by RG-DNO's Algorithm 1: `C1 = C2 = C`; `C_R = {c_D} ∪ connected`;
    /// conflicting ones leave `C2`; with confident retrieval `c_D` leaves `C1`. `None` without a
    /// relational parse. Assumes a validated program (unknown ids are simply not matched).
    pub fn constraint_groups(&self) -> Option<ConstraintGroups> {
        let parse = self.relational_parse.as_ref()?;
        let ids = || self.constraints.iter().map(|constraint| constraint.id.clone());
        let retrieval = ids().filter(|id| *id == parse.most_difficult || parse.connected.contains(id)).collect();
        let confident = parse.retrieval_confidence >= CONFIDENT_RETRIEVAL;
        let random_noise = ids().filter(|id| !(confident && *id == parse.most_difficult)).collect();
        let retrieved_noise = ids().filter(|id| !parse.conflicting.contains(id)).collect();
        Some(ConstraintGroups { retrieval, random_noise, retrieved_noise })
    }
}

fn parse_error(error: &serde_path_to_error::Error<serde_json::Error>) -> ProgramError {
    let path = error.path().to_string();
    parse_error_at(if path == "." { String::new() } else { path }, error.inner())
}

fn parse_error_at(path: String, error: &serde_json::Error) -> ProgramError {
    use serde_json::error::Category;
    let problem = match error.classify() {
        Category::Syntax | Category::Eof | Category::Io => {
            Problem::Syntax { line: error.line(), column: error.column(), message: error.to_string() }
        }
        Category::Data => {
            let (path, message) = serde_util::nested_path(path, &error.to_string());
            return ProgramError::new(path, Problem::Shape(message));
        }
    };
    ProgramError::new(path, problem)
}
