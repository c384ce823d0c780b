//! The whole system's saved state (`Simulation::save_state` /
//! `restore_state`): every instance's FMU state and the master's own state
//! (the unknowns' history, the polynomials' past points, step control,
//! Jacobian reuse, signal values) saved as one value. Restoring it and
//! repeating the steps that followed gives every recorded value and every
//! unknown again bit for bit — also when the state goes through its bytes
//! (`SystemState::write`, `Simulation::read_state`, as the exported FMU's
//! fmi2SerializeFMUstate does) into another simulation of the system.

use tether_fmi::remote::protocol::{In, Out};
use tether_master::{JacobianMode, Simulation, StepControl, SystemSpec};

/// An example file with its FMUs packaged where it points.
fn example(name: &str) -> SystemSpec {
    for fmu in ["oscillator", "link", "controller"] {
        tether_fmu_build::workspace_fmu(fmu).expect("package the FMU");
    }
    let root = tether_fmu_build::workspace_root().expect("workspace root");
    SystemSpec::from_file(&root.join("examples").join(name)).expect("read the example")
}

/// Run `before` steps, save, run `after` steps and keep every row; restore
/// and run the `after` steps again: the rows must be the same bit for bit.
/// Then the same from the saved state's bytes, read by another simulation
/// of `spec` that has taken one step.
fn repeat_after_restore(spec: &SystemSpec, before: usize, after: usize) {
    let mut sim = Simulation::new(spec).expect("simulation");
    for _ in 0..before {
        sim.step().expect("step");
    }
    let mut saved = sim.save_state().expect("save");
    let mut bytes = Out::default();
    saved.write(&mut bytes).expect("write the state");
    let time = sim.time();
    let mut first = Vec::new();
    for _ in 0..after {
        sim.step().expect("step");
        first.push((sim.time(), sim.values().to_vec(), sim.unknowns()));
    }
    sim.restore_state(&saved).expect("restore");
    repeat(&mut sim, time, &first);
    let mut other = Simulation::new(spec).expect("simulation");
    other.step().expect("step");
    let mut input = In::new(&bytes.0);
    let read = other.read_state(&mut input).expect("read the state");
    assert!(input.is_empty(), "every byte read");
    other.restore_state(&read).expect("restore from bytes");
    repeat(&mut other, time, &first);
    // Bytes cut short are refused.
    let cut = &bytes.0[..bytes.0.len() - 3];
    let error = other.read_state(&mut In::new(cut)).err().expect("cut");
    assert!(error.contains("end early"), "{error}");
}

/// Step `sim` from `time` and require the rows of `first` bit for bit.
fn repeat(sim: &mut Simulation, time: f64, first: &[(f64, Vec<f64>, Vec<f64>)]) {
    assert_eq!(sim.time().to_bits(), time.to_bits(), "time after restore");
    for (i, (t, values, unknowns)) in first.iter().enumerate() {
        sim.step().expect("step");
        assert_eq!(
            sim.time().to_bits(),
            t.to_bits(),
            "time of repeated step {i}"
        );
        let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits());
        assert!(
            same(sim.values(), values),
            "values of repeated step {i} at t = {t}"
        );
        assert!(
            same(&sim.unknowns(), unknowns),
            "unknowns of repeated step {i} at t = {t}"
        );
    }
}

#[test]
fn a_restored_state_repeats_the_oscillator_bit_for_bit() {
    repeat_after_restore(&example("oscillator.toml"), 20, 30);
}

/// Model-exchange instances (the kit's builds): the saved state holds each
/// instance's time, continuous states and the FMU's serialized state; the
/// double pendulum at k = 2 on them repeats bit for bit, also through bytes.
#[test]
fn a_restored_state_repeats_model_exchange_instances_bit_for_bit() {
    let mut spec = example("double_pendulum.toml");
    spec.coupling.order = 2;
    for i in &mut spec.instances {
        i.fmi_type = tether_master::InterfaceChoice::ModelExchange;
    }
    repeat_after_restore(&spec, 10, 20);
}

#[test]
fn a_restored_state_repeats_the_polynomials_past_points_bit_for_bit() {
    // k = 2: the polynomials run through the two past points.
    let mut spec = example("double_pendulum.toml");
    spec.coupling.order = 2;
    repeat_after_restore(&spec, 10, 20);
}

#[test]
fn a_restored_state_repeats_adaptive_steps_bit_for_bit() {
    let mut spec = example("double_pendulum.toml");
    spec.step_control = Some(StepControl {
        rtol: 1e-4,
        atol: 1e-4,
        h_min: None,
        h_max: None,
        h_initial: None,
    });
    repeat_after_restore(&spec, 15, 25);
}

#[test]
fn a_restored_state_repeats_jacobian_reuse_bit_for_bit() {
    let mut spec = example("double_pendulum.toml");
    spec.coupling.jacobian = JacobianMode::Reuse;
    repeat_after_restore(&spec, 12, 25);
}

#[test]
fn a_restored_state_repeats_signals_bit_for_bit() {
    // The controlled oscillator with a third oscillator in place of the
    // controller (which has no FMU state): mass1.x drives mass3's force
    // through a signal with k = 1, whose past sender values are master state.
    let mut spec = example("controlled_oscillator.toml");
    let oscillator = spec.instances[1].fmu.clone();
    spec.instances[0].fmu = oscillator;
    spec.instances[0].parameters.clear();
    spec.connections[0].to = "ctrl.F_ext".into();
    spec.connections[1].from = "ctrl.x".into();
    // A gain (a conversion from m to N) instead of the controller's law.
    spec.connections[0].gain = Some(500.0);
    spec.connections[1].gain = Some(-800.0);
    repeat_after_restore(&spec, 10, 20);
}

#[test]
fn an_instance_without_fmu_state_is_named_when_the_state_is_saved() {
    let spec = example("controlled_oscillator.toml");
    let mut sim = Simulation::new(&spec).expect("simulation");
    let error = sim
        .save_state()
        .err()
        .expect("the controller has no FMU state");
    let message = error.to_string();
    assert!(message.contains("'ctrl'"), "{message}");
    assert!(message.contains("canGetAndSetFMUstate"), "{message}");
}

#[test]
fn the_state_of_another_system_is_refused_with_the_reason() {
    let mut pendulum = Simulation::new(&example("double_pendulum.toml")).expect("simulation");
    let mut bytes = Out::default();
    let mut saved = pendulum.save_state().expect("save");
    saved.write(&mut bytes).expect("write the state");
    let oscillator = Simulation::new(&example("oscillator.toml")).expect("simulation");
    let error = oscillator
        .read_state(&mut In::new(&bytes.0))
        .err()
        .expect("a state of another system");
    assert!(error.contains("in this system"), "{error}");
}

/// String connections and String outputs in the state: the texts a String
/// link has carried travel with the bytes, so another simulation of the
/// system, which has seen only the first text, repeats the texts after a
/// second one was set between steps (the Reference FMU Feedthrough passes
/// its String input through).
#[test]
fn a_restored_state_repeats_string_signals() {
    let Some(ft) = tether_fmu_build::fixture_fmu("reference-fmus/fmi2/Feedthrough.fmu") else {
        return;
    };
    let text = format!(
        "[experiment]\nstop = 0.1\nstep = 0.01\n\n\
         [[instance]]\nname = \"src\"\nfmu = {ft:?}\nparameters = {{ String_input = \"first\" }}\n\n\
         [[instance]]\nname = \"dst\"\nfmu = {ft:?}\n\n\
         [[connection]]\nfrom = \"src.String_output\"\nto = \"dst.String_input\"\n"
    );
    let spec = SystemSpec::from_toml(&text).expect("system");
    let mut sim = Simulation::new(&spec).expect("simulation");
    sim.step().expect("step");
    let second = tether_master::StartValue::String("second, \"2\"".into());
    sim.set_parameter("src.String_input", &second).expect("set");
    sim.step().expect("step");
    sim.step().expect("step");
    let mut saved = sim.save_state().expect("save");
    let mut bytes = Out::default();
    saved.write(&mut bytes).expect("write the state");
    let mut first = Vec::new();
    for _ in 0..3 {
        sim.step().expect("step");
        first.push(sim.strings().to_vec());
    }
    let texts: Vec<&str> = first[0].iter().map(|(_, t)| t.as_str()).collect();
    assert_eq!(texts, ["second, \"2\"", "second, \"2\""]);
    let mut other = Simulation::new(&spec).expect("simulation");
    other.step().expect("step");
    let mut input = In::new(&bytes.0);
    let read = other.read_state(&mut input).expect("read the state");
    assert!(input.is_empty(), "every byte read");
    other.restore_state(&read).expect("restore from bytes");
    let texts: Vec<&str> = other.strings().iter().map(|(_, t)| t.as_str()).collect();
    assert_eq!(texts, ["second, \"2\"", "second, \"2\""]);
    for row in &first {
        other.step().expect("step");
        assert_eq!(other.strings(), row.as_slice());
    }
}

/// A String link whose text changes every step keeps only the texts it still
/// holds: over 400 steps of distinct texts, the receiver gets each one and the
/// saved state (which carries the link's table) stays the size it has after 70
/// steps, when the table is first rebuilt.
#[test]
fn a_text_that_changes_every_step_keeps_the_state_small() {
    let Some(ft) = tether_fmu_build::fixture_fmu("reference-fmus/fmi2/Feedthrough.fmu") else {
        return;
    };
    let text = format!(
        "[experiment]\nstop = 10.0\nstep = 0.01\n\n\
         [[instance]]\nname = \"src\"\nfmu = {ft:?}\n\n\
         [[instance]]\nname = \"dst\"\nfmu = {ft:?}\n\n\
         [[connection]]\nfrom = \"src.String_output\"\nto = \"dst.String_input\"\n"
    );
    let spec = SystemSpec::from_toml(&text).expect("system");
    let mut sim = Simulation::new(&spec).expect("simulation");
    let state_bytes = |sim: &mut Simulation| {
        let mut bytes = Out::default();
        sim.save_state()
            .expect("save")
            .write(&mut bytes)
            .expect("write the state");
        bytes.0.len()
    };
    let mut sizes = Vec::new();
    for n in 0..400 {
        let label = tether_master::StartValue::String(format!("label {n:04}, \"step\""));
        sim.set_parameter("src.String_input", &label).expect("set");
        sim.step().expect("step");
        sim.step().expect("step");
        // src's output at T_N is what dst took over the step just made
        // (held): dst reads back the text set before the step before.
        let texts: Vec<&str> = sim.strings().iter().map(|(_, t)| t.as_str()).collect();
        let want = format!("label {n:04}, \"step\"");
        assert_eq!(texts, [want.as_str(), want.as_str()], "step pair {n}");
        if n == 70 || n == 399 {
            sizes.push(state_bytes(&mut sim));
        }
    }
    eprintln!(
        "saved state: {} bytes after 70 step pairs, {} after 400",
        sizes[0], sizes[1]
    );
    assert!(
        sizes[1] <= sizes[0] + 2 * 64 * 20,
        "the saved state grew from {} to {} bytes",
        sizes[0],
        sizes[1]
    );
}
