//! Random training batches: label-balanced windows, one crop length per batch.

use candle_core::{Device, Tensor};
use rand::Rng;

use super::{TrainConfig, TrainError};
use crate::database::{MotionDatabase, Window};
use crate::representation::FEATURE_DIM;
use crate::text::vocabulary::VocabularyEncoder;
use crate::text::TextEncoder;

/// A batch of normalised crops with their condition vectors.
#[derive(Debug, Clone)]
pub struct Batch {
    /// `[batch, frames, 263]`, normalised.
    pub x0: Tensor,
    /// `[batch, text_dim]`, the labels encoded.
    pub text: Tensor,
}

/// Draws batches from a database.
pub struct BatchSampler {
    /// Normalised features of every window, `[frames, 263]` each, with its label's row.
    windows: Vec<(Tensor, usize)>,
    /// Window indices per label.
    by_label: Vec<Vec<usize>>,
    /// Encoded labels `[labels, text_dim]`.
    label_text: Tensor,
    batch_size: usize,
    min_frames: usize,
    max_frames: usize,
    balance: bool,
}

impl BatchSampler {
    /// Normalises every window once, up front.
    pub fn new(
        db: &MotionDatabase,
        encoder: &VocabularyEncoder,
        config: &TrainConfig,
        device: &Device,
    ) -> Result<Self, TrainError> {
        let labels = db.labels();
        let label_text = encoder.encode(&labels.iter().map(String::as_str).collect::<Vec<_>>(), device)?;
        let mut by_label = vec![Vec::new(); labels.len()];
        let mut windows = Vec::new();
        let usable: Vec<&Window> = db.windows().iter().filter(|w| w.frames >= config.min_frames).collect();
        for w in usable {
            let label = labels
                .binary_search_by(|l| l.as_str().cmp(db.label(w)))
                .map_err(|_| TrainError::Data(format!("window {w:?} has a label missing from the label list")))?;
            let x = db.mean_std().to_device(device)?.normalize(&db.window_tensor(w, device)?)?;
            by_label[label].push(windows.len());
            windows.push((x, label));
        }
        by_label.retain(|v| !v.is_empty());
        if windows.is_empty() {
            return Err(TrainError::Data(format!("no window has at least {} frames", config.min_frames)));
        }
        if config.min_frames > config.max_frames || config.batch_size == 0 {
            return Err(TrainError::Data("need batch_size > 0 and min_frames <= max_frames".into()));
        }
        Ok(Self {
            windows,
            by_label,
            label_text,
            batch_size: config.batch_size,
            min_frames: config.min_frames,
            max_frames: config.max_frames,
            balance: config.balance_labels,
        })
    }

    /// One batch: a crop length uniform in [min, max] frames, then windows (label-balanced if
    /// configured) long enough for it, each cropped at a random offset.
    pub fn sample(&self, rng: &mut impl Rng) -> Result<Batch, TrainError> {
        let frames = rng.random_range(self.min_frames..=self.max_frames);
        let long_enough: Vec<Vec<usize>> = self
            .by_label
            .iter()
            .map(|ids| ids.iter().copied().filter(|&i| self.windows[i].0.dims()[0] >= frames).collect::<Vec<_>>())
            .filter(|ids: &Vec<usize>| !ids.is_empty())
            .collect();
        // Fall back to the shortest crop every window can give when none is long enough.
        let (frames, pools) =
            if long_enough.is_empty() { (self.min_frames, self.by_label.clone()) } else { (frames, long_enough) };
        let all: Vec<usize> = pools.iter().flatten().copied().collect();
        let mut crops = Vec::with_capacity(self.batch_size);
        let mut rows = Vec::with_capacity(self.batch_size);
        for _ in 0..self.batch_size {
            let i = if self.balance {
                let pool = &pools[rng.random_range(0..pools.len())];
                pool[rng.random_range(0..pool.len())]
            } else {
                all[rng.random_range(0..all.len())]
            };
            let (x, label) = &self.windows[i];
            let offset = rng.random_range(0..=x.dims()[0] - frames);
            crops.push(x.narrow(0, offset, frames)?);
            rows.push(*label as u32);
        }
        let ids = Tensor::from_vec(rows, self.batch_size, self.label_text.device())?;
        let x0 = Tensor::stack(&crops, 0)?;
        debug_assert_eq!(x0.dims()[2], FEATURE_DIM);
        Ok(Batch { x0, text: self.label_text.index_select(&ids, 0)? })
    }
}
