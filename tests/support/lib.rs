//! Shared helpers for the integration tests in tests/.

pub mod control_loop;
pub mod faulty;
pub mod fmi;
pub mod fmpy;
pub mod multibody;
pub mod oscillator;
pub mod planar;
pub mod reference;
pub mod signals;
pub mod tools;

/// The current value of one result column of `sim` (panics on an unknown name).
pub fn column_value(sim: &tether_master::Simulation, name: &str) -> f64 {
    let i = sim
        .columns()
        .iter()
        .position(|c| c == name)
        .unwrap_or_else(|| panic!("no column {name}"));
    sim.values()[i]
}
