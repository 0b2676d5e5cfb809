//! A flight phase (a jump, a hop, a leap over a hurdle): both feet off the ground together for a
//! run of consecutive frames, somewhere in the frames searched ([`crate::program::Airborne`]).

use candle_core::{Result, Tensor, D};

use super::frames::condition_mask;
use crate::program::Condition;
use crate::skeleton::Joint;

/// The foot joints that must all clear the ground in flight: ankles and toes.
pub const FLIGHT_JOINTS: [Joint; 4] = [Joint::LeftAnkle, Joint::RightAnkle, Joint::LeftFoot, Joint::RightFoot];

/// How far the lowest foot joint is below `clearance` (m) per frame, `relu(c − min_j y_j)` over
/// [`FLIGHT_JOINTS`], `[B, T]` from joints `[B, T, 22, 3]`; 0 on a frame of flight.
pub fn flight_deficit(joints: &Tensor, clearance: f64) -> Result<Tensor> {
    let index = FLIGHT_JOINTS.iter().map(|j| j.index() as u32).collect::<Vec<_>>();
    let feet = joints.index_select(&Tensor::from_vec(index, FLIGHT_JOINTS.len(), joints.device())?, 2)?;
    let lowest = feet.narrow(D::Minus1, 1, 1)?.squeeze(D::Minus1)?.min(D::Minus1)?; // [B, T]
    (clearance - lowest)?.relu()
}

/// Start frames of the windows of `length` consecutive frames that lie wholly inside `kept`
/// (sorted, distinct frame numbers).
pub fn window_starts(kept: &[usize], length: usize) -> Vec<usize> {
    if length == 0 {
        return Vec::new();
    }
    kept.iter()
        .enumerate()
        .filter(|&(i, &f)| kept.get(i + length - 1) == Some(&(f + length - 1)))
        .map(|(_, &f)| f)
        .collect()
}

/// Means of `x` `[B, T]` over the windows of `length` frames starting at `starts` (`[W]`, u32),
/// `[B, W]`.
pub fn window_means(x: &Tensor, starts: &Tensor, length: usize) -> Result<Tensor> {
    let frames = x.dim(1)?;
    if length == 0 || length > frames {
        candle_core::bail!("a window of {length} frames does not fit a signal of {frames}");
    }
    let count = frames - length + 1;
    let mut sum = x.narrow(1, 0, count)?;
    for k in 1..length {
        sum = (sum + x.narrow(1, k, count)?)?;
    }
    (sum / length as f64)?.contiguous()?.index_select(starts, 1)
}

/// Which windows (`[B, W]`, 0/1, no gradient) lie wholly on frames where `when` holds on the
/// current motion; `None` without a condition.
pub fn windows_meeting(
    joints: &Tensor,
    when: &Option<Condition>,
    starts: &Tensor,
    length: usize,
) -> Result<Option<Tensor>> {
    let Some(condition) = when else { return Ok(None) };
    let mask = condition_mask(joints, condition, joints.dim(1)?)?;
    let kept = window_means(&mask, starts, length)?;
    Ok(Some(kept.ge(1.0 - 1e-6)?.to_dtype(joints.dtype())?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn windows_lie_inside_the_kept_frames() {
        assert_eq!(window_starts(&[0, 1, 2, 3, 4], 3), vec![0, 1, 2]);
        assert_eq!(window_starts(&[2, 3, 5, 6, 7], 2), vec![2, 5, 6]);
        assert_eq!(window_starts(&[2, 4, 6], 2), Vec::<usize>::new());
        let x = Tensor::new(&[[1.0f64, 2.0, 3.0, 4.0]], &Device::Cpu).unwrap();
        let starts = Tensor::new(&[0u32, 2], &Device::Cpu).unwrap();
        assert_eq!(window_means(&x, &starts, 2).unwrap().to_vec2::<f64>().unwrap(), vec![vec![1.5, 3.5]]);
    }
}
