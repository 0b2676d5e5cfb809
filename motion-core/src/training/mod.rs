//! Training the MDM prior on a [`TrainingSet`] (the corpus's captioned clips, or a motion
//! database's labelled windows): x0-prediction MSE on random diffusion steps,
//! classifier-free-guidance condition dropout, AdamW with warm-up and cosine decay, EMA
//! weights, a fixed validation loss, and resumable checkpoints.

mod batches;
mod checkpoint;
mod config;
mod error;
mod geometric;
mod trainer;

pub use batches::{Batch, CaptionedSequences, Stretch, TrainingSet};
pub use checkpoint::{saved_model_config, TrainState};
pub use config::TrainConfig;
pub use error::TrainError;
pub use geometric::{GeometricLoss, GeometricTerms, CONTACT_SPEED_M_PER_S};
pub use trainer::{StepReport, Trainer};

#[cfg(test)]
mod tests;
