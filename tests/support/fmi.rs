//! Helpers for the tether-fmi integration tests (`tests/fmi_*.rs`): the workspace's
//! oscillator FMU, hand-made archives, a C stub FMU compiled at test time, RSS.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

/// An instance of `fmu` called `name`, set up at t = 0 and through initialization mode.
pub fn initialized(
    fmu: &tether_fmi::Fmu,
    name: &str,
    options: tether_fmi::InstanceOptions,
) -> tether_fmi::Instance {
    let mut instance = fmu.instantiate(name, options).expect("instantiate");
    instance.setup_experiment(None, 0.0, None).expect("setup");
    instance.enter_initialization_mode().expect("enter init");
    instance.exit_initialization_mode().expect("exit init");
    instance
}

/// The oscillator FMU from `fmus/oscillator`, built and packaged once per process.
pub fn oscillator_fmu() -> PathBuf {
    tether_fmu_build::workspace_fmu("oscillator")
        .unwrap_or_else(|e| panic!("cannot build the oscillator FMU: {e}"))
}

/// One entry of a hand-made zip archive.
pub enum Entry<'a> {
    /// A regular file with its contents (deflated).
    File(&'a str, &'a [u8]),
    /// A directory.
    Dir(&'a str),
    /// A symbolic link and its target.
    Symlink(&'a str, &'a str),
}

/// Writes a zip archive with exactly these entries (names are stored verbatim, so
/// `../evil` and `/abs` can be produced).
pub fn write_zip(path: &Path, entries: &[Entry<'_>]) {
    let file = std::fs::File::create(path).expect("create zip");
    let mut zip = zip::ZipWriter::new(file);
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for entry in entries {
        match entry {
            Entry::File(name, bytes) => {
                zip.start_file(*name, options).expect("start file");
                zip.write_all(bytes).expect("write entry");
            }
            Entry::Dir(name) => zip.add_directory(*name, options).expect("add dir"),
            Entry::Symlink(name, target) => zip
                .add_symlink(*name, *target, options)
                .expect("add symlink"),
        }
    }
    zip.finish().expect("finish zip");
}

/// Writes every file under `dir` into a zip archive at `archive` (a `.fmu`).
pub fn zip_directory(dir: &Path, archive: &Path) {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(String, Vec<u8>)>) {
        for entry in std::fs::read_dir(dir).expect("read dir") {
            let path = entry.expect("dir entry").path();
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                let name = path.strip_prefix(root).expect("prefix");
                let name = name.to_string_lossy().replace('\\', "/");
                out.push((name, std::fs::read(&path).expect("read file")));
            }
        }
    }
    let mut files = Vec::new();
    walk(dir, dir, &mut files);
    let entries: Vec<Entry<'_>> = files
        .iter()
        .map(|(n, b)| Entry::File(n.as_str(), b.as_slice()))
        .collect();
    write_zip(archive, &entries);
}

/// Extracts a (trusted) zip archive into `into`, e.g. to reuse the oscillator's binary.
pub fn unzip(archive: &Path, into: &Path) {
    let file = std::fs::File::open(archive).expect("open archive");
    let mut zip = zip::ZipArchive::new(file).expect("read archive");
    zip.extract(into).expect("extract archive");
}

/// A small FMI modelDescription.xml: `fmi_version`, and which of the `CoSimulation` /
/// `ModelExchange` elements to include (with `model_identifier`).
pub fn model_description(
    fmi_version: &str,
    model_identifier: &str,
    co_simulation: bool,
    model_exchange: bool,
) -> String {
    let cs = if co_simulation {
        format!(
            r#"  <CoSimulation modelIdentifier="{model_identifier}" canGetAndSetFMUstate="true" canSerializeFMUstate="true"/>"#
        )
    } else {
        String::new()
    };
    let me = if model_exchange {
        format!(r#"  <ModelExchange modelIdentifier="{model_identifier}"/>"#)
    } else {
        String::new()
    };
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="{fmi_version}" modelName="stub" guid="{{stub-guid}}">
{cs}
{me}
  <ModelVariables>
    <ScalarVariable name="x" valueReference="0" causality="output"><Real/></ScalarVariable>
    <ScalarVariable name="t" valueReference="1" causality="output"><Real/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="1"/><Unknown index="2"/></Outputs>
  </ModelStructure>
</fmiModelDescription>
"#
    )
}

/// Compiles C `source` into `dir/<name>.so` with the system C compiler.
pub fn compile_shared_library(dir: &Path, name: &str, source: &str, defines: &[String]) -> PathBuf {
    let c_file = dir.join(format!("{name}.c"));
    std::fs::write(&c_file, source).expect("write C source");
    let so = dir.join(format!("{name}.so"));
    let compiler = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let status = Command::new(compiler)
        .args(["-shared", "-fPIC", "-O1", "-o"])
        .arg(&so)
        .args(defines)
        .arg(&c_file)
        .status()
        .expect("run the C compiler");
    assert!(status.success(), "compiling {} failed", c_file.display());
    so
}

/// An unpacked FMU directory (`<dir>/stub`) around the C stub FMU of
/// `tests/fixtures/fmi/stub_fmu.c`, and the file the stub appends its calls to.
pub fn stub_fmu_dir(dir: &Path) -> (PathBuf, PathBuf) {
    stub_fmu_dir_with(dir, &[])
}

/// Like [`stub_fmu_dir`], with extra C compiler arguments (e.g. `-DSTUB_VERSION="3.0"`).
pub fn stub_fmu_dir_with(dir: &Path, extra: &[String]) -> (PathBuf, PathBuf) {
    let root = dir.join("stub");
    let binaries = root.join("binaries").join("linux64");
    std::fs::create_dir_all(&binaries).expect("mkdir binaries");
    std::fs::create_dir_all(root.join("resources")).expect("mkdir resources");
    let log = dir.join("calls.log");
    std::fs::write(&log, "").expect("create call log");
    let source = include_str!("../fixtures/fmi/stub_fmu.c");
    let mut defines = vec![format!("-DSTUB_LOG=\"{}\"", log.display())];
    defines.extend_from_slice(extra);
    compile_shared_library(&binaries, "stub", source, &defines);
    std::fs::write(
        root.join("modelDescription.xml"),
        model_description("2.0", "stub", true, false),
    )
    .expect("write modelDescription.xml");
    (root, log)
}

/// Lines the stub FMU wrote to its call log.
pub fn stub_calls(log: &Path) -> Vec<String> {
    std::fs::read_to_string(log)
        .expect("read call log")
        .lines()
        .map(str::to_owned)
        .collect()
}

/// Resident set size of this process in bytes (from /proc/self/statm).
pub fn rss_bytes() -> u64 {
    let statm = std::fs::read_to_string("/proc/self/statm").expect("read /proc/self/statm");
    let pages: u64 = statm
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .expect("statm has a resident field");
    let page = Command::new("getconf")
        .arg("PAGESIZE")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(4096u64);
    pages * page
}

/// Asserts that an error's `Display` is one line and contains every fragment.
pub fn assert_one_line_naming(error: &dyn std::fmt::Display, fragments: &[&str]) {
    let text = error.to_string();
    assert!(!text.contains('\n'), "message spans lines: {text:?}");
    for fragment in fragments {
        assert!(
            text.contains(fragment),
            "message {text:?} lacks {fragment:?}"
        );
    }
}

/// A model-exchange-only FMI 2.0 FMU, unpacked in `dir`: the sawtooth of
/// `tests/fixtures/fmi/me_sawtooth.c` (x' = −1 from 1, reset to 1 by the state
/// event at x = 0; parameter `mode` 1 chatters, 2 fails in fmi2GetDerivatives
/// after t = 0.5, 3 asks to terminate at the first event, 4 returns NaN
/// derivatives after t = 0.5, 5 runs to infinity at t = 0.9, 6 sleeps 30 s in
/// fmi2GetDerivatives after t = 0.5), compiled now.
pub fn me_sawtooth_fmu(dir: &Path) -> PathBuf {
    let root = dir.join("sawtooth");
    let binaries = root.join("binaries").join("linux64");
    std::fs::create_dir_all(&binaries).unwrap();
    std::fs::create_dir_all(root.join("resources")).unwrap();
    let source = include_str!("../fixtures/fmi/me_sawtooth.c");
    compile_shared_library(&binaries, "sawtooth", source, &[]);
    std::fs::write(
        root.join("modelDescription.xml"),
        include_str!("../fixtures/fmi/me_sawtooth.xml"),
    )
    .unwrap();
    root
}
