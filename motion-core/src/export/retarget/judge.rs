//! The task's constraints judged again on the motion as the rig plays it: where the rig stands
//! (its world, metres) and at the motion's own scale (the rig's joints divided by the leg
//! ratio), beside the verdict on our skeleton.
//!
//! A rig of other proportions does not carry every constraint over: a hand held at a world
//! position is elsewhere on a rig with shorter arms, and a target 5 m ahead is 5.25 m ahead for a
//! rig 1.05 times our size (the path is scaled with the legs). The two verdicts say which.

use candle_core::{DType, Device};
use serde::Serialize;

use crate::constraints::CompiledProgram;
use crate::export::error::ExportError;
use crate::motion::poses_to_tensor;
use crate::skeleton::Pose;

/// What the constraints are judged with.
#[derive(Debug, Clone, Copy)]
pub struct RigJudge<'a> {
    /// The task's compiled program (motions of its frame count, at 20 fps).
    pub compiled: &'a CompiledProgram,
    /// The device the program was compiled on.
    pub device: &'a Device,
    /// Per sample, the unoptimised motion that `stay_near_initial` constraints compare with, m;
    /// `None` when it is not known (such constraints are then not judged).
    pub initial: Option<&'a [Vec<Pose>]>,
}

/// One constraint's verdicts for one sample.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RigConstraint {
    /// The constraint's id in the program.
    pub id: String,
    /// Met by our skeleton's motion.
    pub ours: bool,
    /// Met by the rig's joints where the rig stands, m.
    pub on_rig: bool,
    /// Met by the rig's joints divided by the leg ratio (the motion's own scale).
    pub at_our_scale: bool,
}

/// Judges `compiled`'s constraints on sample `sample`'s motions: `ours` (our joints), `rig` (the
/// rig's nodes of our joints, m) and `rig` divided by `leg_ratio`. Nothing is judged (an empty
/// list) when the motion's frames are not the program's or a `stay_near_initial` constraint has
/// no initial motion; fails when a constraint cannot be evaluated.
pub fn judge_on_rig(
    judge: &RigJudge<'_>,
    sample: usize,
    ours: &[Pose],
    rig: &[Pose],
    leg_ratio: f64,
) -> Result<Vec<RigConstraint>, ExportError> {
    let fail =
        |e: &dyn std::fmt::Display| ExportError::Rig(format!("judging sample {sample}'s constraints on the rig: {e}"));
    if ours.len() != judge.compiled.frames() {
        // The program's frames are another rate's (an export at another input rate).
        return Ok(Vec::new());
    }
    let initial = match judge.initial.and_then(|all| all.get(sample)) {
        Some(initial) => Some(initial.clone()),
        None if judge.compiled.needs_initial() => return Ok(Vec::new()),
        None => None,
    };
    let scaled: Vec<Pose> = rig.iter().map(|pose| pose.map(|v| v / leg_ratio)).collect();
    let verdicts = |motion: &[Pose], initial_scale: f64| -> Result<Vec<(String, bool)>, ExportError> {
        let joints = poses_to_tensor(&[motion.to_vec()], DType::F32, judge.device).map_err(|e| fail(&e))?;
        let initial = initial
            .as_ref()
            .map(|i| {
                let scaled: Vec<Pose> = i.iter().map(|pose| pose.map(|v| v * initial_scale)).collect();
                poses_to_tensor(&[scaled], DType::F32, judge.device)
            })
            .transpose()
            .map_err(|e| fail(&e))?;
        let judged = judge.compiled.satisfaction(&joints, initial.as_ref()).map_err(|e| fail(&e))?;
        Ok(judged.into_iter().map(|c| (c.id, c.pass.first().copied().unwrap_or(false))).collect())
    };
    let (ours, on_rig, at_our_scale) = (verdicts(ours, 1.0)?, verdicts(rig, leg_ratio)?, verdicts(&scaled, 1.0)?);
    Ok(ours
        .into_iter()
        .zip(on_rig)
        .zip(at_our_scale)
        .map(|(((id, ours), (_, on_rig)), (_, at_our_scale))| RigConstraint { id, ours, on_rig, at_our_scale })
        .collect())
}
