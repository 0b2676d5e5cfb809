//! The MDM `trans_enc` denoiser (Tevet et al., "Human Motion Diffusion Model", ICLR 2023),
//! with the official checkpoint's parameter names (anchors §1.3, §1.6).
//!
//! Layout here is `[batch, frames, 263]` (MDM uses `[batch, 263, 1, frames]`). Two paths:
//! - [`Denoiser::predict_x0`]: frozen weights, fused custom ops whose backward returns only
//!   the input gradient (sampling and the DNO loop);
//! - [`Mdm::forward_train`] / [`Mdm::forward_eval`]: primitive candle ops for everything with
//!   weights, so weights held as `Var`s get gradients; the former applies dropout as
//!   PyTorch's training mode.
//!
//! [`Denoiser::predict_x0`]: crate::diffusion::Denoiser::predict_x0

pub mod bench;
mod config;
mod fused_stack;
pub(crate) mod init;
pub(crate) mod layer;
mod mdm;
mod positions;
#[cfg(test)]
mod tests;

pub use config::{MdmConfig, Prediction};
pub use mdm::Mdm;
pub use positions::{sinusoidal_table, MAX_LEN};
