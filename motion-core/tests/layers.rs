//! The import graph of `motion-core/src` against the layer order of the README's layout table:
//! a module may use (`use crate::..` or a `crate::..` path) only modules of the layers below its
//! own, so no arrow runs back up and there is no cycle. Test code (`tests.rs`, `tests/`,
//! `test_*.rs`, inline `#[cfg(test)] mod .. { }`) may reach anywhere: its fixtures come from the
//! importers. And no source file of the workspace grows past 700 lines.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The layers, top to bottom (the README's layout table in the same order).
const LAYERS: &[&[&str]] = &[
    &["pipeline"],
    &["evaluation", "quality"],
    &["generation", "training", "evaluator"],
    &["cleanup"],
    &["dno"],
    &["prior"],
    &["model", "text"],
    &["render"],
    &["export"],
    &["database"],
    &["corpus"],
    &["constraints"],
    &["metrics"],
    &["program"],
    &["import"],
    &["representation"],
    &["motion"],
    &["skeleton"],
    &["npy", "tensor_file"],
    &["files"],
    &["diffusion", "nn", "optim", "limits", "numeric", "testing"],
];

/// The layer of `module`, counted from 1 at the top as in the README.
fn layer_of(module: &str) -> Option<usize> {
    LAYERS.iter().position(|layer| layer.contains(&module)).map(|i| i + 1)
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The crate modules named by the `crate::` paths in `code`, a `use` group's members included,
/// each with the byte offset of its path.
fn crate_modules(code: &str) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        let rest = &code[at + "crate::".len()..];
        let mut names = Vec::new();
        match rest.strip_prefix('{') {
            // The group's top-level members: `{a, b::{c, d}, e}` names a, b and e.
            Some(group) => {
                let (mut depth, mut start) = (0usize, 0usize);
                for (i, c) in group.char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' if depth == 0 => {
                            names.push(&group[start..i]);
                            break;
                        }
                        '}' => depth -= 1,
                        ',' if depth == 0 => {
                            names.push(&group[start..i]);
                            start = i + 1;
                        }
                        _ => {}
                    }
                }
            }
            None => names.push(rest),
        }
        for name in names {
            let ident: String = name.trim().chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            // Lower case: a module (`crate::MotionError` and the like are the crate root's).
            if ident.starts_with(|c: char| c.is_ascii_lowercase()) {
                found.push((at, ident));
            }
        }
    }
    found
}

/// The library code of a source file, comments and inline test modules blanked out so that
/// offsets keep their lines.
fn library_code(text: &str) -> String {
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

#[test]
fn no_module_uses_a_higher_or_equal_layer() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut unplaced = BTreeSet::new();
    let mut arrows = Vec::new();
    for file in &files {
        let relative = file.strip_prefix(&src).unwrap();
        let name = relative.file_name().unwrap().to_string_lossy();
        let in_tests = relative.components().any(|c| c.as_os_str() == "tests");
        if relative == Path::new("lib.rs") || in_tests || name == "tests.rs" || name.starts_with("test_") {
            continue;
        }
        let top = relative.components().next().unwrap().as_os_str().to_string_lossy();
        let top = top.trim_end_matches(".rs").to_owned();
        let Some(own) = layer_of(&top) else {
            unplaced.insert(top);
            continue;
        };
        let code = library_code(&std::fs::read_to_string(file).unwrap());
        for (at, used) in crate_modules(&code) {
            let line = code[..at].matches('\n').count() + 1;
            match layer_of(&used) {
                None => {
                    unplaced.insert(used);
                }
                Some(theirs) if used != top && theirs <= own => arrows
                    .push(format!("{}:{line}: {top} (layer {own}) uses {used} (layer {theirs})", relative.display())),
                Some(_) => {}
            }
        }
    }
    assert!(
        unplaced.is_empty(),
        "modules in no layer (add them to LAYERS and the README's layout table): {unplaced:?}"
    );
    assert!(arrows.is_empty(), "arrows from a lower or equal layer up:\n{}", arrows.join("\n"));
}

#[test]
fn every_module_of_lib_rs_is_in_one_layer() {
    let lib = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("src/lib.rs")).unwrap();
    let declared: BTreeSet<&str> = lib
        .lines()
        .filter_map(|l| l.trim().trim_start_matches("pub ").strip_prefix("mod "))
        .map(|m| m.trim_end_matches(';'))
        .collect();
    let layered: Vec<&str> = LAYERS.iter().flat_map(|l| l.iter().copied()).collect();
    let unique: BTreeSet<&str> = layered.iter().copied().collect();
    assert_eq!(unique.len(), layered.len(), "a module is in two layers");
    assert_eq!(declared, unique, "lib.rs's modules and the layers differ");
}

#[test]
fn the_readme_layout_table_lists_the_layers_top_down() {
    let readme = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../README.md")).unwrap();
    for (i, layer) in LAYERS.iter().enumerate() {
        let prefix = format!("| {} | ", i + 1);
        let row = readme.lines().find(|l| l.starts_with(&prefix)).unwrap_or_else(|| panic!("no row {prefix}"));
        let paths = row.split('|').nth(2).unwrap_or("");
        for module in *layer {
            assert!(
                paths.contains(&format!("{module}/`")) || paths.contains(&format!("{module}.rs`")),
                "README layout row {} should name `{module}`: {paths}",
                i + 1
            );
        }
    }
}

/// Longest source file, lines: a file past it is split along a seam.
const MAX_LINES: usize = 700;

#[test]
fn no_source_file_is_over_700_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut files = Vec::new();
    for dir in ["motion-core/src", "motion-core/tests", "agent/src", "agent/tests", "tests"] {
        if root.join(dir).is_dir() {
            rust_files(&root.join(dir), &mut files);
        }
    }
    let long: Vec<String> = files
        .iter()
        .filter_map(|file| {
            let name = file.strip_prefix(&root).unwrap().to_string_lossy().replace('\\', "/");
            let lines = std::fs::read_to_string(file).unwrap().lines().count();
            (lines > MAX_LINES).then(|| format!("{name}: {lines} lines"))
        })
        .collect();
    assert!(long.is_empty(), "files over {MAX_LINES} lines:\n{}", long.join("\n"));
}
