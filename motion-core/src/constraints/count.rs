//! Differentiable counting (RG-DNO supp. D, eqs. 15–16): soft counts of the peaks or valleys of
//! scalar signals, e.g. steps as peaks of the foot speed, claps as valleys of the hand distance;
//! steps as footfalls (every swing of either foot); events as entries into a region of a signal
//! (hands that meet). Steps and events are judged by state machines with hysteresis
//! ([`crate::metrics::footfalls`], [`crate::metrics::event_count`]); their errors take the
//! judge's count as their value and the soft count's gradient ([`judged_error`]), so the
//! optimiser's minimum is where the judge passes.

use candle_core::{Result, Tensor, D};

use super::geometry::sigmoid;
use super::signal::signal;
use crate::metrics::{SWING_ENTER_M_PER_S, SWING_LEAVE_M_PER_S};
use crate::program::{Axes, Derivative, EventRegion, Extremum, Point, Quantity};
use crate::skeleton::Joint;

/// Soft number of extrema of `s` `[B, n]` at the interior frames listed in `frames` (indices of
/// `s`; frames 0 and n − 1 have no two neighbours and are skipped), `[B]`:
/// - peaks: `Σ_t σ(T(s[t]−s[t+1]))·σ(T(s[t]−s[t−1]))·σ(T(s[t]−θ))`;
/// - valleys: `Σ_t σ(T(s[t+1]−s[t]))·σ(T(s[t−1]−s[t]))·σ(T(θ−s[t]))`.
///
/// `T` is the sharpness per unit of the signal, `θ` the threshold.
pub fn soft_count(s: &Tensor, frames: &[usize], extremum: Extremum, threshold: f64, sharpness: f64) -> Result<Tensor> {
    let (batch, n) = s.dims2()?;
    let interior: Vec<u32> = frames.iter().filter(|&&t| t >= 1 && t + 1 < n).map(|&t| t as u32).collect();
    if interior.is_empty() {
        return Tensor::zeros(batch, s.dtype(), s.device());
    }
    let pick = |offset: i64| -> Result<Tensor> {
        let index: Vec<u32> = interior.iter().map(|&t| (i64::from(t) + offset) as u32).collect();
        s.contiguous()?.index_select(&Tensor::from_vec(index, interior.len(), s.device())?, 1)
    };
    let (centre, next, previous) = (pick(0)?, pick(1)?, pick(-1)?);
    let sign = match extremum {
        Extremum::Peaks => 1.0,
        Extremum::Valleys => -1.0,
    };
    let above = |d: Tensor| sigmoid(&(d * (sign * sharpness))?);
    let score = ((above((&centre - &next)?)? * above((&centre - &previous)?)?)? * above((&centre - threshold)?)?)?;
    score.sum(D::Minus1)
}

/// Frames of the box filter over each toe's speed in [`soft_footfalls`]: a swing's speed may
/// dip for a frame before the toe lands, which the judge's state machine rides through.
const FOOTFALL_SMOOTHING: usize = 3;

/// Soft number of footfalls of joints `[B, T, 22, 3]`, `[B]`: for each toe, its horizontal speed
/// (m/s; the `speed` quantity of the toe over x and z, [`signal`]) over [`FOOTFALL_SMOOTHING`]
/// frames, counted as events of
/// the region above [`SWING_ENTER_M_PER_S`] + b with the hysteresis band b =
/// [`SWING_ENTER_M_PER_S`] − [`SWING_LEAVE_M_PER_S`] below it ([`soft_event_count`]: above
/// 1.5 m/s in a swing, under 1 m/s out of it), the two toes added; each swing of either foot
/// adds one. The soft state has no memory of the judge's, so its band sits one band above the
/// judge's: a toe wiggling inside the judge's band before it swings adds nothing. The soft form
/// of [`crate::metrics::footfalls`] (within 0.2 of it on the shipped walks and run), which also
/// asks a swing to travel [`crate::metrics::FOOTFALL_MIN_M`] and ends it at any frame under
/// 0.5 m/s; where the two differ, the error of a steps constraint takes the judge's count as
/// its value ([`judged_error`]).
pub fn soft_footfalls(joints: &Tensor) -> Result<Tensor> {
    let (batch, frames) = (joints.dim(0)?, joints.dim(1)?);
    if frames < 2 {
        return Tensor::zeros(batch, joints.dtype(), joints.device());
    }
    let band = SWING_ENTER_M_PER_S - SWING_LEAVE_M_PER_S;
    let mut total = Tensor::zeros(batch, joints.dtype(), joints.device())?;
    for toe in [Joint::LeftFoot, Joint::RightFoot] {
        let horizontal = Quantity::Speed(Derivative { of: Point::Joint(toe), axes: Axes::Xz });
        let speed = signal(joints, &horizontal)?.squeeze(D::Minus1)?; // [B, T − 1]
        let speed = if frames > FOOTFALL_SMOOTHING { box_filter(&speed, FOOTFALL_SMOOTHING)? } else { speed };
        total = (total + soft_event_count(&speed, EventRegion::Above(SWING_ENTER_M_PER_S + band), band)?)?;
    }
    Ok(total)
}

/// Soft number of events of `s` `[B, n]` (the frames searched, in order), `[B]`: with `e` the
/// signed depth into the event region (`θ − s` for `below: θ`, `s − θ` for `above: θ`), the
/// soft state `l = σ(e/w) − σ((−e − h)/w)` ∈ [−1, 1] is +1 inside the region, −1 beyond the
/// hysteresis band `h` and 0 inside the band, `w = h/4`, and
/// `n = ½·(Σ_t ½·√((l[t+1] − l[t])² + ε) + (1 + l[0])/2 + (1 + l[n−1])/2)`:
/// each entry into the region and the way out beyond the band add 1, an event under way at the
/// first or last frame counts once. The soft form of [`crate::metrics::event_count`], which it
/// equals when the signal leaves the band between events; a signal that enters the band and goes
/// back out adds ½ where the metric adds 0. The sigmoids reach about `2h` beyond `θ`: a signal
/// further out gets next to no gradient (the prior's motion must come near the event).
pub fn soft_event_count(s: &Tensor, region: EventRegion, hysteresis: f64) -> Result<Tensor> {
    let (batch, n) = s.dims2()?;
    if n == 0 {
        return Tensor::zeros(batch, s.dtype(), s.device());
    }
    let depth = match region {
        EventRegion::Below(threshold) => (threshold - s)?,
        EventRegion::Above(threshold) => (s - threshold)?,
    };
    let edge = hysteresis / 4.0;
    let state = (sigmoid(&(&depth / edge)?)? - sigmoid(&((depth.neg()? - hysteresis)? / edge)?)?)?;
    let ends = ((state.narrow(1, 0, 1)? + state.narrow(1, n - 1, 1)?)?.squeeze(1)? + 2.0)? / 2.0;
    let changes = match n {
        1 => Tensor::zeros(batch, s.dtype(), s.device())?,
        _ => {
            let change = (state.narrow(1, 1, n - 1)? - state.narrow(1, 0, n - 1)?)?;
            ((change.sqr()? + 1e-8)?.sqrt()? * 0.5)?.sum(D::Minus1)?
        }
    };
    (changes + ends)? * 0.5
}

/// Steps of joints `[B, T, 22, 3]` as the judge counts them, footfalls
/// ([`crate::metrics::footfalls`]), per sample.
pub fn judged_footfalls(joints: &Tensor) -> Result<Vec<f64>> {
    Ok(crate::motion::tensor_to_poses(joints)?.iter().map(|m| crate::metrics::footfalls(m) as f64).collect())
}

/// Events of `s` `[B, n]` as the judge counts them ([`crate::metrics::event_count`]), per sample.
pub fn judged_events(s: &Tensor, region: EventRegion, hysteresis: f64) -> Result<Vec<f64>> {
    let rows = s.to_dtype(candle_core::DType::F64)?.to_vec2::<f64>()?;
    Ok(rows.iter().map(|row| crate::metrics::event_count(row, region, hysteresis) as f64).collect())
}

/// `judged` `[B]` as the value with the gradient of `soft` `[B]`: `soft + (judged − sg(soft))`,
/// `sg` stopping the gradient (the straight-through estimator). A count is a whole number that
/// moves in jumps; the soft count says which way the motion should move to change it.
fn valued_as(soft: &Tensor, judged: Vec<f64>) -> Result<Tensor> {
    let judged = Tensor::from_vec(judged, soft.dims(), soft.device())?.to_dtype(soft.dtype())?;
    soft + (judged - soft.detach())?
}

/// The error `(n − N)²` `[B]` of a count that the judge makes as `judged` (per sample) and the
/// soft count relaxes as `soft` `[B]`: its value is the judge's `(n_judge − N)²`, 0 exactly when
/// the judge passes; its gradient `2·((n_soft − N) + (n_judge − N))·∇n_soft` is the paper's pull
/// of the soft count to the target, plus, while the judge's count is off, a pull by the judge's
/// miss ([`valued_as`]), which moves a motion whose soft count sits on the target while the
/// judge counts otherwise.
pub fn judged_error(soft: &Tensor, judged: Vec<f64>, target: f64) -> Result<Tensor> {
    let soft_error = (soft - target)?.sqr()?;
    let judged_error = (valued_as(soft, judged)? - target)?.sqr()?;
    judged_error + (&soft_error - soft_error.detach())?
}

/// Box filter of odd width `w` along axis 1 of `s` `[B, n]`, "valid" mode: `[B, n − w + 1]`,
/// output frame i is the mean of input frames i..i+w (centred on input frame i + (w − 1)/2).
pub fn box_filter(s: &Tensor, w: usize) -> Result<Tensor> {
    let n = s.dim(1)?;
    if w <= 1 {
        return Ok(s.clone());
    }
    if w > n {
        candle_core::bail!("smoothing over {w} frames needs a signal of at least {w} frames, it has {n}");
    }
    let len = n - w + 1;
    let mut sum = s.narrow(1, 0, len)?;
    for k in 1..w {
        sum = (sum + s.narrow(1, k, len)?)?;
    }
    sum / w as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn counts_sharp_peaks_and_valleys_by_hand() {
        let s = Tensor::new(&[[0.0f64, 2.0, 0.0, 0.5, 0.0, 3.0, 1.0, 1.0]], &Device::Cpu).unwrap();
        let all: Vec<usize> = (0..8).collect();
        // Peaks above 1: frames 1 and 5 (the 0.5 bump is below θ).
        let peaks = soft_count(&s, &all, Extremum::Peaks, 1.0, 1e4).unwrap().to_vec1::<f64>().unwrap();
        assert!((peaks[0] - 2.0).abs() < 1e-9, "{peaks:?}");
        // Valleys below 0.25: frames 2 and 4.
        let valleys = soft_count(&s, &all, Extremum::Valleys, 0.25, 1e4).unwrap().to_vec1::<f64>().unwrap();
        assert!((valleys[0] - 2.0).abs() < 1e-9, "{valleys:?}");
        // Only frames 0..=3 searched: one peak.
        let first = soft_count(&s, &[0, 1, 2, 3], Extremum::Peaks, 1.0, 1e4).unwrap().to_vec1::<f64>().unwrap();
        assert!((first[0] - 1.0).abs() < 1e-9);
        let smooth = box_filter(&s, 3).unwrap().to_vec2::<f64>().unwrap();
        assert!((smooth[0][0] - 2.0 / 3.0).abs() < 1e-12 && smooth[0].len() == 6);
    }

    /// Wrist distances (m) of three claps and of hands that come no closer than 0.17 m.
    #[test]
    fn counts_events_by_hand_and_as_the_metric() {
        let claps = [0.4, 0.3, 0.15, 0.01, 0.0, 0.2, 0.35, 0.01, 0.3, 0.25, 0.0, 0.01, 0.3, 0.4];
        let near = [0.4, 0.3, 0.17, 0.2, 0.35, 0.18, 0.3, 0.17, 0.4, 0.4, 0.3, 0.2, 0.17, 0.3];
        // A clap under way at the first frame counts once, and one still under way at the last.
        let ends = [0.01, 0.3, 0.4, 0.3, 0.2, 0.0];
        let region = EventRegion::Below(0.06);
        for (values, expected) in [(&claps[..], 3.0), (&near[..], 0.0), (&ends[..], 2.0)] {
            let s = Tensor::new(values, &Device::Cpu).unwrap().unsqueeze(0).unwrap();
            let soft = soft_event_count(&s, region, 0.05).unwrap().to_vec1::<f64>().unwrap()[0];
            // Within 0.1 of the count when the signal goes 5 cm past θ (the sigmoids' soft edges).
            assert!((soft - expected).abs() < 0.1, "{values:?}: soft {soft}");
            assert_eq!(crate::metrics::event_count(values, region, 0.05) as f64, expected);
        }
        // Above: a pelvis rising past 1.2 m twice.
        let hops = [1.0, 1.0, 1.35, 1.4, 1.0, 1.0, 1.4, 1.0];
        let s = Tensor::new(&hops, &Device::Cpu).unwrap().unsqueeze(0).unwrap();
        let soft = soft_event_count(&s, EventRegion::Above(1.2), 0.1).unwrap().to_vec1::<f64>().unwrap()[0];
        assert!((soft - 2.0).abs() < 0.1, "{soft}");
    }

    #[test]
    fn soft_events_have_the_finite_difference_gradient() {
        let s = Tensor::new(&[[0.3f64, 0.12, 0.07, 0.05, 0.09, 0.13, 0.2, 0.1, 0.06]], &Device::Cpu).unwrap();
        crate::testing::finite_difference_check(
            &s,
            |s| soft_event_count(s, EventRegion::Below(0.06), 0.05)?.sum_all(),
            1e-7,
            1e-4,
        )
        .unwrap();
    }

    fn clip_tensor(name: &str) -> (Vec<crate::skeleton::Pose>, Tensor) {
        use crate::import::{deepmimic::shipped, resample};
        let poses = resample(&shipped::clip(name), 1.0, Some(10.0));
        let flat: Vec<f64> = poses.iter().flatten().flat_map(|v| [v.x, v.y, v.z]).collect();
        let t = Tensor::from_vec(flat, (1, poses.len(), 22, 3), &Device::Cpu).unwrap();
        (poses, t)
    }

    /// The soft count agrees with the footfall metric within half a footfall on 10 s of every
    /// real walk and the run (16 and 26 footfalls).
    #[test]
    fn soft_footfalls_agree_with_the_metric_on_the_real_clips() {
        for name in [
            "humanoid3d_walk.txt",
            "walker_0walk_forward.txt",
            "walker_turn_left0.txt",
            "walker_turn_left1.txt",
            "walker_turn_right0.txt",
            "walker_turn_right1.txt",
            "humanoid3d_run.txt",
        ] {
            let (poses, joints) = clip_tensor(name);
            let soft = soft_footfalls(&joints).unwrap().to_vec1::<f64>().unwrap()[0];
            let hard = crate::metrics::footfalls(&poses) as f64;
            assert!(hard >= 10.0, "{name}: {hard} footfalls in 10 s");
            assert!((soft - hard).abs() <= 0.5, "{name}: soft {soft:.2}, metric {hard}");
        }
        // A foot shuffling 4 cm back and forth every frame (0.8 m/s, inside the band): under
        // one footfall, and none for the metric.
        let (poses, _) = clip_tensor("walker_0walk_forward.txt");
        let mut shuffle = vec![poses[0]; 40];
        for (t, p) in shuffle.iter_mut().enumerate() {
            p[crate::skeleton::Joint::LeftFoot.index()].z += if t % 2 == 0 { 0.02 } else { -0.02 };
        }
        let flat: Vec<f64> = shuffle.iter().flatten().flat_map(|v| [v.x, v.y, v.z]).collect();
        let shuffle_t = Tensor::from_vec(flat, (1, 40, 22, 3), &Device::Cpu).unwrap();
        let shuffled = soft_footfalls(&shuffle_t).unwrap().to_vec1::<f64>().unwrap()[0];
        assert!(shuffled < 1.0, "shuffling counts {shuffled}");
        assert_eq!(crate::metrics::footfalls(&shuffle), 0);
        // Standing still: no footfalls.
        let still: Vec<f64> = std::iter::repeat_n(poses[0], 40).flatten().flat_map(|v| [v.x, v.y, v.z]).collect();
        let still = Tensor::from_vec(still, (1, 40, 22, 3), &Device::Cpu).unwrap();
        assert!(soft_footfalls(&still).unwrap().to_vec1::<f64>().unwrap()[0] < 0.05);
    }

    #[test]
    fn soft_footfalls_have_the_finite_difference_gradient() {
        let (_, joints) = clip_tensor("walker_0walk_forward.txt");
        let joints = joints.narrow(1, 0, 30).unwrap();
        crate::testing::finite_difference_check(&joints, |j| soft_footfalls(j)?.sum_all(), 1e-6, 1e-4).unwrap();
    }
}
