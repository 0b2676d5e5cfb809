//! Text conditioning behind a small encoder seam.

pub mod clip;
