//! Helpers shared by the end-to-end tests.

#[path = "support/llm_server.rs"]
pub mod llm_server;

use std::path::PathBuf;

use candle_core::{Device, Tensor};
use motion_core::representation::{recover_from_ric, FeatureFrame, FEATURE_DIM};
use motion_core::skeleton::{Pose, NUM_JOINTS};

/// The repository's `fixtures/` folder.
pub fn fixtures() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..").join("fixtures")
}

/// Joint positions recovered from raw (de-normalised) features, via the differentiable path.
pub fn recover(features: &[FeatureFrame]) -> candle_core::Result<Vec<Pose>> {
    let flat: Vec<f32> = features.iter().flatten().copied().collect();
    let t = Tensor::from_vec(flat, (1, features.len(), FEATURE_DIM), &Device::Cpu)?;
    let joints = recover_from_ric(&t)?.squeeze(0)?.reshape((features.len(), NUM_JOINTS * 3))?.to_vec2::<f32>()?;
    Ok(joints
        .iter()
        .map(|row| {
            std::array::from_fn(|j| {
                glam::DVec3::new(f64::from(row[3 * j]), f64::from(row[3 * j + 1]), f64::from(row[3 * j + 2]))
            })
        })
        .collect())
}
