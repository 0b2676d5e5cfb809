//! Tests of the program types: the shipped task library, bad programs (each rejected with its
//! path by deserialisation + validation and, where JSON Schema can say it, by the schema), round
//! trips and a property test.

use std::path::PathBuf;

use proptest::prelude::*;
use serde_json::{json, Value};

use super::*;

fn task_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fixtures/tasks")
}

fn load_library() -> Vec<(String, String)> {
    let mut tasks: Vec<(String, String)> = std::fs::read_dir(task_dir())
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|path| path.extension().is_some_and(|ext| ext == "json"))
        .map(|path| (path.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read_to_string(&path).unwrap()))
        .collect();
    tasks.sort();
    tasks
}

#[test]
fn every_shipped_task_parses_validates_and_fits_the_schema() {
    let tasks = load_library();
    assert!(tasks.len() >= 23, "expected the ProgMoGen and RG-DNO task library, found {}", tasks.len());
    for (name, text) in &tasks {
        let program = TaskProgram::from_json_validated(text).unwrap_or_else(|errors| panic!("{name}: {errors:?}"));
        let value: Value = serde_json::from_str(text).unwrap();
        validate_json(&value).unwrap_or_else(|errors| panic!("{name}: {errors:?}"));
        if name.starts_with("rgdno_") {
            let groups = program.constraint_groups().unwrap_or_else(|| panic!("{name}: no relational parse"));
            assert!(!groups.retrieval.is_empty(), "{name}");
        }
    }
}

#[test]
fn round_trip_keeps_every_shipped_task() {
    for (name, text) in load_library() {
        let program = TaskProgram::from_json(&text).unwrap();
        let again = TaskProgram::from_json(&program.to_json_pretty().unwrap()).unwrap();
        assert_eq!(program, again, "{name}");
        validate_json(&serde_json::to_value(&program).unwrap()).unwrap_or_else(|e| panic!("{name}: {e:?}"));
    }
}

#[test]
fn relational_parse_groups_follow_algorithm_1() {
    let text = std::fs::read_to_string(task_dir().join("rgdno_task2_low_barrier.json")).unwrap();
    let mut program = TaskProgram::from_json(&text).unwrap();
    let groups = program.constraint_groups().unwrap();
    assert_eq!(groups.retrieval, ["c1", "c2"]);
    assert_eq!(groups.random_noise, ["c2", "c3", "c4"]);
    assert_eq!(groups.retrieved_noise, ["c1", "c2"]);
    program.relational_parse.as_mut().unwrap().retrieval_confidence = 0.0;
    assert_eq!(program.constraint_groups().unwrap().random_noise, ["c1", "c2", "c3", "c4"]);
}

/// A valid program with constraints `c1..=cn` and this relational parse.
fn parsed(n: usize, most_difficult: &str, connected: &[&str], conflicting: &[&str], confidence: f64) -> TaskProgram {
    let mut program = TaskProgram::from_json(&base().to_string()).unwrap();
    let template = program.constraints[1].clone();
    program.constraints = (1..=n).map(|i| NamedConstraint { id: format!("c{i}"), ..template.clone() }).collect();
    let ids = |list: &[&str]| list.iter().map(|id| id.to_string()).collect();
    program.relational_parse = Some(RelationalParse {
        most_difficult: most_difficult.into(),
        connected: ids(connected),
        conflicting: ids(conflicting),
        retrieval_confidence: confidence,
    });
    program.validate().unwrap();
    program
}

/// `(C_R, C1, C2)` of Algorithm 1.
fn algorithm_1(program: &TaskProgram) -> [Vec<String>; 3] {
    let groups = program.constraint_groups().unwrap();
    [groups.retrieval, groups.random_noise, groups.retrieved_noise]
}

#[test]
fn algorithm_1_on_the_dive_example_of_fig_9() {
    // c2 (head below 0.5 m) is c_D, c3 (dive posture) connected, c1 and c4 (upright) conflicting.
    let confident = parsed(5, "c2", &["c3"], &["c1", "c4"], 1.0);
    assert_eq!(algorithm_1(&confident), [vec!["c2", "c3"], vec!["c1", "c3", "c4", "c5"], vec!["c2", "c3", "c5"]]);
    // s = 0 (Rule 4): c_D is also fitted from random noise; C_R and C2 do not change.
    let unsure = parsed(5, "c2", &["c3"], &["c1", "c4"], 0.0);
    assert_eq!(algorithm_1(&unsure), [vec!["c2", "c3"], vec!["c1", "c2", "c3", "c4", "c5"], vec!["c2", "c3", "c5"]]);
}

#[test]
fn algorithm_1_without_relations_and_at_the_confidence_threshold() {
    // Three touches (Table 6): c_D alone is retrieved; C1 loses it only when confident.
    assert_eq!(algorithm_1(&parsed(2, "c1", &[], &[], 1.0)), [vec!["c1"], vec!["c2"], vec!["c1", "c2"]]);
    assert_eq!(algorithm_1(&parsed(2, "c1", &[], &[], 0.0)), [vec!["c1"], vec!["c1", "c2"], vec!["c1", "c2"]]);
    // s ∈ [0, 1] reads as the paper's s ∈ {0, 1} from CONFIDENT_RETRIEVAL on.
    assert_eq!(algorithm_1(&parsed(2, "c1", &[], &[], CONFIDENT_RETRIEVAL))[1], ["c2"]);
    assert_eq!(algorithm_1(&parsed(2, "c1", &[], &[], 0.49))[1], ["c1", "c2"]);
    let mut no_parse = TaskProgram::from_json(&base().to_string()).unwrap();
    no_parse.relational_parse = None;
    assert_eq!(no_parse.constraint_groups(), None);
}

#[test]
fn algorithm_1_covers_every_constraint_in_the_shipped_tasks() {
    // Eq. 4: C = C1 ∪ C2 and C_R ⊆ C2, at both confidences.
    for (name, text) in load_library().into_iter().filter(|(name, _)| name.starts_with("rgdno_")) {
        let mut program = TaskProgram::from_json(&text).unwrap();
        for confidence in [0.0, 1.0] {
            program.relational_parse.as_mut().unwrap().retrieval_confidence = confidence;
            let [retrieval, random_noise, retrieved_noise] = algorithm_1(&program);
            for constraint in &program.constraints {
                let id = &constraint.id;
                assert!(random_noise.contains(id) || retrieved_noise.contains(id), "{name}: {id} in neither set");
            }
            assert!(retrieval.iter().all(|id| retrieved_noise.contains(id)), "{name}: C_R not in C2");
        }
    }
}

#[test]
fn frame_refs_resolve_like_progmogen() {
    assert_eq!(FrameRef::Middle.resolve(80), Some(40));
    assert_eq!(FrameRef::Middle.resolve(79), Some(39)); // a velocity of an 80-frame clip: (L−1)//2
    assert_eq!(FrameRef::Last.resolve(79), Some(78)); // ... and L−2
    assert_eq!(FrameRef::Fraction(0.5).resolve(101), Some(50));
    assert_eq!(FrameRef::Frame(100).resolve(100), None);
    assert_eq!(FrameRef::First.resolve(0), None);
}

/// A small valid program to break one field at a time.
fn base() -> Value {
    json!({
        "text": "a man walks forwards",
        "frames": 100,
        "constraints": [
            {"id": "c1", "expr": {"op": "scene", "body": {"joints": "all", "surface": true},
                "primitive": {"kind": "gap", "centre_x_m": 0.0, "width_m": 0.4, "z_range_m": [0.5, 3.5]}}},
            {"id": "c2", "expr": {"op": "and", "args": [
                {"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"},
                 "target": [5.0], "frames": {"keyframes": ["last"]}},
                {"op": "equal", "quantity": {"kind": "distance", "a": {"joint": "left_wrist"},
                 "b": {"fixed_m": [0.0, 2.2, 2.5]}, "axes": "xyz"}, "target": [0.0], "reduce": "min"}]}},
            {"id": "c3", "expr": {"op": "count", "signals": [
                {"kind": "speed", "of": {"joint": "left_foot"}, "axes": "xyz"},
                {"kind": "speed", "of": {"joint": "right_foot"}, "axes": "xyz"}],
                "extremum": "peaks", "threshold": 1.0, "target_count": 6}}
        ],
        "relational_parse": {"most_difficult": "c3", "connected": ["c2"], "conflicting": [], "retrieval_confidence": 1.0}
    })
}

/// `base()` with the field at `pointer` set (added when absent).
fn with(pointer: &str, new: Value) -> Value {
    let mut value = base();
    let (parent, key) = pointer.rsplit_once('/').unwrap();
    match value.pointer_mut(parent).unwrap() {
        Value::Object(object) => {
            object.insert(key.to_owned(), new);
        }
        Value::Array(array) => array[key.parse::<usize>().unwrap()] = new,
        _ => panic!("{parent} is not a container"),
    }
    value
}

/// JSON text with every object's `op`/`kind` key first, as the serialiser and an LLM write it.
fn tag_first_text(value: &Value) -> String {
    match value {
        Value::Object(object) => {
            let mut keys: Vec<&String> = object.keys().collect();
            keys.sort_by_key(|key| !(*key == "op" || *key == "kind"));
            let fields: Vec<String> = keys
                .iter()
                .map(|key| format!("{}:{}", Value::from(key.as_str()), tag_first_text(&object[*key])))
                .collect();
            format!("{{{}}}", fields.join(","))
        }
        Value::Array(items) => format!("[{}]", items.iter().map(tag_first_text).collect::<Vec<_>>().join(",")),
        other => other.to_string(),
    }
}

/// Errors of `from_json_validated`, checked to name the same paths whether the tags come first
/// (streamed) or not (`serde_json::Value` sorts keys, so the tagged objects are buffered).
fn rust_errors(value: &Value) -> Vec<ProgramError> {
    let errors = |text: &str| TaskProgram::from_json_validated(text).err().unwrap_or_default();
    let streamed = errors(&tag_first_text(value));
    let buffered = errors(&value.to_string());
    let paths = |errors: &[ProgramError]| errors.iter().map(|e| e.path.clone()).collect::<Vec<_>>();
    assert_eq!(paths(&streamed), paths(&buffered), "{streamed:#?}\n{buffered:#?}");
    streamed
}

fn schema_errors(value: &Value) -> Vec<ProgramError> {
    validate_json(value).err().unwrap_or_default()
}

fn assert_names(errors: &[ProgramError], path: &str, needle: &str) {
    assert!(
        errors.iter().any(|e| e.path == path && e.to_string().contains(needle)),
        "no error at `{path}` containing {needle:?}: {errors:#?}"
    );
}

#[test]
fn base_program_is_valid() {
    assert_eq!(rust_errors(&base()), []);
    assert_eq!(schema_errors(&base()), []);
}

#[test]
fn unknown_joint_names_path_and_valid_joints() {
    let bad = with("/constraints/1/expr/args/0/quantity/of/joint", json!("pelvic"));
    let path = "constraints[1].expr.args[0].quantity.of.joint";
    assert_names(&rust_errors(&bad), path, "expected one of `pelvis`, `left_hip`");
    assert_names(&rust_errors(&bad), path, "`right_wrist`");
    assert_names(&schema_errors(&bad), path, "pelvic");
}

#[test]
fn frame_outside_the_clip_is_rejected() {
    let bad = with("/constraints/1/expr/args/0/frames", json!({"keyframes": ["first", {"frame": 100}]}));
    assert_names(&rust_errors(&bad), "constraints[1].expr.args[0].frames.keyframes[1].frame", "0..=99");
    // JSON Schema knows no clip length, only the absurd bound.
    let absurd = with("/constraints/1/expr/args/0/frames", json!({"keyframes": [{"frame": 20000}]}));
    assert_names(&schema_errors(&absurd), "constraints[1].expr.args[0].frames.keyframes[0].frame", "20000");
    // A velocity has one frame fewer than the clip.
    let velocity = with(
        "/constraints/1/expr/args/0/quantity",
        json!({"kind": "velocity", "of": {"joint": "pelvis"}, "axes": "z"}),
    );
    let velocity = {
        let mut v = velocity;
        *v.pointer_mut("/constraints/1/expr/args/0/frames").unwrap() = json!({"keyframes": [{"frame": 99}]});
        v
    };
    assert_names(&rust_errors(&velocity), "constraints[1].expr.args[0].frames.keyframes[0].frame", "0..=98");
}

#[test]
fn non_finite_numbers_are_rejected() {
    // JSON cannot spell NaN; programs built in Rust can.
    let mut program = TaskProgram::from_json(&base().to_string()).unwrap();
    let Expr::Scene(scene) = &mut program.constraints[0].expr else { panic!() };
    let Primitive::Gap(gap) = &mut scene.primitive else { panic!() };
    gap.width_m = f64::NAN;
    let Expr::Count(count) = &mut program.constraints[2].expr else { panic!() };
    count.threshold = f64::INFINITY;
    let errors = program.validate().unwrap_err();
    assert_names(&errors, "constraints[0].expr.primitive.width_m", "not a finite number");
    assert_names(&errors, "constraints[2].expr.threshold", "inf");
    assert!(TaskProgram::from_json(&base().to_string().replace("2.2", "1e999")).is_err());
}

#[test]
fn negative_gap_width_is_rejected() {
    let bad = with("/constraints/0/expr/primitive/width_m", json!(-0.4));
    assert_names(&rust_errors(&bad), "constraints[0].expr.primitive.width_m", "outside [0, 100] m");
    assert_names(&schema_errors(&bad), "constraints[0].expr.primitive.width_m", "minimum");
    let no_room = with("/constraints/0/expr/primitive/margin_m", json!(0.2));
    assert_names(&rust_errors(&no_room), "constraints[0].expr.primitive.width_m", "no room");
}

#[test]
fn empty_and_or_are_rejected() {
    for op in ["and", "or"] {
        let bad = with("/constraints/1/expr", json!({"op": op, "args": []}));
        assert_names(&rust_errors(&bad), "constraints[1].expr.args", "at least one element");
        assert_names(&schema_errors(&bad), "constraints[1].expr.args", "[]");
    }
}

#[test]
fn negative_count_is_rejected() {
    let bad = with("/constraints/2/expr/target_count", json!(-6));
    assert_names(&rust_errors(&bad), "constraints[2].expr.target_count", "-6");
    assert_names(&schema_errors(&bad), "constraints[2].expr.target_count", "-6");
    let too_many = with("/constraints/2/expr/target_count", json!(500));
    assert_names(&rust_errors(&too_many), "constraints[2].expr.target_count", "cannot fit");
}

#[test]
fn absurd_values_are_rejected() {
    let far = with("/constraints/1/expr/args/1/quantity/b/fixed_m/1", json!(1000.0));
    let path = "constraints[1].expr.args[1].quantity.b.fixed_m[1]";
    assert_names(&rust_errors(&far), path, "outside [-100, 100] m");
    assert_names(&schema_errors(&far), path, "1000");
    let long = with("/frames", json!(4999));
    assert_names(&rust_errors(&long), "frames", "4999 frames, over the limit of 1000 frames (program frames)");
    assert_names(&schema_errors(&long), "frames", "4999");
    // Huge numbers are printed as a person reads them, not as 309 digits.
    let huge = with("/constraints/1/expr/args/1/quantity/b/fixed_m/1", json!(1e308));
    assert_names(&rust_errors(&huge), path, "1e308 is outside [-100, 100] m");
}

/// Issue 18: the sizes a program may ask for are bounded where the schema says so, and the
/// messages name the rule.
#[test]
fn sizes_over_the_limits_are_rejected_with_the_limit_named() {
    let constraint = base()["constraints"][0].clone();
    let many: Vec<Value> = (1..=65)
        .map(|i| {
            let mut c = constraint.clone();
            c["id"] = json!(format!("c{i}"));
            c
        })
        .collect();
    let mut crowded = base();
    crowded["constraints"] = json!(many);
    crowded.as_object_mut().unwrap().remove("relational_parse");
    assert_names(&rust_errors(&crowded), "constraints", "65 constraints, over the limit of 64");
    assert_names(&schema_errors(&crowded), "constraints", "more than 64");
    let wordy = with("/constraints/0/description", json!("x".repeat(2001)));
    assert_names(&rust_errors(&wordy), "constraints[0].description", "2001 characters, over the limit of 2000");
    assert_names(&schema_errors(&wordy), "constraints[0].description", "longer than 2000");
    let escape = with("/text", json!("walk \u{1b}[31mred\u{1b}[0m"));
    assert_names(&rust_errors(&escape), "text", "character 5 is the control character '\\u{1b}'");
    let id = with("/constraints/0/id", json!("c10000"));
    assert_names(&rust_errors(&id), "constraints[0].id", "a number from 1 to 9999");
}

#[test]
fn a_byte_order_mark_is_skipped_and_a_non_object_is_named() {
    let text = format!("\u{feff}{}", base());
    assert!(TaskProgram::from_json_validated(&text).is_ok());
    for (document, found) in [("[1, 2]", "an array"), ("\"walk\"", "a string"), ("  42", "a number"), ("true", "'t'")] {
        let err = TaskProgram::from_json(document).unwrap_err();
        assert_eq!(err.path, "");
        assert!(err.to_string().contains("a program is a JSON object"), "{err}");
        assert!(err.to_string().contains(&format!("this document starts with {found}")), "{err}");
    }
}

#[test]
fn duplicate_and_dangling_ids_are_rejected() {
    let duplicate = with("/constraints/1/id", json!("c1"));
    let errors = rust_errors(&duplicate);
    assert_names(&errors, "constraints[1].id", "duplicate id `c1`");
    assert_names(&errors, "relational_parse.connected[0]", "`c2` names no constraint");
    let dangling = with("/relational_parse/conflicting", json!(["c9"]));
    assert_names(&rust_errors(&dangling), "relational_parse.conflicting[0]", "`c9` names no constraint");
    let twice = with("/relational_parse/conflicting", json!(["c2"]));
    assert_names(&rust_errors(&twice), "relational_parse.conflicting[0]", "listed twice");
    let repeated = with("/relational_parse/connected", json!(["c2", "c2"]));
    assert_names(&schema_errors(&repeated), "relational_parse.connected", "unique");
    let itself = with("/relational_parse/connected", json!(["c3"]));
    assert_names(&rust_errors(&itself), "relational_parse.connected[0]", "most difficult");
    let badly_named = with("/constraints/0/id", json!("gap"));
    assert_names(&rust_errors(&badly_named), "constraints[0].id", "c1");
    assert_names(&schema_errors(&badly_named), "constraints[0].id", "gap");
}

#[test]
fn retrieval_confidence_outside_unit_interval_is_rejected() {
    let bad = with("/relational_parse/retrieval_confidence", json!(1.5));
    assert_names(&rust_errors(&bad), "relational_parse.retrieval_confidence", "outside [0, 1]");
    assert_names(&schema_errors(&bad), "relational_parse.retrieval_confidence", "1.5");
}

#[test]
fn unknown_fields_and_ops_are_rejected() {
    let typo = with("/constraints/0/expr/primitive", json!({"kind": "gap", "centre_x_m": 0.0, "widht_m": 0.4}));
    assert_names(
        &rust_errors(&typo),
        "constraints[0].expr.primitive.widht_m",
        "unknown field `widht_m`, expected one of",
    );
    assert_names(&schema_errors(&typo), "constraints[0].expr.primitive", "widht_m");
    let op = with("/constraints/1/expr/op", json!("xor"));
    assert_names(&rust_errors(&op), "constraints[1].expr.op", "expected one of `equal`");
    assert_names(&schema_errors(&op), "constraints[1].expr.op", "\"and\"");
}

#[test]
fn inconsistent_fields_are_rejected() {
    let vector = with("/constraints/1/expr/args/0/target", json!([0.0, 5.0]));
    assert_names(&rust_errors(&vector), "constraints[1].expr.args[0].target", "1 component(s)");
    let speed =
        with("/constraints/2/expr/signals/0", json!({"kind": "velocity", "of": {"joint": "left_foot"}, "axes": "xz"}));
    assert_names(&rust_errors(&speed), "constraints[2].expr.signals[0]", "must be a scalar");
    let window = with("/constraints/0/expr/primitive/z_range_m", json!([3.5, 0.5]));
    assert_names(&rust_errors(&window), "constraints[0].expr.primitive.z_range_m", "min must be < max");
}

/// The constructs of issue 19 reject what means nothing: an object of size 0, a hysteresis of 0,
/// a flight of 0 frames, a load without mass, one hand holding with itself; each names its field.
#[test]
fn events_flights_and_carried_objects_with_nothing_in_them_are_rejected() {
    let expr = |expr: Value| with("/constraints/1/expr", expr);
    let carry = expr(json!({"op": "carry", "diameter_m": 0.0}));
    assert_names(&rust_errors(&carry), "constraints[1].expr.diameter_m", "diameter 0");
    let same = expr(json!({"op": "carry", "hands": ["left_wrist", "left_wrist"], "diameter_m": 0.3}));
    assert_names(&rust_errors(&same), "constraints[1].expr.hands[1]", "listed twice");
    let wrists =
        json!({"kind": "distance", "a": {"joint": "left_wrist"}, "b": {"joint": "right_wrist"}, "axes": "xyz"});
    let events =
        expr(json!({"op": "events", "signal": wrists, "event": {"below": 0.1}, "hysteresis": 0.0, "target_count": 2}));
    assert_names(&rust_errors(&events), "constraints[1].expr.hysteresis", "wobble");
    let flight = expr(json!({"op": "airborne", "clearance_m": 0.1, "min_frames": 0}));
    assert_names(&rust_errors(&flight), "constraints[1].expr.min_frames", "no flight");
    let load = expr(
        json!({"op": "com_in_support", "support": "both_feet", "load": {"between": ["left_wrist", "right_wrist"], "mass_ratio": 0.0}}),
    );
    assert_names(&rust_errors(&load), "constraints[1].expr.load.mass_ratio", "positive mass");
    let vector = expr(
        json!({"op": "events", "signal": {"kind": "position", "of": {"joint": "head"}, "axes": "xz"}, "event": {"above": 1.0}, "target_count": 1}),
    );
    assert_names(&rust_errors(&vector), "constraints[1].expr.signal", "must be a scalar");
}

#[test]
fn tag_after_other_fields_still_parses_and_names_inner_paths() {
    let text = r#"{"text": "", "frames": 50, "constraints": [{"id": "c1", "expr":
        {"quantity": {"axes": "y", "of": {"joint": "head"}, "kind": "position"}, "max": 0.5, "op": "less_than"}}]}"#;
    assert!(TaskProgram::from_json_validated(text).is_ok());
    let bad = text.replace("\"head\"", "\"hed\"");
    let error = TaskProgram::from_json(&bad).unwrap_err();
    assert_eq!(error.path, "constraints[0].expr.quantity.of.joint");
    assert!(error.to_string().starts_with("constraints[0].expr.quantity.of.joint: unknown variant `hed`"), "{error}");
}

#[test]
fn syntax_errors_report_line_and_column() {
    let error = TaskProgram::from_json("{\"text\": \"walk\",\n \"frames\": }").unwrap_err();
    assert!(matches!(error.problem, Problem::Syntax { line: 2, .. }), "{error}");
}

#[test]
#[ignore = "writes the schema for inspection: cargo test -p motion-core dump_schema -- --ignored"]
fn dump_schema() {
    std::fs::write(
        std::env::temp_dir().join("task_program.schema.json"),
        serde_json::to_string_pretty(json_schema()).unwrap(),
    )
    .unwrap();
}

#[test]
fn schema_describes_ops_and_joints() {
    let schema = json_schema().to_string();
    for needle in [
        "less_than",
        "overhead_barrier",
        "left_wrist",
        "retrieval_confidence",
        "eqs. 15",
        "airborne",
        "carry",
        "events",
    ] {
        assert!(schema.contains(needle), "schema lacks {needle}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Validation accepts exactly the finite, in-range gaps whose frame lies in the clip, and
    /// valid programs survive a JSON round trip.
    #[test]
    fn gap_programs_validate_iff_sensible(
        width in prop_oneof![Just(f64::NAN), -1.0..2.0f64],
        margin in 0.0..0.5f64,
        frames in 1u32..300,
        frame in 0u32..300,
    ) {
        let mut program = TaskProgram::from_json(&base().to_string()).unwrap();
        program.frames = frames;
        program.constraints.truncate(1);
        program.relational_parse = None;
        let Expr::Scene(scene) = &mut program.constraints[0].expr else { panic!() };
        scene.frames = FrameSelection::Keyframes(NonEmpty::new(FrameRef::Frame(frame), vec![]));
        let Primitive::Gap(gap) = &mut scene.primitive else { panic!() };
        gap.width_m = width;
        gap.margin_m = margin;
        let sensible = width.is_finite() && width > 2.0 * margin && frame < frames;
        prop_assert_eq!(program.validate().is_ok(), sensible);
        if sensible {
            let again = TaskProgram::from_json(&program.to_json_pretty().unwrap()).unwrap();
            prop_assert_eq!(&again, &program);
            prop_assert!(validate_json(&serde_json::to_value(&program).unwrap()).is_ok());
        }
    }
}

/// Issue 19: a contact may last a stretch of frames (`during`); it needs frames from somewhere.
#[test]
fn foot_contact_takes_single_frames_a_range_or_both() {
    let program = |contact: &str| {
        format!(
            r#"{{"text": "stand on the right foot", "frames": 40, "constraints": [{{"id": "c1", "expr": {{"op": "foot_contact", "feet": ["right_foot"], {contact} "max_height_m": 0.05}}}}]}}"#
        )
    };
    let errors = |contact: &str| TaskProgram::from_json_validated(&program(contact)).err().unwrap_or_default();
    assert_eq!(errors(r#""during": {"from": {"frame": 5}, "to": "last"},"#), []);
    assert_eq!(errors(r#""at": ["first"], "during": {"from": "middle", "to": "last"},"#), []);
    assert_names(&errors(""), "constraints[0].expr", "`at` (single frames), `during` (a range) or both");
    assert_names(
        &errors(r#""during": {"from": {"frame": 5}, "to": {"frame": 40}},"#),
        "constraints[0].expr.during.to.frame",
        "outside the clip",
    );
    assert_names(
        &errors(r#""during": {"from": "last", "to": "first"},"#),
        "constraints[0].expr.during",
        "39..=0 is empty",
    );
}
