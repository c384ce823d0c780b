//! No two modules of a crate use each other: the modules of each crate's
//! `src/` (a file `src/a.rs` or a folder `src/a/` is module `a`) form layers.
//! A use is any `crate::a` path in a module's code other than `a`'s own (doc
//! comments and tests are not read). Run it alone with
//! `cargo test -p tether-master --test module_graph`.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The crates whose modules are checked: every crate of the workspace.
fn crates(root: &Path) -> Vec<PathBuf> {
    let mut crates: Vec<PathBuf> = std::fs::read_dir(root)
        .unwrap()
        .map(|e| e.unwrap().path().join("src"))
        .filter(|src| src.is_dir())
        .collect();
    crates.sort();
    crates
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

/// The top-level module a file of `src` belongs to (`lib` for lib.rs).
fn module_of(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).unwrap();
    let first = rel
        .components()
        .next()
        .unwrap()
        .as_os_str()
        .to_string_lossy();
    first.trim_end_matches(".rs").to_string()
}

/// The code of a file without comments and without its `#[cfg(test)]` module.
fn code(text: &str) -> String {
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(at) => &text[..at],
        None => text,
    };
    text.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// Module → the modules of the same crate its code names (`crate::x`).
fn uses(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let modules: BTreeSet<String> = files.iter().map(|f| module_of(src, f)).collect();
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in &files {
        let from = module_of(src, file);
        let text = code(&std::fs::read_to_string(file).unwrap());
        let used = graph.entry(from.clone()).or_default();
        for (at, _) in text.match_indices("crate::") {
            let before = text[..at].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                continue; // `tether_fmi_crate::`, `$crate::`
            }
            let name: String = text[at + 7..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            // A grouped use, `crate::{a, b::c}`: every first name in it.
            let names: Vec<String> = if text[at + 7..].starts_with('{') {
                let group = &text[at + 8..];
                let group = &group[..group.find('}').unwrap_or(group.len())];
                group
                    .split(',')
                    .map(|p| p.trim().split("::").next().unwrap_or("").to_string())
                    .collect()
            } else {
                vec![name]
            };
            for name in names {
                if name != from && modules.contains(&name) && name != "lib" {
                    used.insert(name);
                }
            }
        }
    }
    graph
}

#[test]
fn no_two_modules_use_each_other() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut pairs = Vec::new();
    let crates = crates(&root);
    assert!(crates.len() >= 10, "{crates:?}");
    for src in crates {
        let krate = src.parent().unwrap().file_name().unwrap().to_string_lossy();
        let graph = uses(&src);
        for (a, used) in &graph {
            for b in used {
                if a < b && graph.get(b).is_some_and(|u| u.contains(a)) {
                    pairs.push(format!("{krate}: {a} <-> {b}"));
                }
            }
        }
    }
    assert!(
        pairs.is_empty(),
        "modules that use each other:\n{}",
        pairs.join("\n")
    );
}
