//! RG-DNO end to end on the shipped catalog, corpus and prior: retrieval finds a planted crop
//! in a database, the shipped corpus gives a low motion for the barrier from its train split, and
//! a tiny configuration of the whole method runs through every stage.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use candle_core::Device;
use e2e_tests::fixtures;
use motion_core::constraints::CompiledProgram;
use motion_core::database::catalog::Catalog;
use motion_core::database::{DatabaseConfig, MotionDatabase};
use motion_core::generation::method::{GenerationConfig, Method};
use motion_core::generation::rgdno::candidates::{RetrievalDatabase, RetrievalSource};
use motion_core::generation::rgdno::config::{RetrievalConfig, RgDnoConfig};
use motion_core::generation::rgdno::mask::MaskKind;
use motion_core::generation::rgdno::retrieval::{retrieve, RetrievalQuery};
use motion_core::generation::rgdno::{generate_rg_dno, RgDnoTask};
use motion_core::prior::Prior;
use motion_core::program::TaskProgram;
use motion_core::testing::pinned_program_json;
use motion_core::text::{ConditionEncoder, MINILM_NAME};

/// The shipped catalog's clips as a retrieval database (a user's own database takes this path).
fn database() -> RetrievalDatabase {
    let (sources, _) = Catalog::read(&fixtures().join("mocap/catalog.json")).unwrap().load().unwrap();
    let config = DatabaseConfig { speeds: vec![1.0], loop_seconds: 4.0, ..DatabaseConfig::default() };
    RetrievalDatabase::from_motion_database(&MotionDatabase::build(&sources, &config).unwrap()).unwrap()
}

/// A program that pins the pelvis and both wrists of `joints` `[T, 22, 3]` at four keyframes.
fn pinned_program(joints: &candle_core::Tensor) -> TaskProgram {
    TaskProgram::from_json_validated(&pinned_program_json(joints, "a person moves", true).unwrap()).unwrap()
}

/// The shipped Task 2 at 40 frames, edited by `edit` (its JSON), compiled.
fn task2_at_40_frames(edit: impl FnOnce(&mut serde_json::Value), device: &Device) -> (TaskProgram, CompiledProgram) {
    let text = std::fs::read_to_string(fixtures().join("tasks/rgdno_task2_low_barrier.json")).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json["frames"] = 40.into();
    edit(&mut json);
    let program = TaskProgram::from_json_validated(&json.to_string()).unwrap();
    let compiled = CompiledProgram::compile(&program, device).unwrap();
    (program, compiled)
}

/// RG-DNO in miniature: `first` steps for the branches and the blend, `last` final steps,
/// `polish` steps for each inversion polish, 2 temporal segments.
fn tiny_rg(first: usize, last: usize, polish: usize) -> RgDnoConfig {
    RgDnoConfig {
        first_steps: first,
        final_steps: last,
        segments: 2,
        mask_kinds: vec![MaskKind::Temporal],
        inversion: motion_core::generation::inversion::InversionConfig {
            feature_polish_steps: polish,
            polish_steps: polish,
            fixed_point_iterations: 1,
            ..Default::default()
        },
        ..RgDnoConfig::default()
    }
}

#[test]
fn retrieval_finds_a_planted_crop_and_the_semantic_check_filters() {
    let device = Device::Cpu;
    let database = database();
    // The looped clips of this database are 4 s: 79 frames of joints.
    let frames = 50;
    let config = RetrievalConfig::default();
    let crops = database.crops(frames, &config).unwrap();
    assert!(crops.len() > 100, "{} candidates", crops.len());
    // Plant: some crawl crop away from its sequence's start, played as captured.
    let planted = crops
        .iter()
        .find(|c| {
            let s = database.source(c, frames);
            s.caption.contains("crawl") && s.start == 20 && s.frames == frames + 1 && !c.mirrored
        })
        .unwrap();
    let source = database.source(planted, frames);
    // The pins are where the generator's features of the crop put the joints.
    let features = database.features(planted, frames, &device).unwrap().unsqueeze(0).unwrap();
    let joints = motion_core::representation::recover_from_ric(&features).unwrap().squeeze(0).unwrap();
    let program = pinned_program(&joints);
    // Every pin counts fully: the score is the sum of all twelve.
    let all: Vec<String> = program.constraints.iter().map(|c| c.id.clone()).collect();
    let compiled = CompiledProgram::compile(&program, &device).unwrap().subset(&all);
    let config = RetrievalConfig { related_weight: 1.0, ..config };
    let query = RetrievalQuery {
        program: &compiled,
        most_difficult: "c1",
        prompt: &program.text,
        counting: false,
        encoder: None,
    };
    let found = retrieve(&database, &query, &config, &device).unwrap().retrieved;
    assert_eq!(found[0].source, source, "best: {}", found[0].source);
    assert!(found[0].score < 1e-6, "{}", found[0].score);
    assert!(found.len() == config.top_k && found.windows(2).all(|w| w[0].score <= w[1].score));
    // The same pins with a prompt that contradicts the crawl's direction drop every forward crop.
    let backwards = RetrievalQuery { prompt: "a person crawls backwards", ..query };
    let found = retrieve(&database, &backwards, &config, &device).unwrap().retrieved;
    assert!(found.iter().all(|r| !r.source.caption.contains("forward")), "{}", found[0].source);
    // A threshold below every score keeps nothing.
    let strict = RetrievalConfig { threshold: Some(-1.0), ..config };
    assert!(retrieve(&database, &query, &strict, &device).unwrap().retrieved.is_empty());
}

/// The default retrieval database, the shipped corpus's train split: for Task 2 (a 0.5 m barrier)
/// the best crop keeps low (a crouch, a crawl, a dive or a roll) and comes from a train clip.
#[test]
fn the_shipped_corpus_retrieves_a_low_motion_from_its_train_split_for_the_barrier() {
    let device = Device::Cpu;
    let path = fixtures().join("corpus/corpus.safetensors.gz");
    let (database, _) = RetrievalSource::from_path(&path).open().unwrap();
    let corpus = motion_core::corpus::file::load(&path).unwrap();
    let train: Vec<&str> =
        corpus.clips.iter().filter(|c| c.split == motion_core::corpus::Split::Train).map(|c| c.name.as_str()).collect();
    assert_eq!(database.clips(), train.len());
    let program = TaskProgram::from_json_validated(
        &std::fs::read_to_string(fixtures().join("tasks/rgdno_task2_low_barrier.json")).unwrap(),
    )
    .unwrap();
    let groups = program.constraint_groups().unwrap();
    let compiled = CompiledProgram::compile(&program, &device).unwrap().subset(&groups.retrieval);
    let encoder = ConditionEncoder::sentence(MINILM_NAME, &fixtures().join("text"), &device).unwrap();
    let query = RetrievalQuery {
        program: &compiled,
        most_difficult: "c1",
        prompt: &program.text,
        counting: false,
        encoder: Some(&encoder),
    };
    let found = retrieve(&database, &query, &RetrievalConfig::default(), &device).unwrap();
    assert!(found.retrieved.iter().all(|r| r.caption_similarity.is_some_and(|c| (-1.0..=1.0).contains(&c))));
    assert!(found.consistent < found.candidates, "the walk prompt drops runs, jumps and backward walks");
    let best = &found.retrieved[0].source;
    assert!(found.retrieved.iter().all(|r| train.contains(&r.source.clip.as_str())));
    assert!(["crouch", "crawl", "sneak", "creep", "roll", "floor"].iter().any(|w| best.caption.contains(w)), "{best}");
}

#[test]
fn a_tiny_rg_dno_run_goes_through_every_stage() {
    let device = Device::Cpu;
    let prior = Prior::load(&fixtures().join("model/prior.safetensors"), &fixtures().join("text"), &device).unwrap();
    // Task-2 shortened to 40 frames: the barrier at 0.5 < z < 1.0, the target at z = 1.5.
    let (program, compiled) = task2_at_40_frames(
        |json| {
            json["constraints"][0]["expr"]["args"][0]["primitive"]["z_range_m"] = serde_json::json!([0.5, 1.0]);
            for arg in 0..2 {
                json["constraints"][1]["expr"]["args"][arg]["target"] = serde_json::json!([1.5]);
            }
        },
        &device,
    );
    let database = database();
    let rg = tiny_rg(3, 3, 2);
    let mut config = GenerationConfig::new(Method::RgDno);
    config.samples = 2;
    config.guidance = 1.0;
    let mut stages = Vec::new();
    let task = RgDnoTask { program: &program, compiled: &compiled, database: &database };
    let (generated, report) = generate_rg_dno(&prior, task, &config, &rg, &device, |p| {
        if stages.last() != Some(&p.stage) {
            stages.push(p.stage);
        }
    })
    .unwrap();
    use motion_core::generation::rgdno::report::Stage::*;
    assert_eq!(stages, vec![Inversion, Branches, Masks, SoftBlend, FinalRound]);
    assert_eq!(generated.joints.dims(), &[2, 40, 22, 3]);
    let values = generated.joints.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    assert!(values.iter().all(|v| v.is_finite()));
    // C_R is the barrier with the target; the retrieved motion keeps low under it: a crawl.
    assert_eq!(report.retrieval_set, vec!["c1".to_owned(), "c2".to_owned()]);
    assert!(report.retrieved[0].source.caption.contains("crawl"), "{}", report.retrieved[0].source);
    assert_eq!(report.masks.len(), 2);
    assert!(report.masks.iter().all(|m| m.candidate.kind == MaskKind::Temporal && m.candidate.bits < 4));
    assert!(report.inverted.len() == 1 && report.inverted[0].motion == 0 && report.inverted[0].error_m.is_finite());
    assert!(report.soft_blend_objective.iter().all(|v| v.is_finite()));
    assert_eq!(generated.loss_history[0].len(), 3);
    assert_eq!((report.restart.as_slice(), report.motion.as_slice()), ([0, 0].as_slice(), [0, 0].as_slice()));
    // Retrieval keeps one crop per take.
    let takes: Vec<&str> = report.retrieved.iter().map(|r| r.source.clip.split('#').next().unwrap()).collect();
    assert!(takes.len() > 1 && (1..takes.len()).all(|k| !takes[..k].contains(&takes[k])), "{takes:?}");

    // Two retrieved motions: the first is the run above, so each sample keeps a final F_C at
    // most its one-motion value, from the motion that reached the lower one. Skipping the first
    // starts from the second alone.
    let two = RgDnoConfig { retrieved_motions: 2, ..rg.clone() };
    let mut inversions = Vec::new();
    let (_, both) = generate_rg_dno(&prior, task, &config, &two, &device, |p| {
        if p.stage == Inversion {
            inversions.push(p.round);
        }
    })
    .unwrap();
    assert_eq!(both.inverted.iter().map(|i| i.motion).collect::<Vec<_>>(), [0, 1]);
    assert!(inversions.contains(&0) && inversions.contains(&1), "{inversions:?}");
    let second = RgDnoConfig { skip_retrieved: 1, ..rg.clone() };
    let (_, alone) = generate_rg_dno(&prior, task, &config, &second, &device, |_| {}).unwrap();
    assert_eq!((alone.inverted.len(), alone.inverted[0].motion, alone.motion.as_slice()), (1, 1, [1, 1].as_slice()));
    for b in 0..2 {
        let best = report.final_objective[b].min(alone.final_objective[b]);
        assert!((both.final_objective[b] - best).abs() <= 1e-6 * best.max(1.0), "sample {b}");
        let from_second = alone.final_objective[b] < report.final_objective[b];
        assert_eq!(both.motion[b], usize::from(from_second), "sample {b}");
    }

    // Restarts N_S: restart 0 is the run above, so each sample keeps a final F_C at most its
    // one-restart value, from the restart that reached the lower one.
    config.dno.restarts = 2;
    let mut rounds = Vec::new();
    let (_, restarted) = generate_rg_dno(&prior, task, &config, &rg, &device, |p| rounds.push(p.round)).unwrap();
    assert_eq!(rounds.iter().max(), Some(&1));
    for b in 0..2 {
        assert!(restarted.final_objective[b] <= report.final_objective[b], "sample {b}");
        let better = restarted.final_objective[b] < report.final_objective[b];
        assert_eq!(restarted.restart[b], usize::from(better), "sample {b}");
    }
    config.dno.restarts = 1;

    // Table 4's "M = 0.5": no mask search, the branches blended half and half.
    let half = RgDnoConfig { ablation: motion_core::generation::rgdno::config::Ablation::HalfMask, ..rg.clone() };
    let mut stages = Vec::new();
    let (_, halved) = generate_rg_dno(&prior, task, &config, &half, &device, |p| stages.push(p.stage)).unwrap();
    assert!(halved.masks.is_empty() && !stages.contains(&Masks) && !stages.contains(&SoftBlend));

    // Settings the stages cannot run with are errors naming the field, never a panic.
    for (bad, field) in [
        (RgDnoConfig { segments: 40, ..rg.clone() }, "segments"),
        (RgDnoConfig { segments: 0, ..rg.clone() }, "segments"),
        (RgDnoConfig { mask_kinds: vec![], ..rg.clone() }, "mask_kinds"),
        (RgDnoConfig { final_lr: f64::NAN, ..rg.clone() }, "final_lr"),
        (RgDnoConfig { retrieved_motions: 0, ..rg.clone() }, "retrieved_motions"),
    ] {
        let err = generate_rg_dno(&prior, task, &config, &bad, &device, |_| {}).err().unwrap().to_string();
        assert!(err.contains(field), "{err}");
    }
}

/// Under the until-met schedule the stages before the final round sample through every other
/// DDIM timestep; on a program no motion meets, the final round runs its whole budget, first on
/// that sampler and then on the whole one, its steps and curve counted over both.
#[test]
fn the_until_met_final_round_spends_an_unmet_budget_over_both_samplers_and_each_sample_runs_on_its_own() {
    let device = Device::Cpu;
    let prior = Prior::load(&fixtures().join("model/prior.safetensors"), &fixtures().join("text"), &device).unwrap();
    // Task-2 at 40 frames with its target 50 m ahead: no motion of 2 s meets it.
    let (program, compiled) = task2_at_40_frames(
        |json| {
            for arg in 0..2 {
                json["constraints"][1]["expr"]["args"][arg]["target"] = serde_json::json!([50.0]);
            }
        },
        &device,
    );
    let database = database();
    let rg = tiny_rg(2, 8, 1);
    assert_eq!(rg.early_stride, 2);
    let mut config = GenerationConfig::new(Method::RgDno);
    config.samples = 1;
    config.schedule = motion_core::generation::schedule::Schedule::UntilMet;
    let mut final_steps = Vec::new();
    let task = RgDnoTask { program: &program, compiled: &compiled, database: &database };
    use motion_core::generation::rgdno::report::Stage::{FinalRound, FinalRoundCoarse};
    let (generated, report) = generate_rg_dno(&prior, task, &config, &rg, &device, |p| {
        if [FinalRoundCoarse, FinalRound].contains(&p.stage) {
            assert_eq!(p.steps, 8);
            final_steps.push((p.stage, p.step));
        }
    })
    .unwrap();
    let expected: Vec<_> = (1..=8).map(|k| (if k <= 6 { FinalRoundCoarse } else { FinalRound }, k)).collect();
    assert_eq!(final_steps, expected, "6 steps on every other timestep, the last quarter on all, one count");
    assert_eq!((report.steps.final_round, report.steps.final_round_coarse), (8, 6));
    assert_eq!(generated.loss_history[0].len(), 8);
    assert!(!report.final_objective[0].is_nan() && report.final_objective[0] > 1.0, "{:?}", report.final_objective);

    // Each sample runs the stages after the inversion on its own: its progress names it, and the
    // network's motions of the first two of three samples are those of a two-sample run.
    use motion_core::generation::rgdno::report::Stage::{Branches, Inversion};
    let mut named = Vec::new();
    config.samples = 2;
    let (two, _) = generate_rg_dno(&prior, task, &config, &rg, &device, |p| named.push((p.stage, p.sample))).unwrap();
    assert!(named.iter().all(|&(stage, sample)| (stage == Inversion) == sample.is_none()), "{named:?}");
    for i in 0..2 {
        assert!(named.contains(&(Branches, Some(i))) && named.contains(&(FinalRound, Some(i))), "{named:?}");
    }
    config.samples = 3;
    let (three, _) = generate_rg_dno(&prior, task, &config, &rg, &device, |_| {}).unwrap();
    let rows = |t: &candle_core::Tensor| t.narrow(0, 0, 2).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
    assert_eq!(rows(&three.features), rows(&two.features));
}
