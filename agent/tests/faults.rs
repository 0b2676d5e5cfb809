//! Issue 18 as a user meets it: broken priors and flags, bad output folders, oversized and
//! malformed programs, and runs killed or racing each other. Nothing NaN is ever written, an
//! output folder is always one whole run, and every error names what is wrong and where.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const PROGRAM: &str = r#"{"text": "a person walks forward", "frames": 40, "constraints": [
  {"id": "c1", "description": "pelvis 1 m ahead at the end", "expr": {"op": "equal", "quantity": {"kind": "position", "of": {"joint": "pelvis"}, "axes": "z"}, "target": [1.0], "frames": {"keyframes": ["last"]}}}
]}"#;

/// The binary under test; `MOGEN_BIN` points the tests at another build (to show that they fail
/// on one without the protections they test).
fn bin() -> String {
    std::env::var("MOGEN_BIN").unwrap_or_else(|_| env!("CARGO_BIN_EXE_mogen").to_owned())
}

fn mogen(args: &[&str]) -> Output {
    Command::new(bin()).args(args).env("RUST_BACKTRACE", "0").output().unwrap()
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

fn shipped_prior() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../fixtures/model/prior.safetensors")
}

/// Where f32 `tensor`'s values start in the shipped prior's bytes, and how many there are.
fn f32_tensor(bytes: &[u8], tensor: &str) -> (usize, usize) {
    let header_len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + header_len]).unwrap();
    let offsets = &header[tensor]["data_offsets"];
    let (start, end) = (offsets[0].as_u64().unwrap() as usize, offsets[1].as_u64().unwrap() as usize);
    assert_eq!(header[tensor]["dtype"], "F32");
    (8 + header_len + start, (end - start) / 4)
}

/// A copy of the shipped prior with `tensor`'s values changed by `edit(index, count)`.
fn edited_prior(dir: &Path, tensor: &str, edit: impl Fn(usize, usize) -> Option<f32>) -> String {
    let mut bytes = std::fs::read(shipped_prior()).unwrap();
    let (first, count) = f32_tensor(&bytes, tensor);
    for i in 0..count {
        if let Some(value) = edit(i, count) {
            bytes[first + 4 * i..first + 4 * i + 4].copy_from_slice(&value.to_le_bytes());
        }
    }
    let path = dir.join(format!("{tensor}.safetensors"));
    std::fs::write(&path, bytes).unwrap();
    path.display().to_string()
}

/// Finding 1: a broken prior or flag never becomes a NaN file with exit 0.
#[test]
fn non_finite_results_and_flags_are_errors_not_files() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "task.json", PROGRAM);
    let out = dir.path().join("out");
    let out_arg = out.display().to_string();
    // NaN in 1 % of one layer: refused at load, naming the tensor and counting its NaN.
    let layer = "seqTransEncoder.layers.1.linear1.weight";
    let damaged = edited_prior(dir.path(), layer, |i, _| (i % 100 == 0).then_some(f32::NAN));
    let output = mogen(&["run", &program, "--steps", "2", "--prior", &damaged, "--out", &out_arg]);
    assert!(!output.status.success());
    let (_, count) = f32_tensor(&std::fs::read(shipped_prior()).unwrap(), layer);
    assert!(
        stderr(&output).contains(&format!("tensor `{layer}` has {} of {count}", count.div_ceil(100))),
        "{}",
        stderr(&output)
    );
    // A 1e38 text embedding: finite weights, a non-finite motion; the error names the stage.
    let huge = edited_prior(dir.path(), "embed_text.weight", |_, _| Some(1e38));
    for command in [
        vec!["run", &program, "--steps", "2", "--prior", &huge, "--out", &out_arg],
        vec![
            "sample",
            "a person walks forward",
            "-n",
            "1",
            "--frames",
            "40",
            "--steps",
            "5",
            "--prior",
            &huge,
            "--out",
            &out_arg,
        ],
    ] {
        let output = mogen(&command);
        assert!(!output.status.success(), "{command:?}");
        assert!(stderr(&output).contains("of sample 0 is not finite"), "{}", stderr(&output));
        assert!(!out.exists(), "{command:?} wrote files");
    }
    // Numeric flags are checked when read.
    for (flag, rule) in [
        ("--jitter-weight=inf", "inf is not a finite number"),
        ("--jitter-weight=nan", "NaN is not a finite number"),
        ("--jitter-weight=-1e30", "outside [0, 1000000]"),
        ("--flight-weight=nan", "NaN is not a finite number"),
        ("--ballistic-weight=-1", "outside [0, 1000000]"),
        ("--floor-weight=inf", "inf is not a finite number"),
        ("--guidance=1e38", "outside [0, 100]"),
        ("--lr=0", "above 0"),
        ("--samples=100000", "outside 1..=64"),
    ] {
        let output = mogen(&["run", &program, flag, "--out", &out_arg]);
        assert!(!output.status.success(), "{flag}");
        let flag_name = flag.split('=').next().unwrap();
        assert!(stderr(&output).contains(flag_name) && stderr(&output).contains(rule), "{flag}: {}", stderr(&output));
    }
    assert!(!out.exists());
}

/// Finding 3: the output location is checked before any work, and the error names it.
#[test]
fn a_bad_output_location_fails_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "task.json", PROGRAM);
    let file = write(dir.path(), "taken", "x");
    let start = Instant::now();
    let output = mogen(&["run", &program, "--out", &file]);
    assert!(!output.status.success());
    assert!(stderr(&output).contains("taken: exists and is not a folder"), "{}", stderr(&output));
    // No generation ran: the whole 500-step DNO run would take minutes.
    assert!(start.elapsed() < Duration::from_secs(20), "{:?}", start.elapsed());
    let output = mogen(&["--program", &program, "--out", &format!("{file}/sub")]);
    assert!(stderr(&output).contains("taken: cannot create"), "{}", stderr(&output));
    let foreign = dir.path().join("home");
    std::fs::create_dir(&foreign).unwrap();
    std::fs::write(foreign.join("thesis.tex"), "x").unwrap();
    let output = mogen(&["sample", "walk", "--out", &foreign.display().to_string()]);
    assert!(stderr(&output).contains("home: exists and is not an output folder of mogen"), "{}", stderr(&output));
    assert!(foreign.join("thesis.tex").is_file());
}

/// Finding 4 and 7: sizes and documents a program may not have, refused before any work with the
/// file, the JSON path and the rule.
#[test]
fn oversized_and_malformed_programs_name_the_rule() {
    let dir = tempfile::tempdir().unwrap();
    let base: serde_json::Value = serde_json::from_str(PROGRAM).unwrap();
    let variant = |name: &str, edit: &dyn Fn(&mut serde_json::Value)| {
        let mut value = base.clone();
        edit(&mut value);
        write(dir.path(), name, &value.to_string())
    };
    let long = variant("long.json", &|v| v["frames"] = 4999.into());
    let crowded = variant("crowded.json", &|v| {
        let one = v["constraints"][0].clone();
        v["constraints"] = (1..=5000)
            .map(|i| {
                let mut c = one.clone();
                c["id"] = format!("c{i}").into();
                c
            })
            .collect();
    });
    let huge_number = variant("huge.json", &|v| v["constraints"][0]["expr"]["target"][0] = 1e308.into());
    let ansi = variant("ansi.json", &|v| v["constraints"][0]["description"] = "\u{1b}[2J\u{1b}[31mred".into());
    let id = variant("id.json", &|v| v["constraints"][0]["id"] = "c10000".into());
    let array = write(dir.path(), "array.json", &format!("[{PROGRAM}]"));
    for (file, needle) in [
        (&long, "frames: the clip length is 4999 frames, over the limit of 1000 frames (program frames)"),
        (&crowded, "constraints: the program's constraint count is 5000 constraints, over the limit of 64"),
        (&huge_number, "1e308"),
        (&ansi, "constraints[0].description: character 0 is the control character '\\u{1b}'"),
        (&id, "constraints[0].id: id `c10000` must be `c` and a number from 1 to 9999"),
        (&array, "(document): a program is a JSON object"),
        (
            &"/dev/zero".to_owned(),
            "/dev/zero is at least 1048577 bytes, over the limit of 1048576 bytes (program file size)",
        ),
    ] {
        let start = Instant::now();
        for args in [vec!["run", file.as_str()], vec!["--program", file.as_str(), "--dry-run"]] {
            let output = mogen(&args);
            let text = stderr(&output);
            assert!(!output.status.success(), "{args:?}");
            assert!(text.contains(needle), "{args:?}: {text}");
            assert!(text.contains(file.rsplit('/').next().unwrap()), "the file is named: {text}");
            assert!(!text.contains('\u{1b}') && text.len() < 4000, "{text}");
        }
        assert!(start.elapsed() < Duration::from_secs(30), "{file}: {:?}", start.elapsed());
    }
    // A byte-order mark is skipped.
    let bom = write(dir.path(), "bom.json", &format!("\u{feff}{PROGRAM}"));
    let output = mogen(&["--program", &bom, "--dry-run"]);
    assert!(output.status.success(), "{}", stderr(&output));
}

/// The files of a finished run, for comparing runs byte by byte.
fn files(folder: &Path) -> Vec<(String, Vec<u8>)> {
    let mut found = Vec::new();
    let mut pending = vec![folder.to_path_buf()];
    while let Some(dir) = pending.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                pending.push(path);
            } else {
                let name = path.strip_prefix(folder).unwrap().display().to_string();
                found.push((name, std::fs::read(&path).unwrap()));
            }
        }
    }
    found.sort();
    found
}

/// The deterministic files of a run (the report and export manifest hold timings).
fn motion_files(folder: &Path) -> Vec<(String, Vec<u8>)> {
    files(folder).into_iter().filter(|(name, _)| name.ends_with(".npy") || name == "program.json").collect()
}

/// Replaces `out`'s files with those of the finished run in `from`, and removes the staging
/// folders of killed runs beside `out`: the state a finished run of `from`'s settings leaves.
fn restore(from: &Path, out: &Path) {
    if out.exists() {
        std::fs::remove_dir_all(out).unwrap();
    }
    for (name, bytes) in files(from) {
        let path = out.join(name);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, bytes).unwrap();
    }
    let parent = out.parent().unwrap();
    for entry in std::fs::read_dir(parent).unwrap().flatten() {
        if entry.file_name().to_string_lossy().starts_with(".out.staging-") {
            std::fs::remove_dir_all(entry.path()).unwrap();
        }
    }
}

/// `mogen` with `args`, started without waiting for it, its output discarded.
fn spawn_quiet(args: &[&str]) -> Child {
    Command::new(bin()).args(args).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap()
}

/// Waits until `child`, spawned at `spawned`, has begun writing outputs ([`writing_started`])
/// or has ended.
fn wait_until_writing(parent: &Path, out: &Path, spawned: std::time::SystemTime, child: &mut Child) {
    while !writing_started(parent, out, spawned) && child.try_wait().unwrap().is_none() {
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Whether a run spawned at `spawned` has begun writing outputs: a file in a staging folder
/// beside `out`, or a file of `out` itself changed since.
fn writing_started(parent: &Path, out: &Path, spawned: std::time::SystemTime) -> bool {
    let staged = std::fs::read_dir(parent).unwrap().flatten().any(|e| {
        e.file_name().to_string_lossy().starts_with(".out.staging-")
            && std::fs::read_dir(e.path()).is_ok_and(|mut d| d.next().is_some())
    });
    let changed = std::fs::read_dir(out)
        .into_iter()
        .flatten()
        .flatten()
        .any(|e| e.metadata().and_then(|m| m.modified()).is_ok_and(|t| t > spawned));
    staged || changed
}

fn run_args<'a>(program: &'a str, seed: &'a str, out: &'a str) -> Vec<&'a str> {
    vec!["run", program, "--steps", "3", "-n", "4", "--seed", seed, "--out", out]
}

/// Finding 2: killing a run at 20 random moments (the write phase among them) never leaves a
/// partial or mixed output folder; two runs into one folder leave one run's files.
#[test]
fn killed_and_racing_runs_never_leave_a_partial_or_mixed_folder() {
    let dir = tempfile::tempdir().unwrap();
    let program = write(dir.path(), "task.json", PROGRAM);
    let reference = |seed: &str| {
        let out = dir.path().join(format!("reference-{seed}"));
        let start = Instant::now();
        let output = mogen(&run_args(&program, seed, &out.display().to_string()));
        assert!(output.status.success(), "{}", stderr(&output));
        (motion_files(&out), start.elapsed())
    };
    let (old, _) = reference("1");
    let (new, duration) = reference("2");
    assert_ne!(old, new);
    let out = dir.path().join("out");
    let out_arg = out.display().to_string();
    assert!(mogen(&run_args(&program, "1", &out_arg)).status.success());

    // Ten kills at moments spread over the run, ten at moments inside its write phase (a short
    // random delay after the first output file appears), with a fixed seed (xorshift).
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut random = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % 10_000) as f64 / 10_000.0
    };
    let mut killed_while_writing = 0;
    for round in 0..20 {
        let before = files(&out);
        let spawned = std::time::SystemTime::now();
        let mut child = spawn_quiet(&run_args(&program, "2", &out_arg));
        let moment = if round < 10 {
            let moment = duration.mul_f64(0.1 + 0.9 * random());
            std::thread::sleep(moment);
            moment
        } else {
            let begin = Instant::now();
            wait_until_writing(dir.path(), &out, spawned, &mut child);
            std::thread::sleep(Duration::from_secs_f64(0.2 * random()));
            begin.elapsed()
        };
        let _ = child.kill(); // SIGKILL (an error only when the run had already ended)
        child.wait().unwrap();
        let now = motion_files(&out);
        assert!(now == old || now == new, "round {round} ({moment:?}): a mixed or partial folder");
        if now == old {
            assert!(files(&out) == before, "round {round}: the old run's files changed");
        } else {
            assert!(out.join("viewer.html").is_file() && out.join("export.json").is_file());
        }
        let staged = std::fs::read_dir(dir.path())
            .unwrap()
            .flatten()
            .filter(|e| e.file_name().to_string_lossy().starts_with(".out.staging-"))
            .filter(|e| std::fs::read_dir(e.path()).is_ok_and(|mut d| d.next().is_some()))
            .count();
        killed_while_writing += usize::from(staged > 0);
        // Back to the old run for the next round: its files copied back, the killed run's
        // staging folder removed (a whole run each round would double the test's time).
        restore(&dir.path().join("reference-1"), &out);
    }
    eprintln!("{killed_while_writing} of 20 kills fell into the write phase");
    assert!(killed_while_writing > 0, "no kill fell into the write phase");
    // A last kill inside the write phase, then a whole run, which removes its staging folder.
    let spawned = std::time::SystemTime::now();
    let mut child = spawn_quiet(&run_args(&program, "2", &out_arg));
    wait_until_writing(dir.path(), &out, spawned, &mut child);
    let _ = child.kill();
    child.wait().unwrap();
    assert!(mogen(&run_args(&program, "1", &out_arg)).status.success());
    assert_eq!(motion_files(&out), old);
    let left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|name| name.starts_with('.'))
        .collect();
    assert!(left.is_empty(), "staging folders of killed runs are removed by the next run: {left:?}");

    // Two runs racing into one folder: all files from one of them.
    let racers: Vec<_> = ["1", "2"].iter().map(|seed| spawn_quiet(&run_args(&program, seed, &out_arg))).collect();
    for mut racer in racers {
        assert!(racer.wait().unwrap().success());
    }
    let now = motion_files(&out);
    assert!(now == old || now == new, "two runs spliced their files");
}
