//! The differentiable sampler through the real MDM layers (tiny configuration, f64): the
//! gradient of a joint-space loss w.r.t. the start noise is finite, non-zero and matches finite
//! differences.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use candle_core::{DType, Device, Tensor};
use motion_core::diffusion::{DdimSampler, Guidance, NoiseSchedule};
use motion_core::model::{Mdm, MdmConfig};
use motion_core::representation::{recover_from_ric, MeanStd};
use motion_core::testing::finite_difference_check;

#[test]
fn unrolled_ddim10_gradient_to_the_noise_matches_finite_differences() {
    let dev = Device::Cpu;
    let cfg = MdmConfig { latent_dim: 16, ff_size: 32, num_layers: 2, num_heads: 2, text_dim: 4, ..MdmConfig::small() };
    let mdm = Mdm::random(cfg, DType::F64, &dev, 11).unwrap();
    let sampler = DdimSampler::new(&NoiseSchedule::mdm(), 10).unwrap();
    let text = Tensor::new(&[[0.0f64, 1.0, 0.0, 0.0]], &dev).unwrap();
    let stats = MeanStd::from_vecs(vec![0.0; 263], vec![0.1; 263], &dev).unwrap();
    let z = (motion_core::diffusion::noise::gaussian((1, 6, 263), 5, &dev).unwrap().to_dtype(DType::F64).unwrap()
        * 1.0)
        .unwrap();
    // Loss: mean height of the recovered right wrist, through CFG (scale 2.5).
    let loss = |z: &Tensor| {
        let x = sampler.sample_unrolled(&mdm, z, &text, Guidance::default())?;
        let joints = recover_from_ric(&stats.denormalize(&x)?)?;
        joints.narrow(2, 21, 1)?.narrow(3, 1, 1)?.mean_all()
    };
    finite_difference_check(&z, loss, 1e-5, 1e-4).unwrap();
}
