//! `tether sweep`, `tether study`, `tether plot` and `tether run --plot` as a user runs them.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn tether(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_tether"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run tether")
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// The oscillator system with exact integration, written into `dir`.
fn system(dir: &Path) -> PathBuf {
    let fmu = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU");
    let text = format!(
        r#"
        name = "oscillator"
        [experiment]
        stop = 1.0
        step = 5e-3
        [method]
        kind = "baumgarte"
        beta = 0.2
        gamma = 1e-2
        [[instance]]
        name = "mass1"
        fmu = "{fmu}"
        parameters = {{ m = 1.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0, exact = true }}
        [[instance]]
        name = "mass2"
        fmu = "{fmu}"
        parameters = {{ m = 2.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0, exact = true }}
        [[constraint]]
        name = "link"
        position = "mass2.x - mass1.x"
        velocity = "mass2.v - mass1.v"
        acceleration = "mass2.a - mass1.a"
        drives = "mass1.F - mass2.F"
        "#,
        fmu = fmu.display()
    );
    let path = dir.join("osc.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn one_line_error(out: &Output) -> String {
    assert!(!out.status.success(), "{}", text(out));
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!stderr.contains("panicked"), "{stderr}");
    let last = stderr.lines().last().unwrap_or_default().to_string();
    assert!(last.starts_with("error: "), "{stderr}");
    last
}

#[test]
fn sweep_stability_classifies_a_tiny_grid_and_writes_csv_and_plot() {
    let dir = tempfile::tempdir().unwrap();
    system(dir.path());
    let out = tether(
        &[
            "sweep",
            "stability",
            "osc.toml",
            "--x",
            "mass1.c,mass2.c=1e3,1e5:log",
            "--y",
            "mass1.d,mass2.d=10",
            "--growth",
            "1",
            "--monitor",
            "mass1.v",
            "--format",
            "svg,png",
            "--out-dir",
            "maps",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", text(&out));
    assert!(
        text(&out).contains("1 stable, 1 unstable, 0 failed"),
        "{}",
        text(&out)
    );
    let csv = std::fs::read_to_string(dir.path().join("maps/stability.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 3, "{csv}");
    assert!(
        lines[1].contains(",stable,") && lines[2].contains(",unstable,"),
        "{csv}"
    );
    for ext in ["svg", "png"] {
        assert!(dir.path().join(format!("maps/stability.{ext}")).exists());
    }
}

#[test]
fn sweep_convergence_prints_the_fitted_order() {
    let dir = tempfile::tempdir().unwrap();
    system(dir.path());
    let out = tether(
        &[
            "sweep",
            "convergence",
            "osc.toml",
            "--beta",
            "2e-3",
            "--gamma",
            "0",
            "--stop",
            "0.2",
            "--steps",
            "2e-3,1e-3",
            "--reference",
            "two-mass-oscillator",
            "--columns",
            "mass1.x,mass1.v",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", text(&out));
    let t = text(&out);
    let order: f64 = t
        .split("fitted order ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no order in {t}"));
    assert!((1.8..2.3).contains(&order), "{t}");
    assert!(dir.path().join("convergence.csv").exists());
}

#[test]
fn run_plot_and_plot_command_draw_results() {
    let dir = tempfile::tempdir().unwrap();
    system(dir.path());
    let out = tether(
        &[
            "run", "osc.toml", "--stop", "0.1", "--out", "r.csv", "--plot", "r.png", "-q",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", text(&out));
    assert!(std::fs::metadata(dir.path().join("r.png")).unwrap().len() > 1000);
    let out = tether(
        &[
            "plot",
            "r.csv",
            "--columns",
            "mass1.x,link.lambda",
            "--out",
            "p.svg",
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", text(&out));
    let svg = std::fs::read_to_string(dir.path().join("p.svg")).unwrap();
    assert!(svg.contains("link.lambda"));
}

/// A wide results file: the default plot has at most 8 panels, and a line
/// says which columns it shows and how to choose others.
#[test]
fn a_default_plot_has_at_most_eight_panels() {
    let dir = tempfile::tempdir().unwrap();
    let names: Vec<String> = (0..20).map(|i| format!("body{i}.x")).collect();
    let mut csv = format!("time,{}\n", names.join(","));
    for k in 0..5 {
        let row: Vec<String> = (0..20).map(|i| format!("{}", i * k)).collect();
        csv += &format!("{},{}\n", f64::from(k) * 0.1, row.join(","));
    }
    std::fs::write(dir.path().join("wide.csv"), csv).unwrap();
    let out = tether(&["plot", "wide.csv", "--out", "w.svg"], dir.path());
    assert!(out.status.success(), "{}", text(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    let note: Vec<&str> = stderr
        .lines()
        .take_while(|l| !l.starts_with("plot:"))
        .collect();
    assert_eq!(
        note,
        [
            "note: w.svg plots 8 of the 20 columns (body0.x, body1.x, body2.x, body3.x, body4.x, \
             body5.x,",
            "  body6.x, body7.x); choose others with --columns NAME,…",
        ]
    );
    let svg = std::fs::read_to_string(dir.path().join("w.svg")).unwrap();
    assert!(svg.contains("body7.x") && !svg.contains("body8.x"));
}

#[test]
fn bad_sweeps_and_plots_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    system(dir.path());
    std::fs::write(dir.path().join("r.csv"), "time,a.x\n0,1\n1,2\n").unwrap();
    for (args, word) in [
        (
            vec![
                "sweep",
                "stability",
                "osc.toml",
                "--x",
                "mass1.c",
                "--y",
                "step=1e-3",
            ],
            "'='",
        ),
        (
            vec![
                "sweep",
                "stability",
                "osc.toml",
                "--x",
                "mass9.c=1,2",
                "--y",
                "step=1e-3",
            ],
            "mass9",
        ),
        (
            vec![
                "sweep",
                "convergence",
                "osc.toml",
                "--steps",
                "1e-3",
                "--columns",
                "mass1.x",
            ],
            "two steps",
        ),
        (
            vec!["plot", "r.csv", "--columns", "a.v", "--out", "p.svg"],
            "a.v",
        ),
        (vec!["plot", "r.csv", "--out", "p.gif"], ".svg or .png"),
    ] {
        let line = one_line_error(&tether(&args, dir.path()));
        assert!(line.contains(word), "{args:?}: {line}");
    }
}
