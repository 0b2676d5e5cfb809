//! Small numeric helpers shared by every layer.

use std::borrow::Borrow;

/// The arithmetic mean of `values`, summed in order (the same bits as `sum / len`); 0 for none.
pub fn mean<T: Borrow<f64>>(values: impl IntoIterator<Item = T>) -> f64 {
    let mut count = 0usize;
    let sum: f64 = values.into_iter().inspect(|_| count += 1).map(|v| *v.borrow()).sum();
    if count == 0 {
        0.0
    } else {
        sum / count as f64
    }
}

/// The population standard deviation of `values` about their [`mean`]; 0 for none.
pub fn standard_deviation(values: &[f64]) -> f64 {
    let m = mean(values);
    mean(values.iter().map(|x| (x - m) * (x - m))).sqrt()
}

/// A smooth envelope over non-negative `values` per frame that never falls short of any frame's
/// own value: each value dilated (the largest within ±`radius` frames, at least 0), then averaged
/// over the same window. Every window holding frame t holds only values ≥ t's, so a change (a
/// lift, a drop) rises and falls over `radius` frames instead of popping. `NaN` values are
/// skipped by the dilation.
pub fn eased_envelope(values: &[f64], radius: usize) -> Vec<f64> {
    let window = |t: usize| t.saturating_sub(radius)..(t + radius + 1).min(values.len());
    let dilated: Vec<f64> = (0..values.len()).map(|t| values[window(t)].iter().copied().fold(0.0, f64::max)).collect();
    (0..values.len()).map(|t| mean(dilated[window(t)].iter().copied())).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_envelope_covers_every_value_and_eases_in_and_out() {
        let values = [0.0, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let envelope = eased_envelope(&values, 2);
        assert!(envelope.iter().zip(&values).all(|(e, v)| e >= v), "{envelope:?}");
        assert_eq!(envelope[3], 0.3);
        assert!(envelope[0] > 0.0 && envelope[0] < envelope[1] && envelope[9] == 0.0, "{envelope:?}");
        assert!(eased_envelope(&[], 2).is_empty());
    }

    #[test]
    fn the_mean_is_the_sum_over_the_count_and_zero_for_none() {
        let values = [0.1, 0.2, 0.7, 1e-9];
        assert_eq!(mean(values).to_bits(), (values.iter().sum::<f64>() / 4.0).to_bits());
        assert_eq!(mean(std::iter::empty::<f64>()), 0.0);
    }

    #[test]
    fn the_standard_deviation_is_about_the_mean_and_zero_for_none() {
        assert_eq!(standard_deviation(&[2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]), 2.0);
        assert_eq!(standard_deviation(&[3.0]), 0.0);
        assert_eq!(standard_deviation(&[]), 0.0);
    }
}
