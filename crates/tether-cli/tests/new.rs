//! `tether new`: a starter system file for FMUs that runs as written.

mod common;

use std::path::Path;

use common::{error_line, oscillator, read_csv, success, tether};

fn controller() -> std::path::PathBuf {
    tether_fmu_build::workspace_fmu("controller").expect("package the controller FMU")
}

/// Two workspace FMUs copied next to each other, named relative to the
/// current folder: the file names them relative to its own folder, lists the
/// parameters with their start values and units, the interface, the
/// experiment of the default experiments, and runs as written; a suggested
/// connection runs when uncommented.
#[test]
fn a_starter_system_file_runs_as_written() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("fmus")).unwrap();
    std::fs::create_dir(dir.path().join("systems")).unwrap();
    std::fs::copy(oscillator(), dir.path().join("fmus/oscillator.fmu")).unwrap();
    std::fs::copy(controller(), dir.path().join("fmus/controller.fmu")).unwrap();
    let out = tether(
        &[
            "new",
            "fmus/oscillator.fmu",
            "fmus/controller.fmu",
            "--out",
            "systems/starter.toml",
        ],
        dir.path(),
    );
    let said = success(&out);
    assert_eq!(
        said.trim_end(),
        "wrote systems/starter.toml: 2 instances; run it with `tether run systems/starter.toml`"
    );
    let text = std::fs::read_to_string(dir.path().join("systems/starter.toml")).unwrap();
    for line in [
        "[experiment]",
        "stop = 1.0           # from the FMUs' default experiments",
        "step = 0.001         # the macro step H: the smallest stepSize of the FMUs",
        "name = \"oscillator\"",
        "fmu = \"../fmus/oscillator.fmu\"   # oscillator 2.0",
        "# m = 1.0                        # [kg] Mass (must be > 0)",
        "# exact = false                  # Boolean Integrate exactly (matrix exponential) instead of with Dop853",
        "#   oscillator.x                 [m] Position",
        "#   oscillator.F_ext             [N] Additional force on the mass (added to F)",
        "name = \"controller\"",
        "# kp = 1000.0                    # [N/m] Proportional gain",
        "#   controller.y                 [m] Measured position",
        "# from = \"oscillator.x\"",
        "# to = \"controller.y\"",
    ] {
        assert!(text.lines().any(|l| l == line), "no line {line:?} in\n{text}");
    }
    let run = |name: &str| {
        let out = tether(
            &["run", &format!("systems/{name}"), "--out", "r.csv"],
            dir.path(),
        );
        success(&out);
        read_csv(&dir.path().join("r.csv"))
    };
    let (header, rows) = run("starter.toml");
    assert_eq!(rows.len(), 1001);
    for column in ["oscillator.x", "controller.u"] {
        assert!(header.iter().any(|h| h == column), "{header:?}");
    }
    // Uncomment a suggested connection and a parameter: it runs, and they act.
    let edited = text
        .replace(
            "# [[connection]]\n# from = \"oscillator.x\"\n# to = \"controller.y\"",
            "[[connection]]\nfrom = \"oscillator.x\"\nto = \"controller.y\"",
        )
        .replace("# m = 1.0 ", "m = 2.0 ");
    assert_ne!(edited, text);
    std::fs::write(dir.path().join("systems/edited.toml"), &edited).unwrap();
    let (header2, rows2) = run("edited.toml");
    assert_eq!(header2, header);
    assert_ne!(rows2, rows);

    // Not overwritten; an FMU that is not there is named.
    let again = tether(
        &[
            "new",
            "fmus/oscillator.fmu",
            "--out",
            "systems/starter.toml",
        ],
        dir.path(),
    );
    assert_eq!(
        error_line(&again),
        "error: systems/starter.toml exists: tether new does not overwrite it (choose another \
         --out, or remove it)"
    );
    let missing = tether(&["new", "fmus/Oscillator.fmu"], dir.path());
    let line = error_line(&missing);
    assert!(
        line.ends_with("did you mean 'fmus/oscillator.fmu'?"),
        "{line}"
    );
}

/// FMI 3.0 FMUs with arrays and typed values (the Reference FMUs StateSpace
/// and Feedthrough), twice the same FMU (numbered instances), on stdout.
#[test]
fn a_starter_system_file_of_fmi3_fmus_with_arrays_runs_as_written() {
    let (Some(ss), Some(ft)) = (
        tether_fmu_build::fixture_fmu("reference-fmus/fmi3/StateSpace.fmu"),
        tether_fmu_build::fixture_fmu("reference-fmus/fmi3/Feedthrough.fmu"),
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = tether(
        &[
            "new",
            ss.to_str().unwrap(),
            ft.to_str().unwrap(),
            ft.to_str().unwrap(),
        ],
        dir.path(),
    );
    success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    for line in [
        "# x0 = [0.0, 0.0, 0.0]           # array Initial state vector",
        "name = \"feedthrough1\"",
        "name = \"feedthrough2\"",
        "#   feedthrough1.Int32_output    Int32",
        "stop = 10.0          # from the FMUs' default experiments",
    ] {
        assert!(
            text.lines().any(|l| l == line),
            "no line {line:?} in\n{text}"
        );
    }
    let system = dir.path().join("fmi3.toml");
    // Shorter than the default experiment's 10 s, as a user would try first.
    std::fs::write(&system, text.replace("stop = 10.0 ", "stop = 0.1 ")).unwrap();
    let out = tether(
        &["run", system.to_str().unwrap(), "--out", "r.csv"],
        dir.path(),
    );
    success(&out);
    let (header, rows) = read_csv(&Path::new(dir.path()).join("r.csv"));
    assert_eq!(rows.len(), 11, "the Feedthrough stepSize, 0.01");
    assert!(header.iter().any(|h| h == "statespace.y[1]"), "{header:?}");
}
