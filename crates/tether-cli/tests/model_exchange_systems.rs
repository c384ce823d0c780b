//! Model-exchange instances in `tether run`: the paper's oscillator pair
//! (examples/oscillator.toml) with `fmi_type = "model_exchange"` on both
//! instances. Isolated in host processes (the integrator runs in the host)
//! and with parallel runs its results are the in-process sequential bits;
//! adaptive steps and Jacobian reuse run and stay within their tolerances of
//! the co-simulation build; `auto` says in a note why it took model exchange.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// examples/oscillator.toml in `dir` with `keys` in both instances' tables
/// and the oscillator FMU at `fmu`.
fn system(dir: &Path, keys: &str, fmu: &Path) -> PathBuf {
    let root = tether_fmu_build::workspace_root().unwrap();
    let text = std::fs::read_to_string(root.join("examples/oscillator.toml")).unwrap();
    let from = "fmu = \"../target/fmus/oscillator.fmu\"";
    assert_eq!(text.matches(from).count(), 2);
    let text = text.replace(from, &format!("fmu = \"{}\"\n{keys}", fmu.display()));
    let path = dir.join("system.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn tether(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

fn ok(out: &Output) -> String {
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert!(out.status.success(), "{err}");
    err
}

const ME: &str = "fmi_type = \"model_exchange\"\nintegrator = { method = \"rk45\", rtol = 1e-12 }";

/// Isolated (the integrator in the host), parallel (runs on workers) and
/// the plain in-process run give the same CSV, byte for byte.
#[test]
fn isolated_and_parallel_model_exchange_runs_are_the_in_process_bits() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let sys = system(dir.path(), ME, &fmu);
    let sys = sys.to_str().unwrap();
    let mut files = Vec::new();
    for (name, flags) in [
        ("plain.csv", vec!["--parallel", "off"]),
        ("isolated.csv", vec!["--parallel", "off", "--isolate"]),
        ("parallel.csv", vec!["--parallel", "on", "--threads", "2"]),
    ] {
        let mut args = vec!["run", sys, "--quiet", "--out", name];
        args.extend(flags);
        ok(&tether(&args, dir.path()));
        files.push(std::fs::read(dir.path().join(name)).unwrap());
    }
    assert!(files[0].len() > 1000);
    assert!(files[1] == files[0], "isolated differs");
    assert!(files[2] == files[0], "parallel differs");
}

/// Largest |Δ| of `column` between two CSV files of the same grid.
fn deviation(a: &Path, b: &Path, column: &str) -> f64 {
    let read = |p: &Path| {
        let text = std::fs::read_to_string(p).unwrap();
        let mut lines = text.lines().filter(|l| !l.starts_with('#'));
        let header: Vec<String> = lines
            .next()
            .unwrap()
            .split(',')
            .map(str::to_owned)
            .collect();
        let c = header.iter().position(|h| h == column).unwrap();
        lines
            .map(|l| l.split(',').nth(c).unwrap().parse::<f64>().unwrap())
            .collect::<Vec<_>>()
    };
    let (a, b) = (read(a), read(b));
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// Adaptive steps (rollback of rejected steps, steps of varying size) and
/// Jacobian reuse run on model-exchange instances and agree with the same
/// runs of the co-simulation build to within the integrators' tolerances.
#[test]
fn adaptive_steps_and_jacobian_reuse_run_on_model_exchange_instances() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = tether_fmu_build::workspace_fmu("oscillator").unwrap();
    for (flags, tol) in [
        (vec!["--step-rtol", "1e-6", "--step-atol", "1e-6"], 1e-7),
        (vec!["--jacobian", "reuse"], 1e-7),
    ] {
        let mut csv = Vec::new();
        for (keys, name) in [(ME, "me.csv"), ("", "cs.csv")] {
            let sys = system(dir.path(), keys, &fmu);
            let mut args = vec!["run", sys.to_str().unwrap(), "--quiet", "--out", name];
            args.extend(flags.iter().copied());
            ok(&tether(&args, dir.path()));
            csv.push(dir.path().join(name));
        }
        let d = deviation(&csv[0], &csv[1], "mass1.x");
        eprintln!("{flags:?}: mass1.x, model exchange against co-simulation: {d:e}");
        assert!(d < tol, "{flags:?}: {d:e}");
    }
}

/// `auto` on an oscillator FMU whose interfaces declare no FMU states: the
/// run takes model exchange for both instances, says why on stderr, and its
/// summary counts integrated steps and restored states, not `fmi2DoStep`.
#[test]
fn auto_takes_model_exchange_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let fmu = tether_tests::faulty::edited_oscillator(dir.path(), "stateless", |xml| {
        xml.replace(
            r#"canGetAndSetFMUstate="true""#,
            r#"canGetAndSetFMUstate="false""#,
        )
    });
    let sys = system(dir.path(), "", &fmu);
    let err = ok(&tether(
        &["run", sys.to_str().unwrap(), "--out", "out.csv"],
        dir.path(),
    ));
    let err = err.replace("\n  ", " ");
    for name in ["mass1", "mass2"] {
        let note = format!(
            "note: '{name}' runs model exchange (fmi_type = \"auto\"): its co-simulation interface lacks canGetAndSetFMUstate, which the predictor/corrector method baumgarte needs"
        );
        assert!(err.contains(&note), "{err}");
    }
    // The summary counts what a model-exchange instance does.
    assert!(
        err.contains("steps integrated")
            && err.contains("states restored")
            && !err.contains("DoStep"),
        "{err}"
    );
}
