//! Model tests: checkpoint parity with PyTorch, gradients, names, training mode.

use std::collections::{BTreeSet, HashMap};
use std::path::PathBuf;

use candle_core::{DType, Device, IndexOp, Result, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use rand::rngs::StdRng;
use rand::SeedableRng;

use super::layer::Dropout;
use super::*;
use crate::diffusion::{Denoiser, NoiseSchedule};
use crate::nn::testing::randn;
use crate::nn::Isa;
use crate::testing::finite_difference_check;
use crate::testing::max_abs_diff;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fixtures/parity").join(name)
}

/// The configuration of `fixtures/parity/make_mdm_parity.py`.
fn parity_config() -> MdmConfig {
    MdmConfig { latent_dim: 48, ff_size: 96, num_layers: 2, num_heads: 4, ..MdmConfig::official() }
}

/// A tiny f64 model for finite differences.
fn tiny_config() -> MdmConfig {
    MdmConfig {
        input_feats: 7,
        latent_dim: 8,
        ff_size: 12,
        num_layers: 2,
        num_heads: 2,
        text_dim: 5,
        dropout: 0.1,
        prediction: Prediction::X0,
    }
}

struct Inputs {
    x: Tensor,
    t: Tensor,
    text: Tensor,
}

fn tiny_inputs(cfg: &MdmConfig, dev: &Device) -> Result<Inputs> {
    let x = randn(&[2, 5, cfg.input_feats], 50, dev)?;
    let t = Tensor::new(&[999u32, 3], dev)?;
    let text =
        Tensor::cat(&[randn(&[1, cfg.text_dim], 51, dev)?, Tensor::zeros((1, cfg.text_dim), DType::F64, dev)?], 0)?;
    Ok(Inputs { x, t, text })
}

fn parity_model(cfg: MdmConfig, dev: &Device) -> Result<(Mdm, HashMap<String, Tensor>)> {
    let model = Mdm::load(cfg, fixture("mdm_tiny.safetensors"), DType::F32, dev)?;
    let io = candle_core::safetensors::load(fixture("mdm_tiny_io.safetensors"), dev)?;
    Ok((model, io))
}

fn io<'a>(io: &'a HashMap<String, Tensor>, name: &str) -> &'a Tensor {
    io.get(name).unwrap_or_else(|| panic!("{name} missing from mdm_tiny_io.safetensors"))
}

fn checkpoint_parity(dev: &Device) -> Result<()> {
    let (model, io_map) = parity_model(parity_config(), dev)?;
    let (x, text, want) = (io(&io_map, "x"), io(&io_map, "text"), io(&io_map, "out"));
    let t = io(&io_map, "timesteps").to_dtype(DType::U32)?;
    let frozen = model.predict_x0(x, &t, text)?;
    let err = max_abs_diff(&frozen, want)?;
    println!("parity max abs error, frozen path: {err:.3e}");
    assert!(err < 1e-4, "frozen path differs from PyTorch by {err}");

    let eval = model.forward_eval(x, &t, text)?;
    let err = max_abs_diff(&eval, want)?;
    println!("parity max abs error, primitive path: {err:.3e}");
    assert!(err < 1e-4, "primitive path differs from PyTorch by {err}");

    // Training path with dropout off is the same function.
    let no_dropout = parity_model(MdmConfig { dropout: 0.0, ..parity_config() }, dev)?.0;
    let train = no_dropout.forward_train(x, &t, text, &mut StdRng::seed_from_u64(0))?;
    assert!(max_abs_diff(&train, want)? < 1e-4);
    Ok(())
}

fn checkpoint_gradient_parity(dev: &Device) -> Result<()> {
    let (model, io_map) = parity_model(parity_config(), dev)?;
    let (x, text, want) = (io(&io_map, "x"), io(&io_map, "text"), io(&io_map, "grad_x"));
    let t = io(&io_map, "timesteps").to_dtype(DType::U32)?;
    let scale = want.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()? as f64;
    let z = Var::from_tensor(x)?;
    for (name, out) in [
        ("frozen", model.predict_x0(z.as_tensor(), &t, text)?),
        ("primitive", model.forward_eval(z.as_tensor(), &t, text)?),
    ] {
        let loss = out.sqr()?.mean_all()?;
        let want_loss = io(&io_map, "loss").to_vec1::<f32>()?[0];
        assert!((loss.to_scalar::<f32>()? - want_loss).abs() < 1e-5);
        let grads = loss.backward()?;
        let g = grads.get(z.as_tensor()).expect("no gradient for x");
        let err = max_abs_diff(g, want)?;
        println!("grad_x max abs error, {name} path: {err:.3e} (max |grad| {scale:.3e})");
        assert!(err < 1e-4 * scale.max(1e-3), "{name} gradient differs from PyTorch by {err}");
    }
    Ok(())
}

fn loads_by_official_names(dev: &Device) -> Result<()> {
    let ckpt = candle_core::safetensors::load(fixture("mdm_tiny.safetensors"), dev)?;
    let model = Mdm::load(parity_config(), fixture("mdm_tiny.safetensors"), DType::F32, dev)?;
    let ours: BTreeSet<&str> = model.named_parameters().iter().map(|(n, _)| n.as_str()).collect();
    let theirs: BTreeSet<&str> = ckpt.keys().map(String::as_str).filter(|k| !k.ends_with(".pe")).collect();
    assert_eq!(ours, theirs);
    assert_eq!(ckpt.len(), theirs.len() + 2, "both aliased pe buffers are in the checkpoint");
    let count: usize = model.named_parameters().iter().map(|(_, t)| t.elem_count()).sum();
    assert_eq!(count, parity_config().parameter_count());

    // Without the pe buffers the checkpoint still loads.
    let no_pe: HashMap<String, Tensor> = ckpt.clone().into_iter().filter(|(k, _)| !k.ends_with(".pe")).collect();
    Mdm::new(parity_config(), VarBuilder::from_tensors(no_pe, DType::F32, dev))?;
    // A missing parameter is an error.
    let mut missing = ckpt.clone();
    missing.remove("seqTransEncoder.layers.1.norm2.bias");
    assert!(Mdm::new(parity_config(), VarBuilder::from_tensors(missing, DType::F32, dev)).is_err());
    Ok(())
}

fn positional_table_matches_checkpoint_buffer(dev: &Device) -> Result<()> {
    let ckpt = candle_core::safetensors::load(fixture("mdm_tiny.safetensors"), dev)?;
    let theirs = ckpt.get("sequence_pos_encoder.pe").expect("pe buffer").squeeze(1)?;
    let rows = theirs.dim(0)?;
    let ours = sinusoidal_table(MAX_LEN, parity_config().latent_dim, dev)?.narrow(0, 0, rows)?;
    let err = max_abs_diff(&ours, &theirs)?;
    assert!(err < 1e-6, "pe table differs by {err}");
    Ok(())
}

fn save_and_reload_round_trip(dev: &Device) -> Result<()> {
    let cfg = tiny_config();
    let model = Mdm::random(cfg.clone(), DType::F64, dev, 5)?;
    let dir = tempfile::tempdir().map_err(candle_core::Error::wrap)?;
    let path = dir.path().join("tiny.safetensors");
    model.save(&path)?;
    let back = Mdm::load(cfg.clone(), &path, DType::F64, dev)?;
    let inp = tiny_inputs(&cfg, dev)?;
    let a = model.predict_x0(&inp.x, &inp.t, &inp.text)?;
    let b = back.predict_x0(&inp.x, &inp.t, &inp.text)?;
    assert_eq!(max_abs_diff(&a, &b)?, 0.0);
    Ok(())
}

fn frozen_and_primitive_paths_agree(dev: &Device) -> Result<()> {
    let cfg = tiny_config();
    let model = Mdm::random(cfg.clone(), DType::F64, dev, 6)?;
    let inp = tiny_inputs(&cfg, dev)?;
    let frozen = model.predict_x0(&inp.x, &inp.t, &inp.text)?;
    let eval = model.forward_eval(&inp.x, &inp.t, &inp.text)?;
    assert!(max_abs_diff(&frozen, &eval)? < 1e-12);
    assert_eq!(frozen.dims(), inp.x.dims());
    Ok(())
}

/// The fused path's transposed weights follow a trainable model's weights as the optimiser
/// changes them, and a loaded model's cached transposes give the same pass every time.
fn frozen_path_follows_changed_weights(dev: &Device) -> Result<()> {
    let cfg = tiny_config();
    let varmap = VarMap::new();
    let model = Mdm::init_seeded(cfg.clone(), &varmap, DType::F64, dev, 4)?;
    let inp = tiny_inputs(&cfg, dev)?;
    let before = model.predict_x0(&inp.x, &inp.t, &inp.text)?;
    for var in varmap.all_vars() {
        var.set(&(var.as_tensor() * 1.25)?)?;
    }
    let after = model.predict_x0(&inp.x, &inp.t, &inp.text)?;
    assert!(max_abs_diff(&before, &after)? > 1e-3, "the fused path kept the old weights");
    assert!(max_abs_diff(&after, &model.forward_eval(&inp.x, &inp.t, &inp.text)?)? < 1e-12);

    let (loaded, _) = parity_model(parity_config(), dev)?;
    let x = randn(&[1, 4, loaded.config().input_feats], 7, dev)?.to_dtype(DType::F32)?;
    let (t, text) = (Tensor::new(&[5u32], dev)?, Tensor::zeros((1, loaded.config().text_dim), DType::F32, dev)?);
    let first = loaded.predict_x0(&x, &t, &text)?;
    assert_eq!(max_abs_diff(&first, &loaded.predict_x0(&x, &t, &text)?)?, 0.0);
    assert!(max_abs_diff(&first, &loaded.forward_eval(&x, &t, &text)?)? < 1e-5);
    Ok(())
}

fn loss(out: &Tensor, w: &Tensor) -> Result<Tensor> {
    out.mul(w)?.sum_all()? + out.sqr()?.mean_all()?
}

fn gradients_match_finite_differences(dev: &Device) -> Result<()> {
    let cfg = tiny_config();
    let model = Mdm::random(cfg.clone(), DType::F64, dev, 7)?;
    let inp = tiny_inputs(&cfg, dev)?;
    let w = randn(inp.x.dims(), 52, dev)?;
    finite_difference_check(&inp.x, |x| loss(&model.predict_x0(x, &inp.t, &inp.text)?, &w), 1e-5, 1e-6)?;
    finite_difference_check(&inp.x, |x| loss(&model.forward_eval(x, &inp.t, &inp.text)?, &w), 1e-5, 1e-6)
}

fn frozen_gradient_equals_primitive_gradient(dev: &Device) -> Result<()> {
    let cfg = tiny_config();
    let model = Mdm::random(cfg.clone(), DType::F64, dev, 8)?;
    let inp = tiny_inputs(&cfg, dev)?;
    let w = randn(inp.x.dims(), 53, dev)?;
    let z = Var::from_tensor(&inp.x)?;
    let g_frozen = loss(&model.predict_x0(z.as_tensor(), &inp.t, &inp.text)?, &w)?.backward()?;
    let g_frozen = g_frozen.get(z.as_tensor()).expect("no frozen gradient").clone();
    let g_prim = loss(&model.forward_eval(z.as_tensor(), &inp.t, &inp.text)?, &w)?.backward()?;
    let g_prim = g_prim.get(z.as_tensor()).expect("no primitive gradient").clone();
    let diff = max_abs_diff(&g_frozen, &g_prim)?;
    println!("frozen vs primitive dx: {diff:e}");
    assert!(diff < 1e-12);
    let norm = g_frozen.sqr()?.sum_all()?.to_scalar::<f64>()?;
    assert!(norm.is_finite() && norm > 0.0);
    // Each sample's gradient is its own: the batch does not mix.
    assert!(g_frozen.i(1)?.abs()?.sum_all()?.to_scalar::<f64>()? > 0.0);
    Ok(())
}

fn fused_stack_gradient_matches_finite_differences(dev: &Device) -> Result<()> {
    // Sharper check of the fused op alone: two layers, larger width, f64.
    let cfg = MdmConfig { latent_dim: 12, ff_size: 20, num_layers: 2, num_heads: 3, ..tiny_config() };
    let model = Mdm::random(cfg.clone(), DType::F64, dev, 9)?;
    let h = randn(&[2, 4, 12], 54, dev)?;
    let w = randn(&[2, 4, 12], 55, dev)?;
    finite_difference_check(
        &h,
        |h| layer::frozen_stack(&model.layers, h, None, Isa::selected())?.mul(&w)?.sum_all(),
        1e-6,
        1e-7,
    )
}

/// Output and input gradient of the fused stack on 1, 2 and 3 worker threads, for one
/// element (split into row chunks and attention blocks) and for four (one task per element
/// on 2 threads, row phases on 3): the same numbers up to rounding every time (the gemm
/// kernels' blocking depends on the number of rows, so the last bits may differ).
fn fused_stack_is_the_same_on_any_thread_count(dev: &Device) -> Result<()> {
    let cfg = MdmConfig { latent_dim: 12, ff_size: 20, num_layers: 2, num_heads: 3, ..tiny_config() };
    let model = Mdm::random(cfg.clone(), DType::F64, dev, 10)?;
    for batch in [1, 4] {
        let h = randn(&[batch, 40, 12], 56, dev)?;
        let w = randn(&[batch, 40, 12], 57, dev)?;
        let run = |threads: usize| -> Result<(Vec<f64>, Vec<f64>)> {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .map_err(|e| candle_core::Error::Msg(e.to_string()))?;
            pool.install(|| {
                let var = candle_core::Var::from_tensor(&h)?;
                let y = layer::frozen_stack(&model.layers, var.as_tensor(), None, Isa::selected())?;
                let grads = y.mul(&w)?.sum_all()?.backward()?;
                let g = grads.get(var.as_tensor()).ok_or_else(|| candle_core::Error::Msg("no gradient".into()))?;
                Ok((y.flatten_all()?.to_vec1()?, g.flatten_all()?.to_vec1()?))
            })
        };
        let max_diff = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        let one = run(1)?;
        for threads in [2, 3] {
            let (y, g) = run(threads)?;
            assert!(max_diff(&y, &one.0) < 1e-12 && max_diff(&g, &one.1) < 1e-12, "batch {batch}, {threads} threads");
        }
        // And the same as the primitive path.
        let primitive =
            model.layers.iter().try_fold(h.clone(), |h, l| l.forward(&h, &mut Dropout { p: 0.0, rng: None }))?;
        let diff = max_diff(&primitive.flatten_all()?.to_vec1::<f64>()?, &one.0);
        assert!(diff < 1e-12, "batch {batch}: {diff}");
    }
    Ok(())
}

fn training_mode_has_seeded_dropout_and_weight_gradients(dev: &Device) -> Result<()> {
    let cfg = MdmConfig { dropout: 0.3, ..tiny_config() };
    let varmap = VarMap::new();
    let model = Mdm::init_seeded(cfg.clone(), &varmap, DType::F64, dev, 1)?;
    let again = Mdm::init_seeded(cfg.clone(), &VarMap::new(), DType::F64, dev, 1)?;
    for ((n, a), (_, b)) in model.named_parameters().iter().zip(again.named_parameters()) {
        assert_eq!(max_abs_diff(a, b)?, 0.0, "{n} init is not seeded");
    }
    assert_eq!(varmap.all_vars().len(), model.named_parameters().len());

    let inp = tiny_inputs(&cfg, dev)?;
    let a = model.forward_train(&inp.x, &inp.t, &inp.text, &mut StdRng::seed_from_u64(2))?;
    let b = model.forward_train(&inp.x, &inp.t, &inp.text, &mut StdRng::seed_from_u64(2))?;
    let c = model.forward_train(&inp.x, &inp.t, &inp.text, &mut StdRng::seed_from_u64(3))?;
    assert_eq!(max_abs_diff(&a, &b)?, 0.0);
    assert!(max_abs_diff(&a, &c)? > 1e-6);

    let grads = a.sqr()?.mean_all()?.backward()?;
    for (name, t) in model.named_parameters() {
        let g = grads.get(t).unwrap_or_else(|| panic!("no gradient for {name}"));
        assert!(g.sqr()?.sum_all()?.to_scalar::<f64>()?.is_finite());
    }
    // The frozen path gives no weight gradients.
    let grads = model.predict_x0(&inp.x, &inp.t, &inp.text)?.sqr()?.mean_all()?;
    assert!(grads.backward()?.get(&model.named_parameters()[0].1).is_none());
    Ok(())
}

fn velocity_prediction_scales_input_and_output(dev: &Device) -> Result<()> {
    let x0_cfg = tiny_config();
    let v_cfg = MdmConfig { prediction: Prediction::Velocity, ..tiny_config() };
    // Same seed, same weights: only the reading of the output head differs.
    let head = Mdm::random(x0_cfg.clone(), DType::F64, dev, 11)?;
    let model = Mdm::random(v_cfg.clone(), DType::F64, dev, 11)?;
    let inp = tiny_inputs(&v_cfg, dev)?;
    let out = head.predict_x0(&inp.x, &inp.t, &inp.text)?;
    let got = model.predict_x0(&inp.x, &inp.t, &inp.text)?;
    let ab = NoiseSchedule::mdm().alphas_cumprod().to_vec();
    for (b, t) in inp.t.to_vec1::<u32>()?.into_iter().enumerate() {
        let a = ab[t as usize];
        let want = ((inp.x.i(b)? * a.sqrt())? - (out.i(b)? * (1.0 - a).sqrt())?)?;
        assert!(max_abs_diff(&got.i(b)?, &want)? < 1e-12, "sample {b} at t = {t}");
    }
    // At t = 3 x̂0 is within a few per cent of x_t whatever the head says; at t = 999 it is the head.
    assert!(max_abs_diff(&got.i(1)?, &inp.x.i(1)?)? < 0.1 * max_abs_diff(&out.i(1)?, &inp.x.i(1)?)?);
    assert!(max_abs_diff(&model.forward_eval(&inp.x, &inp.t, &inp.text)?, &got)? < 1e-12);
    let w = randn(inp.x.dims(), 56, dev)?;
    finite_difference_check(&inp.x, |x| loss(&model.predict_x0(x, &inp.t, &inp.text)?, &w), 1e-5, 1e-6)?;
    // The schedule has 1000 steps: a later timestep is an error, not a silent wrap.
    let late = Tensor::new(&[1000u32, 3], dev)?;
    assert!(model.predict_x0(&inp.x, &late, &inp.text).is_err());
    Ok(())
}

/// The fused DDIM move (guidance, x̂0 and the update inside the pass) against the composed
/// one, for both predictions, with and without guidance and for the last move (x̂0 itself):
/// the same values, and a gradient that matches finite differences and the composed one.
fn fused_ddim_move_is_the_composed_move(dev: &Device) -> Result<()> {
    use crate::diffusion::{guided_move, DdimMove, Guidance};
    for prediction in [Prediction::X0, Prediction::Velocity] {
        let cfg = MdmConfig { prediction, ..tiny_config() };
        let model = Mdm::random(cfg.clone(), DType::F64, dev, 12)?;
        let x = randn(&[2, 5, cfg.input_feats], 57, dev)?;
        let text = randn(&[2, cfg.text_dim], 58, dev)?;
        let w = randn(x.dims(), 59, dev)?;
        for (guidance, step) in [
            (Guidance::default(), DdimMove::new(500, 0.3, 0.6)),
            (Guidance::none(), DdimMove::new(900, 0.02, 0.1)),
            (Guidance::default(), DdimMove::new(0, 0.99, 1.0)),
        ] {
            let label = format!("{prediction:?}, scale {}, {step:?}", guidance.scale);
            let fused = model.ddim_move(&x, &text, guidance, step)?;
            let composed = guided_move(&model, &x, &text, guidance, step)?;
            assert!(max_abs_diff(&fused, &composed)? < 1e-12, "{label}");
            finite_difference_check(&x, |x| loss(&model.ddim_move(x, &text, guidance, step)?, &w), 1e-5, 1e-6)?;
            let z = Var::from_tensor(&x)?;
            let grad = |out: Tensor| -> Result<Tensor> {
                let grads = loss(&out, &w)?.backward()?;
                grads.get(z.as_tensor()).cloned().ok_or_else(|| candle_core::Error::Msg("no gradient".into()))
            };
            let g_fused = grad(model.ddim_move(z.as_tensor(), &text, guidance, step)?)?;
            let g_composed = grad(guided_move(&model, z.as_tensor(), &text, guidance, step)?)?;
            assert!(max_abs_diff(&g_fused, &g_composed)? < 1e-12, "{label}");
        }
    }
    Ok(())
}

/// The fused denoiser on AVX2/FMA against the same pass on the CPU's best set and against
/// candle's unfused ops, in f32: a guided DDIM move (both branches, the ends and the move
/// inside the op) over three samples, and a plain x̂0 pass; values and input gradients agree
/// to 1e-5 of their largest entry.
fn avx2_fused_denoiser_matches_the_reference_kernels(dev: &Device) -> Result<()> {
    use crate::diffusion::{guided_move, DdimMove, Guidance};
    if !Isa::Avx2.is_available() {
        return Ok(());
    }
    let cfg = MdmConfig { latent_dim: 64, ff_size: 128, num_layers: 2, num_heads: 4, ..tiny_config() };
    let model = |isa: Isa| Mdm::random(cfg.clone(), DType::F32, dev, 13).map(|m| m.with_isa(isa));
    let (avx2, best) = (model(Isa::Avx2)?, model(Isa::best())?);
    let x = randn(&[3, 40, cfg.input_feats], 60, dev)?.to_dtype(DType::F32)?;
    let text = randn(&[3, cfg.text_dim], 61, dev)?.to_dtype(DType::F32)?;
    let w = randn(x.dims(), 62, dev)?.to_dtype(DType::F32)?;
    let step = DdimMove::new(500, 0.3, 0.6);
    let t = Tensor::new(&[999u32, 500, 3], dev)?;
    let value_and_grad = |pass: &dyn Fn(&Tensor) -> Result<Tensor>| -> Result<(Tensor, Tensor)> {
        let z = Var::from_tensor(&x)?;
        let out = pass(z.as_tensor())?;
        let grads = loss(&out, &w)?.backward()?;
        let g = grads.get(z.as_tensor()).cloned().ok_or_else(|| candle_core::Error::Msg("no gradient".into()))?;
        Ok((out, g))
    };
    let close = |label: &str, got: &Tensor, want: &Tensor| -> Result<()> {
        let scale = want.abs()?.flatten_all()?.max(0)?.to_scalar::<f32>()? as f64;
        let err = max_abs_diff(got, want)?;
        assert!(err <= 1e-5 * scale.max(1e-3), "{label}: error {err:e} of {scale:e}");
        Ok(())
    };
    type Pass<'a> = Box<dyn Fn(&Mdm, &Tensor) -> Result<Tensor> + 'a>;
    let passes: [(&str, Pass, Pass); 2] = [
        (
            "guided DDIM move",
            Box::new(|m, x| m.ddim_move(x, &text, Guidance::default(), step)),
            Box::new(|m, x| {
                let copies = Tensor::cat(&[x, x], 0)?;
                let rows = Tensor::cat(&[&text, &text.zeros_like()?], 0)?;
                let t = Tensor::new(&[500u32; 6], dev)?;
                let out = m.forward_eval(&copies, &t, &rows)?;
                let (cond, uncond) = (out.narrow(0, 0, 3)?, out.narrow(0, 3, 3)?);
                let guided = (&uncond + ((cond - &uncond)? * Guidance::default().scale)?)?;
                (x * step.c_x)? + (guided * step.c_0)?
            }),
        ),
        ("x̂0 pass", Box::new(|m, x| m.predict_x0(x, &t, &text)), Box::new(|m, x| m.forward_eval(x, &t, &text))),
    ];
    for (name, fused, unfused) in passes {
        let (y_avx2, g_avx2) = value_and_grad(&|x| fused(&avx2, x))?;
        let (y_best, g_best) = value_and_grad(&|x| fused(&best, x))?;
        let (y_ref, g_ref) = value_and_grad(&|x| unfused(&best, x))?;
        close(&format!("{name}, AVX2 against {}", Isa::best()), &y_avx2, &y_best)?;
        close(&format!("{name} gradient, AVX2 against {}", Isa::best()), &g_avx2, &g_best)?;
        close(&format!("{name}, AVX2 against candle's ops"), &y_avx2, &y_ref)?;
        close(&format!("{name} gradient, AVX2 against candle's ops"), &g_avx2, &g_ref)?;
    }
    // The guided move is the composed one too (guidance, x̂0 and the update outside the op).
    let composed = guided_move(&avx2, &x, &text, Guidance::default(), step)?;
    close("composed move", &avx2.ddim_move(&x, &text, Guidance::default(), step)?, &composed)
}

fn bad_inputs_are_errors(dev: &Device) -> Result<()> {
    let cfg = tiny_config();
    let model = Mdm::random(cfg.clone(), DType::F64, dev, 10)?;
    let inp = tiny_inputs(&cfg, dev)?;
    assert!(model.predict_x0(&inp.x.narrow(2, 0, 6)?, &inp.t, &inp.text).is_err());
    assert!(model.predict_x0(&inp.x, &inp.t.narrow(0, 0, 1)?, &inp.text).is_err());
    assert!(model.predict_x0(&inp.x, &inp.t, &inp.text.narrow(1, 0, 4)?).is_err());
    assert!(model.predict_x0(&inp.x.to_dtype(DType::F32)?, &inp.t, &inp.text).is_err());
    Ok(())
}

mod cpu {
    crate::nn::testing::cpu_tests!(
        checkpoint_parity,
        checkpoint_gradient_parity,
        loads_by_official_names,
        positional_table_matches_checkpoint_buffer,
        save_and_reload_round_trip,
        frozen_and_primitive_paths_agree,
        frozen_path_follows_changed_weights,
        gradients_match_finite_differences,
        frozen_gradient_equals_primitive_gradient,
        fused_stack_gradient_matches_finite_differences,
        fused_stack_is_the_same_on_any_thread_count,
        training_mode_has_seeded_dropout_and_weight_gradients,
        velocity_prediction_scales_input_and_output,
        fused_ddim_move_is_the_composed_move,
        avx2_fused_denoiser_matches_the_reference_kernels,
        bad_inputs_are_errors,
    );
}
