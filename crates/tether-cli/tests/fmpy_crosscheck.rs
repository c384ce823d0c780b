//! `tether simulate` and `fmpy.simulate_fmu` give the same trajectory for the
//! oscillator: the same FMU driven by two independent FMI hosts.

mod common;

use std::ffi::OsStr;
use std::process::Command;

use common::read_csv;

#[test]
fn tether_simulate_matches_fmpy_simulate_fmu() {
    if tether_tests::tools::fmpy().is_none() {
        return;
    }
    let fmu = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator");
    let dir = tempfile::tempdir().unwrap();
    for (label, sets) in [
        ("dop853", vec!["m=2", "d=3", "x0=0.1"]),
        ("exact", vec!["m=2", "d=3", "x0=0.1", "exact=true"]),
    ] {
        let ours = dir.path().join(format!("tether-{label}.csv"));
        let theirs = dir.path().join(format!("fmpy-{label}.csv"));
        let mut args = vec!["simulate".to_string(), fmu.display().to_string()];
        args.extend(["--stop", "1", "--step", "1e-3", "--out"].map(String::from));
        args.push(ours.display().to_string());
        for s in &sets {
            args.extend(["--set".to_string(), s.to_string()]);
        }
        let out = Command::new(env!("CARGO_BIN_EXE_tether"))
            .args(&args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );

        let mut py: Vec<&OsStr> = vec![fmu.as_os_str(), theirs.as_os_str()];
        let fixed = ["--stop", "1", "--step", "1e-3"];
        py.extend(fixed.iter().map(OsStr::new));
        for s in &sets {
            py.extend([OsStr::new("--set"), OsStr::new(*s)]);
        }
        let out = tether_tests::fmpy::run_script("simulate.py", &py).expect("run fmpy");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );

        let (h1, r1) = read_csv(&ours);
        let (h2, r2) = read_csv(&theirs);
        assert_eq!(h1, h2, "{label}: same columns");
        assert_eq!(r1.len(), r2.len(), "{label}: same number of rows");
        let mut worst = 0.0f64;
        for (a, b) in r1.iter().zip(&r2) {
            for (x, y) in a.iter().zip(b) {
                worst = worst.max((x - y).abs() / x.abs().max(1.0));
            }
        }
        eprintln!("{label}: max relative deviation tether vs fmpy = {worst:e}");
        assert!(worst <= 1e-12, "{label}: deviation {worst:e}");
    }
}
