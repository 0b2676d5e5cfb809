//! Test utilities shared by the crate's tests and the workspace's end-to-end tests.

use candle_core::{DType, Result, Tensor, Var};

/// Checks the gradient of a scalar function against central finite differences.
///
/// Fails when no gradient reaches `x`, when it is not finite, when it is zero at every checked
/// coordinate, or when a checked coordinate disagrees.
///
/// `x` must be f64. Up to 12 coordinates with a non-zero analytic gradient and 24 spread over the
/// tensor are perturbed by `eps`; each
/// analytic partial derivative must match within `tol · max(1, |numeric|)`. A missing gradient
/// is an error, never a silent pass (candle returns `None` for ops without a backward).
pub fn finite_difference_check(x: &Tensor, f: impl Fn(&Tensor) -> Result<Tensor>, eps: f64, tol: f64) -> Result<()> {
    if x.dtype() != DType::F64 {
        candle_core::bail!("finite_difference_check needs an f64 input, got {:?}", x.dtype());
    }
    let var = Var::from_tensor(x)?;
    let y = f(var.as_tensor())?;
    let grads = y.backward()?;
    let grad = grads
        .get(var.as_tensor())
        .ok_or_else(|| candle_core::Error::Msg("no gradient reached the input".into()))?
        .flatten_all()?
        .to_vec1::<f64>()?;
    let base = x.flatten_all()?.to_vec1::<f64>()?;
    let n = base.len();
    let picks = 24.min(n);
    // Half the checks where the analytic gradient is non-zero (sparse losses touch few
    // coordinates), half spread over the whole tensor.
    let nonzero: Vec<usize> = (0..n).filter(|&i| grad[i] != 0.0).collect();
    let mut checked: Vec<usize> =
        (0..picks / 2).filter_map(|k| nonzero.get(k * nonzero.len() / (picks / 2).max(1))).copied().collect();
    checked.extend((0..picks).map(|k| (k * n / picks + (k * 7919) % (n / picks).max(1)).min(n - 1)));
    checked.sort_unstable();
    checked.dedup();
    let mut max_abs_grad: f64 = 0.0;
    for i in checked {
        let eval = |delta: f64| -> Result<f64> {
            let mut v = base.clone();
            v[i] += delta;
            let t = Tensor::from_vec(v, x.shape(), x.device())?;
            f(&t)?.to_dtype(DType::F64)?.to_scalar::<f64>()
        };
        let numeric = (eval(eps)? - eval(-eps)?) / (2.0 * eps);
        max_abs_grad = max_abs_grad.max(grad[i].abs());
        if (grad[i] - numeric).abs() > tol * numeric.abs().max(1.0) {
            candle_core::bail!("gradient mismatch at flat index {i}: analytic {} vs numeric {numeric}", grad[i]);
        }
    }
    if grad.iter().any(|g| !g.is_finite()) {
        candle_core::bail!("non-finite gradient");
    }
    if max_abs_grad == 0.0 {
        candle_core::bail!("the gradient is zero at every checked coordinate");
    }
    Ok(())
}

/// The largest absolute element-wise difference of two tensors of one shape (any float dtype,
/// compared in f64).
pub fn max_abs_diff(a: &Tensor, b: &Tensor) -> Result<f64> {
    (a.to_dtype(DType::F64)? - b.to_dtype(DType::F64)?)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f64>()
}

/// The JSON of a constraint program that pins the pelvis and both wrists of `joints`
/// `[T, 22, 3]` (m) at four keyframes (the first, a third, two thirds, the last frame), with
/// `text` as its prompt and, when `parse` is true, a relational parse whose most difficult
/// constraint is the first pin `c1`. A program that a motion meets exactly where it was made
/// from, for the retrieval tests.
pub fn pinned_program_json(joints: &Tensor, text: &str, parse: bool) -> Result<String> {
    let joints = joints.to_dtype(DType::F64)?.to_vec3::<f64>()?;
    let frames = joints.len();
    let mut constraints = Vec::new();
    for t in [0, frames / 3, 2 * frames / 3, frames.saturating_sub(1)] {
        for (name, j) in [("pelvis", 0), ("left_wrist", 20), ("right_wrist", 21)] {
            let p = &joints[t][j];
            constraints.push(format!(
                r#"{{"id": "c{}", "expr": {{"op": "equal", "quantity": {{"kind": "position", "of": {{"joint": "{name}"}}, "axes": "xyz"}},
                   "target": [{}, {}, {}], "frames": {{"keyframes": [{{"frame": {t}}}]}}}}}}"#,
                constraints.len() + 1,
                p[0],
                p[1],
                p[2]
            ));
        }
    }
    let parse = if parse {
        r#", "relational_parse": {"most_difficult": "c1", "connected": [], "conflicting": [], "retrieval_confidence": 1.0}"#
    } else {
        ""
    };
    Ok(format!(r#"{{"text": "{text}", "frames": {frames}, "constraints": [{}]{parse}}}"#, constraints.join(",")))
}
