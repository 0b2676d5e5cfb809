//! Root velocity re-derived from the planted feet: the features carry the root's motion twice,
//! once as its velocity (`[1..3]`) and once through the root-relative foot positions (`ric`)
//! together with the foot contacts (`[259..263]`). In the data both agree; in generated motions
//! the root velocity can run ahead of the legs, and the planted feet then slide. This module
//! makes the two agree by letting the planted feet decide.

use candle_core::{Result, Tensor, D};

use super::layout::{FEATURE_DIM, FOOT_CONTACT, RIC, ROOT_LIN_VEL, ROOT_ROT_VEL};

/// The foot joints whose contacts are features `[259..263]`, in that order: left ankle, left
/// foot, right ankle, right foot.
const CONTACT_JOINTS: [usize; 4] = [7, 10, 8, 11];

/// A foot joint counts as planted between two frames when its contact feature exceeds this in
/// both (the data's contacts are 0 or 1).
pub const PLANTED_CONTACT: f64 = 0.5;

/// Width of the sigmoid that turns a contact feature into a planted weight: contacts 0.1 away
/// from [`PLANTED_CONTACT`] weigh 0.12 or 0.88.
const PLANTED_SHARPNESS: f64 = 0.05;

/// Replaces the root x/z velocity of every frame t−1 whose next frame t keeps a foot joint
/// planted (contact above [`PLANTED_CONTACT`] in both frames) by the velocity that holds the
/// planted joints still in the world, averaged over them:
///
/// v_{t−1} = mean over planted j of [R(−2·ω_{t−1})·ric_{t−1, j} − ric_{t, j}] (x and z)
///
/// with ω the root yaw velocity (a half angle, feature `[0]`) and R a rotation about y; this is
/// what [`super::recover_from_ric`] needs to place the planted joints at the same world x/z in
/// both frames. Frames without a planted joint, and the last frame, keep their velocity. "Planted"
/// is a weight in [0, 1] (see below), which both the mean and the blend with the predicted
/// velocity use.
///
/// - input and output: **de-normalised** features `[batch, frames, 263]`;
/// - differentiable in the features, the contacts included: each joint's weight is a steep
///   sigmoid of its contact features, so the result changes continuously.
pub fn root_velocity_from_planted_feet(features: &Tensor) -> Result<Tensor> {
    let (batch, frames, dim) = features.dims3()?;
    if dim != FEATURE_DIM {
        candle_core::bail!(
            "root_velocity_from_planted_feet: expected [batch, frames, {FEATURE_DIM}], got {:?}",
            features.dims()
        );
    }
    if frames < 2 {
        return Ok(features.clone());
    }
    let pairs = frames - 1;
    let (prev, next) = (features.narrow(1, 0, pairs)?, features.narrow(1, 1, pairs)?);
    // The heading turns by 2ω_{t−1} from frame t−1 to t; R(−2ω) takes t−1's heading frame to t's.
    let angle = (prev.narrow(D::Minus1, ROOT_ROT_VEL, 1)? * -2.0)?; // [B, T−1, 1]
    let (cos, sin) = (angle.cos()?, angle.sin()?);
    // How planted each foot joint is: a steep sigmoid of its contact feature, so the decode
    // changes continuously with the features (DNO's steps must not flip it abruptly); the
    // data's contacts of 0 and 1 give weights of 0 and 1 to within 5e-5.
    let contacts = features.narrow(D::Minus1, FOOT_CONTACT.start, FOOT_CONTACT.len())?;
    let on = (((contacts - PLANTED_CONTACT)? / -PLANTED_SHARPNESS)?.exp()? + 1.0)?.recip()?; // [B, T, 4]
    let planted = (on.narrow(1, 0, pairs)? * on.narrow(1, 1, pairs)?)?; // [B, T−1, 4]

    // A weighted mean over the planted joints, blended with the given velocity by how likely
    // any joint is planted: 1 − Π(1 − w).
    let mut sum = Tensor::zeros((batch, pairs, 2), features.dtype(), features.device())?;
    let mut none = Tensor::ones((batch, pairs, 1), features.dtype(), features.device())?;
    for (c, &joint) in CONTACT_JOINTS.iter().enumerate() {
        let at = RIC.start + 3 * (joint - 1);
        let (px, pz) = (prev.narrow(D::Minus1, at, 1)?, prev.narrow(D::Minus1, at + 2, 1)?);
        let (nx, nz) = (next.narrow(D::Minus1, at, 1)?, next.narrow(D::Minus1, at + 2, 1)?);
        let dx = (((&px * &cos)? - (&pz * &sin)?)? - nx)?;
        let dz = (((&px * &sin)? + (&pz * &cos)?)? - nz)?;
        let weight = planted.narrow(D::Minus1, c, 1)?;
        sum = (sum + Tensor::cat(&[dx, dz], D::Minus1)?.broadcast_mul(&weight)?)?;
        none = (none * (1.0 - &weight)?)?;
    }
    let count = (planted.sum_keepdim(D::Minus1)? + 1e-6)?; // [B, T−1, 1]
    let any = (1.0 - none)?;
    let from_feet = sum.broadcast_div(&count)?;
    let given = prev.narrow(D::Minus1, ROOT_LIN_VEL.start, 2)?;
    let velocity = (from_feet.broadcast_mul(&any)? + given.broadcast_mul(&(1.0 - &any)?)?)?;
    let velocity =
        Tensor::cat(&[velocity, features.narrow(1, pairs, 1)?.narrow(D::Minus1, ROOT_LIN_VEL.start, 2)?], 1)?;
    // Concatenating views along the last axis gives a strided result; callers index into it.
    Tensor::cat(
        &[
            &features.narrow(D::Minus1, 0, ROOT_LIN_VEL.start)?,
            &velocity,
            &features.narrow(D::Minus1, ROOT_LIN_VEL.end, FEATURE_DIM - ROOT_LIN_VEL.end)?,
        ],
        D::Minus1,
    )?
    .contiguous()
}

#[cfg(test)]
mod tests {
    use candle_core::{DType, Device, IndexOp};

    use super::*;
    use crate::motion::test_support::walking_poses;
    use crate::representation::{extract_features, recover_from_ric};
    use crate::testing::finite_difference_check;

    fn walk(frames: usize, turn_rate: f64) -> Tensor {
        let e = extract_features(&walking_poses(frames, turn_rate)).unwrap();
        let flat: Vec<f32> = e.features.iter().flatten().copied().collect();
        Tensor::from_vec(flat, (1, e.features.len(), FEATURE_DIM), &Device::Cpu).unwrap()
    }

    /// Largest x/z step of a joint between frames whose contact feature is on in both.
    fn planted_slide(features: &Tensor) -> f32 {
        let frames = features.dim(1).unwrap();
        let joints: Vec<Vec<f32>> =
            recover_from_ric(features).unwrap().i(0).unwrap().reshape((frames, 66)).unwrap().to_vec2().unwrap();
        let contacts: Vec<Vec<f32>> =
            features.i(0).unwrap().narrow(1, FOOT_CONTACT.start, 4).unwrap().to_vec2().unwrap();
        let mut worst = 0f32;
        for t in 1..contacts.len() {
            for (c, &j) in CONTACT_JOINTS.iter().enumerate() {
                if contacts[t - 1][c] > 0.5 && contacts[t][c] > 0.5 {
                    let (a, b) = (&joints[t - 1], &joints[t]);
                    let step = ((b[3 * j] - a[3 * j]).powi(2) + (b[3 * j + 2] - a[3 * j + 2]).powi(2)).sqrt();
                    worst = worst.max(step);
                }
            }
        }
        worst
    }

    /// Pelvis x/z distance from the first to the last frame, m.
    fn travel(features: &Tensor) -> f32 {
        let root: Vec<Vec<f32>> = recover_from_ric(features).unwrap().i((0, .., 0)).unwrap().to_vec2().unwrap();
        let (a, b) = (&root[0], &root[root.len() - 1]);
        ((b[0] - a[0]).powi(2) + (b[2] - a[2]).powi(2)).sqrt()
    }

    #[test]
    fn keeps_a_consistent_walk_and_pins_the_feet_of_a_gliding_one() {
        let f = walk(80, 0.8);
        let contacts = f.narrow(2, FOOT_CONTACT.start, 4).unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap();
        assert!(contacts > 20.0, "the synthetic walk has planted feet ({contacts} contact frames)");
        let kept = root_velocity_from_planted_feet(&f).unwrap();
        assert!(kept.is_contiguous(), "callers index_select into the features");
        // The synthetic walk marks feet moving up to 4.5 cm per frame as planted (HumanML3D's
        // contact rule), so its root changes a little, but it travels as far.
        let (before, after) = (travel(&f), travel(&kept));
        assert!((after - before).abs() < 0.1 * before, "travel {before} m became {after} m");
        assert!(planted_slide(&kept) < 0.01, "planted joints move {} m per frame", planted_slide(&kept));
        // Everything but the root velocity is untouched.
        let rest = |x: &Tensor| x.narrow(2, ROOT_LIN_VEL.end, FEATURE_DIM - ROOT_LIN_VEL.end).unwrap();
        assert_eq!(
            (rest(&kept) - rest(&f)).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap(),
            0.0
        );

        // The root glides 3 cm per frame faster than the legs: planted feet slide, until projected.
        let push = Tensor::from_vec(vec![0f32, 0.0, 0.03], (1, 1, 3), &Device::Cpu).unwrap();
        let glide = Tensor::cat(
            &[(f.narrow(2, 0, 3).unwrap().broadcast_add(&push)).unwrap(), f.narrow(2, 3, FEATURE_DIM - 3).unwrap()],
            2,
        )
        .unwrap();
        assert!(planted_slide(&glide) > 0.025, "{}", planted_slide(&glide));
        let fixed = root_velocity_from_planted_feet(&glide).unwrap();
        assert!(planted_slide(&fixed) < 0.01, "planted joints still move {} m per frame", planted_slide(&fixed));
        // Frames with no foot planted in both keep the glide.
        let (glided, pinned) = (travel(&glide) - after, travel(&fixed) - after);
        assert!(pinned.abs() < 0.25 * glided, "the glide travels {pinned} m too far, {glided} m before");
    }

    #[test]
    fn gradient_matches_finite_differences() {
        // Contacts near the threshold, where the planted weights have slope.
        let f = walk(10, 0.9).to_dtype(DType::F64).unwrap();
        let near = Tensor::arange(0f64, 36.0, &Device::Cpu).unwrap().affine(0.7, 0.0).unwrap().sin().unwrap();
        let near = ((near * 0.06).unwrap() + PLANTED_CONTACT).unwrap().reshape((1, 9, 4)).unwrap();
        let f = Tensor::cat(&[&f.narrow(2, 0, FOOT_CONTACT.start).unwrap(), &near], 2).unwrap();
        let weights = Tensor::arange(0f64, (9 * FEATURE_DIM) as f64, &Device::Cpu)
            .unwrap()
            .affine(0.013, 0.2)
            .unwrap()
            .sin()
            .unwrap()
            .reshape((1, 9, FEATURE_DIM))
            .unwrap();
        finite_difference_check(&f, |x| (root_velocity_from_planted_feet(x)? * &weights)?.sum_all(), 1e-6, 1e-6)
            .unwrap();
    }

    #[test]
    fn rejects_the_wrong_width_and_passes_single_frames_through() {
        assert!(
            root_velocity_from_planted_feet(&Tensor::zeros((1, 4, 262), DType::F32, &Device::Cpu).unwrap()).is_err()
        );
        let one = walk(3, 0.0).narrow(1, 0, 1).unwrap();
        let same = root_velocity_from_planted_feet(&one).unwrap();
        assert_eq!((same - &one).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap(), 0.0);
    }
}
