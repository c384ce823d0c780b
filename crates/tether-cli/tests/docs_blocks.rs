//! Every system file and command shown in README.md and docs/*.md runs as
//! written: each ```` ```sh ```` line that calls `tether` (also as `cargo
//! tether` or `target/release/tether`) is run with this build's binary, each
//! ```` ```toml ```` system file is run, and a system-file fragment (a
//! `[method]`, `[output]` or `[[instance]]` table) is run in place of the same
//! tables of examples/oscillator.toml. A block that cannot run here carries
//! `(Not run in tests: REASON.)` on the line before it, shown to the reader; this test checks
//! the reason is given. Python blocks are run by crates/tether-py's
//! tests/test_docs.py.
//!
//! The commands run in a scratch folder where `examples`, `target`, `tests`
//! and `tools` are links to the repository's, so that what they write lands
//! where the docs say (`target/…`) or in the scratch folder. It also holds
//! `host.token`, the token file docs/remote.md makes; a `tether host` line
//! starts a host that serves the blocks after it and ends with the test.

use std::path::{Path, PathBuf};
use std::process::Command;

/// One fenced block.
struct Block {
    file: String,
    line: usize,
    lang: String,
    text: String,
    /// The reason given by a `(Not run in tests: ….)` line before it.
    skipped: Option<String>,
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

fn blocks() -> Vec<Block> {
    let root = root();
    let mut files = vec![root.join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    let mut out = Vec::new();
    for path in files {
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let name = path.strip_prefix(&root).unwrap().display().to_string();
        let mut i = 0;
        while i < lines.len() {
            let Some(lang) = lines[i].strip_prefix("```") else {
                i += 1;
                continue;
            };
            let start = i;
            let mut j = i + 1;
            while j < lines.len() && !lines[j].starts_with("```") {
                j += 1;
            }
            let marker = start
                .checked_sub(1)
                .map(|k| lines[k].trim())
                .and_then(|l| l.strip_prefix("(Not run in tests:"))
                .and_then(|l| l.strip_suffix(".)"))
                .map(|r| r.trim().to_string());
            out.push(Block {
                file: name.clone(),
                line: start + 1,
                lang: lang.trim().to_string(),
                text: lines[start + 1..j.min(lines.len())].join("\n"),
                skipped: marker,
            });
            i = j + 1;
        }
    }
    out
}

/// A scratch folder with links to the repository's folders (the docs' FMI 3.0
/// examples find the Reference FMUs in `tests/fixtures/reference-fmus`).
fn scratch() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for name in ["examples", "target", "tests", "tools"] {
        std::os::unix::fs::symlink(root().join(name), dir.path().join(name)).unwrap();
    }
    dir
}

/// The command lines of a shell block: continuations joined, comments and
/// blank lines dropped.
fn commands(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut current = String::new();
    for line in text.lines() {
        let line = match line.find(" #") {
            Some(i) => &line[..i],
            None if line.trim_start().starts_with('#') => "",
            None => line,
        };
        let line = line.trim();
        if let Some(part) = line.strip_suffix('\\') {
            current.push_str(part.trim_end());
            current.push(' ');
            continue;
        }
        current.push_str(line);
        if !current.trim().is_empty() {
            out.push(current.trim().to_string());
        }
        current.clear();
    }
    out
}

/// Words of a command line (single and double quotes group).
fn words(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut word = String::new();
    let mut quote = None;
    let mut any = false;
    for c in line.chars() {
        match (quote, c) {
            (None, '"' | '\'') => {
                quote = Some(c);
                any = true;
            }
            (Some(q), c) if c == q => quote = None,
            (None, c) if c.is_whitespace() => {
                if any {
                    out.push(std::mem::take(&mut word));
                    any = false;
                }
            }
            (_, c) => {
                word.push(c);
                any = true;
            }
        }
    }
    if any {
        out.push(word);
    }
    out
}

/// The arguments of a `tether` command line, if it is one.
fn tether_args(line: &str) -> Option<Vec<String>> {
    let w = words(line);
    let skip = match w.first().map(String::as_str) {
        Some("tether" | "target/release/tether") => 1,
        Some("cargo") if w.get(1).map(String::as_str) == Some("tether") => 2,
        _ => return None,
    };
    Some(w[skip..].to_vec())
}

/// The `tether host` processes started by the docs, killed at the end.
#[derive(Default)]
struct Hosts(Vec<std::process::Child>);

impl Hosts {
    /// Starts `tether host` with `args` and waits until it listens.
    fn start(&mut self, dir: &Path, args: &[String], place: &str) {
        use std::io::BufRead;
        let mut child = Command::new(env!("CARGO_BIN_EXE_tether"))
            .args(args)
            .current_dir(dir)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        std::io::BufReader::new(child.stderr.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        self.0.push(child);
        assert!(
            line.starts_with("tether host: listening on "),
            "{place}: `tether {}` does not listen: {line}",
            args.join(" ")
        );
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for child in &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

fn run_tether(dir: &Path, args: &[String], place: &str) {
    let out = Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{place}: `tether {}` failed:\n{}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A system file's tables by header (`[method]`, `[[instance]]`, …), in order,
/// the lines before the first table under "".
fn tables(text: &str) -> Vec<(String, String)> {
    let mut out = vec![(String::new(), String::new())];
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with('[') {
            let header = t.split('#').next().unwrap().trim().to_string();
            out.push((header, String::new()));
        }
        let last = &mut out.last_mut().unwrap().1;
        last.push_str(line);
        last.push('\n');
    }
    out
}

/// The oscillator example with the fragment's tables in place of its own
/// (an `[[instance]]` fragment replaces the instances and constraints).
fn spliced(fragment: &str) -> String {
    let base = std::fs::read_to_string(root().join("examples/oscillator.toml")).unwrap();
    let given = tables(fragment);
    let replaced: Vec<&str> = given
        .iter()
        .map(|(h, _)| h.as_str())
        .filter(|h| !h.is_empty())
        .collect();
    let drop = |h: &str| {
        replaced.contains(&h) || (replaced.contains(&"[[instance]]") && h == "[[constraint]]")
    };
    let mut text: String = tables(&base)
        .into_iter()
        .filter(|(h, _)| !drop(h))
        .map(|(_, body)| body)
        .collect();
    text.push('\n');
    text.push_str(fragment);
    text.push('\n');
    text
}

fn run_toml(block: &Block, dir: &Path) {
    let place = format!("{}:{}", block.file, block.line);
    let text = &block.text;
    let full = text.contains("[experiment]");
    let fragment = [
        "[method]",
        "[output]",
        "[[instance]]",
        "[coupling]",
        "[signals]",
    ]
    .iter()
    .any(|t| text.lines().any(|l| l.trim_start().starts_with(t)));
    assert!(
        full || fragment,
        "{place}: a toml block that is neither a system file nor a fragment of one; \
         mark it `(Not run in tests: reason.)`"
    );
    // The system file sits one folder down, as examples/ does.
    let sub = dir.join("block");
    std::fs::create_dir_all(&sub).unwrap();
    let file = sub.join(format!("line{}.toml", block.line));
    let (text, extra): (String, &[&str]) = if full {
        (text.clone(), &[])
    } else {
        (spliced(text), &["--stop", "0.01"])
    };
    std::fs::write(&file, text).unwrap();
    let mut args: Vec<String> = ["run", file.to_str().unwrap(), "-q", "--out", "block.csv"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    args.extend(extra.iter().map(|s| s.to_string()));
    run_tether(dir, &args, &place);
}

#[test]
fn every_system_file_and_command_in_the_docs_runs_as_written() {
    tether_fmu_build::workspace_fmus().expect("package the workspace FMUs");
    let dir = scratch();
    let token = dir.path().join("host.token");
    std::fs::write(&token, "a token of this docs test, 40 characters\n").unwrap();
    std::fs::set_permissions(&token, std::os::unix::fs::PermissionsExt::from_mode(0o600)).unwrap();
    let mut hosts = Hosts::default();
    let mut ran = 0;
    for block in blocks() {
        let place = format!("{}:{}", block.file, block.line);
        if let Some(reason) = &block.skipped {
            assert!(!reason.is_empty(), "{place}: say why it is not run");
            continue;
        }
        match block.lang.as_str() {
            "sh" => {
                for line in commands(&block.text) {
                    let args = tether_args(&line).unwrap_or_else(|| {
                        panic!(
                            "{place}: `{line}` is not a tether command; run it in a test or \
                             mark the block `(Not run in tests: reason.)`"
                        )
                    });
                    if args.first().is_some_and(|a| a == "host") {
                        hosts.start(dir.path(), &args, &place);
                    } else {
                        run_tether(dir.path(), &args, &place);
                    }
                    ran += 1;
                }
            }
            "toml" => {
                run_toml(&block, dir.path());
                ran += 1;
            }
            _ => {}
        }
    }
    assert!(ran >= 10, "only {ran} blocks ran");
}

#[test]
fn command_lines_are_split_as_a_shell_would() {
    assert_eq!(
        commands("tether run a.toml \\\n    --out b.csv   # comment\n# only a comment\n\ntether info x.fmu"),
        ["tether run a.toml --out b.csv", "tether info x.fmu"]
    );
    assert_eq!(
        words(r#"tether run "a b.toml" --set 'x=1'"#),
        ["tether", "run", "a b.toml", "--set", "x=1"]
    );
    assert_eq!(
        tether_args("cargo tether run x"),
        Some(vec!["run".into(), "x".into()])
    );
    assert_eq!(tether_args("cargo test"), None);
}
