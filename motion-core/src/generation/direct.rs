//! The IK and IK+Reg baselines: Adam on the motion features themselves (ProgMoGen's
//! `task_configs_eval_others`: lr 1e-2, 100 iterations; IK+reg adds the mean squared difference
//! of consecutive frames of the root, ric and rotation features).

use candle_core::{Result, Tensor, Var, D};

use crate::generation::method::DirectConfig;
use crate::optim::AdamW;
use crate::representation::ROT;

/// Optimises the features `x0` `[B, T, 263]` (normalised) to lower `criterion` `[B]`, plus
/// `smoothness ×` the frame-difference term. Returns the features of the last forward (as DNO
/// does) and the per-sample criterion history.
pub(super) fn optimize_motion(
    x0: &Tensor,
    criterion: &impl Fn(&Tensor) -> Result<Tensor>,
    config: &DirectConfig,
    smoothness: f64,
    mut on_step: impl FnMut(usize, f64),
) -> Result<(Tensor, Vec<Vec<f64>>)> {
    let batch = x0.dim(0)?;
    let x = Var::from_tensor(&x0.detach())?;
    let mut adam = AdamW::new(vec![x.clone()], 0.0)?;
    let mut history = vec![Vec::with_capacity(config.steps); batch];
    let mut last = x0.detach();
    for step in 0..config.steps {
        let loss = criterion(x.as_tensor())?;
        let values = loss.to_dtype(candle_core::DType::F64)?.to_vec1::<f64>()?;
        for (h, &v) in history.iter_mut().zip(&values) {
            h.push(v);
        }
        let mut total = loss.sum_all()?;
        if smoothness > 0.0 {
            total = (total + (frame_difference(x.as_tensor())?.sum_all()? * smoothness)?)?;
        }
        last = x.as_tensor().detach().copy()?;
        let grads = total.backward()?;
        adam.step(&grads, config.lr)?;
        on_step(step, values.iter().sum::<f64>() / batch as f64);
    }
    Ok((last, history))
}

/// Mean over frames of `‖x[t+1] − x[t]‖²` over the root, ric and rotation features, `[B]`.
fn frame_difference(x: &Tensor) -> Result<Tensor> {
    let frames = x.dim(1)?;
    if frames < 2 {
        return Tensor::zeros(x.dim(0)?, x.dtype(), x.device());
    }
    let pose = x.narrow(D::Minus1, 0, ROT.end)?;
    let d = (pose.narrow(1, 1, frames - 1)? - pose.narrow(1, 0, frames - 1)?)?;
    d.sqr()?.sum(D::Minus1)?.mean(D::Minus1)
}
