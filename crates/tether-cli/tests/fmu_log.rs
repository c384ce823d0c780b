//! An FMU's own messages: `--fmu-log [CATEGORIES]` and `-v` switch its debug
//! logging on and show them prefixed with the instance; a failed call reports
//! the FMU's last messages with it.

mod common;

use std::path::Path;

use common::{error_line, oscillator, stderr, tether};

/// `tether simulate` of the oscillator over three steps, with `flags`.
fn simulate(dir: &Path, flags: &[&str]) -> String {
    let fmu = oscillator();
    let mut args = vec![
        "simulate",
        fmu.to_str().unwrap(),
        "--stop",
        "0.003",
        "--step",
        "1e-3",
    ];
    args.extend_from_slice(flags);
    let out = tether(&args, dir);
    let text = stderr(&out);
    assert!(out.status.success(), "{text}");
    text
}

const STEP: &str = "[INFO  fmu::oscillator] [logEvents] step 0.001 -> 0.002 (Dop853)";

#[test]
fn fmu_log_and_verbose_show_the_fmus_messages_by_category() {
    let dir = tempfile::tempdir().unwrap();
    assert!(!simulate(dir.path(), &[]).contains("fmu::"));
    let all = simulate(dir.path(), &["--fmu-log"]);
    assert!(
        all.contains(
            "[INFO  fmu::oscillator] [logEvents] initialized at t = 0, states [0.0, 100.0]"
        ),
        "{all}"
    );
    assert!(all.contains(STEP), "{all}");
    assert!(simulate(dir.path(), &["-v"]).contains(STEP));
    assert!(simulate(dir.path(), &["--fmu-log=logEvents"]).contains(STEP));
    // Another category only: no step messages.
    let warnings = simulate(dir.path(), &["--fmu-log=logStatusWarning"]);
    assert!(!warnings.contains("logEvents"), "{warnings}");
    // A category the model does not declare is named, and skipped.
    let unknown = simulate(dir.path(), &["--fmu-log=logEvents,logNothing"]);
    assert!(
        unknown.contains(
            "model 'oscillator' declares no log category 'logNothing' (it declares: logEvents, \
             logStatusWarning, logStatusDiscard, logStatusError, logStatusFatal, logAll); not \
             asked of instance 'oscillator'"
        ),
        "{unknown}"
    );
    assert!(unknown.contains(STEP), "{unknown}");
}

/// In a coupled run every message names its instance.
#[test]
fn messages_of_a_coupled_run_name_their_instance() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/oscillator.toml"),
    )
    .unwrap()
    .replace(
        "../target/fmus/oscillator.fmu",
        &oscillator().display().to_string(),
    );
    std::fs::write(dir.path().join("osc.toml"), text).unwrap();
    let out = tether(
        &[
            "run",
            "osc.toml",
            "--stop",
            "0.002",
            "--parallel",
            "off",
            "--fmu-log=logEvents",
            "--quiet",
        ],
        dir.path(),
    );
    let text = stderr(&out);
    assert!(out.status.success(), "{text}");
    for instance in ["mass1", "mass2"] {
        assert!(
            text.contains(&format!(
                "[INFO  fmu::{instance}] [logEvents] initialized at t = 0"
            )),
            "{text}"
        );
    }
}

/// A call that fails carries what the FMU logged (errors are kept even when
/// they are not shown): initialisation with invalid parameters, and an
/// `fmi2Instantiate` that returns NULL.
#[test]
fn a_failed_call_reports_the_fmus_last_messages() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = oscillator();
    let out = tether(
        &[
            "simulate",
            fmu.to_str().unwrap(),
            "--stop",
            "0.003",
            "--set",
            "m=-1",
        ],
        dir.path(),
    );
    assert_eq!(
        error_line(&out),
        "error: fmi2ExitInitializationMode returned fmi2Error on instance 'oscillator' at t=0; \
         the FMU's last messages: [logStatusError] fmi2ExitInitializationMode: invalid \
         parameters: m must be > 0, got -1"
    );
    let edited = tether_tests::faulty::edited_oscillator(dir.path(), "wrong-guid", |xml| {
        let start = xml.find("guid=\"").unwrap() + 6;
        let end = start + xml[start..].find('"').unwrap();
        format!(
            "{}00000000-0000-0000-0000-000000000000{}",
            &xml[..start],
            &xml[end..]
        )
    });
    let out = tether(
        &["simulate", edited.to_str().unwrap(), "--stop", "0.003"],
        dir.path(),
    );
    let line = error_line(&out);
    assert!(
        line.starts_with(
            "error: fmi2Instantiate failed for instance 'oscillator' of model 'oscillator'; the \
             FMU's last messages: [logStatusError] fmi2Instantiate: GUID \
             Some(\"00000000-0000-0000-0000-000000000000\") does not match the model's GUID {"
        ),
        "{line}"
    );
}
