//! The `tether` binary as a user runs it.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn tether(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tether")
}

fn oscillator() -> PathBuf {
    tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU")
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The last line of stderr must be the one-line error.
fn error_line(out: &Output) -> String {
    assert!(
        !out.status.success(),
        "expected failure, got success: {}",
        stderr(out)
    );
    let text = stderr(out);
    let line = text.lines().last().unwrap_or_default().to_string();
    assert!(line.starts_with("error: "), "{text}");
    assert!(!text.contains("panicked"), "{text}");
    line
}

#[test]
fn info_prints_identity_capabilities_and_variables() {
    let dir = tempfile::tempdir().unwrap();
    let out = tether(&["info", oscillator().to_str().unwrap()], dir.path());
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8(out.stdout).unwrap();
    for needle in [
        "oscillator",
        "canGetAndSetFMUstate",
        "canInterpolateInputs",
        "input",
        "output",
        " F ",
        " x ",
        " a ",
    ] {
        assert!(text.contains(needle), "missing {needle:?} in\n{text}");
    }
}

#[test]
fn simulate_writes_every_output_on_the_communication_grid() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("free.csv");
    let out = tether(
        &[
            "simulate",
            oscillator().to_str().unwrap(),
            "--stop",
            "0.5",
            "--step",
            "1e-3",
            "--set",
            "v0=1",
            "--set",
            "exact=true",
            "--out",
            csv.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header[0], "time");
    for col in ["x", "v", "a"] {
        assert!(header.contains(&col), "{header:?}");
    }
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 501);
    for (n, row) in rows.iter().enumerate() {
        assert_eq!(row[0], n as f64 * 1e-3, "time is start + n·h");
    }
    let vi = header.iter().position(|c| *c == "v").unwrap();
    assert_eq!(rows[0][vi], 1.0, "--set v0=1 applied");
}

#[test]
fn simulate_refuses_a_bad_setting_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let osc = oscillator();
    let line = error_line(&tether(
        &["simulate", osc.to_str().unwrap(), "--set", "mm=2"],
        dir.path(),
    ));
    assert!(line.contains("mm") && line.contains("'m'"), "{line}");
    let line = error_line(&tether(
        &["simulate", osc.to_str().unwrap(), "--set", "x=2"],
        dir.path(),
    ));
    assert!(line.contains("output"), "{line}");
    let line = error_line(&tether(
        &["simulate", osc.to_str().unwrap(), "--step", "0"],
        dir.path(),
    ));
    assert!(line.contains("step"), "{line}");
}

#[test]
fn run_the_oscillator_example_writes_the_documented_columns() {
    oscillator();
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("osc.csv");
    let example = root().join("examples/oscillator.toml");
    let out = tether(
        &[
            "run",
            example.to_str().unwrap(),
            "--stop",
            "0.1",
            "--out",
            csv.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let summary = stderr(&out);
    assert!(
        summary.contains("macro steps: 100") && summary.contains("fmi2DoStep"),
        "{summary}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let header = text.lines().next().unwrap();
    assert_eq!(
        header,
        "time,mass1.x,mass1.v,mass1.a,mass2.x,mass2.v,mass2.a,link.lambda,link.g"
    );
    assert_eq!(text.lines().count(), 102);
    let first: Vec<f64> = text
        .lines()
        .nth(1)
        .unwrap()
        .split(',')
        .map(|v| v.parse().unwrap())
        .collect();
    assert!(
        (first[7] - 1000.0 / 3.0).abs() < 1e-6,
        "consistent λ0, got {}",
        first[7]
    );
    assert!(summary.contains("(phases not timed)"), "{summary}");

    // --timing adds the phase times to the summary and changes no number.
    let timed_csv = dir.path().join("timed.csv");
    let out = tether(
        &[
            "run",
            example.to_str().unwrap(),
            "--stop",
            "0.1",
            "--timing",
            "--out",
            timed_csv.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let summary = stderr(&out);
    assert!(
        summary.contains("predictor") && summary.contains("corrector"),
        "{summary}"
    );
    assert_eq!(std::fs::read_to_string(&timed_csv).unwrap(), text);
}

fn write_system(dir: &Path, edit: impl Fn(String) -> String) -> PathBuf {
    let text = std::fs::read_to_string(root().join("examples/oscillator.toml")).unwrap();
    let fmu = oscillator();
    let text = text.replace("../target/fmus/oscillator.fmu", fmu.to_str().unwrap());
    let path = dir.join("system.toml");
    std::fs::write(&path, edit(text)).unwrap();
    path
}

#[test]
fn a_system_file_naming_a_missing_variable_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let sys = write_system(dir.path(), |t| {
        t.replace("mass2.x - mass1.x", "mass2.x - mass1.xx")
    });
    let line = error_line(&tether(&["run", sys.to_str().unwrap()], dir.path()));
    assert!(line.contains("xx") && line.contains("'x'"), "{line}");
    let sys = write_system(dir.path(), |t| {
        t.replace("mass1.F - mass2.F", "mass1.F - mass3.F")
    });
    let line = error_line(&tether(&["run", sys.to_str().unwrap()], dir.path()));
    assert!(line.contains("mass3"), "{line}");
    let sys = write_system(dir.path(), |t| {
        t.replace("mass1.F - mass2.F", "mass1.x - mass2.F")
    });
    let line = error_line(&tether(&["run", sys.to_str().unwrap()], dir.path()));
    assert!(line.contains("mass1.x") && line.contains("input"), "{line}");
}

#[test]
fn bad_method_parameters_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let sys = write_system(dir.path(), |t| t);
    let s = sys.to_str().unwrap();
    for (args, needle) in [
        (vec!["--beta", "-1"], "beta"),
        (vec!["--order", "3"], "order"),
        (vec!["--step", "0"], "step"),
        (vec!["--stop", "-1"], "stop"),
        (vec!["--a", "1"], "--a"),
        (vec!["--method", "explicit"], "mu"),
    ] {
        let mut full = vec!["run", s];
        full.extend(args.iter());
        let line = error_line(&tether(&full, dir.path()));
        assert!(line.contains(needle), "{args:?}: {line}");
    }
}

/// The first multiplier of a run: the consistent λ0, set by the masses.
fn first_lambda(csv: &Path) -> f64 {
    let text = std::fs::read_to_string(csv).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|c| *c == "link.lambda").unwrap();
    text.lines()
        .nth(1)
        .unwrap()
        .split(',')
        .nth(col)
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn run_set_changes_an_fmu_parameter() {
    let dir = tempfile::tempdir().unwrap();
    let sys = write_system(dir.path(), |t| t);
    let s = sys.to_str().unwrap();
    let run = |extra: &[&str], out: &str| {
        let mut args = vec!["run", s, "--stop", "0.01", "--out", out, "-q"];
        args.extend(extra);
        let result = tether(&args, dir.path());
        assert!(result.status.success(), "{}", stderr(&result));
        first_lambda(&dir.path().join(out))
    };
    // m1 = 1, m2 = 2 as in the file: λ0 = 1000/3. With m2 = 4 the masses'
    // equal accelerations need λ0 = 600; with m2 = 1 none at all.
    assert!((run(&[], "file.csv") - 1000.0 / 3.0).abs() < 1e-6);
    assert!((run(&["--set", "mass2.m=4"], "heavy.csv") - 600.0).abs() < 1e-6);
    let both = run(&["--set", "mass2.m=4", "--set", "mass2.m=1"], "same.csv");
    assert!(both.abs() < 1e-9, "the last --set wins: {both}");

    for (set, needles) in [
        ("mass3.m=4", &["mass3", "no instance", "mass1, mass2"][..]),
        (
            "mass2.m",
            &["--set mass2.m", "INSTANCE.PARAMETER=VALUE"][..],
        ),
        ("mass2m=4", &["'mass2m'", "instance.parameter"][..]),
        ("mass2.mass=4", &["mass"][..]),
    ] {
        let line = error_line(&tether(&["run", s, "--set", set], dir.path()));
        for needle in needles {
            assert!(line.contains(needle), "{set}: {line}");
        }
    }
}

#[test]
fn divergence_keeps_the_results_and_marks_them_incomplete() {
    let dir = tempfile::tempdir().unwrap();
    let sys = write_system(dir.path(), |t| t);
    let csv = dir.path().join("unstable.csv");
    // Index 3 with linear polynomials is unstable (the paper's conclusion).
    let out = tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--beta",
            "0",
            "--gamma",
            "0",
            "--order",
            "1",
            "--out",
            csv.to_str().unwrap(),
        ],
        dir.path(),
    );
    let line = error_line(&out);
    assert!(line.contains("diverged") && line.contains("t = "), "{line}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let last = text.lines().last().unwrap();
    assert!(
        last.starts_with("# incomplete: coupling diverged"),
        "{last}"
    );
    assert!(text.lines().count() > 3, "accepted steps are kept");
}

#[test]
fn a_multiplier_that_cannot_move_its_constraint_is_a_singular_jacobian() {
    let dir = tempfile::tempdir().unwrap();
    // g = x2 − x2 does not depend on λ: the interface Jacobian is zero.
    let sys = write_system(dir.path(), |t| {
        t.replace("mass2.x - mass1.x", "mass2.x - mass2.x").replace(
            "[method]\nkind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6",
            "[method]\nkind = \"baumgarte\"",
        )
    });
    let csv = dir.path().join("singular.csv");
    let out = tether(
        &["run", sys.to_str().unwrap(), "--out", csv.to_str().unwrap()],
        dir.path(),
    );
    let line = error_line(&out);
    assert!(
        line.contains("singular interface Jacobian")
            && line.contains("t = 0.001")
            && line.contains("condition"),
        "{line}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    assert!(
        text.lines()
            .last()
            .unwrap()
            .starts_with("# incomplete: singular"),
        "{text}"
    );
}

/// Adaptive steps with every instance isolated (`--isolate`): the rollback
/// of a rejected try goes through the host processes, and the results are
/// those of the in-process run byte for byte. Each try saves the states
/// once, so more saves than accepted steps means tries were rejected.
#[test]
fn adaptive_steps_run_isolated_as_in_process() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, isolate: bool| {
        let (csv, json) = (
            dir.path().join(name),
            dir.path().join(format!("{name}.json")),
        );
        let mut args = vec![
            "run",
            "examples/oscillator.toml",
            "--stop",
            "0.2",
            "--step-rtol",
            "1e-6",
            "--step-atol",
            "1e-6",
            "--quiet",
            "--out",
            csv.to_str().unwrap(),
            "--summary-json",
            json.to_str().unwrap(),
        ];
        if isolate {
            args.push("--isolate");
        }
        let out = tether(&args, &root());
        assert!(out.status.success(), "{}", stderr(&out));
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
        (std::fs::read_to_string(csv).unwrap(), summary)
    };
    let (in_process, _) = run("in_process.csv", false);
    let (isolated, summary) = run("isolated.csv", true);
    assert_eq!(in_process, isolated);
    let steps = summary["macro_steps"].as_u64().unwrap();
    let mass1 = &summary["instances"]["mass1"];
    let (saves, restores) = (
        mass1["get_fmu_state"].as_u64().unwrap(),
        mass1["set_fmu_state"].as_u64().unwrap(),
    );
    assert!(
        saves > steps,
        "rejected tries: {saves} saves, {steps} steps"
    );
    assert_eq!(
        restores,
        2 * saves + (saves - steps),
        "two reruns a try, one rollback a rejection"
    );
}

/// The results file of a quiet run, which must succeed.
fn run_bytes(dir: &Path, sys: &Path, extra: &[&str], out: &str) -> Vec<u8> {
    let mut args = vec!["run", sys.to_str().unwrap(), "--stop", "0.05", "-q"];
    args.extend_from_slice(extra);
    args.extend(["--out", out]);
    let result = tether(&args, dir);
    assert!(result.status.success(), "{args:?}: {}", stderr(&result));
    std::fs::read(dir.join(out)).unwrap()
}

#[test]
fn method_index_selects_the_weights_as_the_weight_only_form_does() {
    let dir = tempfile::tempdir().unwrap();
    let weights = "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6";
    let file = |method: &str| {
        let method = method.to_string();
        write_system(dir.path(), move |t| t.replace(weights, &method))
    };
    let d = dir.path();
    // Index 1 of Method 1 without weights: the paper's β = 2e-3, γ = 1e-6.
    let old = run_bytes(d, &file(weights), &[], "old.csv");
    let index1 = run_bytes(d, &file("kind = \"baumgarte\"\nindex = 1"), &[], "i1.csv");
    assert!(
        old == index1,
        "index = 1 differs from beta = 2e-3, gamma = 1e-6"
    );
    let with_weights = file("kind = \"baumgarte\"\nindex = 1\nbeta = 2e-3\ngamma = 1e-6");
    assert!(old == run_bytes(d, &with_weights, &[], "i1w.csv"));
    // --index 2 keeps the file's β and drops γ; index 3 drops both.
    let sys = file(weights);
    let beta_only = run_bytes(d, &sys, &["--gamma", "0"], "b.csv");
    assert!(beta_only == run_bytes(d, &sys, &["--index", "2"], "i2.csv"));
    let none = run_bytes(d, &sys, &["--beta", "0", "--gamma", "0"], "n.csv");
    assert!(none == run_bytes(d, &sys, &["--index", "3"], "i3.csv"));
    // Method 2: index 1 is a = b = 1, index 2 is a = 1.
    let weighted = file("kind = \"weighted\"\na = 1.0\nb = 1.0");
    let ab = run_bytes(d, &weighted, &[], "ab.csv");
    let w1 = file("kind = \"weighted\"\nindex = 1");
    assert!(ab == run_bytes(d, &w1, &[], "w1.csv"));
    let a = run_bytes(d, &weighted, &["--b", "0"], "a.csv");
    assert!(a == run_bytes(d, &w1, &["--index", "2"], "w2.csv"));
    let summary = tether(&["run", w1.to_str().unwrap(), "--stop", "0.01"], d);
    assert!(
        stderr(&summary).contains("weighted (index 1, a = 1, b = 1), k = 0"),
        "{}",
        stderr(&summary)
    );
}

#[test]
fn an_index_that_contradicts_a_weight_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let weights = "kind = \"baumgarte\"\nbeta = 2e-3\ngamma = 1e-6";
    for (method, message) in [
        (
            "kind = \"baumgarte\"\nindex = 2\ngamma = 1e-6",
            "index = 2 contradicts gamma = 0.000001: index 2 means beta > 0 and gamma = 0",
        ),
        (
            "kind = \"weighted\"\nindex = 3\na = 1.0",
            "index = 3 contradicts a = 1: index 3 means a = b = 0",
        ),
        (
            "kind = \"weighted\"\nindex = 1\nb = 0.0",
            "index = 1 contradicts b = 0: index 1 means a > 0 and b > 0",
        ),
        (
            "kind = \"baumgarte\"\nindex = 4",
            "index = 4: expected 1, 2 or 3",
        ),
    ] {
        let sys = write_system(dir.path(), |t| t.replace(weights, method));
        let line = error_line(&tether(&["run", sys.to_str().unwrap()], dir.path()));
        assert!(line.contains(message), "{method}: {line}");
    }
    let sys = write_system(dir.path(), |t| t);
    let s = sys.to_str().unwrap();
    for (args, message) in [
        (
            &["--index", "3", "--beta", "0.1"][..],
            "error: --index 3 contradicts --beta 0.1: index 3 means beta = gamma = 0",
        ),
        (
            &["--method", "explicit", "--mu", "0.1", "--index", "1"][..],
            "error: --index applies to method baumgarte or weighted, but the method is explicit",
        ),
    ] {
        let mut full = vec!["run", s];
        full.extend_from_slice(args);
        assert_eq!(error_line(&tether(&full, dir.path())), message);
    }
    let out = tether(&["run", s, "--index", "0"], dir.path());
    assert!(!out.status.success());
    assert!(
        stderr(&out).contains("invalid value '0' for '--index <INDEX>': 0 is not in 1..=3"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn a_formulation_known_unstable_is_named_before_the_run_and_at_divergence() {
    let dir = tempfile::tempdir().unwrap();
    let sys = write_system(dir.path(), |t| t);
    let s = sys.to_str().unwrap();
    let warning = "warning: baumgarte index 3 with k = 1 is unstable over the whole stability map \
                   (0 of 121 cells at k = 1, docs/paper-reproduction.md); use k = 0, \
                   or index 1 with k = 1 (kind = \"baumgarte\", index = 1)";
    let out = tether(&["run", s, "--index", "3", "--order", "1"], dir.path());
    let text = stderr(&out);
    assert_eq!(text.lines().next(), Some(warning), "{text}");
    let line = error_line(&out);
    let note = warning.trim_start_matches("warning: ");
    assert!(
        line.contains("coupling diverged at t = ") && line.ends_with(&format!("; {note}")),
        "{line}"
    );
    let out = tether(
        &["run", s, "--index", "2", "--order", "1", "--stop", "0.01"],
        dir.path(),
    );
    assert!(
        stderr(&out).starts_with(
            "warning: baumgarte index 2 with k = 1 is unstable over most of the range \
             (33 of 121 cells stable at k = 1, only for d >= 1000, docs/paper-reproduction.md); \
             use k = 0, or index 1 with k = 1 (index = 1: beta = 2e-3, gamma = 1e-6)\n"
        ),
        "{}",
        stderr(&out)
    );
    // The stable ones say nothing.
    let out = tether(&["run", s, "--order", "1", "--stop", "0.01"], dir.path());
    assert!(
        out.status.success() && !stderr(&out).contains("warning"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn a_name_error_says_where_the_name_appears() {
    let dir = tempfile::tempdir().unwrap();
    let line = |edit: &dyn Fn(String) -> String, extra: &[&str]| {
        let sys = write_system(dir.path(), edit);
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", "r.csv"];
        args.extend_from_slice(extra);
        error_line(&tether(&args, dir.path()))
    };
    let same = |t: String| t;
    type Edit = Box<dyn Fn(String) -> String>;
    let cases: Vec<(Edit, &[&str], &str)> = vec![
        (
            Box::new(|t: String| t.replace("mass2.x - mass1.x", "mass2.xx - mass1.x")),
            &[],
            "constraint 'link', position: instance 'mass2' (oscillator.fmu) has no variable \
             'xx'; did you mean 'x', 'x0'?",
        ),
        (
            Box::new(|t: String| t.replace("mass1.F - mass2.F", "mass1.F - mass2.f")),
            &[],
            "constraint 'link', drives: instance 'mass2' (oscillator.fmu) has no variable 'f'; \
             did you mean 'F', 'a', 'c'?",
        ),
        (
            Box::new(|t: String| {
                t + "\n[[coupling_variable]]\nname = \"push\"\ndrives = \"mass1.F\"\nvalue = \"mass2.vv\"\n"
            }),
            &[],
            "coupling variable 'push', value: instance 'mass2' (oscillator.fmu) has no variable \
             'vv'; did you mean 'v', 'v0'?",
        ),
        (
            Box::new(|t: String| t + "\n[[connection]]\nfrom = \"mass1.xx\"\nto = \"mass2.F\"\n"),
            &[],
            "connection mass1.xx → mass2.F, from: instance 'mass1' (oscillator.fmu) has no \
             variable 'xx'; did you mean 'x', 'x0'?",
        ),
        (
            Box::new(|t: String| t.replace("m = 2.0,", "mm = 2.0,")),
            &[],
            "parameters: instance 'mass2' (oscillator.fmu) has no variable 'mm'; did you mean 'm'?",
        ),
        (
            Box::new(same),
            &["--set", "mass1.cc=3"],
            "--set mass1.cc: instance 'mass1' (oscillator.fmu) has no variable 'cc'; did you mean \
             'c'?",
        ),
        (
            Box::new(|t: String| t + "\n[output]\nvariables = [\"link.lam\"]\n"),
            &[],
            "[output] variables, pattern 'link.lam': matches no column; did you mean 'link.lambda', \
             'link.g'?",
        ),
    ];
    for (edit, extra, message) in cases {
        let got = line(&*edit, extra);
        assert!(got.ends_with(message), "{got}\nwanted: {message}");
    }
    // An unknown TOML key is reported at its own line and column.
    let got = line(
        &|t: String| t.replace("beta = 2e-3\n", "beta = 2e-3\n  betta = 1\n"),
        &[],
    );
    let sys = dir.path().join("system.toml");
    let text = std::fs::read_to_string(&sys).unwrap();
    let row = text.lines().position(|l| l.contains("betta")).unwrap() + 1;
    assert_eq!(
        got,
        format!(
            "error: system file {}: line {row}, column 3: unknown field `betta`, expected one of \
             `index`, `beta`, `gamma`",
            sys.display()
        )
    );
    let got = line(
        &|t: String| t.replace("m = 1.0, c", "m = 1.0, cc = 2, c"),
        &[],
    );
    assert!(got.contains("parameters: instance 'mass1'"), "{got}");
}
