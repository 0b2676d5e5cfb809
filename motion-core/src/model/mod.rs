//! The MDM trans_enc denoiser.
