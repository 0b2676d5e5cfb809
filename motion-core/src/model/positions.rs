//! MDM's sinusoidal positional table.

use candle_core::{Device, Result, Tensor};

/// Rows of MDM's sinusoidal table (`PositionalEncoding(max_len=5000)`).
pub const MAX_LEN: usize = 5000;

/// MDM's sinusoidal table `[max_len, d]`: `pe[p, 2i] = sin(p·e^(−2i·ln(10000)/d))`,
/// `pe[p, 2i+1] = cos(..)`, computed in f32 step by step as PyTorch does (so it matches the
/// checkpoint's `sequence_pos_encoder.pe` buffer).
pub fn sinusoidal_table(max_len: usize, d: usize, device: &Device) -> Result<Tensor> {
    let rate = (-(10000f64).ln() / d as f64) as f32;
    let div: Vec<f32> = (0..d / 2).map(|i| ((2 * i) as f32 * rate).exp()).collect();
    let mut pe = vec![0f32; max_len * d];
    for (pos, row) in pe.chunks_exact_mut(d.max(1)).enumerate() {
        for (i, &dv) in div.iter().enumerate() {
            let arg = pos as f32 * dv;
            row[2 * i] = arg.sin();
            row[2 * i + 1] = arg.cos();
        }
    }
    Tensor::from_vec(pe, (max_len, d), device)
}
