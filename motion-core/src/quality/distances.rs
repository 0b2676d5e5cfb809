//! Distances between sets of motion crops: heading-free descriptors, the nearest and the mean
//! pairwise RMS joint distance.

use candle_core::Tensor;

use crate::representation::RIC;

/// Heading-free pose descriptors `[n, frames·63]`: the root-relative joint positions (ric) of
/// raw features `[frames, 263]` each.
pub(super) fn descriptors(raw: &[Tensor]) -> candle_core::Result<Tensor> {
    let rows = raw
        .iter()
        .map(|x| x.narrow(1, RIC.start, RIC.len())?.flatten_all())
        .collect::<candle_core::Result<Vec<_>>>()?;
    Tensor::stack(&rows, 0)
}

/// Mean over rows of `a` of the RMS per-joint distance to the nearest row of `b` allowed by
/// `allowed(i, j)`.
pub(super) fn nearest_distances(
    a: &Tensor,
    b: &Tensor,
    allowed: impl Fn(usize, usize) -> bool,
) -> candle_core::Result<f64> {
    let d2 = pairwise_sq(a, b)?.to_vec2::<f32>()?;
    let joints_frames = (a.dim(1)? / 3) as f64;
    let mut total = 0.0;
    let mut n = 0;
    for (i, row) in d2.iter().enumerate() {
        let best = row
            .iter()
            .enumerate()
            .filter(|(j, _)| allowed(i, *j))
            .map(|(_, d)| f64::from(*d))
            .fold(f64::INFINITY, f64::min);
        if best.is_finite() {
            total += (best.max(0.0) / joints_frames).sqrt();
            n += 1;
        }
    }
    Ok(if n == 0 { f64::NAN } else { total / n as f64 })
}

pub(super) fn mean_pairwise(a: &Tensor) -> candle_core::Result<f64> {
    let d2 = pairwise_sq(a, a)?.to_vec2::<f32>()?;
    let joints_frames = (a.dim(1)? / 3) as f64;
    let n = d2.len();
    let mut total = 0.0;
    for (i, row) in d2.iter().enumerate() {
        for (j, d) in row.iter().enumerate() {
            if i != j {
                total += (f64::from(*d).max(0.0) / joints_frames).sqrt();
            }
        }
    }
    Ok(if n < 2 { 0.0 } else { total / (n * (n - 1)) as f64 })
}

/// Squared Euclidean distances `[a_rows, b_rows]`.
fn pairwise_sq(a: &Tensor, b: &Tensor) -> candle_core::Result<Tensor> {
    let a2 = a.sqr()?.sum_keepdim(1)?;
    let b2 = b.sqr()?.sum_keepdim(1)?.t()?;
    a2.broadcast_add(&b2)?.broadcast_sub(&(a.matmul(&b.t()?)? * 2.0)?)
}
