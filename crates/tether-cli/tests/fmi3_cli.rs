//! `tether info` and `tether simulate` on FMI 3.0 Reference FMUs (third-party FMUs in
//! `tests/fixtures/reference-fmus/fmi3`, vendored).

use std::path::PathBuf;
use std::process::{Command, Output};

/// The FMI 3.0 Reference FMU `model`; `None` where its binary does not run (the
/// test skips, see `tether_fmu_build::fixture_fmu`).
fn reference(model: &str) -> Option<PathBuf> {
    tether_fmu_build::fixture_fmu(&format!("reference-fmus/fmi3/{model}.fmu"))
}

fn tether(args: &[&std::ffi::OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn info_shows_the_fmi3_capabilities_and_array_dimensions() {
    let Some(fmu) = reference("StateSpace") else {
        return;
    };
    let out = tether(&["info".as_ref(), fmu.as_os_str()]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    for expected in [
        "FMI         3.0 co-simulation",
        "canGetAndSetFMUState                   yes",
        "providesIntermediateUpdate             yes",
        "hasEventMode                           yes",
        "fixedInternalStepSize                  1",
        "Tether runs it without event mode",
        "coupling polynomials k > 0                 no: k > 0 needs inputs that take \
         polynomials; array elements of 'u' take values only\n",
        "  m                             1  structural   tunable",
        "UInt64",
        "Arrays (elements named y[1], A[2,3]: 1-based, row-major)",
        "  A                        3x3        (structural parameter n, structural parameter n)",
        "  y                        3          (structural parameter r)",
    ] {
        assert!(text.contains(expected), "missing {expected:?} in\n{text}");
    }
}

#[test]
fn simulate_names_array_elements_and_honours_termination() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("ss.csv");
    let Some(fmu) = reference("StateSpace") else {
        return;
    };
    let out = tether(&[
        "simulate".as_ref(),
        fmu.as_os_str(),
        "--stop".as_ref(),
        "1".as_ref(),
        "--step".as_ref(),
        "0.5".as_ref(),
        "--out".as_ref(),
        csv.as_os_str(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().next(), Some("time,y[1],y[2],y[3]"));

    let csv = dir.path().join("stair.csv");
    let Some(fmu) = reference("Stair") else {
        return;
    };
    let out = tether(&[
        "simulate".as_ref(),
        fmu.as_os_str(),
        "--out".as_ref(),
        csv.as_os_str(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let said =
        String::from_utf8_lossy(&out.stderr).to_string() + &String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("(fmi3DoStep, terminateSimulation)"), "{said}");
}

#[test]
fn a_scheduled_execution_fmu_is_refused_in_one_line() {
    // Refused at its model description: the binary is not loaded.
    let fmu = tether_fmu_build::fixture_path("reference-fmus/fmi3/Clocks.fmu");
    let out = tether(&["info".as_ref(), fmu.as_os_str()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("offers scheduled execution only, no co-simulation"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}
