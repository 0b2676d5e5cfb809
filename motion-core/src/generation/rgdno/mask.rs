//! The masks of RG-DNO's masked noise optimisation (§4.4–4.5, eqs. 10 and 13; supp. A "Soft
//! Mask Blending"): `z' = M ⊙ z1 + (1 − M) ⊙ z2`, `M ∈ [0, 1]^{T×263}`, where 1 takes the
//! random-noise branch `z1` and 0 the retrieved-noise branch `z2`.
//!
//! Binary candidates vary along one axis only (the supplementary avoids spatio-temporal masks):
//! - **temporal**: the frames split into `N_T` segments, segment `i` covering frames
//!   `⌈T/N_T·i⌉ .. ⌈T/N_T·(i+1)⌉`, each wholly 0 or 1 (`2^{N_T}` candidates);
//! - **spatial**: the 263 features split into the 8 [`BodyPart`]s, each wholly 0 or 1 (`2^8`).
//!
//! Bit `i` of a candidate's `bits` is the value of segment or part `i`.

use candle_core::{Device, Result, Tensor};
use serde::{Deserialize, Serialize};

use crate::representation::{FEATURE_DIM, FOOT_CONTACT, LOCAL_VEL, RIC, ROOT_Y, ROT};
use crate::skeleton::{Joint, NUM_JOINTS};

/// The paper's spatial parts of the pose features (§4.5: "root trajectory, left/right arm and
/// hand, left/right leg, head, and two spine segments", `N_S = 8`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BodyPart {
    /// Root rotation and linear velocity, root height, the pelvis's local velocity.
    RootTrajectory,
    /// Left collar, shoulder, elbow and wrist.
    LeftArm,
    /// Right collar, shoulder, elbow and wrist.
    RightArm,
    /// Left hip, knee, ankle and foot, and the left foot contacts.
    LeftLeg,
    /// Right hip, knee, ankle and foot, and the right foot contacts.
    RightLeg,
    /// Neck and head.
    Head,
    /// Spine1 and spine2.
    LowerSpine,
    /// Spine3.
    UpperSpine,
}

impl BodyPart {
    /// Every part, in bit order.
    pub const ALL: [BodyPart; 8] = [
        BodyPart::RootTrajectory,
        BodyPart::LeftArm,
        BodyPart::RightArm,
        BodyPart::LeftLeg,
        BodyPart::RightLeg,
        BodyPart::Head,
        BodyPart::LowerSpine,
        BodyPart::UpperSpine,
    ];

    /// The part a joint belongs to.
    pub fn of_joint(joint: Joint) -> BodyPart {
        use Joint::*;
        match joint {
            Pelvis => BodyPart::RootTrajectory,
            LeftCollar | LeftShoulder | LeftElbow | LeftWrist => BodyPart::LeftArm,
            RightCollar | RightShoulder | RightElbow | RightWrist => BodyPart::RightArm,
            LeftHip | LeftKnee | LeftAnkle | LeftFoot => BodyPart::LeftLeg,
            RightHip | RightKnee | RightAnkle | RightFoot => BodyPart::RightLeg,
            Neck | Head => BodyPart::Head,
            Spine1 | Spine2 => BodyPart::LowerSpine,
            Spine3 => BodyPart::UpperSpine,
        }
    }

    /// The part each of the 263 features belongs to: root channels to the root trajectory,
    /// a joint's position, rotation and velocity channels to its joint's part, the two left
    /// (right) foot contacts to the left (right) leg.
    pub fn of_feature(feature: usize) -> Option<BodyPart> {
        let joint = |j: usize| Some(BodyPart::of_joint(Joint::ALL[j]));
        match feature {
            f if f <= ROOT_Y => Some(BodyPart::RootTrajectory),
            f if RIC.contains(&f) => joint(1 + (f - RIC.start) / 3),
            f if ROT.contains(&f) => joint(1 + (f - ROT.start) / 6),
            f if LOCAL_VEL.contains(&f) => joint((f - LOCAL_VEL.start) / 3),
            f if FOOT_CONTACT.contains(&f) => {
                Some(if f - FOOT_CONTACT.start < 2 { BodyPart::LeftLeg } else { BodyPart::RightLeg })
            }
            _ => None,
        }
    }

    /// Bit index of the part in a spatial candidate.
    pub fn bit(self) -> usize {
        BodyPart::ALL.iter().position(|p| *p == self).unwrap_or(0)
    }
}

const _: () = assert!(NUM_JOINTS == 22 && FEATURE_DIM == 263);

/// Which axis a mask candidate varies along.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskKind {
    /// Segments of frames.
    Temporal,
    /// Body parts of the features.
    Spatial,
}

/// A binary mask candidate: `bits` bit `i` is segment or part `i` (1: random branch `z1`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MaskCandidate {
    /// The axis.
    pub kind: MaskKind,
    /// The values of the segments or parts.
    pub bits: u32,
    /// `N_T` for a temporal mask, 8 for a spatial one.
    pub segments: usize,
}

impl MaskCandidate {
    /// Every temporal candidate with `segments` segments, then every spatial one, without the
    /// spatial repeats of the all-0 and all-1 masks: `2^{N_T} + 2^8 − 2` candidates.
    pub fn all(segments: usize) -> Vec<MaskCandidate> {
        let temporal = (0..1u32 << segments).map(|bits| MaskCandidate { kind: MaskKind::Temporal, bits, segments });
        let full = (1u32 << BodyPart::ALL.len()) - 1;
        let spatial = (1..full).map(|bits| MaskCandidate { kind: MaskKind::Spatial, bits, segments: 8 });
        temporal.chain(spatial).collect()
    }

    /// The first frame of temporal segment `i` of `frames` (`⌈frames/N_T·i⌉`).
    pub fn segment_start(frames: usize, segments: usize, i: usize) -> usize {
        (frames * i).div_ceil(segments)
    }

    /// Per-frame values `[frames]` of a temporal mask, or per-feature values `[263]` of a
    /// spatial one.
    pub fn values(&self, frames: usize) -> Vec<f32> {
        let bit = |i: usize| ((self.bits >> i) & 1) as f32;
        match self.kind {
            MaskKind::Temporal => (0..frames)
                .map(|t| {
                    let i = (0..self.segments)
                        .rev()
                        .find(|&i| Self::segment_start(frames, self.segments, i) <= t)
                        .unwrap_or(0);
                    bit(i)
                })
                .collect(),
            MaskKind::Spatial => {
                (0..FEATURE_DIM).map(|f| BodyPart::of_feature(f).map_or(0.0, |p| bit(p.bit()))).collect()
            }
        }
    }

    /// The mask as a tensor broadcastable to `[B, frames, 263]`: `[1, frames, 1]` (temporal) or
    /// `[1, 1, 263]` (spatial).
    pub fn tensor(&self, frames: usize, device: &Device) -> Result<Tensor> {
        let values = self.values(frames);
        match self.kind {
            MaskKind::Temporal => Tensor::from_vec(values, (1, frames, 1), device),
            MaskKind::Spatial => Tensor::from_vec(values, (1, 1, FEATURE_DIM), device),
        }
    }
}

/// Eq. 10: `M ⊙ z1 + (1 − M) ⊙ z2` for a mask broadcastable to `z1`'s shape.
pub fn blend(mask: &Tensor, z1: &Tensor, z2: &Tensor) -> Result<Tensor> {
    let mask = mask.to_dtype(z1.dtype())?;
    z2.broadcast_add(&(z1 - z2)?.broadcast_mul(&mask)?)
}

/// Logit of the soft mask that starts the sigmoid blend from a binary one: `±SHARPNESS`.
pub const SOFT_MASK_LOGIT: f64 = 3.0;

/// The logits `M'` with `σ(M') ≈ M` for a binary mask tensor: `(2M − 1)·SOFT_MASK_LOGIT`.
pub fn soft_logits(mask: &Tensor) -> Result<Tensor> {
    mask.affine(2.0 * SOFT_MASK_LOGIT, -SOFT_MASK_LOGIT)
}

/// Eq. 10 with the soft mask `σ(M')` (supp. A): differentiable in `logits`, `z1` and `z2`.
pub fn soft_blend(logits: &Tensor, z1: &Tensor, z2: &Tensor) -> Result<Tensor> {
    blend(&candle_nn::ops::sigmoid(logits)?, z1, z2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_spatial_parts_partition_all_263_features() {
        let mut count = [0usize; 8];
        for f in 0..FEATURE_DIM {
            let part = BodyPart::of_feature(f).unwrap_or_else(|| panic!("feature {f} has no part"));
            count[part.bit()] += 1;
        }
        assert_eq!(count.iter().sum::<usize>(), FEATURE_DIM);
        assert!(count.iter().all(|&c| c > 0), "every part holds features: {count:?}");
        assert_eq!(BodyPart::of_feature(FEATURE_DIM), None);
        // Root: 4 root channels + the pelvis velocity; an arm: 4 joints × (3 + 6 + 3).
        assert_eq!(count[BodyPart::RootTrajectory.bit()], 4 + 3);
        assert_eq!(count[BodyPart::LeftArm.bit()], 4 * 12);
        assert_eq!(count[BodyPart::LeftLeg.bit()], 4 * 12 + 2);
        // The elbow's rotation channels belong to the arm.
        assert_eq!(BodyPart::of_feature(ROT.start + 6 * (Joint::LeftElbow.index() - 1)), Some(BodyPart::LeftArm));
    }

    #[test]
    fn the_temporal_masks_split_frames_as_the_papers_formula() {
        // T = 100, N_T = 8: segments start at ⌈12.5·i⌉ = 0, 13, 25, 38, 50, 63, 75, 88.
        let starts: Vec<usize> = (0..8).map(|i| MaskCandidate::segment_start(100, 8, i)).collect();
        assert_eq!(starts, vec![0, 13, 25, 38, 50, 63, 75, 88]);
        let only_third = MaskCandidate { kind: MaskKind::Temporal, bits: 1 << 3, segments: 8 };
        let values = only_third.values(100);
        let ones: Vec<usize> = (0..100).filter(|&t| values[t] == 1.0).collect();
        assert_eq!(ones, (38..50).collect::<Vec<_>>());
        let all = MaskCandidate::all(8);
        assert_eq!(all.len(), 256 + 254);
    }

    #[test]
    fn blending_takes_z1_where_the_mask_is_one() {
        let dev = Device::Cpu;
        let z1 = Tensor::ones((1, 4, FEATURE_DIM), candle_core::DType::F32, &dev).unwrap();
        let z2 = Tensor::zeros((1, 4, FEATURE_DIM), candle_core::DType::F32, &dev).unwrap();
        let mask = MaskCandidate { kind: MaskKind::Temporal, bits: 0b10, segments: 2 }.tensor(4, &dev).unwrap();
        let z = blend(&mask, &z1, &z2).unwrap().mean((0, 2)).unwrap().to_vec1::<f32>().unwrap();
        assert_eq!(z, vec![0.0, 0.0, 1.0, 1.0]);
    }

    #[test]
    fn the_soft_blend_has_the_gradient_of_its_formula() {
        let dev = Device::Cpu;
        let z1 = Tensor::randn(0f64, 1.0, (1, 5, FEATURE_DIM), &dev).unwrap();
        let z2 = Tensor::randn(0f64, 1.0, (1, 5, FEATURE_DIM), &dev).unwrap();
        let logits = Tensor::randn(0f64, 1.0, (1, 5, 1), &dev).unwrap();
        crate::testing::finite_difference_check(&logits, |l| soft_blend(l, &z1, &z2)?.sqr()?.sum_all(), 1e-6, 1e-5)
            .unwrap();
        let binary = MaskCandidate { kind: MaskKind::Temporal, bits: 0b01, segments: 2 }.tensor(5, &dev).unwrap();
        let soft = candle_nn::ops::sigmoid(&soft_logits(&binary).unwrap()).unwrap().to_vec3::<f32>().unwrap();
        assert!(soft[0][0][0] > 0.95 && soft[0][4][0] < 0.05);
    }
}
