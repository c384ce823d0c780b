//! Where an instance's FMI calls go: into the FMU loaded in this process, or
//! across a socket to a host process of its own (`isolation = "process"`,
//! docs/reliability.md). The macro step does not see the difference: both
//! offer the calls a [`Slave`](crate::slave::Slave) makes, and both keep the
//! saved FMU states on their side (in the host process, for isolated ones).

use std::time::Duration;

use tether_fmi::remote::RemoteInstance;
use tether_fmi::{Fmu, FmuState, Instance, Result, ValueReference};

/// Which saved state: the macro step's, or the rollback self-check's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Slot {
    /// The state saved at the start of the macro step.
    Saved = 0,
    /// The rollback self-check's own state.
    Check = 1,
}

/// An FMU instance in this process or in a host process.
#[derive(Debug)]
pub(crate) enum Backend {
    /// The FMU's library is loaded in this process.
    InProcess {
        instance: Instance,
        states: [Option<FmuState>; 2],
    },
    /// The FMU runs in a host process of its own.
    Process(RemoteInstance),
}

/// The same call on either backend.
macro_rules! either {
    ($self:ident, $i:ident => $call:expr) => {
        match $self {
            Backend::InProcess { instance: $i, .. } => $call,
            Backend::Process($i) => $call,
        }
    };
}

impl Backend {
    /// Instantiates `fmu` as `name`, in a host process when `isolated` (each
    /// call then waits at most `timeout`).
    pub(crate) fn new(
        fmu: &Fmu,
        name: &str,
        isolated: bool,
        timeout: Option<Duration>,
    ) -> Result<Backend> {
        Ok(if isolated {
            Backend::Process(RemoteInstance::new(fmu, name, Default::default(), timeout)?)
        } else {
            Backend::InProcess {
                instance: fmu.instantiate(name, Default::default())?,
                states: [None, None],
            }
        })
    }

    /// The communication time tracked for messages.
    pub(crate) fn time(&self) -> f64 {
        either!(self, i => i.time())
    }

    /// Whether the FMU returned `fmi2Fatal`.
    pub(crate) fn is_fatal(&self) -> bool {
        either!(self, i => i.is_fatal())
    }

    pub(crate) fn setup_experiment(
        &mut self,
        tolerance: Option<f64>,
        start: f64,
        stop: Option<f64>,
    ) -> Result<()> {
        either!(self, i => i.setup_experiment(tolerance, start, stop))
    }

    pub(crate) fn enter_initialization_mode(&mut self) -> Result<()> {
        either!(self, i => i.enter_initialization_mode())
    }

    pub(crate) fn exit_initialization_mode(&mut self) -> Result<()> {
        either!(self, i => i.exit_initialization_mode())
    }

    pub(crate) fn terminate(&mut self) -> Result<()> {
        either!(self, i => i.terminate())
    }

    pub(crate) fn terminated(&mut self) -> Result<bool> {
        either!(self, i => i.terminated())
    }

    pub(crate) fn last_successful_time(&mut self) -> Result<f64> {
        either!(self, i => i.last_successful_time())
    }

    #[inline]
    pub(crate) fn set_real(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        either!(self, i => i.set_real(vrs, values))
    }

    #[inline]
    pub(crate) fn get_real(&mut self, vrs: &[ValueReference], out: &mut [f64]) -> Result<()> {
        either!(self, i => i.get_real(vrs, out))
    }

    pub(crate) fn get_integer(&mut self, vrs: &[ValueReference], out: &mut [i32]) -> Result<()> {
        either!(self, i => i.get_integer(vrs, out))
    }

    pub(crate) fn get_boolean(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()> {
        either!(self, i => i.get_boolean(vrs, out))
    }

    #[inline]
    pub(crate) fn set_real_input_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        values: &[f64],
    ) -> Result<()> {
        either!(self, i => i.set_real_input_derivatives(vrs, orders, values))
    }

    pub(crate) fn get_real_output_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()> {
        either!(self, i => i.get_real_output_derivatives(vrs, orders, out))
    }

    #[inline]
    pub(crate) fn do_step(&mut self, t: f64, h: f64) -> Result<()> {
        either!(self, i => i.do_step(t, h, true))
    }

    /// `fmi2GetFMUstate` into `slot` (reusing the state there).
    pub(crate) fn save(&mut self, slot: Slot) -> Result<()> {
        match self {
            Backend::InProcess { instance, states } => match &mut states[slot as usize] {
                Some(s) => instance.update_fmu_state(s),
                empty => {
                    *empty = Some(instance.get_fmu_state()?);
                    Ok(())
                }
            },
            Backend::Process(r) => r.save_state(slot as u32),
        }
    }

    /// `fmi2SetFMUstate` from `slot`, which [`save`](Self::save) filled.
    pub(crate) fn restore(&mut self, slot: Slot) -> Result<()> {
        match self {
            Backend::InProcess { instance, states } => {
                let state = states[slot as usize]
                    .as_ref()
                    .expect("a state is restored only after it was saved");
                instance.set_fmu_state(state)
            }
            Backend::Process(r) => r.restore_state(slot as u32),
        }
    }

    /// `fmi2FreeFMUstate` of `slot`.
    pub(crate) fn free(&mut self, slot: Slot) -> Result<()> {
        match self {
            Backend::InProcess { states, .. } => {
                states[slot as usize] = None;
                Ok(())
            }
            Backend::Process(r) => r.free_state(slot as u32),
        }
    }

    /// `fmi2SerializeFMUstate` of `slot` into `out`.
    pub(crate) fn serialize(&mut self, slot: Slot, out: &mut Vec<u8>) -> Result<()> {
        match self {
            Backend::InProcess { instance, states } => {
                let state = states[slot as usize]
                    .as_ref()
                    .expect("a state is serialised only after it was saved");
                instance.serialize_fmu_state_into(state, out)
            }
            Backend::Process(r) => r.serialize_state(slot as u32, out),
        }
    }

    /// `fmi2DeSerializeFMUstate` of `bytes` into `slot`.
    pub(crate) fn deserialize(&mut self, slot: Slot, bytes: &[u8]) -> Result<()> {
        match self {
            Backend::InProcess { instance, states } => {
                // The previous state is freed (fmi2FreeFMUstate) when replaced.
                states[slot as usize] = Some(instance.deserialize_fmu_state(bytes)?);
                Ok(())
            }
            Backend::Process(r) => r.deserialize_state(slot as u32, bytes),
        }
    }
}

impl crate::start::Settable for Backend {
    fn name(&self) -> &str {
        either!(self, i => i.name())
    }
    fn set_real(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        either!(self, i => i.set_real(vrs, values))
    }
    fn set_integer(&mut self, vrs: &[ValueReference], values: &[i32]) -> Result<()> {
        either!(self, i => i.set_integer(vrs, values))
    }
    fn set_boolean(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()> {
        either!(self, i => i.set_boolean(vrs, values))
    }
    fn set_string(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()> {
        either!(self, i => i.set_string(vrs, values))
    }
}
