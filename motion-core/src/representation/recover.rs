//! Differentiable, batched recovery of joint positions from the 263-d features
//! (HumanML3D's `recover_root_rot_pos` + `recover_from_ric`).

use candle_core::{DType, Device, Result, Tensor, D};

use super::layout::{FEATURE_DIM, RIC, ROOT_LIN_VEL, ROOT_ROT_VEL, ROOT_Y};
use crate::skeleton::NUM_JOINTS;

/// Recovers joint positions from **de-normalised** features.
///
/// - input `features`: `[batch, frames, 263]`
/// - output: `[batch, frames, 22, 3]`, metres, y up; frame 0's pelvis is at x = z = 0 and the
///   heading of frame 0 is the identity (the clip faces +z at its start).
///
/// Yaw θ_t = Σ_{k<t} f[k, 0] is a half angle, so the heading is a rotation by 2θ_t about y; the
/// root velocity of frame t−1 is rotated with frame t's heading and summed; joints 1..21 are the
/// `ric` positions rotated back by the heading and shifted by the root's x/z. Every op used has a
/// backward pass in candle, so gradients flow to `features`.
pub fn recover_from_ric(features: &Tensor) -> Result<Tensor> {
    let (batch, frames, dim) = features.dims3()?;
    if dim != FEATURE_DIM {
        candle_core::bail!("recover_from_ric: expected [batch, frames, {FEATURE_DIM}], got {:?}", features.dims());
    }
    let dev = features.device();
    let dtype = features.dtype();

    let rot_vel = features.narrow(D::Minus1, ROOT_ROT_VEL, 1)?.squeeze(D::Minus1)?; // [B, T]
    let exclusive = exclusive_cumsum_matrix(frames, dtype, dev)?; // [T, T]
    let half_yaw = rot_vel.broadcast_matmul(&exclusive)?; // [B, T]
    let yaw = (half_yaw * 2.0)?;
    let (cos, sin) = (yaw.cos()?.unsqueeze(D::Minus1)?, yaw.sin()?.unsqueeze(D::Minus1)?); // [B, T, 1]

    // Root x/z velocity of frame t−1, placed at frame t (frame 0 gets 0), rotated by the
    // inverse heading: x' = x cos − z sin, z' = x sin + z cos.
    let lin = features.narrow(D::Minus1, ROOT_LIN_VEL.start, 2)?; // [B, T, 2]
    let lin = Tensor::cat(&[Tensor::zeros((batch, 1, 2), dtype, dev)?, lin.narrow(1, 0, frames - 1)?], 1)?;
    let (vx, vz) = (lin.narrow(D::Minus1, 0, 1)?, lin.narrow(D::Minus1, 1, 1)?);
    let wx = ((&vx * &cos)? - (&vz * &sin)?)?;
    let wz = ((&vx * &sin)? + (&vz * &cos)?)?;
    let inclusive = (&exclusive + Tensor::eye(frames, dtype, dev)?)?;
    let root_x = wx.squeeze(D::Minus1)?.broadcast_matmul(&inclusive)?.unsqueeze(D::Minus1)?; // [B, T, 1]
    let root_z = wz.squeeze(D::Minus1)?.broadcast_matmul(&inclusive)?.unsqueeze(D::Minus1)?;
    let root_y = features.narrow(D::Minus1, ROOT_Y, 1)?;
    let root = Tensor::cat(&[&root_x, &root_y, &root_z], D::Minus1)?.unsqueeze(2)?; // [B, T, 1, 3]

    let ric = features.narrow(D::Minus1, RIC.start, RIC.len())?.reshape((batch, frames, NUM_JOINTS - 1, 3))?;
    let (px, py, pz) = (ric.narrow(3, 0, 1)?, ric.narrow(3, 1, 1)?, ric.narrow(3, 2, 1)?);
    let cos4 = cos.unsqueeze(D::Minus1)?; // [B, T, 1, 1]
    let sin4 = sin.unsqueeze(D::Minus1)?;
    let jx = ((px.broadcast_mul(&cos4)? - pz.broadcast_mul(&sin4)?)?.broadcast_add(&root_x.unsqueeze(2)?))?;
    let jz = ((px.broadcast_mul(&sin4)? + pz.broadcast_mul(&cos4)?)?.broadcast_add(&root_z.unsqueeze(2)?))?;
    let joints = Tensor::cat(&[&jx, &py, &jz], 3)?; // [B, T, 21, 3]
    Tensor::cat(&[&root, &joints], 2)
}

/// `[T, T]` matrix M with M[k, t] = 1 when k < t, so `x · M` is the exclusive cumulative sum of
/// the rows of `x` along time (a gemm, which candle differentiates).
fn exclusive_cumsum_matrix(frames: usize, dtype: DType, dev: &Device) -> Result<Tensor> {
    let data: Vec<f32> = (0..frames * frames).map(|i| if i / frames < i % frames { 1.0 } else { 0.0 }).collect();
    Tensor::from_vec(data, (frames, frames), dev)?.to_dtype(dtype)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::test_support::walking_poses;
    use crate::representation::extract_features;
    use crate::testing::finite_difference_check;

    fn features_tensor(poses: &[crate::skeleton::Pose]) -> (Tensor, Vec<crate::skeleton::Pose>) {
        let e = extract_features(poses).unwrap();
        let flat: Vec<f32> = e.features.iter().flatten().copied().collect();
        let n = e.features.len();
        (Tensor::from_vec(flat, (1, n, FEATURE_DIM), &Device::Cpu).unwrap(), e.canonical)
    }

    #[test]
    fn recovers_the_canonical_joints_of_a_turning_walk() {
        let poses = walking_poses(60, 1.2);
        let (f, canonical) = features_tensor(&poses);
        let joints = recover_from_ric(&f).unwrap();
        assert_eq!(joints.dims(), &[1, 59, 22, 3]);
        let got: Vec<Vec<f32>> = joints.reshape((59, 66)).unwrap().to_vec2().unwrap();
        let mut max_err: f64 = 0.0;
        for (t, frame) in got.iter().enumerate() {
            for j in 0..NUM_JOINTS {
                let v = glam::DVec3::new(frame[3 * j] as f64, frame[3 * j + 1] as f64, frame[3 * j + 2] as f64);
                max_err = max_err.max((v - canonical[t][j]).length());
            }
        }
        assert!(max_err < 1e-4, "max joint error {max_err} m");
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let poses = walking_poses(8, 0.9);
        let (f, _) = features_tensor(&poses);
        let f = f.to_dtype(DType::F64).unwrap();
        // A weighted sum of all outputs exercises every path (yaw, velocity, ric).
        let weights = Tensor::arange(0f64, (7 * 22 * 3) as f64, &Device::Cpu)
            .unwrap()
            .affine(0.01, 0.3)
            .unwrap()
            .sin()
            .unwrap()
            .reshape((1, 7, 22, 3))
            .unwrap();
        finite_difference_check(&f, |x| (recover_from_ric(x)? * &weights)?.sum_all(), 1e-6, 1e-6).unwrap();
    }

    #[test]
    fn rejects_the_wrong_feature_width() {
        let x = Tensor::zeros((1, 4, 262), DType::F32, &Device::Cpu).unwrap();
        assert!(recover_from_ric(&x).is_err());
    }
}
