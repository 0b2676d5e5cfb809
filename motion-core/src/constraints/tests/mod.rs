//! Every primitive against a hand-computed value on a hand-built motion, and its gradient
//! against finite differences; property tests over random motions and the shipped tasks.

use candle_core::{DType, Device, Tensor};
use proptest::prelude::*;

use super::probe::STANDING;
use super::*;
use crate::program::TaskProgram;
use crate::skeleton::Joint;
use crate::skeleton::NUM_JOINTS;
use crate::testing::finite_difference_check;

mod counting;
mod scene;

/// The standing pose gliding along +z at 1 m/s (0.05 m per frame), frames `[T][22][3]`.
fn glide(frames: usize) -> Vec<[[f64; 3]; NUM_JOINTS]> {
    (0..frames).map(|t| STANDING.map(|[x, y, z]| [x, y, z + 0.05 * t as f64])).collect()
}

fn tensor(motion: &[[[f64; 3]; NUM_JOINTS]]) -> Tensor {
    let flat: Vec<f64> = motion.iter().flatten().flatten().copied().collect();
    Tensor::from_vec(flat, (1, motion.len(), NUM_JOINTS, 3), &Device::Cpu).unwrap()
}

fn program(frames: usize, expr: &str) -> TaskProgram {
    let text = format!(r#"{{"text": "", "frames": {frames}, "constraints": [{{"id": "c1", "expr": {expr}}}]}}"#);
    TaskProgram::from_json(&text).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

fn compile(frames: usize, expr: &str) -> CompiledProgram {
    CompiledProgram::compile(&program(frames, expr), &Device::Cpu).unwrap_or_else(|e| panic!("{e}\n{expr}"))
}

/// The error of a one-constraint program on `motion`.
fn error_of(expr: &str, motion: &[[[f64; 3]; NUM_JOINTS]]) -> f64 {
    error_with_initial(expr, motion, None)
}

fn error_with_initial(expr: &str, motion: &[[[f64; 3]; NUM_JOINTS]], initial: Option<&Tensor>) -> f64 {
    let compiled = compile(motion.len(), expr);
    let e = compiled.evaluate(&tensor(motion), initial).unwrap();
    let total = e.total.to_vec1::<f64>().unwrap()[0];
    let own = e.per_constraint[0].1.to_vec1::<f64>().unwrap()[0];
    assert_eq!(total, own, "weight 1: total = the constraint's error");
    total
}

fn close(expr: &str, motion: &[[[f64; 3]; NUM_JOINTS]], expected: f64) {
    let got = error_of(expr, motion);
    assert!((got - expected).abs() < 1e-5 * expected.abs().max(1.0), "{expr}\n  got {got}, expected {expected}");
}

/// The gradient of the program's total w.r.t. a jittered version of `motion` matches finite
/// differences, with steps and events valued by their soft count (a judged count's value moves
/// in whole jumps; its gradient is the soft count's, `counting::a_judged_count_has_the_soft_counts_gradient`).
fn gradient_ok(expr: &str, motion: &[[[f64; 3]; NUM_JOINTS]]) {
    let compiled = compile(motion.len(), expr).soft_counts();
    let base = tensor(motion);
    let jitter = (random_motion(motion.len(), 11) - tensor(&glide(motion.len()))).unwrap() * 0.02;
    let jitter = jitter.unwrap();
    let x = (base + jitter).unwrap();
    let initial = (&x + 0.03).unwrap().detach();
    finite_difference_check(
        &x,
        |j| compiled.evaluate(j, Some(&initial)).map_err(candle_core::Error::wrap)?.total.sum_all(),
        1e-6,
        1e-4,
    )
    .unwrap_or_else(|e| panic!("{expr}: {e}"));
}

const PELVIS_Z_LAST: &str = r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "target": [1.0], "frames": {"keyframes": ["last"]}}"#;
const HEAD_BELOW: &str =
    r#"{"op": "less_than", "quantity": {"kind": "position", "of": {"joint": "head"}, "axes": "y"}, "max": 1.5}"#;

#[test]
fn comparisons_of_positions() {
    let m = glide(5);
    close(PELVIS_Z_LAST, &m, 0.64);
    close(HEAD_BELOW, &m, 0.1);
    close(
        r#"{"op": "greater_than", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "y"}, "min": 1.0, "frames": {"keyframes": ["first"]}}"#,
        &m,
        0.1,
    );
    // |z_last − 1| with the absolute metric.
    close(
        r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "target": [1.0], "metric": "absolute", "frames": {"keyframes": ["last"]}}"#,
        &m,
        0.8,
    );
    // Reductions of the head's 0.1 m excess over 5 frames.
    close(&HEAD_BELOW.replace('}', r#", "reduce": "sum"}"#).replacen(r#", "reduce": "sum"}"#, "}", 2), &m, 0.5);
}

#[test]
fn reductions_and_frame_ranges() {
    let m = glide(5);
    let displacement = |reduce: &str| {
        format!(
            r#"{{"op": "less_than", "quantity": {{"kind": "displacement", "of": {{"joint": "pelvis"}}, "since": "first", "axes": "z"}}, "max": 0.1, "reduce": "{reduce}"}}"#
        )
    };
    // Excess per frame: 0, 0, 0, 0.05, 0.1.
    close(&displacement("mean"), &m, 0.03);
    close(&displacement("sum"), &m, 0.15);
    close(&displacement("max"), &m, 0.1);
    close(&displacement("min"), &m, 0.0);
    close(
        r#"{"op": "less_than", "quantity": {"kind": "displacement", "of": {"joint": "pelvis"}, "since": "first", "axes": "z"}, "max": 0.1, "frames": {"range": {"from": {"frame": 3}, "to": "last"}}}"#,
        &m,
        0.075,
    );
}

#[test]
fn derivatives_in_si_units() {
    let m = glide(5);
    // 1 m/s along z: (0 − 0)² + (1 − 2)² per frame.
    close(
        r#"{"op": "equal", "quantity": {"kind": "velocity", "of": {"joint": "pelvis"}, "axes": "xz"}, "target": [0.0, 2.0]}"#,
        &m,
        1.0,
    );
    close(
        r#"{"op": "less_than", "quantity": {"kind": "speed", "of": {"joint": "pelvis"}, "axes": "xyz"}, "max": 0.5}"#,
        &m,
        0.5,
    );
    let mut bumped = glide(5);
    bumped[2][Joint::Head.index()][1] += 0.01;
    // Second differences of the head's y: +0.01, −0.02, +0.01 m/frame² = 4, −8, 4 m/s².
    close(
        r#"{"op": "greater_than", "quantity": {"kind": "acceleration", "of": {"joint": "head"}, "axes": "y"}, "min": -5.0, "reduce": "max"}"#,
        &bumped,
        3.0,
    );
    close(
        r#"{"op": "less_than", "quantity": {"kind": "acceleration", "of": {"joint": "pelvis"}, "axes": "xyz"}, "max": 0.0}"#,
        &m,
        0.0,
    );
}

#[test]
fn distances_to_joints_lines_and_planes() {
    let m = glide(5);
    close(
        r#"{"op": "equal", "quantity": {"kind": "distance", "a": {"joint": "left_wrist"}, "b": {"joint": "right_wrist"}, "axes": "xyz"}, "target": [0.4]}"#,
        &m,
        0.04f64.powi(2),
    );
    close(
        r#"{"op": "equal", "quantity": {"kind": "distance_to_line", "of": {"joint": "pelvis"}, "point_m": [1.0, 0.9, 0.0], "direction": [0.0, 0.0, 3.0]}, "target": [0.0]}"#,
        &m,
        1.0,
    );
    // Signed distance to the plane z = 0.1: −0.1, −0.05, 0, 0.05, 0.1.
    close(
        r#"{"op": "greater_than", "quantity": {"kind": "distance_to_plane", "of": {"joint": "pelvis"}, "point_m": [0.0, 0.0, 0.1], "normal": [0.0, 0.0, 2.0], "signed": true}, "min": 0.0}"#,
        &m,
        0.03,
    );
    close(
        r#"{"op": "equal", "quantity": {"kind": "distance_to_plane", "of": {"joint": "pelvis"}, "point_m": [0.0, 0.0, 0.1], "normal": [0.0, 0.0, 2.0]}, "target": [0.0]}"#,
        &m,
        0.005,
    );
    // A fixed point 1 m above the pelvis's start.
    close(
        r#"{"op": "equal", "quantity": {"kind": "distance", "a": {"joint": "pelvis"}, "b": {"fixed_m": [0.0, 1.9, 0.0]}, "axes": "y"}, "target": [0.0], "frames": {"keyframes": ["first"]}}"#,
        &m,
        1.0,
    );
}

#[test]
fn root_space_follows_the_body() {
    let expr = r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "left_wrist"}, "axes": "xyz", "space": "root"}, "target": [0.22, 0.87, 0.0]}"#;
    close(expr, &glide(5), 0.0);
    // Turned to face +x (a quarter turn about y) and moved: the root-frame position is the same.
    let turned: Vec<_> = glide(5).iter().map(|pose| pose.map(|[x, y, z]| [z + 3.0, y, -x - 1.0])).collect();
    close(expr, &turned, 0.0);
}

#[test]
fn points_midpoint_and_centre_of_mass() {
    let m = glide(3);
    close(
        r#"{"op": "equal", "quantity": {"kind": "position", "of": {"midpoint": ["left_wrist", "right_wrist"]}, "axes": "xy"}, "target": [0.0, 0.0]}"#,
        &m,
        0.87f64.powi(2),
    );
    let weights = centre_of_mass_weights(false);
    assert!((weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    let com_y: f64 = (0..NUM_JOINTS).map(|j| weights[j] * STANDING[j][1]).sum();
    close(
        r#"{"op": "equal", "quantity": {"kind": "position", "of": {"centre_of_mass": {}}, "axes": "y"}, "target": [0.0], "frames": {"keyframes": ["first"]}}"#,
        &m,
        com_y * com_y,
    );
    // An equally heavy ball between the hands: CoM_all = (CoM + hands' midpoint) / 2.
    let fixed = centre_of_mass_weights(true);
    let fixed_y: f64 = (0..NUM_JOINTS).map(|j| fixed[j] * STANDING[j][1]).sum();
    let all_y = (fixed_y + 0.87) / 2.0;
    close(
        r#"{"op": "equal", "quantity": {"kind": "position", "of": {"centre_of_mass": {"exclude_head": true, "load": {"between": ["left_wrist", "right_wrist"], "mass_ratio": 1.0}}}, "axes": "y"}, "target": [0.0], "frames": {"keyframes": ["first"]}}"#,
        &m,
        all_y * all_y,
    );
}

#[test]
fn logic_and_or_not() {
    let m = glide(5);
    close(&format!(r#"{{"op": "and", "args": [{PELVIS_Z_LAST}, {HEAD_BELOW}]}}"#), &m, 0.74);
    close(&format!(r#"{{"op": "or", "args": [{PELVIS_Z_LAST}, {HEAD_BELOW}]}}"#), &m, 0.1);
    close(&format!(r#"{{"op": "not", "arg": {HEAD_BELOW}, "margin": 0.3}}"#), &m, 0.2);
    close(&format!(r#"{{"op": "not", "arg": {PELVIS_Z_LAST}, "margin": 0.3}}"#), &m, 0.0);
}

#[test]
fn conditions_select_frames_of_the_current_motion() {
    let m = glide(5);
    let when = |lo: f64, hi: f64, reduce: &str| {
        format!(
            r#"{{"op": "less_than", "quantity": {{"kind": "position", "of": {{"joint": "head"}}, "axes": "y"}}, "max": 1.5, "reduce": "{reduce}", "when": {{"of": {{"kind": "position", "of": {{"joint": "pelvis"}}, "axes": "z"}}, "min": {lo}, "max": {hi}}}}}"#
        )
    };
    // Pelvis z = 0, 0.05, 0.1, 0.15, 0.2: frames 2 and 3 lie in (0.07, 0.17).
    close(&when(0.07, 0.17, "mean"), &m, 0.1);
    close(&when(0.07, 0.17, "sum"), &m, 0.2);
    close(&when(5.0, 6.0, "mean"), &m, 0.0);
    close(&when(5.0, 6.0, "min"), &m, 0.0);
}

#[test]
fn counting_peaks_and_valleys() {
    // Wrists 0.44 m apart, brought to 0.1 m on frames 1, 3, 5: three claps.
    let claps: Vec<_> = glide(7)
        .into_iter()
        .enumerate()
        .map(|(t, mut pose)| {
            if t % 2 == 1 {
                pose[Joint::LeftWrist.index()][0] = 0.05;
                pose[Joint::RightWrist.index()][0] = -0.05;
            }
            pose
        })
        .collect();
    let count = |target: u32, extremum: &str, threshold: f64| {
        format!(
            r#"{{"op": "count", "signals": [{{"kind": "distance", "a": {{"joint": "left_wrist"}}, "b": {{"joint": "right_wrist"}}, "axes": "xyz"}}], "extremum": "{extremum}", "threshold": {threshold}, "target_count": {target}}}"#
        )
    };
    close(&count(3, "valleys", 0.2), &claps, 0.0);
    close(&count(2, "valleys", 0.2), &claps, 1.0);
    // Peaks above 0.3: frames 2 and 4 (frames 0 and 6 are ends).
    close(&count(2, "peaks", 0.3), &claps, 0.0);
    close(&count(3, "peaks", 0.3), &claps, 1.0);
}

/// The standing glide with the wrists `distance[t]` m apart (side by side in x), frame by frame.
fn wrists_apart(distance: &[f64]) -> Vec<[[f64; 3]; NUM_JOINTS]> {
    glide(distance.len())
        .into_iter()
        .zip(distance)
        .map(|(mut pose, d)| {
            pose[Joint::LeftWrist.index()][0] = d / 2.0;
            pose[Joint::RightWrist.index()][0] = -d / 2.0;
            pose
        })
        .collect()
}

/// A clap that claps (issue 19): events count the hands meeting (within 6 cm), so wrists that
/// stop at 0.17 m make none, where a count of distance minima below 0.2 m counts them as claps.
#[test]
fn events_need_the_event_to_happen() {
    let claps = wrists_apart(&[0.4, 0.3, 0.15, 0.02, 0.01, 0.2, 0.35, 0.02, 0.3, 0.25, 0.01, 0.01, 0.3, 0.4]);
    let near = wrists_apart(&[0.4, 0.3, 0.17, 0.25, 0.35, 0.18, 0.3, 0.4, 0.4, 0.3, 0.25, 0.17, 0.3, 0.4]);
    let wrists = r#"{"kind": "distance", "a": {"joint": "left_wrist"}, "b": {"joint": "right_wrist"}, "axes": "xyz"}"#;
    let events = format!(r#"{{"op": "events", "signal": {wrists}, "event": {{"below": 0.06}}, "target_count": 3}}"#);
    let minima = format!(
        r#"{{"op": "count", "signals": [{wrists}], "extremum": "valleys", "threshold": 0.2, "target_count": 3}}"#
    );
    // Met: the judge's count is 3, so the error is 0.
    assert_eq!(error_of(&events, &claps), 0.0);
    // Hands that never meet: no event, (0 − 3)² = 9.
    assert_eq!(error_of(&events, &near), 9.0);
    // The count of minima is fooled by them.
    assert!(error_of(&minima, &near) < 1e-6);
    // The report counts with the metric: 3 and 0.
    let judge = |motion: &[[[f64; 3]; NUM_JOINTS]]| {
        compile(motion.len(), &events).satisfaction(&tensor(motion), None).unwrap().remove(0)
    };
    assert_eq!((judge(&claps).checks[0].value.clone(), judge(&claps).pass), (vec![0.0], vec![true]));
    assert_eq!((judge(&near).checks[0].value.clone(), judge(&near).pass), (vec![3.0], vec![false]));
    gradient_ok(&events, &wrists_apart(&[0.3, 0.12, 0.07, 0.05, 0.09, 0.13, 0.2, 0.1]));
    // Three events cannot fit in 4 frames.
    let text = format!(r#"{{"text": "", "frames": 4, "constraints": [{{"id": "c1", "expr": {events}}}]}}"#);
    let error = format!("{:?}", TaskProgram::from_json_validated(&text).unwrap_err());
    assert!(error.contains("target_count"), "{error}");
}

/// The glide with the whole body lifted `lift` m on `frames`.
fn lifted(frames: usize, lifted: std::ops::Range<usize>, lift: f64) -> Vec<[[f64; 3]; NUM_JOINTS]> {
    let mut m = glide(frames);
    for pose in &mut m[lifted] {
        for p in pose.iter_mut() {
            p[1] += lift;
        }
    }
    m
}

/// A flight phase (issue 19): both feet (ankles and toes) above 10 cm for 3 frames in a row.
/// Standing, the toes are 2 cm up: 0.08 m short on every frame. A jump lifting the body 0.3 m for
/// 4 frames meets it; for 2 frames it does not; a foot lifted onto a hurdle with the other on the
/// ground is no flight.
#[test]
fn a_flight_needs_both_feet_off_the_ground() {
    let flight = r#"{"op": "airborne", "clearance_m": 0.1, "min_frames": 3}"#;
    close(flight, &glide(10), 0.08f64.powi(2));
    close(flight, &lifted(10, 4..8, 0.3), 0.0);
    // Two frames up: every 3-frame window holds a frame on the ground.
    close(flight, &lifted(10, 4..6, 0.3), 0.08f64.powi(2) / 3.0);
    let mut one_foot = glide(10);
    for pose in &mut one_foot[3..8] {
        pose[Joint::LeftFoot.index()][1] += 0.3;
        pose[Joint::LeftAnkle.index()][1] += 0.3;
    }
    close(flight, &one_foot, 0.08f64.powi(2));
    // Only the second half of the clip may hold the flight.
    let late = r#"{"op": "airborne", "clearance_m": 0.1, "min_frames": 3, "frames": {"range": {"from": "middle", "to": "last"}}}"#;
    close(late, &lifted(10, 1..5, 0.3), 0.08f64.powi(2));
    close(late, &lifted(10, 6..9, 0.3), 0.0);
    let judge = |motion: &[[[f64; 3]; NUM_JOINTS]]| {
        compile(motion.len(), flight).satisfaction(&tensor(motion), None).unwrap().remove(0)
    };
    let standing = judge(&glide(10));
    assert!((standing.checks[0].value[0] - 0.08).abs() < 1e-9 && standing.pass == vec![false]);
    assert_eq!(judge(&lifted(10, 4..8, 0.3)).pass, vec![true]);
    gradient_ok(flight, &lifted(8, 3..5, 0.1));
    gradient_ok(late, &glide(8));
    // Over the box: every frame of the flight with the pelvis between z = 0.9 and 1.5 (frames
    // 19-29 of the glide). A jump at frames 4-7 is not there; one at 20-23 is; a box never
    // reached leaves no flight where it must be: the whole 0.1 m short.
    let over = |lo: f64, hi: f64| {
        format!(
            r#"{{"op": "airborne", "clearance_m": 0.1, "min_frames": 3, "when": {{"of": {{"kind": "position", "of": {{"joint": "pelvis"}}, "axes": "z"}}, "min": {lo}, "max": {hi}}}}}"#
        )
    };
    close(&over(0.9, 1.5), &lifted(30, 4..8, 0.3), 0.08f64.powi(2));
    close(&over(0.9, 1.5), &lifted(30, 20..24, 0.3), 0.0);
    close(&over(50.0, 60.0), &lifted(30, 20..24, 0.3), 0.01);
    let never = compile(30, &over(50.0, 60.0)).satisfaction(&tensor(&lifted(30, 20..24, 0.3)), None).unwrap();
    assert_eq!((never[0].checks[0].value.clone(), never[0].pass.clone()), (vec![0.1], vec![false]));
    gradient_ok(&over(0.1, 0.3), &lifted(8, 3..5, 0.1));
    // A flight longer than the frames it may happen in is rejected, naming min_frames.
    let text = format!(r#"{{"text": "", "frames": 10, "constraints": [{{"id": "c1", "expr": {late}}}]}}"#)
        .replace(r#""min_frames": 3"#, r#""min_frames": 7"#);
    let error = format!("{:?}", TaskProgram::from_json_validated(&text).unwrap_err());
    assert!(error.contains("min_frames"), "{error}");
}

/// A ball of 0.3 m carried between the hands (issue 19, ProgMoGen HOI-2). Standing, the wrists
/// are 0.44 m apart (0.14 m off) and their midpoint (0, 0.87, 0) lies 0.08 m inside the
/// pelvis–spine1 capsule (0.03 m below the segment's end, radius 0.11), so the ball's 0.15 m
/// radius and a 0.05 m clearance intrude 0.28 m; held 0.35 m in front of the chest it costs
/// nothing; pressed to 0.2 m of the spine it intrudes 0.2 − (0.2 − 0.11) = 0.11 m.
#[test]
fn an_object_carried_between_the_hands() {
    let carry = r#"{"op": "carry", "diameter_m": 0.3, "clearance_m": 0.05}"#;
    close(carry, &glide(3), 0.14f64.powi(2) + 0.28f64.powi(2));
    let held = |forward: f64| -> Vec<[[f64; 3]; NUM_JOINTS]> {
        glide(3)
            .into_iter()
            .map(|mut pose| {
                let z = pose[Joint::Pelvis.index()][2] + forward;
                pose[Joint::LeftWrist.index()] = [0.15, 1.1, z];
                pose[Joint::RightWrist.index()] = [-0.15, 1.1, z];
                pose
            })
            .collect()
    };
    close(carry, &held(0.35), 0.0);
    close(carry, &held(0.2), 0.11f64.powi(2));
    let judge = |motion: &[[[f64; 3]; NUM_JOINTS]]| {
        compile(motion.len(), carry).satisfaction(&tensor(motion), None).unwrap().remove(0)
    };
    assert_eq!(judge(&held(0.35)).pass, vec![true]);
    let pressed = judge(&held(0.2));
    assert!((pressed.checks[1].value[0] - 0.11).abs() < 1e-9 && pressed.pass == vec![false], "{pressed:?}");
    let standing = judge(&glide(3));
    assert!((standing.checks[0].value[0] - 0.14).abs() < 1e-9, "{standing:?}");
    gradient_ok(carry, &held(0.25));
    gradient_ok(
        r#"{"op": "carry", "hands": ["left_wrist", "right_elbow"], "diameter_m": 0.2, "reduce": "max"}"#,
        &glide(4),
    );
    // Its weight moves the centre of mass: a ball as heavy as the body held 0.5 m ahead puts the
    // centre of mass halfway to it, past the toes.
    let mut ahead: Vec<_> = std::iter::repeat_n(STANDING, 4).collect();
    for pose in &mut ahead {
        pose[Joint::LeftWrist.index()] = [0.15, 1.1, 0.5];
        pose[Joint::RightWrist.index()] = [-0.15, 1.1, 0.5];
    }
    let w = centre_of_mass_weights(false);
    let body_z: f64 = (0..NUM_JOINTS).map(|j| w[j] * ahead[0][j][2]).sum();
    let outside = (body_z + 0.5) / 2.0 - (0.12 + FOOT_HALF_WIDTH_M);
    let loaded = r#"{"op": "com_in_support", "support": "both_feet", "load": {"between": ["left_wrist", "right_wrist"], "mass_ratio": 1.0}}"#;
    close(loaded, &ahead, outside.powi(2));
    gradient_ok(loaded, &ahead);
}

#[test]
fn bones_feet_and_self_collision() {
    let m = glide(5);
    let (dx, dy) = (0.02f64, -0.28f64);
    let expected = 2.0 - 2.0 * (-dy) / dx.hypot(dy);
    close(r#"{"op": "bone_direction", "joint": "left_elbow", "direction": [0.0, -2.0, 0.0]}"#, &m, expected);
    close(
        r#"{"op": "foot_contact", "feet": ["left_foot"], "at": ["first", "last"], "max_height_m": 0.01}"#,
        &m,
        0.0001,
    );
    close(
        r#"{"op": "foot_contact", "feet": ["left_foot"], "at": ["first", "last"], "max_height_m": 0.01, "max_speed_m_per_s": 0.5}"#,
        &m,
        0.2501,
    );
    // Contact over a stretch of frames ("stand on the right foot"): standing still, the left foot
    // lifted 0.2 m on frames 3..=6 of 10. The right foot's contact during 2..=7 costs nothing;
    // the left foot's costs (y + 0.2 − 0.05)² on 4 of its 6 frames.
    let mut one_foot: Vec<_> = (0..10).map(|_| STANDING).collect();
    let left = Joint::LeftFoot as usize;
    for pose in &mut one_foot[3..=6] {
        pose[left][1] += 0.2;
    }
    let during = |foot: &str| {
        format!(
            r#"{{"op": "foot_contact", "feet": ["{foot}"], "during": {{"from": {{"frame": 2}}, "to": {{"frame": 7}}}}, "max_height_m": 0.05}}"#
        )
    };
    close(&during("right_foot"), &one_foot, 0.0);
    let y = STANDING[left][1];
    close(&during("left_foot"), &one_foot, (y + 0.2 - 0.05).powi(2) * 4.0 / 6.0);
    gradient_ok(&during("left_foot"), &one_foot);
    close(
        r#"{"op": "self_collision", "limbs": ["left_wrist"], "torso": ["pelvis"], "min_distance_m": 0.3, "axes": "xz"}"#,
        &m,
        0.08,
    );
}

#[test]
fn one_limb_in_the_torso_for_one_frame_is_not_averaged_away() {
    // Wrists 0.22 m beside the pelvis (clear of 0.2 m) on nine frames; on frame 4 the left
    // wrist comes to 0.05 m of it: the error is that frame's 0.15 m, not a tenth of it.
    let mut m = glide(10);
    m[4][Joint::LeftWrist as usize][0] = 0.05;
    let expr = r#"{"op": "self_collision", "limbs": ["left_wrist", "right_wrist"], "torso": ["pelvis", "spine1"], "min_distance_m": 0.2, "axes": "xz"}"#;
    close(expr, &m, 0.15);
    gradient_ok(expr, &m);
}

#[test]
fn centre_of_mass_in_the_support_region() {
    let m = glide(3);
    let w = centre_of_mass_weights(false);
    let com_z: f64 = (0..NUM_JOINTS).map(|j| w[j] * STANDING[j][2]).sum();
    let com_x: f64 = (0..NUM_JOINTS).map(|j| w[j] * STANDING[j][0]).sum();
    assert!(com_x.abs() < 1e-12 && (0.0..0.12).contains(&com_z));
    // Both feet: the rectangle x ∈ [−0.1, 0.1], z ∈ [0, 0.12] grown by the foot half-width.
    close(r#"{"op": "com_in_support", "support": "both_feet"}"#, &m, 0.0);
    let depth = 0.1f64.min(com_z).min(0.12 - com_z) + FOOT_HALF_WIDTH_M;
    close(r#"{"op": "com_in_support", "support": "both_feet", "margin_m": 0.2}"#, &m, (0.2 - depth).powi(2));
    // Left foot only: the CoM is 0.1 m beside the left foot's line.
    close(r#"{"op": "com_in_support", "support": "left_foot"}"#, &m, (0.1 - FOOT_HALF_WIDTH_M).powi(2));
}

#[test]
fn staying_near_the_initial_motion() {
    let m = glide(4);
    let moved: Vec<_> = m.iter().map(|pose| pose.map(|[x, y, z]| [x + 0.1, y, z])).collect();
    let expr = r#"{"op": "stay_near_initial", "quantities": [{"kind": "position", "of": {"joint": "pelvis"}, "axes": "xyz"}, {"kind": "velocity", "of": {"joint": "pelvis"}, "axes": "xyz"}]}"#;
    let initial = tensor(&m);
    assert_eq!(error_with_initial(expr, &m, Some(&initial)), 0.0);
    let got = error_with_initial(expr, &moved, Some(&initial));
    assert!((got - 0.01).abs() < 1e-9, "{got}");
    let compiled = compile(4, expr);
    assert!(compiled.needs_initial());
    assert!(matches!(compiled.evaluate(&tensor(&m), None), Err(ConstraintError::NoInitialMotion(_))));
}

#[test]
fn every_primitive_has_the_finite_difference_gradient() {
    let m = glide(8);
    let exprs = [
        PELVIS_Z_LAST.to_owned(),
        HEAD_BELOW.to_owned(),
        r#"{"op": "equal", "quantity": {"kind": "position", "of": {"joint": "left_wrist"}, "axes": "xz", "space": "root"}, "target": [0.3, 0.1], "metric": "absolute"}"#.into(),
        r#"{"op": "equal", "quantity": {"kind": "velocity", "of": {"joint": "pelvis"}, "axes": "xz"}, "target": [0.0, 2.0], "frames": {"range": {"from": "first", "to": "middle"}}}"#.into(),
        r#"{"op": "less_than", "quantity": {"kind": "speed", "of": {"joint": "head"}, "axes": "xyz"}, "max": 0.5, "reduce": "max"}"#.into(),
        r#"{"op": "equal", "quantity": {"kind": "acceleration", "of": {"joint": "head"}, "axes": "xyz"}, "target": [0.1, 0.2, 0.3], "reduce": "sum"}"#.into(),
        r#"{"op": "greater_than", "quantity": {"kind": "displacement", "of": {"joint": "pelvis"}, "since": "first", "axes": "z"}, "min": 1.0}"#.into(),
        r#"{"op": "equal", "quantity": {"kind": "distance", "a": {"joint": "left_wrist"}, "b": {"midpoint": ["right_wrist", "head"]}, "axes": "xyz"}, "target": [0.1]}"#.into(),
        r#"{"op": "equal", "quantity": {"kind": "distance_to_line", "of": {"centre_of_mass": {"load": {"between": ["left_wrist", "right_wrist"], "mass_ratio": 0.5}}}, "point_m": [1.0, 0.9, 0.0], "direction": [0.3, 0.1, 1.0]}, "target": [0.0]}"#.into(),
        r#"{"op": "equal", "quantity": {"kind": "distance_to_plane", "of": {"joint": "right_wrist"}, "point_m": [-1.0, 0.0, 0.0], "normal": [1.0, 0.0, 0.25]}, "target": [0.0]}"#.into(),
        format!(r#"{{"op": "or", "args": [{PELVIS_Z_LAST}, {HEAD_BELOW}]}}"#),
        format!(r#"{{"op": "not", "arg": {HEAD_BELOW}, "margin": 0.3}}"#),
        r#"{"op": "count", "signals": [{"kind": "speed", "of": {"joint": "left_foot"}, "axes": "xz"}, {"kind": "speed", "of": {"joint": "right_foot"}, "axes": "xz"}], "extremum": "peaks", "threshold": 0.9, "target_count": 3, "sharpness": 20.0, "smoothing_frames": 3}"#.into(),
        r#"{"op": "scene", "body": {"joints": "all", "surface": true}, "primitive": {"kind": "gap", "centre_x_m": 0.0, "width_m": 0.4, "margin_m": 0.02, "z_range_m": [-1.0, 0.3]}}"#.into(),
        r#"{"op": "scene", "body": {"joints": "all", "surface": true}, "primitive": {"kind": "overhead_barrier", "underside_height_m": 1.3, "z_range_m": [-1.0, 3.0]}, "reduce": "sum"}"#.into(),
        r#"{"op": "scene", "body": {"joints": {"only": ["left_foot", "right_foot"]}}, "primitive": {"kind": "hurdle", "height_m": 0.3, "z_range_m": [-1.0, 3.0]}}"#.into(),
        r#"{"op": "scene", "body": {"joints": "all"}, "primitive": {"kind": "ground", "height_m": 0.5}}"#.into(),
        r#"{"op": "scene", "body": {"joints": "all"}, "primitive": {"kind": "inside_box", "x_range_m": [-0.15, 0.15], "y_range_m": [0.0, 1.5], "z_range_m": [0.0, 0.2]}}"#.into(),
        r#"{"op": "scene", "body": {"joints": "all"}, "primitive": {"kind": "wall", "point_m": [0.0, 0.0, 0.3], "normal": [0.2, 0.0, -1.0], "margin_m": 0.1}}"#.into(),
        r#"{"op": "scene", "body": {"joints": {"only": ["left_foot", "right_foot"]}}, "primitive": {"kind": "balance_beam", "point_m": [0.5, 0.1, 0.4], "direction": [0.4, 0.0, 1.0]}}"#.into(),
        r#"{"op": "scene", "body": {"joints": {"only": ["left_foot", "right_foot"]}}, "primitive": {"kind": "balance_beam", "point_m": [0.5, 0.1, 0.4], "direction": [0.4, 0.0, 1.0], "horizontal": true, "extent_m": [-1.0, 0.1]}}"#.into(),
        r#"{"op": "scene", "body": {"joints": "all", "surface": true}, "primitive": {"kind": "overhead_barrier", "underside_height_m": 1.3, "z_range_m": [-1.0, 3.0], "x_range_m": [-0.1, 0.3]}}"#.into(),
        r#"{"op": "bone_direction", "joint": "left_elbow", "direction": [1.0, 0.0, 1.0]}"#.into(),
        r#"{"op": "foot_contact", "feet": ["left_foot", "right_ankle"], "at": ["first", "last"], "max_height_m": 0.01, "max_speed_m_per_s": 0.2}"#.into(),
        r#"{"op": "self_collision", "limbs": ["left_wrist", "right_elbow"], "torso": ["pelvis", "spine2"], "min_distance_m": 0.35, "axes": "xyz"}"#.into(),
        r#"{"op": "com_in_support", "support": "right_foot", "margin_m": 0.02}"#.into(),
        r#"{"op": "stay_near_initial", "quantities": [{"kind": "position", "of": {"joint": "head"}, "axes": "xyz", "space": "root"}]}"#.into(),
    ];
    for expr in &exprs {
        gradient_ok(expr, &m);
    }
}

#[test]
fn motions_of_the_wrong_shape_are_rejected() {
    let compiled = compile(5, HEAD_BELOW);
    let short = tensor(&glide(4));
    assert!(matches!(compiled.evaluate(&short, None), Err(ConstraintError::Shape { frames: 5, .. })));
}

#[test]
fn invalid_programs_do_not_compile() {
    let mut p = program(5, PELVIS_Z_LAST);
    p.frames = 0;
    let error = CompiledProgram::compile(&p, &Device::Cpu).unwrap_err();
    assert!(error.to_string().contains("frames"), "{error}");
}

fn shipped_tasks() -> Vec<(String, TaskProgram)> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../fixtures/tasks");
    let mut tasks: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .map(|p| (p.display().to_string(), TaskProgram::from_json(&std::fs::read_to_string(&p).unwrap()).unwrap()))
        .collect();
    tasks.sort_by(|a, b| a.0.cmp(&b.0));
    tasks
}

#[test]
fn every_shipped_task_compiles_and_has_a_gradient() {
    let tasks = shipped_tasks();
    assert!(tasks.len() >= 20);
    for (name, task) in tasks {
        let compiled = CompiledProgram::compile(&task, &Device::Cpu).unwrap_or_else(|e| panic!("{name}: {e}"));
        // On a jittered walk (seeded) the loss is positive and finite ...
        let motion = tensor(&glide(task.frames as usize));
        let jitter = ((random_motion(task.frames as usize, 7) - &motion).unwrap() * 0.25).unwrap();
        let x = (motion + jitter).unwrap();
        let initial = tensor(&glide(task.frames as usize));
        let total = compiled.evaluate(&x, Some(&initial)).unwrap().total.to_vec1::<f64>().unwrap()[0];
        assert!(total.is_finite() && total > 0.0, "{name}: {total}");
        // ... and on the probe walk it has a gradient (counting softened: at T = 10⁴ a count far
        // from its events is flat by design, e.g. three touches of a target out of reach).
        let check = compiled.gradient_check().unwrap();
        assert!(check.gradient_norm.is_finite() && check.gradient_norm > 0.0, "{name}: {check:?}");
    }
}

/// A random motion: the standing pose gliding with random per-joint offsets.
fn random_motion(frames: usize, seed: u64) -> Tensor {
    let base = tensor(&glide(frames));
    let noise = crate::diffusion::noise::gaussian((1, frames, NUM_JOINTS * 3), seed, &Device::Cpu)
        .unwrap()
        .reshape((1, frames, NUM_JOINTS, 3))
        .unwrap()
        .to_dtype(DType::F64)
        .unwrap();
    base.add(&(noise * 0.2).unwrap()).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// On random motions every shipped task's errors are finite and non-negative.
    #[test]
    fn shipped_task_errors_are_finite_and_non_negative(seed in 0u64..10_000) {
        for (name, task) in shipped_tasks() {
            let compiled = CompiledProgram::compile(&task, &Device::Cpu).unwrap();
            let x = random_motion(task.frames as usize, seed);
            let initial = random_motion(task.frames as usize, seed + 1);
            let e = compiled.evaluate(&x, Some(&initial)).unwrap();
            for (id, error) in &e.per_constraint {
                let v = error.to_vec1::<f64>().unwrap()[0];
                prop_assert!(v.is_finite() && v >= 0.0, "{} {}: {}", name, id, v);
            }
        }
    }

    /// A bound the motion already satisfies, or a target it already hits, costs nothing.
    #[test]
    fn satisfied_constraints_cost_nothing(seed in 0u64..10_000, joint in 0usize..22, axis in 0usize..3, kind in 0usize..4) {
        let frames = 12;
        let x = random_motion(frames, seed);
        let name = Joint::ALL[joint].name();
        let axes = ["x", "y", "z"][axis];
        let quantity = match kind {
            0 => format!(r#"{{"kind": "position", "of": {{"joint": "{name}"}}, "axes": "{axes}"}}"#),
            1 => format!(r#"{{"kind": "velocity", "of": {{"joint": "{name}"}}, "axes": "{axes}"}}"#),
            2 => format!(r#"{{"kind": "distance", "a": {{"joint": "{name}"}}, "b": {{"fixed_m": [0.0, 0.0, 0.0]}}, "axes": "xyz"}}"#),
            _ => format!(r#"{{"kind": "position", "of": {{"joint": "{name}"}}, "axes": "{axes}", "space": "root"}}"#),
        };
        let q: crate::program::Quantity = serde_json::from_str(&quantity).unwrap();
        let values = signal(&x, &q).unwrap().flatten_all().unwrap().to_vec1::<f64>().unwrap();
        let (lo, hi) = values.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        let below = format!(r#"{{"op": "less_than", "quantity": {quantity}, "max": {}}}"#, hi + 1e-3);
        let above = format!(r#"{{"op": "greater_than", "quantity": {quantity}, "min": {}}}"#, lo - 1e-3);
        let hit = format!(r#"{{"op": "equal", "quantity": {quantity}, "target": [{}], "frames": {{"keyframes": [{{"frame": 0}}]}}}}"#, values[0]);
        for expr in [below, above, hit] {
            let e = compile(frames, &expr).evaluate(&x, None).unwrap().total.to_vec1::<f64>().unwrap()[0];
            prop_assert!(e.abs() < 1e-9, "{}: {}", expr, e);
        }
    }
}

/// Natural-unit figures on the hand-built glide (head joint at 1.6 m, head-sphere top at 1.7 m,
/// pelvis z = 0.05·t m): a barrier at 1.5 m is penetrated by 0.2 m (fails at 5 cm), one at 1.68 m
/// by 0.02 m (passes); a pelvis target 0.3 m off fails, an `or` with a met branch passes, a `not`
/// flips the verdict; a bone 90° off its direction reads 90°.
#[test]
fn satisfaction_in_natural_units() {
    let m = glide(5);
    let judge = |expr: &str| {
        let s = compile(m.len(), expr).satisfaction(&tensor(&m), None).unwrap();
        assert_eq!(s.len(), 1);
        s.into_iter().next().unwrap()
    };
    let barrier = |h: f64| {
        format!(
            r#"{{"op": "scene", "body": {{"joints": "all", "surface": true}}, "primitive": {{"kind": "overhead_barrier", "underside_height_m": {h}, "z_range_m": [-1.0, 10.0]}}}}"#
        )
    };
    let deep = judge(&barrier(1.5));
    assert_eq!(deep.checks[0].unit, Unit::M);
    assert!((deep.checks[0].value[0] - 0.2).abs() < 1e-6, "{:?}", deep.checks);
    assert!(deep.checks[0].what.contains("overhead_barrier"));
    assert_eq!(deep.pass, vec![false]);
    assert_eq!(judge(&barrier(1.68)).pass, vec![true]);

    let target = |z: f64| {
        format!(
            r#"{{"op": "equal", "quantity": {{"kind": "position", "of": {{"joint": "pelvis"}}, "axes": "z"}}, "target": [{z}], "frames": {{"keyframes": ["last"]}}}}"#
        )
    };
    let off = judge(&target(0.5));
    assert!((off.checks[0].value[0] - 0.3).abs() < 1e-9);
    assert_eq!(off.pass, vec![false]);
    assert_eq!(judge(&target(0.22)).pass, vec![true]);
    let either = judge(&format!(r#"{{"op": "or", "args": [{}, {}]}}"#, target(0.5), target(0.2)));
    assert_eq!((either.checks.len(), either.pass.clone()), (2, vec![true]));
    let both = judge(&format!(r#"{{"op": "and", "args": [{}, {}]}}"#, target(0.5), target(0.2)));
    assert_eq!(both.pass, vec![false]);
    assert_eq!(judge(&format!(r#"{{"op": "not", "margin": 0.01, "arg": {}}}"#, target(0.5))).pass, vec![true]);

    let sideways = judge(r#"{"op": "bone_direction", "joint": "left_elbow", "direction": [0.0, 0.0, 1.0]}"#);
    assert_eq!(sideways.checks[0].unit, Unit::Deg);
    assert!(sideways.checks[0].value[0] > 80.0, "{:?}", sideways.checks);
}
