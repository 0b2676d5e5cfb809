//! The motion-check reward of eq. 14 (as a cost, lower is better), which keeps a mask from
//! passing an incoherent composition of the two noises to the final round:
//!
//! `R(G(z'), z') = λ1·L_jitter + λ2·L_foot_skate + λ3·L_decorr(z') + λ4·L_semantic`
//!
//! - `L_jitter`: the largest joint acceleration `max_{t,j} ‖a_tj‖`, m/frame² ("joint-based
//!   maximum jitter");
//! - `L_foot_skate`: horizontal foot speed (m/frame) where the foot is within 2.5 cm of the
//!   **rectified** ground (the lowest foot height of the motion, supp. B), averaged over frame
//!   pairs; the contact is a sigmoid of the height so the term is differentiable;
//! - `L_decorr`: DNO's noise decorrelation regulariser of `z'`;
//! - `L_semantic`: for "raise hands" (supp. A, as DNO), how far the higher wrist stays below its
//!   shoulder at the frame where it is highest, m (0 once a hand is above its shoulder).
//!
//! Every term is per sample `[B]` and differentiable (for the soft blend).

use candle_core::{Result, Tensor, D};
use rand::Rng;
use serde::{Deserialize, Serialize};

use crate::constraints::{second_difference, NORM_EPS};
use crate::dno::noise_regularize_1d;
use crate::skeleton::Joint;

/// Contact height above the rectified ground, m (supp. B: 0.025).
pub const CONTACT_HEIGHT_M: f64 = 0.025;
/// Width of the sigmoid contact edge, m.
const CONTACT_EDGE_M: f64 = 0.005;

/// The weights λ of eq. 14 (defaults 1, the paper's; 0 leaves a term out).
///
/// In JSON either the four weights (missing ones keep their defaults) or the name of a
/// preset: `"default"`, `"none"`, `"narrow_gap"`, `"low_barrier"`, `"steps_raising_hands"`
/// (the supplementary's per-task choices, [`RewardWeights::preset`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RewardWeights {
    /// λ1, maximum jitter.
    pub jitter: f64,
    /// λ2, rectified foot skate.
    pub foot_skate: f64,
    /// λ3, noise decorrelation.
    pub decorrelation: f64,
    /// λ4, "raise hands" (default 0: only tasks that ask for it).
    pub semantic: f64,
}

impl Default for RewardWeights {
    fn default() -> Self {
        Self { jitter: 1.0, foot_skate: 1.0, decorrelation: 1.0, semantic: 0.0 }
    }
}

impl RewardWeights {
    /// No reward term (Table 4's "w/o reward").
    pub const NONE: Self = Self { jitter: 0.0, foot_skate: 0.0, decorrelation: 0.0, semantic: 0.0 };
    /// Supp. A, Task-1 (narrow gap): `L_jitter + L_decorr + 10·L_foot_skate`.
    pub const NARROW_GAP: Self = Self { jitter: 1.0, foot_skate: 10.0, decorrelation: 1.0, semantic: 0.0 };
    /// Supp. A, Task-2 (low barrier): `L_jitter + L_decorr`.
    pub const LOW_BARRIER: Self = Self { jitter: 1.0, foot_skate: 0.0, decorrelation: 1.0, semantic: 0.0 };
    /// Supp. A, Task-3 (steps while raising hands): `L_foot_skate + 0.5·L_semantic`.
    pub const STEPS_RAISING_HANDS: Self = Self { jitter: 0.0, foot_skate: 1.0, decorrelation: 0.0, semantic: 0.5 };

    /// The weights named `name` (see the type's doc), or `None` for an unknown name.
    pub fn preset(name: &str) -> Option<Self> {
        Some(match name {
            "default" => Self::default(),
            "none" => Self::NONE,
            "narrow_gap" => Self::NARROW_GAP,
            "low_barrier" => Self::LOW_BARRIER,
            "steps_raising_hands" => Self::STEPS_RAISING_HANDS,
            _ => return None,
        })
    }
}

/// Reads the four weights (an object) or a preset's name (a string); an unknown name is an
/// error that lists the presets.
impl<'de> Deserialize<'de> for RewardWeights {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> std::result::Result<Self, D::Error> {
        struct WeightsOrPreset;
        impl<'de> serde::de::Visitor<'de> for WeightsOrPreset {
            type Value = RewardWeights;

            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("reward weights {jitter, foot_skate, decorrelation, semantic} or a preset name")
            }

            fn visit_str<E: serde::de::Error>(self, name: &str) -> std::result::Result<RewardWeights, E> {
                RewardWeights::preset(name).ok_or_else(|| {
                    E::custom(format!(
                        "unknown reward preset {name:?} (default, none, narrow_gap, low_barrier, steps_raising_hands)"
                    ))
                })
            }

            fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> std::result::Result<RewardWeights, A::Error> {
                let Weights { jitter, foot_skate, decorrelation, semantic } =
                    Weights::deserialize(serde::de::value::MapAccessDeserializer::new(map))?;
                Ok(RewardWeights { jitter, foot_skate, decorrelation, semantic })
            }
        }
        deserializer.deserialize_any(WeightsOrPreset)
    }
}

/// The four weights as written out, missing ones at their defaults.
#[derive(Deserialize)]
#[serde(default, deny_unknown_fields)]
struct Weights {
    jitter: f64,
    foot_skate: f64,
    decorrelation: f64,
    semantic: f64,
}

impl Default for Weights {
    fn default() -> Self {
        let RewardWeights { jitter, foot_skate, decorrelation, semantic } = RewardWeights::default();
        Self { jitter, foot_skate, decorrelation, semantic }
    }
}

/// The terms of one evaluation, per sample `[B]`.
#[derive(Debug, Clone)]
pub struct RewardTerms {
    /// `L_jitter`, m/frame².
    pub jitter: Tensor,
    /// `L_foot_skate`, m/frame.
    pub foot_skate: Tensor,
    /// `L_decorr`.
    pub decorrelation: Tensor,
    /// `L_semantic`, m.
    pub semantic: Tensor,
    /// `Σ λ_k·L_k`.
    pub total: Tensor,
}

/// Eq. 14 on joints `[B, T, 22, 3]` (m, y up; T ≥ 3) and the noise `z'` `[B, T, 263]`; `rng`
/// draws the decorrelation's padding noise.
pub fn reward<R: Rng + ?Sized>(
    joints: &Tensor,
    noise: &Tensor,
    weights: &RewardWeights,
    rng: &mut R,
) -> Result<RewardTerms> {
    let batch = joints.dim(0)?;
    let zeros = || Tensor::zeros(batch, joints.dtype(), joints.device());
    let jitter = if weights.jitter > 0.0 { max_jitter(joints)? } else { zeros()? };
    let foot_skate = if weights.foot_skate > 0.0 { rectified_foot_skate(joints)? } else { zeros()? };
    let decorrelation =
        if weights.decorrelation > 0.0 { noise_regularize_1d(noise, rng)?.to_dtype(joints.dtype())? } else { zeros()? };
    let semantic = if weights.semantic > 0.0 { hands_below_shoulders(joints)? } else { zeros()? };
    let total = ((((&jitter * weights.jitter)? + (&foot_skate * weights.foot_skate)?)?
        + (&decorrelation * weights.decorrelation)?)?
        + (&semantic * weights.semantic)?)?;
    Ok(RewardTerms { jitter, foot_skate, decorrelation, semantic, total })
}

/// `max_{t,j} ‖a_tj‖` of joints `[B, T, 22, 3]`, m/frame², `[B]`.
pub fn max_jitter(joints: &Tensor) -> Result<Tensor> {
    let batch = joints.dim(0)?;
    let a = second_difference(joints)?;
    (a.sqr()?.sum(D::Minus1)? + NORM_EPS)?.sqrt()?.reshape((batch, ()))?.max(D::Minus1)
}

/// Mean over frame pairs of `Σ_feet v_xz·σ((h_c − (y − y_ground))/w)`, m/frame, `[B]`, with
/// `y_ground` the lowest foot height of each motion and `h_c` = [`CONTACT_HEIGHT_M`].
pub fn rectified_foot_skate(joints: &Tensor) -> Result<Tensor> {
    let frames = joints.dim(1)?;
    let feet: Vec<u32> = [Joint::LeftAnkle, Joint::LeftFoot, Joint::RightAnkle, Joint::RightFoot]
        .iter()
        .map(|j| j.index() as u32)
        .collect();
    let index = Tensor::from_vec(feet, 4, joints.device())?;
    let feet = joints.contiguous()?.index_select(&index, 2)?; // [B, T, 4, 3]
    let height = feet.narrow(3, 1, 1)?.squeeze(3)?; // [B, T, 4]
    let ground = height.flatten_from(1)?.min_keepdim(1)?.unsqueeze(2)?; // [B, 1, 1]
    let above = height.broadcast_sub(&ground)?;
    let contact = candle_nn::ops::sigmoid(&((above * -1.0)? + CONTACT_HEIGHT_M)?.affine(1.0 / CONTACT_EDGE_M, 0.0)?)?;
    let step = (feet.narrow(1, 1, frames - 1)? - feet.narrow(1, 0, frames - 1)?)?;
    let horizontal = Tensor::cat(&[step.narrow(3, 0, 1)?, step.narrow(3, 2, 1)?], 3)?;
    let speed = (horizontal.sqr()?.sum(3)? + NORM_EPS)?.sqrt()?; // [B, T−1, 4]
    let both = contact.narrow(1, 0, frames - 1)?.mul(&contact.narrow(1, 1, frames - 1)?)?;
    (speed * both)?.sum(2)?.mean(1)
}

/// How far the higher wrist stays below its shoulder at its best frame, m (0 when a wrist
/// rises above its shoulder), `[B]`.
pub fn hands_below_shoulders(joints: &Tensor) -> Result<Tensor> {
    let y = |j: Joint| joints.narrow(2, j.index(), 1)?.squeeze(2)?.narrow(2, 1, 1)?.squeeze(2); // [B, T]
    let left = (y(Joint::LeftWrist)? - y(Joint::LeftShoulder)?)?;
    let right = (y(Joint::RightWrist)? - y(Joint::RightShoulder)?)?;
    let best = left.maximum(&right)?.max(1)?;
    (best * -1.0)?.relu()
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;
    use rand::SeedableRng;

    #[test]
    fn weights_parse_from_numbers_or_a_preset_name() {
        let parse = |json: &str| serde_json::from_str::<RewardWeights>(json);
        assert_eq!(parse(r#""steps_raising_hands""#).ok(), Some(RewardWeights::STEPS_RAISING_HANDS));
        assert_eq!(parse(r#""narrow_gap""#).ok(), Some(RewardWeights::NARROW_GAP));
        let partial = parse(r#"{"semantic": 0.5}"#).ok();
        assert_eq!(partial, Some(RewardWeights { semantic: 0.5, ..RewardWeights::default() }));
        let typo = parse(r#""narrow-gap""#).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(typo.contains("unknown reward preset \"narrow-gap\"") && typo.contains("narrow_gap"), "{typo}");
        assert!(parse(r#"{"jiter": 1.0}"#).is_err());
        // Written out as the four weights, which read back the same.
        let written = serde_json::to_string(&RewardWeights::LOW_BARRIER).unwrap_or_default();
        assert_eq!(parse(&written).ok(), Some(RewardWeights::LOW_BARRIER));
    }

    fn standing(frames: usize) -> Tensor {
        // A still figure: joint j at (0.1·j, 0.05·j, 0), the feet within 1.3 cm of the floor,
        // the left toe lowest (a unique lowest point keeps the ground's min differentiable).
        let mut data = Vec::new();
        for t in 0..frames {
            for j in 0..22 {
                let y = match j {
                    10 => 0.0001 * t as f64,
                    7 | 8 | 11 => 0.004 * (j % 4 + 1) as f64 + 0.0001 * t as f64,
                    _ => 0.05 * j as f64,
                };
                data.extend([0.1 * j as f64, y, 0.0]);
            }
        }
        Tensor::from_vec(data, (1, frames, 22, 3), &Device::Cpu).unwrap()
    }

    #[test]
    fn a_still_figure_costs_nothing_and_a_sliding_foot_costs_its_speed() {
        let joints = standing(10);
        assert!(max_jitter(&joints).unwrap().to_vec1::<f64>().unwrap()[0] < 1e-5);
        assert!(rectified_foot_skate(&joints).unwrap().to_vec1::<f64>().unwrap()[0] < 1e-5);
        // The left foot slides 2 cm per frame along x on the floor.
        let mut data = joints.flatten_all().unwrap().to_vec1::<f64>().unwrap();
        for t in 0..10 {
            data[t * 66 + Joint::LeftFoot.index() * 3] += 0.02 * t as f64;
        }
        let sliding = Tensor::from_vec(data, (1, 10, 22, 3), &Device::Cpu).unwrap();
        let skate = rectified_foot_skate(&sliding).unwrap().to_vec1::<f64>().unwrap()[0];
        // One foot joint of four, fully in contact (σ(5) ≈ 0.993 squared).
        assert!((skate - 0.02 * 0.9866).abs() < 5e-4, "{skate}");
        crate::testing::finite_difference_check(&sliding, |j| rectified_foot_skate(j)?.sum_all(), 1e-6, 1e-4).unwrap();
    }

    #[test]
    fn hands_below_the_shoulders_cost_their_distance_at_the_best_frame() {
        // Wrists lowered to 0.5 + 0.001·t m: the left one (shoulder at 0.8 m) comes closest, at
        // the last frame, 0.291 m below.
        let mut data = standing(10).flatten_all().unwrap().to_vec1::<f64>().unwrap();
        for t in 0..10 {
            for j in [Joint::LeftWrist, Joint::RightWrist] {
                data[t * 66 + j.index() * 3 + 1] = 0.5 + 0.001 * t as f64;
            }
        }
        let low = Tensor::from_vec(data, (1, 10, 22, 3), &Device::Cpu).unwrap();
        let cost = hands_below_shoulders(&low).unwrap().to_vec1::<f64>().unwrap()[0];
        assert!((cost - 0.291).abs() < 1e-9, "{cost}");
        crate::testing::finite_difference_check(&low, |j| hands_below_shoulders(j)?.sum_all(), 1e-6, 1e-4).unwrap();
        assert_eq!(hands_below_shoulders(&standing(10)).unwrap().to_vec1::<f64>().unwrap()[0], 0.0);
    }

    #[test]
    fn the_reward_weights_its_terms() {
        let joints = standing(8);
        let noise = Tensor::randn(0f64, 1.0, (1, 8, 263), &Device::Cpu).unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(0);
        let w = RewardWeights { jitter: 0.0, foot_skate: 0.0, decorrelation: 2.0, semantic: 1.0 };
        let terms = reward(&joints, &noise, &w, &mut rng).unwrap();
        let v = |t: &Tensor| t.to_vec1::<f64>().unwrap()[0];
        assert!((v(&terms.total) - (2.0 * v(&terms.decorrelation) + v(&terms.semantic))).abs() < 1e-12);
        // Wrists (0.1, 0.05·20…) sit above the shoulders (0.05·16…): no semantic cost.
        assert_eq!(v(&terms.semantic), 0.0);
    }
}
