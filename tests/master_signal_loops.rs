//! Signal connections through a direct-feedthrough loop (docs/algorithm.md,
//! "Signal connections"): a decaying source disturbs a first-order plant
//! whose output passes part of its input straight through (fmus/lti), and a
//! PI controller (fmus/controller, command depending directly on its
//! measurement) closes the loop controller.u → plant.u1, plant.y →
//! controller.y. The reference is the monolithic system with the loop
//! solved exactly, integrated exactly (matrix exponential):
//!
//! w' = a_s w,  z' = r − Y,  x' = a x + b1 U + b2 w,
//! U = kp (r − Y) + ki z,  Y = c x + d1 U + d2 w
//!   ⇒ Y = (c x + d1 kp r + d1 ki z + d2 w) / (1 + d1 kp).

use tether_master::{MemoryRecorder, Simulation, SystemSpec};
use tether_tests::control_loop::*;

fn system(h: f64, stop: f64, kp: f64, scheme: &str) -> SystemSpec {
    let lti = tether_fmu_build::workspace_fmu("lti").expect("package lti");
    let ctrl = tether_fmu_build::workspace_fmu("controller").expect("package the controller");
    let text = format!(
        r#"
        [experiment]
        stop = {stop}
        step = {h}

        [signals]
        scheme = "{scheme}"
        tolerance = 1e-13

        [[instance]]
        name = "source"
        fmu = "{lti}"
        parameters = {{ a = {A_S}, b1 = 0.0, c = 1.0, x0 = 1.0 }}

        [[instance]]
        name = "controller"
        fmu = "{ctrl}"
        parameters = {{ kp = {kp}, ki = {KI}, r = {R} }}

        [[instance]]
        name = "plant"
        fmu = "{lti}"
        parameters = {{ a = {A}, b1 = {B1}, b2 = {B2}, c = {C}, d1 = {D1}, d2 = {D2}, x0 = 0.0 }}

        [[connection]]
        from = "source.y"
        to = "plant.u2"

        [[connection]]
        from = "controller.u"
        to = "plant.u1"

        [[connection]]
        from = "plant.y"
        to = "controller.y"
        "#,
        lti = lti.display(),
        ctrl = ctrl.display(),
    );
    SystemSpec::from_toml(&text).unwrap()
}

/// The run's rows of `plant.y`, with their times.
fn plant_y(spec: &SystemSpec) -> Vec<(f64, f64)> {
    let mut sim = Simulation::new(spec).unwrap();
    let mut rec = MemoryRecorder::default();
    sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
    let y = rec.columns.iter().position(|c| c == "plant.y").unwrap();
    rec.times
        .iter()
        .zip(&rec.rows)
        .map(|(&t, row)| (t, row[y]))
        .collect()
}

fn max_error(spec: &SystemSpec, kp: f64) -> f64 {
    plant_y(spec)
        .iter()
        .map(|&(t, y)| (y - monolithic(kp, t)).abs())
        .fold(0.0, f64::max)
}

/// The loop runs under both non-iterated schemes, closed at the macro
/// points: the error against the monolithic loop is first order in H
/// (ratio 2 when H halves). The loop's values at T_0 are consistent, so the
/// start adds no error that does not shrink with H.
#[test]
fn a_feedthrough_loop_converges_at_first_order_under_both_schemes() {
    for scheme in ["jacobi", "gauss_seidel"] {
        let coarse = max_error(&system(2e-3, 2.0, 1.0, scheme), 1.0);
        let fine = max_error(&system(1e-3, 2.0, 1.0, scheme), 1.0);
        let ratio = coarse / fine;
        eprintln!("{scheme}: max |Y − Y_ref| {coarse:.3e} (H = 2 ms), {fine:.3e} (H = 1 ms), ratio {ratio:.3}");
        assert!(fine < 5e-3, "{scheme}: {fine:e}");
        assert!((ratio - 2.0).abs() < 0.1, "{scheme}: ratio {ratio}");
    }
}

/// At T_0 the loop is solved in initialization mode: the first row is the
/// monolithic loop's consistent value, with a loop gain of 0.5 (fixed-point
/// sweeps converge) and of 2 (they diverge; Newton solves it).
#[test]
fn the_loop_starts_from_consistent_values() {
    for kp in [1.0, 4.0] {
        let rows = plant_y(&system(1e-3, 1e-3, kp, "jacobi"));
        let (t, y) = rows[0];
        assert_eq!(t, 0.0);
        let exact = monolithic(kp, 0.0);
        eprintln!("kp {kp}: Y(0) = {y:.17} against {exact:.17}");
        assert!(
            (y - exact).abs() <= 1e-12 * exact.abs(),
            "kp {kp}: {y} vs {exact}"
        );
    }
}

/// d1·kp = −1: Y = c x + d1 kp (r − Y) + … has no solution. One line
/// naming the loop, before the first step.
#[test]
fn a_loop_without_consistent_values_at_t0_is_one_clear_error() {
    let spec = system(1e-3, 0.1, -2.0, "jacobi");
    let message = match Simulation::new(&spec) {
        Ok(_) => panic!("the loop has no solution at T_0"),
        Err(e) => e.to_string(),
    };
    assert!(
        message.starts_with(
            "connection controller.u → plant.u1: direct-feedthrough loop controller.u → \
             plant.u1, then plant.y → controller.y has no consistent values at T_0"
        ),
        "{message}"
    );
    assert!(!message.contains('\n'), "{message}");
}

/// The setup names the loop once, as a note; the source's connection is
/// not part of it.
#[test]
fn the_setup_notes_which_loops_close_at_macro_points() {
    let sim = Simulation::new(&system(1e-3, 0.1, 1.0, "gauss_seidel")).unwrap();
    assert_eq!(
        sim.notes(),
        [
            "direct-feedthrough loop through controller, plant is closed only at macro points: \
          Gauss–Seidel steps its instances in file order and 1 of its 2 connections (those \
          into an instance stepped before its sender) pass the value at T_N (-v names the \
          connections)"
        ]
    );
}

/// examples/control_loop.toml runs as written and matches the monolithic
/// loop to first order.
#[test]
fn the_control_loop_example_runs() {
    for fmu in ["lti", "controller"] {
        tether_fmu_build::workspace_fmu(fmu).expect("package the FMU");
    }
    let root = tether_fmu_build::workspace_root().expect("workspace root");
    let spec = SystemSpec::from_file(&root.join("examples/control_loop.toml")).unwrap();
    let err = max_error(&spec, 1.0);
    eprintln!("examples/control_loop.toml: max |Y − Y_ref| = {err:.3e}");
    assert!(err < 2e-3, "{err:e}");
}

/// A tolerance that is not a positive number is refused by name.
#[test]
fn a_bad_signal_tolerance_is_refused() {
    let mut spec = system(1e-3, 0.1, 1.0, "jacobi");
    spec.signals.tolerance = Some(-1.0);
    let message = match Simulation::new(&spec) {
        Ok(_) => panic!("a negative tolerance"),
        Err(e) => e.to_string(),
    };
    assert!(message.contains("[signals] tolerance"), "{message}");
}

/// The loop exported as SSP and read back runs to the same results, bit
/// for bit (`tether run system.ssp` takes this path).
#[test]
fn the_loop_runs_from_ssp() {
    let spec = system(1e-3, 0.2, 1.0, "gauss_seidel");
    let dir = tempfile::tempdir().unwrap();
    let ssp = dir.path().join("loop.ssp");
    tether_ssp::write(&spec, &ssp).unwrap();
    let loaded = tether_ssp::read(&ssp, None, None).unwrap();
    assert_eq!(loaded.spec.signals, spec.signals);
    assert_eq!(plant_y(&loaded.spec), plant_y(&spec));
}
