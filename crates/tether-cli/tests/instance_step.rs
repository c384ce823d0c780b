//! Per-instance communication steps (`step` of an `[[instance]]`,
//! docs/system-file.md "Per-instance steps") through the `tether` binary:
//! an instance at n·H steps as the FMU alone at n·H does, its outputs held in
//! between; what cannot have its own step is refused in one line. Against
//! libcosim's decimation: tests/libcosim_quarter_truck.rs.

mod common;

use std::path::{Path, PathBuf};

use common::{read_csv as csv, tether};

fn fmu(name: &str) -> PathBuf {
    tether_fmu_build::workspace_fmu(name).expect("package the workspace FMU")
}

fn column(header: &[String], name: &str) -> usize {
    header.iter().position(|c| c == name).unwrap()
}

/// The oscillator (exact) alone at step = 4·H equals `tether simulate` at
/// 4e-3 at its communication points, bit for bit, and holds its outputs
/// in between; the CSV keeps the system's grid.
#[test]
fn an_instance_at_its_own_step_steps_as_the_fmu_alone_at_that_step() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let osc = fmu("oscillator");
    let system = format!(
        r#"
        [experiment]
        stop = 0.1
        step = 1e-3

        [[instance]]
        name = "mass"
        fmu = "{}"
        step = 4e-3
        parameters = {{ exact = true }}
        "#,
        osc.display()
    );
    std::fs::write(d.join("system.toml"), system).unwrap();
    let out = tether(
        &[
            "run",
            "system.toml",
            "--out",
            "run.csv",
            "--summary-json",
            "s.json",
        ],
        d,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = tether(
        &[
            "simulate",
            osc.to_str().unwrap(),
            "--stop",
            "0.1",
            "--step",
            "4e-3",
            "--set",
            "exact=true",
            "--out",
            "alone.csv",
        ],
        d,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (h_run, run) = csv(&d.join("run.csv"));
    let (h_alone, alone) = csv(&d.join("alone.csv"));
    assert_eq!(run.len(), 101, "the system's grid");
    assert_eq!(alone.len(), 26);
    for name in ["x", "v"] {
        let (a, b) = (
            column(&h_run, &format!("mass.{name}")),
            column(&h_alone, name),
        );
        for (n, row) in run.iter().enumerate() {
            let expected = alone[n / 4][b];
            assert_eq!(
                row[a].to_bits(),
                expected.to_bits(),
                "mass.{name} at row {n}"
            );
        }
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("s.json")).unwrap()).unwrap();
    assert_eq!(summary["instances"]["mass"]["do_step"], 25, "{summary}");
}

/// The controlled oscillator (a rigid link between two masses, a PI
/// controller on signals) with the controller at 4·H runs; refused in one
/// line each: a step that is not n·H, an instance in a constraint,
/// Gauss–Seidel, iterated signals, adaptive steps, and `--set ctrl.step`.
#[test]
fn what_cannot_have_its_own_step_is_refused_in_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let example = std::fs::read_to_string(root.join("examples/controlled_oscillator.toml"))
        .unwrap()
        .replace(
            "../target/fmus/controller.fmu",
            fmu("controller").to_str().unwrap(),
        )
        .replace(
            "../target/fmus/oscillator.fmu",
            fmu("oscillator").to_str().unwrap(),
        )
        .replace("../target/fmus/link.fmu", fmu("link").to_str().unwrap());
    let with = |name: &str, instance: &str, step: &str, extra: &str| {
        let text = example.replace(
            &format!("name = \"{instance}\"\n"),
            &format!("name = \"{instance}\"\nstep = {step}\n"),
        );
        let text = format!("{text}\n{extra}");
        std::fs::write(d.join(name), text).unwrap();
        name.to_string()
    };
    let runs = with("ok.toml", "ctrl", "4e-3", "");
    let out = tether(&["run", &runs, "--stop", "0.1", "--out", "ok.csv"], d);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let error = |file: &str, args: &[&str]| {
        let mut all = vec!["run", file, "--stop", "0.1", "--out", "x.csv"];
        all.extend(args);
        let out = tether(&all, d);
        let text = String::from_utf8_lossy(&out.stderr).into_owned();
        assert_eq!(out.status.code(), Some(1), "{text}");
        assert_eq!(text.lines().count(), 1, "{text}");
        text.trim_end().to_string()
    };
    let line = error(&with("half.toml", "ctrl", "2.5e-3", ""), &[]);
    assert!(
        line.starts_with("error: system file ") && line.ends_with(
            "half.toml: instance 'ctrl': step = 0.0025 is not a whole multiple of the system's macro step H = 0.001"
        ),
        "{line}"
    );
    let line = error(&with("linked.toml", "mass1", "4e-3", ""), &[]);
    assert!(
        line.ends_with(
            "linked.toml: instance 'mass1': step = 0.004 (4·H) is refused: it is in a constraint, joint \
             or coupling variable, which every macro step solves"
        ),
        "{line}"
    );
    let gauss = example.replace("scheme = \"jacobi\"", "scheme = \"gauss_seidel\"");
    std::fs::write(
        d.join("gs.toml"),
        gauss.replace("name = \"ctrl\"\n", "name = \"ctrl\"\nstep = 4e-3\n"),
    )
    .unwrap();
    let line = error("gs.toml", &[]);
    assert!(
        line.ends_with(
            "gs.toml: instance 'ctrl': step = 0.004 (4·H) is refused: its signals use the \
             Gauss-Seidel scheme; per-instance steps run with Jacobi"
        ),
        "{line}"
    );
    let iterated = example.replace("scheme = \"jacobi\"", "scheme = \"jacobi\"\niterations = 5");
    std::fs::write(
        d.join("iterated.toml"),
        iterated.replace("name = \"ctrl\"\n", "name = \"ctrl\"\nstep = 4e-3\n"),
    )
    .unwrap();
    let line = error("iterated.toml", &[]);
    assert!(
        line.ends_with(
            "iterated.toml: instance 'ctrl': step = 0.004 (4·H) is refused: the system iterates its \
             signals at every macro step ([signals] iterations)"
        ),
        "{line}"
    );
    let line = error(&runs, &["--step-rtol", "1e-4"]);
    assert!(
        line.ends_with(
            "ok.toml: instance 'ctrl': step = 0.004 (4·H) is refused: the system has adaptive macro \
             steps ([step_control])"
        ),
        "{line}"
    );
    let line = error(&runs, &["--set", "ctrl.step=2e-3"]);
    assert_eq!(
        line,
        "error: target 'ctrl.step': 'step' of instance 'ctrl' is its communication step in the \
         system file, which --set does not change (it sets FMU variables)"
    );
}

/// k = 1 into an instance at its own step: the polynomial through the
/// sender's values at the receiver's last two communication points, spacing
/// n·H. A PI controller with kp = 0, ki = 1, r = 0.1 and no input sends the
/// ramp u = 0.1·t to a free mass (exact integration) at 4·H: the ramp's
/// extrapolation is exact from the second point on (the first step holds
/// u = 0, degree min(k, 0)), so at its communication points T ≥ h = 4·H
/// x(T) = 0.1·((T³ − h³)/6 − h²(T − h)/2), the closed form.
#[test]
fn polynomial_inputs_of_an_instance_at_its_own_step_use_its_spacing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let system = format!(
        r#"
        [experiment]
        stop = 0.1
        step = 1e-3

        [method]
        kind = "baumgarte"
        index = 1

        [coupling]
        order = 1

        [[instance]]
        name = "ctrl"
        fmu = "{ctrl}"
        parameters = {{ kp = 0.0, ki = 1.0, r = 0.1 }}

        [[instance]]
        name = "mass"
        fmu = "{osc}"
        step = 4e-3
        parameters = {{ m = 1.0, c = 0.0, d = 0.0, x0 = 0.0, v0 = 0.0, exact = true }}

        [[connection]]
        from = "ctrl.u"
        to = "mass.F_ext"
        "#,
        ctrl = fmu("controller").display(),
        osc = fmu("oscillator").display()
    );
    std::fs::write(d.join("ramp.toml"), system).unwrap();
    let out = tether(&["run", "ramp.toml", "--out", "ramp.csv"], d);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (header, rows) = csv(&d.join("ramp.csv"));
    let (t, x) = (column(&header, "time"), column(&header, "mass.x"));
    let h = 4e-3;
    let mut worst: f64 = 0.0;
    for (n, row) in rows.iter().enumerate() {
        let at = &rows[n - n % 4];
        assert_eq!(row[x].to_bits(), at[x].to_bits(), "held at row {n}");
        let time = at[t];
        let expected = if time < h {
            0.0
        } else {
            0.1 * ((time.powi(3) - h.powi(3)) / 6.0 - h * h * (time - h) / 2.0)
        };
        worst = worst.max((row[x] - expected).abs() / expected.abs().max(1e-12));
    }
    assert!(worst <= 1e-9, "largest relative error {worst:e}");
}
