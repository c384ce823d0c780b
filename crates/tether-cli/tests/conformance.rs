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
    let out = tether(
        &["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()],
        dir.path(),
    );
    let text = success(&out);
    assert!(
        text.contains(
            "  note: instance 'mass1' requested the end of the simulation at t = 0.5 \
             (fmi2Discard, fmi2Terminated); the run ended normally at t = 0.4, the last accepted point"
        ),
        "{text}"
    );
    assert!(text.contains("t = 0 … 0.4"), "{text}");
    let (_, rows, trailer) = read_csv(&csv);
    assert_eq!(trailer, None, "a normal end");
    assert_eq!(rows.last().unwrap()[0], 0.4);
}

#[test]
fn run_terminates_every_instance_before_freeing_it() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), "", INDEX1, 0.01, 1e-3);
    let csv = dir.path().join("pair.csv");
    let trace = [("TETHER_LOG", "tether_fmi::call=trace")];
    let args = ["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()];
    let text = success(&tether_env(&args, dir.path(), &trace));
    for name in ["mass1", "mass2"] {
        let calls: Vec<&str> = text
            .lines()
            .filter(|l| l.contains("tether_fmi::call") && l.contains(&format!("({name})")))
            .collect();
        let position = |f: &str| {
            calls
                .iter()
                .rposition(|c| c.contains(&format!("{f}({name})")))
        };
        let (step, terminate, free) = (
            position("fmi2DoStep").expect("steps"),
            position("fmi2Terminate"),
            position("fmi2FreeInstance"),
        );
        assert!(
            terminate.is_some_and(|t| t > step && calls[t].ends_with("-> Ok"))
                && free == Some(calls.len() - 1)
                && terminate < free,
            "{name}: fmi2Terminate after the last step, fmi2FreeInstance last: {calls:?}"
        );
    }
}
