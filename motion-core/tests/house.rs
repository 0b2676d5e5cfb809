//! The house rules that the compiler does not see: no command module of the `mogen` command line
//! imports another (what commands share lives in `agent/src/cli/`), no function of the library
//! or the command line grows past 150 lines, and no source comment narrates the project's
//! history (which measurement was made when: that lives in `fixtures/results/` and the model
//! card).

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod source;

use std::path::{Path, PathBuf};

use source::{non_test_code, rust_files};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn files_under(dirs: &[&str]) -> Vec<PathBuf> {
    let mut files = Vec::new();
    for dir in dirs {
        rust_files(&root().join(dir), &mut files);
    }
    files.sort();
    files
}

fn relative(file: &Path) -> String {
    file.strip_prefix(root()).unwrap().to_string_lossy().replace('\\', "/")
}

#[test]
fn no_command_module_imports_another() {
    let mut arrows = Vec::new();
    for file in files_under(&["agent/src/commands"]) {
        let code = non_test_code(&std::fs::read_to_string(&file).unwrap());
        for (n, line) in code.lines().enumerate() {
            if line.contains("super::") || line.contains("crate::commands::") {
                arrows.push(format!("{}:{}: {}", relative(&file), n + 1, line.trim()));
            }
        }
    }
    assert!(arrows.is_empty(), "command modules importing another command module:\n{}", arrows.join("\n"));
}

/// Longest function, lines from its signature to its closing brace.
const MAX_FUNCTION_LINES: usize = 150;

/// The functions of `text` longer than [`MAX_FUNCTION_LINES`]: `(line, name, lines)`. A function
/// starts at a line whose code begins with `fn` (after `pub`, `pub(..)`, `async`, `const`) and
/// ends at the first later line that is its indentation and `}`.
fn long_functions(text: &str) -> Vec<(usize, String, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut long = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let code = line.trim_start();
        let indent = &line[..line.len() - code.len()];
        let mut rest = code;
        for prefix in ["pub(crate) ", "pub(super) ", "pub ", "async ", "const ", "unsafe "] {
            rest = rest.strip_prefix(prefix).unwrap_or(rest);
        }
        let Some(signature) = rest.strip_prefix("fn ") else { continue };
        if code.ends_with(';') {
            continue;
        }
        let name: String = signature.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        let closing = format!("{indent}}}");
        if let Some(end) = lines[i + 1..].iter().position(|l| l.trim_end() == closing) {
            let length = end + 2;
            if length > MAX_FUNCTION_LINES {
                long.push((i + 1, name, length));
            }
        }
    }
    long
}

#[test]
fn no_function_is_over_150_lines() {
    let mut long = Vec::new();
    for file in files_under(&["motion-core/src", "agent/src"]) {
        let text = std::fs::read_to_string(&file).unwrap();
        for (line, name, length) in long_functions(&text) {
            long.push(format!("{}:{line}: {name} ({length} lines)", relative(&file)));
        }
    }
    assert!(long.is_empty(), "functions over {MAX_FUNCTION_LINES} lines:\n{}", long.join("\n"));
}

#[test]
fn the_function_length_counts_signature_to_closing_brace() {
    let body = "    let a = 1;\n".repeat(MAX_FUNCTION_LINES - 1);
    let text = format!("impl A {{\n    pub fn long(&self) {{\n{body}    }}\n\n    fn short() {{}}\n}}\n");
    assert_eq!(long_functions(&text), vec![(2, "long".to_owned(), MAX_FUNCTION_LINES + 1)]);
    let fits = format!("fn fits() {{\n{}}}\n", "    x();\n".repeat(MAX_FUNCTION_LINES - 2));
    assert!(long_functions(&fits).is_empty());
}

#[test]
fn no_comment_names_a_work_session() {
    let mut found = Vec::new();
    for file in files_under(&["motion-core/src", "motion-core/tests", "agent/src", "agent/tests", "tests", "benches"]) {
        let text = std::fs::read_to_string(&file).unwrap();
        for (n, line) in text.lines().enumerate() {
            let Some(at) = line.find("//") else { continue };
            let comment = line[at..].to_lowercase();
            // A link to the LLM client's module of that name is a name, not history.
            if comment.contains("session") && !comment.contains("[`session`]") {
                found.push(format!("{}:{}: {}", relative(&file), n + 1, line.trim()));
            }
        }
    }
    assert!(
        found.is_empty(),
        "comments that name a session (history belongs in fixtures/results/):\n{}",
        found.join("\n")
    );
}
