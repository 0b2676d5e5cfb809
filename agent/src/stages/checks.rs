//! Meaning checks: what a program that parses and fits the schema must still satisfy before the
//! optimiser sees it.
//!
//! [`MEANING_CHECKS`] runs in order on every program, from the LLM or from a task file:
//! [`rules`] covers joints, finite numbers in range, frames inside the clip and the ids of the
//! relational parse ([`TaskProgram::validate`]); [`gradient`] compiles the program and checks
//! that its loss has a non-zero gradient with respect to the motion on a probe walk
//! (ProgMoGen's GPT-written losses sometimes had none, which silently stalls the optimiser).

use candle_core::Device;
use motion_core::constraints::CompiledProgram;
use motion_core::program::{Problem, ProgramError, TaskProgram};

/// A meaning check: the problems of `program`, empty when it passes.
pub type MeaningCheck = fn(&TaskProgram) -> Vec<ProgramError>;

/// Every meaning check, in order.
pub const MEANING_CHECKS: &[MeaningCheck] = &[rules, gradient];

/// The program's own rules ([`TaskProgram::validate`]).
pub fn rules(program: &TaskProgram) -> Vec<ProgramError> {
    program.validate().err().unwrap_or_default()
}

/// The compiled loss must be 0 or have a gradient on the probe motion
/// ([`CompiledProgram::gradient_check`]); the error names each constraint whose positive error has
/// no gradient. Programs that break the rules are left to [`rules`].
pub fn gradient(program: &TaskProgram) -> Vec<ProgramError> {
    let Ok(compiled) = CompiledProgram::compile(program, &Device::Cpu) else { return Vec::new() };
    let check = match compiled.gradient_check() {
        Ok(check) => check,
        Err(error) => {
            return vec![ProgramError::new(
                "constraints",
                Problem::Inconsistent(format!("cannot be evaluated: {error}")),
            )]
        }
    };
    if check.passes() {
        return Vec::new();
    }
    let mut errors: Vec<ProgramError> = check
        .stalled
        .iter()
        .filter_map(|id| program.constraints.iter().position(|c| &c.id == id))
        .map(|i| {
            ProgramError::new(
                format!("constraints[{i}].expr"),
                Problem::Inconsistent(
                    "its error is positive on a walking motion but has no gradient with respect to the joints, \
                     so optimisation cannot reduce it (e.g. a distance between two fixed points)"
                        .into(),
                ),
            )
        })
        .collect();
    if errors.is_empty() {
        errors.push(ProgramError::new(
            "constraints",
            Problem::Inconsistent(format!(
                "the total loss is {:.4} on a walking motion but has no gradient with respect to the joints",
                check.total
            )),
        ));
    }
    errors
}

/// The problems found by every check of [`MEANING_CHECKS`].
pub fn meaning_problems(program: &TaskProgram) -> Vec<ProgramError> {
    MEANING_CHECKS.iter().flat_map(|check| check(program)).collect()
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
        let errors = meaning_problems(&stalled);
        assert_eq!(errors.len(), 1, "{errors:?}");
        assert_eq!(errors[0].path, "constraints[0].expr");
        assert!(errors[0].to_string().contains("no gradient"));
        let fine = program(
            r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "target": [5.0], "frames": {"keyframes": ["last"]}}"#,
        );
        assert!(meaning_problems(&fine).is_empty());
    }
}
