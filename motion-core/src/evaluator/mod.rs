//! Our own text–motion evaluator for the field's metrics (issue 40, item 3): a contrastive pair
//! in the manner of Guo et al. 2022 and TMR (Petrovich et al. 2023), trained on the corpus's
//! train split only, so that R-precision and FID of generated motions can be set beside the
//! same figures of held-out real motion on the same evaluator (the claim is the ratio; values
//! on other evaluators and data are not comparable).
//!
//! - **Motion encoder**: normalised features `[batch, frames, 263]` → a linear to width `d`,
//!   MDM's sinusoidal positions, [`EvaluatorConfig::layers`] post-LN transformer encoder layers
//!   (the same layer as the denoiser's), mean over frames, a linear to the embedding width,
//!   unit length.
//! - **Text head**: a 384-d all-MiniLM-L6-v2 sentence embedding → linear, GELU, linear to the
//!   embedding width, unit length.
//! - **Loss**: symmetric InfoNCE over a batch with temperature τ (eq. 1 of TMR), where pairs
//!   whose captions are the same sentence are not counted as negatives.
//!
//! [`r_precision`] and [`frechet_distance`] are the metrics computed on the embeddings.

mod encoders;
mod error;
mod metrics;
mod train;

pub use encoders::{Evaluator, EvaluatorConfig};
pub use error::EvaluatorError;
pub use metrics::{frechet_distance, r_precision};
pub use train::{EvaluatorStep, EvaluatorTrainer};
