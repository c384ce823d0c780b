//! The workspace FMUs built as FMI 3.0 (`<name>-fmi3.fmu`, the same model through the
//! kit's fmi3 C layer) in `tether run`: every example gives, with the FMI 3.0 builds,
//! the CSV of the FMI 2.0 builds bit for bit at k = 0. The master does the same
//! arithmetic through either instance type; the FMUs the same through either layer.

mod common;

use std::path::{Path, PathBuf};

use common::{success, tether};
use tether_fmu_build::FmiVersion;

fn root() -> PathBuf {
    tether_fmu_build::workspace_root().unwrap()
}

/// `text` with every `"../target/fmus/NAME.fmu"` replaced by the absolute path of
/// NAME's build in `version`, and the exported pair by `pair`.
fn with_fmus(text: &str, version: FmiVersion, pair: &Path) -> String {
    let mut out = text.replace("\"../target/rigid_pair.fmu\"", &format!("{pair:?}"));
    for name in tether_fmu_build::workspace_fmu_names().unwrap() {
        let from = format!("\"../target/fmus/{name}.fmu\"");
        if out.contains(&from) {
            let fmu = tether_fmu_build::workspace_fmu_as(&name, version).unwrap();
            out = out.replace(&from, &format!("{fmu:?}"));
        }
    }
    assert!(
        !out.contains("\"../"),
        "a relative path is left in the system:\n{out}"
    );
    out
}

fn run(system: &Path, csv: &Path, dir: &Path) -> Vec<u8> {
    let args = [
        "run",
        system.to_str().unwrap(),
        "--order",
        "0",
        "--quiet",
        "--out",
        csv.to_str().unwrap(),
    ];
    success(&tether(&args, dir));
    std::fs::read(csv).unwrap()
}

#[test]
fn every_example_with_the_fmi3_builds_gives_the_fmi2_csv_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let pair = dir.path().join("rigid_pair.fmu");
    tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let export = [
        "fmu",
        "export",
        "examples/rigid_pair_export.toml",
        "--out",
        pair.to_str().unwrap(),
    ];
    success(&tether(&export, &root()));
    let mut examples: Vec<PathBuf> = std::fs::read_dir(root().join("examples"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    examples.sort();
    assert!(examples.len() >= 10, "{examples:?}");
    for example in &examples {
        let name = example.file_stem().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(example).unwrap();
        let mut csv = Vec::new();
        for version in [FmiVersion::Fmi2, FmiVersion::Fmi3] {
            let system = dir.path().join(format!("{name}-{version:?}.toml"));
            std::fs::write(&system, with_fmus(&text, version, &pair)).unwrap();
            let out = dir.path().join(format!("{name}-{version:?}.csv"));
            csv.push(run(&system, &out, dir.path()));
        }
        assert!(csv[0].len() > 1000, "{name}: a short CSV");
        assert!(
            csv[0] == csv[1],
            "{name}: the FMI 3.0 builds give another CSV than the FMI 2.0 builds"
        );
    }
}
