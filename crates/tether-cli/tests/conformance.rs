//! FMI conformance and diagnostics through the `tether` binary (issue 33), with
//! the workspace FMU `quirks`: a single-mass oscillator whose parameters select
//! a misbehaviour (fmus/quirks/src/lib.rs).

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn tether(args: &[&str], dir: &Path) -> Output {
    tether_env(args, dir, &[])
}

fn tether_env(args: &[&str], dir: &Path, env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .envs(env.iter().copied())
        .current_dir(dir)
        .output()
        .expect("run tether")
}

fn quirks() -> PathBuf {
    tether_fmu_build::workspace_fmu("quirks").expect("package the quirks FMU")
}

fn oscillator() -> PathBuf {
    tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn success(out: &Output) -> String {
    let text = stderr(out);
    assert!(out.status.success(), "expected success: {text}");
    assert!(!text.contains("panicked"), "{text}");
    text
}

/// The last line of stderr must be the one-line error, exit code 1.
fn error_line(out: &Output) -> String {
    let text = stderr(out);
    assert_eq!(out.status.code(), Some(1), "expected exit 1: {text}");
    assert!(!text.contains("panicked"), "{text}");
    let line = text.lines().last().unwrap_or_default().to_string();
    assert!(line.starts_with("error: "), "{text}");
    line
}

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>, Option<String>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let mut rows = Vec::new();
    let mut trailer = None;
    for line in lines {
        if let Some(t) = line.strip_prefix("# ") {
            trailer = Some(t.to_string());
        } else {
            rows.push(line.split(',').map(|v| v.parse().unwrap()).collect());
        }
    }
    (header, rows, trailer)
}

/// Two masses coupled by x2 − x1 = 0 (examples/oscillator.toml), mass1 a
/// quirks FMU with `parameters`, at H = `step` up to `stop`.
fn system(dir: &Path, parameters: &str, method: &str, stop: f64, step: f64) -> PathBuf {
    system_with(dir, parameters, method, "", stop, step)
}

/// [`system`] with more `[coupling]` keys.
fn system_with(
    dir: &Path,
    parameters: &str,
    method: &str,
    coupling: &str,
    stop: f64,
    step: f64,
) -> PathBuf {
    let text = format!(
        r#"
name = "quirky pair"
[experiment]
stop = {stop}
step = {step}
[method]
{method}
[coupling]
parallel = "off"
{coupling}
[[instance]]
name = "mass1"
fmu = "{quirks}"
parameters = {{ m = 1.0{parameters} }}
[[instance]]
name = "mass2"
fmu = "{oscillator}"
parameters = {{ m = 2.0, exact = true }}
[[constraint]]
name = "link"
position = "mass2.x - mass1.x"
velocity = "mass2.v - mass1.v"
acceleration = "mass2.a - mass1.a"
drives = "mass1.F - mass2.F"
"#,
        quirks = quirks().display(),
        oscillator = oscillator().display(),
    );
    let path = dir.join("pair.toml");
    std::fs::write(&path, text).unwrap();
    path
}

const INDEX1: &str = "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6";

#[test]
fn simulate_ends_normally_when_the_fmu_requests_termination_as_fmpy_does() {
    let fmu = quirks();
    let dir = tempfile::tempdir().unwrap();
    let ours = dir.path().join("tether.csv");
    let theirs = dir.path().join("fmpy.csv");
    let out = tether(
        &[
            "simulate",
            fmu.to_str().unwrap(),
            "--stop",
            "1",
            "--step",
            "0.1",
            "--set",
            "stop_after=0.5",
            "--out",
            ours.to_str().unwrap(),
        ],
        dir.path(),
    );
    let text = success(&out);
    assert!(
        text.contains(
            "quirks: steps of 0.1 from 0; the FMU requested the end of the simulation at t = 0.5 \
             (fmi2Discard, fmi2Terminated), before the stop time 1; results: "
        ),
        "{text}"
    );
    let (h1, r1, trailer) = read_csv(&ours);
    assert_eq!(trailer, None, "a normal end");
    assert_eq!(
        r1.last().unwrap()[0],
        0.5,
        "the point the FMU reached is the last row"
    );
    assert_eq!(r1.len(), 6);

    // The same rows as fmpy (skipped without fmpy, except on CI).
    if tether_tests::tools::fmpy().is_none() {
        return;
    }
    let py: Vec<&OsStr> = [
        fmu.as_os_str(),
        theirs.as_os_str(),
        OsStr::new("--stop"),
        OsStr::new("1"),
        OsStr::new("--step"),
        OsStr::new("0.1"),
        OsStr::new("--set"),
        OsStr::new("stop_after=0.5"),
    ]
    .to_vec();
    let out = tether_tests::fmpy::run_script("simulate.py", &py).expect("run fmpy");
    assert!(out.status.success(), "{}", stderr(&out));
    let (h2, r2, _) = read_csv(&theirs);
    assert_eq!(h1, h2, "same columns");
    assert_eq!(r1.len(), r2.len(), "the same rows as fmpy.simulate_fmu");
    // fmpy steps by differences of its grid times (0.30000000000000004 − 0.2),
    // Tether by H: the same up to rounding.
    for (a, b) in r1.iter().zip(&r2) {
        assert_eq!(a[0], b[0], "the same times");
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() <= 1e-12 * x.abs().max(1.0), "{a:?} vs {b:?}");
        }
    }
}

#[test]
fn run_ends_normally_at_the_last_accepted_point_when_an_instance_requests_termination() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), ", stop_after = 0.5", INDEX1, 1.0, 0.1);
    let csv = dir.path().join("pair.csv");
    // In process and in a host process: both instances say the same.
    for isolate in [&[][..], &["--isolate"][..]] {
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()];
        args.extend_from_slice(isolate);
        let out = tether(&args, dir.path());
        let text = success(&out);
        // The summary wraps its lines within 100 characters.
        let flat = text.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(
            flat.contains(
                "note: instance 'mass1' requested the end of the simulation at t = 0.5 \
                 (fmi2Discard, fmi2Terminated); the run ended normally at t = 0.4, the last accepted point"
            ),
            "{isolate:?}: {text}"
        );
        assert!(text.contains("t = 0 … 0.4"), "{isolate:?}: {text}");
        let (_, rows, trailer) = read_csv(&csv);
        assert_eq!(trailer, None, "a normal end");
        assert_eq!(rows.last().unwrap()[0], 0.4);
    }
}

#[test]
fn run_terminates_every_instance_before_freeing_it() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), "", INDEX1, 0.01, 1e-3);
    let csv = dir.path().join("pair.csv");
    let trace = [("TETHER_LOG", "tether_fmi::call=trace")];
    // With parallel = "on": the instances' runs on a worker thread too.
    let args = [
        "run",
        sys.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
        "--parallel",
        "on",
    ];
    let text = success(&tether_env(&args, dir.path(), &trace));
    for name in ["mass1", "mass2"] {
        let calls: Vec<&str> = text
            .lines()
            // The trace lines of target `tether_fmi::call` (the only ones
            // at that level), shown as `trace: …`.
            .filter(|l| l.starts_with("trace: ") && l.contains(&format!("({name})")))
            .collect();
        let position = |f: &str| {
            calls
                .iter()
                .rposition(|c| c.contains(&format!("{f}({name})")))
        };
        let (step, terminate, free) = (
            position("fmi2DoStep"),
            position("fmi2Terminate"),
            position("fmi2FreeInstance"),
        );
        assert!(
            terminate.is_some_and(|t| step.is_none_or(|s| t > s) && calls[t].ends_with("-> Ok"))
                && free == Some(calls.len() - 1)
                && terminate < free,
            "{name}: fmi2Terminate after the last step, fmi2FreeInstance last: {calls:?}"
        );
    }
}

fn run(dir: &Path, sys: &Path, extra: &[&str]) -> Output {
    let csv = dir.join("pair.csv");
    let mut args = vec!["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()];
    args.extend_from_slice(extra);
    tether(&args, dir)
}

const ADVICE: &str = "; the predictor/corrector method repeats every macro step from a saved \
     state and needs an exact rollback: use --method explicit (no rollback), or \
     check_rollback = \"off\" to run anyway";

#[test]
fn a_rollback_that_restores_nothing_is_caught_at_setup() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), ", rollback = 1", INDEX1, 0.1, 1e-3);
    let line = error_line(&run(dir.path(), &sys, &[]));
    assert_eq!(
        line,
        format!(
            "error: rollback self-check failed for instance 'mass1': after fmi2SetFMUstate back \
             to t = 0, output 'x' reads 0.0996511784189058, not 0 as at fmi2GetFMUstate (the \
             state was not restored){ADVICE}"
        )
    );
    // The advice works: the explicit method does not roll back.
    let text = success(&run(
        dir.path(),
        &sys,
        &["--method", "explicit", "--mu", "1e-2"],
    ));
    assert!(text.contains("explicit"), "{text}");
}

#[test]
fn a_repeated_step_that_differs_is_caught_at_setup() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), ", rollback = 2", INDEX1, 0.1, 1e-3);
    let line = error_line(&run(dir.path(), &sys, &[]));
    assert_eq!(
        line,
        format!(
            "error: rollback self-check failed for instance 'mass1': the step from t = 0 to \
             0.001 repeated after fmi2SetFMUstate with the same inputs gives output 'x' = \
             0.0996511804189058, not 0.0996511794189058 as the first time (not \
             bit-identical){ADVICE}"
        )
    );
}

/// `check_rollback = "off"` skips the check: the broken rollback then breaks
/// the link, which `residual_limit` catches; with both off the run goes on.
#[test]
fn check_rollback_off_runs_a_broken_rollback_anyway() {
    let dir = tempfile::tempdir().unwrap();
    let off = "check_rollback = \"off\"";
    let sys = system_with(dir.path(), ", rollback = 1", INDEX1, off, 0.01, 1e-3);
    let line = error_line(&run(dir.path(), &sys, &[]));
    assert!(line.contains("constraint broken at t = "), "{line}");
    let both = "check_rollback = \"off\"\nresidual_limit = \"off\"";
    let sys = system_with(dir.path(), ", rollback = 1", INDEX1, both, 0.01, 1e-3);
    success(&run(dir.path(), &sys, &[]));
}

#[test]
fn every_step_catches_a_rollback_that_breaks_mid_run() {
    let dir = tempfile::tempdir().unwrap();
    // The rollback breaks from t = 0.05 on: the setup check passes, the next
    // check would be at t = 0.1; by default the broken link stops the run.
    let quirk = ", rollback = 1, rollback_after = 0.05";
    let sys = system(dir.path(), quirk, INDEX1, 0.1, 1e-3);
    let line = error_line(&run(dir.path(), &sys, &[]));
    assert!(
        line.contains("constraint broken at t = 0.064: |link.g| = "),
        "{line}"
    );
    let every = "check_rollback = \"every_step\"";
    let sys = system_with(dir.path(), quirk, INDEX1, every, 0.1, 1e-3);
    let line = error_line(&run(dir.path(), &sys, &[]));
    assert!(
        line.starts_with("error: run stopped; results up to t = 0.05 kept in ")
            && line.contains(
                "pair.csv (marked incomplete): rollback self-check failed for instance 'mass1': \
                 after fmi2SetFMUstate back to t = 0.05, output 'x' reads 3.1800475028207864, \
                 not 3.1674508608149887 as at fmi2GetFMUstate (the state was not restored)",
            )
            && line.ends_with(ADVICE),
        "{line}"
    );
}

#[test]
fn the_setup_check_leaves_results_and_per_step_counts_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let csv = |name: &str| dir.path().join(name);
    let mut results = Vec::new();
    // 250 steps: the periodic check (the default) runs at steps 100 and 200.
    for (label, mode) in [
        ("setup", "setup"),
        ("off", "off"),
        ("every", "every_step"),
        ("periodic", "periodic"),
    ] {
        let coupling = format!("check_rollback = \"{mode}\"");
        let sys = system_with(dir.path(), "", INDEX1, &coupling, 0.25, 1e-3);
        let out_csv = csv(&format!("{label}.csv"));
        let out = tether(
            &[
                "run",
                sys.to_str().unwrap(),
                "--out",
                out_csv.to_str().unwrap(),
            ],
            dir.path(),
        );
        let text = success(&out);
        results.push((std::fs::read(&out_csv).unwrap(), text));
    }
    assert_eq!(
        results[0].0, results[1].0,
        "the check changes no result bit"
    );
    assert_eq!(results[0].0, results[2].0, "nor does every_step");
    assert_eq!(results[0].0, results[3].0, "nor does the periodic check");
    let counts = |text: &str| {
        text.lines()
            .filter(|l| l.trim_start().starts_with("fmi2"))
            .map(str::to_string)
            .collect::<Vec<_>>()
    };
    // 250 steps, 2 instances, one unknown: 3 doStep, 1 getFMUstate, 2
    // setFMUstate per instance and step; the checks are not counted.
    assert_eq!(counts(&results[0].1), counts(&results[1].1));
    assert_eq!(counts(&results[0].1), counts(&results[3].1));
    assert_eq!(
        counts(&results[0].1)[..3],
        [
            "  fmi2DoStep         750    750",
            "  fmi2GetFMUstate    250    250",
            "  fmi2SetFMUstate    500    500",
        ],
        "{}",
        results[0].1
    );
}

#[test]
fn a_nan_output_is_reported_as_its_instances_not_as_a_singular_jacobian() {
    let dir = tempfile::tempdir().unwrap();
    for method in [
        INDEX1,
        "kind = \"baumgarte\"",
        "kind = \"weighted\"\na = 1.0",
    ] {
        let sys = system(dir.path(), ", nan_after = 0.05", method, 0.1, 1e-3);
        let line = error_line(&run(dir.path(), &sys, &[]));
        assert!(
            line.ends_with(
                "pair.csv (marked incomplete): instance 'mass1': output 'x' = NaN after the \
                 predictor's fmi2DoStep at t = 0.05 (the FMU computed a non-finite value)"
            ),
            "{line}"
        );
        assert!(line.contains("results up to t = 0.049 kept in "), "{line}");
    }
    // The explicit method steps once, then reads the outputs through direct
    // feedthrough: that read is checked.
    let sys = system(
        dir.path(),
        ", nan_after = 0.05",
        "kind = \"explicit\"\nmu = 1e-2",
        0.1,
        1e-3,
    );
    let line = error_line(&run(dir.path(), &sys, &[]));
    assert!(
        line.ends_with("instance 'mass1': output 'x' = NaN after fmi2SetReal of the coupled inputs (direct feedthrough) at t = 0.05 (the FMU computed a non-finite value)"),
        "{line}"
    );
}

/// A finite but huge output of mass1 (1e300 from t = 0.05) reaches mass2 as
/// an input before the accepted point is checked: mass2's solver fails
/// (`exact = false`: Dop853), or the interface Jacobian turns singular. The
/// error names mass1, whose output went beyond its divergence limit where it
/// was read, then the failure it led to; every row before is kept, in
/// process and isolated.
#[test]
fn a_huge_output_is_reported_as_its_instances_not_as_another_instances_failure() {
    let dir = tempfile::tempdir().unwrap();
    let tmp = dir.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    let culprit = "instance 'mass1': output 'x' = 1e300 after the predictor's fmi2DoStep at \
                   t = 0.05 is beyond its divergence limit 1.0e6 (divergence_factor × its \
                   initial size); then: ";
    for (method, then) in [
        (
            INDEX1,
            "fmi2DoStep returned fmi2Error on instance 'mass2' at t=0.049",
        ),
        (
            "kind = \"baumgarte\"",
            "singular interface Jacobian (position level) at t = 0.05",
        ),
    ] {
        let sys = system(dir.path(), ", huge_after = 0.05", method, 0.1, 1e-3);
        let text = std::fs::read_to_string(&sys).unwrap();
        std::fs::write(&sys, text.replace("exact = true", "exact = false")).unwrap();
        for isolate in [false, true] {
            let csv = dir.path().join("pair.csv");
            let mut args = vec!["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()];
            if isolate {
                args.push("--isolate");
            }
            let out = tether_env(&args, dir.path(), &[("TMPDIR", tmp.to_str().unwrap())]);
            let line = error_line(&out);
            let reason = line
                .split_once("(marked incomplete): ")
                .map(|(_, r)| r.to_string())
                .unwrap_or_default();
            assert!(
                reason.starts_with(&format!("{culprit}{then}")),
                "{method}, isolate = {isolate}: {line}"
            );
            assert!(line.contains("results up to t = 0.049 kept in "), "{line}");
            let (_, rows, trailer) = read_csv(&csv);
            assert_eq!(rows.len(), 50, "t = 0 … 0.049");
            assert_eq!(trailer, Some(format!("incomplete: {reason}")));
            assert_eq!(std::fs::read_dir(&tmp).unwrap().count(), 0);
        }
    }
}

#[test]
fn simulate_stops_at_a_nan_output_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("quirks.csv");
    let fmu = quirks();
    let out = tether(
        &[
            "simulate",
            fmu.to_str().unwrap(),
            "--stop",
            "0.1",
            "--step",
            "0.01",
            "--set",
            "nan_after=0.05",
            "--out",
            csv.to_str().unwrap(),
        ],
        dir.path(),
    );
    let message = "instance 'quirks': output 'x' = NaN after fmi2DoStep at t = 0.05 (the FMU \
                   computed a non-finite value)";
    let line = error_line(&out);
    assert!(line.ends_with(message), "{line}");
    let (_, rows, trailer) = read_csv(&csv);
    assert_eq!(rows.last().unwrap()[0], 0.04, "no NaN row is written");
    assert!(rows.iter().flatten().all(|v| v.is_finite()));
    assert_eq!(
        trailer.as_deref(),
        Some(format!("incomplete: {message}").as_str())
    );
}

fn example(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name)
        .canonicalize()
        .unwrap()
}

#[test]
fn the_summary_prints_max_g_and_warns_above_the_threshold() {
    let dir = tempfile::tempdir().unwrap();
    let sys = example("oscillator.toml");
    let csv = dir.path().join("o.csv");
    let base = ["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()];
    let text = success(&tether(&base, dir.path()));
    assert!(text.contains("\n  max |g|:  link.g 2.88e-5\n"), "{text}");
    assert!(!text.contains("warning"), "{text}");
    let mut args = base.to_vec();
    args.extend(["--method", "explicit", "--mu", "1", "--step", "0.02"]);
    let text = success(&tether(&args, dir.path()));
    assert!(
        text.contains(
            "  max |g|:  link.g 5.82e-1\n  warning: max |link.g| = 5.82e-1 exceeds \
             residual_warning = 1e-3: the constraint is not held to\n    that accuracy (a \
             smaller step, another index or method, or a larger residual_warning)\n"
        ),
        "{text}"
    );
    // Beyond residual_limit (default 1) the constraint is broken: the run fails.
    let mut args = base.to_vec();
    args.extend(["--method", "explicit", "--mu", "1", "--step", "0.1"]);
    let line = error_line(&tether(&args, dir.path()));
    assert!(
        line.contains(
            "(marked incomplete): constraint broken at t = 0.1: |link.g| = 1.7481069035190133e0 \
             exceeds residual_limit = 1e0 (in the condition's units)"
        ),
        "{line}"
    );
}

#[test]
fn a_stop_time_off_the_grid_is_refused_by_run_and_warned_by_simulate() {
    let dir = tempfile::tempdir().unwrap();
    // The example names the packaged FMU under target/fmus.
    tether_fmu_build::workspace_fmu("oscillator").expect("oscillator FMU");
    let sys = example("oscillator.toml");
    let csv = dir.path().join("o.csv");
    let args = [
        "run",
        sys.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
        "--stop",
        "1e-4",
        "--step",
        "1e-3",
    ];
    let out = tether(&args, dir.path());
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr).trim_end(),
        "error: invalid stop = 0.0001: expected a point of the macro grid start + n·step (start = \
         0, step = 0.001); the nearest is 0.001 (or give a step that divides stop - start, or \
         adaptive steps)"
    );
    assert!(!csv.exists(), "refused before the run");
    // On the grid: no warning.
    let args = [
        "run",
        sys.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
        "--stop",
        "0.01",
    ];
    assert!(!success(&tether(&args, dir.path())).contains("warning"));
    // tether simulate likewise.
    let fmu = quirks();
    let args = [
        "simulate",
        fmu.to_str().unwrap(),
        "--stop",
        "1",
        "--step",
        "0.3",
        "--out",
        csv.to_str().unwrap(),
    ];
    let text = success(&tether(&args, dir.path()));
    assert!(
        text.starts_with(
            "warning: stop = 1 is not on the communication grid start + n·step (start = 0, step \
             = 0.3): the simulation ends at t = 0.8999999999999999\n"
        ),
        "{text}"
    );
}

#[test]
fn the_reported_stop_time_of_a_failure_is_the_last_rows() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("o.csv");
    // Divergence with index 3 and linear polynomials, and a huge output of
    // mass1 (caught as divergence of its column, not as mass2's failure).
    let oscillator = example("oscillator.toml");
    let pair = system(dir.path(), ", huge_after = 0.05", INDEX1, 0.1, 1e-3);
    let unstable = ["--beta", "0", "--gamma", "0", "--order", "1"];
    for (sys, extra) in [(oscillator, &unstable[..]), (pair, &[][..])] {
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()];
        args.extend_from_slice(extra);
        let line = error_line(&tether(&args, dir.path()));
        let (_, rows, trailer) = read_csv(&csv);
        let last = rows.last().unwrap()[0];
        assert!(
            line.starts_with(&format!(
                "error: run stopped; results up to t = {last} kept in "
            )),
            "{line}"
        );
        assert!(trailer
            .unwrap()
            .starts_with("incomplete: coupling diverged"));
        if extra.is_empty() {
            assert!(
                line.ends_with("coupling diverged at t = 0.05: mass1.x = 1e300 (limit 1.0e6)"),
                "{line}"
            );
            assert_eq!(last, 0.049);
        }
    }
}
