//! `tether simulate` equals fmpy's `simulate_fmu` column by column (to 1e-12
//! relative, arrays element by element) on the FMI 3.0 Reference FMUs that fmpy runs in
//! co-simulation, third-party FMUs vendored in `tests/fixtures/reference-fmus/fmi3`.
//!
//! Left out: Roberts (fmpy's co-simulation of it does not finish) and Clocks
//! (scheduled execution only: no co-simulation to compare).
//!
//! Without fmpy the test is skipped with the reason printed, unless `CI` is set: then
//! it fails.

use std::collections::HashMap;
use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::Command;

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    // Names hold no commas here ("A[2,3]" would: none of these FMUs has a matrix output).
    let header = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

/// The FMI 3.0 Reference FMU `model`; `None` where its binary does not run (the
/// test skips, see `tether_fmu_build::fixture_fmu`).
fn reference(model: &str) -> Option<PathBuf> {
    tether_fmu_build::fixture_fmu(&format!("reference-fmus/fmi3/{model}.fmu"))
}

/// The Reference FMUs fmpy runs in co-simulation, with a stop time and step.
const MODELS: &[(&str, &str, &str)] = &[
    ("BouncingBall", "3", "0.01"),
    ("Dahlquist", "10", "0.1"),
    ("Feedthrough", "2", "0.004"),
    ("Resource", "1", "0.002"),
    ("Stair", "10", "0.2"),
    ("VanDerPol", "20", "0.01"),
    ("StateSpace", "10", "0.02"),
];

#[test]
fn tether_simulate_equals_fmpy_on_the_fmi3_reference_fmus() {
    if tether_tests::tools::fmpy().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for &(model, stop, step) in MODELS {
        let Some(fmu) = reference(model) else {
            return;
        };
        let ours = dir.path().join(format!("tether-{model}.csv"));
        let theirs = dir.path().join(format!("fmpy-{model}.csv"));
        let out = Command::new(env!("CARGO_BIN_EXE_tether"))
            .arg("simulate")
            .arg(&fmu)
            .args(["--stop", stop, "--step", step, "--out"])
            .arg(&ours)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{model}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let py: Vec<&OsStr> = vec![
            fmu.as_os_str(),
            theirs.as_os_str(),
            OsStr::new("--stop"),
            OsStr::new(stop),
            OsStr::new("--step"),
            OsStr::new(step),
        ];
        let out = tether_tests::fmpy::run_script("simulate.py", &py).expect("run fmpy");
        assert!(
            out.status.success(),
            "{model}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let (h1, r1) = read_csv(&ours);
        let (h2, r2) = read_csv(&theirs);
        // fmpy orders its columns by type; the same names, compared by name.
        let mut sorted1 = h1.clone();
        let mut sorted2 = h2.clone();
        sorted1.sort();
        sorted2.sort();
        assert_eq!(sorted1, sorted2, "{model}: same columns");
        assert_eq!(r1.len(), r2.len(), "{model}: same number of rows");
        let at: HashMap<&str, usize> = h2
            .iter()
            .enumerate()
            .map(|(i, n)| (n.as_str(), i))
            .collect();
        let mut worst = 0.0f64;
        for (a, b) in r1.iter().zip(&r2) {
            for (i, x) in a.iter().enumerate() {
                let y = b[at[h1[i].as_str()]];
                worst = worst.max((x - y).abs() / x.abs().max(y.abs()).max(1e-300));
            }
        }
        eprintln!(
            "{model}: {} columns x {} rows, max relative deviation tether vs fmpy = {worst:e}",
            h1.len(),
            r1.len()
        );
        assert!(worst <= 1e-12, "{model}: deviation {worst:e}");
    }
}
