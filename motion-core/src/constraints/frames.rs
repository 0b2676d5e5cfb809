//! Frame selections, conditions and reductions: which frames (and points) of a per-frame error
//! count, and how they become one number per sample.

use candle_core::{DType, Device, Result, Tensor, D};

use super::signal::signal;
use crate::program::{Condition, FrameRef, FrameSelection, Reduce};

/// A [`FrameSelection`] resolved against a signal of `n` frames: sorted, distinct indices, or
/// every frame.
#[derive(Debug, Clone)]
pub struct Frames {
    /// `None`: all `n` frames; else the kept indices `[k]` (u32).
    index: Option<Tensor>,
    /// The kept frame numbers.
    kept: Vec<usize>,
    /// Whether the selection is a span of consecutive frames (all of them, or a range), which
    /// [`Frames::thinned`] thins; keyframes are never thinned.
    span: bool,
}

impl Frames {
    /// Resolves `selection` for a signal of `n ≥ 1` frames; an error names a frame outside it
    /// (validated programs never produce one).
    pub fn resolve(selection: &FrameSelection, n: usize, device: &Device) -> Result<Frames> {
        let resolve = |frame: FrameRef| {
            frame
                .resolve(n as u32)
                .map(|f| f as usize)
                .ok_or_else(|| candle_core::Error::Msg(format!("frame {frame:?} is outside a signal of {n} frames")))
        };
        let mut kept = match selection {
            FrameSelection::All => return Ok(Frames { index: None, kept: (0..n).collect(), span: true }),
            FrameSelection::Keyframes(keys) => keys.iter().map(|&k| resolve(k)).collect::<Result<Vec<_>>>()?,
            FrameSelection::Range(range) => (resolve(range.from)?..=resolve(range.to)?).collect(),
        };
        kept.sort_unstable();
        kept.dedup();
        let span = matches!(selection, FrameSelection::Range(_));
        let index = Tensor::from_vec(kept.iter().map(|&f| f as u32).collect::<Vec<_>>(), kept.len(), device)?;
        Ok(Frames { index: Some(index), kept, span })
    }

    /// A span thinned to every `step`-th of its frames, its first and last kept (a cheaper
    /// approximation of the same selection); keyframes, and spans of at most two frames, as
    /// they are.
    pub fn thinned(&self, step: usize, device: &Device) -> Result<Frames> {
        let Some(&last) = self.kept.last() else { return Ok(self.clone()) };
        if !self.span || step <= 1 || self.kept.len() <= 2 {
            return Ok(self.clone());
        }
        let mut kept: Vec<usize> = self.kept.iter().copied().step_by(step).collect();
        if kept.last() != Some(&last) {
            kept.push(last);
        }
        let index = Tensor::from_vec(kept.iter().map(|&f| f as u32).collect::<Vec<_>>(), kept.len(), device)?;
        Ok(Frames { index: Some(index), kept, span: true })
    }

    /// The kept frame numbers.
    pub fn kept(&self) -> &[usize] {
        &self.kept
    }

    /// The 0/1 mask `[B, F]` of the selected frames of an `n`-frame signal where `when` holds on
    /// the current motion ([`condition_mask`]); `None` without a condition.
    pub fn condition_mask(&self, joints: &Tensor, when: &Option<Condition>, n: usize) -> Result<Option<Tensor>> {
        when.as_ref().map(|condition| self.select(&condition_mask(joints, condition, n)?)).transpose()
    }

    /// Keeps the selected frames of `x` along axis 1.
    pub fn select(&self, x: &Tensor) -> Result<Tensor> {
        match &self.index {
            None => Ok(x.clone()),
            Some(index) => x.contiguous()?.index_select(index, 1),
        }
    }
}

/// The 0/1 mask `[B, n]` of the frames of an `n`-frame signal where `condition` holds on the
/// current motion. Computed without gradient (ProgMoGen's if-else selects frames by a boolean
/// mask); frames beyond the condition's own signal (its lag) are 0.
pub fn condition_mask(joints: &Tensor, condition: &Condition, n: usize) -> Result<Tensor> {
    let values = signal(&joints.detach(), &condition.of)?.squeeze(D::Minus1)?.to_dtype(DType::F64)?;
    let (batch, available) = values.dims2()?;
    let values = values.to_vec2::<f64>()?;
    let mut mask = vec![0f32; batch * n];
    for (b, row) in values.iter().enumerate() {
        for (t, &v) in row.iter().enumerate().take(n.min(available)) {
            let inside = condition.min.is_none_or(|lo| v > lo) && condition.max.is_none_or(|hi| v < hi);
            if inside != condition.outside {
                mask[b * n + t] = 1.0;
            }
        }
    }
    Tensor::from_vec(mask, (batch, n), joints.device())?.to_dtype(joints.dtype())
}

/// Reduces errors `[B, F, ..]` (all ≥ 0) over everything but the batch to `[B]`. `mask`, when
/// given, is `[B, F]` of 0/1 and keeps frames; an empty selection gives 0, never NaN.
pub fn reduce(errors: &Tensor, mask: Option<&Tensor>, how: Reduce) -> Result<Tensor> {
    let batch = errors.dim(0)?;
    let flat = errors.reshape((batch, ()))?;
    let Some(mask) = mask else {
        return match how {
            Reduce::Mean => flat.mean(D::Minus1),
            Reduce::Sum => flat.sum(D::Minus1),
            Reduce::Max => flat.max(D::Minus1),
            Reduce::Min => flat.min(D::Minus1),
        };
    };
    let mut shape = mask.dims().to_vec();
    shape.extend(std::iter::repeat_n(1, errors.rank() - 2));
    let mask = mask.reshape(shape)?.broadcast_as(errors.shape())?.reshape((batch, ()))?;
    let kept = (&flat * &mask)?;
    let count = mask.sum(D::Minus1)?;
    match how {
        Reduce::Mean => kept.sum(D::Minus1)?.broadcast_div(&count.maximum(1.0)?),
        Reduce::Sum => kept.sum(D::Minus1),
        Reduce::Max => kept.max(D::Minus1),
        Reduce::Min => {
            // Masked-out entries are pushed far above any error; a sample with no kept entry
            // gets 0 (its minimum × 0).
            let far = ((1.0 - &mask)? * 1e9)?;
            let any = count.minimum(1.0)?;
            (flat + far)?.min(D::Minus1)? * any
        }
    }
}
