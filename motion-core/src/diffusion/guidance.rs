//! Classifier-free guidance on the x̂0 prediction (MDM's `ClassifierFreeSampleModel`).

use candle_core::{DType, Result, Tensor};

/// Classifier-free guidance (Ho & Salimans 2022) on the x̂0 output, as MDM's
/// `ClassifierFreeSampleModel`: x̂0 = x̂0_uncond + scale·(x̂0_cond − x̂0_uncond), where the
/// unconditional branch sees an all-zero text row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Guidance {
    /// Guidance scale s; 1 means plain conditional prediction (one denoiser call).
    pub scale: f64,
}

impl Default for Guidance {
    /// MDM's, DNO's and ProgMoGen's scale, 2.5.
    fn default() -> Self {
        Self { scale: Self::MDM_SCALE }
    }
}

impl Guidance {
    /// The scale MDM samples with (`guidance_param` 2.5).
    pub const MDM_SCALE: f64 = 2.5;

    /// No guidance: scale 1, one denoiser call per step.
    pub fn none() -> Self {
        Self { scale: 1.0 }
    }

    /// Whether the unconditional branch is evaluated at all (scale ≠ 1).
    pub fn is_active(&self) -> bool {
        self.scale != 1.0
    }

    /// This guidance for the condition `text` (`[batch, text_dim]`): an all-zero text makes the
    /// conditional and unconditional branches identical, so guidance is switched off.
    ///
    /// Reads `text` back from the device; call it once per sampling run, not per step.
    pub fn for_text(self, text: &Tensor) -> Result<Self> {
        if !self.is_active() {
            return Ok(self);
        }
        let magnitude = text.detach().abs()?.sum_all()?.to_dtype(DType::F64)?.to_scalar::<f64>()?;
        Ok(if magnitude == 0.0 { Self::none() } else { self })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diffusion::test_denoiser::{start_noise, text, Call, GaussianDenoiser};
    use crate::diffusion::Denoiser;
    use crate::testing::max_abs_diff;
    use candle_core::Device;

    #[test]
    fn guidance_makes_one_call_and_combines_branches() -> Result<()> {
        let d = GaussianDenoiser::new(0.2, 0.5, 0.3);
        let x = start_noise(2, 3)?;
        let t = Tensor::new(&[500u32, 500], &Device::Cpu)?;
        let cond = text(&[[0.5, -0.2, 1.0], [0.1, 0.0, 0.4]])?;
        let zeros = cond.zeros_like()?;

        let guided = Guidance { scale: 2.5 }.predict_x0(&d, &x, &t, &cond)?;
        assert_eq!(*d.calls.borrow(), vec![Call { rows: 4, zero_text_rows: vec![false, false, true, true] }]);
        let c = d.predict_x0(&x, &t, &cond)?;
        let u = d.predict_x0(&x, &t, &zeros)?;
        let expected = (&u + ((&c - &u)? * 2.5)?)?;
        assert!(max_abs_diff(&guided, &expected)? < 1e-12);

        d.calls.borrow_mut().clear();
        let plain = Guidance::none().predict_x0(&d, &x, &t, &cond)?;
        assert_eq!(*d.calls.borrow(), vec![Call { rows: 2, zero_text_rows: vec![false, false] }]);
        assert_eq!(max_abs_diff(&plain, &c)?, 0.0);
        Ok(())
    }
}
