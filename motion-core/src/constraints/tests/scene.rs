//! Scene primitives (walls, barriers, hurdles, beams, boxes) on joints and on the body surface,
//! on the frames a condition keeps and on part of the path.

use super::*;

/// `when` on a scene term (issue 19): "every footfall on the line" tests the left toe only while
/// it is on the ground (below 5 cm), so the swing may leave the line; a hurdle only while the
/// pelvis is past z = 0.12, and the maximum penetration honours the same frames.
#[test]
fn scene_terms_on_the_frames_a_condition_keeps() {
    let line = |when: &str| {
        format!(
            r#"{{"op": "scene", "body": {{"joints": {{"only": ["left_foot"]}}}}, "primitive": {{"kind": "balance_beam", "point_m": [0.0, 0.0, 0.0], "direction": [0.0, 0.0, 1.0], "half_width_m": 0.05, "horizontal": true}}{when}}}"#
        )
    };
    let planted = r#", "when": {"of": {"kind": "position", "of": {"joint": "left_foot"}, "axes": "y"}, "max": 0.05}"#;
    // Frames 0-2 swing 0.2 m up and 0.4 m out; frames 3-4 stand on the line's edge zone at 0.1 m.
    let mut m = glide(5);
    for pose in &mut m[..3] {
        pose[Joint::LeftFoot.index()] = [0.4, 0.2, pose[Joint::LeftFoot.index()][2]];
    }
    let (swing, stance) = (0.35f64.powi(2), 0.05f64.powi(2));
    close(&line(""), &m, (3.0 * swing + 2.0 * stance) / 5.0);
    close(&line(planted), &m, stance);
    for pose in &mut m[3..] {
        pose[Joint::LeftFoot.index()][0] = 0.0;
    }
    close(&line(planted), &m, 0.0);
    let judged = compile(5, &line(planted)).satisfaction(&tensor(&m), None).unwrap().remove(0);
    assert_eq!((judged.checks[0].value.clone(), judged.pass), (vec![0.0], vec![true]));
    gradient_ok(&line(planted), &glide(6));

    let hurdle = |when: &str| {
        format!(
            r#"{{"op": "scene", "body": {{"joints": {{"only": ["left_foot"]}}}}, "primitive": {{"kind": "hurdle", "height_m": 0.1, "z_range_m": [-1.0, 10.0]}}{when}}}"#
        )
    };
    let past = r#", "when": {"of": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "min": 0.12}"#;
    // The toe stands in the hurdle (0.08 m) on frames 0-2 and is lifted over it on frames 3-4,
    // where the pelvis is past z = 0.12.
    let mut over = glide(5);
    for pose in &mut over[3..] {
        pose[Joint::LeftFoot.index()][1] = 0.2;
    }
    let depth = |when: &str| {
        compile(5, &hurdle(when)).max_scene_penetration(&tensor(&over)).unwrap().unwrap().to_vec1::<f64>().unwrap()[0]
    };
    assert!((depth("") - 0.08).abs() < 1e-9);
    assert_eq!(depth(past), 0.0);
    close(&hurdle(past), &over, 0.0);
}

#[test]
fn scene_primitives_on_joints() {
    let m = glide(5);
    let scene = |joints: &str, primitive: &str, reduce: &str| {
        format!(r#"{{"op": "scene", "body": {{"joints": {joints}}}, "primitive": {primitive}, "reduce": "{reduce}"}}"#)
    };
    let wrists = r#"{"only": ["left_wrist", "right_wrist"]}"#;
    close(&scene(wrists, r#"{"kind": "gap", "centre_x_m": 0.0, "width_m": 0.4}"#, "mean"), &m, 0.02);
    close(&scene(wrists, r#"{"kind": "gap", "centre_x_m": 0.0, "width_m": 0.4, "margin_m": 0.05}"#, "mean"), &m, 0.07);
    // Walls only for 0.07 < z < 0.17: frames 2 and 3 of 5, the mean over those two.
    close(
        &scene(wrists, r#"{"kind": "gap", "centre_x_m": 0.0, "width_m": 0.4, "z_range_m": [0.07, 0.17]}"#, "mean"),
        &m,
        0.02,
    );
    close(
        &scene(wrists, r#"{"kind": "gap", "centre_x_m": 0.0, "width_m": 0.4, "z_range_m": [0.07, 0.17]}"#, "sum"),
        &m,
        0.04,
    );
    close(
        &scene(
            r#"{"only": ["head"]}"#,
            r#"{"kind": "overhead_barrier", "underside_height_m": 1.5, "z_range_m": [-1.0, 10.0]}"#,
            "mean",
        ),
        &m,
        0.1,
    );
    close(
        &scene(
            r#"{"only": ["left_foot"]}"#,
            r#"{"kind": "hurdle", "height_m": 0.1, "z_range_m": [-1.0, 10.0]}"#,
            "mean",
        ),
        &m,
        0.08,
    );
    close(&scene(r#"{"only": ["pelvis"]}"#, r#"{"kind": "ground", "height_m": 1.0}"#, "mean"), &m, 0.1);
    close(&scene(r#""all""#, r#"{"kind": "ground"}"#, "max"), &m, 0.0);
    close(&scene(wrists, r#"{"kind": "inside_box", "x_range_m": [-0.1, 0.1]}"#, "mean"), &m, 0.12);
    close(
        &scene(
            r#"{"only": ["pelvis"]}"#,
            r#"{"kind": "wall", "point_m": [0.0, 0.0, 0.1], "normal": [0.0, 0.0, 1.0]}"#,
            "mean",
        ),
        &m,
        // Behind the wall by 0.1 and 0.05 m on frames 0 and 1, clear after.
        0.075,
    );
    let beam = (0.1f64.hypot(0.02) - 0.05).powi(2);
    close(
        &scene(
            r#"{"only": ["left_foot"]}"#,
            r#"{"kind": "balance_beam", "point_m": [0.0, 0.0, 0.0], "direction": [0.0, 0.0, 1.0], "half_width_m": 0.05}"#,
            "mean",
        ),
        &m,
        beam,
    );
}

/// Scene primitives on part of the path (issue 19): a table (an overhead barrier with an x
/// extent), a hurdle with one, a beam on the floor measured in the ground plane and a beam along
/// part of the walk. The standing pose's head is at x = 0, y = 1.6; its left toe at x = 0.1,
/// y = 0.02, z = 0, 0.05, … 0.2 over the 5 frames.
#[test]
fn scene_primitives_limited_to_a_stretch() {
    let m = glide(5);
    let scene = |joint: &str, primitive: &str, reduce: &str| {
        format!(
            r#"{{"op": "scene", "body": {{"joints": {{"only": ["{joint}"]}}}}, "primitive": {primitive}, "reduce": "{reduce}"}}"#
        )
    };
    let table = |x: &str| {
        format!(
            r#"{{"kind": "overhead_barrier", "underside_height_m": 1.5, "z_range_m": [-1.0, 10.0], "x_range_m": {x}}}"#
        )
    };
    // A table beside the path does not touch the head; one over it does (0.1 m in).
    close(&scene("head", &table("[0.5, 1.5]"), "mean"), &m, 0.0);
    close(&scene("head", &table("[-0.5, 0.5]"), "mean"), &m, 0.1);
    // A foot standing inside a hurdle 0.1 m high is 0.08 m in it; beside it, clear.
    let hurdle =
        |x: &str| format!(r#"{{"kind": "hurdle", "height_m": 0.1, "z_range_m": [-1.0, 10.0], "x_range_m": {x}}}"#);
    close(&scene("left_foot", &hurdle("[0.0, 0.3]"), "mean"), &m, 0.08);
    close(&scene("left_foot", &hurdle("[0.3, 0.6]"), "mean"), &m, 0.0);
    // A line on the floor under the left toe: in 3-D the toe, 2 cm up, is off it by 2 cm, and
    // lifted 20 cm by 22 cm; measured in the ground plane it stays on the line.
    let line = |horizontal: bool| {
        format!(
            r#"{{"kind": "balance_beam", "point_m": [0.1, 0.0, 0.0], "direction": [0.0, 0.0, 1.0], "horizontal": {horizontal}}}"#
        )
    };
    let mut lifted = glide(5);
    for pose in &mut lifted {
        pose[Joint::LeftFoot.index()][1] += 0.2;
    }
    close(&scene("left_foot", &line(false), "mean"), &m, 0.02f64.powi(2));
    close(&scene("left_foot", &line(false), "mean"), &lifted, 0.22f64.powi(2));
    close(&scene("left_foot", &line(true), "mean"), &lifted, 0.0);
    // A beam 10 cm to the toe's right along 0.07 < z < 0.17 only: frames 2 and 3 are tested, each
    // (0.1 − 0.05)² off it.
    let stretch = |extent: &str| {
        format!(
            r#"{{"kind": "balance_beam", "point_m": [0.0, 0.0, 0.0], "direction": [0.0, 0.0, 1.0], "half_width_m": 0.05, "horizontal": true{extent}}}"#
        )
    };
    close(&scene("left_foot", &stretch(""), "sum"), &m, 5.0 * 0.05f64.powi(2));
    close(&scene("left_foot", &stretch(r#", "extent_m": [0.07, 0.17]"#), "sum"), &m, 2.0 * 0.05f64.powi(2));
    // A beam on the floor needs a horizontal direction.
    let upright = r#"{"text": "", "frames": 5, "constraints": [{"id": "c1", "expr": {"op": "scene", "body": {"joints": "all"}, "primitive": {"kind": "balance_beam", "point_m": [0.0, 0.0, 0.0], "direction": [0.0, 1.0, 0.0], "horizontal": true}}}]}"#;
    let error = format!("{:?}", TaskProgram::from_json_validated(upright).unwrap_err());
    assert!(error.contains("direction") && error.contains("horizontal"), "{error}");
}

/// The scene error is the depth of the worst point, whatever the number of clear points and
/// frames around it: a head 0.3 m into a barrier for 2 frames of 100 costs 0.3, more than a
/// head 0.1 m in for all 100, and a deeper violation always costs more.
#[test]
fn the_scene_loss_grows_with_the_worst_penetration_and_cannot_be_averaged_away() {
    let barrier = r#"{"op": "scene", "body": {"joints": "all", "surface": true}, "primitive": {"kind": "overhead_barrier", "underside_height_m": 1.8, "z_range_m": [-1.0, 100.0]}}"#;
    // The standing pose's head-sphere top is at 1.7 m; lift frames to push it in.
    let lifted = |frames: usize, lifted_frames: usize, lift: f64| {
        let mut m = glide(frames);
        for pose in m.iter_mut().take(lifted_frames) {
            for p in pose.iter_mut() {
                p[1] += lift;
            }
        }
        m
    };
    let brief_deep = error_of(barrier, &lifted(100, 2, 0.4));
    let long_shallow = error_of(barrier, &lifted(100, 100, 0.2));
    assert!((brief_deep - 0.3).abs() < 1e-6, "{brief_deep}");
    assert!((long_shallow - 0.1).abs() < 1e-6, "{long_shallow}");
    let mut last = 0.0;
    for lift in [0.15, 0.2, 0.3, 0.5, 0.8] {
        let e = error_of(barrier, &lifted(100, 3, lift));
        assert!(e > last, "lift {lift}: {e} after {last}");
        last = e;
    }
    assert_eq!(error_of(barrier, &glide(100)), 0.0);
}

#[test]
fn scene_primitives_on_the_body_surface() {
    let m = glide(3);
    // The top of the head sphere is 0.1 m above the head joint (1.6 m): 0.05 m into a barrier
    // at 1.65 m; the joints alone stay below it.
    let barrier = |surface: bool| {
        format!(
            r#"{{"op": "scene", "body": {{"joints": {{"only": ["head"]}}, "surface": {surface}}}, "primitive": {{"kind": "overhead_barrier", "underside_height_m": 1.65, "z_range_m": [-1.0, 1.0]}}, "reduce": "max"}}"#
        )
    };
    close(&barrier(true), &m, 0.05);
    close(&barrier(false), &m, 0.0);
    let compiled = compile(3, &barrier(true));
    let depth = compiled.max_scene_penetration(&tensor(&m)).unwrap().unwrap().to_vec1::<f64>().unwrap();
    assert!((depth[0] - 0.05).abs() < 1e-9);
}

/// Retrieval's ranking proxy: a span thinned to every 4th frame (its first and last kept, here
/// frames 0, 4, 8 and 9 of 10) misses a wrist out of the gap on frame 2 alone; a keyframe is
/// read as it is, and step 1 is the program itself.
#[test]
fn a_thinned_program_reads_every_step_th_frame_of_a_span_and_every_keyframe() {
    let mut m = glide(10);
    m[2][Joint::LeftWrist.index()][0] = 1.0;
    let gap = |frames: &str| {
        format!(
            r#"{{"op": "scene", "body": {{"joints": {{"only": ["left_wrist", "right_wrist"]}}}}, "primitive": {{"kind": "gap", "centre_x_m": 0.0, "width_m": 0.4}}, "reduce": "max"{frames}}}"#
        )
    };
    let thinned = |expr: &str, step: usize| {
        let proxy = compile(10, expr).thinned(step, &Device::Cpu).unwrap();
        proxy.evaluate(&tensor(&m), None).unwrap().total.to_vec1::<f64>().unwrap()[0]
    };
    close(&gap(""), &m, 0.8);
    assert!((thinned(&gap(""), 4) - 0.02).abs() < 1e-9);
    assert!((thinned(&gap(""), 1) - 0.8).abs() < 1e-9);
    let keyframe = r#", "frames": {"keyframes": [{"frame": 2}]}"#;
    assert!((thinned(&gap(keyframe), 4) - 0.8).abs() < 1e-9);
    let range = r#", "frames": {"range": {"from": {"frame": 1}, "to": {"frame": 3}}}"#;
    assert!((thinned(&gap(range), 4) - 0.02).abs() < 1e-9, "frames 1 and 3 of the range 1..=3");
}
