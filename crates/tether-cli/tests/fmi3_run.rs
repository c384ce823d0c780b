//! FMI 3.0 FMUs in coupled systems (`tether run`): a third-party FMI 3.0 mass, made with
//! pythonfmu3 from `tests/fixtures/pythonfmu3/Mass.py` (state handling and serialization
//! switched on at build), linked rigidly to the workspace's FMI 2.0 oscillator: the
//! paper's two-mass oscillator (Schweizer & Lu 2015, Sect. 4.1) with mass 2 an FMI 3.0
//! FMU, against the closed form and against the workspace pair.
//!
//! The Python FMU embeds the interpreter: the test runs `tether` with its libpython
//! preloaded (the Python that built it says where it is). Without Python and pythonfmu3
//! the tests are skipped with the reason printed, unless `CI` is set: then they fail.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

// The closed form of the coupled oscillator (m = m1 + m2, c = 2C, d = 2D) and
// its parameters, as the master's tests use them.
use tether_tests::oscillator::{reference, C, D, M1, M2, V0};

/// The Python FMU and the libpython it needs, built once; `None` (skip) without
/// Python or pythonfmu3 outside CI.
fn python_mass() -> Option<&'static (PathBuf, PathBuf)> {
    static BUILT: OnceLock<Option<(PathBuf, PathBuf)>> = OnceLock::new();
    BUILT
        .get_or_init(|| {
            tether_tests::fmpy::pythonfmu3_for_test("Mass").map(|b| (b.fmu, b.libpython))
        })
        .as_ref()
}

fn oscillator() -> PathBuf {
    tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU")
}

/// The paper's oscillator: mass 1 the workspace oscillator, mass 2 `mass2_fmu`
/// (the Python FMU or the workspace oscillator again).
fn system(mass2_fmu: &Path, method: &str, extra: &str) -> String {
    let exact = if mass2_fmu.ends_with("Mass.fmu") {
        ""
    } else {
        ", exact = true"
    };
    format!(
        r#"
[experiment]
stop = 1.0
step = 1e-3

[method]
{method}

[coupling]
order = 0
{extra}

[[instance]]
name = "mass1"
fmu = "{osc}"
parameters = {{ m = {M1}, c = {C}, d = {D}, x0 = 0.0, v0 = {V0}, exact = true }}

[[instance]]
name = "mass2"
fmu = "{mass2}"
parameters = {{ m = {M2}, c = {C}, d = {D}, x0 = 0.0, v0 = {V0}{exact} }}

[[constraint]]
name = "link"
position = "mass2.x - mass1.x"
velocity = "mass2.v - mass1.v"
acceleration = "mass2.a - mass1.a"
drives = "mass1.F - mass2.F"
"#,
        osc = oscillator().display(),
        mass2 = mass2_fmu.display(),
    )
}

/// Runs `tether run` on `toml` with `args`; the CSV's text and the process output.
fn run(libpython: &Path, toml: &str, args: &[&str]) -> (String, Output) {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("system.toml");
    std::fs::write(&file, toml).unwrap();
    let csv = dir.path().join("out.csv");
    let output = Command::new(env!("CARGO_BIN_EXE_tether"))
        .env("LD_PRELOAD", libpython)
        .arg("run")
        .arg(&file)
        .arg("--out")
        .arg(&csv)
        .args(args)
        .output()
        .unwrap();
    let text = std::fs::read_to_string(&csv).unwrap_or_default();
    (text, output)
}

fn ok(libpython: &Path, toml: &str, args: &[&str]) -> String {
    let (text, output) = run(libpython, toml, args);
    assert!(
        output.status.success(),
        "tether run failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    text
}

/// Max-norm errors of mass1.x, mass1.v and link.lambda against the closed form.
fn errors(csv: &str) -> [f64; 3] {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (t, x, v, l) = (
        col("time"),
        col("mass1.x"),
        col("mass1.v"),
        col("link.lambda"),
    );
    let mut e = [0.0f64; 3];
    for line in lines.filter(|l| !l.starts_with('#')) {
        let row: Vec<f64> = line.split(',').map(|s| s.parse().unwrap()).collect();
        let (rx, rv, rl) = reference(row[t]);
        e[0] = e[0].max((row[x] - rx).abs());
        e[1] = e[1].max((row[v] - rv).abs());
        e[2] = e[2].max((row[l] - rl).abs());
    }
    e
}

const BAUMGARTE_1: &str = "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6";
const WEIGHTED_2: &str = "kind = \"weighted\"\na = 1.0";

/// The FMI 3.0 mass integrates with classical Runge-Kutta (8 substeps), the
/// workspace oscillator exactly: the coupling error dominates both, and the errors
/// of x1, v1 and λ against the closed form agree within 1 %.
#[test]
fn a_pythonfmu3_mass_linked_to_the_oscillator_has_the_error_of_the_workspace_pair() {
    let Some((mass, libpython)) = python_mass() else {
        return;
    };
    for method in [BAUMGARTE_1, WEIGHTED_2] {
        let fmi3 = errors(&ok(libpython, &system(mass, method, ""), &[]));
        let fmi2 = errors(&ok(libpython, &system(&oscillator(), method, ""), &[]));
        eprintln!("{method:?}: FMI 3.0 pair errors {fmi3:?}, FMI 2.0 pair {fmi2:?}");
        for (a, b) in fmi3.iter().zip(&fmi2) {
            assert!(
                (a - b).abs() <= 0.01 * b,
                "{method}: FMI 3.0 pair {fmi3:?}, workspace pair {fmi2:?}"
            );
        }
    }
}

/// Isolation (the FMI 3.0 instance in a host process), parallel runs (the
/// instance's runs on a worker thread) and the rollback self-check at every step
/// change nothing: the same CSV bit for bit.
#[test]
fn fmi3_instances_isolated_parallel_and_self_checked_give_the_same_csv() {
    let Some((mass, libpython)) = python_mass() else {
        return;
    };
    let plain = ok(
        libpython,
        &system(mass, BAUMGARTE_1, ""),
        &["--parallel", "off"],
    );
    let isolated = ok(
        libpython,
        &system(mass, BAUMGARTE_1, ""),
        &["--isolate", "--parallel", "off"],
    );
    assert!(plain == isolated, "--isolate changed the results");
    let parallel = ok(
        libpython,
        &system(mass, BAUMGARTE_1, ""),
        &["--parallel", "on"],
    );
    assert!(plain == parallel, "--parallel on changed the results");
    let checked = ok(
        libpython,
        &system(mass, BAUMGARTE_1, "check_rollback = \"every_step\""),
        &["--parallel", "off"],
    );
    assert!(
        plain == checked,
        "check_rollback = every_step changed the results"
    );
}

/// Adaptive macro steps with an FMI 3.0 instance: the run ends at the stop time
/// within the same error of the closed form as the workspace pair (1 %).
#[test]
fn adaptive_steps_with_an_fmi3_mass_match_the_workspace_pair() {
    let Some((mass, libpython)) = python_mass() else {
        return;
    };
    let args = ["--step-rtol", "1e-4"];
    let fmi3 = ok(libpython, &system(mass, WEIGHTED_2, ""), &args);
    let fmi2 = ok(libpython, &system(&oscillator(), WEIGHTED_2, ""), &args);
    let last = |csv: &str| {
        csv.lines()
            .last()
            .unwrap()
            .split(',')
            .next()
            .unwrap()
            .to_string()
    };
    assert_eq!(last(&fmi3).parse::<f64>().unwrap(), 1.0);
    let (e3, e2) = (errors(&fmi3), errors(&fmi2));
    eprintln!("adaptive: FMI 3.0 pair errors {e3:?}, FMI 2.0 pair {e2:?}");
    for (a, b) in e3.iter().zip(&e2) {
        assert!((a - b).abs() <= 0.01 * b, "FMI 3.0 {e3:?}, FMI 2.0 {e2:?}");
    }
}

/// k > 0 on FMI 3.0 needs intermediate update, which the pythonfmu3 mass does not
/// provide: refused in one line naming the instance, before any step.
#[test]
fn coupling_polynomials_of_degree_one_are_refused_for_the_fmi3_instance() {
    let Some((mass, libpython)) = python_mass() else {
        return;
    };
    let toml = system(mass, BAUMGARTE_1, "").replace("order = 0", "order = 1");
    let (_, output) = run(libpython, &toml, &[]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success());
    let line = stderr.trim();
    assert_eq!(line.lines().count(), 1, "one line: {stderr}");
    assert_eq!(
        line,
        "error: instance 'mass2' (Mass): k > 0 needs inputs that take polynomials; the FMU \
         does not provide intermediate update (providesIntermediateUpdate), FMI 3.0's only way \
         to pass them; use order = 0"
    );
}

/// An isolated FMI 3.0 instance's macro step is two messages to its host, as an
/// FMI 2.0 one's (the batched protocol is the same for both): `round_trips` of the
/// run summary between two stop times (the setup cancels out), for the pair with
/// the FMI 3.0 mass and for the workspace pair.
#[test]
fn an_isolated_fmi3_macro_step_costs_two_round_trips_like_fmi2() {
    let Some((mass, libpython)) = python_mass() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let trips = |mass2: &Path, stop: &str| {
        let json = dir.path().join("summary.json");
        let args = ["--isolate", "--parallel", "off", "--stop", stop];
        let mut args: Vec<&str> = args.to_vec();
        args.extend(["--summary-json", json.to_str().unwrap()]);
        ok(libpython, &system(mass2, BAUMGARTE_1, ""), &args);
        let text = std::fs::read_to_string(&json).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let steps = v["macro_steps"].as_u64().unwrap();
        let per = |name: &str| v["instances"][name]["round_trips"].as_u64().unwrap();
        (steps, [per("mass1"), per("mass2")])
    };
    let per_step = |mass2: &Path| {
        let ((s0, a), (s1, b)) = (trips(mass2, "0.2"), trips(mass2, "0.4"));
        let steps = s1 - s0;
        assert!(steps >= 100, "{steps} steps");
        [
            (b[0] - a[0]) as f64 / steps as f64,
            (b[1] - a[1]) as f64 / steps as f64,
        ]
    };
    let (fmi3, fmi2) = (per_step(mass), per_step(&oscillator()));
    eprintln!("round trips per macro step: FMI 3.0 pair {fmi3:?}, FMI 2.0 pair {fmi2:?}");
    assert_eq!(fmi3, [2.0, 2.0]);
    assert_eq!(fmi2, [2.0, 2.0]);
}
