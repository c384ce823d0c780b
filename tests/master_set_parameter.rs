//! Setting an input between macro steps (`Simulation::set_parameter`) against
//! the closed form, and the refusals FMI 2.0 asks for.
//!
//! Two oscillators coupled by the paper's link, and a third one on its own
//! whose force input F no constraint drives: a step in F at t1 must give the
//! closed-form response of a damped oscillator under a constant force.

use tether_master::{MasterError, Simulation, StartValue, SystemSpec};

const M3: f64 = 1.5;
const C3: f64 = 800.0;
const D3: f64 = 4.0;

fn system() -> SystemSpec {
    let fmu = tether_fmu_build::workspace_fmu("oscillator").expect("package the oscillator FMU");
    let text = format!(
        r#"
        [experiment]
        stop = 0.5
        step = 1e-3
        [method]
        kind = "baumgarte"
        beta = 2e-3
        [[instance]]
        name = "mass1"
        fmu = "{fmu}"
        parameters = {{ m = 1.0, exact = true }}
        [[instance]]
        name = "mass2"
        fmu = "{fmu}"
        parameters = {{ m = 2.0, exact = true }}
        [[instance]]
        name = "mass3"
        fmu = "{fmu}"
        parameters = {{ m = {M3}, c = {C3}, d = {D3}, v0 = 1.0, exact = true }}
        [[constraint]]
        name = "link"
        position = "mass2.x - mass1.x"
        velocity = "mass2.v - mass1.v"
        acceleration = "mass2.a - mass1.a"
        drives = "mass1.F - mass2.F"
        "#,
        fmu = fmu.display()
    );
    SystemSpec::from_toml(&text).unwrap()
}

/// x(τ) of m ẍ + d ẋ + c x = f from x(0) = x0, ẋ(0) = v0 (underdamped).
fn forced(f: f64, x0: f64, v0: f64, tau: f64) -> f64 {
    let delta = D3 / (2.0 * M3);
    let wd = (C3 / M3 - delta * delta).sqrt();
    let (a, xs) = (x0 - f / C3, f / C3);
    let b = (v0 + delta * a) / wd;
    xs + (-delta * tau).exp() * (a * (wd * tau).cos() + b * (wd * tau).sin())
}

/// A force step F = 40 at t = 0.2 on mass 3 of `spec`, run to 0.5: the
/// simulation and the largest |x − closed form| after the step.
fn force_step(spec: &SystemSpec) -> (Simulation, f64) {
    let mut sim = Simulation::new(spec).unwrap();
    while sim.time() < 0.2 - 1e-12 {
        sim.step().unwrap();
    }
    let (t1, x1, v1) = (
        sim.time(),
        sim.value("mass3.x").unwrap(),
        sim.value("mass3.v").unwrap(),
    );
    sim.set_parameter("mass3.F", &StartValue::Real(FORCE))
        .unwrap();
    let mut worst: f64 = 0.0;
    while sim.time() < 0.5 - 1e-12 {
        sim.step().unwrap();
        let x = sim.value("mass3.x").unwrap();
        worst = worst.max((x - forced(FORCE, x1, v1, sim.time() - t1)).abs());
    }
    (sim, worst)
}

/// The force of [`force_step`].
const FORCE: f64 = 40.0;

#[test]
fn a_force_step_between_steps_follows_the_closed_form() {
    let (sim, worst) = force_step(&system());
    // The response moves the mass by ~f/c = 0.05; the FMU integrates exactly.
    assert!(worst < 1e-12, "max |x - closed form| = {worst:e}");
    let a = sim.value("mass3.a").unwrap();
    let (x, v) = (sim.value("mass3.x").unwrap(), sim.value("mass3.v").unwrap());
    assert!((a - (FORCE - C3 * x - D3 * v) / M3).abs() < 1e-9, "a = {a}");
}

#[test]
fn setting_before_the_first_step_equals_the_start_value() {
    let mut spec = system();
    spec.instances[2]
        .parameters
        .insert("F".into(), StartValue::Real(-7.5));
    let mut given = Simulation::new(&spec).unwrap();
    let mut set = Simulation::new(&system()).unwrap();
    set.set_parameter("mass3.F", &StartValue::Real(-7.5))
        .unwrap();
    for _ in 0..100 {
        given.step().unwrap();
        set.step().unwrap();
        // At T_0 the recorded a differs (read before the set); from the
        // first step on every value agrees, bit for bit.
        assert_eq!(given.values(), set.values(), "t = {}", set.time());
    }
}

#[test]
fn fixed_parameters_coupled_inputs_and_outputs_are_refused() {
    let mut sim = Simulation::new(&system()).unwrap();
    let refuse = |sim: &mut Simulation, target: &str, value: StartValue| -> String {
        let e = sim.set_parameter(target, &value).unwrap_err();
        assert!(
            matches!(
                e,
                MasterError::StartValue { .. }
                    | MasterError::UnknownInstance { .. }
                    | MasterError::UnknownVariable(_)
            ),
            "{e:?}"
        );
        e.to_string()
    };
    let e = refuse(&mut sim, "mass1.m", StartValue::Real(2.0));
    assert!(
        e.contains("mass1") && e.contains("fixed") && e.contains("start value"),
        "{e}"
    );
    let e = refuse(&mut sim, "mass1.F", StartValue::Real(1.0));
    assert!(e.contains("coupling drives"), "{e}");
    let e = refuse(&mut sim, "mass3.x", StartValue::Real(1.0));
    assert!(e.contains("Real output"), "{e}");
    let e = refuse(&mut sim, "mass3.F", StartValue::Boolean(true));
    assert!(e.contains("Real input"), "{e}");
    let e = refuse(&mut sim, "mass3.F", StartValue::Real(f64::NAN));
    assert!(e.contains("finite"), "{e}");
    let e = refuse(&mut sim, "mass4.F", StartValue::Real(1.0));
    assert!(e.contains("mass4") && e.contains("mass3"), "{e}");
    let e = refuse(&mut sim, "mass3.G", StartValue::Real(1.0));
    assert_eq!(
        e,
        "set_parameter: instance 'mass3' (model 'oscillator') has no variable 'G'; did you mean 'F', 'a', 'c'?"
    );
    let e = refuse(&mut sim, "massF", StartValue::Real(1.0));
    assert!(e.contains("INSTANCE.VARIABLE"), "{e}");
    // Nothing was set: the run goes on as before.
    sim.step().unwrap();
    assert_eq!(sim.value("mass3.F"), None);
}

/// The progress callback is optional: `run_to_end` gives the same results
/// as `run` with a callback, which sees every step once, in order.
#[test]
fn progress_is_optional_and_sees_every_step() {
    use tether_master::MemoryRecorder;
    let mut calls = Vec::new();
    let mut with = MemoryRecorder::default();
    let mut sim = Simulation::new(&system()).unwrap();
    sim.run(&mut [&mut with], &mut |done, total| {
        calls.push((done, total))
    })
    .unwrap();
    let mut without = MemoryRecorder::default();
    Simulation::new(&system())
        .unwrap()
        .run_to_end(&mut [&mut without])
        .unwrap();
    assert_eq!(calls.len(), 500);
    assert!(calls
        .iter()
        .enumerate()
        .all(|(i, &c)| c == (i as u64 + 1, 500)));
    assert_eq!(with.times, without.times);
    assert_eq!(with.rows, without.rows);
}

/// The same force step on model-exchange instances (rk45, rtol 1e-12): the
/// new input holds from the next step on and the response follows the closed
/// form to the integrator's tolerance.
#[test]
fn a_force_step_on_model_exchange_instances_follows_the_closed_form() {
    let mut spec = system();
    for i in &mut spec.instances {
        i.fmi_type = tether_master::InterfaceChoice::ModelExchange;
        i.integrator = Some(tether_master::IntegratorSpec {
            method: Some("rk45".into()),
            rtol: Some(1e-12),
            ..Default::default()
        });
    }
    let (_, worst) = force_step(&spec);
    eprintln!("model exchange: max |x - closed form| = {worst:e}");
    assert!(worst < 1e-9, "max |x - closed form| = {worst:e}");
}
