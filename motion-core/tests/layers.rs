//! The import graph of `motion-core/src` against the layer order of the README's layout table:
//! a module may use (`use crate::..` or a `crate::..` path) only modules of the layers below its
//! own, so no arrow runs back up and there is no cycle. Test code (`tests.rs`, `tests/`,
//! `test_*.rs`, inline `#[cfg(test)] mod .. { }`) may reach anywhere: its fixtures come from the
//! importers. And no source file of the workspace grows past 700 lines.

// Test helpers may unwrap: a failure is the test failing.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

mod source;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use source::{library_code, non_test_code, rust_files};

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

fn is_ident_char(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// The paths of the use tree or path expression that starts at the head of `code`, each with its
/// segments (a group's `self` names the group's module), and the length of the code they take.
fn use_tree(code: &str) -> (Vec<Vec<String>>, usize) {
    let mut segments: Vec<String> = Vec::new();
    let mut at = 0;
    loop {
        let rest = &code[at..];
        let start = rest.len() - rest.trim_start().len();
        let ident: String = rest[start..].chars().take_while(|c| is_ident_char(*c) || *c == '$').collect();
        if ident.is_empty() {
            return (vec![segments], at);
        }
        segments.push(ident.trim_start_matches('$').to_owned());
        at += start + ident.len();
        let rest = &code[at..];
        let Some(after) = rest.trim_start().strip_prefix("::") else {
            return (vec![segments], at);
        };
        let after_at = at + rest.len() - after.len();
        let trimmed = after.trim_start();
        let next = after_at + after.len() - trimmed.len();
        if trimmed.starts_with('*') {
            segments.push("*".to_owned());
            return (vec![segments], next + 1);
        }
        if trimmed.starts_with('{') {
            let mut paths = Vec::new();
            let mut member = next + 1;
            loop {
                let (members, used) = use_tree(&code[member..]);
                for tail in members.into_iter().filter(|tail| !tail.is_empty()) {
                    let mut path = segments.clone();
                    path.extend(tail.into_iter().filter(|s| s != "self"));
                    paths.push(path);
                }
                let rest = &code[member + used..];
                let trimmed = rest.trim_start();
                let here = member + used + rest.len() - trimmed.len();
                match trimmed.chars().next() {
                    Some(',') => member = here + 1,
                    Some('}') => return (paths, here + 1),
                    _ => return (paths, here),
                }
            }
        }
        if !trimmed.starts_with(|c: char| is_ident_char(c) || c == '$') {
            return (vec![segments], at);
        }
        at = after_at;
    }
}

/// One crate's module files: the module path (`["render", "strip"]`) of each file, the root's
/// the empty path; and the names each file re-exports (`pub use strip::motion_strip;`) with the
/// whole path each names.
struct CrateFiles {
    modules: std::collections::BTreeMap<Vec<String>, PathBuf>,
    reexports: std::collections::BTreeMap<Vec<String>, std::collections::BTreeMap<String, Vec<String>>>,
}

/// The whole path of `path` as written in the module `base` (`crate::`, `super::` and `self::`
/// taken off).
fn absolute(path: &[String], base: &[String]) -> Vec<String> {
    let mut module = base.to_vec();
    let mut rest = path;
    while let Some((head, tail)) = rest.split_first() {
        match head.as_str() {
            "crate" => module.clear(),
            "super" => {
                module.pop();
            }
            "self" => {}
            _ => break,
        }
        rest = tail;
    }
    module.extend(rest.iter().cloned());
    module
}

/// The deepest module file on a whole path, and the rest of the path after it.
fn split_at_file(mut path: Vec<String>, modules: &CrateFiles) -> (Vec<String>, Vec<String>) {
    let mut rest = Vec::new();
    while !modules.modules.contains_key(&path) {
        rest.insert(0, path.pop().unwrap());
    }
    (path, rest)
}

/// The names that the code of the module `own` re-exports (`pub use ..;`, `pub(crate) use ..;`)
/// from modules of its crate, each with the whole path it names.
fn reexports_of(
    code: &str,
    own: &[String],
    modules: &std::collections::BTreeMap<Vec<String>, PathBuf>,
) -> std::collections::BTreeMap<String, Vec<String>> {
    let mut found = std::collections::BTreeMap::new();
    for (at, _) in code.match_indices("pub") {
        if code[..at].chars().next_back().is_some_and(is_ident_char) {
            continue;
        }
        let mut rest = &code[at + "pub".len()..];
        if let Some(group) = rest.strip_prefix('(') {
            rest = group.split_once(')').map_or("", |(_, after)| after);
        }
        let Some(tree) = rest.trim_start().strip_prefix("use ") else { continue };
        for path in use_tree(tree).0 {
            let local = path.first().is_some_and(|head| {
                ["crate", "super", "self"].contains(&head.as_str())
                    || modules.contains_key(&[own.to_vec(), vec![head.clone()]].concat())
            });
            match path.last() {
                Some(name) if local && name != "*" => {
                    found.insert(name.clone(), absolute(&path, own));
                }
                _ => {}
            }
        }
    }
    found
}

/// The crates of the source folder `src`: `lib.rs` and `main.rs` with the files of the modules
/// that each declares.
fn crates_of(src: &Path) -> Vec<CrateFiles> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut crates = Vec::new();
    for root in ["lib.rs", "main.rs"] {
        let Ok(text) = std::fs::read_to_string(src.join(root)) else { continue };
        let declared: BTreeSet<String> = library_code(&text)
            .lines()
            .filter_map(|l| {
                let l = l.trim();
                let l = l.strip_prefix("pub(crate) ").or_else(|| l.strip_prefix("pub ")).unwrap_or(l);
                l.strip_prefix("mod ")?.strip_suffix(';').map(str::to_owned)
            })
            .collect();
        let mut modules = std::collections::BTreeMap::new();
        modules.insert(Vec::new(), src.join(root));
        for file in &files {
            let mut path: Vec<String> = file
                .strip_prefix(src)
                .unwrap()
                .components()
                .map(|c| c.as_os_str().to_string_lossy().trim_end_matches(".rs").to_owned())
                .collect();
            if path.last().is_some_and(|last| last == "mod") {
                path.pop();
            }
            if path.first().is_some_and(|top| declared.contains(top)) {
                modules.insert(path, file.clone());
            }
        }
        let reexports = modules
            .iter()
            .map(|(own, file)| {
                let code = non_test_code(&std::fs::read_to_string(file).unwrap());
                (own.clone(), reexports_of(&code, own, &modules))
            })
            .collect();
        crates.push(CrateFiles { modules, reexports });
    }
    crates
}

/// Whether a file of a source folder is test code (`tests.rs`, `tests/`, `test_*.rs`).
fn is_test_file(relative: &Path) -> bool {
    let name = relative.file_name().unwrap().to_string_lossy();
    relative.components().any(|c| c.as_os_str() == "tests") || name == "tests.rs" || name.starts_with("test_")
}

/// The inline modules (`mod name { .. }`) of `code`: each name with the byte range of its body.
fn inline_modules(code: &str) -> Vec<(String, std::ops::Range<usize>)> {
    let mut found = Vec::new();
    for (at, _) in code.match_indices("mod ") {
        if code[..at].chars().next_back().is_some_and(is_ident_char) {
            continue;
        }
        let rest = &code[at + "mod ".len()..];
        let name: String = rest.chars().take_while(|c| is_ident_char(*c)).collect();
        let Some(body) = rest[name.len()..].trim_start().strip_prefix('{') else { continue };
        let open = code.len() - body.len();
        let mut depth = 1;
        let close = body
            .char_indices()
            .find(|(_, c)| {
                match c {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    _ => {}
                }
                depth == 0
            })
            .map_or(code.len(), |(i, _)| open + i);
        found.push((name, open..close));
    }
    found
}

/// The files that `code` (of the module `own`) uses through `crate::`, `super::`, `self::` and
/// child-module paths: each with the byte offset of its use tree or path, one path of it (a
/// group's members one by one) and the module file that the path names: the deepest module file
/// on it, or, for a name that a module outside `own`'s ancestors re-exports (a folder's face seen
/// from outside it), the file that the re-export names. A file inside the folder that reaches a
/// name through the folder's face uses the face's file.
fn used_files(code: &str, own: &[String], modules: &CrateFiles) -> Vec<(usize, String, Vec<String>)> {
    let inline = inline_modules(code);
    let mut found = Vec::new();
    let mut parsed_to = 0;
    for (at, _) in code.match_indices("::") {
        let start = code[..at].trim_end_matches(|c: char| is_ident_char(c) || c == '$').len();
        if start < parsed_to || start == at || code[..start].trim_end().ends_with("::") {
            continue;
        }
        let ident = code[start..at].trim_start_matches('$');
        let mut base = own.to_vec();
        base.extend(inline.iter().filter(|(_, body)| body.contains(&start)).map(|(name, _)| name.clone()));
        let child = [base.clone(), vec![ident.to_owned()]].concat();
        if !["crate", "super", "self"].contains(&ident) && !modules.modules.contains_key(&child) {
            continue;
        }
        let (paths, used) = use_tree(&code[start..]);
        parsed_to = start + used;
        for path in paths {
            let written = path.join("::");
            let (mut module, mut rest) = split_at_file(absolute(&path, &base), modules);
            // Through re-exports, a few at most (a face may re-export a face).
            for _ in 0..8 {
                let Some(first) = rest.first().filter(|_| !own.starts_with(&module)) else { break };
                let Some(target) = modules.reexports.get(&module).and_then(|names| names.get(first)) else { break };
                (module, rest) = split_at_file([target.clone(), rest[1..].to_vec()].concat(), modules);
            }
            found.push((start, written, module));
        }
    }
    found
}

/// The strongly connected components of more than one node of a graph given as adjacency sets.
fn circles(graph: &[BTreeSet<usize>]) -> Vec<Vec<usize>> {
    struct Tarjan<'a> {
        graph: &'a [BTreeSet<usize>],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        stack: Vec<usize>,
        on_stack: Vec<bool>,
        next: usize,
        found: Vec<Vec<usize>>,
    }
    impl Tarjan<'_> {
        fn visit(&mut self, v: usize) {
            self.index[v] = Some(self.next);
            self.low[v] = self.next;
            self.next += 1;
            self.stack.push(v);
            self.on_stack[v] = true;
            for &w in self.graph[v].iter() {
                match self.index[w] {
                    None => {
                        self.visit(w);
                        self.low[v] = self.low[v].min(self.low[w]);
                    }
                    Some(i) if self.on_stack[w] => self.low[v] = self.low[v].min(i),
                    Some(_) => {}
                }
            }
            if Some(self.low[v]) == self.index[v] {
                let mut component = Vec::new();
                loop {
                    let w = self.stack.pop().unwrap();
                    self.on_stack[w] = false;
                    component.push(w);
                    if w == v {
                        break;
                    }
                }
                if component.len() > 1 {
                    component.sort_unstable();
                    self.found.push(component);
                }
            }
        }
    }
    let n = graph.len();
    let mut tarjan = Tarjan {
        graph,
        index: vec![None; n],
        low: vec![0; n],
        stack: Vec::new(),
        on_stack: vec![false; n],
        next: 0,
        found: Vec::new(),
    };
    for v in 0..n {
        if tarjan.index[v].is_none() {
            tarjan.visit(v);
        }
    }
    tarjan.found
}

/// The file-level import graph of each crate of `motion-core` and `agent`: no non-test file
/// uses an item of an ancestor module's file (`super::X` from `render/strip.rs` reads
/// `render/mod.rs`; the crate root, the crate's face, aside), and no files use each other in a
/// circle. A parent's `pub use child::X` is an arrow down, and fine.
#[test]
fn no_file_uses_its_parent_module_and_no_files_use_each_other_in_a_circle() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let (mut up, mut loops) = (Vec::new(), Vec::new());
    for src in ["motion-core/src", "agent/src"].map(|dir| root.join(dir)) {
        for krate in crates_of(&src) {
            let files: Vec<(&Vec<String>, &PathBuf)> = krate.modules.iter().collect();
            let index: std::collections::BTreeMap<&Vec<String>, usize> =
                files.iter().enumerate().map(|(i, (module, _))| (*module, i)).collect();
            let mut graph = vec![BTreeSet::new(); files.len()];
            // Each arrow's uses, `file:line: uses path, path (file used)`, in the order of the file.
            let mut uses: std::collections::BTreeMap<(usize, usize), Vec<String>> = std::collections::BTreeMap::new();
            let name = |file: &Path| file.strip_prefix(&root).unwrap().to_string_lossy().replace('\\', "/");
            for (from, (own, file)) in files.iter().enumerate() {
                if is_test_file(file.strip_prefix(&src).unwrap()) {
                    continue;
                }
                let code = non_test_code(&std::fs::read_to_string(file).unwrap());
                // The paths of each use tree or path, by its line and the file they name.
                let mut by_line: std::collections::BTreeMap<(usize, usize), Vec<String>> =
                    std::collections::BTreeMap::new();
                for (at, written, used) in used_files(&code, own, &krate) {
                    let to = index[&used];
                    let line = code[..at].matches('\n').count() + 1;
                    if to != from && !by_line.get(&(line, to)).is_some_and(|paths| paths.contains(&written)) {
                        by_line.entry((line, to)).or_default().push(written);
                    }
                }
                for ((line, to), paths) in by_line {
                    let used = files[to].0;
                    let what = format!("{}:{line}: uses {} ({})", name(file), paths.join(", "), name(files[to].1));
                    if !used.is_empty() && used.len() < own.len() && own.starts_with(used) {
                        up.push(what.clone());
                    }
                    graph[from].insert(to);
                    uses.entry((from, to)).or_default().push(what);
                }
            }
            for circle in circles(&graph) {
                let members: Vec<String> = circle.iter().map(|&i| name(files[i].1)).collect();
                let ties: Vec<&String> = uses
                    .iter()
                    .filter(|((from, to), _)| circle.contains(from) && circle.contains(to))
                    .flat_map(|(_, what)| what)
                    .collect();
                loops.push(format!(
                    "circle of {}: {}\n    {}",
                    members.len(),
                    members.join(", "),
                    ties.iter().map(|t| t.as_str()).collect::<Vec<_>>().join("\n    ")
                ));
            }
        }
    }
    assert!(
        up.is_empty() && loops.is_empty(),
        "files that use their parent module's file ({}):\n{}\ncircles of files ({}):\n{}",
        up.len(),
        up.join("\n"),
        loops.len(),
        loops.join("\n")
    );
}
