//! The bad-input corpus: hostile and broken FMUs, mistyped system files, bad method
//! parameters and FMUs that fail mid-run. The cases check:
//!
//! 1. the exact error kind, from the library (`SystemSpec` + `Simulation`); for broken
//!    FMUs that is `Fmu::open`'s business and tested in tests/fmi_bad_fmus.rs, so here
//!    there is one FMU per class of defect, through the binary only;
//! 2. the `tether` binary (`tether info FMU` or `tether run SYSTEM`) exits non-zero
//!    with a last stderr line `error: …` that names the culprit, and never panics;
//! 3. for failures mid-run, the CSV keeps every accepted step, flushed, and ends with
//!    `# incomplete: <the error>`; no FMU extraction directory is left behind.
//!
//! Every FMU is real: archives are written here, binaries are the workspace oscillator
//! or the faulty oscillator compiled from C at test time (tests/support/faulty.rs).
//!
//! Joints: an unknown marker, an unknown kind and a spatial joint on a planar marker
//! without the port it needs.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use tether_fmi::{Error, Fmu};
use tether_master::{MasterError, MemoryRecorder, Simulation, SystemSpec};
use tether_tests::faulty::{edited_oscillator, faulty_fmu, Capabilities};
use tether_tests::fmi::{model_description, oscillator_fmu, write_zip, Entry};

// ---------------------------------------------------------------- helpers

fn tether(args: &[&str], dir: &Path) -> Output {
    tether_env(args, dir, None)
}

/// Runs `tether` with `TMPDIR` (where FMUs are extracted) set to `tmp` if given.
fn tether_env(args: &[&str], dir: &Path, tmp: Option<&Path>) -> Output {
    let mut command = Command::new(env!("CARGO_BIN_EXE_tether"));
    command.args(args).current_dir(dir);
    if let Some(tmp) = tmp {
        command.env("TMPDIR", tmp);
    }
    command.output().expect("run tether")
}

/// Asserts exit code 1, no panic, and a last stderr line `error: …` holding every
/// fragment; returns that line.
fn cli_error(out: &Output, fragments: &[&str]) -> String {
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "exit code; stderr:\n{text}");
    assert!(!text.contains("panicked"), "{text}");
    let line = text.lines().last().unwrap_or_default().to_string();
    assert!(line.starts_with("error: "), "{text}");
    for fragment in fragments {
        assert!(line.contains(fragment), "{line:?} lacks {fragment:?}");
    }
    line
}

/// Runs `tether info FMU`; asserts [`cli_error`] and that the error line is all of stderr.
fn info_error(fmu: &Path, fragments: &[&str]) -> String {
    let dir = fmu.parent().unwrap();
    let out = tether(&["info", fmu.to_str().unwrap()], dir);
    let line = cli_error(&out, fragments);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    line
}

/// The error that keeps a system from starting (reading, validating, instantiating).
fn setup_err(system: &Path) -> MasterError {
    let result = SystemSpec::from_file(system).and_then(|spec| Simulation::new(&spec).map(drop));
    match result {
        Ok(()) => panic!("{} was accepted", system.display()),
        Err(e) => e,
    }
}

/// Runs a system in-process; returns the error that stopped it and what was recorded.
fn run_err(system: &Path) -> (MasterError, MemoryRecorder) {
    let spec = SystemSpec::from_file(system).expect("valid system file");
    let mut sim = Simulation::new(&spec).expect("the system starts");
    let mut recorder = MemoryRecorder::default();
    let err = sim
        .run(&mut [&mut recorder], &mut |_, _| {})
        .expect_err("the run fails");
    (err, recorder)
}

fn fmi(err: &MasterError) -> &Error {
    match err {
        MasterError::Fmi(e) | MasterError::InstanceFmu { error: e, .. } => e,
        other => panic!("expected an FMI error, got {other:?}"),
    }
}

fn shown(path: &Path) -> String {
    path.display().to_string()
}

fn with_description(dir: &Path, name: &str, xml: &str) -> PathBuf {
    let path = dir.join(name);
    write_zip(
        &path,
        &[Entry::File("modelDescription.xml", xml.as_bytes())],
    );
    path
}

fn cs_description() -> String {
    model_description("2.0", "stub", true, false)
}

const OSCILLATOR_SYSTEM: &str = r#"
name = "bad-input test"

[experiment]
start = 0.0
stop = 0.1
step = 1e-3

[method]
kind = "baumgarte"
beta = 2e-3
gamma = 1e-6

[coupling]
order = 0

[[instance]]
name = "mass1"
fmu = "FMU1"
parameters = { m = 1.0, c = 1000.0, d = 10.0, v0 = 100.0 }

[[instance]]
name = "mass2"
fmu = "FMU2"
parameters = { m = 2.0, c = 1000.0, d = 10.0, v0 = 100.0 }

[[constraint]]
name = "link"
position = "mass2.x - mass1.x"
velocity = "mass2.v - mass1.v"
acceleration = "mass2.a - mass1.a"
drives = "mass1.F - mass2.F"
"#;

/// Writes `<dir>/system.toml`: two coupled masses, `fmu2` for mass 2 (the oscillator
/// for both when `None`), after `edit`.
fn system_with(dir: &Path, fmu2: Option<&Path>, edit: impl Fn(String) -> String) -> PathBuf {
    let osc = oscillator_fmu();
    let text = OSCILLATOR_SYSTEM
        .replace("FMU1", osc.to_str().unwrap())
        .replace("FMU2", fmu2.unwrap_or(&osc).to_str().unwrap());
    let path = dir.join("system.toml");
    std::fs::write(&path, edit(text)).unwrap();
    path
}

fn system(dir: &Path, edit: impl Fn(String) -> String) -> PathBuf {
    system_with(dir, None, edit)
}

fn run_error(system: &Path, fragments: &[&str]) -> String {
    let dir = system.parent().unwrap();
    cli_error(&tether(&["run", system.to_str().unwrap()], dir), fragments)
}

/// Replaces `from` (which must occur) by `to`.
fn swap(text: String, from: &str, to: &str) -> String {
    assert!(text.contains(from), "{from:?} not in the system file");
    text.replacen(from, to, 1)
}

/// Mass 2 held to its co-simulation interface (`fmi_type = "auto"` would run
/// the workspace oscillator's model exchange where co-simulation lacks a
/// capability: `auto_runs_model_exchange_where_co_simulation_lacks_a_capability`).
fn co_simulation(text: String) -> String {
    swap(
        text,
        "name = \"mass2\"\n",
        "name = \"mass2\"\nfmi_type = \"co_simulation\"\n",
    )
}

// ---------------------------------------------------------------- FMUs

// The library's refusal of each broken or hostile FMU (the exact error variant, every
// distinct archive, description and binary defect) is tested once, in
// tests/fmi_bad_fmus.rs. Here one FMU per class of defect goes through `tether info`:
// the process exits with 1, does not panic, and prints one line that names the FMU
// (or the part of it at fault).

/// The path: nothing at it.
#[test]
fn a_missing_fmu_path_is_one_error_line_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("missing.fmu");
    info_error(&path, &[&shown(&path), "cannot access"]);
}

/// The container: not a zip archive.
#[test]
fn a_file_that_is_not_a_zip_is_one_error_line_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.fmu");
    std::fs::write(&path, "this is not a zip archive").unwrap();
    info_error(&path, &[&shown(&path), "not an FMU archive"]);
}

/// The entries: one that would land outside the extraction directory.
#[test]
fn a_zip_slip_entry_is_one_error_line_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("slip.fmu");
    let name = format!("resources/../../tether-slip-{}", std::process::id());
    write_zip(
        &path,
        &[
            Entry::File("modelDescription.xml", cs_description().as_bytes()),
            Entry::File(&name, b"owned"),
        ],
    );
    info_error(&path, &[&shown(&path), &name, "escapes"]);
}

/// The model description: not well-formed, reported with its line.
#[test]
fn a_malformed_model_description_is_one_error_line_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let xml = cs_description().replace("</ModelVariables>", "</ModelVariable>");
    let line = 1 + xml
        .lines()
        .position(|l| l.contains("</ModelVariable>"))
        .unwrap();
    let path = with_description(dir.path(), "malformed.fmu", &xml);
    info_error(
        &path,
        &[
            &shown(&path),
            "modelDescription.xml",
            &format!("line {line}"),
        ],
    );
}

/// The standard: an FMU of another FMI version.
#[test]
fn an_fmi_4_0_fmu_is_one_error_line_naming_the_version() {
    let dir = tempfile::tempdir().unwrap();
    let xml = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="4.0" modelName="m" instantiationToken="{x}">
  <CoSimulation modelIdentifier="m"/>
</fmiModelDescription>"#;
    let path = with_description(dir.path(), "four.fmu", xml);
    info_error(&path, &[&shown(&path), "FMI 4.0", "FMI 2.0 and 3.0"]);
}

/// An FMI 3.0 FMU is read; without its binary (under x86_64-linux) it is refused.
#[test]
fn an_fmi_3_0_fmu_without_its_binary_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let xml = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="3.0" modelName="m" instantiationToken="{x}">
  <CoSimulation modelIdentifier="m"/>
  <ModelVariables><Float64 name="x" valueReference="0"/></ModelVariables>
  <ModelStructure/>
</fmiModelDescription>"#;
    let path = with_description(dir.path(), "three.fmu", xml);
    info_error(
        &path,
        &["no x86_64-linux binary", "binaries/x86_64-linux/m.so"],
    );
}

/// The binary: present but not loadable (the loader's message, on one line).
#[test]
fn a_binary_that_is_not_a_shared_library_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("notelf.fmu");
    write_zip(
        &path,
        &[
            Entry::File("modelDescription.xml", cs_description().as_bytes()),
            Entry::File("binaries/linux64/stub.so", b"#!/bin/sh\necho not ELF\n"),
        ],
    );
    info_error(&path, &["cannot load FMU library", "stub.so"]);
}

/// The model description: nested 200 000 levels deep (1.4 MB), refused at the first
/// element past the XML reader's depth limit.
#[test]
fn a_deeply_nested_model_description_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let depth = 200_000;
    let xml = cs_description().replace(
        "<ModelVariables>",
        &format!(
            "<VendorAnnotations><Tool name=\"t\">{}{}</Tool></VendorAnnotations><ModelVariables>",
            "<x>".repeat(depth),
            "</x>".repeat(depth)
        ),
    );
    // Stored: deflated, the file's compression ratio (about 200) is over the
    // archive limit, which refuses it before the XML is read.
    let path = dir.path().join("deep.fmu");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&path).unwrap());
    let stored =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    zip.start_file("modelDescription.xml", stored).unwrap();
    std::io::Write::write_all(&mut zip, xml.as_bytes()).unwrap();
    zip.finish().unwrap();
    info_error(
        &path,
        &[
            &format!("XML file '{}/modelDescription.xml'", shown(&path)),
            "nested more than 256 deep",
        ],
    );
    let deflated = with_description(dir.path(), "deflated.fmu", &xml);
    info_error(
        &deflated,
        &[
            &format!("FMU archive '{}'", shown(&deflated)),
            "entry 'modelDescription.xml'",
            "compression ratio over the limit of 100",
        ],
    );
}

// ---------------------------------------------------------------- SSP archives and files

// The library's refusal of each hostile SSP input is tested in
// crates/tether-ssp/tests/hostile_inputs.rs. Here `tether run` and `tether ssp import`
// exit with 1 and one line naming the archive and the entry (or the file and the
// position), with `TMPDIR` empty afterwards: nothing was extracted, or it was removed.

/// A system with one component whose `source` is `source`; `inner` inside the
/// root system.
fn ssd(source: &str, inner: &str) -> String {
    format!(
        r#"<?xml version="1.0"?>
<ssd:SystemStructureDescription version="1.0" name="t"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription">
  <ssd:System name="s">
    <ssd:Elements><ssd:Component name="a" source="{source}"/></ssd:Elements>
    {inner}
  </ssd:System>
  <ssd:DefaultExperiment stopTime="1"/>
</ssd:SystemStructureDescription>"#
    )
}

/// Runs `tether run SSP` and `tether ssp import SSP` with an empty `TMPDIR` of their
/// own; both must fail with one line holding every fragment and leave `TMPDIR` empty.
fn ssp_error(ssp: &Path, fragments: &[&str]) {
    let dir = ssp.parent().unwrap();
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let ssp = ssp.to_str().unwrap();
    for args in [
        vec!["run", ssp, "--step", "1e-3", "--out", "out.csv"],
        vec![
            "ssp",
            "import",
            ssp,
            "--step",
            "1e-3",
            "-o",
            "imported/system.toml",
        ],
    ] {
        let out = tether_env(&args, dir, Some(&tmp));
        cli_error(&out, fragments);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(stderr.lines().count(), 1, "{args:?}: {stderr}");
        let leftovers: Vec<_> = std::fs::read_dir(&tmp).unwrap().collect();
        assert!(
            leftovers.is_empty(),
            "{args:?} left in TMPDIR: {leftovers:?}"
        );
    }
}

/// Overwrites the declared uncompressed size of the entries called `name` (local and
/// central headers).
fn declare_size(path: &Path, name: &str, size: u32) {
    let mut bytes = std::fs::read(path).unwrap();
    for i in 0..bytes.len() - 46 {
        let (at, name_at) = match &bytes[i..i + 4] {
            [0x50, 0x4b, 0x03, 0x04] => (22, 30),
            [0x50, 0x4b, 0x01, 0x02] => (24, 46),
            _ => continue,
        };
        if bytes[i + name_at..].starts_with(name.as_bytes()) {
            bytes[i + at..i + at + 4].copy_from_slice(&size.to_le_bytes());
        }
    }
    std::fs::write(path, bytes).unwrap();
}

/// A 4.7 KB archive declaring an unused 3 GiB entry: refused before anything is
/// written.
#[test]
fn an_ssp_with_a_3_gib_entry_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bomb.ssp");
    let text = ssd("resources/a.fmu", "");
    write_zip(
        &path,
        &[
            Entry::File("SystemStructure.ssd", text.as_bytes()),
            Entry::File("resources/a.fmu", b""),
            Entry::File("resources/unused.bin", &[7; 4096]),
        ],
    );
    declare_size(&path, "resources/unused.bin", 3 << 30);
    ssp_error(
        &path,
        &[
            &format!("SSP archive '{}'", shown(&path)),
            "entry 'resources/unused.bin'",
            "limit 1073741824",
        ],
    );
}

/// Two `SystemStructure.ssd` entries: refused, not the last one read.
#[test]
fn an_ssp_with_two_system_structures_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("twice.ssp");
    let (first, second) = (ssd("resources/a.fmu", ""), ssd("resources/b.fmu", ""));
    write_zip(
        &path,
        &[
            Entry::File("SystemStructure.ssd", first.as_bytes()),
            Entry::File("SystemStructure.ssX", second.as_bytes()),
        ],
    );
    // The zip writer refuses equal names: make them equal afterwards.
    let mut bytes = std::fs::read(&path).unwrap();
    let from = b"SystemStructure.ssX";
    for i in 0..bytes.len() - from.len() {
        if &bytes[i..i + from.len()] == from {
            bytes[i..i + from.len()].copy_from_slice(b"SystemStructure.ssd");
        }
    }
    std::fs::write(&path, bytes).unwrap();
    ssp_error(
        &path,
        &[
            &shown(&path),
            "entry 'SystemStructure.ssd'",
            "duplicate entry",
        ],
    );
}

/// A component whose source climbs out of the archive.
#[test]
fn an_ssp_component_outside_the_archive_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("outside.ssp");
    let source = "../../../../etc/passwd";
    let text = ssd(source, "");
    write_zip(
        &path,
        &[Entry::File("SystemStructure.ssd", text.as_bytes())],
    );
    ssp_error(
        &path,
        &[
            "SystemStructure.ssd:5:",
            &format!("source=\"{source}\" leaves the archive"),
            &shown(&path),
        ],
    );
}

/// An SSD nested 200 000 levels deep (1.4 MB), in an unpacked folder.
#[test]
fn a_deeply_nested_ssd_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let system = dir.path().join("system");
    std::fs::create_dir(&system).unwrap();
    let depth = 200_000;
    let text = ssd(
        "a.fmu",
        &format!("{}{}", "<x>".repeat(depth), "</x>".repeat(depth)),
    );
    std::fs::write(system.join("SystemStructure.ssd"), text).unwrap();
    std::fs::write(system.join("a.fmu"), b"").unwrap();
    ssp_error(
        &system,
        &[
            "SystemStructure.ssd:6:",
            "elements nested more than 256 deep",
        ],
    );
}

/// `entries` as `dir/name.ssp`, deflated.
fn ssp_of(dir: &Path, name: &str, entries: &[Entry<'_>]) -> PathBuf {
    let path = dir.join(name);
    write_zip(&path, entries);
    path
}

/// An SSD of 8 MiB (whitespace after the root) that deflates to about 8 KiB: refused by
/// the compression ratio before anything is written (the issue's 1.5 GB SSD in a 3.2 MB
/// archive, smaller).
#[test]
fn an_ssp_with_a_highly_compressible_system_structure_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = ssd("resources/a.fmu", "");
    text.push_str(&" ".repeat(8 << 20));
    let path = ssp_of(
        dir.path(),
        "ratio.ssp",
        &[
            Entry::File("SystemStructure.ssd", text.as_bytes()),
            Entry::File("resources/a.fmu", b""),
        ],
    );
    ssp_error(
        &path,
        &[
            &format!(
                "SSP archive '{}' exceeds the extraction limit at entry 'SystemStructure.ssd': declares {} bytes from",
                shown(&path),
                text.len()
            ),
            "a compression ratio over the limit of 100 (for entries over 1048576 bytes)",
        ],
    );
}

/// An unused entry of 8 MiB of zeros that declares 1000 bytes (so its ratio looks
/// harmless): the bytes inflated are counted, the extraction stops at the entry and
/// the folder is removed.
#[test]
fn an_ssp_entry_inflating_past_its_declared_size_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let text = ssd("resources/a.fmu", "");
    let zeros = vec![0; 8 << 20];
    let path = ssp_of(
        dir.path(),
        "liar.ssp",
        &[
            Entry::File("SystemStructure.ssd", text.as_bytes()),
            Entry::File("resources/a.fmu", b""),
            Entry::File("resources/zeros", &zeros),
        ],
    );
    declare_size(&path, "resources/zeros", 1000);
    ssp_error(
        &path,
        &[
            &format!("SSP archive '{}' has entry 'resources/zeros'", shown(&path)),
            "larger than its declared uncompressed size",
        ],
    );
}

/// One entry declaring 600 MiB, under the 1 GiB total: over the per-entry limit.
#[test]
fn an_ssp_entry_over_the_per_entry_limit_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let text = ssd("resources/a.fmu", "");
    let path = ssp_of(
        dir.path(),
        "big.ssp",
        &[
            Entry::File("SystemStructure.ssd", text.as_bytes()),
            Entry::File("resources/a.fmu", &[7; 4096]),
        ],
    );
    declare_size(&path, "resources/a.fmu", 600 << 20);
    ssp_error(
        &path,
        &[&format!(
            "SSP archive '{}' exceeds the extraction limit at entry 'resources/a.fmu': declares 629145600 bytes, limit 536870912 per entry",
            shown(&path)
        )],
    );
}

/// 100 001 empty entries: over the entry limit, named after the first one past it.
#[test]
fn an_ssp_with_more_entries_than_the_limit_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("many.ssp");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&path).unwrap());
    let stored =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    zip.start_file("SystemStructure.ssd", stored).unwrap();
    for i in 1..=100_000 {
        zip.start_file(format!("resources/{i}"), stored).unwrap();
    }
    zip.finish().unwrap();
    ssp_error(
        &path,
        &[&format!(
            "SSP archive '{}' exceeds the extraction limit at entry 'resources/100000': 100001 entries, limit 100000",
            shown(&path)
        )],
    );
}

/// A central directory header whose extra field runs past the directory: the zip
/// reader refuses the whole archive, the error names the entry.
#[test]
fn an_ssp_with_a_broken_central_directory_header_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let text = ssd("resources/a.fmu", "");
    let path = ssp_of(
        dir.path(),
        "directory.ssp",
        &[
            Entry::File("SystemStructure.ssd", text.as_bytes()),
            Entry::File("resources/a.fmu", b""),
        ],
    );
    let mut bytes = std::fs::read(&path).unwrap();
    let second = (0..bytes.len() - 4)
        .filter(|&i| bytes[i..i + 4] == [0x50, 0x4b, 0x01, 0x02])
        .nth(1)
        .unwrap();
    bytes[second + 30..second + 32].copy_from_slice(&60_000u16.to_le_bytes());
    std::fs::write(&path, bytes).unwrap();
    ssp_error(
        &path,
        &[&format!(
            "SSP archive '{}' has entry 'resources/a.fmu' that cannot be extracted: unreadable central directory header:",
            shown(&path)
        )],
    );
}

/// A parameter set (`.ssv`) in the archive nested 200 000 levels deep.
#[test]
fn a_deeply_nested_ssv_in_an_ssp_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let depth = 200_000;
    let text = ssd(
        "resources/a.fmu",
        r#"<ssd:ParameterBindings><ssd:ParameterBinding source="resources/p.ssv"/></ssd:ParameterBindings>"#,
    );
    let ssv = format!(
        "<?xml version=\"1.0\"?>\n<ssv:ParameterSet version=\"1.0\" name=\"p\" \
         xmlns:ssv=\"http://ssp-standard.org/SSP1/SystemStructureParameterValues\">\n{}{}</ssv:ParameterSet>",
        "<x>".repeat(depth),
        "</x>".repeat(depth)
    );
    // Stored: deflated, its ratio would be refused first.
    let path = dir.path().join("deep.ssp");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&path).unwrap());
    let stored =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, bytes) in [
        ("SystemStructure.ssd", text.as_bytes()),
        ("resources/a.fmu", b"".as_slice()),
        ("resources/p.ssv", ssv.as_bytes()),
    ] {
        zip.start_file(name, stored).unwrap();
        std::io::Write::write_all(&mut zip, bytes).unwrap();
    }
    zip.finish().unwrap();
    ssp_error(
        &path,
        &["p.ssv:3:", "elements nested more than 256 deep (the limit)"],
    );
}

/// A `tether-ssp-*` folder a killed run left (marked, its lock free) is swept by the
/// next extraction, whatever that run's outcome.
#[test]
fn a_leftover_ssp_folder_is_swept() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path().join("tmp");
    let leftover = tmp.join("tether-ssp-killed");
    std::fs::create_dir_all(leftover.join("resources")).unwrap();
    std::fs::write(leftover.join(".tether-lock"), b"").unwrap();
    std::fs::write(leftover.join("resources/a.fmu"), b"x").unwrap();
    // An archive that extracts, then fails: its source is missing.
    let text = ssd("resources/missing.fmu", "");
    let path = ssp_of(
        dir.path(),
        "missing.ssp",
        &[Entry::File("SystemStructure.ssd", text.as_bytes())],
    );
    ssp_error(&path, &["SystemStructure.ssd:5:", "resources/missing.fmu"]);
}

// ---------------------------------------------------------------- system files

#[test]
fn a_system_file_that_is_not_toml_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| swap(t, "stop = 0.1", "stop = = 0.1"));
    assert!(matches!(setup_err(&sys), MasterError::SystemFile { .. }));
    run_error(&sys, &[&shown(&sys), "line"]);
}

#[test]
fn a_system_file_with_an_unknown_key_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| {
        swap(t, "stop = 0.1", "stop = 0.1\nstpe = 1e-3")
    });
    assert!(matches!(setup_err(&sys), MasterError::SystemFile { .. }));
    run_error(&sys, &[&shown(&sys), "stpe"]);
}

/// Array blocks are bounded (docs/system-file.md, "Limits"): a `count` of 10⁸
/// instances, which would take gigabytes before any other check, and more
/// constraint blocks in all than the limit are each one error naming the
/// block, before anything is expanded; no results file is written.
#[test]
fn array_counts_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let instances = system(dir.path(), |t| {
        swap(
            t,
            "name = \"mass2\"\n",
            "name = \"mass2_{i}\"\ncount = 100000000\n",
        )
    });
    assert!(matches!(
        setup_err(&instances),
        MasterError::SystemFile { .. }
    ));
    run_error(
        &instances,
        &[
            &shown(&instances),
            "[[instance]] block 2 (count = 100000000): makes 100000001 [[instance]] blocks, above the limit of 10000",
        ],
    );
    let constraints = system(dir.path(), |t| {
        swap(
            t,
            "name = \"link\"\n",
            "name = \"link{i}\"\ncount = 100001\n",
        )
    });
    run_error(
        &constraints,
        &["[[constraint]] block 1 (count = 100001): makes 100001 [[constraint]] blocks, above the limit of 100000"],
    );
    assert!(!dir.path().join("system.csv").exists());
}

/// A placeholder nested 10⁵ deep (a 200 KB system file; the parser recurses once a
/// level) is one error line naming the file, the block's line, the block and the
/// limit, with the text cut short around the error: not a stack overflow.
#[test]
fn a_placeholder_nested_beyond_the_limit_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let deep = format!("\"{{{}1{}}}\"", "(".repeat(100_000), ")".repeat(100_000));
    let sys = system(dir.path(), |t| {
        swap(
            swap(t, "name = \"mass2\"\n", "name = \"mass2_{i}\"\ncount = 1\n"),
            "parameters = { m = 2.0",
            &format!("parameters = {{ x0 = {deep}, m = 2.0"),
        )
    });
    let line = run_error(
        &sys,
        &[
            &format!(
                "system file {}: line 22: [[instance]] block 2 (count = 1), i = 0: nested more \
                 than 64 deep (the limit) at 65",
                shown(&sys)
            ),
            "(200003 characters, » marks the column)",
        ],
    );
    assert!(line.len() < 600, "{line}");
}

/// TOML arrays and inline tables nested 10⁵ deep: the TOML reader's own limit, one
/// line naming the file, the line and the limit.
#[test]
fn toml_nested_beyond_the_limit_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let n = 100_000;
    for (deep, column) in [
        (format!("{}{}", "[".repeat(n), "]".repeat(n)), 88),
        (format!("{}1{}", "{ a = ".repeat(n), "}".repeat(n)), 488),
    ] {
        let sys = system(dir.path(), |t| {
            swap(t, "[experiment]", &format!("deep = {deep}\n[experiment]"))
        });
        let line = run_error(
            &sys,
            &[&format!(
                "system file {}: line 4, column {column}: arrays and inline tables nested \
                 more than 80 deep (the limit)",
                shown(&sys)
            )],
        );
        assert!(line.len() < 300, "{line}");
    }
}

/// A constraint expression of 10⁵ parentheses (a linear expression has none): one
/// line, the expression cut to 200 characters around the error, which » marks.
#[test]
fn a_deeply_parenthesised_constraint_is_one_short_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let n = 100_000;
    let deep = format!("{}mass2.x{} - mass1.x", "(".repeat(n), ")".repeat(n));
    let sys = system(dir.path(), |t| {
        swap(
            t,
            "position = \"mass2.x - mass1.x\"",
            &format!("position = \"{deep}\""),
        )
    });
    let line = run_error(
        &sys,
        &[
            "constraint 'link', position: cannot read expression '»(((",
            "(200017 characters, » marks the column): expected an instance name at column 1",
        ],
    );
    assert!(line.len() < 600, "{line}");
}

/// A `count` beyond TOML's 64-bit integers, or below zero: its block, its line
/// and the range.
#[test]
fn a_count_out_of_range_names_its_block_and_the_range() {
    let dir = tempfile::tempdir().unwrap();
    // The line of the number the TOML reader refuses, else the block's.
    for (count, line) in [("99999999999999999999", 24), ("-5", 22)] {
        let sys = system(dir.path(), |t| {
            swap(
                t,
                "name = \"mass2\"\n",
                &format!("name = \"mass2_{{i}}\"\ncount = {count}\n"),
            )
        });
        let line = run_error(
            &sys,
            &[&format!(
                "system file {}: line {line}: [[instance]] block 2 (count = {count}): count \
                 must be an integer from 0 to 10000",
                shown(&sys)
            )],
        );
        assert!(line.len() < 300, "{line}");
    }
}

/// 100 000 constraints between the same two masses are within the block limits, but
/// each couples every other: an interface Jacobian of 10¹⁰ entries. One error naming
/// the file, before the matrices are allocated (docs/system-file.md, "Limits").
#[test]
fn an_interface_system_over_the_entry_limit_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let dense = system(dir.path(), |t| {
        swap(
            t,
            "name = \"link\"\n",
            "name = \"link{i}\"\ncount = 100000\n",
        )
    });
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let out = tether_env(&["run", dense.to_str().unwrap()], dir.path(), Some(&tmp));
    cli_error(
        &out,
        &[&format!(
            "system file {}: its 100000 coupling unknowns make an interface Jacobian with more than 10000000 entries that can be non-zero, above the limit",
            shown(&dense)
        )],
    );
    assert_eq!(String::from_utf8_lossy(&out.stderr).lines().count(), 1);
    assert_eq!(std::fs::read_dir(&tmp).unwrap().count(), 0);
    assert!(!dir.path().join("system.csv").exists());
}

#[test]
fn a_system_file_naming_a_missing_fmu_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nowhere.fmu");
    let sys = system_with(dir.path(), Some(&missing), |t| t);
    assert!(matches!(fmi(&setup_err(&sys)), Error::Missing { .. }));
    run_error(&sys, &[&shown(&missing)]);
}

#[test]
fn a_duplicate_instance_name_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| {
        swap(t, "name = \"mass2\"", "name = \"mass1\"")
    });
    assert!(matches!(setup_err(&sys), MasterError::SystemFile { .. }));
    run_error(&sys, &["'mass1'", "twice"]);
}

#[test]
fn an_unknown_instance_in_a_constraint_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| {
        swap(t, "position = \"mass2.x", "position = \"mass3.x")
    });
    assert!(matches!(
        setup_err(&sys),
        MasterError::UnknownInstance { .. }
    ));
    run_error(&sys, &["'mass3'", "'link'"]);
}

#[test]
fn an_unknown_variable_in_a_constraint_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| {
        swap(t, "mass2.v - mass1.v", "mass2.v - mass1.vv")
    });
    assert!(matches!(setup_err(&sys), MasterError::UnknownVariable(_)));
    run_error(
        &sys,
        &["constraint 'link', velocity: instance 'mass1' (oscillator.fmu) has no variable 'vv'; did you mean 'v', 'v0'?"],
    );
}

#[test]
fn an_unknown_parameter_name_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| swap(t, "m = 2.0", "mass = 2.0"));
    assert!(matches!(setup_err(&sys), MasterError::UnknownVariable(_)));
    run_error(
        &sys,
        &["parameters: instance 'mass2' (oscillator.fmu) has no variable 'mass'; did you mean 'm'?"],
    );
}

#[test]
fn coupling_into_an_output_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| {
        swap(t, "mass1.F - mass2.F", "mass1.F - mass2.x")
    });
    assert!(matches!(setup_err(&sys), MasterError::WrongVariable { .. }));
    run_error(&sys, &["mass2.x", "output", "'drives'", "Real input"]);
}

#[test]
fn a_constraint_on_an_input_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| {
        swap(t, "mass2.x - mass1.x", "mass2.F - mass1.x")
    });
    assert!(matches!(setup_err(&sys), MasterError::WrongVariable { .. }));
    run_error(&sys, &["mass2.F", "input", "Real output"]);
}

#[test]
fn setting_an_output_as_a_parameter_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| {
        swap(t, "v0 = 100.0 }", "v0 = 100.0, x = 1.0 }")
    });
    assert!(matches!(setup_err(&sys), MasterError::StartValue { .. }));
    run_error(&sys, &["'mass1'", "x = 1", "output"]);
}

#[test]
fn a_nan_parameter_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| swap(t, "c = 1000.0", "c = nan"));
    assert!(matches!(setup_err(&sys), MasterError::StartValue { .. }));
    run_error(&sys, &["'mass1'", "c = NaN", "not a finite number"]);
}

#[test]
fn an_infinite_parameter_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| swap(t, "d = 10.0", "d = inf"));
    assert!(matches!(setup_err(&sys), MasterError::StartValue { .. }));
    run_error(&sys, &["'mass1'", "d = inf", "not a finite number"]);
}

#[test]
fn a_parameter_below_its_declared_min_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| swap(t, "c = 1000.0", "c = -1000.0"));
    assert!(matches!(setup_err(&sys), MasterError::StartValue { .. }));
    run_error(
        &sys,
        &["'mass1'", "c = -1000", "below the declared min = 0"],
    );
}

#[test]
fn a_negative_mass_the_fmu_refuses_is_one_error_line_naming_the_instance() {
    // m has no declared min; the oscillator itself refuses m <= 0 when it initializes.
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| swap(t, "m = 2.0", "m = -2.0"));
    let err = setup_err(&sys);
    assert!(
        matches!(
            fmi(&err),
            Error::Failed {
                function: "fmi2ExitInitializationMode",
                ..
            }
        ),
        "{err:?}"
    );
    run_error(
        &sys,
        &["fmi2ExitInitializationMode", "fmi2Error", "'mass2'"],
    );
}

// ---------------------------------------------------------------- units

/// The one error line of `tether run SYSTEM` (all of stderr), exit code 1.
fn only_line(system: &Path) -> String {
    let dir = system.parent().unwrap();
    let out = tether(&["run", system.to_str().unwrap(), "--quiet"], dir);
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert_eq!(text.lines().count(), 1, "one line: {text}");
    text.trim_end().to_string()
}

/// The oscillator's model description with its output `x` in millimetres.
fn in_millimetres(xml: &str) -> String {
    let (head, tail) = xml.split_at(xml.find(r#"<ScalarVariable name="x""#).unwrap());
    format!(
        "{head}{}",
        tail.replacen(r#"<Real unit="m"/>"#, r#"<Real unit="mm"/>"#, 1)
    )
}

/// Units the FMUs declare are checked in constraints before the first step: the
/// terms of a level, the levels against each other, the drives.
#[test]
fn constraint_terms_in_units_that_do_not_fit_are_one_line_before_the_first_step() {
    let dir = tempfile::tempdir().unwrap();
    // Metres minus metres per second (the mistake that used to fail at t = 0 with
    // advice about the numerical method).
    let sys = system_with(dir.path(), None, |t| {
        swap(
            t,
            "position = \"mass2.x - mass1.x\"",
            "position = \"mass2.x - mass1.v\"",
        )
    });
    assert!(matches!(setup_err(&sys), MasterError::Units { .. }));
    assert_eq!(
        only_line(&sys),
        "error: constraint 'link', position: mass2.x is in 'm' and mass1.v in 'm/s': the \
         terms of a level need one unit (a coefficient converts)"
    );
    // A velocity level in metres.
    let sys = system_with(dir.path(), None, |t| {
        swap(
            t,
            "velocity = \"mass2.v - mass1.v\"",
            "velocity = \"mass2.x - mass1.x\"",
        )
    });
    assert_eq!(
        only_line(&sys),
        "error: constraint 'link', velocity: mass2.x is in 'm'; the velocity level needs the \
         position level's unit per second (mass2.x is in 'm')"
    );
    // An acceleration level in m/s, after no velocity level (index 3 needs none).
    let sys = system_with(dir.path(), None, |t| {
        let t = swap(t, "velocity = \"mass2.v - mass1.v\"\n", "");
        let t = swap(t, "beta = 2e-3\ngamma = 1e-6", "index = 3");
        swap(
            t,
            "acceleration = \"mass2.a - mass1.a\"",
            "acceleration = \"mass2.v - mass1.v\"",
        )
    });
    assert_eq!(
        only_line(&sys),
        "error: constraint 'link', acceleration: mass2.v is in 'm/s'; the acceleration level \
         needs the position level's unit per second squared (mass2.x is in 'm')"
    );
    // der(x) is in m/s: a velocity level of derivatives fits.
    let sys = system_with(dir.path(), None, |t| {
        swap(
            t,
            "velocity = \"mass2.v - mass1.v\"",
            "velocity = \"der(mass2.x) - der(mass1.x)\"",
        )
    });
    let out = tether(&["run", sys.to_str().unwrap(), "--quiet"], dir.path());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Millimetres against metres: a coefficient converts.
    let mm = edited_oscillator(dir.path(), "mm", in_millimetres);
    let sys = system_with(dir.path(), Some(&mm), |t| t);
    let line = only_line(&sys);
    assert_eq!(
        line,
        "error: constraint 'link', position: mass2.x is in 'mm' and mass1.x in 'm': the \
         terms of a level need one unit (a coefficient converts)"
    );
    let sys = system_with(dir.path(), Some(&mm), |t| {
        swap(
            t,
            "position = \"mass2.x - mass1.x\"",
            "position = \"0.001*mass2.x - mass1.x\"",
        )
    });
    assert!(!matches!(
        SystemSpec::from_file(&sys).and_then(|spec| Simulation::new(&spec).map(drop)),
        Err(MasterError::Units { .. })
    ));
    // A multiplier that would drive a position input.
    let kinematic = edited_oscillator(dir.path(), "fm", |xml| {
        xml.replace(r#"unit="N"/>"#, r#"unit="m"/>"#)
    });
    let sys = system_with(dir.path(), Some(&kinematic), |t| t);
    assert_eq!(
        only_line(&sys),
        "error: constraint 'link', drives: mass2.F is in 'm': the multiplier drives force or \
         torque inputs, not positions, velocities or accelerations"
    );
}

/// A connection between different units says how `gain` and `offset` convert,
/// with the numbers where the units are one quantity.
#[test]
fn a_connection_unit_error_says_how_gain_and_offset_convert() {
    let dir = tempfile::tempdir().unwrap();
    let mm = edited_oscillator(dir.path(), "mm", in_millimetres);
    let ctrl = tether_fmu_build::workspace_fmu("controller").unwrap();
    let write = |extra: &str| {
        let path = dir.path().join("signals.toml");
        std::fs::write(
            &path,
            format!(
                "[experiment]\nstop = 0.01\nstep = 1e-3\n\n[method]\nkind = \"explicit\"\nmu = 1e-3\n\n\
                 [[instance]]\nname = \"mass1\"\nfmu = {mm:?}\n\n[[instance]]\nname = \"ctrl\"\n\
                 fmu = {ctrl:?}\n\n[[connection]]\nfrom = \"mass1.x\"\nto = \"ctrl.y\"\n{extra}"
            ),
        )
        .unwrap();
        path
    };
    assert_eq!(
        only_line(&write("")),
        "error: connection mass1.x → ctrl.y: mass1.x is in 'mm' and ctrl.y in 'm': units \
         differ; gain = 0.001 on the connection converts (to = gain·from + offset)"
    );
    let out = tether(
        &["run", write("gain = 0.001\n").to_str().unwrap(), "--quiet"],
        dir.path(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Another quantity: how, without numbers.
    let sys = write("");
    let text = std::fs::read_to_string(&sys)
        .unwrap()
        .replace("from = \"mass1.x\"", "from = \"mass1.v\"");
    std::fs::write(&sys, text).unwrap();
    assert_eq!(
        only_line(&sys),
        "error: connection mass1.v → ctrl.y: mass1.v is in 'm/s' and ctrl.y in 'm': units \
         differ; set gain (and offset) on the connection to convert (to = gain·from + offset)"
    );
}

// ---------------------------------------------------------------- method parameters

fn invalid_parameter(edit: impl Fn(String) -> String, name: &str, fragments: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), edit);
    match setup_err(&sys) {
        MasterError::InvalidParameter { name: n, .. } => assert_eq!(n, name),
        other => panic!("{other:?}"),
    }
    let mut all = vec![name];
    all.extend_from_slice(fragments);
    run_error(&sys, &all);
}

#[test]
fn a_negative_beta_is_one_error_line() {
    invalid_parameter(
        |t| swap(t, "beta = 2e-3", "beta = -2e-3"),
        "beta",
        &["-0.002"],
    );
}

#[test]
fn a_polynomial_degree_above_two_is_one_error_line() {
    invalid_parameter(
        |t| swap(t, "order = 0", "order = 3"),
        "order",
        &["0, 1 or 2"],
    );
}

#[test]
fn a_zero_macro_step_is_one_error_line() {
    invalid_parameter(|t| swap(t, "step = 1e-3", "step = 0.0"), "step", &["> 0"]);
}

#[test]
fn a_nan_macro_step_is_one_error_line() {
    invalid_parameter(|t| swap(t, "step = 1e-3", "step = nan"), "step", &["NaN"]);
}

#[test]
fn a_stop_time_before_the_start_is_one_error_line() {
    invalid_parameter(|t| swap(t, "stop = 0.1", "stop = -0.1"), "stop", &["-0.1"]);
}

#[test]
fn a_finite_difference_increment_of_zero_is_one_error_line() {
    invalid_parameter(
        |t| swap(t, "order = 0", "order = 0\nepsilon = 0.0"),
        "epsilon",
        &["(0, 1)"],
    );
}

#[test]
fn an_infinite_initial_multiplier_is_one_error_line() {
    invalid_parameter(
        |t| {
            swap(
                t,
                "drives = \"mass1.F - mass2.F\"",
                "drives = \"mass1.F - mass2.F\"\ninitial = -inf",
            )
        },
        "link.initial",
        &["-inf"],
    );
}

// ---------------------------------------------------------------- capabilities

#[test]
fn rollback_without_can_get_and_set_fmu_state_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = edited_oscillator(dir.path(), "nostate", |xml| {
        xml.replace(
            r#"canGetAndSetFMUstate="true""#,
            r#"canGetAndSetFMUstate="false""#,
        )
    });
    let sys = system_with(dir.path(), Some(&fmu), co_simulation);
    match setup_err(&sys) {
        MasterError::MissingCapability { capability, .. } => {
            assert_eq!(capability, "canGetAndSetFMUstate")
        }
        other => panic!("{other:?}"),
    }
    run_error(&sys, &["'mass2'", "canGetAndSetFMUstate", "baumgarte"]);
}

/// Each capability the method needs and the oscillator's co-simulation
/// interface is edited to lack: with `fmi_type = "auto"` mass 2 runs model
/// exchange instead, and a note names the instance and the capability.
#[test]
fn auto_runs_model_exchange_where_co_simulation_lacks_a_capability() {
    let dir = tempfile::tempdir().unwrap();
    for (flag, extra, needed_by) in [
        (
            "canGetAndSetFMUstate",
            "",
            "the predictor/corrector method baumgarte",
        ),
        (
            "canHandleVariableCommunicationStepSize",
            "--step-rtol",
            "adaptive steps ([step_control])",
        ),
        (
            "canInterpolateInputs",
            "--order",
            "coupling polynomials of degree k > 0",
        ),
    ] {
        // The flag of the CoSimulation element only.
        let fmu = edited_oscillator(dir.path(), flag, |xml| {
            xml.lines()
                .map(|line| match line.contains("<CoSimulation") {
                    true => {
                        line.replace(&format!(r#"{flag}="true""#), &format!(r#"{flag}="false""#))
                    }
                    false => line.to_string(),
                })
                .collect::<Vec<_>>()
                .join("\n")
        });
        let sys = system_with(dir.path(), Some(&fmu), |t| t);
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", "out.csv"];
        match extra {
            "--step-rtol" => args.extend(["--step-rtol", "1e-4"]),
            "--order" => args.extend(["--order", "1"]),
            _ => {}
        }
        let out = tether(&args, dir.path());
        let text = String::from_utf8_lossy(&out.stderr).replace("\n  ", " ");
        assert_eq!(out.status.code(), Some(0), "{flag}: {text}");
        let capability = if flag == "canInterpolateInputs" {
            "inputs that take polynomials"
        } else {
            flag
        };
        let note = format!(
            "note: 'mass2' runs model exchange (fmi_type = \"auto\"): its co-simulation interface lacks {capability}, which {needed_by} needs"
        );
        assert!(text.contains(&note), "{flag}: {text}");
        assert!(
            !text.contains("'mass1' runs model exchange"),
            "{flag}: {text}"
        );
    }
}

#[test]
fn adaptive_steps_without_variable_step_sizes_are_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = edited_oscillator(dir.path(), "fixedstep", |xml| {
        xml.replace(
            r#"canHandleVariableCommunicationStepSize="true""#,
            r#"canHandleVariableCommunicationStepSize="false""#,
        )
    });
    let sys = system_with(dir.path(), Some(&fmu), co_simulation);
    // Fixed steps run; adaptive ones are refused naming the instance.
    let out = tether(&["run", sys.to_str().unwrap(), "--quiet"], dir.path());
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    let sys = sys.to_str().unwrap();
    let out = tether(&["run", sys, "--step-rtol", "1e-4"], dir.path());
    cli_error(
        &out,
        &[
            "'mass2'",
            "canHandleVariableCommunicationStepSize",
            "adaptive",
        ],
    );
    let nostate = edited_oscillator(dir.path(), "nostate", |xml| {
        xml.replace(
            r#"canGetAndSetFMUstate="true""#,
            r#"canGetAndSetFMUstate="false""#,
        )
    });
    let sys = system_with(dir.path(), Some(&nostate), |t| {
        co_simulation(swap(
            t,
            "[coupling]",
            "[step_control]\nrtol = 1e-4\n\n[coupling]",
        ))
    });
    run_error(&sys, &["'mass2'", "canGetAndSetFMUstate"]);
    // The explicit method has no error estimate.
    let sys = system_with(dir.path(), None, |t| t);
    let out = tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--method",
            "explicit",
            "--mu",
            "1e-2",
            "--step-atol",
            "1e-6",
        ],
        dir.path(),
    );
    cli_error(&out, &["step_control", "explicit"]);
}

#[test]
fn input_polynomials_without_can_interpolate_inputs_are_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = edited_oscillator(dir.path(), "nointerp", |xml| {
        xml.replace(
            r#"canInterpolateInputs="true""#,
            r#"canInterpolateInputs="false""#,
        )
    });
    let sys = system_with(dir.path(), Some(&fmu), |t| {
        co_simulation(swap(t, "order = 0", "order = 1"))
    });
    match setup_err(&sys) {
        MasterError::NoPolynomialInput { reason, .. } => {
            assert_eq!(reason, "the FMU does not declare canInterpolateInputs")
        }
        other => panic!("{other:?}"),
    }
    // The sentence `tether info` prints for the FMU, after the instance.
    run_error(
        &sys,
        &[
            "instance 'mass2' (oscillator): k > 0 needs inputs that take polynomials; \
             the FMU does not declare canInterpolateInputs; use order = 0",
        ],
    );
    // `tether info` says the FMU takes them through model exchange.
    let out = tether(&["info", fmu.to_str().unwrap()], dir.path());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(
            "coupling polynomials k > 0                 yes, through model exchange (fmi_type = \"auto\")\n"
        ),
        "{text}"
    );
}

#[test]
fn two_instances_of_a_once_per_process_fmu_are_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let caps = Capabilities {
        only_once_per_process: true,
        ..Capabilities::default()
    };
    let fmu = faulty_fmu(dir.path(), "once", caps);
    let sys = system_with(dir.path(), Some(&fmu), |t| {
        swap(t, "fmu = \"", &format!("fmu = \"{}\"\n#", fmu.display()))
    });
    match fmi(&setup_err(&sys)) {
        Error::OnlyOncePerProcess {
            instance, existing, ..
        } => assert_eq!((instance.as_str(), existing.as_str()), ("mass2", "mass1")),
        other => panic!("{other:?}"),
    }
    run_error(
        &sys,
        &[
            "'faulty'",
            "canBeInstantiatedOnlyOncePerProcess",
            "'mass2'",
            "'mass1'",
        ],
    );
    // One instance is fine, and the slot is free again once it is dropped.
    let one = Fmu::open(&fmu).unwrap();
    drop(one.instantiate("first", Default::default()).unwrap());
    drop(one.instantiate("again", Default::default()).unwrap());
}

// ---------------------------------------------------------------- failures mid-run

#[test]
fn a_singular_interface_jacobian_ends_the_run_with_the_rows_kept() {
    let dir = tempfile::tempdir().unwrap();
    // g = x2 − x2 does not depend on the multiplier.
    let sys = system(dir.path(), |t| {
        let t = swap(t, "mass2.x - mass1.x", "mass2.x - mass2.x");
        swap(t, "beta = 2e-3\ngamma = 1e-6", "")
    });
    let (err, _) = run_err(&sys);
    assert!(
        matches!(err, MasterError::SingularJacobian { .. }),
        "{err:?}"
    );
    let csv = failed_run(
        &sys,
        &[
            "singular interface Jacobian",
            "t = 0.001 (macro step H = 1e-3)",
        ],
    );
    assert!(csv.trailer.starts_with("# incomplete: singular"));
}

/// A faulty oscillator as mass 2 that fails as told (`fail_in`: 0 doStep, 1 setFMUstate).
fn faulty_system(dir: &Path, fail_status: i32, fail_in: i32) -> PathBuf {
    let fmu = faulty_fmu(dir, "faulty", Capabilities::default());
    system_with(dir, Some(&fmu), |t| {
        swap(
            t,
            "m = 2.0, c = 1000.0, d = 10.0, v0 = 100.0",
            &format!(
                "m = 2.0, c = 1000.0, d = 10.0, v0 = 100.0, fail_time = 0.0505, fail_status = {fail_status}, fail_in = {fail_in}"
            ),
        )
    })
}

/// What a failed CLI run left in its CSV.
struct Csv {
    rows: Vec<Vec<f64>>,
    trailer: String,
}

/// Runs `tether run` with its own TMPDIR; checks the exit, the one-line error, that the
/// CSV holds complete rows up to the time the error reports and ends with the error as
/// trailer, and that no extraction directory remains.
fn failed_run(system: &Path, fragments: &[&str]) -> Csv {
    let dir = system.parent().unwrap();
    let tmp = dir.join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let csv_path = dir.join("out.csv");
    let out = tether_env(
        &[
            "run",
            system.to_str().unwrap(),
            "--out",
            csv_path.to_str().unwrap(),
        ],
        dir,
        Some(&tmp),
    );
    let line = cli_error(&out, fragments);
    check_results(&csv_path, &line, &tmp)
}

/// Checks a failed run's CSV against the CLI's error line and that `tmp` is empty.
fn check_results(csv_path: &Path, line: &str, tmp: &Path) -> Csv {
    let leftovers: Vec<_> = std::fs::read_dir(tmp).unwrap().collect();
    assert!(leftovers.is_empty(), "left in TMPDIR: {leftovers:?}");
    let text = std::fs::read_to_string(csv_path).unwrap();
    assert!(text.ends_with('\n'), "flushed to the last byte");
    let mut lines = text.lines();
    let width = lines.next().unwrap().split(',').count();
    let mut rows = Vec::new();
    let mut trailer = String::new();
    for l in lines {
        assert!(trailer.is_empty(), "a line after the trailer: {l}");
        if l.starts_with('#') {
            trailer = l.to_string();
        } else {
            let row: Vec<f64> = l.split(',').map(|v| v.parse().unwrap()).collect();
            assert_eq!(row.len(), width, "complete row {l}");
            rows.push(row);
        }
    }
    assert!(trailer.starts_with("# incomplete: "), "{text}");
    // The CLI line is "error: run stopped; results up to t = T kept in … : <reason>".
    let reason = &trailer["# incomplete: ".len()..];
    assert!(line.ends_with(reason), "{line:?} vs trailer {reason:?}");
    // The time as messages print it: as the grid gives it.
    let t = line
        .split("results up to t = ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .unwrap_or_else(|| panic!("no time in {line:?}"));
    assert_eq!(
        tether_master::Time(rows.last().unwrap()[0]).to_string(),
        t,
        "last row is the last accepted step"
    );
    Csv { rows, trailer }
}

#[test]
fn discard_from_do_step_mid_run_ends_the_run_with_the_rows_kept() {
    let dir = tempfile::tempdir().unwrap();
    let sys = faulty_system(dir.path(), 2, 0);
    let (err, rec) = run_err(&sys);
    assert!(
        matches!(
            fmi(&err),
            Error::Discard {
                function: "fmi2DoStep",
                ..
            }
        ),
        "{err:?}"
    );
    assert_eq!(rec.times.last(), Some(&0.05));
    let csv = failed_run(
        &sys,
        &["fmi2DoStep returned fmi2Discard", "'mass2'", "t=0.05"],
    );
    assert_eq!(csv.rows.len(), 51, "t = 0 … 0.05");
}

#[test]
fn error_from_do_step_mid_run_ends_the_run_with_the_rows_kept() {
    let dir = tempfile::tempdir().unwrap();
    let sys = faulty_system(dir.path(), 3, 0);
    let (err, _) = run_err(&sys);
    assert!(
        matches!(
            fmi(&err),
            Error::Failed {
                function: "fmi2DoStep",
                ..
            }
        ),
        "{err:?}"
    );
    let csv = failed_run(
        &sys,
        &["fmi2DoStep returned fmi2Error", "'mass2'", "t=0.05"],
    );
    assert_eq!(csv.rows.len(), 51);
}

#[test]
fn fatal_from_do_step_mid_run_ends_the_run_with_the_rows_kept() {
    let dir = tempfile::tempdir().unwrap();
    let sys = faulty_system(dir.path(), 4, 0);
    let (err, _) = run_err(&sys);
    assert!(
        matches!(
            fmi(&err),
            Error::Fatal {
                function: "fmi2DoStep",
                ..
            }
        ),
        "{err:?}"
    );
    let csv = failed_run(
        &sys,
        &["fmi2DoStep returned fmi2Fatal", "'mass2'", "t=0.05"],
    );
    assert_eq!(csv.rows.len(), 51);
    assert!(csv.trailer.contains("fmi2Fatal"));
}

#[test]
fn a_failing_set_fmu_state_mid_run_ends_the_run_with_the_rows_kept() {
    let dir = tempfile::tempdir().unwrap();
    let sys = faulty_system(dir.path(), 3, 1);
    let (err, _) = run_err(&sys);
    assert!(
        matches!(
            fmi(&err),
            Error::Failed {
                function: "fmi2SetFMUstate",
                ..
            }
        ),
        "{err:?}"
    );
    failed_run(&sys, &["fmi2SetFMUstate returned fmi2Error", "'mass2'"]);
}

#[test]
fn a_fatal_set_fmu_state_mid_run_ends_the_run_with_the_rows_kept() {
    let dir = tempfile::tempdir().unwrap();
    let sys = faulty_system(dir.path(), 4, 1);
    let (err, _) = run_err(&sys);
    assert!(
        matches!(
            fmi(&err),
            Error::Fatal {
                function: "fmi2SetFMUstate",
                ..
            }
        ),
        "{err:?}"
    );
    failed_run(&sys, &["fmi2SetFMUstate returned fmi2Fatal", "'mass2'"]);
}

#[test]
fn the_faulty_oscillator_runs_cleanly_when_told_not_to_fail() {
    // The same FMU and system with the failure after the stop time: the run completes,
    // so the failures above come from the injected status and nothing else.
    let dir = tempfile::tempdir().unwrap();
    let sys = faulty_system(dir.path(), 3, 0);
    let text = std::fs::read_to_string(&sys).unwrap();
    std::fs::write(&sys, text.replace("fail_time = 0.0505", "fail_time = 10.0")).unwrap();
    let csv = dir.path().join("ok.csv");
    let out = tether(
        &["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()],
        dir.path(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().count(), 102);
    assert!(!text.contains('#'));
}

// ---------------------------------------------------------------- Ctrl-C

/// Kills and reaps the child if the test fails before waiting for it (the run
/// below would otherwise go on for hours).
struct Reaper(Option<std::process::Child>);

impl Drop for Reaper {
    fn drop(&mut self) {
        if let Some(child) = &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

#[test]
fn sigint_stops_the_run_keeps_the_results_and_removes_the_extractions() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| swap(t, "stop = 0.1", "stop = 1e4"));
    let tmp = dir.path().join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let csv = dir.path().join("long.csv");
    let mut child = Reaper(Some(
        Command::new(env!("CARGO_BIN_EXE_tether"))
            .args(["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()])
            .current_dir(dir.path())
            .env("TMPDIR", &tmp)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("spawn tether"),
    ));
    // Wait until results are being written (the FMUs are extracted by then).
    let started = std::time::Instant::now();
    while std::fs::metadata(&csv).map(|m| m.len()).unwrap_or(0) == 0 {
        assert!(started.elapsed().as_secs() < 120, "no results after 120 s");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    assert_eq!(
        std::fs::read_dir(&tmp).unwrap().count(),
        1,
        "one extraction, shared by the two instances of the FMU"
    );
    let status = Command::new("kill")
        .args(["-INT", &child.0.as_ref().expect("running").id().to_string()])
        .status()
        .expect("run kill");
    assert!(status.success());
    let out = child
        .0
        .take()
        .expect("running")
        .wait_with_output()
        .expect("wait for tether");
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(130), "{text}");
    assert!(!text.contains("panicked"), "{text}");
    let line = text.lines().last().unwrap().to_string();
    assert!(
        line.starts_with("error: ") && line.contains("interrupted (Ctrl-C or termination signal)"),
        "{line}"
    );
    let csv = check_results(&csv, &line, &tmp);
    assert!(csv.trailer.starts_with("# incomplete: interrupted"));
    assert!(csv.rows.len() > 1);
}

// ---------------------------------------------------------------- joints

/// The double pendulum example, edited, in `dir` with the FMU path made absolute.
fn pendulum(dir: &Path, edit: impl Fn(String) -> String) -> PathBuf {
    let fmu = tether_fmu_build::workspace_fmu("link").expect("package the link FMU");
    let root = tether_fmu_build::workspace_root().expect("workspace root");
    let text = std::fs::read_to_string(root.join("examples/double_pendulum.toml")).unwrap();
    let text = text.replace("../target/fmus/link.fmu", &fmu.display().to_string());
    let path = dir.join("pendulum.toml");
    std::fs::write(&path, edit(text)).unwrap();
    path
}

#[test]
fn a_joint_naming_an_unknown_marker_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = pendulum(dir.path(), |t| {
        swap(t, "i = \"link1.B\"", "i = \"link1.tip\"")
    });
    assert!(matches!(setup_err(&sys), MasterError::UnknownMarker { .. }));
    run_error(&sys, &["joint 'hinge'", "'link1'", "'tip'", "A, B"]);
}

#[test]
fn a_joint_of_an_unknown_kind_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = pendulum(dir.path(), |t| {
        swap(t, "kind = \"atpoint\"", "kind = \"hinge\"")
    });
    assert!(matches!(setup_err(&sys), MasterError::Joint { .. }));
    run_error(&sys, &["joint 'hinge'", "unknown kind 'hinge'", "revolute"]);
}

#[test]
fn a_spatial_joint_on_a_planar_marker_without_the_port_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let sys = pendulum(dir.path(), |t| swap(t, "plane = \"xy\"", ""));
    assert!(matches!(setup_err(&sys), MasterError::MissingPort { .. }));
    run_error(&sys, &["joint 'hinge'", "'B.F[3]'", "'link1'"]);
}

// ---------------------------------------------------------------- results file

/// A results file that cannot be written (a full disk: `/dev/full`, Linux) stops
/// `tether run` and `tether simulate` with one line naming the file and the cause
/// once, whether the writer thread fails at the end (10 steps) or in the middle
/// (20 000 steps, many blocks of rows).
#[test]
fn a_full_disk_for_the_results_is_one_error_line_and_an_incomplete_summary() {
    if !Path::new("/dev/full").exists() {
        eprintln!("no /dev/full here: skipped");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), |t| t);
    let (system, fmu) = (sys.to_str().unwrap(), oscillator_fmu());
    let fmu = fmu.to_str().unwrap();
    for stop in ["0.01", "20"] {
        for args in [
            vec!["run", system, "--stop", stop, "-q"],
            vec!["simulate", fmu, "--stop", stop, "--step", "1e-3"],
        ] {
            let out = tether(&[&args[..], &["--out", "/dev/full"]].concat(), dir.path());
            let line = cli_error(&out, &["cannot write /dev/full", "No space left on device"]);
            assert_eq!(line.matches("No space left").count(), 1, "{line}");
            assert!(!line.contains("kept"), "claims results were kept: {line}");
        }
        // The summary says so too, also when the rows fit in the buffer and
        // only the end of the file fails (stop = 0.01).
        let summary = dir.path().join("summary.json");
        let args = ["run", system, "--stop", stop, "-q", "--out", "/dev/full"];
        let out = tether(
            &[&args[..], &["--summary-json", summary.to_str().unwrap()]].concat(),
            dir.path(),
        );
        cli_error(&out, &["cannot write /dev/full"]);
        let json = std::fs::read_to_string(&summary).unwrap();
        assert!(json.contains("\"completed\": false"), "{json}");
        assert!(json.contains("No space left on device"), "{json}");
    }
}
