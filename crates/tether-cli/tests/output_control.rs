//! What `tether run` records and reports: `[output]` and its flags (interval,
//! column patterns), Integer and Boolean outputs, the JSON run summary, and
//! the checks of the command line made before a run starts.

mod common;

use std::path::{Path, PathBuf};

use common::{error_line, oscillator, success, tether};

/// The paper's oscillator pair with `mass1` from `fmu1` (parameters
/// `extra` added), `[output]` text `output`, stop 1, H = 1e-3.
fn system(dir: &Path, fmu1: &Path, extra: &str, output: &str) -> PathBuf {
    let text = format!(
        r#"
name = "pair"
[experiment]
stop = 1.0
step = 1e-3
[method]
kind = "baumgarte"
beta = 2e-3
gamma = 1e-6
[coupling]
parallel = "off"
{output}
[[instance]]
name = "mass1"
fmu = "{fmu1}"
parameters = {{ m = 1.0{extra} }}
[[instance]]
name = "mass2"
fmu = "{oscillator}"
parameters = {{ m = 2.0 }}
[[constraint]]
name = "link"
position = "mass2.x - mass1.x"
velocity = "mass2.v - mass1.v"
acceleration = "mass2.a - mass1.a"
drives = "mass1.F - mass2.F"
"#,
        fmu1 = fmu1.display(),
        oscillator = oscillator().display(),
    );
    let path = dir.join("pair.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// Header and rows of a results file (names with commas are quoted).
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_path(path)
        .unwrap();
    let header = reader
        .headers()
        .unwrap()
        .iter()
        .map(str::to_string)
        .collect();
    let rows = reader
        .records()
        .map(|r| r.unwrap().iter().map(|v| v.parse().unwrap()).collect())
        .collect();
    (header, rows)
}

/// `--output-interval` records every 0.3 s and the last point; the values are
/// those of the full run at the same times, bit for bit; `--output-variables`
/// keeps the matching columns in their order; `[output]` in the file does the
/// same as the flags.
#[test]
fn the_output_grid_and_the_columns_are_chosen_and_the_values_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), &oscillator(), "", "");
    let full = dir.path().join("full.csv");
    success(&tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            full.to_str().unwrap(),
        ],
        dir.path(),
    ));
    let coarse = dir.path().join("coarse.csv");
    let text = success(&tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            coarse.to_str().unwrap(),
            "--output-interval",
            "0.3",
            "--output-variables",
            "mass1.*",
            "--output-variables",
            "link.g",
        ],
        dir.path(),
    ));
    assert!(text.contains("macro steps: 1000"), "{text}");
    let (all_names, all_rows) = read_csv(&full);
    let (names, rows) = read_csv(&coarse);
    assert_eq!(names, ["time", "mass1.x", "mass1.v", "mass1.a", "link.g"]);
    let times: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(times, [0.0, 0.3, 0.6, 0.9, 1.0]);
    for row in &rows {
        let n = (row[0] / 1e-3).round() as usize;
        for (k, name) in names.iter().enumerate() {
            let j = all_names.iter().position(|c| c == name).unwrap();
            assert_eq!(
                row[k].to_bits(),
                all_rows[n][j].to_bits(),
                "{name} at {}",
                row[0]
            );
        }
    }
    // The same from the system file.
    let sys = system(
        dir.path(),
        &oscillator(),
        "",
        "[output]\ninterval = 0.3\nvariables = [\"mass1.*\", \"link.g\"]",
    );
    let from_file = dir.path().join("file.csv");
    success(&tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            from_file.to_str().unwrap(),
        ],
        dir.path(),
    ));
    assert_eq!(
        std::fs::read_to_string(&from_file).unwrap(),
        std::fs::read_to_string(&coarse).unwrap()
    );
}

#[test]
fn an_output_interval_off_the_step_and_a_pattern_matching_nothing_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), &oscillator(), "", "");
    let run = |extra: &[&str]| {
        let mut args = vec!["run", sys.to_str().unwrap(), "--out", "r.csv"];
        args.extend_from_slice(extra);
        tether(&args, dir.path())
    };
    assert_eq!(
        error_line(&run(&["--output-interval", "0.0025"])),
        "error: invalid output interval = 0.0025: expected a whole multiple of the step \
         H = 0.001 (the nearest is 3·H)"
    );
    assert_eq!(
        error_line(&run(&["--output-interval", "-1"])),
        "error: invalid output interval = -1: expected a whole multiple of the step \
         H = 0.001 (the nearest is 1·H)"
    );
    assert_eq!(
        error_line(&run(&["--output-variables", "mass3.*"])),
        "error: --output-variables, pattern 'mass3.*': matches no column; did you mean \
         'mass1.x', 'mass1.v', 'mass1.a', 'mass2.x', 'mass2.v', 'mass2.a'?"
    );
    // A negative step is a value, refused as one.
    assert_eq!(
        error_line(&run(&["--step", "-1e-3"])),
        "error: invalid step = -0.001: expected a finite macro-step size > 0"
    );
}

/// `--plot … --columns X` with a column the run does not record stops before
/// the run (no results file is written).
#[test]
fn plot_columns_are_checked_before_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), &oscillator(), "", "");
    let out = tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            "r.csv",
            "--plot",
            "p.svg",
            "--columns",
            "link.lambda,mass1.q",
        ],
        dir.path(),
    );
    assert_eq!(
        error_line(&out),
        "error: --columns mass1.q: the run records no column 'mass1.q'; columns are: mass1.x, \
         mass1.v, mass1.a, mass2.x, mass2.v, mass2.a, link.lambda, link.g"
    );
    assert!(!dir.path().join("r.csv").exists());
}

/// Integer and Boolean outputs are columns, as numbers (0/1 for Booleans),
/// after the Real outputs of their instance; the faults FMU with two of its
/// parameters declared as outputs (`flood`, an Integer, 2000; `exact`, a
/// Boolean, false).
#[test]
fn integer_and_boolean_outputs_are_recorded_as_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let faults = tether_fmu_build::workspace_fmu("faults").expect("package the faults FMU");
    let edited = tether_tests::faulty::edited_fmu(&faults, dir.path(), "typed", |xml| {
        xml.replace(
            "name=\"flood\" valueReference=\"11\" description=\"Mode 6: warnings logged by each \
             fmi2DoStep from `at` on\" causality=\"parameter\" variability=\"fixed\"",
            "name=\"flood\" valueReference=\"11\" description=\"Mode 6\" causality=\"output\" \
             variability=\"discrete\"",
        )
        .replace(
            "causality=\"parameter\" variability=\"fixed\" initial=\"exact\">\n      <Boolean",
            "causality=\"output\" variability=\"discrete\" initial=\"exact\">\n      <Boolean",
        )
    });
    let sys = system(dir.path(), &edited, "", "");
    let summary = dir.path().join("s.json");
    success(&tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            "r.csv",
            "--stop",
            "0.01",
            "--summary-json",
            summary.to_str().unwrap(),
        ],
        dir.path(),
    ));
    let (names, rows) = read_csv(&dir.path().join("r.csv"));
    assert_eq!(
        names[..6],
        [
            "time",
            "mass1.x",
            "mass1.v",
            "mass1.a",
            "mass1.flood",
            "mass1.exact"
        ]
    );
    assert_eq!(rows.len(), 11);
    for row in &rows {
        assert_eq!((row[4], row[5]), (2000.0, 0.0));
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    // One read of each kind per recorded point.
    assert_eq!(json["instances"]["mass1"]["get_integer"], 11);
    assert_eq!(json["instances"]["mass1"]["get_boolean"], 11);
    assert_eq!(json["instances"]["mass2"]["get_integer"], 0);
}

/// The JSON summary has the documented fields, agrees with the text summary,
/// and is written for a failed run too, saying why it stopped.
#[test]
fn the_json_summary_says_how_the_run_went() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), &oscillator(), "", "");
    let summary = dir.path().join("summary.json");
    let text = success(&tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            "r.csv",
            "--output-interval",
            "0.01",
            "--summary-json",
            summary.to_str().unwrap(),
        ],
        dir.path(),
    ));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert_eq!(json["schema"], "tether-run-summary/1");
    assert_eq!(json["method"]["kind"], "baumgarte");
    assert_eq!(json["method"]["beta"], 2e-3);
    assert_eq!(json["order"], 0);
    assert_eq!(json["step"], 1e-3);
    assert_eq!(json["output_interval"], 0.01);
    assert_eq!(json["completed"], true);
    assert_eq!(json["stop_reason"], "completed");
    assert_eq!(json["end_time"], 1.0);
    assert_eq!(json["macro_steps"], 1000);
    assert!(json["wall_time"].as_f64().unwrap() > 0.0);
    assert_eq!(json["instances"]["mass1"]["do_step"], 3000);
    assert_eq!(json["instances"]["mass2"]["get_fmu_state"], 1000);
    let g = json["max_abs_g"]["link.g"].as_f64().unwrap();
    assert!(g > 0.0 && g < 1e-4, "{g}");
    assert!(text.contains(&format!("link.g {g:.2e}")), "{text}");
    assert_eq!(json["residual_warning"], 1e-3);
    assert_eq!(json["residual_limit"], 1.0);
    assert!(json["failure"].is_null());
    assert!(json["termination"].is_null());

    // A run that fails: the summary is still written, with the reason.
    let sys = system(
        dir.path(),
        &tether_fmu_build::workspace_fmu("quirks").unwrap(),
        ", nan_after = 0.5",
        "",
    );
    let out = tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            "r.csv",
            "--summary-json",
            summary.to_str().unwrap(),
        ],
        dir.path(),
    );
    let line = error_line(&out);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    assert_eq!(json["completed"], false);
    let reason = json["stop_reason"].as_str().unwrap();
    assert!(
        reason.contains("mass1") && line.ends_with(reason),
        "{reason} / {line}"
    );
    let end = json["end_time"].as_f64().unwrap();
    assert!((0.49..0.5).contains(&end), "{end}");
    let failure = &json["failure"];
    assert_eq!(failure["kind"], "non_finite_output", "{failure}");
    assert_eq!(failure["instance"], "mass1");
    assert_eq!(failure["message"], reason);
}

/// `run --plot` labels the axes with the units the FMUs declare; ticks at
/// zero read `0`, not a rounding error such as `-5.6e-17`.
#[test]
fn plot_axes_carry_units_and_clean_zero_ticks() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), &oscillator(), "", "");
    success(&tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            "r.csv",
            "--plot",
            "p.svg",
            "--columns",
            "mass1.x,mass1.v",
            "link.lambda",
        ],
        dir.path(),
    ));
    let svg = std::fs::read_to_string(dir.path().join("p.svg")).unwrap();
    // The texts of the SVG's <text> elements.
    let texts: Vec<&str> = svg
        .split("<text")
        .skip(1)
        .filter_map(|s| s.split_once('>'))
        .filter_map(|(_, rest)| rest.split('<').next())
        .map(str::trim)
        .collect();
    for label in ["mass1.x [m]", "mass1.v [m/s]", "link.lambda", "time [s]"] {
        assert!(texts.contains(&label), "{label}: {texts:?}");
    }
    // Every tick label is a plain number, none a tiny multiple of the span.
    let ticks: Vec<&str> = texts
        .iter()
        .copied()
        .filter(|s| s.parse::<f64>().is_ok())
        .collect();
    assert!(ticks.contains(&"0"), "{ticks:?}");
    for t in &ticks {
        let v: f64 = t.parse().unwrap();
        assert!(v == 0.0 || v.abs() > 1e-6, "tick {t}");
    }
}

/// A run that fails between two points of the output grid still records its
/// last accepted point, the time the error line names.
#[test]
fn a_failed_run_on_a_coarse_grid_keeps_its_last_accepted_point() {
    let dir = tempfile::tempdir().unwrap();
    let quirks = tether_fmu_build::workspace_fmu("quirks").unwrap();
    let sys = system(dir.path(), &quirks, ", nan_after = 0.5", "");
    let out = tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            "r.csv",
            "--output-interval",
            "0.3",
        ],
        dir.path(),
    );
    let line = error_line(&out);
    let (_, rows) = read_csv(&dir.path().join("r.csv"));
    let times: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(times[..2], [0.0, 0.3]);
    assert_eq!(times.len(), 3, "{times:?}");
    let last = times[2];
    assert!((0.49..0.5).contains(&last), "{last}");
    assert!(
        line.contains(&format!(
            "results up to t = {last} kept in r.csv (marked incomplete)"
        )),
        "{line}"
    );
    let text = std::fs::read_to_string(dir.path().join("r.csv")).unwrap();
    assert!(
        text.lines().last().unwrap().starts_with("# incomplete: "),
        "{text}"
    );
}

/// `--output-variables 'a,b'` is `--output-variables a --output-variables b`,
/// as `--columns` splits at commas.
#[test]
fn output_variables_take_commas_as_columns_does() {
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), &oscillator(), "", "");
    let s = sys.to_str().unwrap();
    let run = |flags: &[&str], out: &str| {
        let mut args = vec!["run", s, "--stop", "0.01", "-q", "--out", out];
        args.extend_from_slice(flags);
        success(&tether(&args, dir.path()));
        std::fs::read(dir.path().join(out)).unwrap()
    };
    let commas = run(&["--output-variables", "mass1.*,link.g"], "commas.csv");
    let repeated = run(
        &[
            "--output-variables",
            "mass1.*",
            "--output-variables",
            "link.g",
        ],
        "repeated.csv",
    );
    assert!(commas == repeated);
    let header = String::from_utf8(commas).unwrap();
    assert_eq!(
        header.lines().next(),
        Some("time,mass1.x,mass1.v,mass1.a,link.g")
    );
}

/// A start value for an input a constraint drives is refused, in the system
/// file and with `--set`, as `Simulation::set_parameter` refuses it.
#[test]
fn a_start_value_for_a_driven_input_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let message = "error: instance 'mass1': cannot set F = 3: it is an input the coupling \
                   drives; the master sets it at every step";
    let sys = system(dir.path(), &oscillator(), ", F = 3.0", "");
    let out = tether(
        &["run", sys.to_str().unwrap(), "--out", "r.csv"],
        dir.path(),
    );
    assert_eq!(error_line(&out), message);
    let sys = system(dir.path(), &oscillator(), "", "");
    let out = tether(
        &[
            "run",
            sys.to_str().unwrap(),
            "--out",
            "r.csv",
            "--set",
            "mass1.F=3",
        ],
        dir.path(),
    );
    assert_eq!(error_line(&out), message);
}

/// A results file estimated above 1 GB is announced before the run starts,
/// with the options that shrink it (the run itself is stopped here).
#[test]
fn a_results_file_above_a_gigabyte_is_announced_before_the_run() {
    use std::io::BufRead;
    let dir = tempfile::tempdir().unwrap();
    let sys = system(dir.path(), &oscillator(), "", "");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(["run", sys.to_str().unwrap(), "--out", "big.csv"])
        .args(["--step", "1e-7", "--stop", "1000"])
        .current_dir(dir.path())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let first = std::io::BufReader::new(child.stderr.take().unwrap())
        .lines()
        .next()
        .unwrap()
        .unwrap();
    child.kill().unwrap();
    child.wait().unwrap();
    // 1e10 + 1 rows of time, the 2 × 3 outputs x, v, a and link.lambda, link.g.
    assert!(
        first.starts_with("warning: the results file will be about ")
            && first.ends_with(
                " GB (10000000001 rows × 9 columns); --output-interval DT records fewer rows, \
                 --output-variables PATTERN,… fewer columns"
            ),
        "{first}"
    );
    // The example's own size: no warning.
    let out = tether(
        &["run", sys.to_str().unwrap(), "--out", "small.csv"],
        dir.path(),
    );
    assert!(!success(&out).contains("GB"));
}

/// The control loop of docs/system-file.md ("[signals]"), iterated with too
/// few repetitions: without `strict` the run completes and the summary
/// counts the steps that did not converge, with one warning; with
/// `strict = true` the first such step fails the run with one line, the
/// rows so far kept and marked incomplete.
#[test]
fn an_iterated_step_that_does_not_converge_is_counted_or_fails_with_strict() {
    let dir = tempfile::tempdir().unwrap();
    let lti = tether_fmu_build::workspace_fmu("lti").unwrap();
    let write = |strict: bool| {
        let text = format!(
            r#"
            [experiment]
            stop = 0.05
            step = 1e-2

            [signals]
            iterations = 2
            strict = {strict}

            [[instance]]
            name = "controller"
            fmu = "{lti}"
            parameters = {{ a = 0.0, b1 = 1.0, b2 = -1.0, c = 2.0, d1 = 1.0, d2 = -1.0, u1 = 1.0 }}

            [[instance]]
            name = "plant"
            fmu = "{lti}"
            parameters = {{ a = -1.0, b1 = 1.0, c = 1.0, d1 = 0.5 }}

            [[connection]]
            from = "controller.y"
            to = "plant.u1"

            [[connection]]
            from = "plant.y"
            to = "controller.u2"
            "#,
            lti = lti.display()
        );
        let path = dir.path().join(format!("loop-{strict}.toml"));
        std::fs::write(&path, text).unwrap();
        path
    };
    let lenient = write(false);
    let out = tether(
        &["run", lenient.to_str().unwrap(), "--out", "a.csv"],
        dir.path(),
    );
    let text = success(&out);
    // The summary wraps its lines within 100 characters.
    let flat = text.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(
        flat.contains(
            "signal iterations per step: 2.00 on average, 2 at most (10 repeated runs of the \
             step); not converged: 5 steps"
        ),
        "{text}"
    );
    assert!(
        flat.contains("warning: 5 macro steps did not converge within [signals] iterations"),
        "{text}"
    );
    let strict = write(true);
    let out = tether(
        &["run", strict.to_str().unwrap(), "--out", "b.csv"],
        dir.path(),
    );
    let line = error_line(&out);
    assert!(
        line.contains(
            "[signals] strict: the macro step from t = 0 did not converge in 2 iterations"
        ),
        "{line}"
    );
    let csv = std::fs::read_to_string(dir.path().join("b.csv")).unwrap();
    assert!(
        csv.lines().last().unwrap().starts_with("# incomplete: "),
        "{csv}"
    );
    let rows = csv.lines().filter(|l| !l.starts_with('#')).count() - 1;
    assert_eq!(rows, 1, "the row at T_0 is kept: {csv}");
}

/// The texts of an SVG's `<text>` elements, in order.
fn svg_texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|s| s.split_once('>'))
        .filter_map(|(_, rest)| rest.split('<').next())
        .map(|t| t.trim().replace("&amp;", "&"))
        .collect()
}

/// `tether run --plot` without columns: the instances' coupled outputs first,
/// then the multiplier and the residual; a long title on two lines that fit;
/// no legend repeating the title.
#[test]
fn the_default_plot_of_a_run_shows_the_coupled_outputs_first() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/controlled_oscillator.toml"),
    )
    .unwrap();
    for fmu in ["oscillator", "controller"] {
        text = text.replace(
            &format!("../target/fmus/{fmu}.fmu"),
            &tether_fmu_build::workspace_fmu(fmu)
                .unwrap()
                .display()
                .to_string(),
        );
    }
    std::fs::write(dir.path().join("co.toml"), text).unwrap();
    let out = tether(
        &[
            "run", "co.toml", "--stop", "0.1", "--out", "r.csv", "--plot", "p.svg",
        ],
        dir.path(),
    );
    let said = success(&out);
    assert!(
        said.lines().any(|l| l
            == "note: p.svg plots 5 of the 9 columns (mass2.x, mass1.x, ctrl.u, link.lambda, \
                link.g); choose others"),
        "{said}"
    );
    let texts = svg_texts(&std::fs::read_to_string(dir.path().join("p.svg")).unwrap());
    assert_eq!(
        texts[..2],
        [
            "controlled two-mass oscillator: baumgarte (index 1, beta = 2e-3, gamma = 1e-6),",
            "signals: Jacobi, k = 1, H = 0.001",
        ]
    );
    let panels: Vec<&String> = texts
        .iter()
        .filter(|t| t.contains('.') && t.chars().next().is_some_and(char::is_alphabetic))
        .filter(|t| !t.starts_with("controlled") && !t.starts_with("signals"))
        .collect();
    assert_eq!(
        panels,
        [
            "mass2.x [m]",
            "mass1.x [m]",
            "ctrl.u [N]",
            "link.lambda",
            "link.g"
        ],
        "{texts:?}"
    );
    assert!(
        !texts.iter().any(|t| t == "controlled two-mass oscillator"),
        "{texts:?}"
    );
}

/// `tether simulate --plot`: the outputs with their units, titled with the model
/// and the grid; a plot file that is not SVG or PNG is refused before the run.
#[test]
fn simulate_plots_the_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let osc = oscillator();
    let fmu = osc.to_str().unwrap();
    let out = tether(
        &[
            "simulate", fmu, "--stop", "0.5", "--out", "s.csv", "--plot", "s.svg",
        ],
        dir.path(),
    );
    let said = success(&out);
    assert!(said.lines().any(|l| l == "plot: s.svg"), "{said}");
    let texts = svg_texts(&std::fs::read_to_string(dir.path().join("s.svg")).unwrap());
    assert_eq!(texts[0], "oscillator: H = 0.001, t = 0 … 0.5");
    for label in ["x [m]", "v [m/s]", "a [m/s2]", "time [s]"] {
        assert!(texts.iter().any(|t| t == label), "{label}: {texts:?}");
    }
    let out = tether(
        &[
            "simulate", fmu, "--stop", "0.5", "--out", "t.csv", "--plot", "s.txt",
        ],
        dir.path(),
    );
    assert_eq!(
        error_line(&out),
        "error: --plot s.txt: the file name must end in .svg or .png"
    );
    assert!(!dir.path().join("t.csv").exists());
}
