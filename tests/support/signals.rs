//! The paper's two-mass oscillator under PI position control through signal
//! connections, and its monolithic reference, for the tests that run it
//! (tests/master_signals.rs, tests/adaptive_steps.rs).

use nalgebra::{Matrix4, Vector4};
use tether_master::{MemoryRecorder, Simulation, SystemSpec};

pub const M1: f64 = 1.0;
pub const M2: f64 = 2.0;
pub const C: f64 = 1000.0;
pub const D: f64 = 10.0;
pub const KP: f64 = 1000.0;
pub const KI: f64 = 10000.0;
pub const R: f64 = 0.1;

/// The monolithic reference: x(t) of the controlled pair from rest at 0.
pub fn reference(t: f64) -> f64 {
    let (m, c, d) = (M1 + M2, 2.0 * C, 2.0 * D);
    // s = (x, v, z, 1): ṡ = A s.
    #[rustfmt::skip]
    let a = Matrix4::new(
        0.0,              1.0,    0.0,    0.0,
        -(c + KP) / m,    -d / m, KI / m, KP * R / m,
        -1.0,             0.0,    0.0,    R,
        0.0,              0.0,    0.0,    0.0,
    );
    ((a * t).exp() * Vector4::new(0.0, 0.0, 0.0, 1.0))[0]
}

pub fn system(h: f64, order: usize, scheme: &str, extra: &str) -> SystemSpec {
    let osc = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator");
    let ctrl = tether_fmu_build::workspace_fmu("controller").expect("package the controller");
    let text = format!(
        r#"
        [experiment]
        stop = 1.0
        step = {h}

        [method]
        kind = "baumgarte"
        beta = 2e-3
        gamma = 1e-6

        [coupling]
        order = {order}

        [signals]
        scheme = "{scheme}"

        [[instance]]
        name = "ctrl"
        fmu = "{ctrl}"
        parameters = {{ kp = {KP}, ki = {KI}, r = {R} }}

        [[instance]]
        name = "mass1"
        fmu = "{osc}"
        parameters = {{ m = {M1}, c = {C}, d = {D}, x0 = 0.0, v0 = 0.0, exact = true }}

        [[instance]]
        name = "mass2"
        fmu = "{osc}"
        parameters = {{ m = {M2}, c = {C}, d = {D}, x0 = 0.0, v0 = 0.0, exact = true }}

        [[constraint]]
        name = "link"
        position = "mass2.x - mass1.x"
        velocity = "mass2.v - mass1.v"
        acceleration = "mass2.a - mass1.a"
        drives = "mass1.F - mass2.F"

        [[connection]]
        from = "mass1.x"
        to = "ctrl.y"

        [[connection]]
        from = "ctrl.u"
        to = "mass1.F_ext"
        {extra}
        "#,
        osc = osc.display(),
        ctrl = ctrl.display(),
    );
    SystemSpec::from_toml(&text).unwrap()
}

/// Largest |x1 − x_ref| over the run, and the run's statistics.
pub fn run(spec: &SystemSpec) -> (f64, tether_master::RunStats) {
    let mut sim = Simulation::new(spec).unwrap();
    let mut rec = MemoryRecorder::default();
    let stats = sim.run(&mut [&mut rec], &mut |_, _| {}).unwrap();
    let x = rec.columns.iter().position(|c| c == "mass1.x").unwrap();
    let err = rec
        .times
        .iter()
        .zip(&rec.rows)
        .map(|(t, row)| (row[x] - reference(*t)).abs())
        .fold(0.0, f64::max);
    (err, stats)
}

/// The one-line error of a system refused at setup.
pub fn setup_error(spec: &SystemSpec) -> String {
    match Simulation::new(spec) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("the system was accepted"),
    }
}
