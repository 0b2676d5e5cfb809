//! Differentiable counting (RG-DNO supp. D, eqs. 15–16): soft counts of the peaks or valleys of
//! scalar signals, e.g. steps as peaks of the foot speed, claps as valleys of the hand distance.

use candle_core::{Result, Tensor, D};

use super::geometry::sigmoid;
use crate::program::Extremum;

/// Soft number of extrema of `s` `[B, n]` at the interior frames listed in `frames` (indices of
/// `s`; frames 0 and n − 1 have no two neighbours and are skipped), `[B]`:
/// - peaks: `Σ_t σ(T(s[t]−s[t+1]))·σ(T(s[t]−s[t−1]))·σ(T(s[t]−θ))`;
/// - valleys: `Σ_t σ(T(s[t+1]−s[t]))·σ(T(s[t−1]−s[t]))·σ(T(θ−s[t]))`.
///
/// `T` is the sharpness per unit of the signal, `θ` the threshold.
pub fn soft_count(s: &Tensor, frames: &[usize], extremum: Extremum, threshold: f64, sharpness: f64) -> Result<Tensor> {
    let (batch, n) = s.dims2()?;
    let interior: Vec<u32> = frames.iter().filter(|&&t| t >= 1 && t + 1 < n).map(|&t| t as u32).collect();
    if interior.is_empty() {
        return Tensor::zeros(batch, s.dtype(), s.device());
    }
    let pick = |offset: i64| -> Result<Tensor> {
        let index: Vec<u32> = interior.iter().map(|&t| (i64::from(t) + offset) as u32).collect();
        s.contiguous()?.index_select(&Tensor::from_vec(index, interior.len(), s.device())?, 1)
    };
    let (centre, next, previous) = (pick(0)?, pick(1)?, pick(-1)?);
    let sign = match extremum {
        Extremum::Peaks => 1.0,
        Extremum::Valleys => -1.0,
    };
    let above = |d: Tensor| sigmoid(&(d * (sign * sharpness))?);
    let score = ((above((&centre - &next)?)? * above((&centre - &previous)?)?)? * above((&centre - threshold)?)?)?;
    score.sum(D::Minus1)
}

/// Box filter of odd width `w` along axis 1 of `s` `[B, n]`, "valid" mode: `[B, n − w + 1]`,
/// output frame i is the mean of input frames i..i+w (centred on input frame i + (w − 1)/2).
pub fn box_filter(s: &Tensor, w: usize) -> Result<Tensor> {
    let n = s.dim(1)?;
    if w <= 1 {
        return Ok(s.clone());
    }
    if w > n {
        candle_core::bail!("smoothing over {w} frames needs a signal of at least {w} frames, it has {n}");
    }
    let len = n - w + 1;
    let mut sum = s.narrow(1, 0, len)?;
    for k in 1..w {
        sum = (sum + s.narrow(1, k, len)?)?;
    }
    sum / w as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn counts_sharp_peaks_and_valleys_by_hand() {
        let s = Tensor::new(&[[0.0f64, 2.0, 0.0, 0.5, 0.0, 3.0, 1.0, 1.0]], &Device::Cpu).unwrap();
        let all: Vec<usize> = (0..8).collect();
        // Peaks above 1: frames 1 and 5 (the 0.5 bump is below θ).
        let peaks = soft_count(&s, &all, Extremum::Peaks, 1.0, 1e4).unwrap().to_vec1::<f64>().unwrap();
        assert!((peaks[0] - 2.0).abs() < 1e-9, "{peaks:?}");
        // Valleys below 0.25: frames 2 and 4.
        let valleys = soft_count(&s, &all, Extremum::Valleys, 0.25, 1e4).unwrap().to_vec1::<f64>().unwrap();
        assert!((valleys[0] - 2.0).abs() < 1e-9, "{valleys:?}");
        // Only frames 0..=3 searched: one peak.
        let first = soft_count(&s, &[0, 1, 2, 3], Extremum::Peaks, 1.0, 1e4).unwrap().to_vec1::<f64>().unwrap();
        assert!((first[0] - 1.0).abs() < 1e-9);
        let smooth = box_filter(&s, 3).unwrap().to_vec2::<f64>().unwrap();
        assert!((smooth[0][0] - 2.0 / 3.0).abs() < 1e-12 && smooth[0].len() == 6);
    }
}
