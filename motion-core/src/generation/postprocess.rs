//! What every method ends with (after [`crate::generation::generate`]'s optimisation): the
//! joints of its features, the kinematic refinement against the program's geometric
//! constraints ([`crate::generation::refine`]), the contact-aware foot clean-up ([`crate::cleanup`]) and a
//! check that every result is finite.

use std::time::Instant;

use candle_core::Tensor;

use crate::cleanup::{foot_lock, FootLockConfig, FootLockReport};
use crate::constraints::CompiledProgram;
use crate::generation::method::{ensure_finite, Generated, GenerationConfig, GenerationError, Task};
use crate::generation::refine::{refine, RefineConfig, RefineReport};
use crate::generation::schedule::Schedule;
use crate::motion::{poses_to_tensor, tensor_to_poses};
use crate::prior::Prior;
use crate::program::{Primitive, TaskProgram};

/// A method's motion before the finishing stages.
#[derive(Debug, Clone)]
pub struct Unfinished {
    /// Normalised features `[B, T, 263]`.
    pub features: Tensor,
    /// The unconstrained start `G(z0)` as joints, `[B, T, 22, 3]`.
    pub initial_joints: Tensor,
    /// Per sample, the criterion loss at every optimisation step.
    pub loss_history: Vec<Vec<f64>>,
}

/// What every method ends with: the joints of `features`, the kinematic refinement against
/// the program, the clean-up (with its floor planting off for programs on a raised support)
/// and the [`Generated`] record, timed from `start`.
pub fn finish(
    prior: &Prior,
    Task { program, compiled }: Task<'_>,
    config: &GenerationConfig,
    Unfinished { features, initial_joints, loss_history }: Unfinished,
    start: Instant,
) -> Result<Generated, GenerationError> {
    ensure_finite(&features, &format!("{}'s motion features", config.method))?;
    let raw_joints = prior.to_joints(&features)?;
    ensure_finite(&raw_joints, &format!("{}'s joint positions", config.method))?;
    let refine_config = RefineConfig { enabled: config.refines(), ..config.refine.clone() };
    let (refined, refine) =
        refine_in_parallel(&raw_joints, compiled, &initial_joints, (&refine_config, config.schedule))?;
    ensure_finite(&refined, "the refinement's joint positions")?;
    let (cleaned, mut foot_lock) = clean_up(&refined, &finishing_foot_lock(program, config))?;
    ensure_finite(&cleaned, "the foot clean-up's joint positions")?;
    let joints = keep_what_was_met(compiled, &initial_joints, (&refined, cleaned), &mut foot_lock)?;
    Ok(Generated {
        features,
        joints,
        raw_joints,
        refine,
        foot_lock,
        initial_joints,
        loss_history,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// The cleaned motion `[B, T, 22, 3]`, except for each sample where the clean-up would fail a
/// constraint of `compiled` that the motion before it met: that sample keeps the motion before,
/// and its report names the constraints (`undone_for`). So the clean-up never breaks what was
/// met (a balance held over one foot, a hand on its target), and the report says where it was
/// given up.
fn keep_what_was_met(
    compiled: &CompiledProgram,
    initial: &Tensor,
    (before, cleaned): (&Tensor, Tensor),
    reports: &mut [FootLockReport],
) -> Result<Tensor, GenerationError> {
    let (met, now) = (compiled.satisfaction(before, Some(initial))?, compiled.satisfaction(&cleaned, Some(initial))?);
    let mut undone = vec![false; reports.len()];
    for (b, report) in reports.iter_mut().enumerate() {
        report.undone_for =
            met.iter().zip(&now).filter(|(m, n)| m.pass[b] && !n.pass[b]).map(|(m, _)| m.id.clone()).collect();
        undone[b] = !report.undone_for.is_empty();
    }
    if !undone.contains(&true) {
        return Ok(cleaned);
    }
    let mask =
        Tensor::from_vec(undone.iter().map(|&u| u8::from(u)).collect(), (undone.len(), 1, 1, 1), before.device())?;
    Ok(mask.broadcast_as(before.shape())?.where_cond(before, &cleaned)?)
}

/// The clean-up a generation of `program` ends with: `config.foot_lock`, with its floor planting
/// off for programs on a raised support, its floor guard off over a pit, and its locks judged
/// only under [`Schedule::UntilMet`] (the papers' schedule writes the motions it always wrote).
pub fn finishing_foot_lock(program: &TaskProgram, config: &GenerationConfig) -> FootLockConfig {
    let mut lock = config.foot_lock.clone();
    lock.plant_on_floor &= !has_raised_support(program);
    lock.keep_above_floor &= !has_sunk_ground(program);
    lock.judge_locks &= config.schedule == Schedule::UntilMet;
    lock
}

/// [`refine`] with the batch cut into one contiguous group per rayon worker, the groups
/// refined in parallel. Every sample's refinement is its own (its loss, its Adam moments,
/// its keep-or-drop verdict); the rest skeleton each group measures is the prior's, the
/// same for every sample.
fn refine_in_parallel(
    joints: &Tensor,
    compiled: &CompiledProgram,
    initial: &Tensor,
    (config, schedule): (&RefineConfig, Schedule),
) -> Result<(Tensor, Vec<RefineReport>), GenerationError> {
    use rayon::prelude::*;
    let batch = joints.dim(0)?;
    let groups = rayon::current_num_threads().clamp(1, batch.max(1));
    if groups == 1 || initial.dim(0)? != batch {
        return Ok(refine(joints, compiled, Some(initial), config, schedule)?);
    }
    let parts = (0..groups)
        .into_par_iter()
        .map(|g| {
            let (first, end) = (g * batch / groups, (g + 1) * batch / groups);
            let (joints, initial) = (joints.narrow(0, first, end - first)?, initial.narrow(0, first, end - first)?);
            refine(&joints, compiled, Some(&initial), config, schedule)
        })
        .collect::<std::result::Result<Vec<_>, _>>()?;
    let (tensors, reports): (Vec<Tensor>, Vec<Vec<RefineReport>>) = parts.into_iter().unzip();
    Ok((Tensor::cat(&tensors, 0)?, reports.concat()))
}

/// [`fn@foot_lock`] on every sample of `joints` `[B, T, 22, 3]` (samples in parallel): the
/// cleaned joints (same shape, dtype and device) and each sample's report.
pub fn clean_up(joints: &Tensor, config: &FootLockConfig) -> Result<(Tensor, Vec<FootLockReport>), GenerationError> {
    use rayon::prelude::*;
    let motions = tensor_to_poses(joints)?;
    let locked = motions
        .par_iter()
        .enumerate()
        .map(|(sample, poses)| {
            foot_lock(poses, None, config).map_err(|source| GenerationError::FootLock { sample, source })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (cleaned, reports): (Vec<_>, Vec<_>) = locked.into_iter().map(|l| (l.poses, l.report)).unzip();
    if !config.enabled {
        return Ok((joints.clone(), reports));
    }
    Ok((poses_to_tensor(&cleaned, joints.dtype(), joints.device())?, reports))
}

/// Whether the scene's ground lies more than 1 cm below y = 0 (a pit), where legs may go below
/// y = 0.
fn has_sunk_ground(program: &TaskProgram) -> bool {
    program.scene_primitives().iter().any(|p| matches!(p, Primitive::Ground(ground) if ground.height_m < -0.01))
}

/// Whether the scene holds a support more than 1 cm above or below the floor y = 0 (a raised
/// balance beam, a raised or sunk ground), on which feet must not be planted at y = 0.
fn has_raised_support(program: &TaskProgram) -> bool {
    program.scene_primitives().iter().any(|p| match p {
        Primitive::BalanceBeam(beam) => beam.point_m[1].abs() > 0.01,
        Primitive::Ground(ground) => ground.height_m.abs() > 0.01,
        _ => false,
    })
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device};
    use glam::DVec3;

    use super::*;
    use crate::skeleton::{rest_pose, Joint, Pose};

    /// 40 frames of a figure standing with its right foot under its centre of mass, sliding
    /// along +x at `speed` m/frame, feet on the floor.
    fn on_the_right_foot(speed: f64) -> Vec<Pose> {
        let mut pose = rest_pose();
        let lowest = pose.iter().map(|j| j.y).fold(f64::INFINITY, f64::min);
        for j in pose.iter_mut() {
            j.y -= lowest;
        }
        // The right foot joint (the toes) under the pelvis, the ankle behind it.
        let (pelvis, foot) = (pose[Joint::Pelvis.index()], pose[Joint::RightFoot.index()]);
        for joint in [Joint::RightAnkle, Joint::RightFoot] {
            let p = pose[joint.index()];
            pose[joint.index()] = DVec3::new(pelvis.x, p.y, pelvis.z + (p.z - foot.z));
        }
        (0..40).map(|t| pose.map(|p| p + DVec3::new(speed * t as f64, 0.0, 0.0))).collect()
    }

    #[test]
    fn the_locks_are_judged_under_the_until_met_schedule_only() {
        let program = TaskProgram::from_json(r#"{"text": "walk", "frames": 40, "constraints": []}"#).unwrap();
        let mut config = GenerationConfig::new(crate::generation::method::Method::Dno);
        for (schedule, judged) in [(Schedule::Paper, false), (Schedule::UntilMet, true)] {
            config.schedule = schedule;
            assert_eq!(finishing_foot_lock(&program, &config).judge_locks, judged, "{schedule:?}");
        }
    }

    #[test]
    fn a_balance_the_motion_met_stays_met_where_the_clean_up_would_break_it() {
        let device = Device::Cpu;
        let program = TaskProgram::from_json(
            r#"{"text": "stand on the right foot", "frames": 40, "constraints": [{"id": "c1", "expr": {"op": "equal",
            "quantity": {"kind": "distance", "a": {"centre_of_mass": {}}, "b": {"joint": "right_foot"}, "axes": "xz"},
            "target": [0.0]}}]}"#,
        )
        .unwrap();
        let compiled = CompiledProgram::compile(&program, &device).unwrap();
        let motions = [on_the_right_foot(0.004), on_the_right_foot(0.0)];
        let joints = poses_to_tensor(&motions, DType::F32, &device).unwrap();
        let met = |j: &Tensor| compiled.satisfaction(j, None).unwrap()[0].pass.clone();
        assert_eq!(met(&joints), [true, true], "the motions keep the centre of mass over the right foot");
        let (cleaned, mut reports) = clean_up(&joints, &FootLockConfig::default()).unwrap();
        assert_eq!(met(&cleaned), [false, true], "locking the sliding foot alone breaks the balance");

        let kept = keep_what_was_met(&compiled, &joints, (&joints, cleaned.clone()), &mut reports).unwrap();
        assert_eq!(met(&kept), [true, true]);
        assert_eq!(reports[0].undone_for, ["c1"]);
        assert!(reports[1].undone_for.is_empty());
        let row = |t: &Tensor, b: usize| t.get(b).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(row(&kept, 0), row(&joints, 0), "sample 0 keeps the motion before the clean-up");
        assert_eq!(row(&kept, 1), row(&cleaned, 1), "sample 1 keeps its clean-up");
    }
}
