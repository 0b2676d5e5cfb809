//! A program ready for the optimiser: every meaning check passed, compiled once.
//!
//! A program that parses and fits the schema must still mean something an optimiser can reach.
//! [`CheckedProgram::check`] runs, in order: the program's own rules ([`TaskProgram::validate`]:
//! joints, finite numbers in range, frames inside the clip, the ids of the relational parse);
//! then it compiles the program and checks that its loss is 0 or has a non-zero gradient with
//! respect to the motion on a probe walk ([`CompiledProgram::gradient_check`]; ProgMoGen's
//! GPT-written losses sometimes had none, which silently stalls the optimiser). Programs from
//! the LLM and from task files go through the same checks, and the compiled program is the one
//! the generator runs.

use candle_core::Device;

use super::compiled::CompiledProgram;
use super::error::ConstraintError;
use crate::program::{Problem, ProgramError, RelationalParse, TaskProgram};

/// A program that passed every meaning check, with its compiled loss.
#[derive(Debug, Clone)]
pub struct CheckedProgram {
    program: TaskProgram,
    compiled: CompiledProgram,
    device: Device,
}

impl CheckedProgram {
    /// Checks `program` and compiles it on `device`; the error lists every problem with its JSON
    /// path (as the LLM's repair round and a task file's reader show them).
    pub fn check(program: TaskProgram, device: &Device) -> Result<Self, Vec<ProgramError>> {
        program.validate()?;
        let compiled = CompiledProgram::compile(&program, device).map_err(|error| match error {
            ConstraintError::Invalid(problems) => problems,
            other => vec![inconsistent("constraints", format!("cannot be compiled: {other}"))],
        })?;
        // The probe walk lives on the CPU; a program compiled elsewhere is probed on a CPU copy.
        let probed = if device.is_cpu() {
            compiled.gradient_check()
        } else {
            CompiledProgram::compile(&program, &Device::Cpu)
                .map_err(candle_core::Error::wrap)
                .and_then(|c| c.gradient_check())
        };
        let check =
            probed.map_err(|error| vec![inconsistent("constraints", format!("cannot be evaluated: {error}"))])?;
        if check.passes() {
            return Ok(CheckedProgram { program, compiled, device: device.clone() });
        }
        let mut problems: Vec<ProgramError> = check
            .stalled
            .iter()
            .filter_map(|id| program.constraints.iter().position(|c| &c.id == id))
            .map(|i| {
                inconsistent(
                    format!("constraints[{i}].expr"),
                    "its error is positive on a walking motion but has no gradient with respect to the joints, so \
                     optimisation cannot reduce it (e.g. a distance between two fixed points)"
                        .into(),
                )
            })
            .collect();
        if problems.is_empty() {
            problems.push(inconsistent(
                "constraints",
                format!(
                    "the total loss is {:.4} on a walking motion but has no gradient with respect to the joints",
                    check.total
                ),
            ));
        }
        Err(problems)
    }

    /// The program.
    pub fn program(&self) -> &TaskProgram {
        &self.program
    }

    /// The program compiled for motions of its frame count.
    pub fn compiled(&self) -> &CompiledProgram {
        &self.compiled
    }

    /// The device the program was compiled on (its motions' tensors must live there).
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The program with `parse` as its relational parse, checked against the program's ids (the
    /// compiled loss does not depend on the parse).
    pub fn with_relational_parse(self, parse: Option<RelationalParse>) -> Result<Self, Vec<ProgramError>> {
        let CheckedProgram { mut program, compiled, device } = self;
        program.relational_parse = parse;
        program.validate()?;
        Ok(CheckedProgram { program, compiled, device })
    }
}

fn inconsistent(path: impl Into<String>, why: String) -> ProgramError {
    ProgramError::new(path, Problem::Inconsistent(why))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn program(expr: &str) -> TaskProgram {
        let text = format!(r#"{{"text": "", "frames": 40, "constraints": [{{"id": "c1", "expr": {expr}}}]}}"#);
        TaskProgram::from_json(&text).unwrap()
    }

    #[test]
    fn a_loss_without_gradient_is_reported_at_its_constraint() {
        let stalled = program(
            r#"{"op": "equal", "quantity": {"kind": "distance", "a": {"fixed_m": [0.0, 0.0, 0.0]}, "b": {"fixed_m": [1.0, 0.0, 0.0]}, "axes": "xyz"}, "target": [0.0]}"#,
        );
        let errors = CheckedProgram::check(stalled, &Device::Cpu).unwrap_err();
        assert_eq!(errors.len(), 1, "{errors:?}");
        assert_eq!(errors[0].path, "constraints[0].expr");
        assert!(errors[0].to_string().contains("no gradient"));
        let fine = program(
            r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "target": [5.0], "frames": {"keyframes": ["last"]}}"#,
        );
        let checked = CheckedProgram::check(fine, &Device::Cpu).unwrap();
        assert_eq!(checked.compiled().frames(), 40);
    }

    #[test]
    fn rules_come_first_and_a_parse_is_checked_against_the_ids() {
        let late = program(
            r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "target": [5.0], "frames": {"keyframes": [{"frame": 40}]}}"#,
        );
        let errors = CheckedProgram::check(late.clone(), &Device::Cpu).unwrap_err();
        assert!(errors.iter().all(|e| !e.to_string().contains("no gradient")), "{errors:?}");
        let mut fine = late;
        fine.constraints[0].expr = program(
            r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "target": [5.0], "frames": {"keyframes": ["last"]}}"#,
        )
        .constraints[0]
            .expr
            .clone();
        let checked = CheckedProgram::check(fine, &Device::Cpu).unwrap();
        let parse = |id: &str| RelationalParse {
            most_difficult: id.into(),
            connected: Vec::new(),
            conflicting: Vec::new(),
            retrieval_confidence: 1.0,
        };
        let errors = checked.clone().with_relational_parse(Some(parse("c9"))).unwrap_err();
        assert!(errors.iter().any(|e| e.to_string().contains("c9")), "{errors:?}");
        let parsed = checked.with_relational_parse(Some(parse("c1"))).unwrap();
        assert_eq!(parsed.program().relational_parse.as_ref().unwrap().most_difficult, "c1");
    }
}
