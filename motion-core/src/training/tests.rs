//! The trainer: resumption, shards, loss terms, EMA, schedule and the corpus path.

use std::path::Path;

use candle_core::{Device, Tensor};
use rand::rngs::StdRng;
use rand::SeedableRng;

use super::trainer::perturb_conditions;
use super::*;
use crate::database::catalog::Catalog;
use crate::database::{DatabaseConfig, MotionDatabase};
use crate::model::{MdmConfig, Prediction};
use crate::prior::Prior;

fn tiny_run() -> (TrainingSet, MdmConfig, TrainConfig) {
    let catalog = Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/mocap/catalog.json");
    let (sources, _) = Catalog::read(&catalog).unwrap().load().unwrap();
    let sources: Vec<_> =
        sources.into_iter().filter(|s| s.name.contains("walk") || s.name.contains("run")).take(2).collect();
    let db = MotionDatabase::build(
        &sources,
        &DatabaseConfig { speeds: vec![1.0], mirror: false, loop_seconds: 3.0, ..DatabaseConfig::default() },
    )
    .unwrap();
    let model = MdmConfig { latent_dim: 16, ff_size: 32, num_layers: 1, num_heads: 2, ..MdmConfig::small() };
    let train = TrainConfig {
        steps: 4,
        batch_size: 2,
        max_frames: 40,
        warmup_steps: 2,
        checkpoint_every: 2,
        ..TrainConfig::default()
    };
    (TrainingSet::from_database(&db, train.min_frames, train.balance_labels, &Device::Cpu).unwrap(), model, train)
}

#[test]
fn a_resumed_run_matches_an_uninterrupted_one_and_keeps_no_graph() {
    let (data, model, train) = tiny_run();
    let dev = Device::Cpu;
    let mut straight = Trainer::new(data.clone(), model.clone(), train.clone(), &dev).unwrap();
    straight.run(None, None, |_, _| Ok(())).unwrap();

    let dir = tempfile::tempdir().unwrap();
    let ckpt = dir.path().join("ckpt.safetensors");
    // Paused at step 2 of 4: the schedule stays 4 steps long, so the resumed run matches.
    let mut first = Trainer::new(data.clone(), model.clone(), train.clone(), &dev).unwrap();
    first.run(Some(2), Some(&ckpt), |_, _| Ok(())).unwrap();
    assert_eq!(first.step(), 2);
    let mut resumed = Trainer::new(data.clone(), model, train, &dev).unwrap();
    assert_eq!(resumed.resume(&ckpt).unwrap().step, 2);
    let mut losses = Vec::new();
    resumed
        .run(None, None, |r, _| {
            losses.push(r.loss);
            Ok(())
        })
        .unwrap();
    assert_eq!(losses.len(), 2);
    for ((a, b), (ea, eb)) in straight.vars.iter().zip(&resumed.vars).zip(straight.ema.iter().zip(&resumed.ema)) {
        let d =
            (a.1.as_tensor() - b.1.as_tensor()).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
        assert!(d < 1e-6, "{}: weights differ by {d}", a.0);
        let d = (ea - eb).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
        assert!(d < 1e-6, "{}: EMA differs by {d}", a.0);
        // The EMA must not hold an autograd graph (it would chain every step's graph).
        assert!(!ea.track_op(), "{}: EMA tensor tracks a graph", a.0);
    }
    let prior_path = dir.path().join("prior.safetensors");
    resumed.save_prior(&prior_path).unwrap();
    assert!(Prior::load(&prior_path, dir.path(), &dev).is_ok());
}

/// `--init`: a fine-tune starts at step 0 with the written prior's weights as both the model's
/// and the EMA's; a prior of another size is refused with the reason.
#[test]
fn a_fine_tune_starts_from_a_written_prior() {
    let (data, model, train) = tiny_run();
    let dev = Device::Cpu;
    let mut trained = Trainer::new(data.clone(), model.clone(), train.clone(), &dev).unwrap();
    trained.run(None, None, |_, _| Ok(())).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let prior = dir.path().join("prior.safetensors");
    trained.save_prior(&prior).unwrap();
    let fresh = TrainConfig { seed: 5, ..train.clone() };
    let mut tuned = Trainer::new(data.clone(), model.clone(), fresh.clone(), &dev).unwrap();
    tuned.init_from_prior(&prior).unwrap();
    assert_eq!(tuned.step(), 0);
    for (((name, var), ema), shipped) in tuned.vars.iter().zip(&tuned.ema).zip(&trained.ema) {
        for t in [var.as_tensor(), ema] {
            let d = (t - shipped).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
            assert!(d == 0.0, "{name}: differs from the prior's EMA by {d}");
        }
    }
    // The sizes come back from the file, so a caller need not repeat them.
    assert_eq!(&saved_model_config(&prior).unwrap(), trained.model_config());
    let ckpt = dir.path().join("ckpt.safetensors");
    trained.save_checkpoint(&ckpt).unwrap();
    assert_eq!(&saved_model_config(&ckpt).unwrap(), trained.model_config());
    let err = saved_model_config(&dir.path().join("none.safetensors")).unwrap_err().to_string();
    assert!(err.contains("none.safetensors"), "{err}");
    let wider = MdmConfig { latent_dim: 32, ..model };
    let mut other = Trainer::new(data, wider, fresh, &dev).unwrap();
    let err = other.init_from_prior(&prior).unwrap_err().to_string();
    assert!(err.contains("the model differs"), "{err}");
}

/// Sharding splits the batch, not the objective: without dropout (the only draw made per
/// shard) one shard and three uneven ones give the same training, and the number of
/// threads does not change a sharded run at all.
#[test]
fn shards_give_the_whole_batch_update_on_any_number_of_threads() {
    let (data, model, train) = tiny_run();
    let model = MdmConfig { dropout: 0.0, ..model };
    let train = TrainConfig { batch_size: 4, steps: 3, ..train };
    let run = |shards: usize, threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let config = TrainConfig { shards, ..train.clone() };
            let mut trainer = Trainer::new(data.clone(), model.clone(), config, &Device::Cpu).unwrap();
            let mut losses = Vec::new();
            trainer
                .run(None, None, |r, _| {
                    losses.push(r.loss);
                    Ok(())
                })
                .unwrap();
            let weights: Vec<Vec<f32>> =
                trainer.vars.iter().map(|(_, v)| v.as_tensor().flatten_all().unwrap().to_vec1().unwrap()).collect();
            (losses, weights)
        })
    };
    let (whole_losses, whole) = run(1, 1);
    let (sharded_losses, sharded) = run(3, 2);
    for (a, b) in whole_losses.iter().zip(&sharded_losses) {
        assert!((a - b).abs() < 1e-5 * a.abs(), "losses {whole_losses:?} against {sharded_losses:?}");
    }
    let largest = whole.iter().flatten().zip(sharded.iter().flatten()).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
    assert!(largest < 1e-5, "weights differ by up to {largest}");
    assert_eq!(run(3, 1), (sharded_losses, sharded), "the thread count changed a sharded run");
}

#[test]
fn geometric_terms_are_trained_and_reported_unless_switched_off() {
    let (data, model, train) = tiny_run();
    let dev = Device::Cpu;
    let on = TrainConfig { velocity_weight: 1.0, foot_contact_weight: 0.1, ..train.clone() };
    let mut on = Trainer::new(data.clone(), model.clone(), on, &dev).unwrap();
    let r = on.train_step().unwrap();
    assert!(r.velocity > 0.0 && r.foot_contact >= 0.0, "velocity {} foot contact {}", r.velocity, r.foot_contact);
    let off = TrainConfig { velocity_weight: 0.0, foot_contact_weight: 0.0, ..train };
    let mut off = Trainer::new(data.clone(), model, off, &dev).unwrap();
    let r = off.train_step().unwrap();
    assert_eq!((r.velocity, r.foot_contact), (0.0, 0.0));
}

#[test]
fn noisier_timesteps_and_corrupted_frames_change_what_the_denoiser_sees() {
    let (data, model, train) = tiny_run();
    let dev = Device::Cpu;
    let a = Trainer::new(data.clone(), model.clone(), train.clone(), &dev).unwrap().train_step().unwrap();
    for (name, config) in [
        ("high-noise fraction", TrainConfig { high_noise_fraction: 1.0, ..train.clone() }),
        ("frame corruption", TrainConfig { frame_corruption: 0.5, ..train.clone() }),
    ] {
        let b = Trainer::new(data.clone(), model.clone(), config, &dev).unwrap().train_step().unwrap();
        assert!(b.loss.is_finite(), "{name}");
        assert_ne!(a.loss, b.loss, "{name}: other inputs, another x0 MSE");
    }
}

#[test]
fn the_ema_forgets_the_random_initial_weights_within_a_few_steps() {
    let (data, model, train) = tiny_run();
    let mut t = Trainer::new(data.clone(), model, TrainConfig { ema_decay: 0.999, ..train }, &Device::Cpu).unwrap();
    let flat = |x: &Tensor| x.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let init = flat(t.vars[0].1.as_tensor());
    for _ in 0..3 {
        t.train_step().unwrap();
    }
    let (raw, ema) = (flat(t.vars[0].1.as_tensor()), flat(&t.ema[0]));
    let dist = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f32>().sqrt();
    // Warm-up decays 1/10, 2/11, 3/12 leave the initial weights 0.45 % of the EMA, the rest
    // is steps 1–3; a constant 0.999 would leave 99.7 % and the EMA would not move.
    let (moved, travelled) = (dist(&ema, &init), dist(&raw, &init));
    assert!(moved > 0.5 * travelled, "EMA moved {moved}, the weights {travelled}");
}

#[test]
fn loss_weightings_change_the_update_but_not_the_reported_mse() {
    let (data, model, train) = tiny_run();
    let dev = Device::Cpu;
    let moved = |t: &Trainer| t.vars[0].1.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
    let mut plain = Trainer::new(data.clone(), model.clone(), train.clone(), &dev).unwrap();
    let a = plain.train_step().unwrap();
    let weighted = [
        ("root weight", TrainConfig { root_weight: 25.0, ..train.clone() }),
        ("ric weight", TrainConfig { ric_weight: 10.0, ..train.clone() }),
        ("min-SNR", TrainConfig { snr_gamma: 5.0, ..train.clone() }),
    ];
    for (name, config) in weighted {
        let mut weighted = Trainer::new(data.clone(), model.clone(), config, &dev).unwrap();
        let b = weighted.train_step().unwrap();
        assert_eq!(a.loss, b.loss, "{name}: the same batch and weights give the same plain MSE");
        assert_ne!(moved(&plain), moved(&weighted), "{name}: the weighted loss must change the step");
    }
    // Velocity prediction: the default weighting is the v-MSE, not the x0 MSE of the same head.
    let velocity = MdmConfig { prediction: Prediction::Velocity, ..model };
    let mut v_mse = Trainer::new(data.clone(), velocity.clone(), train.clone(), &dev).unwrap();
    let a = v_mse.train_step().unwrap();
    let mut min_snr = Trainer::new(data.clone(), velocity, TrainConfig { snr_gamma: 5.0, ..train }, &dev).unwrap();
    let b = min_snr.train_step().unwrap();
    assert_eq!(a.loss, b.loss);
    assert_ne!(moved(&v_mse), moved(&min_snr), "the v-MSE must weight the steps differently");
}

#[test]
fn learning_rate_warms_up_then_decays_to_a_tenth() {
    let c = TrainConfig { steps: 1000, warmup_steps: 100, lr: 1.0, ..TrainConfig::default() };
    assert!((c.lr_at(0) - 0.01).abs() < 1e-12);
    assert!((c.lr_at(99) - 1.0).abs() < 1e-12);
    assert!((c.lr_at(100) - 1.0).abs() < 1e-12);
    assert!((c.lr_at(1000) - 0.1).abs() < 1e-12);
    assert!(c.lr_at(550) < c.lr_at(300));
}

/// The corpus path end to end: a split's clips train, another split's validate on the
/// training statistics; the validation loss depends on its seed only, and the prior written
/// names the encoder it was trained with.
#[test]
fn a_corpus_run_validates_on_held_out_clips_and_writes_its_encoder() {
    use crate::corpus::Split;
    let corpus = batches::tests::two_clip_corpus([Split::Train, Split::Validation]);
    let dev = Device::Cpu;
    let encoder = batches::tests::vocabulary();
    let train_set = TrainingSet::from_corpus(&corpus, Split::Train, encoder.clone(), None, &dev, |_, _| {}).unwrap();
    let held_out =
        TrainingSet::from_corpus(&corpus, Split::Validation, encoder, Some(train_set.mean_std()), &dev, |_, _| {})
            .unwrap();
    let (_, model, train) = tiny_run();
    let mut trainer = Trainer::new(train_set, model, train, &dev).unwrap();
    let before = trainer.validation_loss(&held_out, 2, 7).unwrap();
    assert!(before.is_finite() && before > 0.0);
    assert_eq!(before, trainer.validation_loss(&held_out, 2, 7).unwrap(), "fixed by the seed");
    let mut seen = Vec::new();
    trainer
        .run(None, None, |r, t| {
            seen.push((r.step, t.step()));
            Ok(())
        })
        .unwrap();
    assert_eq!(seen, vec![(1, 1), (2, 2), (3, 3), (4, 4)]);
    assert_ne!(before, trainer.validation_loss(&held_out, 2, 7).unwrap(), "the EMA weights moved");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("prior.safetensors");
    trainer.save_prior(&path).unwrap();
    let prior = Prior::load(&path, dir.path(), &dev).unwrap();
    assert!(matches!(prior.encoder, crate::text::ConditionEncoder::Vocabulary(_)));
    assert_eq!(prior.rest.map(|r| r.bone_lengths_m), Some(crate::skeleton::rest_bone_lengths()));
}

#[test]
fn text_noise_keeps_each_condition_s_length_and_blank_rows() {
    let dim = 384;
    let mut unit = vec![0f32; dim];
    unit[0] = 0.6;
    unit[1] = 0.8;
    let long: Vec<f32> = unit.iter().map(|v| 3.0 * v).collect();
    let rows = [unit.clone(), vec![0.0; dim], long].concat();
    let text = Tensor::from_vec(rows, (3, dim), &Device::Cpu).unwrap();
    let moved = perturb_conditions(&text, 0.05, &mut StdRng::seed_from_u64(7)).unwrap();
    let norms = moved.sqr().unwrap().sum(1).unwrap().sqrt().unwrap().to_vec1::<f32>().unwrap();
    assert!((norms[0] - 1.0).abs() < 1e-5 && norms[1] == 0.0 && (norms[2] - 3.0).abs() < 1e-4, "{norms:?}");
    // Moved, but at σ ≤ 0.05 no further than cosine 1/√(1 + 384·0.05²) ≈ 0.71 on average.
    let cosine = (&moved * &text).unwrap().sum(1).unwrap().to_vec1::<f32>().unwrap();
    assert!(cosine[0] < 1.0 - 1e-4 && cosine[0] > 0.4, "{cosine:?}");
    assert!((cosine[2] / 9.0 - 1.0).abs() > 1e-4 && cosine[2] / 9.0 > 0.4, "{cosine:?}");
    // The same stream moves them the same way (a resumed run draws what an uninterrupted one does).
    let again = perturb_conditions(&text, 0.05, &mut StdRng::seed_from_u64(7)).unwrap();
    assert_eq!(again.to_vec2::<f32>().unwrap(), moved.to_vec2::<f32>().unwrap());
}
