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

/// The shipped prior through the primitive candle ops (`Mdm::forward_eval`), the reference
/// the fused, multi-threaded denoiser must reproduce.
struct Primitive<'a>(&'a Mdm);

impl motion_core::diffusion::Denoiser for Primitive<'_> {
    fn predict_x0(&self, x_t: &Tensor, timesteps: &Tensor, text: &Tensor) -> candle_core::Result<Tensor> {
        self.0.forward_eval(x_t, timesteps, text)
    }

    fn text_dim(&self) -> usize {
        motion_core::diffusion::Denoiser::text_dim(self.0)
    }
}

/// Issue 17's guard for the speed work: DDIM-50 samples of the shipped prior from a fixed
/// seed (3 motions with guidance 2.5, so 6 rows: one task per row pair on 2 threads, row
/// phases on 1 and 4) give the same joints through the fused parallel kernels on every
/// thread count as through the primitive ops, within 1e-4 m.
#[test]
fn the_fused_parallel_denoiser_samples_the_motion_of_the_primitive_path() {
    let dev = Device::Cpu;
    let prior = motion_core::prior::Prior::load(
        &e2e_tests::fixtures().join("model/prior.safetensors"),
        &e2e_tests::fixtures().join("text"),
        &dev,
    )
    .unwrap();
    let sampler = DdimSampler::new(&NoiseSchedule::mdm(), 50).unwrap();
    let text = prior.encode_text(&["a person walks forward"; 3], &dev).unwrap();
    let z = motion_core::diffusion::noise::gaussian((3, 60, 263), 0, &dev).unwrap();
    let joints = |denoiser: &dyn motion_core::diffusion::Denoiser| {
        let x = sampler.sample(denoiser, &z, &text, Guidance::default()).unwrap();
        prior.to_joints(&x).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap()
    };
    let reference = joints(&Primitive(&prior.mdm));
    for threads in [1, 2, 4] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let fast = pool.install(|| joints(&prior.mdm));
        let worst = fast.iter().zip(&reference).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{threads} threads: joints {worst} m from the primitive path");
    }
}
