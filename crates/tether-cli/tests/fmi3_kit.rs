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
/// NAME's build in `version`, and the exported pairs by `pair` and the
/// `rigid_pair_accel.fmu` beside it.
fn with_fmus(text: &str, version: FmiVersion, pair: &Path) -> String {
    let accel = pair.with_file_name("rigid_pair_accel.fmu");
    let mut out = text
        .replace("\"../target/rigid_pair.fmu\"", &format!("{pair:?}"))
        .replace("\"../target/rigid_pair_accel.fmu\"", &format!("{accel:?}"));
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

/// The examples, with the exported pairs that examples use as members
/// (`rigid_pair.fmu`, `rigid_pair_accel.fmu`) built into `dir`; the first's path.
fn examples(dir: &Path) -> (Vec<PathBuf>, PathBuf) {
    let pair = dir.join("rigid_pair.fmu");
    tether_fmu_build::workspace_fmu("oscillator").unwrap();
    for (system, fmu) in [
        ("examples/rigid_pair_export.toml", "rigid_pair.fmu"),
        (
            "examples/rigid_pair_accel_export.toml",
            "rigid_pair_accel.fmu",
        ),
    ] {
        let out = dir.join(fmu);
        let export = ["fmu", "export", system, "--out", out.to_str().unwrap()];
        success(&tether(&export, &root()));
    }
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
            .map(|l| {
                l.split(',')
                    .map(|x| x.trim().parse::<f64>().unwrap())
                    .collect()
            })
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
/// diverges at k > 0) is refused with the FMI 3.0 builds too. Not compared: the
/// systems with an exported pair as a member (`nested_three_masses`,
/// `exported_pair_feedback`): at k > 0 their coupling through the pair is rough in
/// the accelerations and multipliers (the nested pair's a at k = 1 differs from
/// k = 0 by 2 % of its magnitude, λ by its whole magnitude), which amplifies the
/// ulp-level input difference to 4e-4.
#[test]
fn every_example_at_k_above_0_with_the_fmi3_builds_gives_the_fmi2_csv() {
    let dir = tempfile::tempdir().unwrap();
    let (examples, pair) = examples(dir.path());
    let mut compared = 0;
    let mut worst = Vec::new();
    for example in &examples {
        let name = example.file_stem().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(example).unwrap();
        if text.contains("\"../target/rigid_pair") {
            continue;
        }
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

/// At k = 0 (`--order 0`), every example but `exported_pair_feedback`, whose loop
/// through the exported pair's acceleration needs its k = 2 (at k = 0 its
/// constraint breaks at t = 0.008 with either build).
#[test]
fn every_example_with_the_fmi3_builds_gives_the_fmi2_csv_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let (examples, pair) = examples(dir.path());
    for example in &examples {
        let name = example.file_stem().unwrap().to_string_lossy().into_owned();
        if name == "exported_pair_feedback" {
            continue;
        }
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

/// The oscillator example with the FMI 3.0 builds, written into `dir`.
fn fmi3_oscillator(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(root().join("examples/oscillator.toml")).unwrap();
    let system = dir.join("oscillator-fmi3.toml");
    let pair = dir.join("unused.fmu");
    std::fs::write(&system, with_fmus(&text, FmiVersion::Fmi3, &pair)).unwrap();
    system
}

/// An isolated FMI 3.0 instance at k = 1 evaluates its polynomial in the callback in
/// its host process: the CSV of the in-process instances bit for bit, and still two
/// round trips per instance and macro step (`round_trips` of the run summary between
/// two stop times; the setup cancels out).
#[test]
fn isolated_fmi3_instances_at_k_1_give_the_in_process_csv_in_two_round_trips_a_step() {
    let dir = tempfile::tempdir().unwrap();
    let system = fmi3_oscillator(dir.path());
    let csv = |name: &str| dir.path().join(name);
    let plain = run_at(
        &system,
        &csv("plain.csv"),
        dir.path(),
        "1",
        &["--parallel", "off"],
    );
    let isolated = run_at(
        &system,
        &csv("isolated.csv"),
        dir.path(),
        "1",
        &["--isolate", "--parallel", "off"],
    );
    let plain = plain.expect("the in-process run succeeds");
    assert!(plain.len() > 1000);
    assert!(
        Some(&plain) == isolated.as_ref(),
        "--isolate changed the results at k = 1"
    );
    let trips = |stop: &str| {
        let json = dir.path().join(format!("summary-{stop}.json"));
        let args = [
            "--isolate",
            "--parallel",
            "off",
            "--stop",
            stop,
            "--summary-json",
            json.to_str().unwrap(),
        ];
        run_at(&system, &csv("trips.csv"), dir.path(), "1", &args).expect("the run succeeds");
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let per = |name: &str| v["instances"][name]["round_trips"].as_u64().unwrap();
        (
            v["macro_steps"].as_u64().unwrap(),
            [per("mass1"), per("mass2")],
        )
    };
    let ((s0, a), (s1, b)) = (trips("0.2"), trips("0.4"));
    let steps = (s1 - s0) as f64;
    assert!(steps >= 100.0, "{steps} steps");
    let per_step = [(b[0] - a[0]) as f64 / steps, (b[1] - a[1]) as f64 / steps];
    println!("round trips per macro step at k = 1: {per_step:?}");
    assert_eq!(per_step, [2.0, 2.0]);
}

/// The intermediate update callback only where polynomials go: at k = 0 the FMI 3.0
/// builds get no callback and make none, at k = 1 they call back twice in each
/// `fmi3DoStep` (at T_N + H/2 and T_{N+1}), in this process and in an isolated
/// instance's host alike. The kit logs each callback and each step (logEvents), so
/// the counts are the FMU's own.
#[test]
fn the_fmi3_builds_are_called_back_only_at_k_above_0() {
    let dir = tempfile::tempdir().unwrap();
    let system = fmi3_oscillator(dir.path());
    let csv = dir.path().join("log.csv");
    for isolation in [&[][..], &["--isolate"][..]] {
        for k in ["0", "1"] {
            let mut args = vec![
                "run",
                system.to_str().unwrap(),
                "--order",
                k,
                "--stop",
                "0.01",
                "--parallel",
                "off",
                "--fmu-log=logEvents",
                "--fmu-log-limit",
                "off",
                "--out",
                csv.to_str().unwrap(),
            ];
            args.extend_from_slice(isolation);
            let text = success(&tether(&args, dir.path()));
            let count = |instance: &str, what: &str| {
                text.lines()
                    .filter(|l| l.contains(&format!("fmu::{instance}]")) && l.contains(what))
                    .count()
            };
            for instance in ["mass1", "mass2"] {
                let steps = count(instance, "[logEvents] step ");
                let callbacks = count(instance, "[logEvents] intermediate update at t = ");
                println!("{isolation:?} k = {k}, {instance}: {steps} steps, {callbacks} callbacks");
                assert!(steps >= 10, "{isolation:?} k = {k}: {steps} steps\n{text}");
                let expected = if k == "0" { 0 } else { 2 * steps };
                assert_eq!(
                    callbacks, expected,
                    "{isolation:?} k = {k}, {instance}\n{text}"
                );
            }
        }
    }
}

/// Adaptive steps at k = 1 with the FMI 3.0 builds: the error estimate compares the
/// predicted and corrected runs, each taking its polynomial through intermediate
/// update. The run ends at the stop time after as many steps as with the FMI 2.0
/// builds, and its errors of x₁, v₁ and λ against the closed form are theirs within
/// 1 % (the step sizes follow the estimate, which the rounding of the intermediate
/// values moves a little).
#[test]
fn adaptive_steps_at_k_1_with_the_fmi3_builds_follow_the_fmi2_builds() {
    use tether_tests::oscillator::reference;
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("examples/oscillator.toml")).unwrap();
    let pair = dir.path().join("unused.fmu");
    let mut results = Vec::new();
    for version in [FmiVersion::Fmi2, FmiVersion::Fmi3] {
        let system = dir.path().join(format!("oscillator-{version:?}.toml"));
        std::fs::write(&system, with_fmus(&text, version, &pair)).unwrap();
        let out = dir.path().join(format!("adaptive-{version:?}.csv"));
        let csv = run_at(&system, &out, dir.path(), "1", &["--step-rtol", "1e-4"])
            .expect("the adaptive run succeeds");
        let text = String::from_utf8(csv).unwrap();
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        let (x, v, l) = (col("mass1.x"), col("mass1.v"), col("link.lambda"));
        let (mut rows, mut last, mut e) = (0, 0.0, [0.0f64; 3]);
        for line in lines.filter(|l| !l.starts_with('#')) {
            let row: Vec<f64> = line.split(',').map(|s| s.parse().unwrap()).collect();
            let (rx, rv, rl) = reference(row[0]);
            e[0] = e[0].max((row[x] - rx).abs());
            e[1] = e[1].max((row[v] - rv).abs());
            e[2] = e[2].max((row[l] - rl).abs());
            rows += 1;
            last = row[0];
        }
        results.push((rows, last, e));
    }
    let ((rows2, _, e2), (rows3, last3, e3)) = (results[0], results[1]);
    println!("adaptive steps at k = 1: FMI 2.0 {rows2} rows, errors {e2:?}; FMI 3.0 {rows3} rows, errors {e3:?}");
    assert!(rows2 > 10 && rows2 < 1000, "{rows2} rows");
    assert_eq!(rows2, rows3);
    assert_eq!(last3, 1.0, "ends at the stop time");
    for (a, b) in e3.iter().zip(&e2) {
        assert!((a - b).abs() <= 0.01 * b, "FMI 3.0 {e3:?}, FMI 2.0 {e2:?}");
    }
}

/// k > 0 on an FMI 3.0 FMU without intermediate update for its coupled input: the
/// Reference FMU `Feedthrough` provides intermediate update, but its input
/// `Float64_continuous_input` does not declare `intermediateUpdate="true"`: refused
/// before the run, in one line naming the instance and the input.
#[test]
fn k_1_into_an_fmi3_input_without_intermediate_update_is_refused_by_name() {
    let Some(reference) = tether_fmu_build::fixture_fmu("reference-fmus/fmi3/Feedthrough.fmu")
    else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let oscillator = tether_fmu_build::workspace_fmu_as("oscillator", FmiVersion::Fmi3).unwrap();
    let system = dir.path().join("feedthrough.toml");
    std::fs::write(
        &system,
        format!(
            r#"
[experiment]
stop = 0.1
step = 1e-3

[method]
kind = "baumgarte"

[[instance]]
name = "mass1"
fmu = {oscillator:?}

[[instance]]
name = "ft"
fmu = {reference:?}

[[constraint]]
name = "link"
position = "ft.Float64_continuous_output - mass1.x"
drives = "mass1.F - ft.Float64_continuous_input"
initial = 0.0
"#
        ),
    )
    .unwrap();
    let output = tether(
        &[
            "run",
            system.to_str().unwrap(),
            "--order",
            "1",
            "--quiet",
            "--out",
            dir.path().join("out.csv").to_str().unwrap(),
        ],
        dir.path(),
    );
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "k = 1 ran: {stderr}");
    // Index 3 at k = 1 is also warned about as unstable: one error line.
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| !l.starts_with("warning:"))
        .collect();
    assert_eq!(errors.len(), 1, "one line: {stderr}");
    let line = errors[0];
    assert_eq!(
        line,
        "error: instance 'ft' (Feedthrough): k > 0 needs inputs that take polynomials; \
         input 'Float64_continuous_input' is not declared intermediateUpdate=\"true\"; \
         use order = 0"
    );
}
