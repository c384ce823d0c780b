//! FMI 3.0 arrays wherever a variable is named, on the Reference FMU `StateSpace`
//! (third-party, vendored in `tests/fixtures/reference-fmus/fmi3`): whole arrays and elements set as
//! start values (`tether simulate --set`, a system file's `parameters`), elements in a
//! constraint's expressions and `drives`, element columns in `tether run`, and one
//! clear line for every name that does not fit.
//!
//! `StateSpace` computes ẋ = A x + B u, y = C x + D u with n = m = r = 3 and steps
//! forward Euler at a fixed internal step of 1e-3 (its `FIXED_SOLVER_STEP`); its
//! structural parameters cannot be changed (its `fmi3SetUInt64` fails for every
//! call, see [`the_reference_statespace_refuses_its_structural_parameters`]), and it
//! ignores `x0` (its state starts at 0).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The Reference FMU `StateSpace`; `None` where its binary does not run (the test
/// skips, see `tether_fmu_build::fixture_fmu`).
fn statespace() -> Option<PathBuf> {
    tether_fmu_build::fixture_fmu("reference-fmus/fmi3/StateSpace.fmu")
}

/// The Reference FMU `Feedthrough`, as [`statespace`].
fn feedthrough() -> Option<PathBuf> {
    tether_fmu_build::fixture_fmu("reference-fmus/fmi3/Feedthrough.fmu")
}

fn oscillator() -> PathBuf {
    tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU")
}

fn tether(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .output()
        .unwrap()
}

/// The one line `tether` printed on stderr for a run that must fail.
fn one_line(output: &Output) -> String {
    assert!(!output.status.success(), "the run should fail");
    let stderr = String::from_utf8_lossy(&output.stderr).trim().to_string();
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    stderr
}

/// CSV text → header and rows (array names hold a comma, `A[2,3]`: split outside
/// brackets).
fn read_csv(text: &str) -> (Vec<String>, Vec<Vec<f64>>) {
    let split = |line: &str| -> Vec<String> {
        let (mut out, mut depth, mut cur) = (Vec::new(), 0, String::new());
        for c in line.chars() {
            match c {
                '[' => depth += 1,
                ']' => depth -= 1,
                ',' if depth == 0 => {
                    out.push(std::mem::take(&mut cur));
                    continue;
                }
                _ => {}
            }
            cur.push(c);
        }
        out.push(cur);
        out
    };
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header = split(lines.next().unwrap());
    let rows = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

// The joined masses: mass 1 the workspace oscillator (exact integration), mass 2
// StateSpace as a damped mass on a spring, state [x, v, unused], force u[1],
// outputs y = [x, v, a]; both start at rest, a constant force F0 pulls mass 1.
const M1: f64 = 1.0;
const M2: f64 = 2.0;
const C: f64 = 10.0;
const D: f64 = 1.0;
const F0: f64 = 10.0;

/// The system file: the method and the macro step.
fn joined(method: &str, step: f64, ss: &Path) -> String {
    let (k, d) = (C / M2, D / M2);
    let b = 1.0 / M2;
    format!(
        r#"
[experiment]
stop = 2.0
step = {step}

[method]
{method}

[coupling]
order = 0

[[instance]]
name = "mass1"
fmu = "{osc}"
parameters = {{ m = {M1}, c = {C}, d = {D}, x0 = 0.0, v0 = 0.0, exact = true, F_ext = {F0} }}

[[instance]]
name = "ss"
fmu = "{ss}"

[instance.parameters]
A = [[0.0, 1.0, 0.0], [-{k}, -{d}, 0.0], [0.0, 0.0, 0.0]]
B = [0.0, 0.0, 0.0, {b}, 0.0, 0.0, 0.0, 0.0, 0.0]
C = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-{k}, -{d}, 0.0]]
D = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [{b}, 0.0, 0.0]]
"u[2]" = 0.0
"u[3]" = 0.0

[[constraint]]
name = "link"
position = "ss.y[1] - mass1.x"
velocity = "ss.y[2] - mass1.v"
acceleration = "ss.y[3] - mass1.a"
drives = "mass1.F - ss.u[1]"
"#,
        osc = oscillator().display(),
        ss = ss.display(),
    )
}

/// Closed form of the joined masses (m = M1 + M2, c = 2C, d = 2D, from rest under
/// F0): x, v and the multiplier λ = M1·a − F0 + C·x + D·v at time t.
fn closed_form(t: f64) -> (f64, f64, f64) {
    let (m, c, d) = (M1 + M2, 2.0 * C, 2.0 * D);
    let delta = d / (2.0 * m);
    let wd = (c / m - delta * delta).sqrt();
    let (s, co, e) = ((wd * t).sin(), (wd * t).cos(), (-delta * t).exp());
    let x = F0 / c * (1.0 - e * (co + delta / wd * s));
    let v = F0 / c * e * (delta * delta / wd + wd) * s;
    let a = (F0 - c * x - d * v) / m;
    (x, v, M1 * a - F0 + C * x + D * v)
}

/// `tether run` of `toml`; the CSV's text.
fn run(toml: &str, dir: &Path) -> String {
    let file = dir.join("system.toml");
    std::fs::write(&file, toml).unwrap();
    let csv = dir.join("out.csv");
    let out = tether(&[
        "run",
        file.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "tether run failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::read_to_string(&csv).unwrap()
}

/// Max errors of mass1.x, mass1.v (whole run) and link.lambda (after t = 0.1, past
/// the first steps' transient) against the closed form, and the largest |y[1] − x1|.
fn errors(csv: &str) -> [f64; 4] {
    let (header, rows) = read_csv(csv);
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (t, x, v, l, y1) = (
        col("time"),
        col("mass1.x"),
        col("mass1.v"),
        col("link.lambda"),
        col("ss.y[1]"),
    );
    let mut e = [0.0f64; 4];
    for row in &rows {
        let (rx, rv, rl) = closed_form(row[t]);
        e[0] = e[0].max((row[x] - rx).abs());
        e[1] = e[1].max((row[v] - rv).abs());
        if row[t] > 0.1 {
            e[2] = e[2].max((row[l] - rl).abs());
        }
        e[3] = e[3].max((row[y1] - row[x]).abs());
    }
    e
}

const WEIGHTED_2: &str = "kind = \"weighted\"\na = 1.0";
const BAUMGARTE_1: &str = "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6";

/// StateSpace (matrices set whole, nested and flat; two input elements set one by
/// one) joined rigidly to the workspace oscillator through its array elements
/// follows the closed form of the joined masses. The error is StateSpace's own
/// forward Euler at its fixed step 1e-3, not the coupling's: it is the same (to 1 %)
/// at macro steps 1e-3 and 2e-3, where the workspace pair's coupling error would
/// double. Measured: max |x1 − x| = 7.9e-4 (0.16 % of the static deflection
/// F0/2C = 0.5), max |v1 − v| = 2.5e-3, λ after 0.1 s within 4e-3 of its closed form
/// (|λ| ≈ 5.4), the constraint held to 1e-6.
#[test]
fn statespace_joined_to_the_oscillator_follows_the_closed_form_of_the_joined_masses() {
    let Some(ss) = statespace() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    for method in [WEIGHTED_2, BAUMGARTE_1] {
        let csv = run(&joined(method, 1e-3, &ss), dir.path());
        let (header, _) = read_csv(&csv);
        for column in ["ss.y[1]", "ss.y[2]", "ss.y[3]"] {
            assert!(header.iter().any(|h| h == column), "{column} in {header:?}");
        }
        let fine = errors(&csv);
        let coarse = errors(&run(&joined(method, 2e-3, &ss), dir.path()));
        eprintln!(
            "{method:?}: errors (x, v, λ after 0.1 s, |g|) H = 1e-3 {fine:?}, H = 2e-3 {coarse:?}"
        );
        assert!(
            fine[0] < 1e-3 && fine[1] < 3e-3 && fine[2] < 5e-3,
            "{fine:?}"
        );
        assert!(fine[3] < 1e-5, "constraint residual {}", fine[3]);
        for k in 0..2 {
            assert!(
                (fine[k] - coarse[k]).abs() <= 0.01 * fine[k],
                "error does not follow the macro step: {fine:?} vs {coarse:?}"
            );
        }
    }
}

/// `tether simulate` with whole arrays (nested and flat) and an element set by
/// `--set` equals fmpy's `simulate_fmu` given the same values as arrays, element by
/// element, to 1e-12 relative.
#[test]
fn statespace_with_arrays_set_equals_fmpy() {
    if tether_tests::tools::fmpy().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let ours = dir.path().join("tether.csv");
    let theirs = dir.path().join("fmpy.csv");
    let Some(fmu) = statespace() else {
        return;
    };
    let out = tether(&[
        "simulate",
        fmu.to_str().unwrap(),
        "--stop",
        "2",
        "--step",
        "0.01",
        "--set",
        "A=[[0, 1, 0], [-5, -0.5, 0], [0, 0, -1]]",
        "--set",
        "B=[0, 0, 0, 0.5, 0, 0, 0, 0, 1]",
        "--set",
        "C=[[1, 0, 0], [0, 1, 0], [-5, -0.5, 0]]",
        "--set",
        "D=[[0, 0, 0], [0, 0, 0], [0.5, 0, 0]]",
        "--set",
        "u=[1, 0, 0]",
        "--set",
        "u[3]=2",
        "--out",
        ours.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let sets = [
        "A=0 1 0 -5 -0.5 0 0 0 -1",
        "B=0 0 0 0.5 0 0 0 0 1",
        "C=1 0 0 0 1 0 -5 -0.5 0",
        "D=0 0 0 0 0 0 0.5 0 0",
        "u=1 0 2",
    ];
    let mut args: Vec<&std::ffi::OsStr> = vec![
        fmu.as_os_str(),
        theirs.as_os_str(),
        "--stop".as_ref(),
        "2".as_ref(),
        "--step".as_ref(),
        "0.01".as_ref(),
    ];
    for s in &sets {
        args.push("--set".as_ref());
        args.push(s.as_ref());
    }
    let out = tether_tests::fmpy::run_script("simulate.py", &args).expect("run fmpy");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (h1, r1) = read_csv(&std::fs::read_to_string(&ours).unwrap());
    let (h2, r2) = read_csv(&std::fs::read_to_string(&theirs).unwrap());
    assert_eq!(h1, h2);
    assert_eq!(r1.len(), r2.len());
    let mut worst = 0.0f64;
    let mut moved = 0.0f64;
    for (a, b) in r1.iter().zip(&r2) {
        for (x, y) in a.iter().zip(b) {
            worst = worst.max((x - y).abs() / x.abs().max(y.abs()).max(1e-300));
        }
        moved = moved.max(a[1].abs());
    }
    eprintln!("StateSpace with arrays set: max relative deviation tether vs fmpy = {worst:e}");
    assert!(worst <= 1e-12, "deviation {worst:e}");
    assert!(
        moved > 0.01,
        "the force moved the mass: max |y[1]| = {moved}"
    );
}

/// Names that do not fit get one line naming the instance, the name, where it
/// appears and the valid range.
#[test]
fn array_names_that_do_not_fit_are_refused_in_one_line() {
    let Some(ss) = statespace() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let base = joined(WEIGHTED_2, 1e-3, &ss);
    let case = |from: &str, to: &str| {
        assert!(base.contains(from), "{from}");
        let file = dir.path().join("bad.toml");
        std::fs::write(&file, base.replace(from, to)).unwrap();
        one_line(&tether(&["run", file.to_str().unwrap(), "--stop", "0.01"]))
    };
    let line = case(
        r#"position = "ss.y[1] - mass1.x""#,
        r#"position = "ss.y[4] - mass1.x""#,
    );
    assert!(
        line.contains("constraint 'link', position")
            && line.contains("instance 'ss'")
            && line.contains("'y[4]'")
            && line.contains("1..=3"),
        "{line}"
    );
    let line = case(
        r#"drives = "mass1.F - ss.u[1]""#,
        r#"drives = "mass1.F - ss.u[1,1]""#,
    );
    assert!(
        line.contains("drives") && line.contains("'u[1,1]'") && line.contains("1 dimension"),
        "{line}"
    );
    let line = case(
        r#"position = "ss.y[1] - mass1.x""#,
        r#"position = "ss.y[1] - mass1.x[1]""#,
    );
    assert!(
        line.contains("instance 'mass1'") && line.contains("'x[1]'") && line.contains("scalar"),
        "{line}"
    );
    let line = case(
        r#"position = "ss.y[1] - mass1.x""#,
        r#"position = "ss.y - mass1.x""#,
    );
    assert!(
        line.contains("'y'") && line.contains("it is an array") && line.contains("y[1]"),
        "{line}"
    );
    let line = case(
        "B = [0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0]",
        "B = [0.0, 0.5]",
    );
    assert!(
        line.contains("instance 'ss'")
            && line.contains("B")
            && line.contains("3×3 = 9 elements")
            && line.contains("has 2"),
        "{line}"
    );
    let line = case(r#""u[3]" = 0.0"#, r#""u[0]" = 0.0"#);
    assert!(
        line.contains("'u[0]'") && line.contains("1-based"),
        "{line}"
    );
    // tether simulate --set: the same checks.
    let fmu = &ss;
    let line = one_line(&tether(&[
        "simulate",
        fmu.to_str().unwrap(),
        "--set",
        "A[4,1]=1",
        "--out",
        dir.path().join("x.csv").to_str().unwrap(),
    ]));
    assert!(
        line.contains("--set A[4,1]") && line.contains("'A[4,1]'") && line.contains("dimension 1"),
        "{line}"
    );
}

/// The Reference StateSpace's `fmi3SetUInt64` advances its value index before it
/// checks it, so every set of `n`, `m` or `r` fails in the FMU (nValues = 1 is
/// "Expected nValues >= 2"); Tether sets them in configuration mode as the standard
/// says and reports the FMU's refusal in one line with its message (after the
/// messages the FMU logs itself).
#[test]
fn the_reference_statespace_refuses_its_structural_parameters() {
    let dir = tempfile::tempdir().unwrap();
    let Some(fmu) = statespace() else {
        return;
    };
    let out = tether(&[
        "simulate",
        fmu.to_str().unwrap(),
        "--set",
        "n=2",
        "--out",
        dir.path().join("x.csv").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let line = stderr.trim().lines().last().unwrap_or_default().to_string();
    assert!(line.starts_with("error: "), "{stderr}");
    assert!(
        line.contains("fmi3SetUInt64") && line.contains("Expected nValues >= 2"),
        "{line}"
    );
}

/// Typed start values on the Reference FMU `Feedthrough`: a String value is text, a
/// Binary value hexadecimal text (either case); Int64 and UInt64 values pass through
/// exactly, also beyond 2^53 where a float would round them (the CSV column holds
/// the integer's digits). Text that is not hexadecimal and a value outside the
/// variable's type are refused in one line naming the variable.
#[test]
fn feedthrough_takes_typed_values_and_64_bit_integers_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let Some(fmu) = feedthrough() else {
        return;
    };
    let csv = dir.path().join("out.csv");
    let simulate = |sets: &[&str]| {
        let mut args = vec![
            "simulate",
            fmu.to_str().unwrap(),
            "--stop",
            "0.1",
            "--step",
            "0.1",
            "--out",
            csv.to_str().unwrap(),
        ];
        for s in sets {
            args.extend(["--set", s]);
        }
        tether(&args)
    };
    let out = simulate(&[
        "String_input=hello",
        "Binary_input=0A0bff",
        "Int64_input=-9007199254740993",
        "UInt64_input=9223372036854775807",
        "Int32_input=-7",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for row in text.lines().skip(1) {
        let row: Vec<&str> = row.split(',').collect();
        assert_eq!(row[col("Int64_output")], "-9007199254740993", "{text}");
        assert_eq!(row[col("UInt64_output")], "9223372036854775807", "{text}");
        assert_eq!(row[col("Int32_output")].parse::<f64>().unwrap(), -7.0);
    }
    let line = one_line(&simulate(&["Binary_input=xyz"]));
    assert!(
        line.contains("Feedthrough") && line.contains("\"xyz\" is not hexadecimal"),
        "{line}"
    );
    let line = one_line(&simulate(&["Int8_input=300"]));
    assert!(
        line.contains("fmi3SetInt8")
            && line.contains("300 is outside the range of Int8 'Int8_input'"),
        "{line}"
    );
    let line = one_line(&simulate(&["UInt64_input=-1"]));
    assert!(
        line.contains("-1 is outside the range of UInt64 'UInt64_input'"),
        "{line}"
    );
    let line = one_line(&simulate(&["Float64_continuous_input=9007199254740993"]));
    assert!(
        line.contains("Float64_continuous_input")
            && line.contains("the integer 9007199254740993 has no exact Real value"),
        "{line}"
    );
}

/// In a system, an Int64 output beyond 2^53 is recorded exactly, in process and
/// isolated alike; a signal
/// connection, which carries Reals, refuses it in one line naming the
/// connection, the variable, the value and the time.
#[test]
fn a_system_records_64_bit_integers_exactly_and_a_connection_refuses_what_a_float_rounds() {
    let dir = tempfile::tempdir().unwrap();
    let Some(fmu) = feedthrough() else {
        return;
    };
    let system = |connect: &str| {
        format!(
            r#"
[experiment]
stop = 0.3
step = 0.1

[[instance]]
name = "a"
fmu = "{fmu}"
parameters = {{ Int64_input = 9007199254740993 }}

[[instance]]
name = "b"
fmu = "{fmu}"
{connect}
"#,
            fmu = fmu.display()
        )
    };
    let text = run(&system(""), dir.path());
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "a.Int64_output").unwrap();
    assert_eq!(text.lines().count(), 5, "{text}");
    for row in text.lines().skip(1) {
        assert_eq!(row.split(',').nth(col), Some("9007199254740993"), "{text}");
    }
    // The same through host processes (the integers cross the protocol whole).
    let isolated = system("").replace("fmu = ", "isolation = \"process\"\nfmu = ");
    assert_eq!(run(&isolated, dir.path()), text);
    let file = dir.path().join("connected.toml");
    let connect = "\n[[connection]]\nfrom = \"a.Int64_output\"\nto = \"b.Int64_input\"\n";
    std::fs::write(&file, system(connect)).unwrap();
    let line = one_line(&tether(&[
        "run",
        file.to_str().unwrap(),
        "--out",
        dir.path().join("connected.csv").to_str().unwrap(),
    ]));
    assert!(
        line.contains("a.Int64_output")
            && line.contains("'Int64_output' = 9007199254740993 at t = 0")
            && line.contains("no exact Real value"),
        "{line}"
    );
}

/// The pythonfmu3 FMU of tests/fixtures/pythonfmu3/Decays.py, built once; `None`
/// (skip) without Python or pythonfmu3 outside CI.
fn decays() -> Option<tether_tests::fmpy::PythonFmu> {
    tether_tests::fmpy::pythonfmu3_for_test("Decays")
}

/// Structural parameters end to end on a third-party FMU: the pythonfmu3 FMU
/// `Decays` (tests/fixtures/pythonfmu3/Decays.py) has an output array x of n
/// elements, n a fixed structural parameter (3 by default), x_i(t) = exp(−i·t).
/// `parameters = { n = 5 }` (set in configuration mode) makes x and its columns
/// follow: `d.x[1]` … `d.x[5]`, each the closed form to 1e-15 relative, and
/// `d.x[5]` a name a connection can take; at the default n = 3 that name is
/// refused in one line. The instance runs isolated: pythonfmu3's runtime can
/// abort the process that loaded it at exit (its interpreter finalizer reads an
/// object already freed), after the results, and isolated that exit is the host's.
#[test]
fn a_structural_parameter_resizes_the_array_its_columns_and_its_names() {
    let Some(py) = decays() else { return };
    let dir = tempfile::tempdir().unwrap();
    let system = |parameters: &str| {
        format!(
            r#"
[experiment]
stop = 0.5
step = 0.1

[[instance]]
name = "d"
fmu = "{decays}"
isolation = "process"
{parameters}

[[instance]]
name = "o"
fmu = "{osc}"
parameters = {{ exact = true }}

[[connection]]
from = "d.x[5]"
to = "o.F"
"#,
            decays = py.fmu.display(),
            osc = oscillator().display()
        )
    };
    let run = |toml: &str, name: &str| {
        let file = dir.path().join(format!("{name}.toml"));
        std::fs::write(&file, toml).unwrap();
        py.env(&mut Command::new(env!("CARGO_BIN_EXE_tether")))
            .args(["run", file.to_str().unwrap(), "--out"])
            .arg(dir.path().join(format!("{name}.csv")))
            .output()
            .unwrap()
    };
    let out = run(&system("parameters = { n = 5 }"), "five");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (header, rows) = read_csv(&std::fs::read_to_string(dir.path().join("five.csv")).unwrap());
    let x: Vec<String> = (1..=5).map(|i| format!("d.x[{i}]")).collect();
    assert_eq!(header[1..6], x[..], "{header:?}");
    assert!(!header.iter().any(|h| h == "d.x[6]"), "{header:?}");
    assert_eq!(rows.len(), 6);
    for row in &rows {
        for i in 1..=5 {
            let exact = (-(i as f64) * row[0]).exp();
            assert!(
                ((row[i] - exact) / exact).abs() <= 1e-15,
                "x[{i}] at t = {}: {} against {exact}",
                row[0],
                row[i]
            );
        }
    }
    // The FMU's host may add its own exit message (see above) to stderr: the
    // error is the one `error:` line.
    let out = run(&system(""), "three");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let errors: Vec<&str> = stderr.lines().filter(|l| l.starts_with("error:")).collect();
    assert_eq!(errors.len(), 1, "{stderr}");
    assert!(
        errors[0].contains("index 5 is out of range") && errors[0].contains("valid: 1..=3"),
        "{stderr}"
    );
}

/// Signal connections take elements of Integer and Boolean arrays as of Real ones:
/// two `Decays` instances (n = 4 and n = 3), `a.k[2] → b.shift[3]` (Int64) and
/// `a.held[1] → b.hold[2]` (Boolean), the receivers' other elements at their
/// values set in `parameters`. After step s, a.k[2] = 2s and b.k[3] = 3s plus the
/// value a.k[2] had at the previous point, 2(s − 1); b.held = [false, true, true].
#[test]
fn signal_connections_take_integer_and_boolean_array_elements() {
    let Some(py) = decays() else { return };
    let dir = tempfile::tempdir().unwrap();
    let toml = format!(
        r#"
[experiment]
stop = 0.5
step = 0.1

[[instance]]
name = "a"
fmu = "{fmu}"
isolation = "process"
parameters = {{ n = 4, hold = [true, false, false, false] }}

[[instance]]
name = "b"
fmu = "{fmu}"
isolation = "process"
parameters = {{ shift = [10, 20, 30], hold = [false, false, true] }}

[[connection]]
from = "a.k[2]"
to = "b.shift[3]"

[[connection]]
from = "a.held[1]"
to = "b.hold[2]"
"#,
        fmu = py.fmu.display()
    );
    let file = dir.path().join("system.toml");
    std::fs::write(&file, toml).unwrap();
    let csv = dir.path().join("out.csv");
    let out = py
        .env(&mut Command::new(env!("CARGO_BIN_EXE_tether")))
        .args([
            "run",
            file.to_str().unwrap(),
            "--out",
            csv.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (header, rows) = read_csv(&std::fs::read_to_string(&csv).unwrap());
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    assert_eq!(rows.len(), 6);
    for (s, row) in rows.iter().enumerate().skip(1) {
        let s = s as f64;
        assert_eq!(row[col("a.k[2]")], 2.0 * s);
        assert_eq!(row[col("b.k[1]")], 10.0 + s);
        assert_eq!(row[col("b.k[2]")], 20.0 + 2.0 * s);
        assert_eq!(row[col("b.k[3]")], 3.0 * s + 2.0 * (s - 1.0), "step {s}");
        assert_eq!(
            [
                row[col("b.held[1]")],
                row[col("b.held[2]")],
                row[col("b.held[3]")]
            ],
            [0.0, 1.0, 1.0]
        );
    }
}

/// `Simulation::set_parameter` (Python's `Simulation.set_parameter`) takes array
/// elements and whole arrays between steps, the other elements keeping their
/// values; out-of-range elements, a wrong length and an array for an element are
/// refused with the variable named. `Decays` runs isolated, in `tether`'s host
/// given the environment its embedded Python needs.
#[test]
fn set_parameter_takes_array_elements_and_whole_arrays_between_steps() {
    use tether_master::{Simulation, StartValue, SystemSpec};
    let Some(py) = decays() else { return };
    tether_fmi::remote::set_host(tether_fmi::remote::HostCommand {
        program: "/usr/bin/env".into(),
        args: vec![
            format!("LD_PRELOAD={}", py.libpython.display()).into(),
            format!("PYTHONPATH={}", py.site_packages.display()).into(),
            env!("CARGO_BIN_EXE_tether").into(),
            "__fmi-host".into(),
        ],
    });
    let spec = SystemSpec::from_toml(&format!(
        r#"
[experiment]
stop = 1.0
step = 0.1

[[instance]]
name = "d"
fmu = "{}"
isolation = "process"
"#,
        py.fmu.display()
    ))
    .unwrap();
    let mut sim = Simulation::new(&spec).unwrap();
    let k = |sim: &Simulation| -> Vec<f64> {
        (1..=3)
            .map(|i| sim.value(&format!("d.k[{i}]")).unwrap())
            .collect()
    };
    sim.step().unwrap();
    sim.step().unwrap();
    assert_eq!(k(&sim), [2.0, 4.0, 6.0]);
    sim.set_parameter("d.shift[2]", &StartValue::Integer(100))
        .unwrap();
    sim.step().unwrap();
    assert_eq!(k(&sim), [3.0, 106.0, 9.0]);
    let whole = StartValue::Array(vec![
        StartValue::Integer(-1),
        StartValue::Integer(-2),
        StartValue::Integer(-3),
    ]);
    sim.set_parameter("d.shift", &whole).unwrap();
    sim.set_parameter("d.hold[3]", &StartValue::Boolean(true))
        .unwrap();
    sim.step().unwrap();
    assert_eq!(k(&sim), [3.0, 6.0, 9.0]);
    assert_eq!(sim.value("d.held[3]"), Some(1.0));
    assert_eq!(sim.value("d.held[1]"), Some(0.0));
    let refused = |sim: &mut Simulation, target: &str, value: StartValue| {
        sim.set_parameter(target, &value).unwrap_err().to_string()
    };
    let e = refused(&mut sim, "d.shift[4]", StartValue::Integer(1));
    assert!(
        e.contains("index 4 is out of range") && e.contains("'d'"),
        "{e}"
    );
    let e = refused(
        &mut sim,
        "d.shift",
        StartValue::Array(vec![StartValue::Integer(1)]),
    );
    assert!(
        e.contains("3 = 3 elements") && e.contains("the value has 1"),
        "{e}"
    );
    let e = refused(&mut sim, "d.shift[1]", whole.clone());
    assert!(e.contains("an element takes one value"), "{e}");
    let e = refused(&mut sim, "d.k[1]", StartValue::Integer(1));
    assert!(e.contains("only inputs and tunable parameters"), "{e}");
    sim.step().unwrap();
    assert_eq!(k(&sim), [4.0, 8.0, 12.0], "nothing refused was set");
}

/// Signal connections to and from array elements: the workspace oscillator's `x`
/// into StateSpace's `u[2]` (the array set whole, `u[1]` and `u[3]` keeping their
/// start values 1 and 3), StateSpace's `y[2]` (y = D u with D = diag(1, 2, 1), A, B,
/// C zero) into a second oscillator. A connection hands the sender's value at the
/// previous macro point: y[2](T_n) = 2·x(T_{n−1}), bit for bit.
#[test]
fn signal_connections_take_array_elements() {
    let Some(ss) = statespace() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let zeros = "[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]";
    let toml = format!(
        r#"
[experiment]
stop = 0.5
step = 1e-2

[[instance]]
name = "mass1"
fmu = "{osc}"
parameters = {{ m = 1.0, c = 10.0, d = 0.0, x0 = 0.0, v0 = 1.0, exact = true }}

[[instance]]
name = "ss"
fmu = "{ss}"
parameters = {{ A = {zeros}, B = {zeros}, C = {zeros}, D = [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]] }}

[[instance]]
name = "mass2"
fmu = "{osc}"
parameters = {{ m = 1.0, c = 10.0, d = 0.0, x0 = 0.0, v0 = 0.0, exact = true }}

[[connection]]
from = "mass1.x"
to = "ss.u[2]"

[[connection]]
from = "ss.y[2]"
to = "mass2.F_ext"
"#,
        osc = oscillator().display(),
        ss = ss.display(),
    );
    let (header, rows) = read_csv(&run(&toml, dir.path()));
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let (x, y1, y2, y3, x2) = (
        col("mass1.x"),
        col("ss.y[1]"),
        col("ss.y[2]"),
        col("ss.y[3]"),
        col("mass2.x"),
    );
    assert_eq!(rows.len(), 51);
    for n in 1..rows.len() {
        assert_eq!(rows[n][y2], 2.0 * rows[n - 1][x], "row {n}");
        assert_eq!((rows[n][y1], rows[n][y3]), (1.0, 3.0), "row {n}");
    }
    assert!(rows[50][x2].abs() > 0.01, "mass2 moved: {}", rows[50][x2]);
    // A whole array in a connection is refused in one line.
    let file = dir.path().join("whole.toml");
    std::fs::write(&file, toml.replace("\"ss.u[2]\"", "\"ss.u\"")).unwrap();
    let line = one_line(&tether(&["run", file.to_str().unwrap()]));
    assert!(
        line.contains("'u'") && line.contains("name an element"),
        "{line}"
    );
}

/// k > 0 on StateSpace, whose input `u` is an array: one reason, the same sentence
/// in `tether info`, in the refusal of `tether run --order 1` and in
/// docs/algorithm.md ("FMI 3.0 instances"), although the FMU declares
/// `providesIntermediateUpdate`.
#[test]
fn k_1_on_statespace_is_refused_with_the_reason_tether_info_gives() {
    let Some(ss) = statespace() else {
        return;
    };
    let reason = "k > 0 needs inputs that take polynomials; array elements of 'u' take values only";
    let info = tether(&["info", ss.to_str().unwrap()]);
    assert!(info.status.success());
    let text = String::from_utf8_lossy(&info.stdout);
    let line = text
        .lines()
        .find(|l| l.contains("coupling polynomials k > 0"))
        .unwrap_or_else(|| panic!("no k > 0 line in\n{text}"));
    assert!(line.ends_with(&format!("no: {reason}")), "{line}");
    assert!(
        text.contains("providesIntermediateUpdate             yes"),
        "{text}"
    );

    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("system.toml");
    std::fs::write(&file, joined(BAUMGARTE_1, 1e-3, &ss)).unwrap();
    let out = tether(&["run", file.to_str().unwrap(), "--order", "1", "--quiet"]);
    assert_eq!(
        one_line(&out),
        format!("error: instance 'ss' (StateSpace): {reason}; use order = 0")
    );

    let docs = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/algorithm.md"),
    )
    .unwrap();
    let docs = docs.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        docs.contains(reason),
        "docs/algorithm.md does not say: {reason}"
    );
}
