//! Parsers of numeric flags: each value is checked (finite, in range) when the command line is
//! read, so a bad flag fails at once with its name and rule instead of after minutes of work or
//! as NaN in the outputs.

use std::ops::RangeInclusive;

use motion_core::import::check_clip_length;
use motion_core::limits::{BATCH_SAMPLES, PROGRAM_FRAMES};

/// A finite number in `range`.
fn number_in(text: &str, range: RangeInclusive<f64>) -> Result<f64, String> {
    let value: f64 = text.trim().parse().map_err(|_| format!("`{text}` is not a number"))?;
    if !value.is_finite() {
        return Err(format!("{value} is not a finite number"));
    }
    if !range.contains(&value) {
        return Err(format!("{value} is outside [{}, {}]", range.start(), range.end()));
    }
    Ok(value)
}

/// A whole number in `range`.
fn count_in(text: &str, range: RangeInclusive<usize>) -> Result<usize, String> {
    let value: usize = text.trim().parse().map_err(|_| format!("`{text}` is not a whole number ≥ 0"))?;
    if !range.contains(&value) {
        return Err(format!("{value} is outside {}..={}", range.start(), range.end()));
    }
    Ok(value)
}

/// A weight or scale: finite, in [0, 1e6].
pub fn weight(text: &str) -> Result<f64, String> {
    number_in(text, 0.0..=1e6)
}

/// A learning rate: finite, in (0, 10].
pub fn learning_rate(text: &str) -> Result<f64, String> {
    let value = number_in(text, 0.0..=10.0)?;
    if value == 0.0 {
        return Err("a learning rate must be above 0".into());
    }
    Ok(value)
}

/// A fraction: finite, in [0, 1].
pub fn fraction(text: &str) -> Result<f64, String> {
    number_in(text, 0.0..=1.0)
}

/// A sampling temperature of an LLM: finite, in [0, 2] (OpenAI's range).
pub fn temperature(text: &str) -> Result<f64, String> {
    number_in(text, 0.0..=2.0)
}

/// Frames per second: finite, in (0, 1000].
pub fn fps(text: &str) -> Result<f64, String> {
    let value = number_in(text, 0.0..=1000.0)?;
    if value == 0.0 {
        return Err("frames per second must be above 0".into());
    }
    Ok(value)
}

/// `--loop-seconds`: a positive, finite number of seconds whose 20 fps frames fit the limit on
/// an imported clip's length.
pub fn loop_seconds(text: &str) -> Result<f64, String> {
    let seconds = number_in(text, f64::MIN..=f64::MAX)?;
    if seconds <= 0.0 {
        return Err(format!("{seconds} s: the loop must last a positive number of seconds"));
    }
    check_clip_length(seconds, format_args!("--loop-seconds {text}")).map_err(|e| e.to_string())?;
    Ok(seconds)
}

/// Classifier-free guidance scale: finite, in [0, 100].
pub fn guidance(text: &str) -> Result<f64, String> {
    number_in(text, 0.0..=100.0)
}

/// Motions in one batch: 1 to [`BATCH_SAMPLES`].
pub fn samples(text: &str) -> Result<usize, String> {
    count_in(text, 1..=BATCH_SAMPLES.max_usize())
}

/// Optimisation steps or restarts: 1 to 100,000.
pub fn steps(text: &str) -> Result<usize, String> {
    count_in(text, 1..=100_000)
}

/// DDIM steps of a sampler: 1 to 1000 (the diffusion has 1000 timesteps).
pub fn ddim_steps(text: &str) -> Result<usize, String> {
    count_in(text, 1..=1000)
}

/// A diffusion timestep: 0 to 999.
pub fn timestep(text: &str) -> Result<usize, String> {
    count_in(text, 0..=999)
}

/// Frames of a generated motion: 2 to [`PROGRAM_FRAMES`].
pub fn frames(text: &str) -> Result<usize, String> {
    count_in(text, 2..=PROGRAM_FRAMES.max_usize())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_negative_and_out_of_range_values_are_refused() {
        assert_eq!(weight("1.5"), Ok(1.5));
        assert_eq!(weight("inf").unwrap_err(), "inf is not a finite number");
        assert_eq!(weight("nan").unwrap_err(), "NaN is not a finite number");
        assert!(weight("-1e30").unwrap_err().contains("outside [0, 1000000]"));
        assert!(learning_rate("0").unwrap_err().contains("above 0"));
        assert!(guidance("1e38").unwrap_err().contains("outside"));
        assert_eq!(samples("64"), Ok(64));
        assert!(samples("0").unwrap_err().contains("outside 1..=64"));
        assert!(samples("-3").unwrap_err().contains("not a whole number"));
        assert!(frames("5000").unwrap_err().contains("outside 2..=1000"));
        assert_eq!(timestep("0"), Ok(0));
    }
}
