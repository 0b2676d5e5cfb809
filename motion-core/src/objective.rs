//! The criterion every noise-optimising method minimises (DNO, RG-DNO's stages): the compiled
//! program's `Σ wᵢ·Eᵢ` on the joints recovered from the features, plus a guard against
//! one-frame glitches.

use candle_core::Tensor;

use crate::constraints::{second_difference, CompiledProgram, NORM_EPS};
use crate::prior::Prior;

/// Joint acceleration above which the jitter guard acts, m/frame² (0.15 m/frame² = 60 m/s²;
/// our training walks peak at 0.13).
pub const JITTER_LIMIT: f64 = 0.15;

/// The jitter guard `Σ_{t,j} relu(‖a_tj‖ − limit)²` per sample `[B]` of joints `[B, T, 22, 3]`,
/// with `a` the second time difference (m/frame²); 0 for fewer than 3 frames.
pub fn jitter_penalty(joints: &Tensor, limit: f64) -> candle_core::Result<Tensor> {
    let (batch, frames, _, _) = joints.dims4()?;
    if frames < 3 {
        return Tensor::zeros(batch, joints.dtype(), joints.device());
    }
    let a = second_difference(joints)?;
    let norm = (a.sqr()?.sum(candle_core::D::Minus1)? + NORM_EPS)?.sqrt()?;
    (norm - limit)?.relu()?.sqr()?.reshape((batch, ()))?.sum(candle_core::D::Minus1)
}

/// The criterion every noise-optimising method minimises: per sample `[B]`, the program's
/// `Σ wᵢ·Eᵢ` on the joints of normalised features `x` `[B, T, 263]`, plus `jitter_weight ×`
/// [`jitter_penalty`]. `initial` `[B or 1, T, 22, 3]` is what `stay_near_initial` terms compare
/// with.
pub fn program_objective<'a>(
    prior: &'a Prior,
    compiled: &'a CompiledProgram,
    initial: &'a Tensor,
    jitter_weight: f64,
) -> impl Fn(&Tensor) -> candle_core::Result<Tensor> + 'a {
    let on_joints = joints_objective(compiled, initial, jitter_weight);
    move |x: &Tensor| on_joints(&prior.to_joints(x)?)
}

/// [`program_objective`] on joints `[B, T, 22, 3]` (m) instead of features.
pub fn joints_objective<'a>(
    compiled: &'a CompiledProgram,
    initial: &'a Tensor,
    jitter_weight: f64,
) -> impl Fn(&Tensor) -> candle_core::Result<Tensor> + 'a {
    move |joints: &Tensor| {
        let error = compiled.evaluate(joints, Some(initial)).map_err(candle_core::Error::wrap)?.total;
        if jitter_weight > 0.0 {
            error + (jitter_penalty(joints, JITTER_LIMIT)? * jitter_weight)?
        } else {
            Ok(error)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn jitter_penalty_by_hand_and_its_gradient() {
        // One joint jumps 0.5 m up on frame 2 of 5: second differences 0.5, −1.0, 0.5 m/frame².
        let mut data = vec![0f64; 5 * 22 * 3];
        data[2 * 66 + 3 * 15 + 1] = 0.5;
        let joints = Tensor::from_vec(data, (1, 5, 22, 3), &Device::Cpu).unwrap();
        let expected = 2.0 * (0.5 - JITTER_LIMIT).powi(2) + (1.0 - JITTER_LIMIT).powi(2);
        let got = jitter_penalty(&joints, JITTER_LIMIT).unwrap().to_vec1::<f64>().unwrap();
        assert!((got[0] - expected).abs() < 1e-9, "{got:?} vs {expected}");
        let smooth = Tensor::zeros((2, 5, 22, 3), candle_core::DType::F64, &Device::Cpu).unwrap();
        assert_eq!(jitter_penalty(&smooth, JITTER_LIMIT).unwrap().to_vec1::<f64>().unwrap(), vec![0.0, 0.0]);
        crate::testing::finite_difference_check(&joints, |j| jitter_penalty(j, JITTER_LIMIT)?.sum_all(), 1e-6, 1e-5)
            .unwrap();
    }
}
