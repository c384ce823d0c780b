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
