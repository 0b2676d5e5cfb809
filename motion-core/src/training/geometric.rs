//! Geometric training losses on the joints recovered from the predicted clean motion, MDM's
//! `vel` and `fc` terms in our units.
//!
//! The x0 MSE alone treats the 263 features as independent numbers, but foot skating comes
//! from their *disagreement*: a small error in the root velocity (features 1–2) against the
//! root-relative joints (`ric`) slides a planted foot over the floor. Both terms below look at
//! world-frame joint positions recovered from x̂0 and x0 with the differentiable
//! [`recover_from_ric`], so they tie the root velocity to the limbs:
//!
//! - **velocity**: mean over batch, frames, joints and axes of w·(v̂ − v)², where v is the joint
//!   velocity in m/s ([`velocity`]: frame difference × fps);
//! - **foot contact**: Σ w·‖v̂‖² / Σ 1 (m²/s²) over the (frame, foot joint) pairs whose *training*
//!   foot joint moves slower than [`CONTACT_SPEED_M_PER_S`]: a foot that is planted in the data
//!   must be planted in the prediction. The feet are HumanML3D's ankles and toes.
//!
//! w is a per-sample weight; the trainer passes ᾱ_t, the signal fraction of the noisy input.
//! At high noise the best x̂0 is a blur over many motions, and asking it for planted feet and
//! exact velocities there pulls the prediction towards standing still (unweighted, a fine-tune
//! of the shipped prior collapsed its walks into standing within 300 steps).

use candle_core::{DType, Result, Tensor, D};

use crate::constraints::velocity;
use crate::representation::{recover_from_ric, MeanStd};
use crate::skeleton::CONTACT_JOINTS;

/// A training foot joint slower than this is planted (m/s; MDM's 0.01 m/frame at 20 fps).
pub const CONTACT_SPEED_M_PER_S: f64 = 0.2;

/// The two geometric terms of one batch, scalar tensors (with their graphs).
#[derive(Debug, Clone)]
pub struct GeometricTerms {
    /// Joint velocity MSE, (m/s)².
    pub velocity: Tensor,
    /// Mean squared speed of predicted feet where the data's feet are planted, (m/s)².
    pub foot_contact: Tensor,
}

/// Computes [`GeometricTerms`] from normalised features.
#[derive(Debug, Clone)]
pub struct GeometricLoss {
    mean_std: MeanStd,
    /// Indices of the foot joints, `[4]` u32.
    feet: Tensor,
}

impl GeometricLoss {
    /// `mean_std` de-normalises the model's features (on the training device).
    pub fn new(mean_std: MeanStd) -> Result<Self> {
        let feet: Vec<u32> = CONTACT_JOINTS.iter().map(|j| j.index() as u32).collect();
        let feet = Tensor::from_vec(feet, CONTACT_JOINTS.len(), mean_std.mean().device())?;
        Ok(Self { mean_std, feet })
    }

    /// Both terms for a prediction `x0_hat` against its target `x0`, normalised
    /// `[batch, frames ≥ 2, 263]` each, with per-sample weights `weights` `[batch]`. Gradients
    /// flow to `x0_hat` only.
    pub fn terms(&self, x0_hat: &Tensor, x0: &Tensor, weights: &Tensor) -> Result<GeometricTerms> {
        let predicted = self.velocities(x0_hat)?; // [B, T−1, 22, 3]
        let target = self.velocities(&x0.detach())?.detach();
        let batch = predicted.dim(0)?;
        let w = weights.to_dtype(predicted.dtype())?.reshape((batch, 1, 1, 1))?;
        let velocity = (&predicted - &target)?.sqr()?.broadcast_mul(&w)?.mean_all()?;

        let feet_predicted = predicted.index_select(&self.feet, 2)?; // [B, T−1, 4, 3]
        let feet_target = target.index_select(&self.feet, 2)?;
        let planted = feet_target.sqr()?.sum(D::Minus1)?.lt(CONTACT_SPEED_M_PER_S * CONTACT_SPEED_M_PER_S)?;
        let planted = planted.to_dtype(predicted.dtype())?; // [B, T−1, 4]
        let count = planted.sum_all()?.to_dtype(DType::F64)?.to_scalar::<f64>()?;
        let speed2 = feet_predicted.sqr()?.sum(D::Minus1)?.broadcast_mul(&w.squeeze(3)?)?;
        let foot_contact = ((speed2 * planted)?.sum_all()? / count.max(1.0))?;
        Ok(GeometricTerms { velocity, foot_contact })
    }

    /// World-frame joint velocities (m/s) of normalised features: `[B, T, 263]` → `[B, T−1, 22, 3]`.
    fn velocities(&self, x: &Tensor) -> Result<Tensor> {
        velocity(&recover_from_ric(&self.mean_std.denormalize(x)?)?)
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Var};

    use super::*;
    use crate::motion::test_support::walking_poses;
    use crate::representation::{extract_features, FEATURE_DIM, ROOT_LIN_VEL};

    /// A walk's features `[1, T, 263]` and unit Mean/Std (normalised = raw).
    fn walk() -> (Tensor, GeometricLoss) {
        let e = extract_features(&walking_poses(40, 1.2)).unwrap();
        let n = e.features.len();
        let flat: Vec<f32> = e.features.iter().flatten().copied().collect();
        let x = Tensor::from_vec(flat, (1, n, FEATURE_DIM), &Device::Cpu).unwrap();
        let unit = MeanStd::from_vecs(vec![0.0; FEATURE_DIM], vec![1.0; FEATURE_DIM], &Device::Cpu).unwrap();
        (x, GeometricLoss::new(unit).unwrap())
    }

    fn ones(batch: usize) -> Tensor {
        Tensor::ones(batch, DType::F32, &Device::Cpu).unwrap()
    }

    #[test]
    fn a_perfect_prediction_costs_nothing() {
        let (x, loss) = walk();
        let t = loss.terms(&x, &x, &ones(1)).unwrap();
        assert_eq!(t.velocity.to_scalar::<f32>().unwrap(), 0.0);
        assert_eq!(t.foot_contact.to_scalar::<f32>().unwrap(), 0.0);
    }

    #[test]
    fn a_root_velocity_error_slides_the_planted_feet_by_that_speed() {
        // A person standing still: the walk's first frame held, no root motion.
        let (x, loss) = walk();
        let mut still = x.narrow(1, 0, 1).unwrap().repeat((1, 30, 1)).unwrap();
        still = still
            .slice_assign(&[0..1, 0..30, 0..3], &Tensor::zeros((1, 30, 3), DType::F32, &Device::Cpu).unwrap())
            .unwrap();
        // Add 0.01 m/frame of sideways root velocity on every frame. Frame t's root is the
        // sum of the velocities of the frames before it, so every joint of every frame pair
        // moves 0.2 m/s: (0.2 m/s)² spread over 3 axes, and every foot is planted in the target.
        let mut shift = vec![0f32; FEATURE_DIM];
        shift[ROOT_LIN_VEL.start] = 0.01;
        let shift = Tensor::from_vec(shift, (1, 1, FEATURE_DIM), &Device::Cpu).unwrap();
        let skating = still.broadcast_add(&shift).unwrap();
        let t = loss.terms(&skating, &still, &ones(1)).unwrap();
        let v = t.velocity.to_scalar::<f32>().unwrap();
        assert!((v - 0.04 / 3.0).abs() < 1e-5, "velocity term {v}");
        let c = t.foot_contact.to_scalar::<f32>().unwrap();
        assert!((c - 0.04).abs() < 1e-5, "foot contact term {c}");
        // Weights scale both terms per sample: a batch of the skating and the exact motion,
        // weighted 0.5 and 1, averages to a quarter.
        let pair_hat = Tensor::cat(&[&skating, &still], 0).unwrap();
        let pair = Tensor::cat(&[&still, &still], 0).unwrap();
        let w = Tensor::new(&[0.5f32, 1.0], &Device::Cpu).unwrap();
        let t = loss.terms(&pair_hat, &pair, &w).unwrap();
        let v = t.velocity.to_scalar::<f32>().unwrap();
        assert!((v - 0.01 / 3.0).abs() < 1e-5, "weighted velocity term {v}");
        let c = t.foot_contact.to_scalar::<f32>().unwrap();
        assert!((c - 0.01).abs() < 1e-5, "weighted foot contact term {c}");
    }

    #[test]
    fn the_gradient_reaches_the_root_velocity() {
        let (x, loss) = walk();
        let var = Var::from_tensor(&(&x + 0.01).unwrap()).unwrap();
        let t = loss.terms(var.as_tensor(), &x, &ones(1)).unwrap();
        let grads = (t.velocity + t.foot_contact).unwrap().backward().unwrap();
        let g = grads.get(&var).unwrap();
        let root = g.narrow(2, ROOT_LIN_VEL.start, 2).unwrap().abs().unwrap().sum_all().unwrap();
        assert!(root.to_scalar::<f32>().unwrap() > 0.0);
    }
}
