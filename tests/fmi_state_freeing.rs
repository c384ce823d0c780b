//! When `fmi2FreeFMUstate` and `fmi2FreeInstance` run for the oscillator's states,
//! observed through tether-fmi's trace record of every FMI call.
//!
//! An instance takes no lock for its calls, so a state dropped while the instance
//! lives is freed by the instance before its next call; a state that outlives its
//! instance frees itself, and the last one frees the instance.

use std::sync::Mutex;

use tether_fmi::{Fmu, Instance, InstanceOptions};
use tether_tests::fmi::{self, oscillator_fmu};

/// The messages of target `tether_fmi::call`, in order.
struct Calls(Mutex<Vec<String>>);

impl log::Log for Calls {
    fn enabled(&self, metadata: &log::Metadata<'_>) -> bool {
        metadata.target() == "tether_fmi::call"
    }
    fn log(&self, record: &log::Record<'_>) {
        if self.enabled(record.metadata()) {
            self.0
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(record.args().to_string());
        }
    }
    fn flush(&self) {}
}

static CALLS: Calls = Calls(Mutex::new(Vec::new()));

/// The calls on instance `name` so far, as "function" names in order.
fn calls_on(name: &str) -> Vec<String> {
    let _ = log::set_logger(&CALLS);
    log::set_max_level(log::LevelFilter::Trace);
    let tag = format!("({name})");
    CALLS
        .0
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .filter(|m| m.contains(&tag))
        .map(|m| m[..m.find('(').unwrap_or(m.len())].to_owned())
        .collect()
}

fn count(calls: &[String], function: &str) -> usize {
    calls.iter().filter(|c| *c == function).count()
}

fn initialized(fmu: &Fmu, name: &str) -> Instance {
    calls_on(name); // installs the logger
    fmi::initialized(fmu, name, InstanceOptions::default())
}

#[test]
fn a_state_dropped_while_its_instance_lives_is_freed_before_the_next_call() {
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    let name = "freed-before-next-call";
    let mut inst = initialized(&fmu, name);
    let states: Vec<_> = (0..3)
        .map(|_| inst.get_fmu_state().expect("state"))
        .collect();
    drop(states);
    assert_eq!(
        count(&calls_on(name), "fmi2FreeFMUstate"),
        0,
        "freed only by the instance"
    );
    inst.do_step(0.0, 1e-3, true).expect("step");
    let calls = calls_on(name);
    assert_eq!(count(&calls, "fmi2FreeFMUstate"), 3, "{calls:?}");
    let step = calls.iter().rposition(|c| c == "fmi2DoStep").expect("step");
    let last_free = calls
        .iter()
        .rposition(|c| c == "fmi2FreeFMUstate")
        .expect("free");
    assert!(last_free < step, "freed before the step: {calls:?}");
    // Nothing is freed twice.
    inst.do_step(1e-3, 1e-3, true).expect("step");
    drop(inst);
    let calls = calls_on(name);
    assert_eq!(count(&calls, "fmi2FreeFMUstate"), 3, "{calls:?}");
    assert_eq!(calls.last().map(String::as_str), Some("fmi2FreeInstance"));
}

#[test]
fn states_dropped_on_another_thread_are_freed_once_each() {
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    let name = "dropped-on-another-thread";
    let mut inst = initialized(&fmu, name);
    let states: Vec<_> = (0..50)
        .map(|_| inst.get_fmu_state().expect("state"))
        .collect();
    let dropper = std::thread::spawn(move || {
        for state in states {
            drop(state);
            std::thread::yield_now();
        }
    });
    let mut t = 0.0;
    while !dropper.is_finished() {
        inst.do_step(t, 1e-4, true).expect("step while states drop");
        t += 1e-4;
    }
    dropper.join().expect("dropper");
    inst.do_step(t, 1e-4, true).expect("step");
    assert_eq!(count(&calls_on(name), "fmi2FreeFMUstate"), 50);
}

#[test]
fn the_last_state_of_a_dropped_instance_frees_it() {
    let fmu = Fmu::open(oscillator_fmu()).expect("open");
    let name = "outlived-by-states";
    let mut inst = initialized(&fmu, name);
    let early = inst.get_fmu_state().expect("state");
    let mut late: Vec<_> = (0..2)
        .map(|_| inst.get_fmu_state().expect("state"))
        .collect();
    drop(early);
    drop(inst);
    let calls = calls_on(name);
    assert_eq!(
        count(&calls, "fmi2FreeFMUstate"),
        1,
        "the instance frees what was dropped before it: {calls:?}"
    );
    assert_eq!(count(&calls, "fmi2FreeInstance"), 0, "states remain");
    late.pop();
    assert_eq!(count(&calls_on(name), "fmi2FreeFMUstate"), 2);
    assert_eq!(count(&calls_on(name), "fmi2FreeInstance"), 0);
    drop(late);
    let calls = calls_on(name);
    assert_eq!(count(&calls, "fmi2FreeFMUstate"), 3, "{calls:?}");
    assert_eq!(calls.last().map(String::as_str), Some("fmi2FreeInstance"));
}
