//! Hyper-parameters of MDM's `trans_enc` denoiser.

use candle_core::{bail, Result};
use serde::{Deserialize, Serialize};

/// What the output head (`poseFinal`) predicts. The model returns x̂0 either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Prediction {
    /// The clean sample x0 itself (MDM).
    #[default]
    X0,
    /// The velocity v = √ᾱ_t·ε − √(1−ᾱ_t)·x0 of Salimans & Ho ("Progressive Distillation",
    /// 2022), under MDM's cosine schedule; x̂0 = √ᾱ_t·x_t − √(1−ᾱ_t)·v̂. At low noise x̂0 is
    /// x_t plus a small correction, so a small network keeps the detail of its input instead
    /// of re-synthesising every feature (which costs foot contacts their precision).
    Velocity,
}

impl std::str::FromStr for Prediction {
    type Err = String;

    /// `x0` or `velocity` (as in the prior file's config).
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "x0" => Ok(Self::X0),
            "velocity" => Ok(Self::Velocity),
            other => Err(format!("unknown prediction {other:?}: expected \"x0\" or \"velocity\"")),
        }
    }
}

impl std::fmt::Display for Prediction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::X0 => "x0",
            Self::Velocity => "velocity",
        })
    }
}

/// Sizes of the MDM `trans_enc` denoiser (`model/mdm.py`; anchors §1.2).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MdmConfig {
    /// Features per frame: 263 for the HumanML3D representation.
    pub input_feats: usize,
    /// Token width d (official: 512).
    pub latent_dim: usize,
    /// Hidden width of each feed-forward block (official: 1024).
    pub ff_size: usize,
    /// Post-LN encoder layers (official: 8).
    pub num_layers: usize,
    /// Attention heads; `latent_dim` must be a multiple (official: 4).
    pub num_heads: usize,
    /// Width of the text condition vector (CLIP ViT-B/32: 512).
    pub text_dim: usize,
    /// Dropout probability of the training path (official: 0.1; inactive at inference).
    pub dropout: f64,
    /// What the output head predicts (official: x0; absent from older prior files = x0).
    #[serde(default)]
    pub prediction: Prediction,
}

impl MdmConfig {
    /// The released HumanML3D checkpoint `humanml_trans_enc_512` (17.9 M parameters).
    pub fn official() -> Self {
        Self {
            input_feats: 263,
            latent_dim: 512,
            ff_size: 1024,
            num_layers: 8,
            num_heads: 4,
            text_dim: 512,
            dropout: 0.1,
            prediction: Prediction::X0,
        }
    }

    /// The CPU-sized prior trained here (d=128, ff=256, 4 layers, 0.70 M parameters).
    ///
    /// Measured with `model::bench` on the shared 2-core box (frozen path, K=10, 100 frames,
    /// forward + backward): 0.05–0.08 s per DNO step at batch 1 and 0.09–0.12 s at batch 2
    /// (classifier-free guidance); a training step (batch 32 × 100 frames) takes 0.45–0.52 s.
    /// d=192/ff=384 also meets 0.15 s at batch 1 (0.085–0.12 s) but not with guidance
    /// (0.16–0.19 s) and trains 1.6× slower; d=256/ff=512 needs 0.15–0.20 s at batch 1.
    pub fn small() -> Self {
        Self { latent_dim: 128, ff_size: 256, num_layers: 4, ..Self::official() }
    }

    /// Channels per attention head.
    pub fn head_dim(&self) -> usize {
        self.latent_dim / self.num_heads.max(1)
    }

    /// Number of trainable parameters (the positional tables are buffers, not counted).
    pub fn parameter_count(&self) -> usize {
        let (f, d, ff, t) = (self.input_feats, self.latent_dim, self.ff_size, self.text_dim);
        let layer = 3 * d * d + 3 * d + d * d + d + ff * d + ff + d * ff + d + 4 * d;
        (f * d + d) + 2 * (d * d + d) + (t * d + d) + self.num_layers * layer + (d * f + f)
    }

    /// Checks that the sizes describe a buildable model.
    pub fn validate(&self) -> Result<()> {
        if self.input_feats == 0 || self.latent_dim == 0 || self.ff_size == 0 || self.text_dim == 0 {
            bail!("MDM sizes must be positive: {self:?}");
        }
        if self.num_heads == 0 || self.latent_dim % self.num_heads != 0 {
            bail!("latent_dim {} is not divisible into {} heads", self.latent_dim, self.num_heads);
        }
        if self.latent_dim % 2 != 0 {
            bail!("latent_dim {} must be even for the sinusoidal encoding", self.latent_dim);
        }
        if !(0.0..1.0).contains(&self.dropout) {
            bail!("dropout {} must be in [0, 1)", self.dropout);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn official_parameter_count_matches_the_checkpoint() {
        // anchors §1.6: 17,880,327 parameters, CLIP excluded.
        assert_eq!(MdmConfig::official().parameter_count(), 17_880_327);
        assert!(MdmConfig::official().validate().is_ok());
        assert!(MdmConfig::small().validate().is_ok());
        assert!(MdmConfig { num_heads: 3, ..MdmConfig::small() }.validate().is_err());
    }

    #[test]
    fn prediction_names_round_trip_and_older_files_mean_x0() {
        for p in [Prediction::X0, Prediction::Velocity] {
            assert_eq!(p.to_string().parse::<Prediction>(), Ok(p));
            let json = serde_json::to_string(&p).unwrap();
            assert_eq!(json, format!("\"{p}\""));
        }
        assert!("eps".parse::<Prediction>().unwrap_err().contains("\"eps\""));
        let mut old = serde_json::to_value(MdmConfig::small()).unwrap();
        old.as_object_mut().unwrap().remove("prediction");
        assert_eq!(serde_json::from_value::<MdmConfig>(old).unwrap().prediction, Prediction::X0);
    }
}
