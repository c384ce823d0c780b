//! Hostile and broken SSP input: archives over the extraction budget, duplicate
//! entries, unreadable entries, sources outside the archive, deeply nested XML.
//! Each is refused by `tether_ssp::read` with one line naming the file or entry.
//! The archives are built here; no test writes more than a few megabytes.

use std::io::Write;
use std::path::{Path, PathBuf};

use tether_fmi::xml::MAX_DEPTH;
use tether_ssp::SspError;

/// A system with one component whose `source` is `source`; `extra` goes into the
/// root system (parameter bindings, say).
fn ssd(source: &str, extra: &str) -> String {
    format!(
        r#"<?xml version="1.0"?>
<ssd:SystemStructureDescription version="1.0" name="t"
    xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon">
  <ssd:System name="s">
    <ssd:Elements>
      <ssd:Component name="a" source="{source}"/>
    </ssd:Elements>
    {extra}
  </ssd:System>
  <ssd:DefaultExperiment stopTime="1"/>
</ssd:SystemStructureDescription>"#
    )
}

/// Writes a zip of `(name, bytes)` entries, deflated.
fn zip_of(path: &Path, entries: &[(&str, &[u8])]) {
    let mut zip = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for (name, bytes) in entries {
        zip.start_file(*name, options).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap();
}

/// Sets the declared uncompressed size of every entry called `name` (local and
/// central headers) to `size`.
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

fn read_err(path: &Path) -> String {
    match tether_ssp::read(path, Some(0.1), None) {
        Ok(_) => panic!("{} was accepted", path.display()),
        Err(e) => {
            let text = e.to_string();
            assert!(!text.contains('\n'), "{text}");
            text
        }
    }
}

/// `dir/name.ssp` holding `entries`.
fn ssp(dir: &Path, name: &str, entries: &[(&str, &[u8])]) -> PathBuf {
    let path = dir.join(name);
    zip_of(&path, entries);
    path
}

#[test]
fn an_ssp_with_a_3_gib_entry_is_refused_by_its_declared_size() {
    let dir = tempfile::tempdir().unwrap();
    let text = ssd("resources/a.fmu", "");
    let path = ssp(
        dir.path(),
        "bomb.ssp",
        &[
            ("SystemStructure.ssd", text.as_bytes()),
            ("resources/a.fmu", b""),
            ("resources/unused.bin", &[7; 4096]),
        ],
    );
    declare_size(&path, "resources/unused.bin", 3 << 30);
    let err = read_err(&path);
    assert_eq!(
        err,
        format!(
            "SSP archive '{}' exceeds the extraction limit at entry 'resources/unused.bin': \
             declared uncompressed size reaches {} bytes, limit 1073741824",
            path.display(),
            (3u64 << 30) + text.len() as u64
        )
    );
}

#[test]
fn an_ssp_entry_over_the_per_entry_limit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let text = ssd("resources/a.fmu", "");
    let path = ssp(
        dir.path(),
        "big.ssp",
        &[
            ("SystemStructure.ssd", text.as_bytes()),
            ("resources/a.fmu", &[7; 4096]),
        ],
    );
    declare_size(&path, "resources/a.fmu", 600 << 20);
    let err = read_err(&path);
    assert!(
        err.ends_with(
            "at entry 'resources/a.fmu': declares 629145600 bytes, limit 536870912 per entry"
        ),
        "{err}"
    );
}

#[test]
fn a_highly_compressible_ssd_is_refused_by_the_compression_ratio() {
    // A 3 MiB SystemStructure.ssd (whitespace after the root) deflates to a few KiB.
    let dir = tempfile::tempdir().unwrap();
    let mut text = ssd("resources/a.fmu", "");
    text.push_str(&" ".repeat(3 << 20));
    let path = ssp(
        dir.path(),
        "ratio.ssp",
        &[
            ("SystemStructure.ssd", text.as_bytes()),
            ("resources/a.fmu", b""),
        ],
    );
    let err = read_err(&path);
    assert!(
        err.starts_with(&format!(
            "SSP archive '{}' exceeds the extraction limit at entry 'SystemStructure.ssd': declares {} bytes from",
            path.display(),
            text.len()
        )),
        "{err}"
    );
    assert!(
        err.ends_with("a compression ratio over the limit of 100 (for entries over 1048576 bytes)"),
        "{err}"
    );
}

#[test]
fn an_ssp_with_more_entries_than_the_limit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("many.ssp");
    let mut zip = zip::ZipWriter::new(std::fs::File::create(&path).unwrap());
    let stored =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for i in 0..=100_000 {
        zip.start_file(format!("{i}"), stored).unwrap();
    }
    zip.finish().unwrap();
    let err = read_err(&path);
    assert_eq!(
        err,
        format!(
            "SSP archive '{}' exceeds the extraction limit at entry '100000': 100001 entries, limit 100000",
            path.display()
        )
    );
}

#[test]
fn an_ssp_with_two_system_structures_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let first = ssd("resources/a.fmu", "");
    let second = ssd("resources/b.fmu", "");
    let path = ssp(
        dir.path(),
        "twice.ssp",
        &[
            ("SystemStructure.ssd", first.as_bytes()),
            ("SystemStructure.ssX", second.as_bytes()),
            ("resources/a.fmu", b""),
        ],
    );
    // The zip writer refuses equal names: make the second one equal afterwards.
    let bytes = std::fs::read(&path).unwrap();
    let (from, to) = (b"SystemStructure.ssX", b"SystemStructure.ssd");
    let mut patched = bytes.clone();
    for i in 0..bytes.len() - from.len() {
        if &bytes[i..i + from.len()] == from {
            patched[i..i + from.len()].copy_from_slice(to);
        }
    }
    std::fs::write(&path, patched).unwrap();
    let err = read_err(&path);
    assert_eq!(
        err,
        format!(
            "SSP archive '{}' has entry 'SystemStructure.ssd' that cannot be extracted: \
             duplicate entry (the archive has two entries of this name)",
            path.display()
        )
    );
    // The same path under two names.
    let path = ssp(
        dir.path(),
        "dot.ssp",
        &[
            ("SystemStructure.ssd", first.as_bytes()),
            ("./SystemStructure.ssd", second.as_bytes()),
        ],
    );
    let err = read_err(&path);
    assert!(
        err.ends_with(
            "entry './SystemStructure.ssd' that cannot be extracted: duplicate entry \
             (the same path as entry 'SystemStructure.ssd')"
        ),
        "{err}"
    );
}

#[test]
fn zip_errors_of_an_ssp_name_the_entry() {
    let dir = tempfile::tempdir().unwrap();
    let text = ssd("resources/a.fmu", "");
    let path = ssp(
        dir.path(),
        "corrupt.ssp",
        &[
            ("SystemStructure.ssd", text.as_bytes()),
            ("resources/a.fmu", &[7; 4096]),
        ],
    );
    // Damage the deflated data of resources/a.fmu: its CRC no longer matches.
    let mut bytes = std::fs::read(&path).unwrap();
    let at = bytes
        .windows(15)
        .position(|w| w == b"resources/a.fmu")
        .unwrap();
    bytes[at + 15 + 2] ^= 0xff;
    std::fs::write(&path, bytes).unwrap();
    let err = read_err(&path);
    assert!(
        err.starts_with(&format!(
            "SSP archive '{}' has entry 'resources/a.fmu' that cannot be extracted: corrupt data:",
            path.display()
        )),
        "{err}"
    );
    // A zip entry that escapes, and a file that is no zip at all.
    let path = ssp(
        dir.path(),
        "slip.ssp",
        &[
            ("SystemStructure.ssd", text.as_bytes()),
            ("../../tether-ssp-slip", b"x"),
        ],
    );
    assert_eq!(
        read_err(&path),
        format!(
            "SSP archive '{}' has entry '../../tether-ssp-slip' that escapes the extraction directory",
            path.display()
        )
    );
    let path = dir.path().join("plain.ssp");
    std::fs::write(&path, "not a zip").unwrap();
    assert!(
        read_err(&path).starts_with(&format!("'{}' is not an SSP archive", path.display())),
        "{}",
        read_err(&path)
    );
}

#[test]
fn a_source_outside_the_archive_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    for (source, why) in [
        ("../../../etc/passwd", "leaves the archive"),
        ("resources/../../x.fmu", "leaves the archive"),
        ("/etc/passwd", "is an absolute path"),
        ("file:///etc/passwd", "is an absolute path"),
    ] {
        let text = ssd(source, "");
        let path = ssp(
            dir.path(),
            "outside.ssp",
            &[("SystemStructure.ssd", text.as_bytes())],
        );
        assert_eq!(
            read_err(&path),
            format!(
                "SystemStructure.ssd:7: source=\"{source}\" {why}: a source in the .ssp archive \
                 '{}' must be a relative path to a file in it",
                path.display()
            )
        );
    }
    // A parameter set's source too.
    let binding = r#"<ssd:ParameterBindings>
      <ssd:ParameterBinding source="../values.ssv"/>
    </ssd:ParameterBindings>"#;
    let text = ssd("a.fmu", binding);
    let path = ssp(
        dir.path(),
        "ssv.ssp",
        &[("SystemStructure.ssd", text.as_bytes()), ("a.fmu", b"")],
    );
    let err = read_err(&path);
    assert!(
        err.starts_with("SystemStructure.ssd:10: source=\"../values.ssv\" leaves the archive"),
        "{err}"
    );
}

#[test]
fn an_ssd_on_disk_may_name_files_outside_its_folder() {
    // The user names the SSD: its paths are the user's, as in a system file.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("a.fmu"), b"").unwrap();
    let system = dir.path().join("system");
    std::fs::create_dir(&system).unwrap();
    std::fs::write(system.join("SystemStructure.ssd"), ssd("../a.fmu", "")).unwrap();
    let loaded = tether_ssp::read(&system, Some(0.1), None).unwrap();
    assert_eq!(loaded.spec.instances[0].fmu, system.join("../a.fmu"));
    let absolute = dir.path().join("a.fmu");
    std::fs::write(
        system.join("SystemStructure.ssd"),
        ssd(&absolute.display().to_string(), ""),
    )
    .unwrap();
    let loaded = tether_ssp::read(&system.join("SystemStructure.ssd"), Some(0.1), None).unwrap();
    assert_eq!(loaded.spec.instances[0].fmu, absolute);
}

#[test]
fn an_ssp_is_extracted_to_a_private_folder_removed_with_the_system() {
    let dir = tempfile::tempdir().unwrap();
    let text = ssd("resources/a.fmu", "");
    let path = ssp(
        dir.path(),
        "ok.ssp",
        &[
            ("SystemStructure.ssd", text.as_bytes()),
            ("resources/a.fmu", b""),
        ],
    );
    let loaded = tether_ssp::read(&path, Some(0.1), None).unwrap();
    let folder = loaded.ssd.parent().unwrap().to_path_buf();
    let name = folder.file_name().unwrap().to_string_lossy().into_owned();
    assert!(name.starts_with("tether-ssp-"), "{name}");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&folder).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o700, "{mode:o}");
    }
    // Marked for the sweep of a later process, should this one be killed.
    assert!(folder.join(".tether-lock").is_file());
    assert_eq!(loaded.spec.instances[0].fmu, folder.join("resources/a.fmu"));
    drop(loaded);
    assert!(!folder.exists());
}

/// `depth` nested `<x>` elements inside the root system, on one line.
fn nested(depth: usize) -> String {
    format!("{}{}", "<x>".repeat(depth), "</x>".repeat(depth))
}

#[test]
fn a_deeply_nested_ssd_is_one_error() {
    // 200 000 levels (1.4 MB): refused at the first element past the limit.
    let dir = tempfile::tempdir().unwrap();
    let text = ssd("a.fmu", &nested(200_000));
    std::fs::write(dir.path().join("SystemStructure.ssd"), &text).unwrap();
    std::fs::write(dir.path().join("a.fmu"), b"").unwrap();
    let err = read_err(dir.path());
    // The root and ssd:System are the first two levels.
    let column = 5 + 3 * (MAX_DEPTH - 2);
    assert_eq!(
        err,
        format!("SystemStructure.ssd:9:{column}: elements nested more than 256 deep (the limit)")
    );
    // The same in an archive (10 000 levels: 200 000 deflate past the compression
    // ratio limit, which refuses the archive before its SSD is read).
    let text = ssd("a.fmu", &nested(10_000));
    let path = ssp(
        dir.path(),
        "deep.ssp",
        &[("SystemStructure.ssd", text.as_bytes()), ("a.fmu", b"")],
    );
    assert_eq!(read_err(&path), err);
}

#[test]
fn a_deeply_nested_ssv_is_one_error() {
    let dir = tempfile::tempdir().unwrap();
    let binding = r#"<ssd:ParameterBindings>
      <ssd:ParameterBinding source="values.ssv"/>
    </ssd:ParameterBindings>"#;
    std::fs::write(
        dir.path().join("SystemStructure.ssd"),
        ssd("a.fmu", binding),
    )
    .unwrap();
    std::fs::write(dir.path().join("a.fmu"), b"").unwrap();
    std::fs::write(dir.path().join("values.ssv"), nested(200_000)).unwrap();
    let err = read_err(dir.path());
    assert_eq!(
        err,
        format!(
            "values.ssv:1:{}: elements nested more than 256 deep (the limit)",
            1 + 3 * MAX_DEPTH
        )
    );
}

#[test]
fn an_ssd_over_the_size_limit_is_refused_unread() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("SystemStructure.ssd");
    // A sparse file: nothing is written.
    let file = std::fs::File::create(&path).unwrap();
    file.set_len(tether_fmi::xml::MAX_BYTES as u64 + 1).unwrap();
    let err = read_err(&path);
    assert_eq!(
        err,
        format!(
            "{}: more than 134217728 bytes, the limit for XML files",
            path.display()
        )
    );
    assert!(matches!(
        tether_ssp::read(&path, Some(0.1), None),
        Err(SspError::File { .. })
    ));
}
