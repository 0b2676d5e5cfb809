//! Diffusion noise optimisation (DNO): constrained motion generation by optimising the start
//! noise z of a frozen diffusion prior through its unrolled DDIM sampler.
//!
//! Karunratanakul, Preechakul, Aksan, Beeler, Suwajanakorn & Tang, "Optimizing Diffusion Noise
//! Can Serve As Universal Motion Priors", CVPR 2024; reference code `dno.py` of
//! korrawe/Diffusion-Noise-Optimization (anchors §2.1–2.3). Shapes: z and x are
//! `[batch, frames, 263]` normalised features; a criterion returns one loss per sample.
//!
//! - [`DnoConfig`]: DNO's settings with its defaults and lr schedule;
//! - [`Solver`] / [`UnrolledDdim`]: the differentiable map z → x;
//! - [`noise_regularize_1d`]: the noise decorrelation regulariser;
//! - [`optimize`]: the loop; [`optimize_until`]: the loop that may end before its budget;
//!   [`optimize_with_restarts`]: best of N_S random restarts.

mod config;
mod optimize;
mod regularizer;
mod solver;
#[cfg(test)]
mod tests;

pub use config::DnoConfig;
pub(crate) use optimize::per_sample_norm;
pub(crate) use optimize::{beats, take_rows};
pub use optimize::{
    optimize, optimize_until, optimize_with_restarts, DnoResult, DnoStep, RestartsResult, SampleHistory,
};
pub use regularizer::{decorrelation_terms, noise_regularize_1d};
pub use solver::{Solver, UnrolledDdim};
