//! Gaussian diffusion over normalised 263-d features: the denoiser contract, the cosine
//! schedule, DDIM sampling and inversion.

pub mod ddim;
mod denoiser;
mod error;
pub mod guidance;
pub mod noise;
pub mod schedule;
#[cfg(test)]
mod test_denoiser;

pub use ddim::{guided_move, respaced_timesteps, DdimMove, DdimProgress, DdimSampler};
pub use denoiser::Denoiser;
pub use error::DiffusionError;
pub use guidance::Guidance;
pub use schedule::NoiseSchedule;
