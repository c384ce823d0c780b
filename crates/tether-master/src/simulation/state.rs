//! The run's state as one value: the master's own state (the unknowns'
//! history, the coupled and recorded outputs, the time grid with its step
//! control, the signal values and texts, the method's Jacobian reuse and error scales,
//! the residuals so far) and, for the whole system, every instance's FMU
//! state. Restoring it and repeating a step gives the same results bit for
//! bit (tests/master_state.rs).

use tether_fmi::remote::protocol::{In, Out};

use super::{grid::Grid, health::Health, Simulation};
use crate::algorithm::predictor_corrector::pass_saved;
use crate::algorithm::step::MethodState;
use crate::state_bytes::{Pass, Passed};
use crate::MasterError;

/// The master's own state at an accepted point ([`Simulation::save_master`]).
pub struct MasterState {
    history: Vec<[f64; 3]>,
    outputs: Vec<Vec<f64>>,
    recorded: Vec<Vec<f64>>,
    /// The recorded String outputs.
    recorded_strings: Vec<Vec<(usize, String)>>,
    grid: Grid,
    health: Health,
    signals: (Vec<[f64; 3]>, Vec<f64>),
    /// The texts of the String links, which their values in `signals` index.
    signal_texts: Vec<Vec<String>>,
    method: MethodState,
}

/// The whole system's state at an accepted point: the master's and every
/// instance's serialized FMU state ([`Simulation::save_state`]).
pub struct SystemState {
    master: MasterState,
    instances: Vec<Vec<u8>>,
}

impl SystemState {
    /// The master's part.
    pub fn master(&self) -> &MasterState {
        &self.master
    }

    /// Each instance's serialized FMU state, in the order of the system file.
    pub fn instances(&self) -> &[Vec<u8>] {
        &self.instances
    }
}

impl Simulation {
    /// The master's own state at the current point (no FMI call).
    pub fn save_master(&self) -> MasterState {
        let system = &self.system;
        MasterState {
            history: system.history.clone(),
            outputs: system.outputs.clone(),
            recorded: system
                .slaves
                .iter()
                .map(|s| s.recorded_values().to_vec())
                .collect(),
            recorded_strings: system
                .slaves
                .iter()
                .map(|s| s.recorded_strings().to_vec())
                .collect(),
            grid: self.grid.clone(),
            health: self.health.clone(),
            signals: self.signals.values(),
            signal_texts: self.signals.texts(),
            method: self.method.save(),
        }
    }

    /// Back to a state of [`save_master`](Self::save_master) of this
    /// simulation (the instances are not touched).
    pub fn restore_master(&mut self, state: &MasterState) {
        let system = &mut self.system;
        system.history.clone_from(&state.history);
        system.outputs.clone_from(&state.outputs);
        for (slave, recorded) in system.slaves.iter_mut().zip(&state.recorded) {
            slave.set_recorded_values(recorded);
        }
        for (slave, strings) in system.slaves.iter_mut().zip(&state.recorded_strings) {
            slave.set_recorded_strings(strings);
        }
        self.grid.clone_from(&state.grid);
        self.health.clone_from(&state.health);
        self.signals.set_values(&state.signals);
        self.signals.set_texts(&state.signal_texts);
        self.method.restore(&state.method);
        self.row.fill(&self.system);
    }

    /// The whole system's state at the current point: every instance's FMU
    /// state (`fmi2GetFMUstate`, `fmi2SerializeFMUstate`) and the master's.
    /// Every instance must declare `canGetAndSetFMUstate` and
    /// `canSerializeFMUstate`.
    pub fn save_state(&mut self) -> Result<SystemState, MasterError> {
        let mut instances = Vec::with_capacity(self.system.slaves.len());
        for slave in &mut self.system.slaves {
            let mut bytes = Vec::new();
            slave.snapshot(&mut bytes)?;
            instances.push(bytes);
        }
        Ok(SystemState {
            master: self.save_master(),
            instances,
        })
    }

    /// Back to a state of [`save_state`](Self::save_state) of this
    /// simulation: every instance's FMU state, then the master's.
    pub fn restore_state(&mut self, state: &SystemState) -> Result<(), MasterError> {
        let slaves = &mut self.system.slaves;
        for ((slave, bytes), recorded) in slaves
            .iter_mut()
            .zip(&state.instances)
            .zip(&state.master.recorded)
        {
            slave.load_snapshot(bytes, recorded)?;
        }
        self.restore_master(&state.master);
        Ok(())
    }
}

impl MasterState {
    /// Its numbers through `p`, in a fixed order.
    fn pass(&mut self, p: &mut Pass) -> Passed {
        p.f64s(self.history.as_flattened_mut(), "the unknowns")?;
        for (what, lists) in [
            ("the coupled outputs", &mut self.outputs),
            ("the recorded outputs", &mut self.recorded),
        ] {
            p.same(lists.len(), what)?;
            lists.iter_mut().try_for_each(|l| p.f64s(l, what))?;
        }
        self.grid.pass(p)?;
        self.health.pass(p)?;
        p.f64s(self.signals.0.as_flattened_mut(), "the signal links")?;
        p.f64s(&mut self.signals.1, "the signal links")?;
        p.same(self.signal_texts.len(), "the signal links")?;
        self.signal_texts.iter_mut().try_for_each(|t| p.texts(t))?;
        p.same(self.recorded_strings.len(), "the number of instances")?;
        for strings in &mut self.recorded_strings {
            p.same(strings.len(), "the recorded String outputs")?;
            strings.iter_mut().try_for_each(|(_, t)| p.text(t))?;
        }
        pass_saved(&mut self.method, p)
    }
}

impl SystemState {
    /// Appends the state to `out` as bytes: every instance's serialized FMU
    /// state, then the master's numbers (little-endian; the sizes of the
    /// system with them). [`Simulation::read_state`] reads them back.
    pub fn write(&mut self, out: &mut Out) -> Result<(), String> {
        let mut p = Pass::Write(out);
        p.same(self.instances.len(), "the number of instances")?;
        self.instances.iter_mut().try_for_each(|b| p.bytes(b))?;
        self.master.pass(&mut p)
    }
}

impl Simulation {
    /// A state of [`SystemState::write`] read from `input`, for this
    /// simulation: a state of a system of other sizes or options, or bytes
    /// that end early, are refused with the reason.
    pub fn read_state(&self, input: &mut In) -> Result<SystemState, String> {
        let mut p = Pass::Read(input);
        let mut instances = vec![Vec::new(); self.system.slaves.len()];
        p.same(instances.len(), "the number of instances")?;
        instances.iter_mut().try_for_each(|b| p.bytes(b))?;
        let mut master = self.save_master();
        master.pass(&mut p)?;
        Ok(SystemState { master, instances })
    }
}
