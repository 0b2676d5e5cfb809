//! Mean/Std normalisation of the 263-d features, computed HumanML3D's way.

use std::path::Path;

use candle_core::{DType, Device, Tensor};

use super::layout::{FeatureFrame, FEATURE_DIM, FOOT_CONTACT, LOCAL_VEL, RIC, ROOT_LIN_VEL, ROOT_ROT_VEL, ROOT_Y, ROT};

/// Floor on each standard deviation so constant features cannot divide by zero.
const MIN_STD: f64 = 1e-4;

/// Errors building or loading normalisation statistics.
#[derive(Debug, thiserror::Error)]
pub enum NormalizationError {
    /// No frames to compute statistics from.
    #[error("cannot compute Mean/Std from zero frames")]
    Empty,
    /// A statistics vector of the wrong length.
    #[error("{what}: expected {FEATURE_DIM} values, found {found}")]
    WrongLength {
        /// Which vector.
        what: String,
        /// Its length.
        found: usize,
    },
    /// A mean that is not finite or a std that is not positive.
    #[error("{what}[{index}] = {value} is not usable (means must be finite, stds finite and > 0)")]
    BadValue {
        /// Which vector.
        what: String,
        /// Feature index.
        index: usize,
        /// The value.
        value: f32,
    },
    /// A tensor error while loading.
    #[error("{what}: {source}")]
    Tensor {
        /// Which file or tensor.
        what: String,
        /// The candle error.
        source: candle_core::Error,
    },
}

/// Per-feature mean and standard deviation; the diffusion model works on `(x − mean) / std`.
///
/// The std is **block-constant** as in HumanML3D's `cal_mean_variance`: every group of the
/// layout (yaw velocity, x/z velocity, height, ric, rotations, local velocities, contacts)
/// shares the mean of its per-dimension stds.
#[derive(Debug, Clone)]
pub struct MeanStd {
    mean: Tensor,
    std: Tensor,
}

impl MeanStd {
    /// Statistics of a set of feature frames.
    pub fn from_frames<'a>(frames: impl IntoIterator<Item = &'a FeatureFrame>) -> Result<Self, NormalizationError> {
        let mut n = 0usize;
        let mut sum = [0f64; FEATURE_DIM];
        let mut sum_sq = [0f64; FEATURE_DIM];
        for f in frames {
            n += 1;
            for (i, v) in f.iter().enumerate() {
                sum[i] += f64::from(*v);
                sum_sq[i] += f64::from(*v) * f64::from(*v);
            }
        }
        if n == 0 {
            return Err(NormalizationError::Empty);
        }
        let mean: Vec<f64> = sum.iter().map(|s| s / n as f64).collect();
        let mut std: Vec<f64> = sum_sq.iter().zip(&mean).map(|(s, m)| (s / n as f64 - m * m).max(0.0).sqrt()).collect();
        for block in
            [ROOT_ROT_VEL..ROOT_ROT_VEL + 1, ROOT_LIN_VEL, ROOT_Y..ROOT_Y + 1, RIC, ROT, LOCAL_VEL, FOOT_CONTACT]
        {
            let avg = crate::numeric::mean(std[block.clone()].iter().copied());
            std[block].iter_mut().for_each(|s| *s = avg.max(MIN_STD));
        }
        Self::from_vecs(mean.iter().map(|v| *v as f32).collect(), std.iter().map(|v| *v as f32).collect(), &Device::Cpu)
    }

    /// Statistics from explicit vectors of 263 values each.
    pub fn from_vecs(mean: Vec<f32>, std: Vec<f32>, device: &Device) -> Result<Self, NormalizationError> {
        for (what, v, positive) in [("mean", &mean, false), ("std", &std, true)] {
            if v.len() != FEATURE_DIM {
                return Err(NormalizationError::WrongLength { what: what.into(), found: v.len() });
            }
            if let Some((index, value)) = v.iter().enumerate().find(|(_, x)| !x.is_finite() || (positive && **x <= 0.0))
            {
                return Err(NormalizationError::BadValue { what: what.into(), index, value: *value });
            }
        }
        let t = |what: &str, v: Vec<f32>| {
            Tensor::from_vec(v, FEATURE_DIM, device)
                .map_err(|source| NormalizationError::Tensor { what: what.into(), source })
        };
        Ok(Self { mean: t("mean", mean)?, std: t("std", std)? })
    }

    /// Loads HumanML3D's `Mean.npy` and `Std.npy` (float32 or float64, shape `[263]`).
    pub fn read_npy(mean_path: &Path, std_path: &Path) -> Result<Self, NormalizationError> {
        let load = |p: &Path| -> Result<Vec<f32>, NormalizationError> {
            let what = p.display().to_string();
            let err = |source| NormalizationError::Tensor { what: what.clone(), source };
            let t = Tensor::read_npy(p).map_err(err)?;
            let t = t.to_dtype(DType::F32).map_err(err)?.flatten_all().map_err(err)?;
            t.to_vec1::<f32>().map_err(err)
        };
        let (mean, std) = (load(mean_path)?, load(std_path)?);
        let named = |e: NormalizationError, p: &Path| match e {
            NormalizationError::WrongLength { found, .. } => {
                NormalizationError::WrongLength { what: p.display().to_string(), found }
            }
            other => other,
        };
        if mean.len() != FEATURE_DIM {
            return Err(named(NormalizationError::WrongLength { what: String::new(), found: mean.len() }, mean_path));
        }
        if std.len() != FEATURE_DIM {
            return Err(named(NormalizationError::WrongLength { what: String::new(), found: std.len() }, std_path));
        }
        Self::from_vecs(mean, std, &Device::Cpu)
    }

    /// The mean, `[263]`.
    pub fn mean(&self) -> &Tensor {
        &self.mean
    }

    /// The std, `[263]`.
    pub fn std(&self) -> &Tensor {
        &self.std
    }

    /// The same statistics on another device.
    pub fn to_device(&self, device: &Device) -> candle_core::Result<Self> {
        Ok(Self { mean: self.mean.to_device(device)?, std: self.std.to_device(device)? })
    }

    /// `(x − mean) / std` for `x` of shape `[..., 263]`.
    pub fn normalize(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        x.broadcast_sub(&self.mean.to_dtype(x.dtype())?)?.broadcast_div(&self.std.to_dtype(x.dtype())?)
    }

    /// `x · std + mean` for `x` of shape `[..., 263]`.
    pub fn denormalize(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        x.broadcast_mul(&self.std.to_dtype(x.dtype())?)?.broadcast_add(&self.mean.to_dtype(x.dtype())?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn std_is_block_constant_and_normalisation_inverts() {
        let frames: Vec<FeatureFrame> = (0..10)
            .map(|i| {
                let mut f = [0f32; FEATURE_DIM];
                for (d, v) in f.iter_mut().enumerate() {
                    *v = ((i * 7 + d * 3) % 11) as f32 * 0.1;
                }
                f
            })
            .collect();
        let ms = MeanStd::from_frames(&frames).unwrap();
        let std = ms.std().to_vec1::<f32>().unwrap();
        assert!(RIC.clone().all(|i| std[i] == std[RIC.start]));
        assert!(ROT.clone().all(|i| std[i] == std[ROT.start]));
        let x = Tensor::from_vec(frames[3].to_vec(), (1, FEATURE_DIM), &Device::Cpu).unwrap();
        let back = ms.denormalize(&ms.normalize(&x).unwrap()).unwrap();
        let diff = (back - x).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
        assert!(diff < 1e-5);
    }

    #[test]
    fn bad_statistics_are_rejected_by_name() {
        assert!(matches!(MeanStd::from_frames(&[]), Err(NormalizationError::Empty)));
        let err = MeanStd::from_vecs(vec![0.0; 262], vec![1.0; 263], &Device::Cpu).unwrap_err();
        assert!(err.to_string().contains("mean") && err.to_string().contains("262"));
        let mut std = vec![1.0; 263];
        std[17] = 0.0;
        let err = MeanStd::from_vecs(vec![0.0; 263], std, &Device::Cpu).unwrap_err();
        assert!(err.to_string().contains("std[17]"));
    }

    #[test]
    fn npy_files_of_the_wrong_shape_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let (m, s) = (dir.path().join("Mean.npy"), dir.path().join("Std.npy"));
        Tensor::zeros(263, DType::F32, &Device::Cpu).unwrap().write_npy(&m).unwrap();
        Tensor::ones(100, DType::F64, &Device::Cpu).unwrap().write_npy(&s).unwrap();
        let err = MeanStd::read_npy(&m, &s).unwrap_err().to_string();
        assert!(err.contains("Std.npy") && err.contains("100"), "{err}");
        Tensor::ones(263, DType::F64, &Device::Cpu).unwrap().write_npy(&s).unwrap();
        assert!(MeanStd::read_npy(&m, &s).is_ok());
        std::fs::write(&s, b"\x93NUMPY garbage").unwrap();
        assert!(MeanStd::read_npy(&m, &s).is_err());
    }
}
