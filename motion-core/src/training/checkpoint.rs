//! Resumable training checkpoints: weights, EMA weights, optimiser moments and the step, in one
//! safetensors file (`model.*`, `ema.*`, `adam_m.*`, `adam_v.*`; metadata `step`, `train_config`,
//! `mdm_config`).

use std::collections::HashMap;
use std::path::Path;

use candle_core::Tensor;

use crate::model::MdmConfig;
use crate::tensor_file::{read_file_metadata, read_metadata, write_safetensors};

use super::error::TrainError;
use super::trainer::Trainer;

/// The model a checkpoint or a written prior was made with (its `mdm_config`), so that a
/// resumed run or a fine-tune can take its sizes from the file instead of from the caller.
pub fn saved_model_config(path: &Path) -> Result<MdmConfig, TrainError> {
    let err = |message: String| TrainError::Checkpoint { path: path.into(), message };
    let meta = read_file_metadata(path).map_err(err)?;
    model_config(&meta).map(|(config, _)| config).map_err(err)
}

/// The `mdm_config` of a file's metadata, parsed (not compared as text, so fields added later
/// with defaults still match), beside its text for messages.
fn model_config(meta: &HashMap<String, String>) -> Result<(MdmConfig, &str), String> {
    let saved = meta.get("mdm_config").ok_or("no mdm_config in metadata")?;
    let config = serde_json::from_str(saved).map_err(|e| format!("mdm_config: {e}"))?;
    Ok((config, saved))
}

/// Summary of a checkpoint, for display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrainState {
    /// Steps done.
    pub step: usize,
}

impl Trainer {
    /// Writes a checkpoint (atomically: a temporary file renamed into place).
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), TrainError> {
        let err = |message: String| TrainError::Checkpoint { path: path.into(), message };
        let (m, v) = self.optimizer.moments();
        let mut tensors: Vec<(String, Tensor)> = Vec::with_capacity(4 * self.vars.len());
        for (i, (name, var)) in self.vars.iter().enumerate() {
            tensors.push((format!("model.{name}"), var.as_tensor().clone()));
            tensors.push((format!("ema.{name}"), self.ema[i].clone()));
            tensors.push((format!("adam_m.{name}"), m[i].clone()));
            tensors.push((format!("adam_v.{name}"), v[i].clone()));
        }
        let metadata = HashMap::from([
            ("step".to_owned(), self.step.to_string()),
            ("train_config".to_owned(), serde_json::to_string(&self.config).map_err(|e| err(e.to_string()))?),
            ("mdm_config".to_owned(), serde_json::to_string(&self.model_config).map_err(|e| err(e.to_string()))?),
        ]);
        let tmp = path.with_extension("tmp");
        write_safetensors(&tmp, &tensors, metadata).map_err(err)?;
        std::fs::rename(&tmp, path).map_err(|e| err(e.to_string()))
    }

    /// Restores weights, EMA, optimiser state and step from a checkpoint of the same model.
    pub fn resume(&mut self, path: &Path) -> Result<TrainState, TrainError> {
        let err = |message: String| TrainError::Checkpoint { path: path.into(), message };
        let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
        let meta = read_metadata(&bytes).map_err(err)?;
        let step: usize =
            meta.get("step").and_then(|s| s.parse().ok()).ok_or_else(|| err("no step in metadata".into()))?;
        let (saved, saved_cfg) = model_config(&meta).map_err(err)?;
        if saved != self.model_config {
            return Err(err(format!("the model differs: checkpoint {saved_cfg}")));
        }
        let tensors = candle_core::safetensors::load_buffer(&bytes, &self.device).map_err(|e| err(e.to_string()))?;
        let get = |prefix: &str, name: &str| {
            tensors.get(&format!("{prefix}.{name}")).cloned().ok_or_else(|| err(format!("missing `{prefix}.{name}`")))
        };
        let (mut m, mut v) = (Vec::new(), Vec::new());
        for (i, (name, var)) in self.vars.iter().enumerate() {
            var.set(&get("model", name)?)?;
            self.ema[i] = get("ema", name)?;
            m.push(get("adam_m", name)?);
            v.push(get("adam_v", name)?);
        }
        self.optimizer.restore(m, v, step)?;
        self.step = step;
        Ok(TrainState { step })
    }

    /// Starts a fine-tune of a written prior (a file of [`Prior::write`](crate::prior::Prior::write)):
    /// its weights become the model's and the EMA's, at step 0 with fresh optimiser moments.
    /// The prior must be of this model's size and normalised with this training set's
    /// statistics (the same corpus split), so that its weights mean the same here.
    pub fn init_from_prior(&mut self, path: &Path) -> Result<(), TrainError> {
        let err = |message: String| TrainError::Checkpoint { path: path.into(), message };
        let bytes = std::fs::read(path).map_err(|e| err(e.to_string()))?;
        let meta = read_metadata(&bytes).map_err(err)?;
        let (saved, saved_cfg) = model_config(&meta).map_err(err)?;
        if saved != self.model_config {
            return Err(err(format!("the model differs: the prior is {saved_cfg}")));
        }
        let tensors = candle_core::safetensors::load_buffer(&bytes, &self.device).map_err(|e| err(e.to_string()))?;
        let stats = self.data.mean_std();
        for (key, ours) in [("normalization.mean", stats.mean()), ("normalization.std", stats.std())] {
            let theirs = tensors.get(key).ok_or_else(|| err(format!("missing `{key}`")))?;
            let gap = (theirs - ours)?.abs()?.max_all()?.to_scalar::<f32>()?;
            if gap.is_nan() || gap > 1e-4 {
                return Err(err(format!("`{key}` differs from this training set's by {gap}: trained on other data")));
            }
        }
        for (i, (name, var)) in self.vars.iter().enumerate() {
            let w = tensors.get(name).ok_or_else(|| err(format!("missing `{name}`")))?;
            var.set(w)?;
            self.ema[i] = w.copy()?.detach();
        }
        self.step = 0;
        Ok(())
    }
}
