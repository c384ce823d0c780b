//! Broken, hostile and unsupported FMUs are refused with the exact error variant and a
//! one-line message naming the culprit. Each FMU is built here, in a temporary directory.

use std::path::{Path, PathBuf};

use tether_fmi::{Error, ExtractLimits, Fmu, OpenOptions};
use tether_tests::fmi::{
    assert_one_line_naming, compile_shared_library, model_description, oscillator_fmu,
    stub_fmu_dir_with, write_zip, zip_directory, Entry,
};

fn open_err(path: &Path) -> Error {
    match Fmu::open(path) {
        Ok(_) => panic!("{} was accepted", path.display()),
        Err(e) => e,
    }
}

fn cs_description() -> String {
    model_description("2.0", "stub", true, false)
}

fn shown(path: &Path) -> String {
    path.display().to_string()
}

#[test]
fn a_file_that_is_not_a_zip_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("plain.fmu");
    std::fs::write(&path, "this is not a zip archive").unwrap();
    let err = open_err(&path);
    assert!(matches!(err, Error::NotAnArchive { .. }), "{err:?}");
    assert_one_line_naming(&err, &[&shown(&path), "not an FMU archive"]);
}

#[test]
fn an_empty_file_is_refused_as_not_a_zip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.fmu");
    std::fs::write(&path, b"").unwrap();
    let err = open_err(&path);
    assert!(matches!(err, Error::NotAnArchive { .. }), "{err:?}");
    assert_one_line_naming(&err, &[&shown(&path), "not an FMU archive"]);
}

#[test]
fn a_truncated_zip_is_refused_as_not_a_zip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("truncated.fmu");
    let bytes = std::fs::read(oscillator_fmu()).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let err = open_err(&path);
    assert!(matches!(err, Error::NotAnArchive { .. }), "{err:?}");
    assert_one_line_naming(&err, &[&shown(&path), "not an FMU archive"]);
}

#[test]
fn a_missing_path_is_an_io_error_naming_it() {
    let path = PathBuf::from("/nonexistent/tether/none.fmu");
    let err = open_err(&path);
    assert!(matches!(err, Error::Missing { .. }), "{err:?}");
    assert_one_line_naming(&err, &["/nonexistent/tether/none.fmu"]);
}

#[test]
fn a_zip_without_model_description_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.fmu");
    write_zip(
        &path,
        &[Entry::File("documentation/index.html", b"<html/>")],
    );
    let err = open_err(&path);
    assert!(
        matches!(err, Error::MissingModelDescription { .. }),
        "{err:?}"
    );
    assert_one_line_naming(&err, &[&shown(&path), "modelDescription.xml"]);
}

#[test]
fn an_entry_escaping_the_extraction_directory_is_refused_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let pid = std::process::id();
    // A leading `..`, and one that first enters a directory and then climbs out of it.
    for (file, name, landed) in [
        (
            "escape.fmu",
            format!("../tether-evil-{pid}"),
            format!("tether-evil-{pid}"),
        ),
        (
            "slip.fmu",
            format!("resources/../../tether-slip-{pid}"),
            format!("tether-slip-{pid}"),
        ),
    ] {
        let path = dir.path().join(file);
        write_zip(
            &path,
            &[
                Entry::File("modelDescription.xml", cs_description().as_bytes()),
                Entry::File(&name, b"owned"),
            ],
        );
        let err = open_err(&path);
        match &err {
            Error::EntryEscapes { entry, .. } => assert_eq!(entry, &name),
            other => panic!("{other:?}"),
        }
        assert_one_line_naming(&err, &[&shown(&path), &name, "escapes"]);
        let landed = std::env::temp_dir().join(landed);
        assert!(!landed.exists(), "{} was written", landed.display());
    }
}

#[test]
fn an_absolute_entry_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("absolute.fmu");
    write_zip(&path, &[Entry::File("/tmp/tether-absolute", b"x")]);
    let err = open_err(&path);
    assert!(matches!(err, Error::AbsoluteEntry { .. }), "{err:?}");
    assert_one_line_naming(&err, &[&shown(&path), "/tmp/tether-absolute", "absolute"]);
}

#[test]
fn a_symlink_entry_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("link.fmu");
    write_zip(
        &path,
        &[
            Entry::File("modelDescription.xml", cs_description().as_bytes()),
            Entry::Dir("resources/"),
            Entry::Symlink("resources/passwd", "/etc/passwd"),
        ],
    );
    let err = open_err(&path);
    match &err {
        Error::SymlinkEntry { entry, .. } => assert_eq!(entry, "resources/passwd"),
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(&err, &[&shown(&path), "resources/passwd", "symbolic link"]);
}

#[test]
fn a_decompression_bomb_is_refused_by_the_declared_size() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bomb.fmu");
    let zeros = vec![0u8; 4 << 20];
    write_zip(
        &path,
        &[
            Entry::File("modelDescription.xml", cs_description().as_bytes()),
            Entry::File("resources/zeros.bin", &zeros),
        ],
    );
    assert!(
        std::fs::metadata(&path).unwrap().len() < 64 << 10,
        "compresses well"
    );
    let options = OpenOptions {
        limits: ExtractLimits {
            max_total_bytes: 1 << 20,
            ..ExtractLimits::default()
        },
    };
    let err = Fmu::open_with(&path, &options).unwrap_err();
    match &err {
        Error::ArchiveTooLarge { entry, .. } => assert_eq!(entry, "resources/zeros.bin"),
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(&err, &[&shown(&path), "resources/zeros.bin", "1048576"]);
}

#[test]
fn a_declared_size_above_the_default_limit_is_refused_before_extraction() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bomb.fmu");
    write_zip(&path, &[Entry::File("resources/bomb.bin", &[0u8; 4096])]);
    // Declares 3.75 GiB, over the default 1 GiB budget: refused before any byte lands.
    declare_sizes(&path, 0xF000_0000, Headers::Central);
    let err = open_err(&path);
    match &err {
        Error::ArchiveTooLarge { entry, .. } => assert_eq!(entry, "resources/bomb.bin"),
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(
        &err,
        &[
            &shown(&path),
            "resources/bomb.bin",
            "4026531840",
            "1073741824",
        ],
    );
}

/// Which zip headers [`declare_sizes`] rewrites.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Headers {
    /// The central directory only (what the extraction budget reads first).
    Central,
    /// Every local and central header.
    All,
}

/// Overwrites the uncompressed-size fields of the chosen headers with `size`.
fn declare_sizes(path: &Path, size: u32, headers: Headers) {
    let mut bytes = std::fs::read(path).unwrap();
    let mut i = 0;
    while i + 4 <= bytes.len() {
        let offset = match &bytes[i..i + 4] {
            [0x50, 0x4b, 0x03, 0x04] if headers == Headers::All => Some(22),
            [0x50, 0x4b, 0x01, 0x02] => Some(24),
            _ => None,
        };
        if let Some(o) = offset {
            bytes[i + o..i + o + 4].copy_from_slice(&size.to_le_bytes());
        }
        i += 1;
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn an_entry_inflating_past_its_declared_size_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("liar.fmu");
    let zeros = vec![0u8; 1 << 20];
    write_zip(&path, &[Entry::File("resources/zeros.bin", &zeros)]);
    declare_sizes(&path, 100, Headers::All);
    let err = open_err(&path);
    // The zip reader notices the overrun first; Tether's own byte count (ArchiveTooLarge)
    // is the second line of defence.
    assert!(matches!(err, Error::UnsupportedEntry { .. }), "{err:?}");
    assert_one_line_naming(&err, &[&shown(&path), "resources/zeros.bin", "declared"]);
}

/// `dir/notelf.fmu`, whose "shared library" is a shell script.
fn not_elf_fmu(dir: &Path) -> PathBuf {
    let path = dir.join("notelf.fmu");
    write_zip(
        &path,
        &[
            Entry::File("modelDescription.xml", cs_description().as_bytes()),
            Entry::File("binaries/linux64/stub.so", b"#!/bin/sh\necho not ELF\n"),
        ],
    );
    path
}

#[test]
fn a_binary_that_is_not_a_shared_library_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let err = open_err(&not_elf_fmu(dir.path()));
    match &err {
        Error::LibraryLoad { path: so, .. } => {
            assert!(so.ends_with("binaries/linux64/stub.so"), "{}", so.display())
        }
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(&err, &["cannot load FMU library", "stub.so"]);
}

/// The loader's own reason is in the message (libloading's error text alone
/// is "dlopen failed"); an FMU that needs the Python runtime (pythonfmu) gets
/// the hint to preload libpython.
#[test]
fn a_library_that_cannot_load_says_why_and_a_python_fmu_gets_a_hint() {
    let dir = tempfile::tempdir().unwrap();
    let err = open_err(&not_elf_fmu(dir.path())).to_string();
    assert!(
        err.ends_with("stub.so: file too short"),
        "the loader's reason: {err}"
    );
    let (root, _log) = stub_fmu_dir_with(dir.path(), &["-DSTUB_NEEDS_PYTHON".into()]);
    let err = open_err(&root);
    let so = root.join("binaries/linux64/stub.so");
    assert_eq!(
        err.to_string(),
        format!(
            "cannot load FMU library '{so}': dlopen failed: {so}: undefined symbol: _Py_NoneStruct \
             (the FMU needs the Python runtime, as FMUs exported by pythonfmu do: preload \
             libpython, e.g. LD_PRELOAD=$(python3 -c \"import sysconfig, os; \
             print(os.path.join(sysconfig.get_config_var('LIBDIR'), \
             sysconfig.get_config_var('LDLIBRARY')))\"))",
            so = so.display()
        )
    );
}

#[test]
fn a_library_lacking_fmi2_functions_is_refused_naming_the_first_missing_symbol() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("partial");
    let binaries = root.join("binaries/linux64");
    std::fs::create_dir_all(&binaries).unwrap();
    std::fs::write(root.join("modelDescription.xml"), cs_description()).unwrap();
    let source = r#"
        const char *fmi2GetTypesPlatform(void) { return "default"; }
        const char *fmi2GetVersion(void) { return "2.0"; }
    "#;
    let so = compile_shared_library(&binaries, "stub", source, &[]);
    let archive = dir.path().join("partial.fmu");
    zip_directory(&root, &archive);
    for path in [&root, &archive] {
        let err = open_err(path);
        match &err {
            Error::MissingSymbol { symbol, library } => {
                assert_eq!(*symbol, "fmi2SetDebugLogging");
                assert!(library.ends_with("binaries/linux64/stub.so"));
            }
            other => panic!("{other:?}"),
        }
        assert_one_line_naming(&err, &["fmi2SetDebugLogging", "stub.so"]);
    }
    let err = open_err(&root);
    assert_one_line_naming(&err, &[&shown(&so)]);
}

#[test]
fn a_library_reporting_another_fmi_version_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (root, _log) = stub_fmu_dir_with(dir.path(), &["-DSTUB_VERSION=\"3.0\"".into()]);
    let err = open_err(&root);
    match &err {
        Error::IncompatibleLibrary {
            function, found, ..
        } => {
            assert_eq!((*function, found.as_str()), ("fmi2GetVersion", "3.0"))
        }
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(&err, &["fmi2GetVersion", "3.0", "stub.so"]);
}

fn zip_with_description(dir: &Path, name: &str, xml: &str) -> PathBuf {
    let path = dir.join(name);
    write_zip(
        &path,
        &[Entry::File("modelDescription.xml", xml.as_bytes())],
    );
    path
}

#[test]
fn an_fmi3_fmu_without_its_binary_is_refused_naming_the_x86_64_linux_path() {
    let dir = tempfile::tempdir().unwrap();
    let xml = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="3.0" modelName="m" instantiationToken="{x}">
  <CoSimulation modelIdentifier="m"/>
  <ModelVariables><Float64 name="x" valueReference="0"/></ModelVariables>
  <ModelStructure/>
</fmiModelDescription>"#;
    let path = zip_with_description(dir.path(), "three.fmu", xml);
    let err = open_err(&path);
    match &err {
        Error::MissingBinary { expected, .. } => {
            assert!(expected.ends_with("binaries/x86_64-linux/m.so"), "{err}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn an_fmi4_fmu_is_refused_by_version() {
    let dir = tempfile::tempdir().unwrap();
    let xml = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="4.0" modelName="m" instantiationToken="{x}">
  <CoSimulation modelIdentifier="m"/>
</fmiModelDescription>"#;
    let path = zip_with_description(dir.path(), "four.fmu", xml);
    let err = open_err(&path);
    match &err {
        Error::UnsupportedFmiVersion { version, .. } => assert_eq!(version, "4.0"),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        err.to_string(),
        format!(
            "'{}' is an FMI 4.0 FMU; Tether supports FMI 2.0 and 3.0 (co-simulation and model exchange)",
            path.display()
        )
    );
}

#[test]
fn an_fmi1_fmu_is_refused_by_version() {
    let dir = tempfile::tempdir().unwrap();
    let xml = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="1.0" modelName="m" modelIdentifier="m" guid="{x}" numberOfContinuousStates="0" numberOfEventIndicators="0">
  <ModelVariables/>
  <Implementation><CoSimulation_StandAlone><Capabilities/></CoSimulation_StandAlone></Implementation>
</fmiModelDescription>"#;
    let path = zip_with_description(dir.path(), "one.fmu", xml);
    let err = open_err(&path);
    match &err {
        Error::UnsupportedFmiVersion { version, .. } => assert_eq!(version, "1.0"),
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(
        &err,
        &[
            &shown(&path),
            "FMI 1.0",
            "FMI 2.0 and 3.0 (co-simulation and model exchange)",
        ],
    );
}

/// A model-exchange-only FMU is read (its description is valid): without a
/// binary it is refused for the missing library, named after the
/// model-exchange model identifier.
#[test]
fn a_model_exchange_only_fmu_is_read_and_needs_its_binary() {
    let dir = tempfile::tempdir().unwrap();
    let xml = model_description("2.0", "stub", false, true);
    let path = zip_with_description(dir.path(), "me.fmu", &xml);
    let err = open_err(&path);
    match &err {
        Error::MissingBinary { expected, .. } => {
            assert_eq!(expected, &path.join("binaries/linux64/stub.so"))
        }
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(&err, &["binaries/linux64/stub.so", "'stub'"]);
}

#[test]
fn a_missing_linux64_binary_names_the_expected_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = zip_with_description(dir.path(), "nobinary.fmu", &cs_description());
    let err = open_err(&path);
    match &err {
        Error::MissingBinary { expected, .. } => {
            assert_eq!(expected, &path.join("binaries/linux64/stub.so"))
        }
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(&err, &["linux64", "binaries/linux64/stub.so", "'stub'"]);
}

#[test]
fn malformed_xml_is_reported_with_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let xml = cs_description().replace("</ModelVariables>", "</ModelVariable>");
    let line = xml
        .lines()
        .position(|l| l.contains("</ModelVariable>"))
        .unwrap()
        + 1;
    let path = zip_with_description(dir.path(), "malformed.fmu", &xml);
    let err = open_err(&path);
    match &err {
        Error::MalformedXml { line: l, file, .. } => {
            assert_eq!(*l, line);
            assert_eq!(file, &path.join("modelDescription.xml"));
        }
        other => panic!("{other:?}"),
    }
    assert_one_line_naming(
        &err,
        &[
            &shown(&path),
            "modelDescription.xml",
            &format!("line {line}"),
        ],
    );
}

#[test]
fn a_schema_violation_is_reported_with_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let xml = cs_description().replace(r#"name="t" valueReference="1""#, r#"name="t""#);
    let path = zip_with_description(dir.path(), "novr.fmu", &xml);
    let err = open_err(&path);
    assert!(
        matches!(err, Error::InvalidModelDescription { line: 7, .. }),
        "{err:?}"
    );
    assert_one_line_naming(
        &err,
        &["modelDescription.xml", "line 7", "'t'", "valueReference"],
    );
}

#[test]
fn binary_garbage_as_model_description_is_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("garbage.fmu");
    let garbage: Vec<u8> = (0..512u32).map(|i| (i * 97 % 251) as u8).collect();
    write_zip(&path, &[Entry::File("modelDescription.xml", &garbage)]);
    let err = open_err(&path);
    assert!(
        matches!(
            err,
            Error::MalformedXml { .. } | Error::InvalidModelDescription { .. }
        ),
        "{err:?}"
    );
    assert_one_line_naming(&err, &[&shown(&path), "modelDescription.xml"]);
}

#[test]
fn an_unknown_variable_name_suggests_close_matches() {
    let fmu = Fmu::open(oscillator_fmu()).expect("open oscillator");
    let err = fmu.model_description().variable("xx").unwrap_err();
    match &err {
        Error::UnknownVariable {
            name, suggestions, ..
        } => {
            assert_eq!(name, "xx");
            assert_eq!(suggestions.first().map(String::as_str), Some("x"));
        }
        other => panic!("{other:?}"),
    }
    assert!(
        err.to_string()
            .starts_with("no variable 'xx' in model 'oscillator'; did you mean 'x'"),
        "{err}"
    );
    let err = fmu.model_description().variable("tolerence").unwrap_err();
    assert_one_line_naming(&err, &["'tolerence'", "did you mean 'tolerance'?"]);
}
