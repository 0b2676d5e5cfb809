//! What every restart of RG-DNO's stages shares.

use candle_core::Tensor;

use super::config::RgDnoConfig;
use crate::cleanup::FootLockConfig;
use crate::constraints::CompiledProgram;
use crate::diffusion::Denoiser;
use crate::dno::UnrolledDdim;
use crate::generation::method::GenerationConfig;
use crate::prior::Prior;
use crate::program::ConstraintGroups;

/// What every restart shares: the compiled task and its groups, the settings, the solvers of
/// one job (`R` rows: 1, or every sample for a counting program; `2R` for the branches), the
/// inverted noise `z_R` `[R, T, 263]` and the clean-up the generation ends with.
pub(super) struct Stages<'a, M: Denoiser + ?Sized> {
    pub(super) prior: &'a Prior,
    pub(super) compiled: &'a CompiledProgram,
    pub(super) groups: &'a ConstraintGroups,
    pub(super) config: &'a GenerationConfig,
    pub(super) rg: &'a RgDnoConfig,
    /// The final round's solver, which also samples the restart's unoptimised motion.
    pub(super) solver: &'a UnrolledDdim<'a, M>,
    /// The solver of the mask search, the soft blend and the final round's start (`solver` on
    /// fewer timesteps and without guidance under
    /// [`crate::generation::rgdno::config::RgDnoConfig::early_stride`] and
    /// [`crate::generation::rgdno::config::RgDnoConfig::early_unguided`]).
    pub(super) early: &'a UnrolledDdim<'a, M>,
    pub(super) both: &'a UnrolledDdim<'a, M>,
    pub(super) z_r: &'a Tensor,
    pub(super) foot_lock: &'a FootLockConfig,
}
