//! A model description's quirks, as a user reads them (docs/fmi-import.md):
//! `warning: NAME.fmu: modelDescription.xml:LINE: …` with the FMU's file
//! name, one line per kind of quirk and FMU with how many more variables,
//! once per FMU however many instances use it, and no Rust module path.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn tether(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tether")
}

/// The workspace oscillator with `initial="exact"` on its two inputs, which
/// FMI 2.0 does not allow: `quirky.fmu` in `dir`.
fn quirky(dir: &Path) -> PathBuf {
    let fmu = tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let mut archive = zip::ZipArchive::new(std::fs::File::open(fmu).unwrap()).unwrap();
    let path = dir.join("quirky.fmu");
    let mut out = zip::ZipWriter::new(std::fs::File::create(&path).unwrap());
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).unwrap();
        let name = entry.name().unwrap().to_string();
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes).unwrap();
        if name == "modelDescription.xml" {
            let text = String::from_utf8(bytes).unwrap().replace(
                r#"causality="input" variability="continuous">"#,
                r#"causality="input" variability="continuous" initial="exact">"#,
            );
            bytes = text.into_bytes();
        }
        if name.ends_with('/') {
            out.add_directory(name, zip::write::SimpleFileOptions::default())
                .unwrap();
            continue;
        }
        out.start_file(name, zip::write::SimpleFileOptions::default())
            .unwrap();
        out.write_all(&bytes).unwrap();
    }
    out.finish().unwrap();
    path
}

/// The warning about `quirky.fmu` in `dir`: it names the line of the first
/// input given `initial="exact"`.
fn line(dir: &Path) -> String {
    let file = std::fs::File::open(dir.join("quirky.fmu")).unwrap();
    let mut archive = zip::ZipArchive::new(file).unwrap();
    let mut text = String::new();
    archive
        .by_name("modelDescription.xml")
        .unwrap()
        .read_to_string(&mut text)
        .unwrap();
    let at = 1 + text
        .lines()
        .position(|l| l.contains(r#"causality="input" variability="continuous" initial="exact""#))
        .expect("an input made quirky");
    format!(
        "warning: quirky.fmu: modelDescription.xml:{at}: variable 'F' declares initial=Exact, \
         not allowed for causality Input and variability Continuous; using the default \
         (and 1 more variable)"
    )
}

fn warnings(out: &Output) -> Vec<String> {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| l.contains("initial=") || l.contains("tether_"))
        .map(str::to_string)
        .collect()
}

/// Three instances of the FMU in a run: the quirk is one line.
#[test]
fn a_quirk_is_one_line_per_fmu_and_kind() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    quirky(d);
    let line = line(d);
    let system = r#"
        [experiment]
        stop = 0.01
        step = 1e-3

        [[instance]]
        name = "a"
        fmu = "quirky.fmu"

        [[instance]]
        name = "b"
        fmu = "quirky.fmu"

        [[instance]]
        name = "c"
        fmu = "quirky.fmu"
    "#;
    std::fs::write(d.join("system.toml"), system).unwrap();
    let out = tether(&["run", "system.toml", "--out", "out.csv"], d);
    assert_eq!(warnings(&out), [line.as_str()]);
    // Isolated, each instance in a host process of its own: still one line.
    let out = tether(&["run", "system.toml", "--isolate", "--out", "out.csv"], d);
    assert_eq!(warnings(&out), [line.as_str()]);
    // `tether info` and `tether simulate` say it the same way.
    let out = tether(&["info", "quirky.fmu"], d);
    assert_eq!(warnings(&out), [line.as_str()]);
    let out = tether(&["simulate", "quirky.fmu", "--stop", "0.01"], d);
    assert_eq!(warnings(&out), [line.as_str()]);
}

/// `-vv`: Tether's own lines say what they are (`info:`, `debug:`), without
/// the Rust module they come from; the FMU's messages name the instance.
#[test]
fn verbose_lines_name_no_rust_module() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fmu = tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let out = tether(
        &["-vv", "simulate", fmu.to_str().unwrap(), "--stop", "0.01"],
        d,
    );
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(!text.contains("tether_"), "{text}");
    // Bracketed lines are the FMU's own messages, naming the instance.
    for line in text.lines().filter(|l| l.starts_with('[')) {
        assert!(line.contains(" fmu::oscillator] "), "{line}");
    }
}
