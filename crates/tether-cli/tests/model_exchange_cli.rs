//! `tether simulate --fmi-type` and `--integrator`, and what `tether info` says
//! about each interface: on the Reference FMUs (third-party FMUs vendored in
//! `tests/fixtures/reference-fmus`) and on a model-exchange-only FMU compiled
//! from `tests/fixtures/fmi/me_sawtooth.c`.

use std::ffi::OsStr;
use std::path::PathBuf;
use std::process::{Command, Output};

fn reference(standard: &str, model: &str) -> Option<PathBuf> {
    tether_fmu_build::fixture_fmu(&format!("reference-fmus/{standard}/{model}.fmu"))
}

fn tether(args: &[&OsStr]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .output()
        .unwrap()
}

fn os(s: &str) -> &OsStr {
    OsStr::new(s)
}

/// The command succeeded (else its stderr is the failure).
fn succeeded(out: &Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The one line of a failed command's stderr.
fn error_line(out: &Output) -> String {
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr).trim().to_string();
    assert_eq!(err.lines().count(), 1, "{err}");
    err
}

#[test]
fn info_shows_what_each_interface_allows() {
    for (standard, flag) in [
        ("fmi2", "completedIntegratorStepNotNeeded       no"),
        ("fmi3", "needsCompletedIntegratorStep           no"),
    ] {
        let Some(fmu) = reference(standard, "BouncingBall") else {
            return;
        };
        let out = tether(&[os("info"), fmu.as_os_str()]);
        assert!(out.status.success());
        let text = String::from_utf8_lossy(&out.stdout);
        for expected in [
            "co-simulation, model exchange\n",
            "\nModel exchange\n",
            "continuous states                      2\n",
            "event indicators                       1\n",
            flag,
            "tether simulate --fmi-type model-exchange  yes: built-in integrator (bdf, esdirk, rk45, dop853)",
            "model exchange coupled in a system         yes: fmi_type = \"model_exchange\"; rollback with FMU states, polynomials on every input",
        ] {
            assert!(
                text.contains(expected),
                "{standard}: {expected:?} in\n{text}"
            );
        }
    }
}

#[test]
fn a_model_exchange_only_fmu_runs_as_model_exchange_by_default() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = tether_tests::fmi::me_sawtooth_fmu(dir.path());
    let info = tether(&[os("info"), fmu.as_os_str()]);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(
        text.contains("FMI         2.0 model exchange\n")
            && text.contains("none: the FMU offers model exchange only")
            && text.contains("predictor/corrector (baumgarte, weighted)  yes, through model exchange (fmi_type = \"auto\")")
            && text.contains("explicit                                   yes, through model exchange")
            && text.contains("rollback from its states while no event falls in a step"),
        "{text}"
    );
    let csv = dir.path().join("saw.csv");
    let out = tether(&[
        os("simulate"),
        fmu.as_os_str(),
        os("--stop"),
        os("2.4"),
        os("--step"),
        os("0.3"),
        os("--tolerance"),
        os("1e-10"),
        os("--out"),
        csv.as_os_str(),
    ]);
    succeeded(&out);
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some("time,x,events"));
    let mut rows = 0;
    for line in lines {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        // x = 1 − (t − ⌊t⌋): reset to 1 by the state events at t = 1 and 2,
        // which `events` counts (grid points off the events).
        let t = v[0];
        assert!((v[1] - (1.0 - (t - t.floor()))).abs() < 1e-12, "{line}");
        assert_eq!(v[2], t.floor(), "{line}");
        rows += 1;
    }
    assert_eq!(rows, 9);
    let out = tether(&[
        os("simulate"),
        fmu.as_os_str(),
        os("--fmi-type"),
        os("co-simulation"),
        os("--out"),
        csv.as_os_str(),
    ]);
    let err = error_line(&out);
    assert!(
        err.contains("model-exchange-only") && err.contains("--fmi-type model-exchange"),
        "{err}"
    );
}

#[test]
fn a_chattering_model_is_one_error_line() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = tether_tests::fmi::me_sawtooth_fmu(dir.path());
    let csv = dir.path().join("saw.csv");
    let out = tether(&[
        os("simulate"),
        fmu.as_os_str(),
        os("--set"),
        os("mode=1"),
        os("--out"),
        csv.as_os_str(),
    ]);
    let err = error_line(&out);
    assert!(
        err.contains("'sawtooth'")
            && err.contains("t = 0")
            && err.contains("more than 100 event iterations")
            && err.contains("chatters"),
        "{err}"
    );
}

#[test]
fn the_integrator_settings_are_checked_in_one_line() {
    let Some(fmu) = reference("fmi2", "Dahlquist") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("d.csv");
    for (setting, fmi_type, expected) in [
        (
            "method=radau",
            "model-exchange",
            "unknown method 'radau' (known: bdf, esdirk, rk45, dop853)",
        ),
        ("rtol=x", "model-exchange", "rtol = 'x' is not a number"),
        (
            "atol=0",
            "model-exchange",
            "atol = 0: expected a finite number > 0",
        ),
        ("step=1", "model-exchange", "unknown key 'step'"),
        ("rk45", "model-exchange", "'rk45' is not KEY=VALUE"),
        (
            "method=rk45",
            "co-simulation",
            "--integrator applies to model exchange",
        ),
    ] {
        let out = tether(&[
            os("simulate"),
            fmu.as_os_str(),
            os("--fmi-type"),
            os(fmi_type),
            os("--integrator"),
            os(setting),
            os("--out"),
            csv.as_os_str(),
        ]);
        let err = error_line(&out);
        assert!(err.contains(expected), "{setting}: {err}");
    }
}

/// dop853 and a largest step: Dahlquist's x(10) = e^−10 to 1e-12 at rtol 1e-12
/// (measured 2.6e-17 … 3.0e-16 over the grid).
#[test]
fn the_integrator_settings_are_used() {
    let Some(fmu) = reference("fmi3", "Dahlquist") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("d.csv");
    let out = tether(&[
        os("simulate"),
        fmu.as_os_str(),
        os("--fmi-type"),
        os("model-exchange"),
        os("--integrator"),
        os("method=dop853, rtol=1e-12, max_step=0.05"),
        os("--out"),
        csv.as_os_str(),
    ]);
    succeeded(&out);
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut worst: f64 = 0.0;
    for line in text.lines().skip(1) {
        let (t, x) = line.split_once(',').unwrap();
        let (t, x): (f64, f64) = (t.parse().unwrap(), x.parse().unwrap());
        worst = worst.max((x - (-t).exp()).abs());
    }
    assert!(worst < 1e-12 && worst > 0.0, "{worst:e}");
}

#[test]
fn an_fmu_requesting_the_end_ends_the_model_exchange_run() {
    let Some(fmu) = reference("fmi2", "Stair") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("stair.csv");
    let out = tether(&[
        os("simulate"),
        fmu.as_os_str(),
        os("--fmi-type"),
        os("model-exchange"),
        os("--out"),
        csv.as_os_str(),
    ]);
    succeeded(&out);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains(
            "requested the end of the simulation at t = 9 (model exchange, terminateSimulation)"
        ),
        "{said}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(text.ends_with("9.0,10.0\n"), "{text}");
}

/// The stiff Reference FMU Roberts (its archive lists `extra/` twice, each
/// copy the same): the default bdf runs it to its stop time, 1e8; rk45
/// stops as the model turns stiff, t ≈ 1.8, in one line naming it.
#[test]
fn roberts_runs_with_bdf_and_stops_rk45_as_stiff() {
    let Some(fmu) = reference("fmi3", "Roberts") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("roberts.csv");
    let args = |method: &'static str| {
        vec![
            os("simulate"),
            fmu.as_os_str(),
            os("--fmi-type"),
            os("model-exchange"),
            os("--tolerance"),
            os("1e-8"),
            os("--integrator"),
            os(method),
            os("--out"),
            csv.as_os_str(),
        ]
    };
    succeeded(&tether(&args("method=bdf")));
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(
        text.lines().last().unwrap().starts_with("100000000"),
        "{text}"
    );
    let err = error_line(&tether(&args("method=rk45")));
    let t: f64 = err
        .split("stopped at t = ")
        .nth(1)
        .and_then(|rest| rest.split(':').next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("{err}"));
    assert!(
        err.contains("'Roberts'") && err.contains("became stiff") && (1.0..3.0).contains(&t),
        "{err}"
    );
}
