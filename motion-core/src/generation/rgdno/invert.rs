//! Stage 3 (eq. 7): a retrieved motion `x_R` inverted to noise, `z_R = G⁻¹(x_R)`, once for the
//! batch ([`crate::generation::inversion::invert_motion`]: fixed-point DDIM inversion, then polishing).

use candle_core::{DType, Tensor};

use super::error::RgDnoError;
use super::figures::scalar;
use super::report::{Stage, StageProgress};
use crate::generation::inversion::{invert_motion, mean_joint_distance, InversionConfig};
use crate::numeric::mean;
use crate::prior::Prior;

/// The noise `[1, T, 263]` whose sample reproduces the raw features `x_r` `[T, 263]` under the
/// prompt `text` `[1, ..]`, and the mean joint distance of its motion to `x_R`, m; `round` names
/// the retrieved motion in the progress reports.
pub(super) fn invert_retrieved(
    prior: &Prior,
    x_r: &Tensor,
    text: &Tensor,
    inversion: &InversionConfig,
    round: usize,
    progress: &mut dyn FnMut(&StageProgress),
) -> Result<(Tensor, f64), RgDnoError> {
    let x_r = prior.mean_std.normalize(&x_r.to_dtype(DType::F32)?.unsqueeze(0)?)?;
    let polish_steps = inversion.feature_polish_steps + inversion.polish_steps;
    let mut polished = 0;
    let inverted = invert_motion(prior, &x_r, text, inversion, |s| {
        polished += 1;
        progress(&StageProgress {
            stage: Stage::Inversion,
            round,
            step: polished,
            steps: polish_steps,
            loss: mean(&s.loss),
            sample: None,
        });
    })?;
    let error_m = scalar(&mean_joint_distance(&prior.to_joints(&inverted.x)?, &prior.to_joints(&x_r)?)?)?;
    Ok((inverted.z, error_m))
}
