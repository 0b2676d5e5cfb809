//! Small differentiable tensor geometry on the last axis `(x, y, z)`: joint picking, axis
//! selection, norms, dot and cross products, constants. Every op used has a backward pass in
//! candle (`reference/candle-and-crates.md` §1.3).

use candle_core::{DType, Device, Result, Tensor, D};

use crate::program::Axes;
use crate::skeleton::Joint;

/// Added under every square root of a squared norm, m²: the gradient stays finite at zero length,
/// and distances are biased by at most `sqrt(NORM_EPS)` = 1e-6 m.
pub const NORM_EPS: f64 = 1e-12;

/// The joint's positions `[B, T, 3]` from joints `[B, T, 22, 3]`.
pub fn joint(joints: &Tensor, joint: Joint) -> Result<Tensor> {
    joints.narrow(2, joint.index(), 1)?.squeeze(2)
}

/// Keeps the coordinates `axes` of `x` `[.., 3]` → `[.., C]`.
pub fn select_axes(x: &Tensor, axes: Axes) -> Result<Tensor> {
    match axes.indices() {
        [single] => x.narrow(D::Minus1, *single, 1),
        [0, 1] => x.narrow(D::Minus1, 0, 2),
        [1, 2] => x.narrow(D::Minus1, 1, 2),
        [0, 1, 2] => Ok(x.clone()),
        indices => {
            let index = Tensor::from_vec(indices.iter().map(|&i| i as u32).collect(), indices.len(), x.device())?;
            x.contiguous()?.index_select(&index, x.rank() - 1)
        }
    }
}

/// Euclidean norm over the last axis, `sqrt(Σ x² + NORM_EPS)`; the last axis is removed.
pub fn norm(x: &Tensor) -> Result<Tensor> {
    (x.sqr()?.sum(D::Minus1)? + NORM_EPS)?.sqrt()
}

/// Dot product over the last axis (removed).
pub fn dot(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    a.broadcast_mul(b)?.sum(D::Minus1)
}

/// Cross product over the last axis (length 3), broadcasting.
pub fn cross(a: &Tensor, b: &Tensor) -> Result<Tensor> {
    let c = |t: &Tensor, i: usize| t.narrow(D::Minus1, i, 1);
    let (ax, ay, az) = (c(a, 0)?, c(a, 1)?, c(a, 2)?);
    let (bx, by, bz) = (c(b, 0)?, c(b, 1)?, c(b, 2)?);
    let x = (ay.broadcast_mul(&bz)? - az.broadcast_mul(&by)?)?;
    let y = (az.broadcast_mul(&bx)? - ax.broadcast_mul(&bz)?)?;
    let z = (ax.broadcast_mul(&by)? - ay.broadcast_mul(&bx)?)?;
    Tensor::cat(&[x, y, z], D::Minus1)
}

/// A constant vector `[n]` of `dtype` on `device`.
pub fn constant(values: &[f64], dtype: DType, device: &Device) -> Result<Tensor> {
    Tensor::new(values, device)?.to_dtype(dtype)
}

/// `v / ‖v‖` for a constant 3-vector (validation guarantees a non-zero length).
pub fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(f64::MIN_POSITIVE);
    [v[0] / n, v[1] / n, v[2] / n]
}

/// Logistic function `σ(x) = (tanh(x/2) + 1)/2`, finite with a finite gradient for any `x`
/// (`1/(1 + e^{−x})` overflows to a NaN gradient for very negative `x`).
pub fn sigmoid(x: &Tensor) -> Result<Tensor> {
    ((x * 0.5)?.tanh()? + 1.0)? * 0.5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cross_dot_norm_by_hand() {
        let dev = Device::Cpu;
        let a = Tensor::new(&[[1.0f64, 0.0, 0.0]], &dev).unwrap();
        let b = Tensor::new(&[[0.0f64, 2.0, 0.0]], &dev).unwrap();
        assert_eq!(cross(&a, &b).unwrap().to_vec2::<f64>().unwrap(), vec![vec![0.0, 0.0, 2.0]]);
        assert_eq!(dot(&a, &b).unwrap().to_vec1::<f64>().unwrap(), vec![0.0]);
        let n = norm(&Tensor::new(&[[3.0f64, 4.0, 0.0]], &dev).unwrap()).unwrap().to_vec1::<f64>().unwrap();
        assert!((n[0] - 5.0).abs() < 1e-9);
        let xz = select_axes(&Tensor::new(&[[1.0f64, 2.0, 3.0]], &dev).unwrap(), Axes::Xz).unwrap();
        assert_eq!(xz.to_vec2::<f64>().unwrap(), vec![vec![1.0, 3.0]]);
        let s = sigmoid(&Tensor::new(&[-1e4f64, 0.0, 1e4], &dev).unwrap()).unwrap().to_vec1::<f64>().unwrap();
        assert_eq!(s, vec![0.0, 0.5, 1.0]);
    }
}
