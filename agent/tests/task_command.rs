//! `mogen "<task>"` as a user runs it, offline: with no endpoint configured the recorded replies
//! answer, and `--dry-run` validates every recorded task and stops before generation.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("fixtures")
}

/// `mogen args...` with no LLM endpoint in the environment.
fn mogen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mogen"))
        .args(args)
        .env_remove("OPENAI_BASE_URL")
        .env_remove("OPENAI_API_KEY")
        .env_remove("OPENAI_MODEL")
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn recorded_tasks() -> Vec<String> {
    let mut tasks: Vec<String> = std::fs::read_dir(fixtures().join("llm").join("answers"))
        .unwrap()
        .map(|entry| {
            let value: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(entry.unwrap().path()).unwrap()).unwrap();
            value["task"].as_str().unwrap().to_owned()
        })
        .collect();
    tasks.sort();
    tasks
}

#[test]
fn dry_run_validates_every_recorded_task_offline() {
    let tasks = recorded_tasks();
    assert!(tasks.len() >= 16);
    for task in tasks {
        let output = mogen(&["--dry-run", &task]);
        let (stdout, stderr) = (text(&output.stdout), text(&output.stderr));
        assert!(output.status.success(), "{task}\n{stderr}");
        assert!(
            stderr.contains("no LLM endpoint configured") && stderr.contains("replaying recorded replies"),
            "{stderr}"
        );
        assert!(stdout.contains("\"constraints\"") && stdout.contains("Algorithm 1: C_R = {"), "{stdout}");
        assert!(stdout.ends_with("dry run: the program is valid; stopping before generation\n"), "{stdout}");
    }
}

#[test]
fn an_unrecorded_task_fails_loudly_with_its_key() {
    let output = mogen(&["--dry-run", "dance the tango backwards"]);
    let stderr = text(&output.stderr);
    assert!(!output.status.success());
    assert!(
        stderr.contains("no recorded reply") && stderr.contains("key ") && stderr.contains("dance the tango"),
        "{stderr}"
    );
}

#[test]
fn a_task_file_gives_the_program_and_parse_by_hand() {
    let file = fixtures().join("tasks").join("rgdno_task2_low_barrier.json");
    let output = mogen(&["--dry-run", "--program", file.to_str().unwrap()]);
    let stdout = text(&output.stdout);
    assert!(output.status.success(), "{}", text(&output.stderr));
    assert!(stdout.contains("conflicting {c3, c4}") && stdout.contains("C2 = {c1, c2}"), "{stdout}");
}

#[test]
fn without_dry_run_the_task_becomes_motions_with_rg_dno() {
    let out = tempfile::tempdir().unwrap();
    let task = "take exactly 6 steps to cover 4 m while raising both hands";
    // RG-DNO by default, its stages cut to a few steps and 4 temporal masks for the test.
    let tiny = r#"{"segments": 2, "mask_kinds": ["temporal"]}"#;
    let output = mogen(&[
        task,
        "--show-program",
        "--steps",
        "3",
        "--guidance",
        "1",
        "--rg-dno",
        tiny,
        "--retry-unmet",
        "1",
        "--out",
        out.path().to_str().unwrap(),
    ]);
    assert!(output.status.success(), "{}", text(&output.stderr));
    let written = std::fs::read_to_string(out.path().join("program.json")).unwrap();
    assert!(written.contains("\"target_count\": 6") && written.contains("relational_parse"), "{written}");
    for file in ["features.npy", "joints.npy", "report.json", "strip.png"] {
        assert!(out.path().join(file).is_file(), "{file} missing");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(report["config"]["method"], "rg-dno");
    assert_eq!(report["steps"]["target"], 6, "the step count is measured against the program's count");
    // Footfalls beside the leg alternations, one per sample.
    let (counts, footfalls) = (&report["steps"]["counts"], &report["steps"]["footfalls"]);
    assert_eq!(footfalls.as_array().map(Vec::len), counts.as_array().map(Vec::len), "{}", report["steps"]);
    // The report names the retrieved clip, its caption and the chosen mask; the database is the
    // shipped corpus's train split.
    let rg = &report["rg_dno"];
    assert!(rg["retrieved"][0]["source"]["clip"].is_string(), "{rg}");
    assert!(rg["retrieved"][0]["source"]["caption"].is_string(), "{rg}");
    // Its semantic score: the cosine similarity of its caption's sentence vector to the prompt's.
    let similarity = rg["retrieved"][0]["caption_similarity"].as_f64().unwrap_or(f64::NAN);
    assert!(similarity > 0.0 && similarity <= 1.0 + 1e-6, "{rg}");
    assert_eq!(rg["masks"][0]["candidate"]["kind"], "temporal", "{rg}");
    assert_eq!(rg["config"]["final_steps"], 3, "--steps scales the stages: {rg}");
    let (stdout, stderr) = (text(&output.stdout), text(&output.stderr));
    assert!(stdout.contains("rg-dno: constraint error") && stdout.contains("retrieved "), "{stdout}");
    assert!(stdout.contains(&format!("caption similarity {similarity:.2}")), "{stdout}");
    assert!(stderr.contains("retrieval database: ") && stderr.contains("the train split of "), "{stderr}");
    // Three steps meet nothing: the sample runs again, RG-DNO on the same database (opened once).
    assert!(stderr.contains("attempt 2 of 2: sample(s) 0 miss a constraint"), "{stderr}");
    assert_eq!(stderr.matches("retrieval database: ").count(), 1, "{stderr}");
    assert_eq!(report["attempt"].as_array().map(Vec::len), Some(1), "{report}");
    assert_eq!(rg["masks"].as_array().map(Vec::len), Some(1), "{rg}");
}

#[test]
fn a_task_without_relational_parse_falls_back_to_dno_and_says_why() {
    let out = tempfile::tempdir().unwrap();
    let mut program: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(fixtures().join("tasks").join("rgdno_task1_narrow_gap.json")).unwrap(),
    )
    .unwrap();
    program.as_object_mut().unwrap().remove("relational_parse");
    let file = out.path().join("no_parse.json");
    std::fs::write(&file, program.to_string()).unwrap();
    let folder = out.path().join("out");
    let output = mogen(&[
        "--program",
        file.to_str().unwrap(),
        "--steps",
        "2",
        "--guidance",
        "1",
        "--out",
        folder.to_str().unwrap(),
    ]);
    let (stdout, stderr) = (text(&output.stdout), text(&output.stderr));
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("RG-DNO falls back to DNO: the program has no relational parse"), "{stderr}");
    assert!(stdout.contains("dno: constraint error") && stdout.contains("RG-DNO fell back to DNO"), "{stdout}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("report.json")).unwrap()).unwrap();
    assert_eq!(report["config"]["method"], "dno");
    assert!(report["fallback"].as_str().unwrap().contains("no relational parse"));
}
