//! The exact words of `tether run` for mistakes in a system file, and its
//! progress report on a non-terminal.

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{oscillator, tether_env as tether};

/// Stderr must be exactly one error line; exit code 1.
fn only_error(out: &Output) -> String {
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "expected exit 1: {text}");
    assert_eq!(text.lines().count(), 1, "one line: {text}");
    text.trim_end().to_string()
}

/// examples/oscillator.toml with the oscillator's path and `edit` applied,
/// written to `dir/<rel>`.
fn example(dir: &Path, rel: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/oscillator.toml"),
    )
    .unwrap()
    .replace(
        "../target/fmus/oscillator.fmu",
        &oscillator().display().to_string(),
    );
    let path = dir.join(rel);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(&path, edit(text)).unwrap();
    path
}

#[test]
fn system_file_mistakes_are_one_clear_line() {
    let dir = tempfile::tempdir().unwrap();
    let osc = oscillator().display().to_string();
    let run = |file: &str| only_error(&tether(&["run", file, "--out", "r.csv"], dir.path(), &[]));

    // A wrong FMU path: resolved against the system file's folder, which is
    // named with the resolved path; the OS error once, the instance named.
    example(dir.path(), "sub/wrong.toml", |t| {
        t.replacen(&osc, "../fmus/nothere.fmu", 1)
    });
    let root = dir.path().display();
    assert_eq!(
        run("sub/wrong.toml"),
        format!(
            "error: instance 'mass1': cannot access '{root}/fmus/nothere.fmu' \
             ('../fmus/nothere.fmu' in {root}/sub, the system file's folder): No such file or \
             directory (os error 2)"
        )
    );
    // A name that differs only in case: did you mean.
    std::fs::create_dir_all(dir.path().join("fmus")).unwrap();
    std::fs::copy(oscillator(), dir.path().join("fmus/Mass.fmu")).unwrap();
    example(dir.path(), "sub/case.toml", |t| {
        t.replacen(&osc, "../fmus/mass.fmu", 1)
    });
    assert_eq!(
        run("sub/case.toml"),
        format!(
            "error: instance 'mass1': cannot access '{root}/fmus/mass.fmu' \
             ('../fmus/mass.fmu' in {root}/sub, the system file's folder): No such file or \
             directory (os error 2); did you mean '../fmus/Mass.fmu'?"
        )
    );
    // On the command line: against the current folder.
    let info = |file: &str| only_error(&tether(&["info", file], dir.path(), &[]));
    assert_eq!(
        info("fmus/MASS.fmu"),
        format!(
            "error: cannot access '{root}/fmus/MASS.fmu' ('fmus/MASS.fmu' in {root}, the \
             current folder): No such file or directory (os error 2); did you mean \
             'fmus/Mass.fmu'?"
        )
    );
    assert_eq!(
        run("sub/Case.toml"),
        format!(
            "error: system file sub/Case.toml: cannot access '{root}/sub/Case.toml' \
             ('sub/Case.toml' in {root}, the current folder): No such file or directory (os \
             error 2); did you mean 'sub/case.toml'?"
        )
    );
    std::fs::write(dir.path().join("Results.csv"), "time,x\n0,1\n").unwrap();
    assert_eq!(
        only_error(&tether(
            &["compare", "results.csv", "Results.csv"],
            dir.path(),
            &[]
        )),
        format!(
            "error: cannot access '{root}/results.csv' ('results.csv' in {root}, the current \
             folder): No such file or directory (os error 2); did you mean 'Results.csv'?"
        )
    );

    // A name used twice: the file is named.
    example(dir.path(), "dup.toml", |t| {
        t.replace("name = \"mass2\"", "name = \"mass1\"")
    });
    assert_eq!(
        run("dup.toml"),
        "error: system file dup.toml: name 'mass1' is used twice"
    );

    // A constant term: said once, as what it is.
    example(dir.path(), "constant.toml", |t| {
        t.replace(
            "position = \"mass2.x - mass1.x\"",
            "position = \"mass2.x - mass1.x + 0.5\"",
        )
    });
    assert_eq!(
        run("constant.toml"),
        "error: constraint 'link', position: cannot read expression 'mass2.x - mass1.x + 0.5': \
         a constant term (0.5) is not allowed: an expression is a sum of terms \
         coefficient*instance.variable (an offset belongs in an FMU output) at column 21"
    );

    // Drives that cancel: the constraint is named before any step.
    example(dir.path(), "cancel.toml", |t| {
        t.replace(
            "drives = \"mass1.F - mass2.F\"",
            "drives = \"mass1.F - mass1.F\"",
        )
    });
    assert_eq!(
        run("cancel.toml"),
        "error: constraint 'link': drives 'mass1.F - mass1.F' cancel out: the multiplier acts \
         on no input (every input's coefficients sum to 0), so the interface Jacobian would be \
         singular"
    );
}

/// On a non-terminal (a log file, CI) a run that lasts prints a progress line
/// in simulated time every interval (10 s; here 0.05 s).
#[test]
fn a_long_run_reports_progress_in_simulated_time_on_a_non_terminal() {
    let dir = tempfile::tempdir().unwrap();
    example(dir.path(), "osc.toml", |t| t);
    let out = tether(
        &[
            "run",
            "osc.toml",
            "--out",
            "r.csv",
            "--stop",
            "20",
            "--parallel",
            "off",
        ],
        dir.path(),
        &[("TETHER_PROGRESS_INTERVAL", "0.05")],
    );
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{text}");
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| l.starts_with("progress: t = "))
        .collect();
    assert!(!lines.is_empty(), "{text}");
    for line in &lines {
        // progress: t = 3.456 of 20.000 (17 %), 1 s elapsed, about 5 s left
        let rest = line.strip_prefix("progress: t = ").unwrap();
        let (t, rest) = rest.split_once(" of 20.000 (").expect(line);
        let t: f64 = t.parse().expect(line);
        assert!(t > 0.0 && t < 20.0, "{line}");
        assert!(
            t.to_string().split('.').nth(1).map_or(0, str::len) <= 3,
            "{line}"
        );
        assert!(
            rest.contains(" %), ") && rest.ends_with(" s left"),
            "{line}"
        );
    }
    // --quiet: none.
    let out = tether(
        &[
            "run", "osc.toml", "--out", "r.csv", "--stop", "5", "--quiet",
        ],
        dir.path(),
        &[("TETHER_PROGRESS_INTERVAL", "0.01")],
    );
    assert!(!String::from_utf8_lossy(&out.stderr).contains("progress:"));
}

/// An example's system file with its workspace FMUs' paths, written to `dir/<rel>`.
fn example_named(dir: &Path, name: &str, edit: impl Fn(String) -> String) -> PathBuf {
    let mut text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../examples/{name}.toml")),
    )
    .unwrap();
    for fmu in ["oscillator", "controller", "lti"] {
        let path = tether_fmu_build::workspace_fmu(fmu).unwrap();
        text = text.replace(
            &format!("../target/fmus/{fmu}.fmu"),
            &path.display().to_string(),
        );
    }
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, edit(text)).unwrap();
    path
}

/// Every line of a run's stderr within 100 characters; the lines.
fn short_lines(out: &Output) -> Vec<String> {
    let text = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{text}");
    for line in text.lines() {
        assert!(
            line.chars().count() <= 100,
            "{} characters: {line}",
            line.chars().count()
        );
    }
    text.lines().map(str::to_string).collect()
}

/// The summary of a run with a constraint and signals: within 100 columns, the
/// method and the signals' scheme named, the FMI functions called in a table
/// (those never called left out), no internal words.
#[test]
fn the_run_summary_fits_100_columns_and_names_the_fmi_functions_called() {
    let dir = tempfile::tempdir().unwrap();
    let system = example_named(dir.path(), "controlled_oscillator", |t| t);
    let out = tether(
        &[
            "run",
            system.to_str().unwrap(),
            "--out",
            "r.csv",
            "--parallel",
            "auto",
        ],
        dir.path(),
        &[],
    );
    let lines = short_lines(&out);
    assert_eq!(
        lines[..2],
        [
            "controlled two-mass oscillator: baumgarte (index 1, beta = 2e-3, gamma = 1e-6), \
             signals: Jacobi,",
            "  k = 1, H = 0.001, t = 0 … 1",
        ]
    );
    let table: Vec<&str> = lines
        .iter()
        .skip_while(|l| !l.starts_with("  FMI calls"))
        .take(7)
        .map(String::as_str)
        .collect();
    assert_eq!(
        table,
        [
            "  FMI calls                    ctrl  mass1  mass2",
            "  fmi2DoStep                   1000   3000   3000",
            "  fmi2GetFMUstate                 0   1000   1000",
            "  fmi2SetFMUstate                 0   2000   2000",
            "  fmi2SetReal                  1003   4010   3007",
            "  fmi2GetReal                  2004   4008   3005",
            "  fmi2SetRealInputDerivatives     0   4010   3007",
        ]
    );
    let text = lines.join("\n");
    assert!(!text.contains("getRealOutputDerivatives"), "{text}");
    assert!(
        !text.contains("hand-off could save") && !text.contains("worker(s)"),
        "{text}"
    );
    // The runs cost microseconds: "auto" keeps them on the main thread,
    // whether their cost alone rules workers out or a timed hand-off does.
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("  parallel runs not started: ")),
        "{text}"
    );
}

/// A system of signals only is summarised by what it does (no coupling method),
/// and the loop note says whether the FMUs declare their feedthrough.
#[test]
fn a_signal_only_system_is_summarised_by_its_signals() {
    let dir = tempfile::tempdir().unwrap();
    let system = example_named(dir.path(), "control_loop", |t| t);
    let out = tether(
        &["run", system.to_str().unwrap(), "--out", "r.csv"],
        dir.path(),
        &[],
    );
    let lines = short_lines(&out);
    assert_eq!(
        lines[..4],
        [
            "note: direct-feedthrough loop through controller, plant is closed only at macro points: Gauss–Seidel",
            "  steps its instances in file order and 1 of its 2 connections (those into an instance stepped",
            "  before its sender) pass the value at T_N (-v names the connections)",
            "control loop with direct feedthrough: signals: Gauss–Seidel, H = 0.001, t = 0 … 2",
        ]
    );
    assert!(
        lines[4].starts_with("macro steps: 2000   wall time: "),
        "{lines:?}"
    );
    assert_eq!(lines[5], "  FMI calls    source  controller  plant");
    assert_eq!(lines[6], "  fmi2DoStep     2000        2000   2000");
    let text = lines.join("\n");
    assert!(
        !text.contains("baumgarte") && !text.contains("FMUstate"),
        "{text}"
    );

    // FMUs that declare no dependencies of their outputs (the ordinary case):
    // the note says that the loop is assumed.
    let undeclared = |fmu: &str, from: &str, to: &str| {
        tether_tests::faulty::edited_fmu(
            &tether_fmu_build::workspace_fmu(fmu).unwrap(),
            dir.path(),
            &format!("{fmu}-nodeps"),
            |xml| xml.replace(from, to),
        )
    };
    let lti = undeclared(
        "lti",
        r#"<Unknown index="11" dependencies="9 10 12"/>"#,
        r#"<Unknown index="11"/>"#,
    );
    let controller = undeclared(
        "controller",
        r#"<Unknown index="6" dependencies="5 7"/>"#,
        r#"<Unknown index="6"/>"#,
    );
    let system = example_named(dir.path(), "control_loop", |t| {
        let lti_path = tether_fmu_build::workspace_fmu("lti").unwrap();
        let ctrl_path = tether_fmu_build::workspace_fmu("controller").unwrap();
        t.replace(&lti_path.display().to_string(), &lti.display().to_string())
            .replace(
                &ctrl_path.display().to_string(),
                &controller.display().to_string(),
            )
    });
    let out = tether(
        &["run", system.to_str().unwrap(), "--out", "r.csv"],
        dir.path(),
        &[],
    );
    let lines = short_lines(&out);
    let note: Vec<&str> = lines
        .iter()
        .take_while(|l| !l.starts_with("control loop"))
        .map(|l| l.trim())
        .collect();
    assert_eq!(
        note.join(" "),
        "note: the connections between controller, plant form a loop; controller, plant declare no \
         dependencies of their outputs, so Tether takes them to feed through, and the loop is \
         closed at macro points as co-simulation masters do: Gauss–Seidel steps its instances \
         in file order and 1 of its 2 connections (those into an instance stepped before its \
         sender) pass the value at T_N (-v names the connections)"
    );
}

/// FMI 3.0 instances and Integer and Boolean connections: each function under
/// its own name (`fmi3SetInt32`, `fmi3SetBoolean`), not counted as Real calls;
/// the recorded String output `String_output` read once per recorded point.
#[test]
fn call_counts_name_the_fmi3_functions_and_the_value_types() {
    let Some(ft) = tether_fmu_build::fixture_fmu("reference-fmus/fmi3/Feedthrough.fmu") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let system = dir.path().join("ft.toml");
    std::fs::write(
        &system,
        format!(
            "[experiment]\nstop = 0.01\nstep = 1e-3\n\n\
             [[instance]]\nname = \"ft1\"\nfmu = {ft:?}\n\n[[instance]]\nname = \"ft2\"\nfmu = {ft:?}\n\n\
             [[connection]]\nfrom = \"ft1.Float64_continuous_output\"\nto = \"ft2.Float64_continuous_input\"\n\n\
             [[connection]]\nfrom = \"ft1.Int32_output\"\nto = \"ft2.Int32_input\"\n\n\
             [[connection]]\nfrom = \"ft1.Boolean_output\"\nto = \"ft2.Boolean_input\"\n"
        ),
    )
    .unwrap();
    let out = tether(
        &["run", system.to_str().unwrap(), "--out", "r.csv"],
        dir.path(),
        &[],
    );
    let lines = short_lines(&out);
    let table: Vec<&str> = lines
        .iter()
        .skip_while(|l| !l.starts_with("  FMI calls"))
        .take_while(|l| l.starts_with("  FMI calls") || l.starts_with("  fmi3"))
        .map(String::as_str)
        .collect();
    assert_eq!(
        table,
        [
            "  FMI calls               ft1  ft2",
            "  fmi3DoStep               10   10",
            "  fmi3SetFloat64            0   12",
            "  fmi3GetFloat64/Float32   23   11",
            "  fmi3SetInt32              0   12",
            "  fmi3GetInt*              23   11",
            "  fmi3SetBoolean            0   12",
            "  fmi3GetBoolean           23   11",
            "  fmi3GetString            11   11",
        ],
        "{lines:#?}"
    );
}
