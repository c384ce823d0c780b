//! libcosim (the Open Simulation Platform's master, through libcosimpy)
//! against Tether on SSP: a signal-only system — the workspace's oscillator
//! under PI control, no constraint — exported by Tether, and the hand-written
//! SSD of tests/fixtures, each run by both with the same Jacobi algorithm and
//! step (inputs held over a step). The results agree to
//! |a − b| ≤ 1e-12·max(1, |b|) at every step.
//!
//! Needs `libcosimpy` in the test Python: `.ci/run` installs it into
//! `TETHER_PYTHON`, and without `TETHER_PYTHON` it is installed into the
//! tests' own virtualenv. Where it cannot be installed or imported, the
//! tests fail on CI (`CI` set) and elsewhere are skipped saying why.

use std::path::Path;
use std::process::Command;

use tether_master::SystemSpec;
use tether_tests::fmpy::workspace_root;

fn fmu(name: &str) -> std::path::PathBuf {
    tether_fmu_build::workspace_fmu(name).expect("package the workspace FMU")
}

/// Run `ssp_dir` in libcosim; the rows of `columns` after every step.
/// `step` is libcosim's, or with `from_ssp` the one the SSD's OSP
/// annotation must give.
fn libcosim(
    python: &Path,
    ssp_dir: &Path,
    (step, from_ssp): (f64, bool),
    stop: f64,
    columns: &[&str],
) -> Vec<Vec<f64>> {
    let out = ssp_dir.join("libcosim.csv");
    let script = workspace_root().join("tests/libcosim/run_ssp.py");
    let mut cmd = Command::new(python);
    cmd.arg(script)
        .arg(ssp_dir)
        .arg(if from_ssp {
            format!("ssp:{step}")
        } else {
            step.to_string()
        })
        .arg(stop.to_string())
        .arg(&out)
        .args(columns);
    let output = cmd.output().expect("run python");
    assert!(
        output.status.success(),
        "libcosim failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let text = std::fs::read_to_string(out).unwrap();
    text.lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect()
}

fn tether(spec: &SystemSpec, columns: &[&str]) -> Vec<Vec<f64>> {
    tether_tests::tools::tether_rows(spec, columns)
}

fn compare(ours: &[Vec<f64>], theirs: &[Vec<f64>]) -> f64 {
    assert_eq!(ours.len(), theirs.len(), "number of steps");
    let mut worst: f64 = 0.0;
    for (a, b) in ours.iter().zip(theirs) {
        assert!((a[0] - b[0]).abs() < 1e-9, "time {} vs {}", a[0], b[0]);
        for (x, y) in a[1..].iter().zip(&b[1..]) {
            let rel = (x - y).abs() / y.abs().max(1.0);
            assert!(rel <= 1e-12, "t = {}: Tether {x}, libcosim {y}", a[0]);
            worst = worst.max(rel);
        }
    }
    worst
}

const COLUMNS: [&str; 3] = ["mass.x", "mass.v", "ctrl.u"];

fn signal_only_system() -> SystemSpec {
    let text = format!(
        r#"
        name = "controlled_mass"
        [experiment]
        stop = 0.5
        step = 1e-3

        [[instance]]
        name = "mass"
        fmu = "{osc}"
        parameters = {{ m = 2.0, c = 800.0, d = 5.0, v0 = 0.0, exact = true }}

        [[instance]]
        name = "ctrl"
        fmu = "{ctrl}"
        parameters = {{ kp = 500.0, ki = 2000.0 }}

        [[connection]]
        from = "mass.x"
        to = "ctrl.y"

        [[connection]]
        from = "ctrl.u"
        to = "mass.F_ext"
        "#,
        osc = fmu("oscillator").display(),
        ctrl = fmu("controller").display()
    );
    SystemSpec::from_toml(&text).unwrap()
}

#[test]
fn libcosim_and_tether_agree_on_an_exported_signal_only_system() {
    let Some(python) = tether_tests::tools::libcosimpy() else {
        return;
    };
    let spec = signal_only_system();
    let dir = tempfile::tempdir().unwrap();
    let ssp = dir.path().join("system.ssp");
    tether_ssp::write(&spec, &ssp).unwrap();
    // libcosim reads unpacked SSP folders.
    let unpacked = dir.path().join("unpacked");
    zip::ZipArchive::new(std::fs::File::open(&ssp).unwrap())
        .unwrap()
        .extract(&unpacked)
        .unwrap();
    // libcosim takes the step from the OSP annotation Tether writes.
    let theirs = libcosim(&python, &unpacked, (1e-3, true), 0.5, &COLUMNS);
    let read = tether_ssp::read(&ssp, None, None).unwrap();
    let ours = tether(&read.spec, &COLUMNS);
    let worst = compare(&ours, &theirs);
    println!("largest |a - b| / max(1, |b|) over 500 steps: {worst:.1e}");
}

#[test]
fn libcosim_and_tether_agree_on_the_hand_written_ssd() {
    let Some(python) = tether_tests::tools::libcosimpy() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let src = workspace_root().join("tests/fixtures/ssp/controlled_mass");
    std::fs::create_dir(dir.path().join("resources")).unwrap();
    for f in ["SystemStructure.ssd", "resources/mass.ssv"] {
        std::fs::copy(src.join(f), dir.path().join(f)).unwrap();
    }
    for name in ["oscillator", "controller"] {
        std::fs::copy(fmu(name), dir.path().join(format!("resources/{name}.fmu"))).unwrap();
    }
    let theirs = libcosim(&python, dir.path(), (1e-3, false), 0.5, &COLUMNS);
    let read = tether_ssp::read(dir.path(), Some(1e-3), None).unwrap();
    let ours = tether(&read.spec, &COLUMNS);
    let worst = compare(&ours, &theirs);
    println!("largest |a - b| / max(1, |b|) over 500 steps: {worst:.1e}");
}
