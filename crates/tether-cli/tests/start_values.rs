//! Where start values go (issue 66, docs/fmi-import.md "Start values"):
//! FMI 2.0 `fmi2SetupExperiment` right after `fmi2Instantiate`, then the
//! start values, then `fmi2EnterInitializationMode`, as FMPy and libcosim
//! do; and the read-back of the parameters set with `initial="exact"` after
//! initialization. With the workspace FMU `quirks`, whose
//! `reset_parameters = 1` resets every parameter in `fmi2SetupExperiment`
//! (as FMUs of some modelling tools do) and `reset_parameters = 2` in
//! `fmi2ExitInitializationMode`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use tether_fmi::Fmu;

fn tether(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tether")
}

fn quirks() -> PathBuf {
    tether_fmu_build::workspace_fmu("quirks").expect("package the quirks FMU")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn success(out: &Output) -> String {
    let text = stderr(out);
    assert!(out.status.success(), "expected success: {text}");
    assert!(!text.contains("panicked"), "{text}");
    text
}

fn warnings(text: &str) -> Vec<&str> {
    text.lines().filter(|l| l.starts_with("warning:")).collect()
}

/// The FMU itself, driven in the two orders: a value set before
/// `fmi2SetupExperiment` is lost in mode 1, one set after it stays; in mode
/// 2 both are lost. This is what the importer's order decides.
#[test]
fn the_quirks_fmu_resets_its_parameters_where_its_mode_says() {
    let fmu = Fmu::open(quirks()).unwrap();
    let md = fmu.model_description();
    let vr = |name: &str| md.value_reference(name).unwrap();
    let m_after_init = |mode: i32, set_before_setup: bool| -> f64 {
        let mut i = fmu.instantiate("q", Default::default()).unwrap();
        let set = |i: &mut tether_fmi::Instance| {
            i.set_integer(&[vr("reset_parameters")], &[mode]).unwrap();
            i.set_real(&[vr("m")], &[2.0]).unwrap();
        };
        if set_before_setup {
            set(&mut i);
        }
        i.setup_experiment(None, 0.0, Some(1.0)).unwrap();
        if !set_before_setup {
            set(&mut i);
        }
        i.enter_initialization_mode().unwrap();
        i.exit_initialization_mode().unwrap();
        let mut m = [0.0];
        i.get_real(&[vr("m")], &mut m).unwrap();
        m[0]
    };
    // Mode 0: the value stays in either order.
    assert_eq!(m_after_init(0, true), 2.0);
    assert_eq!(m_after_init(0, false), 2.0);
    // Mode 1: lost when set before fmi2SetupExperiment (Tether's order
    // before issue 66), kept when set after it (FMPy's, libcosim's, Tether's).
    assert_eq!(m_after_init(1, true), 1.0);
    assert_eq!(m_after_init(1, false), 2.0);
    // Mode 2: lost whatever the order.
    assert_eq!(m_after_init(2, true), 1.0);
    assert_eq!(m_after_init(2, false), 1.0);
}

fn simulate(dir: &Path, out: &str, sets: &[&str]) -> (String, String) {
    let fmu = quirks();
    let mut args = vec![
        "simulate",
        fmu.to_str().unwrap(),
        "--stop",
        "0.2",
        "--step",
        "1e-2",
        "--out",
        out,
    ];
    for s in sets {
        args.extend(["--set", s]);
    }
    let text = success(&tether(&args, dir));
    (text, std::fs::read_to_string(dir.join(out)).unwrap())
}

/// `tether simulate`: with `reset_parameters = 1` the value of `--set` is
/// taken (the CSV equals the well-behaved FMU's with the same value), no
/// warning.
#[test]
fn simulate_sets_start_values_after_setup_experiment() {
    let dir = tempfile::tempdir().unwrap();
    let (text, resetting) = simulate(
        dir.path(),
        "reset.csv",
        &["reset_parameters=1", "m=2", "c=800"],
    );
    assert!(warnings(&text).is_empty(), "{text}");
    let (_, plain) = simulate(dir.path(), "plain.csv", &["m=2", "c=800"]);
    let (_, default) = simulate(dir.path(), "default.csv", &[]);
    assert_eq!(resetting, plain);
    assert_ne!(plain, default, "m and c change the result");
}

/// `tether simulate` with `reset_parameters = 2`: every parameter set is
/// lost in initialization, and each one changed is one warning line with
/// the value set and the value read.
#[test]
fn simulate_warns_of_each_parameter_the_fmu_changed() {
    let dir = tempfile::tempdir().unwrap();
    let (text, csv) = simulate(
        dir.path(),
        "reset.csv",
        &["reset_parameters=2", "m=2", "v0=100"],
    );
    let (_, default) = simulate(dir.path(), "default.csv", &[]);
    assert_eq!(csv, default, "the FMU runs with its start values");
    // The instance of `tether simulate` is named by the model identifier;
    // v0 = 100 is its start value: not changed, no line. The lines come in
    // the order of `--set`.
    assert_eq!(
        warnings(&text),
        [
            "warning: instance 'quirks': the FMU changed parameter 'reset_parameters' in its initialization: set to 2, reads 0",
            "warning: instance 'quirks': the FMU changed parameter 'm' in its initialization: set to 2, reads 1",
        ],
        "{text}"
    );
}

fn system(dir: &Path, name: &str, mass: &str) -> PathBuf {
    let text = format!(
        r#"
        [experiment]
        stop = 0.2
        step = 1e-2

        [[instance]]
        name = "mass"
        fmu = "{fmu}"
        parameters = {{ {mass} }}

        [[instance]]
        name = "other"
        fmu = "{fmu}"
        parameters = {{ c = 400.0 }}
        "#,
        fmu = quirks().display()
    );
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn run(dir: &Path, system: &Path, out: &str) -> (String, String, serde_json::Value) {
    let summary = dir.join(format!("{out}.json"));
    let text = success(&tether(
        &[
            "run",
            system.to_str().unwrap(),
            "--out",
            out,
            "--summary-json",
            summary.to_str().unwrap(),
        ],
        dir,
    ));
    let csv = std::fs::read_to_string(dir.join(out)).unwrap();
    let json = serde_json::from_str(&std::fs::read_to_string(summary).unwrap()).unwrap();
    (text, csv, json)
}

/// `tether run`: the same, for an instance of a system; the read-back is not
/// in the summary's call counts.
#[test]
fn run_sets_start_values_after_setup_experiment_and_reads_them_back() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let plain = system(d, "plain.toml", "m = 2.0, c = 800.0");
    let reset_at_setup = system(d, "setup.toml", "reset_parameters = 1, m = 2.0, c = 800.0");
    let reset_at_init = system(d, "init.toml", "reset_parameters = 2, c = 800.0");
    let default = system(d, "default.toml", "");
    let (text, plain_csv, plain_json) = run(d, &plain, "plain.csv");
    assert!(warnings(&text).is_empty(), "{text}");
    let (text, setup_csv, _) = run(d, &reset_at_setup, "setup.csv");
    assert!(warnings(&text).is_empty(), "{text}");
    assert_eq!(setup_csv, plain_csv);
    let (text, init_csv, init_json) = run(d, &reset_at_init, "init.csv");
    let (_, default_csv, default_json) = run(d, &default, "default.csv");
    assert_eq!(init_csv, default_csv);
    assert_ne!(plain_csv, default_csv);
    assert_eq!(
        warnings(&text),
        [
            "warning: instance 'mass': the FMU changed parameter 'c' in its initialization: set to 800, reads 1000",
            "warning: instance 'mass': the FMU changed parameter 'reset_parameters' in its initialization: set to 2, reads 0",
        ],
        "{text}"
    );
    // Parameters read back or not, the same calls are counted.
    for json in [&plain_json, &init_json] {
        assert_eq!(json["instances"], default_json["instances"]);
    }
}

/// The kit's `tolerance` parameter: its `fmi2SetupExperiment` sets it from
/// the experiment's tolerance (`tether simulate` passes the FMU's
/// DefaultExperiment tolerance, 1e-10), and a `tolerance` the user sets
/// comes after it and wins.
#[test]
fn a_tolerance_the_user_sets_wins_over_the_experiments() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let fmu = tether_fmu_build::workspace_fmu("oscillator").unwrap();
    let fmu = fmu.to_str().unwrap();
    let csv = |out: &str, sets: &[&str]| {
        let mut args = vec!["simulate", fmu, "--stop", "0.5", "--out", out];
        for s in sets {
            args.extend(["--set", s]);
        }
        let text = success(&tether(&args, d));
        assert!(warnings(&text).is_empty(), "{text}");
        std::fs::read_to_string(d.join(out)).unwrap()
    };
    let loose = csv("loose.csv", &["tolerance=1e-3"]);
    let default = csv("default.csv", &[]);
    let strict = csv("strict.csv", &["tolerance=1e-10"]);
    assert_eq!(strict, default, "1e-10 is the experiment's tolerance");
    assert_ne!(
        loose, default,
        "the user's tolerance 1e-3 is the integrator's"
    );
}

/// A system exported as an FMU: its members take their start values (the
/// system file's and the exported parameters', set by the importer) after
/// `fmi2SetupExperiment` too, and a member's changed parameter is a warning
/// the exported FMU logs to its importer.
#[test]
fn an_exported_systems_members_take_their_start_values_after_setup() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let write = |name: &str, parameters: &str| {
        let text = format!(
            r#"
            [experiment]
            stop = 0.2
            step = 1e-2

            [[instance]]
            name = "mass"
            fmu = "{fmu}"
            parameters = {{ {parameters} }}

            [export]
            model_name = "exported_mass"

            [[export.parameter]]
            name = "c"
            to = "mass.c"

            [[export.output]]
            name = "x"
            from = "mass.x"
            "#,
            fmu = quirks().display()
        );
        std::fs::write(d.join(name), text).unwrap();
    };
    write("plain.toml", "m = 2.0");
    write("setup.toml", "reset_parameters = 1, m = 2.0");
    write("init.toml", "reset_parameters = 2, m = 2.0");
    // The plain member with c = 800, run by tether run.
    let text = std::fs::read_to_string(d.join("plain.toml"))
        .unwrap()
        .replace("m = 2.0", "m = 2.0, c = 800.0");
    std::fs::write(d.join("direct.toml"), text).unwrap();
    success(&tether(&["run", "direct.toml", "--out", "direct.csv"], d));
    let direct = std::fs::read_to_string(d.join("direct.csv")).unwrap();
    let x_of = |csv: &str, column: &str| -> Vec<String> {
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let i = header.iter().position(|c| *c == column).unwrap();
        lines
            .map(|l| l.split(',').nth(i).unwrap().to_string())
            .collect()
    };
    let exported = |system: &str| {
        let fmu = format!("{system}.fmu");
        success(&tether(
            &["fmu", "export", &format!("{system}.toml"), "--out", &fmu],
            d,
        ));
        let out = format!("{system}.csv");
        let text = success(&tether(
            &[
                "simulate", &fmu, "--stop", "0.2", "--step", "1e-2", "--set", "c=800", "--out",
                &out,
            ],
            d,
        ));
        (text, std::fs::read_to_string(d.join(out)).unwrap())
    };
    let (text, csv) = exported("setup");
    assert!(!text.contains("changed parameter"), "{text}");
    assert_eq!(x_of(&csv, "x"), x_of(&direct, "mass.x"));
    let (text, csv) = exported("init");
    assert!(
        text.contains(
            "[WARN  fmu::exported_mass] [logStatusWarning] instance 'mass': the FMU changed \
             parameter 'c' in its initialization: set to 800, reads 1000"
        ),
        "{text}"
    );
    assert_ne!(x_of(&csv, "x"), x_of(&direct, "mass.x"));
}
