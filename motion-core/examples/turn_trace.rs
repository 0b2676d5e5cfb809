//! Where the turning walks lose their turn (`fixtures/model/HISTORY.md`, "Why the turns fall
//! short"): for a label, the turn of the network's x̂0 of pure noise, then of every tenth DDIM
//! step's x̂0 while sampling, and of the final samples, each the mean over the samples with the
//! shares turning more than 30° left and right (`quality::MetricMeans`).
//!
//! Usage: `cargo run --release --example turn_trace -p motion-core -- PRIOR LABEL SAMPLES
//! DDIM_STEPS GUIDANCE SEED`, e.g. `fixtures/model/prior.safetensors "a person walks and turns
//! left" 16 50 2.5 7`.
use std::error::Error;
use std::path::Path;

use candle_core::{Device, Tensor};
use motion_core::diffusion::noise::gaussian;
use motion_core::diffusion::{DdimSampler, Denoiser, Guidance, NoiseSchedule};
use motion_core::metrics::MetricMeans;
use motion_core::prior::Prior;
use motion_core::quality::joints_of;
use motion_core::representation::FEATURE_DIM;

fn describe(what: &str, m: &MetricMeans) {
    println!(
        "{what:32} turn {:+5.0}° ({:.0} % left / {:.0} % right of 30°), travel {:.2} m",
        m.turn_deg,
        100.0 * m.turn_left_share,
        100.0 * m.turn_right_share,
        m.travel_m
    );
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, prior, label, samples, steps, guidance, seed] = args.as_slice() else {
        return Err("usage: turn_trace PRIOR LABEL SAMPLES DDIM_STEPS GUIDANCE SEED".into());
    };
    let (samples, steps): (usize, usize) = (samples.parse()?, steps.parse()?);
    let dev = Device::Cpu;
    let prior = Prior::load(Path::new(prior), &Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/text"), &dev)?;
    let text = prior.encode_text(&vec![label.as_str(); samples], &dev)?;
    let noise = gaussian((samples, 120, FEATURE_DIM), seed.parse()?, &dev)?;
    let t = Tensor::full(999u32, samples, &dev)?;
    let x0 = prior.mdm.predict_x0(&noise, &t, &text)?;
    describe("x̂0 of pure noise (t = 999)", &MetricMeans::of(&joints_of(&prior, &x0)?));
    let sampler = DdimSampler::new(&NoiseSchedule::mdm(), steps)?;
    let guided = Guidance { scale: guidance.parse()? }.for_text(&text)?;
    let every = (steps / 10).max(1);
    let out = sampler.sample_with_progress(&prior.mdm, &noise, &text, guided, |p| {
        if p.step % every == 1 || every == 1 {
            match joints_of(&prior, p.x0_hat) {
                Ok(j) => describe(&format!("step {} (t = {})", p.step, p.timestep), &MetricMeans::of(&j)),
                Err(e) => eprintln!("step {}: {e}", p.step),
            }
        }
    })?;
    describe("final samples", &MetricMeans::of(&joints_of(&prior, &out)?));
    Ok(())
}
