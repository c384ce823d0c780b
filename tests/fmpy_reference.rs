//! Tether against the fmpy reference (`tools/fmpy_reference`): the same system
//! file run by `tether_master` and by an independent Python implementation of
//! the same equations with fmpy as the FMI host (docs/validation.md).

use std::fs::File;
use std::path::{Path, PathBuf};

use tether_master::{CsvRecorder, Method, Simulation, SystemSpec};
use tether_tests::fmpy::{python, workspace_root};

/// A result file: column names (after `time`), times, rows.
struct Results {
    names: Vec<String>,
    times: Vec<f64>,
    rows: Vec<Vec<f64>>,
    incomplete: bool,
}

fn read(path: &Path) -> Results {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    assert_eq!(header[0], "time");
    let (mut times, mut rows) = (Vec::new(), Vec::new());
    for line in lines {
        let mut values: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        times.push(values.remove(0));
        rows.push(values);
    }
    Results {
        names: header[1..].to_vec(),
        times,
        rows,
        incomplete: text.contains("\n# incomplete:"),
    }
}

/// Run `system` with tether (library) and with the fmpy reference, both with
/// `flags`; return both results.
fn both(system: &str, method: Method, order: usize, flags: &[&str]) -> (Results, Results) {
    tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU");
    let root = workspace_root();
    let file = root.join("tests").join("validation").join(system);
    let dir = tempfile::tempdir().unwrap();
    let ours: PathBuf = dir.path().join("tether.csv");
    let theirs: PathBuf = dir.path().join("fmpy.csv");

    let mut spec = SystemSpec::from_file(&file).unwrap();
    spec.method = method;
    spec.coupling.order = order;
    let mut sim = Simulation::new(&spec).unwrap();
    let mut csv = CsvRecorder::new(File::create(&ours).unwrap());
    let outcome = sim.run(&mut [&mut csv], &mut |_, _| {});
    drop(csv);

    let python = python().expect("a Python with fmpy");
    let output = std::process::Command::new(python)
        .arg(root.join("tools").join("fmpy_reference"))
        .arg(&file)
        .args(flags)
        .args(["--order", &order.to_string(), "--quiet", "--out"])
        .arg(&theirs)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(
        output.status.success(),
        outcome.is_ok(),
        "both hosts complete or both stop: tether {outcome:?}, fmpy reference: {stderr}"
    );
    (read(&ours), read(&theirs))
}

/// Max over rows of |a − b| / (max over rows of |a|, |b|), per column (the
/// measure of `tether compare`), and the column where it is largest.
fn worst(a: &Results, b: &Results, skip: &str) -> (f64, String) {
    assert_eq!(a.names, b.names, "same columns");
    assert_eq!(a.times, b.times, "same times");
    assert_eq!(a.incomplete, b.incomplete);
    let mut worst = (0.0, String::new());
    for (j, name) in a.names.iter().enumerate() {
        if name.ends_with(skip) {
            continue;
        }
        let (mut dev, mut scale) = (0.0f64, 0.0f64);
        for (ra, rb) in a.rows.iter().zip(&b.rows) {
            dev = dev.max((ra[j] - rb[j]).abs());
            scale = scale.max(ra[j].abs()).max(rb[j].abs());
        }
        let rel = if dev == 0.0 { 0.0 } else { dev / scale };
        if rel >= worst.0 {
            worst = (rel, name.clone());
        }
    }
    worst
}

#[test]
fn oscillator_agrees_with_the_fmpy_reference() {
    let variants: [(&str, Method, usize, &[&str]); 5] = [
        (
            "Method 1 index 1",
            Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6,
            },
            0,
            &["--beta", "2e-3", "--gamma", "1e-6"],
        ),
        (
            "Method 2 index 2",
            Method::Weighted { a: 1.0, b: 0.0 },
            0,
            &["--method", "weighted", "--a", "1"],
        ),
        (
            "Method 2 index 1, k = 1",
            Method::Weighted { a: 1.0, b: 1.0 },
            1,
            &["--method", "weighted", "--a", "1", "--b", "1"],
        ),
        (
            "explicit",
            Method::Explicit { mu: 1e-2 },
            0,
            &["--method", "explicit", "--mu", "1e-2"],
        ),
        (
            "Method 1 index 3, k = 1 (diverges)",
            Method::Baumgarte {
                beta: 0.0,
                gamma: 0.0,
            },
            1,
            &[],
        ),
    ];
    for (label, method, order, flags) in variants {
        let (a, b) = both("oscillator.toml", method, order, flags);
        let (rel, column) = worst(&a, &b, "\u{0}");
        eprintln!(
            "{label}: {} rows, max relative deviation {rel:e} ({column})",
            a.times.len()
        );
        assert!(a.times.len() > 10, "{label}");
        assert!(rel <= 1e-9, "{label}: {column} deviates by {rel:e}");
    }
}

/// Two multipliers coupled through a shared instance: the two hosts' linear
/// solvers round differently, and the finite-difference Jacobian amplifies
/// rounding-level differences (docs/validation.md, "Bounds").
#[test]
fn chain_of_three_masses_agrees_within_the_explained_bound() {
    let (a, b) = both(
        "chain.toml",
        Method::Baumgarte {
            beta: 2e-3,
            gamma: 0.0,
        },
        0,
        &[],
    );
    let (rel, column) = worst(&a, &b, ".g");
    eprintln!("chain, Method 1 index 2: max relative deviation {rel:e} ({column}) outside .g");
    assert!(rel <= 1e-5, "{column} deviates by {rel:e}");
    for (j, name) in a.names.iter().enumerate() {
        if name.ends_with(".g") {
            let dev = a
                .rows
                .iter()
                .zip(&b.rows)
                .map(|(x, y)| (x[j] - y[j]).abs())
                .fold(0.0, f64::max);
            eprintln!("chain: {name} max |a-b| = {dev:e}");
            assert!(dev <= 1e-9, "{name}: {dev:e}");
        }
    }
}
