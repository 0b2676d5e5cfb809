//! Rigid bones by construction: joint positions re-derived on a rest skeleton's bone lengths.
//!
//! The 263-d features carry each joint's root-relative position (`ric`) independently, so a
//! generated motion's bones can stretch by centimetres from frame to frame. [`rigid_bones`] keeps
//! every bone's direction (parent → child, as generated) and gives it the rest length, walking
//! the tree from the pelvis (HumanML3D's `uniform_skeleton` applied to every frame, batched and
//! differentiable). The pelvis trajectory is unchanged.

use candle_core::{DType, Device, Result, Tensor, D};
use serde::{Deserialize, Serialize};

use crate::skeleton::{bone_lengths, Joint, Pose, NUM_JOINTS};

/// Squared-length floor of a bone vector before it is normalised, m² (keeps the gradient of a
/// collapsed bone finite).
const BONE_EPS_M2: f64 = 1e-12;

/// Bone lengths of a rest skeleton, m, indexed by child joint (entry 0, the pelvis, is 0).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RestSkeleton {
    /// Length of the bone ending at each joint, m.
    pub bone_lengths_m: [f64; NUM_JOINTS],
}

impl RestSkeleton {
    /// The bone lengths of one pose.
    pub fn of_pose(pose: &Pose) -> Self {
        Self { bone_lengths_m: bone_lengths(pose) }
    }

    /// The mean bone lengths of poses `[.., 22, 3]` (any leading shape), m; `None` when there are
    /// no poses or a length is not finite.
    pub fn mean_of(joints: &Tensor) -> Result<Option<Self>> {
        let flat = joints.to_dtype(DType::F64)?.reshape(((), NUM_JOINTS, 3))?;
        let rows = flat.dim(0)?;
        if rows == 0 {
            return Ok(None);
        }
        let lengths = bone_vectors(&flat.unsqueeze(0)?)?.sqr()?.sum(D::Minus1)?.sqrt()?.mean(1)?.squeeze(0)?;
        let lengths: Vec<f64> = lengths.to_vec1()?;
        let mut out = [0.0; NUM_JOINTS];
        for (o, l) in out.iter_mut().zip(lengths) {
            if !l.is_finite() {
                return Ok(None);
            }
            *o = l;
        }
        Ok(Some(Self { bone_lengths_m: out }))
    }
}

/// Joints `[batch, frames, 22, 3]` with every bone re-scaled to `rest`'s length along its own
/// direction, accumulated from the pelvis down the tree; differentiable. Bones of zero length
/// stay at zero length.
pub fn rigid_bones(joints: &Tensor, rest: &RestSkeleton) -> Result<Tensor> {
    let (batch, frames, joints_n, three) = joints.dims4()?;
    if (joints_n, three) != (NUM_JOINTS, 3) {
        candle_core::bail!("rigid_bones: expected [batch, frames, {NUM_JOINTS}, 3], got {:?}", joints.dims());
    }
    let (dtype, dev) = (joints.dtype(), joints.device());
    let v = bone_vectors(joints)?; // [B, T, 22, 3], pelvis row 0
    let norm = (v.sqr()?.sum_keepdim(D::Minus1)? + BONE_EPS_M2)?.sqrt()?;
    let lengths = Tensor::from_vec(rest.bone_lengths_m.to_vec(), (NUM_JOINTS, 1), dev)?.to_dtype(dtype)?;
    let scaled = v.broadcast_div(&norm)?.broadcast_mul(&lengths)?;
    // position_j = pelvis + Σ_{k on the path pelvis → j, k ≠ pelvis} scaled_k: one gemm over the
    // joint axis with the ancestry matrix.
    let summed = scaled.transpose(2, 3)?.contiguous()?.broadcast_matmul(&ancestry_matrix(dtype, dev)?)?; // [B, T, 3, 22]
    let pelvis = joints.narrow(2, 0, 1)?;
    summed.transpose(2, 3)?.broadcast_add(&pelvis)?.reshape((batch, frames, NUM_JOINTS, 3))
}

/// Bone vectors child − parent of joints `[B, T, 22, 3]`, `[B, T, 22, 3]` (the pelvis row is 0).
fn bone_vectors(joints: &Tensor) -> Result<Tensor> {
    let parents: Vec<u32> =
        Joint::ALL.iter().map(|j| j.parent().map_or(Joint::Pelvis.index(), Joint::index) as u32).collect();
    let parents = Tensor::from_vec(parents, NUM_JOINTS, joints.device())?;
    joints.contiguous()?.index_select(&parents, 2)?.neg()?.add(joints)
}

/// `[22, 22]` matrix M with M[k, j] = 1 when bone k (ending at joint k ≠ pelvis) lies on the path
/// from the pelvis to joint j, so `bones[.., 3, 22] · M` sums each joint's chain.
fn ancestry_matrix(dtype: DType, dev: &Device) -> Result<Tensor> {
    let mut m = vec![0f32; NUM_JOINTS * NUM_JOINTS];
    for j in Joint::ALL {
        let mut k = Some(j);
        while let Some(bone) = k.filter(|b| *b != Joint::Pelvis) {
            m[bone.index() * NUM_JOINTS + j.index()] = 1.0;
            k = bone.parent();
        }
    }
    Tensor::from_vec(m, (NUM_JOINTS, NUM_JOINTS), dev)?.to_dtype(dtype)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skeleton::bones;
    use crate::skeleton::rest_pose;
    use crate::testing::finite_difference_check;

    fn rest() -> RestSkeleton {
        RestSkeleton::of_pose(&rest_pose())
    }

    fn stretched_motion(dev: &Device) -> Tensor {
        // The rest pose, moved, with every joint jittered by up to ±6 cm per frame.
        let pose = rest_pose();
        let mut data = Vec::new();
        for t in 0..5 {
            for (j, p) in pose.iter().enumerate() {
                let wobble = 0.06 * (((t * 7 + j * 13) % 11) as f64 / 5.0 - 1.0);
                data.extend([p.x + wobble, p.y + 0.9 - wobble * 0.5, p.z + 0.1 * t as f64 + wobble]);
            }
        }
        Tensor::from_vec(data, (1, 5, NUM_JOINTS, 3), dev).unwrap()
    }

    #[test]
    fn every_bone_gets_the_rest_length_and_keeps_its_direction() {
        let dev = Device::Cpu;
        let x = stretched_motion(&dev);
        let y = rigid_bones(&x, &rest()).unwrap();
        let x = x.squeeze(0).unwrap().to_vec3::<f64>().unwrap();
        let y = y.squeeze(0).unwrap().to_vec3::<f64>().unwrap();
        let rest = rest();
        for t in 0..5 {
            assert_eq!(y[t][0], x[t][0], "the pelvis does not move");
            for (p, c) in bones() {
                let (p, c) = (p.index(), c.index());
                let bone = |m: &Vec<Vec<Vec<f64>>>| [0, 1, 2].map(|a| m[t][c][a] - m[t][p][a]);
                let (bx, by) = (bone(&x), bone(&y));
                let len = |b: [f64; 3]| b.iter().map(|v| v * v).sum::<f64>().sqrt();
                assert!((len(by) - rest.bone_lengths_m[c]).abs() < 1e-9, "bone {c} at frame {t}");
                let cos = bx.iter().zip(&by).map(|(a, b)| a * b).sum::<f64>() / (len(bx) * len(by));
                assert!(cos > 1.0 - 1e-9, "bone {c} keeps its direction");
            }
        }
    }

    #[test]
    fn a_rigid_motion_on_the_rest_lengths_is_unchanged_and_the_mean_recovers_them() {
        let dev = Device::Cpu;
        let pose = rest_pose();
        let data: Vec<f64> =
            (0..3).flat_map(|t| pose.iter().flat_map(move |p| [p.x, p.y + 0.9, p.z + t as f64])).collect();
        let x = Tensor::from_vec(data, (1, 3, NUM_JOINTS, 3), &dev).unwrap();
        let y = rigid_bones(&x, &rest()).unwrap();
        let diff = (y - &x).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f64>().unwrap();
        assert!(diff < 1e-9, "{diff}");
        let mean = RestSkeleton::mean_of(&x).unwrap().unwrap();
        for j in 0..NUM_JOINTS {
            assert!((mean.bone_lengths_m[j] - rest().bone_lengths_m[j]).abs() < 1e-9);
        }
        assert_eq!(RestSkeleton::mean_of(&Tensor::zeros((0, NUM_JOINTS, 3), DType::F64, &dev).unwrap()).unwrap(), None);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let dev = Device::Cpu;
        let x = stretched_motion(&dev);
        let w = Tensor::randn(0f64, 1.0, (1, 5, NUM_JOINTS, 3), &dev).unwrap();
        finite_difference_check(&x, |x| (rigid_bones(x, &rest())? * &w)?.sum_all(), 1e-6, 1e-5).unwrap();
    }

    #[test]
    fn rejects_a_wrong_shape() {
        let x = Tensor::zeros((1, 2, 21, 3), DType::F32, &Device::Cpu).unwrap();
        assert!(rigid_bones(&x, &rest()).unwrap_err().to_string().contains("[batch, frames, 22, 3]"));
    }
}
