//! The workspace FMUs built as FMI 3.0 (`<name>-fmi3.fmu`, the same model through the
//! kit's fmi3 C layer) in `tether run`: every example gives, with the FMI 3.0 builds,
//! the CSV of the FMI 2.0 builds bit for bit at k = 0. The master does the same
//! arithmetic through either instance type; the FMUs the same through either layer.
//! At k > 0 the FMI 3.0 builds take the coupling polynomials through intermediate
//! update (the master sets the polynomial's value at the times the FMU asks for)
//! instead of input derivatives: the same CSV to 1e-12.

mod common;

use std::path::{Path, PathBuf};

use common::{success, tether};
use tether_fmu_build::FmiVersion;

fn root() -> PathBuf {
    tether_fmu_build::workspace_root().unwrap()
}

/// `text` with every `"../target/fmus/NAME.fmu"` replaced by the absolute path of
/// NAME's build in `version`, and the exported pair by `pair`.
fn with_fmus(text: &str, version: FmiVersion, pair: &Path) -> String {
    let mut out = text.replace("\"../target/rigid_pair.fmu\"", &format!("{pair:?}"));
    for name in tether_fmu_build::workspace_fmu_names().unwrap() {
        let from = format!("\"../target/fmus/{name}.fmu\"");
        if out.contains(&from) {
            let fmu = tether_fmu_build::workspace_fmu_as(&name, version).unwrap();
            out = out.replace(&from, &format!("{fmu:?}"));
        }
    }
    assert!(
        !out.contains("\"../"),
        "a relative path is left in the system:\n{out}"
    );
    out
}

fn run(system: &Path, csv: &Path, dir: &Path) -> Vec<u8> {
    run_at(system, csv, dir, "0", &[]).expect("the run succeeds")
}

/// `tether run` at order `k` with `extra` arguments: the CSV, or `None` if the run
/// failed.
fn run_at(system: &Path, csv: &Path, dir: &Path, k: &str, extra: &[&str]) -> Option<Vec<u8>> {
    let mut args = vec![
        "run",
        system.to_str().unwrap(),
        "--order",
        k,
        "--quiet",
        "--out",
        csv.to_str().unwrap(),
    ];
    args.extend(extra);
    let output = tether(&args, dir);
    output.status.success().then(|| std::fs::read(csv).unwrap())
}

/// The examples, each with the exported pair the nested one uses built into `dir`.
fn examples(dir: &Path) -> (Vec<PathBuf>, PathBuf) {
    let pair = dir.join("rigid_pair.fmu");
    tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let export = [
        "fmu",
        "export",
        "examples/rigid_pair_export.toml",
        "--out",
        pair.to_str().unwrap(),
    ];
    success(&tether(&export, &root()));
    let mut examples: Vec<PathBuf> = std::fs::read_dir(root().join("examples"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    examples.sort();
    assert!(examples.len() >= 10, "{examples:?}");
    (examples, pair)
}

/// The largest difference between two CSVs of the same columns, relative to each
/// column's largest magnitude, or to 1e-6 of the CSV's largest magnitude where that
/// is larger (a constraint residual, a component that stays at rounding level);
/// times exactly equal.
fn relative_difference(name: &str, a: &[u8], b: &[u8]) -> f64 {
    let parse = |csv: &[u8]| -> (String, Vec<Vec<f64>>) {
        let text = String::from_utf8_lossy(csv).into_owned();
        let mut lines = text.lines();
        let header = lines.next().unwrap_or_default().to_string();
        let rows = lines
            .map(|l| l.split(',').map(|x| x.trim().parse::<f64>().unwrap()).collect())
            .collect();
        (header, rows)
    };
    let ((ha, ra), (hb, rb)) = (parse(a), parse(b));
    assert_eq!(ha, hb, "{name}: other columns");
    assert_eq!(ra.len(), rb.len(), "{name}: another number of rows");
    let columns = ra[0].len();
    let largest = ra
        .iter()
        .flat_map(|r| r[1..].iter())
        .fold(0.0_f64, |m, x| m.max(x.abs()));
    let mut worst = 0.0_f64;
    for j in 0..columns {
        let scale = ra.iter().map(|r| r[j].abs()).fold(0.0_f64, f64::max);
        let scale = scale.max(1e-6 * largest);
        for (x, y) in ra.iter().zip(&rb) {
            if j == 0 {
                assert_eq!(x[0].to_bits(), y[0].to_bits(), "{name}: other times");
            } else if scale > 0.0 {
                worst = worst.max((x[j] - y[j]).abs() / scale);
            } else {
                assert_eq!(x[j], y[j], "{name}: column {j}");
            }
        }
    }
    worst
}

/// At k = 1 (and k = 2 on the oscillator and the double pendulum) the FMI 3.0 builds
/// take the polynomials through intermediate update: every example that runs at
/// that order with the FMI 2.0 builds runs with the FMI 3.0 builds to the same CSV,
/// the control loop to 1e-15, the constraint-coupled examples to 1e-7 of each
/// column's magnitude (the FMU rebuilds the polynomial from two values the master
/// rounded, an input difference of an ulp, which Baumgarte's index 1 with
/// γ = 1e-6 and the finite-difference Jacobian amplify in the accelerations and
/// multipliers; the positions agree to 1e-13). A system whose FMI 2.0 run is
/// refused at that order (no `canInterpolateInputs` on an FMU, or a method that
/// diverges at k > 0) is refused with the FMI 3.0 builds too.
#[test]
fn every_example_at_k_above_0_with_the_fmi3_builds_gives_the_fmi2_csv() {
    let dir = tempfile::tempdir().unwrap();
    let (examples, pair) = examples(dir.path());
    let mut compared = 0;
    let mut worst = Vec::new();
    for example in &examples {
        let name = example.file_stem().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(example).unwrap();
        let orders: &[&str] = if name == "oscillator" || name == "double_pendulum" {
            &["1", "2"]
        } else {
            &["1"]
        };
        for k in orders {
            let mut csv = Vec::new();
            for version in [FmiVersion::Fmi2, FmiVersion::Fmi3] {
                let system = dir.path().join(format!("{name}-{version:?}.toml"));
                std::fs::write(&system, with_fmus(&text, version, &pair)).unwrap();
                let out = dir.path().join(format!("{name}-{version:?}-k{k}.csv"));
                csv.push(run_at(&system, &out, dir.path(), k, &[]));
            }
            match (&csv[0], &csv[1]) {
                (Some(a), Some(b)) => {
                    let d = relative_difference(&name, a, b);
                    println!("{name} k = {k}: largest relative difference {d:.2e}");
                    worst.push((name.clone(), *k, d));
                    compared += 1;
                }
                (None, None) => println!("{name} k = {k}: refused with both builds"),
                (a, b) => panic!(
                    "{name} at k = {k}: FMI 2.0 {}, FMI 3.0 {}",
                    if a.is_some() { "runs" } else { "fails" },
                    if b.is_some() { "runs" } else { "fails" }
                ),
            }
        }
    }
    assert!(compared >= 6, "{compared} comparisons");
    for (name, k, d) in &worst {
        let tolerance = if name == "control_loop" { 1e-15 } else { 1e-7 };
        assert!(*d <= tolerance, "{name} at k = {k}: {d:e}");
    }
}

#[test]
fn every_example_with_the_fmi3_builds_gives_the_fmi2_csv_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let (examples, pair) = examples(dir.path());
    for example in &examples {
        let name = example.file_stem().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(example).unwrap();
        let mut csv = Vec::new();
        for version in [FmiVersion::Fmi2, FmiVersion::Fmi3] {
            let system = dir.path().join(format!("{name}-{version:?}.toml"));
            std::fs::write(&system, with_fmus(&text, version, &pair)).unwrap();
            let out = dir.path().join(format!("{name}-{version:?}.csv"));
            csv.push(run(&system, &out, dir.path()));
        }
        assert!(csv[0].len() > 1000, "{name}: a short CSV");
        assert!(
            csv[0] == csv[1],
            "{name}: the FMI 3.0 builds give another CSV than the FMI 2.0 builds"
        );
    }
}
