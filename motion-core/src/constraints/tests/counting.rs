//! One measure for the optimiser and the judge (issue 60, item 4): a step or event count's error
//! is 0 exactly when the judge passes it, on motions where the soft count alone is at its minimum
//! but the judge counts otherwise, and all along an optimisation.

use candle_core::{Tensor, Var};

use super::*;
use crate::optim::AdamW;

const WRISTS: &str =
    r#"{"kind": "distance", "a": {"joint": "left_wrist"}, "b": {"joint": "right_wrist"}, "axes": "xyz"}"#;

/// Three claps: the wrists within 6 cm, opening beyond 11 cm between (the default 5 cm band).
fn three_claps() -> String {
    format!(r#"{{"op": "events", "signal": {WRISTS}, "event": {{"below": 0.06}}, "target_count": 3}}"#)
}

/// Two claps, and between them and after them two dips of the wrists into the band (to 8.5 and
/// 8 cm): the judge counts 2; the soft count about 3, as each dip goes half-way in its soft
/// state. (Two dips of one depth would cross θ together under any optimiser that moves them
/// alike, taking the judge's count from 2 to 4 in one step.)
fn two_claps_and_two_dips() -> Vec<[[f64; 3]; NUM_JOINTS]> {
    wrists_apart(&[0.4, 0.3, 0.02, 0.01, 0.3, 0.3, 0.085, 0.3, 0.3, 0.02, 0.3, 0.3, 0.08, 0.3, 0.4])
}

/// Standing, the left toe `forward[t]` m ahead of where it stands.
fn left_toe_at(forward: &[f64]) -> Vec<[[f64; 3]; NUM_JOINTS]> {
    forward
        .iter()
        .map(|d| {
            let mut pose = STANDING;
            pose[Joint::LeftFoot.index()][2] += d;
            pose
        })
        .collect()
}

/// The constraint's error on `motion`, valued as the judge counts and by the soft count, and
/// whether the judge passes it.
fn judged_soft_pass(expr: &str, motion: &[[[f64; 3]; NUM_JOINTS]]) -> (f64, f64, bool) {
    let compiled = compile(motion.len(), expr);
    let error =
        |program: &CompiledProgram| program.evaluate(&tensor(motion), None).unwrap().total.to_vec1::<f64>().unwrap()[0];
    let pass = compiled.satisfaction(&tensor(motion), None).unwrap().remove(0).pass[0];
    (error(&compiled), error(&compiled.soft_counts()), pass)
}

#[test]
fn where_the_soft_count_is_at_its_minimum_but_the_judge_counts_otherwise_the_error_is_the_judges() {
    // Events: the dips make the soft count 3 (error about 0), the judge 2 (error 1).
    let (judged, soft, pass) = judged_soft_pass(&three_claps(), &two_claps_and_two_dips());
    assert!(soft < 0.01 && !pass && judged == 1.0, "soft {soft}, judged {judged}, pass {pass}");
    // Steps: the left toe swings 45 cm at 3 m/s, rests for one frame (0.2 m/s) and swings 45 cm
    // again. The judge ends a swing under 0.5 m/s and counts 2 footfalls; the soft count, on the
    // speed over 3 frames, rides through the rest and counts 1.
    let two_swings = [0.0, 0.0, 0.0, 0.0, 0.15, 0.3, 0.45, 0.46, 0.61, 0.76, 0.91, 0.91, 0.91, 0.91];
    let one_step = r#"{"op": "steps", "target_count": 1}"#;
    let (judged, soft, pass) = judged_soft_pass(one_step, &left_toe_at(&two_swings));
    assert!(soft < 0.01 && !pass && judged == 1.0, "soft {soft}, judged {judged}, pass {pass}");
    let two_steps = r#"{"op": "steps", "target_count": 2}"#;
    let (judged, _, pass) = judged_soft_pass(two_steps, &left_toe_at(&two_swings));
    assert!(pass && judged == 0.0, "judged {judged}, pass {pass}");
}

#[test]
fn a_judged_count_has_the_soft_counts_gradient() {
    // The error's gradient is 2((n_soft − N) + (n_judge − N)) · dn_soft/dx: the soft error's
    // gradient 2(n_soft − N) · dn_soft/dx scaled by 1 + (n_judge − N)/(n_soft − N).
    let motion = two_claps_and_two_dips();
    let compiled = compile(motion.len(), &three_claps());
    let gradient = |program: &CompiledProgram| {
        let x = Var::from_tensor(&tensor(&motion)).unwrap();
        let error = program.evaluate(x.as_tensor(), None).unwrap().total;
        let grads = error.sum_all().unwrap().backward().unwrap();
        let gradient = grads.get(x.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f64>().unwrap();
        (error.to_vec1::<f64>().unwrap()[0], gradient)
    };
    let (judged_error, judged) = gradient(&compiled);
    let (soft_error, soft) = gradient(&compiled.soft_counts());
    // n_judge − N = −1 and n_soft − N = ±√soft_error.
    assert_eq!(judged_error, 1.0);
    let largest = (0..soft.len()).max_by(|a, b| soft[*a].abs().total_cmp(&soft[*b].abs())).unwrap();
    assert!(soft[largest].abs() > 0.0);
    let scale = judged[largest] / soft[largest];
    let expected = [1.0 - 1.0 / soft_error.sqrt(), 1.0 + 1.0 / soft_error.sqrt()];
    assert!(expected.iter().any(|e| (scale - e).abs() < 1e-6 * e.abs()), "{scale} against {expected:?}");
    for (j, s) in judged.iter().zip(&soft) {
        assert!((j - s * scale).abs() <= 1e-9 * judged[largest].abs(), "{j} against {s} × {scale}");
    }
}

/// Adam on the wrists from the two claps and two dips: at every step the error is 0 exactly when
/// the judge passes, and the optimiser reaches it (the dips become claps). On the soft count
/// alone the same start is already at its minimum, and the judge fails it.
#[test]
fn optimising_a_judged_count_ends_where_the_judge_passes() {
    let motion = two_claps_and_two_dips();
    let compiled = compile(motion.len(), &three_claps());
    let x = Var::from_tensor(&tensor(&motion)).unwrap();
    let mut adam = AdamW::new(vec![x.clone()], 0.0).unwrap();
    let mut reached = None;
    for step in 0..200 {
        let error = compiled.evaluate(x.as_tensor(), None).unwrap().total;
        let value = error.to_vec1::<f64>().unwrap()[0];
        let pass = compiled.satisfaction(x.as_tensor(), None).unwrap().remove(0).pass[0];
        assert_eq!(value == 0.0, pass, "step {step}: error {value}, judge {pass}");
        if pass {
            reached = Some(step);
            break;
        }
        adam.step(&error.sum_all().unwrap().backward().unwrap(), 0.005).unwrap();
    }
    let reached = reached.expect("the optimiser reaches the judge's count");
    assert!(reached > 0, "the start does not pass");
    let soft = compiled.soft_counts();
    let start = tensor(&motion);
    let soft_error = soft.evaluate(&start, None).unwrap().total.to_vec1::<f64>().unwrap()[0];
    assert!(soft_error < 0.01 && !soft.satisfaction(&start, None).unwrap().remove(0).pass[0]);
}

#[test]
fn soft_counts_is_a_proxy_of_the_same_constraints() {
    let compiled = compile(15, &three_claps());
    let soft = compiled.soft_counts();
    assert_eq!(soft.ids().collect::<Vec<_>>(), compiled.ids().collect::<Vec<_>>());
    let motion = tensor(&two_claps_and_two_dips());
    let as_f64 = |t: &Tensor| t.to_vec1::<f64>().unwrap();
    let judged = compiled.satisfaction(&motion, None).unwrap().remove(0).checks[0].value.clone();
    assert_eq!(judged, soft.satisfaction(&motion, None).unwrap().remove(0).checks[0].value, "the judge is the same");
    assert_ne!(
        as_f64(&compiled.evaluate(&motion, None).unwrap().total),
        as_f64(&soft.evaluate(&motion, None).unwrap().total)
    );
}
