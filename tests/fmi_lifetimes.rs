//! Lifetimes of the oscillator's `Fmu`, `Instance` and `FmuState` values: each may be
//! dropped before the others, and instances and states move across threads.

use tether_fmi::{Fmu, InstanceOptions};
use tether_tests::fmi::{self, oscillator_fmu};

fn initialized(fmu: &Fmu, name: &str) -> tether_fmi::Instance {
    fmi::initialized(fmu, name, InstanceOptions::default())
}

#[test]
fn an_instance_keeps_stepping_after_its_fmu_value_is_dropped() {
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    let dir = fmu.directory().to_owned();
    let x = fmu.model_description().value_reference("x").expect("x");
    let mut inst = initialized(&fmu, "a");
    drop(fmu);
    assert!(
        dir.join("modelDescription.xml").is_file(),
        "extracted files removed too early"
    );
    let mut y = [0.0];
    for k in 0..100 {
        inst.do_step(k as f64 * 1e-3, 1e-3, true).expect("step");
    }
    inst.get_real(&[x], &mut y).expect("x");
    assert!(y[0].is_finite() && y[0] != 0.0);
    assert_eq!(inst.variable("x").expect("lookup").value_reference, x);
    drop(inst);
    assert!(
        !dir.exists(),
        "the extraction directory outlived its last user"
    );
}

#[test]
fn a_state_outliving_its_instance_is_freed_safely() {
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    let mut inst = initialized(&fmu, "a");
    let states: Vec<_> = (0..3)
        .map(|_| inst.get_fmu_state().expect("state"))
        .collect();
    drop(inst);
    drop(fmu);
    assert_eq!(states[0].instance_name(), "a");
    drop(states);
}

#[test]
fn instances_and_states_move_to_other_threads() {
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    let mut inst = initialized(&fmu, "a");
    let state = inst.get_fmu_state().expect("state");
    let handle = std::thread::spawn(move || {
        inst.do_step(0.0, 1e-3, false)
            .expect("step on another thread");
        inst.set_fmu_state(&state)
            .expect("restore on another thread");
        inst.time()
    });
    assert_eq!(handle.join().expect("thread"), 0.0);
}
