//! Settings of a DNO run and its learning-rate schedule (DNO's `DNOOptions`, anchors §2.1).

use candle_core::{bail, Result};
use serde::{Deserialize, Serialize};

/// Hyper-parameters of diffusion noise optimisation; the defaults are DNO's (`dno.py`
/// `DNOOptions`), so `DnoConfig::default()` reproduces the paper's optimiser.
///
/// Serialisable so that a run's settings can be printed into its output report; fields missing
/// from a deserialised config take their defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DnoConfig {
    /// Optimisation steps N (default 500; DNO's help text: 300 for editing, 500 for refinement;
    /// its demo uses 800).
    pub steps: usize,
    /// Peak Adam learning rate (default 0.05; Adam β = 0.9, 0.999, ε = 1e-8 on z only).
    pub lr: f64,
    /// Linear warm-up steps W (default 50): the factor is s/W for s < W, so the lr is 0 at step 0.
    pub lr_warmup_steps: usize,
    /// Cosine decay over the last D steps, from 1 at step N − D to 0 at step N (default `None`,
    /// meaning D = N: the whole run).
    pub lr_decay_steps: Option<usize>,
    /// Per-sample gradient normalisation g_b ← g_b/‖g_b‖₂ over the non-batch dims before each
    /// Adam step (default on, as DNO).
    pub normalize_gradient: bool,
    /// Weight of the noise decorrelation regulariser [`super::noise_regularize_1d`] (default 1000;
    /// 0 switches it off, as DNO's editing evaluation does).
    pub decorrelate_scale: f64,
    /// After each step z += N(0, I)·perturb_scale·(lr factor) (default 0: off).
    pub perturb_scale: f64,
    /// Weight of the stay-close penalty ‖z − z_start‖₂ per sample, not squared (default 0;
    /// DNO uses 2e-3 for editing tasks).
    pub diff_penalty_scale: f64,
    /// DDIM steps K of the unrolled sampler z → x (default 10, timesteps 900, 800, …, 0). Read
    /// by whoever builds the solver ([`super::UnrolledDdim::from_config`]), not by the loop.
    pub ddim_steps: usize,
    /// Late start: when set, z is the noise of the unconstrained motion G(z0) noised to the
    /// last spaced timestep at or below this one, and only the DDIM steps from there are run
    /// ([`super::UnrolledDdim::starting_late`]; default `None`: z is the start latent at the
    /// first timestep, as DNO).
    #[serde(default)]
    pub start_timestep: Option<usize>,
    /// Independent restarts N_S from random noise; the best per sample by final criterion
    /// loss is kept (default 1; RG-DNO's ProgMoGen+DNO baseline uses 5).
    pub restarts: usize,
    /// Seed of the random start noise and of the loop's noise (regulariser padding,
    /// perturbation); restart r uses `seed + r` (default 0).
    pub seed: u64,
    /// Return, per sample, the iterate with the lowest criterion loss seen instead of the last
    /// one (default off, as DNO). RG-DNO turns it on for its branches and final round: a step
    /// can throw a latent that starts from an inverted motion over a cliff it never climbs back
    /// (HSI-2's `z2`: loss 0.017 at step 15, 0.37 from step 20 on).
    #[serde(default)]
    pub keep_best: bool,
}

impl Default for DnoConfig {
    fn default() -> Self {
        Self {
            steps: 500,
            lr: 0.05,
            lr_warmup_steps: 50,
            lr_decay_steps: None,
            normalize_gradient: true,
            decorrelate_scale: 1000.0,
            perturb_scale: 0.0,
            diff_penalty_scale: 0.0,
            ddim_steps: 10,
            start_timestep: None,
            restarts: 1,
            seed: 0,
            keep_best: false,
        }
    }
}

impl DnoConfig {
    /// The lr multiplier at step `step` (0-based): warm-up × cosine decay (DNO's
    /// `warmup_scheduler` × `cosine_decay_scheduler(decay_first=False)`), in [0, 1].
    ///
    /// warm-up = min(s/W, 1); decay = 1 before step N − D, then (cos(π·(s − (N − D))/D) + 1)/2,
    /// and 0 from step N on.
    pub fn lr_factor(&self, step: usize) -> f64 {
        let warmup = if step < self.lr_warmup_steps { step as f64 / self.lr_warmup_steps as f64 } else { 1.0 };
        let total = self.steps;
        let decay_steps = self.lr_decay_steps.unwrap_or(total).min(total);
        let decay = if step >= total {
            0.0
        } else if step < total - decay_steps {
            1.0
        } else {
            let into = (step - (total - decay_steps)) as f64 / decay_steps as f64;
            ((std::f64::consts::PI * into).cos() + 1.0) / 2.0
        };
        warmup * decay
    }

    /// The learning rate at step `step`: `lr · lr_factor(step)`.
    pub fn learning_rate(&self, step: usize) -> f64 {
        self.lr * self.lr_factor(step)
    }

    /// Errors on settings the loop cannot run with (no steps or restarts, negative or
    /// non-finite weights).
    pub fn validate(&self) -> Result<()> {
        if self.steps == 0 || self.restarts == 0 {
            bail!("DnoConfig.steps and .restarts must be at least 1, got {} and {}", self.steps, self.restarts);
        }
        for (name, value) in [
            ("lr", self.lr),
            ("decorrelate_scale", self.decorrelate_scale),
            ("perturb_scale", self.perturb_scale),
            ("diff_penalty_scale", self.diff_penalty_scale),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                bail!("DnoConfig.{name} must be finite and non-negative, got {value}");
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedule_warms_up_peaks_at_50_and_decays_to_zero() {
        let c = DnoConfig::default();
        assert_eq!(c.learning_rate(0), 0.0);
        assert!(
            (c.learning_rate(25) - 0.05 * 0.5 * (((25.0 / 500.0) * std::f64::consts::PI).cos() + 1.0) / 2.0).abs()
                < 1e-15
        );
        let peak = 0.05 * ((0.1 * std::f64::consts::PI).cos() + 1.0) / 2.0;
        assert!((c.learning_rate(50) - peak).abs() < 1e-15);
        let argmax = (0..=500).max_by(|&a, &b| c.learning_rate(a).total_cmp(&c.learning_rate(b)));
        assert_eq!(argmax, Some(50));
        assert!((c.learning_rate(250) - 0.025).abs() < 1e-12, "half way down the cosine");
        assert!(c.learning_rate(499) > 0.0 && c.learning_rate(499) < 1e-6);
        assert_eq!(c.learning_rate(500), 0.0);
        assert!((1..500).all(|s| s <= 50 || c.learning_rate(s) <= c.learning_rate(s - 1)));
    }

    #[test]
    fn decay_only_over_the_last_steps_and_no_warmup() {
        let c = DnoConfig { steps: 100, lr_warmup_steps: 0, lr_decay_steps: Some(20), ..DnoConfig::default() };
        assert_eq!(c.learning_rate(0), 0.05);
        assert_eq!(c.learning_rate(80), 0.05);
        assert!((c.learning_rate(90) - 0.025).abs() < 1e-12);
        assert_eq!(c.learning_rate(100), 0.0);
    }

    #[test]
    fn serde_round_trip_fills_defaults_and_rejects_typos() {
        let c = DnoConfig { steps: 20, seed: 7, ..DnoConfig::default() };
        let back: DnoConfig = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
        assert_eq!(back, c);
        let partial: DnoConfig = serde_json::from_str(r#"{"restarts": 5}"#).unwrap();
        assert_eq!(partial, DnoConfig { restarts: 5, ..DnoConfig::default() });
        assert!(serde_json::from_str::<DnoConfig>(r#"{"stpes": 5}"#).is_err());
        assert!(DnoConfig { restarts: 0, ..DnoConfig::default() }.validate().is_err());
        assert!(DnoConfig { lr: f64::NAN, ..DnoConfig::default() }.validate().is_err());
        assert!(DnoConfig::default().validate().is_ok());
    }
}
