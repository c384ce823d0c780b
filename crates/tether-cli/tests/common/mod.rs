//! Helpers shared by the CLI test files that `mod common;` them.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the `tether` binary in `dir` with extra environment variables.
pub fn tether_env(args: &[&str], dir: &Path, env: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .envs(env.iter().copied())
        .current_dir(dir)
        .output()
        .expect("run tether")
}

/// Runs the `tether` binary in `dir`.
pub fn tether(args: &[&str], dir: &Path) -> Output {
    tether_env(args, dir, &[])
}

/// The packaged workspace oscillator FMU.
pub fn oscillator() -> PathBuf {
    tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU")
}

pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Stderr of a run that must have succeeded.
pub fn success(out: &Output) -> String {
    let text = stderr(out);
    assert!(out.status.success(), "expected success: {text}");
    assert!(!text.contains("panicked"), "{text}");
    text
}

/// The last line of stderr, which must be the one-line error (exit code 1).
pub fn error_line(out: &Output) -> String {
    let text = stderr(out);
    assert_eq!(out.status.code(), Some(1), "expected exit 1: {text}");
    assert!(!text.contains("panicked"), "{text}");
    text.lines().last().unwrap_or_default().to_string()
}

/// A results file's header and rows (every record after the header a row
/// of numbers, a String output's text read as NaN: a trailer line fails the
/// parse).
pub fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut reader = csv::Reader::from_reader(text.as_bytes());
    let header = reader.headers().unwrap().iter().map(String::from).collect();
    let rows = reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            let quoted =
                |field: &str| text.contains(&format!("\"{}\"", field.replace('"', "\"\"")));
            r.iter()
                .map(|v| match v.parse() {
                    Ok(x) => x,
                    Err(_) if quoted(v) => f64::NAN,
                    Err(e) => panic!("{v:?} is not a number: {e}"),
                })
                .collect()
        })
        .collect();
    (header, rows)
}

/// fmpy's model-exchange run of `fmu` (`simulate_fmu(..., fmi_type=
/// "ModelExchange", solver="CVode", relative_tolerance=1e-10)`, through
/// tests/fmpy/simulate.py) on the grid `start`, `start + step`, … `stop`
/// with `--set` values `sets`, into `out`: its header and rows.
pub fn fmpy_model_exchange(
    fmu: &Path,
    out: &Path,
    (start, stop, step): (f64, f64, f64),
    sets: &[&str],
) -> (Vec<String>, Vec<Vec<f64>>) {
    let grid = [start, stop, step].map(|v| v.to_string());
    let mut args: Vec<&std::ffi::OsStr> = vec![fmu.as_os_str(), out.as_os_str()];
    for (flag, value) in ["--start", "--stop", "--step"].iter().zip(&grid) {
        args.extend([std::ffi::OsStr::new(flag), std::ffi::OsStr::new(value)]);
    }
    for set in sets {
        args.extend([std::ffi::OsStr::new("--set"), std::ffi::OsStr::new(set)]);
    }
    for arg in [
        "--fmi-type",
        "ModelExchange",
        "--solver",
        "CVode",
        "--relative-tolerance",
        "1e-10",
    ] {
        args.push(std::ffi::OsStr::new(arg));
    }
    let run = tether_tests::fmpy::run_script("simulate.py", &args).expect("run fmpy");
    assert!(
        run.status.success(),
        "{}: {}",
        fmu.display(),
        String::from_utf8_lossy(&run.stderr)
    );
    read_csv(out)
}
