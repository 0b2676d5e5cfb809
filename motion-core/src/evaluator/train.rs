//! Training the evaluator on batches of normalised crops and their captions' sentence
//! embeddings (the prior's training batches serve): AdamW on the symmetric InfoNCE loss.

use candle_core::{DType, Device, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};

use super::encoders::{Evaluator, EvaluatorConfig};
use super::error::EvaluatorError;
use crate::nn::unit_rows;
use crate::optim::AdamW;
use crate::representation::MeanStd;

/// Captions whose sentence embeddings have a dot product above this are the same sentence.
const SAME_CAPTION_DOT: f32 = 0.9999;

/// What one step reports.
#[derive(Debug, Clone, Copy)]
pub struct EvaluatorStep {
    /// 1-based step just done.
    pub step: usize,
    /// The InfoNCE loss of the batch.
    pub loss: f64,
    /// Share of the batch's motions whose nearest text (among the batch's) is their own.
    pub accuracy: f64,
}

/// An evaluator in training.
pub struct EvaluatorTrainer {
    model: Evaluator,
    vars: Vec<(String, Var)>,
    optimizer: AdamW,
    step: usize,
}

impl EvaluatorTrainer {
    /// A fresh evaluator with seeded weights, for features normalised by `mean_std` (the
    /// training data's).
    pub fn new(config: EvaluatorConfig, mean_std: MeanStd, device: &Device, seed: u64) -> Result<Self, EvaluatorError> {
        let varmap = VarMap::new();
        let model = Evaluator::init_seeded(config, mean_std, &varmap, device, seed)?;
        let vars = crate::model::init::named_vars(&varmap, model.named_parameters())?;
        let optimizer = AdamW::new(vars.iter().map(|(_, v)| v.clone()).collect(), 0.0)?;
        Ok(Self { model, vars, optimizer, step: 0 })
    }

    /// Steps done.
    pub fn step(&self) -> usize {
        self.step
    }

    /// One optimiser step at learning rate `lr` on normalised crops `x0` `[batch, frames, 263]`
    /// and their captions' sentence embeddings `text` `[batch, text_dim]`.
    pub fn train_step(&mut self, x0: &Tensor, text: &Tensor, lr: f64) -> Result<EvaluatorStep, EvaluatorError> {
        let unit_text = unit_rows(text)?;
        let dots: Vec<Vec<f32>> = unit_text.matmul(&unit_text.t()?)?.to_vec2()?;
        let same: Vec<Vec<bool>> = dots.iter().map(|row| row.iter().map(|d| *d > SAME_CAPTION_DOT).collect()).collect();
        let motion = self.model.embed_motion(x0)?;
        let texts = self.model.embed_text(text)?;
        let loss = self.model.contrastive_loss(&motion, &texts, &same)?;
        let value = f64::from(loss.to_scalar::<f32>()?);
        if !value.is_finite() {
            return Err(candle_core::Error::Msg(format!("step {}: the loss is {value}", self.step + 1)).into());
        }
        let similarity: Vec<Vec<f32>> = motion.matmul(&texts.t()?)?.to_vec2()?;
        let correct = similarity
            .iter()
            .enumerate()
            .filter(|(i, row)| row.iter().enumerate().all(|(j, s)| j == *i || same[*i][j] || *s <= row[*i]))
            .count();
        self.optimizer.step(&loss.backward()?, lr)?;
        self.step += 1;
        Ok(EvaluatorStep { step: self.step, loss: value, accuracy: correct as f64 / similarity.len().max(1) as f64 })
    }

    /// The evaluator with the current weights, frozen.
    pub fn evaluator(&self) -> Result<Evaluator, EvaluatorError> {
        let tensors = self.vars.iter().map(|(n, v)| (n.clone(), v.as_tensor().detach())).collect();
        let device = self.vars.first().map_or(Device::Cpu, |(_, v)| v.device().clone());
        let vb = VarBuilder::from_tensors(tensors, DType::F32, &device);
        Ok(Evaluator::new(self.model.config().clone(), self.model.mean_std().clone(), vb)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::representation::FEATURE_DIM;

    /// Four motions told apart by a constant offset, four captions: a few steps teach the pair
    /// to match them.
    #[test]
    fn a_few_steps_learn_to_match_distinct_pairs() {
        let dev = Device::Cpu;
        let config = EvaluatorConfig {
            width: 16,
            ff_size: 32,
            layers: 1,
            heads: 2,
            embedding: 8,
            text_dim: 4,
            temperature: 0.1,
        };
        let mut trainer = EvaluatorTrainer::new(config, super::super::encoders::tests::unit(), &dev, 0).unwrap();
        let offsets = Tensor::new(&[-1.5f32, -0.5, 0.5, 1.5], &dev).unwrap().reshape((4, 1, 1)).unwrap();
        let noise = crate::diffusion::noise::gaussian((4, 12, FEATURE_DIM), 5, &dev).unwrap();
        let x0 = (noise * 0.1).unwrap().broadcast_add(&offsets).unwrap();
        let text = Tensor::eye(4, DType::F32, &dev).unwrap();
        let first = trainer.train_step(&x0, &text, 3e-3).unwrap();
        let mut last = first;
        for _ in 0..60 {
            last = trainer.train_step(&x0, &text, 3e-3).unwrap();
        }
        assert_eq!(last.step, 61);
        assert!(last.loss < 0.5 * first.loss, "loss {} → {}", first.loss, last.loss);
        assert_eq!(last.accuracy, 1.0);
        let frozen = trainer.evaluator().unwrap();
        let m = frozen.embed_motion(&x0).unwrap();
        let t = frozen.embed_text(&text).unwrap();
        assert_eq!(super::super::r_precision(&m, &t, 4, &[1], 0).unwrap(), vec![1.0]);
    }
}
