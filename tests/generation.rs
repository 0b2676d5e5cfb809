//! Constrained generation end to end with the shipped prior: a program compiled, every method
//! run on a short clip, the report's figures checked.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use candle_core::Device;
use e2e_tests::fixtures;
use motion_core::constraints::CompiledProgram;
use motion_core::evaluation::report;
use motion_core::generation::{generate, GenerationConfig, Method};
use motion_core::prior::Prior;
use motion_core::program::TaskProgram;

/// A 40-frame walk between walls 0.4 m apart that ends 1.5 m ahead.
const GAP_WALK: &str = r#"{
  "text": "a man walks forwards",
  "frames": 40,
  "constraints": [
    {"id": "c1", "expr": {"op": "scene", "body": {"joints": "all", "surface": true},
      "primitive": {"kind": "gap", "centre_x_m": 0.0, "width_m": 0.4, "z_range_m": [0.3, 1.2]}}},
    {"id": "c2", "expr": {"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"},
      "target": [1.5], "frames": {"keyframes": ["last"]}}}
  ]
}"#;

fn setup() -> (Prior, TaskProgram, CompiledProgram) {
    let device = Device::Cpu;
    let prior = Prior::load(&fixtures().join("model/prior.safetensors"), &device).unwrap();
    let program = TaskProgram::from_json_validated(GAP_WALK).unwrap();
    let compiled = CompiledProgram::compile(&program, &device).unwrap();
    (prior, program, compiled)
}

fn config(method: Method, steps: usize) -> GenerationConfig {
    let mut config = GenerationConfig::new(method);
    config.samples = 2;
    config.seed = 3;
    config.guidance = 1.0;
    config.dno.steps = steps;
    config.dno.lr_warmup_steps = 2;
    config.direct.steps = steps;
    config
}

#[test]
fn every_method_runs_and_optimisers_lower_the_error() {
    let (prior, program, compiled) = setup();
    let device = Device::Cpu;
    let unconstrained =
        generate(&prior, &program, &compiled, &config(Method::Unconstrained, 0), &device, |_| {}).unwrap();
    let base = report(&program, &compiled, &unconstrained, &config(Method::Unconstrained, 0)).unwrap();
    assert_eq!(unconstrained.joints.dims(), [2, 40, 22, 3]);
    assert!(base.constraint_error > 0.0 && base.constraint_error.is_finite());
    for method in [Method::Ik, Method::IkReg, Method::Dno] {
        let mut steps = 0;
        let run = generate(&prior, &program, &compiled, &config(method, 12), &device, |_| steps += 1).unwrap();
        assert_eq!(steps, 12, "{method}: one progress call per step");
        let r = report(&program, &compiled, &run, &config(method, 12)).unwrap();
        assert_eq!(r.constraints.len(), 2);
        assert!(
            r.constraint_error < base.constraint_error,
            "{method}: {} not below the unconstrained {}",
            r.constraint_error,
            base.constraint_error
        );
        for history in &run.loss_history {
            assert_eq!(history.len(), 12);
            assert!(history[11] < history[0], "{method}: {history:?}");
        }
        assert!(r.max_scene_penetration_m.is_some_and(f64::is_finite));
        assert!(r.foot_skate_ratio.is_finite() && r.max_acceleration.is_finite());
    }
}

#[test]
fn dno_is_reproducible_from_its_seed() {
    let (prior, program, compiled) = setup();
    let device = Device::Cpu;
    let a = generate(&prior, &program, &compiled, &config(Method::Dno, 3), &device, |_| {}).unwrap();
    let b = generate(&prior, &program, &compiled, &config(Method::Dno, 3), &device, |_| {}).unwrap();
    let diff = (a.joints - b.joints).unwrap().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
    assert_eq!(diff, 0.0);
}
