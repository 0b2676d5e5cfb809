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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mean_is_the_sum_over_the_count_and_zero_for_none() {
        let values = [0.1, 0.2, 0.7, 1e-9];
        assert_eq!(mean(values).to_bits(), (values.iter().sum::<f64>() / 4.0).to_bits());
        assert_eq!(mean(std::iter::empty::<f64>()), 0.0);
    }
}
