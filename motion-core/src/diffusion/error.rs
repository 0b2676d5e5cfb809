//! What can go wrong configuring a noise schedule or a respaced sampler.

/// Errors configuring a noise schedule or a respaced sampler.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DiffusionError {
    /// A schedule with zero timesteps.
    #[error("a noise schedule needs at least one timestep")]
    EmptySchedule,
    /// No integer stride `s` gives `len(range(0, timesteps, s)) == steps` (MDM's "ddimN" rule).
    #[error("cannot respace {timesteps} timesteps into exactly {steps} DDIM steps with an integer stride")]
    NoStride {
        /// Timesteps of the original schedule.
        timesteps: usize,
        /// Requested DDIM steps.
        steps: usize,
    },
}
