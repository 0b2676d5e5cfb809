//! Per-sample figures read off tensors.

use candle_core::{DType, Tensor};

use crate::numeric::mean;

/// A per-sample figure `[B]` as `f64`s.
pub(super) fn to_vec(t: &Tensor) -> candle_core::Result<Vec<f64>> {
    t.to_dtype(DType::F64)?.to_vec1::<f64>()
}

/// The mean over the samples of a per-sample figure `[B]`.
pub(super) fn scalar(t: &Tensor) -> candle_core::Result<f64> {
    Ok(mean(to_vec(t)?))
}
