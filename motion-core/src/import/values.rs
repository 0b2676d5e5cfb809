//! Checks and printing of imported values: positions within reach, clip lengths within
//! [`CLIP_FRAMES`], finite numbers, and numbers as messages print them.

use crate::limits::{LimitExceeded, CLIP_FRAMES};
use crate::skeleton::FPS;

/// Largest distance of an imported position from the origin after unit scaling, m. Real
/// captures stay within a few hundred metres; beyond this a value is a unit or export error,
/// and far beyond it the features overflow.
pub const MAX_POSITION_M: f64 = 1e4;

/// Whether a coordinate, m, is finite and within [`MAX_POSITION_M`] of zero.
pub(crate) fn in_reach(v_m: f64) -> bool {
    v_m.abs() <= MAX_POSITION_M
}

/// Frames of a clip of `duration_s` seconds sampled at 20 fps (what [`resample`](super::resample) makes of it at
/// speed 1), checked against [`CLIP_FRAMES`] before anything is allocated for them. `what`
/// names the file and where its length comes from.
pub fn check_clip_length(duration_s: f64, what: impl std::fmt::Display) -> Result<(), LimitExceeded> {
    let frames = duration_s * FPS;
    // Saturating: a non-finite duration is reported as the largest count.
    let count = if frames.is_finite() && frames >= 0.0 { (frames.floor() as u64).saturating_add(1) } else { u64::MAX };
    CLIP_FRAMES.check(count, what)
}

/// A number as messages print it: as written for ordinary magnitudes, in exponent form when
/// huge or tiny (`1e308`, not 309 digits).
pub fn short_number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e6).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// A finite number, or `None`.
pub(crate) fn parse_finite(tok: &str) -> Option<f64> {
    tok.parse::<f64>().ok().filter(|v| v.is_finite())
}
