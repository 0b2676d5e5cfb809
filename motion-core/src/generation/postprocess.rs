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
    let (joints, foot_lock) = clean_up(&refined, &finishing_foot_lock(program, config))?;
    ensure_finite(&joints, "the foot clean-up's joint positions")?;
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

/// The clean-up a generation of `program` ends with: `config.foot_lock`, with its floor planting
/// off for programs on a raised support and its floor guard off over a pit.
pub fn finishing_foot_lock(program: &TaskProgram, config: &GenerationConfig) -> FootLockConfig {
    let mut lock = config.foot_lock.clone();
    lock.plant_on_floor &= !has_raised_support(program);
    lock.keep_above_floor &= !has_sunk_ground(program);
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

/// [`foot_lock`] on every sample of `joints` `[B, T, 22, 3]` (samples in parallel): the
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
