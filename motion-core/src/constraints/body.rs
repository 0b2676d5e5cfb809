//! The capsule body model: our stand-in for the SMPL vertices RG-DNO tests against the scene.
//!
//! Every bone (parent → child) carries a capsule of a fixed radius, sized for a 1.70 m adult
//! (the prior's stature). Surface points sit on rings around the bone axis at fractions
//! [`RING_FRACTIONS`] of its length, [`POINTS_PER_RING`] per ring, plus a sphere of points around
//! the head. The points are a differentiable function of the joints: ring directions come from
//! the bone direction and a helper axis (world y, or world x for bones within ~25° of vertical).
//! There are no hands or toes beyond the wrists and the foot joints (the skeleton has none).

use candle_core::{Result, Tensor, D};

use super::geometry::{cross, norm, NORM_EPS};
use crate::skeleton::{bones, Joint};

/// Positions along each bone where a ring of surface points sits (fraction of the bone, from
/// the parent).
pub const RING_FRACTIONS: [f64; 3] = [0.2, 0.5, 0.8];

/// Surface points on each ring.
pub const POINTS_PER_RING: usize = 8;

/// Radius of the head sphere around the head joint, m.
pub const HEAD_RADIUS_M: f64 = 0.10;

/// Capsule radius of the bone ending at `child`, m (a 1.70 m adult).
pub fn bone_radius_m(child: Joint) -> f64 {
    match child {
        Joint::LeftHip | Joint::RightHip => 0.09,
        Joint::LeftKnee | Joint::RightKnee => 0.075,
        Joint::LeftAnkle | Joint::RightAnkle => 0.05,
        Joint::LeftFoot | Joint::RightFoot => 0.04,
        Joint::Spine1 | Joint::Spine2 | Joint::Spine3 => 0.11,
        Joint::Neck => 0.06,
        Joint::Head => 0.07,
        Joint::LeftCollar | Joint::RightCollar => 0.06,
        Joint::LeftShoulder | Joint::RightShoulder => 0.055,
        Joint::LeftElbow | Joint::RightElbow => 0.045,
        Joint::LeftWrist | Joint::RightWrist => 0.035,
        Joint::Pelvis => 0.0,
    }
}

/// Number of head-sphere points (6 axis directions and 8 cube diagonals).
pub const HEAD_POINTS: usize = 14;

/// Total surface points per frame: 21 bones × rings × points per ring + the head sphere.
pub const SURFACE_POINTS: usize = 21 * RING_FRACTIONS.len() * POINTS_PER_RING + HEAD_POINTS;

/// Surface points `[B, T, SURFACE_POINTS, 3]` (m) of joints `[B, T, 22, 3]`.
pub fn surface_points(joints: &Tensor) -> Result<Tensor> {
    let dtype = joints.dtype();
    let device = joints.device();
    let (parents, children): (Vec<u32>, Vec<u32>) = bones().map(|(p, c)| (p.index() as u32, c.index() as u32)).unzip();
    let n_bones = parents.len();
    let parent = joints.index_select(&Tensor::from_vec(parents, n_bones, device)?, 2)?; // [B, T, K, 3]
    let child = joints.index_select(&Tensor::from_vec(children, n_bones, device)?, 2)?;
    let axis = (&child - &parent)?;
    let dir = axis.broadcast_div(&norm(&axis)?.unsqueeze(D::Minus1)?)?;

    // Helper axis per bone: y unless the bone is near vertical (decided without gradient).
    let vertical = dir.narrow(D::Minus1, 1, 1)?.abs()?.detach().ge(0.9)?.to_dtype(dtype)?; // [B, T, K, 1]
    let y = Tensor::new(&[0.0, 1.0, 0.0], device)?.to_dtype(dtype)?.reshape((1, 1, 1, 3))?;
    let x = Tensor::new(&[1.0, 0.0, 0.0], device)?.to_dtype(dtype)?.reshape((1, 1, 1, 3))?;
    let helper = (vertical.broadcast_mul(&x)? + (1.0 - &vertical)?.broadcast_mul(&y)?)?;
    let u = cross(&dir, &helper)?;
    let u = u.broadcast_div(&(u.sqr()?.sum_keepdim(D::Minus1)? + NORM_EPS)?.sqrt()?)?;
    let v = cross(&dir, &u)?;

    // Every ring point at once: point (fraction f, angle a) of bone k is
    // parent_k + f·axis_k + cos a·r_k·u_k + sin a·r_k·v_k, one product of the `[ring points, 4]`
    // coefficients with `[parent; axis; r·u; r·v]` per frame (a few graph nodes instead of a few
    // per point: the DNO loop and the refinement differentiate this hundreds of times).
    let ring_points = RING_FRACTIONS.len() * POINTS_PER_RING;
    let mut coefficients = Vec::with_capacity(ring_points * 4);
    for fraction in RING_FRACTIONS {
        for k in 0..POINTS_PER_RING {
            let angle = std::f64::consts::TAU * k as f64 / POINTS_PER_RING as f64;
            coefficients.extend([1.0, fraction, angle.cos(), angle.sin()]);
        }
    }
    let coefficients = Tensor::from_vec(coefficients, (ring_points, 4), device)?.to_dtype(dtype)?;
    let radii: Vec<f64> = bones().map(|(_, c)| bone_radius_m(c)).collect();
    let radii = Tensor::new(radii.as_slice(), device)?.to_dtype(dtype)?.reshape((1, 1, n_bones, 1))?;
    let (b, t) = (joints.dim(0)?, joints.dim(1)?);
    let basis = Tensor::stack(&[&parent, &axis, &u.broadcast_mul(&radii)?, &v.broadcast_mul(&radii)?], 2)?
        .reshape((b, t, 4, n_bones * 3))?;
    // [B, T, K·rings·points, 3], fraction-major, then the point on the ring, then the bone.
    let rings = coefficients.broadcast_matmul(&basis)?.reshape((b, t, ring_points * n_bones, 3))?;

    let head = joints.narrow(2, Joint::Head.index(), 1)?; // [B, T, 1, 3]
    let directions: Vec<f64> = head_directions().into_iter().flatten().collect();
    let sphere = Tensor::from_vec(directions, (1, 1, HEAD_POINTS, 3), device)?.to_dtype(dtype)?;
    let head_points = head.broadcast_add(&(sphere * HEAD_RADIUS_M)?)?;
    Tensor::cat(&[rings, head_points], 2)
}

/// Unit directions of the head-sphere points.
fn head_directions() -> Vec<[f64; 3]> {
    let s = 1.0 / 3f64.sqrt();
    let mut directions =
        vec![[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
    for sx in [-s, s] {
        for sy in [-s, s] {
            for sz in [-s, s] {
                directions.push([sx, sy, sz]);
            }
        }
    }
    directions
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diffusion::noise::gaussian;
    use crate::testing::finite_difference_check;
    use candle_core::{DType, Device};

    /// A T-pose-like skeleton: every joint placed along its raw offset from its parent, 0.2 m.
    fn tpose() -> Tensor {
        let mut positions = [[0.0f64; 3]; 22];
        positions[0] = [0.0, 1.0, 0.0];
        for joint in Joint::ALL.into_iter().skip(1) {
            let parent = joint.parent().map_or(0, Joint::index);
            let o = joint.raw_offset();
            positions[joint.index()] =
                [positions[parent][0] + 0.2 * o.x, positions[parent][1] + 0.2 * o.y, positions[parent][2] + 0.2 * o.z];
        }
        let flat: Vec<f64> = positions.iter().flatten().copied().collect();
        Tensor::from_vec(flat, (1, 1, 22, 3), &Device::Cpu).unwrap()
    }

    #[test]
    fn surface_points_lie_at_the_capsule_radius_from_their_bone() {
        let joints = tpose();
        let points = surface_points(&joints).unwrap();
        assert_eq!(points.dims(), [1, 1, SURFACE_POINTS, 3]);
        let p = points.flatten_to(2).unwrap().squeeze(0).unwrap().to_vec2::<f64>().unwrap();
        let j = joints.reshape((22, 3)).unwrap().to_vec2::<f64>().unwrap();
        // Order: ring fraction, point on the ring, bone.
        let bone_list: Vec<_> = bones().collect();
        for (r, fraction) in RING_FRACTIONS.into_iter().enumerate() {
            for k in 0..POINTS_PER_RING {
                for (b, (parent, child)) in bone_list.iter().enumerate() {
                    let q = &p[(r * POINTS_PER_RING + k) * bone_list.len() + b];
                    let (a, e) = (&j[parent.index()], &j[child.index()]);
                    let centre: Vec<f64> = (0..3).map(|c| a[c] + fraction * (e[c] - a[c])).collect();
                    let d: f64 = (0..3).map(|c| (q[c] - centre[c]).powi(2)).sum::<f64>().sqrt();
                    assert!((d - bone_radius_m(*child)).abs() < 1e-6, "bone {child}: {d}");
                    let along: f64 = (0..3).map(|c| (q[c] - centre[c]) * (e[c] - a[c])).sum();
                    assert!(along.abs() < 1e-9, "ring point off the ring plane");
                }
            }
        }
        let i = RING_FRACTIONS.len() * POINTS_PER_RING * bone_list.len();
        let head = &j[Joint::Head.index()];
        for q in &p[i..] {
            let d: f64 = (0..3).map(|k| (q[k] - head[k]).powi(2)).sum::<f64>().sqrt();
            assert!((d - HEAD_RADIUS_M).abs() < 1e-12);
        }
    }

    #[test]
    fn surface_gradient_matches_finite_differences() {
        let joints = (tpose()
            + (gaussian((1, 1, 22, 3), 1, &Device::Cpu).unwrap().to_dtype(DType::F64).unwrap() * 0.02))
            .unwrap();
        let weights = gaussian((1, 1, SURFACE_POINTS, 3), 2, &Device::Cpu).unwrap().to_dtype(DType::F64).unwrap();
        finite_difference_check(&joints, |j| surface_points(j)?.broadcast_mul(&weights)?.sum_all(), 1e-6, 1e-4)
            .unwrap();
    }
}
