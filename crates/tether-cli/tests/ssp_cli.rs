//! `tether run` of SSP (an archive, a folder, a SystemStructure.ssd) and
//! `tether ssp export` / `import` through the binary: the same CSV bit for
//! bit as the system file; other tools' annotations listed with -v; a
//! missing step one clear line and exit code 1.

use std::path::Path;
use std::process::{Command, Output};

fn tether(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tether")
}

fn ok(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn ssp_runs_like_its_system_file_and_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let osc = tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let ctrl = tether_fmu_build::workspace_fmu("controller").unwrap();
    let example =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/controlled_oscillator.toml");
    let text = std::fs::read_to_string(example)
        .unwrap()
        .replace("../target/fmus/oscillator.fmu", &osc.display().to_string())
        .replace("../target/fmus/controller.fmu", &ctrl.display().to_string())
        .replace("stop = 1.0", "stop = 0.1");
    std::fs::write(d.join("system.toml"), text).unwrap();
    ok(&tether(
        &["run", "system.toml", "-q", "--out", "toml.csv"],
        d,
    ));
    ok(&tether(
        &["ssp", "export", "system.toml", "-o", "system.ssp"],
        d,
    ));
    ok(&tether(&["run", "system.ssp", "-q", "--out", "ssp.csv"], d));
    ok(&tether(
        &["ssp", "import", "system.ssp", "-o", "imported/system.toml"],
        d,
    ));
    ok(&tether(
        &["run", "imported/system.toml", "-q", "--out", "imported.csv"],
        d,
    ));
    // The unpacked folder and its SystemStructure.ssd.
    let unpacked = d.join("unpacked");
    zip::ZipArchive::new(std::fs::File::open(d.join("system.ssp")).unwrap())
        .unwrap()
        .extract(&unpacked)
        .unwrap();
    ok(&tether(&["run", "unpacked", "-q", "--out", "dir.csv"], d));
    ok(&tether(
        &[
            "run",
            "unpacked/SystemStructure.ssd",
            "-q",
            "--out",
            "ssd.csv",
        ],
        d,
    ));
    let reference = std::fs::read(d.join("toml.csv")).unwrap();
    for csv in ["ssp.csv", "imported.csv", "dir.csv", "ssd.csv"] {
        assert!(
            std::fs::read(d.join(csv)).unwrap() == reference,
            "{csv} differs"
        );
    }
}

#[test]
fn foreign_annotations_are_listed_with_v_and_a_missing_step_is_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fixture =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/ssp/controlled_mass");
    std::fs::create_dir(d.join("resources")).unwrap();
    for f in ["SystemStructure.ssd", "resources/mass.ssv"] {
        std::fs::copy(fixture.join(f), d.join(f)).unwrap();
    }
    for name in ["oscillator", "controller"] {
        let fmu = tether_fmu_build::workspace_fmu(name).unwrap();
        std::fs::copy(fmu, d.join(format!("resources/{name}.fmu"))).unwrap();
    }
    let out = tether(
        &["-v", "run", ".", "--step", "1e-3", "-q", "--out", "out.csv"],
        d,
    );
    ok(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr
            .contains("skipped another tool's annotation com.example.layout (SystemStructure.ssd:"),
        "{stderr}"
    );
    let out = tether(&["run", ".", "--out", "out.csv"], d);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("error: SystemStructure.ssd: no macro-step size"),
        "{stderr}"
    );
}

/// A connector the FMU does not have is named with the file it appears in.
#[test]
fn an_unknown_connector_names_the_ssd_and_the_connection() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fixture =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/ssp/controlled_mass");
    std::fs::create_dir(d.join("resources")).unwrap();
    let ssd = std::fs::read_to_string(fixture.join("SystemStructure.ssd"))
        .unwrap()
        .replace(
            r#"<ssd:Connector name="x" kind="output">"#,
            r#"<ssd:Connector name="xx" kind="output">"#,
        )
        .replace(r#"startConnector="x""#, r#"startConnector="xx""#);
    std::fs::write(d.join("SystemStructure.ssd"), ssd).unwrap();
    std::fs::copy(
        fixture.join("resources/mass.ssv"),
        d.join("resources/mass.ssv"),
    )
    .unwrap();
    for name in ["oscillator", "controller"] {
        let fmu = tether_fmu_build::workspace_fmu(name).unwrap();
        std::fs::copy(fmu, d.join(format!("resources/{name}.fmu"))).unwrap();
    }
    let out = tether(&["run", ".", "--step", "1e-3", "--out", "out.csv"], d);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("error: ./SystemStructure.ssd: connection ")
            && stderr.contains(
                "instance 'mass' (oscillator.fmu) has no variable 'xx'; did you mean 'x'"
            ),
        "{stderr}"
    );
}
