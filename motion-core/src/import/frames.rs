//! Frame timing of the captures sampled at a fixed rate (BVH, AMC): where a time falls between
//! two frames.

/// The frames `(k, k + 1)` around `t_s` (seconds) in a clip of `frames` frames `frame_time_s`
/// apart, and the fraction of the way from the first to the second; times outside the clip
/// (and NaN) hold its end frames.
pub(crate) fn bracket(t_s: f64, frames: usize, frame_time_s: f64) -> (usize, usize, f64) {
    let last = frames.saturating_sub(1);
    let x = (t_s / frame_time_s).clamp(0.0, last as f64);
    let x = if x.is_nan() { 0.0 } else { x };
    let k = (x.floor() as usize).min(last);
    let k1 = (k + 1).min(last);
    (k, k1, x - k as f64)
}
