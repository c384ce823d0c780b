//! Iterated signal coupling (`[signals] iterations`, docs/algorithm.md,
//! "Signal connections"): the control loop of tests/master_signal_loops.rs
//! with a PI controller that can roll back — fmus/lti as the controller
//! (z' = u1 − u2, U = ki z + kp u1 − kp u2 with u1 = r) — so that every
//! macro step can be repeated from its saved states until the exchanged
//! values agree.
//!
//! The reference is the loop's implicit discretization, which a converged
//! iterated step with held inputs (k = 0) computes: every instance steps
//! exactly from T_N with its inputs held at the values the senders give at
//! T_{N+1}. With w the source, z the controller's and x the plant's state,
//! and U, Y the values at T_{N+1} of the loop's two connections:
//!
//! w₁ = e^{a_s H} w,  z₁ = z + H (r − Y),  U = ki z₁ + kp (r − Y),
//! x₁ = e^{a H} x + H φ₁(a H) (b1 U + b2 w₁),  Y = c x₁ + d1 U + d2 w₁,
//!
//! two linear equations in U and Y per step (φ₁(z) = (e^z − 1)/z).

use tether_master::{MemoryRecorder, SignalSolver, Simulation, SystemSpec};

use tether_tests::control_loop::*;

/// The controller's proportional gain (loop gain D1·KP = 0.5).
const KP: f64 = 1.0;

/// The implicit discretization's Y at T_1 … T_steps (after Y_0, the
/// consistent start).
fn implicit(h: f64, steps: usize) -> Vec<f64> {
    let phi1 = (A * h).exp_m1() / (A * h);
    let (mut w, mut z, mut x) = (1.0_f64, 0.0_f64, 0.0_f64);
    let mut out = Vec::with_capacity(steps);
    for _ in 0..steps {
        let w1 = (A_S * h).exp() * w;
        // [1, kp + ki H; −(d1 + c H φ₁ b1), 1] [U; Y] = [p; q]
        let (a11, a12) = (1.0, KP + KI * h);
        let (a21, a22) = (-(D1 + C * h * phi1 * B1), 1.0);
        let p = KI * z + KI * h * R + KP * R;
        let q = C * (A * h).exp() * x + C * h * phi1 * B2 * w1 + D2 * w1;
        let det = a11 * a22 - a12 * a21;
        let u = (p * a22 - a12 * q) / det;
        let y = (a11 * q - a21 * p) / det;
        z += h * (R - y);
        x = (A * h).exp() * x + h * phi1 * (B1 * u + B2 * w1);
        w = w1;
        out.push(y);
    }
    out
}

/// The loop with the lti controller; `signals` is the `[signals]` table's
/// body, `order` the degree k.
fn system(h: f64, steps: usize, order: usize, signals: &str) -> SystemSpec {
    let lti = tether_fmu_build::workspace_fmu("lti").expect("package lti");
    let stop = h * steps as f64;
    let text = format!(
        r#"
        [experiment]
        stop = {stop}
        step = {h}

        [coupling]
        order = {order}

        [signals]
        tolerance = 1e-12
        {signals}

        [[instance]]
        name = "source"
        fmu = "{lti}"
        parameters = {{ a = {A_S}, b1 = 0.0, c = 1.0, x0 = 1.0 }}

        [[instance]]
        name = "controller"
        fmu = "{lti}"
        parameters = {{ a = 0.0, b1 = 1.0, b2 = -1.0, c = {KI}, d1 = {KP}, d2 = {mkp}, x0 = 0.0, u1 = {R} }}

        [[instance]]
        name = "plant"
        fmu = "{lti}"
        parameters = {{ a = {A}, b1 = {B1}, b2 = {B2}, c = {C}, d1 = {D1}, d2 = {D2}, x0 = 0.0 }}

        [[connection]]
        from = "source.y"
        to = "plant.u2"

        [[connection]]
        from = "controller.y"
        to = "plant.u1"

        [[connection]]
        from = "plant.y"
        to = "controller.u2"
        "#,
        lti = lti.display(),
        mkp = -KP,
    );
    SystemSpec::from_toml(&text).unwrap()
}

/// A run's `plant.y` rows and its summary's iteration counts
/// (iterations, most in one step, steps not converged).
fn run(spec: &SystemSpec) -> (Vec<f64>, (u64, u64, u64)) {
    let mut sim = Simulation::new(spec).unwrap();
    let mut rec = MemoryRecorder::default();
    let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
    let y = rec.columns.iter().position(|c| c == "plant.y").unwrap();
    let counts = stats.signals.map_or((0, 0, 0), |s| {
        (s.iterations, s.max_iterations, s.not_converged)
    });
    (rec.rows.iter().map(|row| row[y]).collect(), counts)
}

/// Largest |a − b| over rows 1… (row 0 is the consistent start).
fn max_deviation(rows: &[f64], reference: &[f64]) -> f64 {
    assert_eq!(rows.len(), reference.len() + 1);
    rows[1..]
        .iter()
        .zip(reference)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

const H: f64 = 1e-2;
const STEPS: usize = 100;

/// Iterated to convergence, Jacobi and Gauss–Seidel (fixed point) and
/// Newton all give the implicit discretization, to the tolerance; the
/// non-iterated schemes differ from it at first order in H. Newton needs
/// far fewer updates per step than the fixed point, and Gauss–Seidel fewer
/// than Jacobi (it passes one of the loop's two values within the sweep).
#[test]
fn iterated_steps_converge_to_the_implicit_discretization() {
    let reference = implicit(H, STEPS);
    let mut counts = Vec::new();
    for signals in [
        "scheme = \"jacobi\"\niterations = 200",
        "scheme = \"gauss_seidel\"\niterations = 200",
        "solver = \"newton\"\niterations = 10",
    ] {
        let (rows, (total, most, failed)) = run(&system(H, STEPS, 0, signals));
        let deviation = max_deviation(&rows, &reference);
        let mean = total as f64 / STEPS as f64;
        eprintln!(
            "{}: max |Y − Y_implicit| = {deviation:.3e}, iterations per step {mean:.2} (at most {most})",
            signals.replace('\n', ", ")
        );
        assert_eq!(failed, 0, "{signals}");
        assert!(deviation < 1e-10, "{signals}: {deviation:e}");
        counts.push(most);
    }
    let (jacobi, gauss_seidel, newton) = (counts[0], counts[1], counts[2]);
    assert!((1..=2).contains(&newton), "Newton: {newton}");
    assert!(gauss_seidel >= 10 * newton, "{gauss_seidel} vs {newton}");
    assert!(jacobi > gauss_seidel, "{jacobi} vs {gauss_seidel}");
    // Without iterations: the schemes close the loop at macro points, an
    // error of order H against the same implicit result.
    for scheme in ["jacobi", "gauss_seidel"] {
        let (rows, counts) = run(&system(H, STEPS, 0, &format!("scheme = \"{scheme}\"")));
        let deviation = max_deviation(&rows, &reference);
        eprintln!("{scheme}, not iterated: max |Y − Y_implicit| = {deviation:.3e}");
        assert_eq!(counts, (0, 0, 0));
        assert!(deviation > 1e-4, "{scheme}: {deviation:e}");
    }
}

/// The implicit discretization itself converges at first order in H to the
/// monolithic loop (the closed form of tests/master_signal_loops.rs is the
/// same system): the converged iterations are a first-order method, which
/// halving H shows.
#[test]
fn the_implicit_result_is_first_order_in_h() {
    let error = |h: f64, steps: usize| {
        let (rows, _) = run(&system(h, steps, 0, "solver = \"newton\"\niterations = 10"));
        rows.iter()
            .enumerate()
            .map(|(n, y)| (y - monolithic(KP, n as f64 * h)).abs())
            .fold(0.0, f64::max)
    };
    let coarse = error(2e-2, 50);
    let fine = error(1e-2, 100);
    eprintln!("Newton-iterated: max |Y − Y_mono| {coarse:.3e} (H = 2e-2), {fine:.3e} (H = 1e-2), ratio {:.3}", coarse / fine);
    assert!((coarse / fine - 2.0).abs() < 0.15, "{coarse:e} / {fine:e}");
}

/// With inputs interpolated (k = 1, the lti FMU takes input derivatives),
/// each repetition hands the receivers the line through y_N and the
/// iterate: the converged results of Jacobi, Gauss–Seidel and Newton are
/// the same fixed point and agree within the tolerance.
#[test]
fn converged_schemes_agree_with_interpolated_inputs() {
    let runs: Vec<Vec<f64>> = [
        "scheme = \"jacobi\"\niterations = 200",
        "scheme = \"gauss_seidel\"\niterations = 200",
        "solver = \"newton\"\niterations = 10",
    ]
    .iter()
    .map(|signals| {
        let (rows, (_, _, failed)) = run(&system(H, STEPS, 1, signals));
        assert_eq!(failed, 0, "{signals}");
        rows
    })
    .collect();
    for other in &runs[1..] {
        let d = max_deviation(other, &runs[0][1..]);
        eprintln!("k = 1: max difference to Jacobi-iterated {d:.3e}");
        assert!(d < 1e-10, "{d:e}");
    }
    // And they are not the held-input result.
    let (held, _) = run(&system(H, STEPS, 0, "solver = \"newton\"\niterations = 10"));
    assert!(max_deviation(&held, &runs[0][1..]) > 1e-5);
}

/// Too few iterations: reported and counted, the run completes; with
/// `strict = true` the run fails at the first such step with one line.
#[test]
fn steps_that_do_not_converge_are_counted_or_fail_the_run() {
    let (rows, (total, most, failed)) = run(&system(H, 20, 0, "iterations = 2"));
    assert_eq!(rows.len(), 21);
    assert_eq!((most, failed), (2, 20), "{total}");
    let spec = system(H, 20, 0, "iterations = 2\nstrict = true");
    let mut sim = Simulation::new(&spec).unwrap();
    let mut rec = MemoryRecorder::default();
    let message = sim
        .run(&mut [&mut rec], &mut |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        message.starts_with(
            "[signals] strict: the macro step from t = 0 did not converge in 2 iterations: \
             |Δv| of connection "
        ),
        "{message}"
    );
    assert!(!message.contains('\n'), "{message}");
    assert_eq!(rec.rows.len(), 1, "the rows before the failure are kept");
    let stats = sim.stats();
    assert_eq!(stats.failure.unwrap().kind, "signals_not_converged");
}

/// An instance without FMU state handling (fmus/controller) cannot repeat a
/// step: refused by name before the first step.
#[test]
fn an_instance_without_rollback_is_refused_by_name() {
    let lti = tether_fmu_build::workspace_fmu("lti").expect("package lti");
    let ctrl = tether_fmu_build::workspace_fmu("controller").expect("package the controller");
    let text = format!(
        r#"
        [experiment]
        stop = 0.1
        step = 0.01

        [signals]
        iterations = 5

        [[instance]]
        name = "pi"
        fmu = "{ctrl}"
        parameters = {{ kp = 1.0, ki = 2.0, r = 1.0 }}

        [[instance]]
        name = "plant"
        fmu = "{lti}"
        parameters = {{ d1 = 0.5 }}

        [[connection]]
        from = "pi.u"
        to = "plant.u1"

        [[connection]]
        from = "plant.y"
        to = "pi.y"
        "#,
        lti = lti.display(),
        ctrl = ctrl.display(),
    );
    let spec = SystemSpec::from_toml(&text).unwrap();
    let message = match Simulation::new(&spec) {
        Ok(_) => panic!("the PI controller cannot roll back"),
        Err(e) => e.to_string(),
    };
    assert_eq!(
        message,
        "instance 'pi' (controller) does not declare canGetAndSetFMUstate, which [signals] \
         iterations (every instance repeats the macro step from its state at T_N) needs"
    );
}

/// The setup's note says the loop is iterated, and how.
#[test]
fn the_note_says_how_the_loop_is_iterated() {
    let notes = |signals: &str| {
        Simulation::new(&system(H, 1, 0, signals))
            .unwrap()
            .notes()
            .to_vec()
    };
    assert_eq!(
        notes("solver = \"newton\"\niterations = 10"),
        [
            "direct-feedthrough loop through controller, plant is iterated at every macro step \
          (Newton, at most 10 updates; -v names the connections)"
        ]
    );
    assert_eq!(
        notes("scheme = \"gauss_seidel\"\niterations = 50"),
        [
            "direct-feedthrough loop through controller, plant is iterated at every macro step \
          (Gauss–Seidel fixed point, at most 50 repetitions of the step; -v names the \
          connections)"
        ]
    );
}

/// The keys that do not fit together, one line each, naming the key.
#[test]
fn signal_keys_that_do_not_fit_are_refused() {
    for (signals, expected) in [
        (
            "scheme = \"gauss_seidel\"\nsolver = \"newton\"\niterations = 5",
            "[signals] scheme does not apply with solver = \"newton\"",
        ),
        ("iterations = 0", "[signals] iterations = 0"),
        (
            "solver = \"newton\"",
            "[signals] solver needs iterations = N",
        ),
        ("strict = true", "[signals] strict needs iterations = N"),
    ] {
        let spec = system(H, 10, 0, signals);
        let message = match Simulation::new(&spec) {
            Ok(_) => panic!("{signals} runs"),
            Err(e) => e.to_string(),
        };
        assert!(message.contains(expected), "{signals}: {message}");
        assert!(!message.contains('\n'), "{message}");
    }
}

/// The keys survive SSP (the Tether annotation) and give the same rows.
#[test]
fn iterated_signals_run_from_ssp() {
    let spec = system(
        H,
        20,
        0,
        "solver = \"newton\"\niterations = 10\nstrict = true",
    );
    assert_eq!(spec.signals.solver, Some(SignalSolver::Newton));
    let dir = tempfile::tempdir().unwrap();
    let ssp = dir.path().join("loop.ssp");
    tether_ssp::write(&spec, &ssp).unwrap();
    let loaded = tether_ssp::read(&ssp, None, None).unwrap();
    assert_eq!(loaded.spec.signals, spec.signals);
    assert_eq!(run(&loaded.spec), run(&spec));
}

/// A mixed system: the paper's oscillator pair held together by the rigid
/// link (predictor/corrector) under PI position control through signals,
/// the controller an lti that can roll back. Each repetition of an iterated
/// step is the whole predictor/corrector step, `[coupling] iterations`
/// corrections inside it. Converged, Jacobi, Gauss–Seidel and Newton agree
/// within the tolerance, and differ from the non-iterated step.
#[test]
fn a_mixed_system_iterates_the_whole_predictor_corrector_step() {
    let osc = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator");
    let lti = tether_fmu_build::workspace_fmu("lti").expect("package lti");
    let spec = |signals: &str| {
        let text = format!(
            r#"
            [experiment]
            stop = 0.2
            step = 1e-3

            [method]
            kind = "baumgarte"
            beta = 2e-3
            gamma = 1e-6

            [coupling]
            iterations = 2

            [signals]
            tolerance = 1e-12
            {signals}

            [[instance]]
            name = "pi"
            fmu = "{lti}"
            parameters = {{ a = 0.0, b1 = 1.0, b2 = -1.0, c = 10000.0, d1 = 1000.0, d2 = -1000.0, u1 = 0.1 }}

            [[instance]]
            name = "mass1"
            fmu = "{osc}"
            parameters = {{ m = 1.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 0.0 }}

            [[instance]]
            name = "mass2"
            fmu = "{osc}"
            parameters = {{ m = 2.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 0.0 }}

            [[constraint]]
            name = "link"
            position = "mass2.x - mass1.x"
            velocity = "mass2.v - mass1.v"
            acceleration = "mass2.a - mass1.a"
            drives = "mass1.F - mass2.F"

            [[connection]]
            from = "mass1.x"
            to = "pi.u2"

            [[connection]]
            from = "pi.y"
            to = "mass1.F_ext"
            "#,
            lti = lti.display(),
            osc = osc.display(),
        );
        SystemSpec::from_toml(&text).unwrap()
    };
    let x1 = |signals: &str| {
        let mut sim = Simulation::new(&spec(signals)).unwrap();
        let mut rec = MemoryRecorder::default();
        let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
        let x = rec.columns.iter().position(|c| c == "mass1.x").unwrap();
        assert_eq!(stats.max_corrections, 2, "{signals}");
        let rows: Vec<f64> = rec.rows.iter().map(|r| r[x]).collect();
        (rows, stats.signals)
    };
    let (plain, none) = x1("scheme = \"jacobi\"");
    assert!(none.is_none());
    let mut converged = Vec::new();
    for signals in [
        "scheme = \"jacobi\"\niterations = 20",
        "scheme = \"gauss_seidel\"\niterations = 20",
        "solver = \"newton\"\niterations = 5",
    ] {
        let (rows, counts) = x1(signals);
        let counts = counts.unwrap();
        eprintln!("mixed, {}: {counts:?}", signals.replace('\n', ", "));
        assert_eq!(counts.not_converged, 0, "{signals}");
        assert!(counts.max_iterations >= 1, "{signals}");
        converged.push(rows);
    }
    for other in &converged[1..] {
        let d = max_deviation(other, &converged[0][1..]);
        eprintln!("mixed: max difference of mass1.x to Jacobi-iterated {d:.3e}");
        assert!(d < 1e-12, "{d:e}");
    }
    let d = max_deviation(&plain, &converged[0][1..]);
    eprintln!("mixed: not iterated against iterated {d:.3e}");
    assert!(d > 1e-6, "{d:e}");
}
