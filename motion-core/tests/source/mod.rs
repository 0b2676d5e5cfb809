//! Reading the workspace's source files as text, for the structure tests.

use std::path::{Path, PathBuf};

/// Every `.rs` file under `dir`, at any depth.
pub fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The library code of a source file, comments and inline test modules blanked out so that
/// offsets keep their lines.
pub fn library_code(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let mut kept = Vec::with_capacity(lines.len());
    // Inside an inline `#[cfg(test)] mod .. {`: its brace depth so far.
    let mut in_test: Option<isize> = None;
    for (n, line) in lines.iter().enumerate() {
        let trimmed = line.trim();
        let next = lines.get(n + 1).map_or("", |l| l.trim());
        if in_test.is_none() && trimmed == "#[cfg(test)]" && next.contains("mod ") && next.ends_with('{') {
            in_test = Some(0);
        } else if let Some(depth) = in_test {
            let depth = depth + trimmed.matches('{').count() as isize - trimmed.matches('}').count() as isize;
            in_test = (depth > 0).then_some(depth);
        } else if !trimmed.starts_with("//") {
            kept.push(*line);
            continue;
        }
        kept.push("");
    }
    kept.join("\n")
}

/// The code of a source file that the library builds: `library_code`, and also each other
/// `#[cfg(test)]` item (a `use ..;` line, a `fn .. { }`) and each `//` comment at a line's end
/// blanked, so that offsets keep their lines.
pub fn non_test_code(text: &str) -> String {
    let code = library_code(text);
    let mut kept = Vec::new();
    // Inside a `#[cfg(test)]` item: its brace depth so far, `None` before its first `{`.
    let mut in_test: Option<Option<isize>> = None;
    for line in code.lines() {
        let trimmed = line.trim();
        match in_test {
            None if trimmed == "#[cfg(test)]" => {
                in_test = Some(None);
                kept.push(String::new());
            }
            None => {
                // A `//` outside a string literal: an even number of quotes before it.
                let cut = line
                    .match_indices("//")
                    .find(|(at, _)| line[..*at].matches('"').count() % 2 == 0)
                    .map_or(line.len(), |(at, _)| at);
                kept.push(line[..cut].to_owned());
            }
            Some(depth) => {
                let opened = depth.unwrap_or(0) + trimmed.matches('{').count() as isize;
                let depth = opened - trimmed.matches('}').count() as isize;
                let ended = if depth > 0 || opened > 0 { depth <= 0 } else { trimmed.ends_with(';') };
                in_test = (!ended).then_some((opened > 0).then_some(depth));
                kept.push(String::new());
            }
        }
    }
    kept.join("\n")
}
