//! How an installed `mogen` finds its defaults: from an empty folder, with no variable pointing
//! into the source tree, the main job's defaults (prior, recorded replies) are unpacked from the
//! binary into the data directory and used.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::path::Path;
use std::process::{Command, Output};

const TASK: &str = "walk forwards through a 0.4 m wide gap and stop 5 m ahead";

/// `mogen args...` run in `cwd` as a user of an installed binary: no fixtures variable, no LLM
/// endpoint, `home` as the home folder.
fn installed_mogen(cwd: &Path, home: &Path, data_dir: Option<&Path>, args: &[&str]) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_mogen"));
    command
        .args(args)
        .current_dir(cwd)
        .env_remove("MOGEN_FIXTURES")
        .env_remove("MOGEN_DATA_DIR")
        .env_remove("XDG_DATA_HOME")
        .env_remove("OPENAI_BASE_URL")
        .env_remove("OPENAI_API_KEY")
        .env("HOME", home);
    if let Some(dir) = data_dir {
        command.env("MOGEN_DATA_DIR", dir);
    }
    command.output().unwrap()
}

fn unpacked(root: &Path) -> Vec<String> {
    std::fs::read_dir(root)
        .map_or(Vec::new(), |d| d.map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect())
}

#[test]
fn an_installed_binary_runs_from_an_empty_folder_on_its_embedded_defaults() {
    let temp = tempfile::tempdir().unwrap();
    let (cwd, home) = (temp.path().join("empty"), temp.path().join("home"));
    std::fs::create_dir_all(&cwd).unwrap();
    std::fs::create_dir_all(&home).unwrap();

    // The recorded replies answer from $HOME/.local/share/mogen.
    let output = installed_mogen(&cwd, &home, None, &[TASK, "--dry-run"]);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert!(stdout.contains("dry run: the program is valid"), "{stdout}");
    let share = home.join(".local/share/mogen");
    let folders = unpacked(&share);
    assert_eq!(folders.len(), 1, "{folders:?}");
    assert!(folders[0].starts_with("fixtures-"), "{folders:?}");
    assert!(share.join(&folders[0]).join("model/prior.safetensors").is_file());

    // The prior comes from MOGEN_DATA_DIR when it is set; outputs go under the current folder.
    let data = temp.path().join("data");
    let output = installed_mogen(
        &cwd,
        &home,
        Some(&data),
        &["sample", "a person walks forward", "-n", "1", "--frames", "40", "--steps", "5"],
    );
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    assert_eq!(unpacked(&data).len(), 1);
    assert!(cwd.join("out/sample/sample_0/motion.bvh").is_file());
    assert!(cwd.join("out/sample/viewer.html").is_file());
}

#[test]
fn no_writable_data_directory_is_a_clear_error() {
    let temp = tempfile::tempdir().unwrap();
    let blocked = temp.path().join("a-file");
    std::fs::write(&blocked, "").unwrap();
    let output = installed_mogen(temp.path(), temp.path(), Some(&blocked), &[TASK, "--dry-run"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    assert!(stderr.contains("MOGEN_DATA_DIR") && stderr.contains("a-file"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}
