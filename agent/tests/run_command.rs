//! `mogen run` as a user calls it: outputs on success, clear errors on bad programs.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;
use std::process::{Command, Output};

const PROGRAM: &str = r#"{"text": "a person walks", "frames": 30, "constraints": [
  {"id": "c1", "expr": {"op": "less_than", "quantity": {"kind": "position", "of": {"joint": "head"}, "axes": "y"}, "max": 1.2}}
]}"#;

fn mogen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mogen")).args(args).output().unwrap()
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

#[test]
fn run_writes_motion_report_and_picture() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "task.json", PROGRAM);
    let out = dir.path().join("out");
    let output = mogen(&["run", &program, "--method", "dno", "--steps", "2", "--out", &out.display().to_string()]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    for file in [
        "features.npy",
        "joints.npy",
        "report.json",
        "strip.png",
        "program.json",
        "sample_0/motion.bvh",
        "sample_0/motion.glb",
        "viewer.html",
        "export.json",
    ] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["config"]["method"], "dno");
    assert_eq!(report["config"]["dno"]["steps"], 2);
    assert!(report["constraint_error"].as_f64().is_some_and(f64::is_finite));
    assert!(String::from_utf8_lossy(&output.stdout).contains("constraint error"));
    // The report names the prior that made the motion: the shipped one, by its bytes.
    let shipped = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../fixtures/model/prior.safetensors")).unwrap();
    let digest = motion_core::files::sha256_hex(&shipped);
    assert_eq!(report["prior"]["file"], "prior.safetensors");
    assert_eq!(report["prior"]["sha256"], digest.as_str());
}

#[test]
fn bad_programs_and_missing_files_get_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let unknown = write(dir.path(), "bad.json", &PROGRAM.replace("\"head\"", "\"hed\""));
    let output = mogen(&["run", &unknown, "--steps", "1"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains("constraints[0].expr.quantity.of.joint") && stderr.contains("hed"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");

    let outside = write(
        dir.path(),
        "frames.json",
        &PROGRAM.replace(r#""max": 1.2"#, r#""max": 1.2, "frames": {"keyframes": [{"frame": 30}]}"#),
    );
    let stderr = String::from_utf8_lossy(&mogen(&["run", &outside, "--steps", "1"]).stderr).into_owned();
    assert!(
        stderr.contains("constraints[0].expr.frames.keyframes[0].frame") && stderr.contains("outside the clip"),
        "{stderr}"
    );

    let missing = dir.path().join("nope.json").display().to_string();
    let output = mogen(&["run", &missing]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success() && stderr.contains("nope.json"), "{stderr}");
}

/// With stderr redirected (a log, CI) the run still reports progress, as plain lines; a user
/// error is one line of causes with no backtrace, even with `RUST_BACKTRACE` set.
#[test]
fn progress_goes_to_a_log_and_errors_carry_no_backtrace() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "task.json", PROGRAM);
    let out = dir.path().join("out").display().to_string();
    let output = mogen(&["run", &program, "--steps", "12", "--out", &out]);
    assert!(output.status.success());
    let log = String::from_utf8_lossy(&output.stderr);
    assert!(log.contains("dno round 0: step 1/12 loss") && log.contains("dno round 0: step 12/12 loss"), "{log}");

    let output = Command::new(env!("CARGO_BIN_EXE_mogen"))
        .args(["run", &dir.path().join("missing.json").display().to_string()])
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1));
    assert!(stderr.starts_with("error: cannot read the task file: ") && stderr.contains("missing.json"), "{stderr}");
    assert!(!stderr.to_lowercase().contains("backtrace") && stderr.lines().count() == 1, "{stderr}");
}

/// `mogen sample` says which training caption a prompt is conditioned on: a paraphrase far
/// from every caption takes the nearest one (a crawl), a caption keeps its own vector, and a
/// prompt whose verbs no caption uses says how it was restated (WordNet).
#[test]
fn sample_names_the_training_caption_a_prompt_is_conditioned_on() {
    let dir = tempfile::tempdir().unwrap();
    let sample = |prompt: &str, out: &str| {
        let out = dir.path().join(out).display().to_string();
        let output = mogen(&["sample", prompt, "-n", "1", "--frames", "40", "--steps", "2", "-o", &out]);
        let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
        assert!(output.status.success(), "{stderr}");
        stderr
    };
    let far = sample("a toddler scrambles across the floor on its knees", "far");
    let line = far.lines().find(|l| l.contains("conditioned on the nearest")).unwrap_or_else(|| panic!("{far}"));
    assert!(line.contains("crawls"), "{line}");
    let near = sample("a person walks forward", "near");
    assert!(
        near.contains("the nearest training caption: \"a person walks forward\" (cosine similarity 1.00)"),
        "{near}"
    );
    assert!(!near.contains("restated"), "{near}");
    let restated = sample("someone ambles and veers off to their left", "restated");
    assert!(
        restated.contains("\"someone walks and turns off to their left\" (ambles → walks, veers → turns)"),
        "{restated}"
    );
}

/// A prior file whose header disagrees with its tensors (here `latent_dim` 64 over 128-wide
/// weights) is a user error: one line naming the file and the tensor, no backtrace, even with
/// `RUST_BACKTRACE` set (candle captures one into the error's message otherwise), and nothing
/// written.
#[test]
fn a_damaged_prior_is_one_line_without_a_backtrace() {
    let shipped = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../fixtures/model/prior.safetensors")).unwrap();
    let n = usize::try_from(u64::from_le_bytes(shipped[..8].try_into().unwrap())).unwrap();
    let mut header: serde_json::Value = serde_json::from_slice(&shipped[8..8 + n]).unwrap();
    let meta = &mut header["__metadata__"];
    let mut config: serde_json::Value = serde_json::from_str(meta["mdm_config"].as_str().unwrap()).unwrap();
    config["latent_dim"] = 64.into();
    meta["mdm_config"] = config.to_string().into();
    let mut text = header.to_string().into_bytes();
    text.resize(text.len().div_ceil(8) * 8, b' ');
    let mut bytes = (text.len() as u64).to_le_bytes().to_vec();
    bytes.extend_from_slice(&text);
    bytes.extend_from_slice(&shipped[8 + n..]);
    let dir = tempfile::tempdir().unwrap();
    let prior = dir.path().join("damaged.safetensors");
    std::fs::write(&prior, bytes).unwrap();
    let out = dir.path().join("out");

    let output = Command::new(env!("CARGO_BIN_EXE_mogen"))
        .args(["sample", "a person walks forward", "--prior", &prior.display().to_string()])
        .args(["-o", &out.display().to_string()])
        .env("RUST_BACKTRACE", "1")
        .env_remove("RUST_LIB_BACKTRACE")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("damaged.safetensors") && stderr.contains("shape mismatch"), "{stderr}");
    assert!(stderr.lines().count() == 1 && !stderr.contains("error.rs"), "{stderr}");
    assert!(!out.exists(), "an output folder was written for a failed run");
}

/// `mogen run` of `program` with two DNO steps, `samples` motions and `--retry-unmet retries`
/// into `out`: its report and stderr.
fn run_retrying(program: &str, out: &Path, samples: &str, retries: &str) -> (serde_json::Value, String) {
    let output = mogen(&[
        "run",
        program,
        "--method",
        "dno",
        "--steps",
        "2",
        "-n",
        samples,
        "--no-refine",
        "--retry-unmet",
        retries,
        "--out",
        &out.display().to_string(),
    ]);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    (report, String::from_utf8_lossy(&output.stderr).into_owned())
}

/// Per sample: the constraints met and the constraint error of a report.
fn standing(report: &serde_json::Value) -> Vec<(usize, f64)> {
    let errors = report["constraint_error_per_sample"].as_array().unwrap();
    let constraints = report["constraints"].as_array().unwrap();
    (0..errors.len())
        .map(|b| {
            let met = constraints.iter().filter(|c| c["pass"][b].as_bool().unwrap()).count();
            (met, errors[b].as_f64().unwrap())
        })
        .collect()
}

#[test]
fn retries_generate_the_unmet_samples_again_and_keep_the_better_attempt() {
    let dir = tempfile::tempdir().unwrap();
    // The pelvis 2 m to the side on the last frame: no sample meets it after two DNO steps.
    let program = write(
        dir.path(),
        "task.json",
        r#"{"text": "a person walks", "frames": 30, "constraints": [{"id": "c1", "expr": {"op": "equal",
            "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "x"}, "target": [2.0],
            "frames": {"keyframes": ["last"]}}}]}"#,
    );
    let (once, once_log) = run_retrying(&program, &dir.path().join("once"), "2", "0");
    let (retried, log) = run_retrying(&program, &dir.path().join("retried"), "2", "2");
    assert!(once.get("attempt").is_none(), "no attempts are reported without retries: {once}");
    assert!(!once_log.contains("attempt 2"), "{once_log}");
    assert!(log.contains("attempt 2 of 3: sample(s) 0, 1 miss a constraint"), "{log}");
    let kept = retried["attempt"].as_array().unwrap();
    assert_eq!(kept.len(), 2, "{retried}");
    for ((met, error), (met_once, error_once)) in standing(&retried).into_iter().zip(standing(&once)) {
        assert!(met > met_once || (met == met_once && error <= error_once), "{error} against {error_once}");
    }
    // The first attempt is the run without retries: a sample that kept it has its error.
    for (b, k) in kept.iter().enumerate() {
        if k.as_u64() == Some(0) {
            assert_eq!(retried["constraint_error_per_sample"][b], once["constraint_error_per_sample"][b]);
        }
    }
    assert!(kept.iter().any(|k| k.as_u64() != Some(0)), "fresh noise ends nearer the target for some sample: {kept:?}");
}

#[test]
fn retries_leave_samples_that_meet_every_constraint_alone() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "task.json", &PROGRAM.replace("\"max\": 1.2", "\"max\": 5.0"));
    let (report, log) = run_retrying(&program, &dir.path().join("out"), "1", "3");
    assert!(!log.contains("attempt 2"), "{log}");
    assert_eq!(report["attempt"], serde_json::json!([0]), "{report}");
}

/// A bad held-out paraphrase file stops `mogen report prior` before any family is sampled, with
/// the file and the line, and writes no report.
#[test]
fn report_refuses_a_bad_paraphrase_file_before_sampling() {
    let dir = tempfile::tempdir().unwrap();
    let bad = write(dir.path(), "bad.tsv", "walk\tsomeone strolls\nskate\tsomeone glides\n");
    let out = dir.path().join("report").display().to_string();
    let output = mogen(&["report", "prior", "--paraphrases", &bad, "-o", &out]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("bad.tsv: line 2: unknown family \"skate\""), "{stderr}");
    assert!(!dir.path().join("report").join("report.md").exists());
}
