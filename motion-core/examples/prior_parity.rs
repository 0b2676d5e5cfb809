//! Parity of a prior trained by the PyTorch mirror (`fixtures/model/gpu/train_mdm.py --parity`)
//! with the candle model that loads it: the denoiser's eval-mode output on the same input, as
//! the largest absolute difference (normalised feature units; f32 rounding is about 1e-5).
//!
//! Usage: `cargo run --release --example prior_parity -p motion-core -- PRIOR PARITY [TEXT_MODELS]`
//! (TEXT_MODELS, default `fixtures/text`, holds the sentence encoder a prior may name).
use std::error::Error;
use std::path::Path;

use candle_core::{DType, Device};
use motion_core::prior::Prior;

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (prior, parity, text_models) = match args.as_slice() {
        [_, prior, parity] => (prior, parity, "fixtures/text"),
        [_, prior, parity, text_models] => (prior, parity, text_models.as_str()),
        _ => return Err("usage: prior_parity PRIOR PARITY [TEXT_MODELS]".into()),
    };
    let device = Device::Cpu;
    let prior = Prior::load(Path::new(prior), Path::new(text_models), &device)?;
    let io = candle_core::safetensors::load(parity, &device)?;
    let get = |name: &str| io.get(name).ok_or_else(|| format!("{parity}: no `{name}`"));
    let t = get("t")?.to_dtype(DType::U32)?;
    let out = prior.mdm.forward_eval(get("x_t")?, &t, get("text")?)?;
    let diff = (&out - get("out")?)?.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()?;
    println!("max |candle − PyTorch| = {diff:.3e} over {:?}", out.dims());
    if diff > 1e-3 {
        return Err(format!("the prior does not reproduce PyTorch's output (max difference {diff:.3e})").into());
    }
    Ok(())
}
