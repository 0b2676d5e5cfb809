//! The criterion every noise-optimising method minimises (DNO, RG-DNO's stages): the compiled
//! program's `Σ wᵢ·Eᵢ` on the joints recovered from the features, plus four guards that no
//! task's constraint asks for and every person obeys: no one-frame glitches, no flight longer
//! than a jump can last, a centre of mass that falls freely in flight, and no joint under the
//! floor.

use candle_core::{Tensor, D};
use serde::{Deserialize, Serialize};

use crate::constraints::{centre_of_mass_weights, second_difference, CompiledProgram, NORM_EPS};
use crate::metrics::{AIRBORNE_M, FLOATING_FLIGHT_S};
use crate::prior::Prior;
use crate::skeleton::FPS;

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

/// The longest flight the flight guard allows, frames: [`FLOATING_FLIGHT_S`] (0.7 s, an
/// athlete's standing jump) at 20 fps, 14 frames, rounded to the nearest frame (a truncated
/// product a hair under 14 would give 13). A longer flight is what the metrics call floating.
pub const FLIGHT_LIMIT_FRAMES: usize = (FLOATING_FLIGHT_S * FPS + 0.5) as usize;

/// The flight guard `Σ_W relu(min_{t∈W} y_t − AIRBORNE_M)` per sample `[B]` of joints
/// `[B, T, 22, 3]` (m, y up, floor at 0), over every window W of `limit + 1` consecutive
/// frames, with `y_t` the lowest joint's height at frame t and [`AIRBORNE_M`] = 0.10 m: in every
/// such window some joint must come within 0.10 m of the floor, so no flight (every joint
/// above 0.10 m, [`crate::metrics::longest_flight_s`]) lasts more than `limit` frames. Its
/// gradient pulls the lowest joint of the window's lowest frame down. The hinge is not squared,
/// so the pull stays whole up to the bound: an exact penalty, which a weight above the bound's
/// Lagrange multiplier meets exactly, where a squared hinge leaves the flight a frame too long
/// (0.75 s in every RG-DNO sample of Table 6's foot to 1.8 m, `fixtures/results/README.md`). 0 for
/// `T ≤ limit`.
pub fn flight_penalty(joints: &Tensor, limit: usize) -> candle_core::Result<Tensor> {
    let (batch, frames, _, _) = joints.dims4()?;
    let window = limit + 1;
    if frames < window {
        return Tensor::zeros(batch, joints.dtype(), joints.device());
    }
    let lowest = joint_heights(joints)?.min(D::Minus1)?; // [B, T]
    let count = frames - window + 1;
    let mut window_lowest = lowest.narrow(1, 0, count)?;
    for k in 1..window {
        window_lowest = window_lowest.minimum(&lowest.narrow(1, k, count)?)?;
    }
    (window_lowest - AIRBORNE_M)?.relu()?.sum(D::Minus1)
}

/// The joints' heights `[B, T, 22]` (m, y) of joints `[B, T, 22, 3]`.
fn joint_heights(joints: &Tensor) -> candle_core::Result<Tensor> {
    joints.narrow(D::Minus1, 1, 1)?.squeeze(D::Minus1)
}

/// The floor guard `Σ_{t,j} relu(−y_tj)` per sample `[B]` of joints `[B, T, 22, 3]` (m, y up,
/// floor at 0): how far every joint of every frame lies under the floor, summed. The network's
/// own samples dip 3–9 cm under it (`fixtures/model/report.md`) and the foot clean-up lifts them
/// out afterwards; without the guard the optimiser may meet a one-sided bound such as "feet
/// below 5 cm on the last frame" with a foot 9 cm under the floor, which the clean-up's lift
/// then undoes (two of four RG-DNO samples of Table 6's foot to 1.8 m without the guard,
/// `fixtures/results/README.md`). Like the flight guard an L1 hinge, an exact penalty.
pub fn floor_penalty(joints: &Tensor) -> candle_core::Result<Tensor> {
    let batch = joints.dim(0)?;
    joint_heights(joints)?.neg()?.relu()?.reshape((batch, ()))?.sum(D::Minus1)
}

/// Gravity, m/s².
pub const GRAVITY_M_PER_S2: f64 = 9.81;

/// The ballistic guard `Σ_t m_t·(a_t + g)²` per sample `[B]` of joints `[B, T, 22, 3]` (m, y
/// up, floor at 0): `a_t` the centre of mass's vertical acceleration (second difference,
/// m/frame², [`centre_of_mass_weights`]), `g` = [`GRAVITY_M_PER_S2`]/20² = 0.0245 m/frame², and
/// `m_t` = 1 where the three frames of the difference are all in flight (every joint above
/// [`AIRBORNE_M`], read off the motion without a gradient). In flight nothing but gravity acts
/// on the centre of mass, so its path is a parabola: a 0.7 s flight rises at most g·t²/8 =
/// 0.6 m. 0 for fewer than 3 frames.
pub fn ballistic_penalty(joints: &Tensor) -> candle_core::Result<Tensor> {
    let (batch, frames, joint_count, _) = joints.dims4()?;
    if frames < 3 {
        return Tensor::zeros(batch, joints.dtype(), joints.device());
    }
    let heights = joint_heights(joints)?;
    let weights = Tensor::new(&centre_of_mass_weights(false), joints.device())?.to_dtype(joints.dtype())?.reshape((
        1,
        1,
        joint_count,
    ))?;
    let com = heights.broadcast_mul(&weights)?.sum(D::Minus1)?; // [B, T]
    let a = second_difference(&com)?; // [B, T − 2]
    let airborne = heights.min(D::Minus1)?.gt(AIRBORNE_M)?.to_dtype(joints.dtype())?;
    let n = frames - 2;
    let in_flight = ((airborne.narrow(1, 0, n)? * airborne.narrow(1, 1, n)?)? * airborne.narrow(1, 2, n)?)?;
    let g = GRAVITY_M_PER_S2 / (FPS * FPS);
    ((a + g)?.sqr()? * in_flight)?.sum(D::Minus1)
}

/// The weights of the guards added to every program's criterion. Ours, not DNO's or
/// ProgMoGen's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Guards {
    /// λ of the jitter guard `λ·`[`jitter_penalty`] at [`JITTER_LIMIT`]: without it, DNO through
    /// our small prior meets keyframe constraints with one-frame glitches (max acceleration
    /// 5–12× the unconstrained samples' on HSI-2/3). 0 switches it off.
    pub jitter: f64,
    /// λ of the flight guard `λ·`[`flight_penalty`] at [`FLIGHT_LIMIT_FRAMES`]: without it, DNO
    /// raises a foot to 1.8 m or clears a 0.6 m hurdle with leaps that hang 1.4–1.55 s in the
    /// air (Table 6 without the guards, `fixtures/results/README.md`). 0 switches it off.
    pub flight: f64,
    /// λ of the ballistic guard `λ·`[`ballistic_penalty`]: with the flight guard alone, DNO
    /// clears a 0.6 m hurdle with the pelvis rising 0.9 m in 0.7 s (falling at up to 4 g). 0
    /// switches it off.
    pub ballistic: f64,
    /// λ of the floor guard `λ·`[`floor_penalty`]: without it, RG-DNO meets "feet on the ground
    /// on the last frame" with one foot 9 cm under the floor, and the clean-up's lift leaves the
    /// other 14 cm up (two of four foot-to-1.8 m samples of Table 6). Default 0.1: on Table 6 it
    /// holds every network motion within 3 mm of the floor, as 1 does, and at 1 the hurdle loses
    /// a sample in each method to leaps that land on the hurdle (`fixtures/results/README.md`).
    /// 0 switches it off. Settings written before it existed read as 0 (no floor guard ran).
    #[serde(default)]
    pub floor: f64,
}

impl Guards {
    /// The jitter, flight and ballistic guards at weight 1, the floor guard at 0.1.
    pub const DEFAULT: Self = Self { jitter: 1.0, flight: 1.0, ballistic: 1.0, floor: 0.1 };
    /// No guard: the program's error alone.
    pub const NONE: Self = Self { jitter: 0.0, flight: 0.0, ballistic: 0.0, floor: 0.0 };

    /// The weighted guards per sample `[B]` of joints `[B, T, 22, 3]`; `None` when all are off.
    pub fn penalty(&self, joints: &Tensor) -> candle_core::Result<Option<Tensor>> {
        let mut terms = Vec::new();
        if self.jitter > 0.0 {
            terms.push((jitter_penalty(joints, JITTER_LIMIT)? * self.jitter)?);
        }
        if self.flight > 0.0 {
            terms.push((flight_penalty(joints, FLIGHT_LIMIT_FRAMES)? * self.flight)?);
        }
        if self.ballistic > 0.0 {
            terms.push((ballistic_penalty(joints)? * self.ballistic)?);
        }
        if self.floor > 0.0 {
            terms.push((floor_penalty(joints)? * self.floor)?);
        }
        let mut terms = terms.into_iter();
        let Some(first) = terms.next() else { return Ok(None) };
        terms.try_fold(first, |sum, term| sum + term).map(Some)
    }

    /// Whether every weight is finite and ≥ 0; the error names the first that is not.
    pub fn check(&self) -> Result<(), String> {
        for (name, weight) in
            [("jitter", self.jitter), ("flight", self.flight), ("ballistic", self.ballistic), ("floor", self.floor)]
        {
            if !(weight.is_finite() && weight >= 0.0) {
                return Err(format!("the {name} guard's weight must be finite and ≥ 0, got {weight}"));
            }
        }
        Ok(())
    }
}

impl Default for Guards {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The criterion every noise-optimising method minimises: per sample `[B]`, the program's
/// `Σ wᵢ·Eᵢ` on the joints of normalised features `x` `[B, T, 263]`, plus the [`Guards`].
/// `initial` `[B or 1, T, 22, 3]` is what `stay_near_initial` terms compare with.
pub fn program_objective<'a>(
    prior: &'a Prior,
    compiled: &'a CompiledProgram,
    initial: &'a Tensor,
    guards: Guards,
) -> impl Fn(&Tensor) -> candle_core::Result<Tensor> + 'a {
    let on_joints = joints_objective(compiled, initial, guards);
    move |x: &Tensor| on_joints(&prior.to_joints(x)?)
}

/// [`program_objective`] on joints `[B, T, 22, 3]` (m) instead of features.
pub fn joints_objective<'a>(
    compiled: &'a CompiledProgram,
    initial: &'a Tensor,
    guards: Guards,
) -> impl Fn(&Tensor) -> candle_core::Result<Tensor> + 'a {
    move |joints: &Tensor| {
        let error = compiled.evaluate(joints, Some(initial)).map_err(candle_core::Error::wrap)?.total;
        match guards.penalty(joints)? {
            Some(penalty) => error + penalty,
            None => Ok(error),
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

    /// Joints `[1, T, 22, 3]` standing on the floor (every joint at `height(t)` + its index × 1 cm).
    fn body_at(heights: &[f64]) -> Tensor {
        let data = heights
            .iter()
            .flat_map(|&h| (0..22).flat_map(move |j| [0.0, h + 0.01 * j as f64, 0.0]))
            .collect::<Vec<_>>();
        Tensor::from_vec(data, (1, heights.len(), 22, 3), &Device::Cpu).unwrap()
    }

    #[test]
    fn flight_penalty_lets_a_jump_land_and_pulls_a_hang_down() {
        // A 0.5 s jump (10 frames up to 0.4 m) in 40 frames: every 15-frame window touches down.
        let mut jump = vec![0.0; 40];
        for (k, h) in jump[15..25].iter_mut().enumerate() {
            *h = 0.4 * (1.0 - ((k as f64 - 4.5) / 5.5).powi(2)) + 0.11;
        }
        let penalty =
            |h: &[f64]| flight_penalty(&body_at(h), FLIGHT_LIMIT_FRAMES).unwrap().to_vec1::<f64>().unwrap()[0];
        assert_eq!(penalty(&jump), 0.0);
        // The same body hanging 0.5 m up for 20 frames (1 s): the windows starting at 10..=15 lie
        // wholly in the air (six of the 26), each short of the floor by 0.5 − 0.10 m.
        let mut hang = vec![0.0; 40];
        hang[10..30].iter_mut().for_each(|h| *h = 0.5);
        let expected = 6.0 * 0.4;
        assert!((penalty(&hang) - expected).abs() < 1e-9, "{} vs {expected}", penalty(&hang));
        // Too short a motion to hold a window: nothing to guard.
        assert_eq!(penalty(&hang[..FLIGHT_LIMIT_FRAMES]), 0.0);
        // A rising hang (no two frames at one height, so each window's minimum is one joint).
        let rising: Vec<f64> =
            (0..40).map(|t| if (10..30).contains(&t) { 0.4 + 0.01 * t as f64 } else { 0.0 }).collect();
        assert!(penalty(&rising) > 0.0);
        crate::testing::finite_difference_check(
            &body_at(&rising),
            |j| flight_penalty(j, FLIGHT_LIMIT_FRAMES)?.sum_all(),
            1e-6,
            1e-5,
        )
        .unwrap();
    }

    #[test]
    fn guards_add_their_weighted_penalties_and_none_is_nothing() {
        let mut hang = vec![0.0; 40];
        hang[10..30].iter_mut().for_each(|h| *h = 0.5);
        let joints = body_at(&hang);
        let flight = flight_penalty(&joints, FLIGHT_LIMIT_FRAMES).unwrap().to_vec1::<f64>().unwrap()[0];
        let jitter = jitter_penalty(&joints, JITTER_LIMIT).unwrap().to_vec1::<f64>().unwrap()[0];
        let ballistic = ballistic_penalty(&joints).unwrap().to_vec1::<f64>().unwrap()[0];
        let floor = floor_penalty(&joints).unwrap().to_vec1::<f64>().unwrap()[0];
        let all = Guards { jitter: 2.0, flight: 3.0, ballistic: 5.0, floor: 7.0 }.penalty(&joints).unwrap().unwrap();
        let expected = 2.0 * jitter + 3.0 * flight + 5.0 * ballistic + 7.0 * floor;
        assert!((all.to_vec1::<f64>().unwrap()[0] - expected).abs() < 1e-9);
        assert!(Guards::NONE.penalty(&joints).unwrap().is_none());
        assert!(Guards { jitter: f64::NAN, ..Guards::DEFAULT }.check().unwrap_err().contains("jitter"));
    }

    #[test]
    fn ballistic_penalty_is_zero_on_a_parabola_and_counts_a_hover() {
        let g = GRAVITY_M_PER_S2 / (FPS * FPS);
        let penalty = |h: &[f64]| ballistic_penalty(&body_at(h)).unwrap().to_vec1::<f64>().unwrap()[0];
        // A 0.65 s leap: the body leaves at 0.2 m up at 3 m/s and falls under gravity alone.
        let mut leap = vec![0.0; 40];
        for (k, h) in leap[10..23].iter_mut().enumerate() {
            *h = 0.2 + 3.0 * k as f64 / FPS - 0.5 * GRAVITY_M_PER_S2 * (k as f64 / FPS).powi(2);
        }
        assert!(leap[10..23].iter().all(|&h| h > AIRBORNE_M), "{leap:?}");
        assert!(penalty(&leap) < 1e-20, "{}", penalty(&leap));
        // Hanging 0.5 m up for 20 frames: 18 second differences in the air, each g short.
        let mut hang = vec![0.0; 40];
        hang[10..30].iter_mut().for_each(|h| *h = 0.5);
        assert!((penalty(&hang) - 18.0 * g * g).abs() < 1e-12, "{} vs {}", penalty(&hang), 18.0 * g * g);
        assert_eq!(penalty(&hang[..2]), 0.0);
        let rising: Vec<f64> =
            (0..40).map(|t| if (10..30).contains(&t) { 0.4 + 0.01 * t as f64 } else { 0.0 }).collect();
        crate::testing::finite_difference_check(&body_at(&rising), |j| ballistic_penalty(j)?.sum_all(), 1e-6, 1e-5)
            .unwrap();
    }

    #[test]
    fn floor_penalty_sums_the_depth_under_the_floor_and_pulls_joints_up() {
        // Standing joints (0, 1, ..., 21 cm up) on frames 0 and 2; on frame 1 the body is 5 cm
        // lower, so joints 0..=4 lie 5, 4, 3, 2 and 1 cm under the floor (joint 5 exactly on it).
        let joints = body_at(&[0.0, -0.05, 0.0]);
        let got = floor_penalty(&joints).unwrap().to_vec1::<f64>().unwrap()[0];
        assert!((got - 0.15).abs() < 1e-12, "{got}");
        assert_eq!(floor_penalty(&body_at(&[0.0, 0.3])).unwrap().to_vec1::<f64>().unwrap(), vec![0.0]);
        // Away from the kink at 0 (no joint exactly on the floor): −1 per metre for the six sunk
        // joints' heights, 0 for the others.
        let sunk = body_at(&[0.005, -0.055, 0.005]);
        crate::testing::finite_difference_check(&sunk, |j| floor_penalty(j)?.sum_all(), 1e-6, 1e-5).unwrap();
    }
}
