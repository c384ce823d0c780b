//! [`FmuState`]: owned FMU states (`fmi2GetFMUstate` & co), freed on drop.

use std::sync::Arc;

use crate::error::{Error, Result};
use crate::instance::{lock, Core, Instance};
use crate::raw::component::RawState;

/// A saved FMU state, tied to the instance that created it.
///
/// The state holds the instance's core alive, so it may outlive the [`Instance`]
/// value; `fmi2FreeFMUstate` runs on drop, `fmi2FreeInstance` after the last state and
/// the instance are gone. Using it with another instance is an
/// [`Error::ForeignState`], never undefined behaviour.
#[derive(Debug)]
pub struct FmuState {
    core: Core,
    raw: RawState,
    time: Option<f64>,
}

impl FmuState {
    /// The name of the instance this state belongs to.
    pub fn instance_name(&self) -> &str {
        self.raw.owner_name()
    }

    /// The communication time at which the state was taken (`None` for a deserialized
    /// state: the bytes carry no time Tether can read).
    pub fn time(&self) -> Option<f64> {
        self.time
    }
}

impl Drop for FmuState {
    fn drop(&mut self) {
        let mut component = lock(&self.core);
        if component.is_fatal() {
            return;
        }
        if let Err(e) = component.fmi2FreeFMUstate(&mut self.raw) {
            log::warn!(target: "tether_fmi::call", "{e}");
        }
    }
}

impl Instance {
    fn owns(&self, function: &'static str, state: &FmuState) -> Result<()> {
        if Arc::ptr_eq(&self.core, &state.core) {
            Ok(())
        } else {
            Err(Error::ForeignState {
                function,
                instance: self.name().to_owned(),
                owner: state.instance_name().to_owned(),
            })
        }
    }

    fn require_get_set(&self, operation: &'static str) -> Result<()> {
        self.require(
            self.fmu
                .model_description
                .co_simulation
                .can_get_and_set_fmu_state,
            "canGetAndSetFMUstate",
            operation,
        )
    }

    fn require_serialize(&self, operation: &'static str) -> Result<()> {
        self.require_get_set(operation)?;
        self.require(
            self.fmu
                .model_description
                .co_simulation
                .can_serialize_fmu_state,
            "canSerializeFMUstate",
            operation,
        )
    }

    /// `fmi2GetFMUstate` into a new state. Needs `canGetAndSetFMUstate`.
    pub fn get_fmu_state(&mut self) -> Result<FmuState> {
        self.require_get_set("fmi2GetFMUstate")?;
        let mut component = self.lock();
        let raw = component.fmi2GetFMUstate_new()?;
        Ok(FmuState {
            core: Arc::clone(&self.core),
            raw,
            time: Some(component.time),
        })
    }

    /// `fmi2GetFMUstate` into an existing state of this instance, letting the FMU reuse
    /// its memory (no allocation on the master's side).
    pub fn update_fmu_state(&mut self, state: &mut FmuState) -> Result<()> {
        const F: &str = "fmi2GetFMUstate";
        self.require_get_set(F)?;
        self.owns(F, state)?;
        let mut component = self.lock();
        component.fmi2GetFMUstate_update(&mut state.raw)?;
        state.time = Some(component.time);
        Ok(())
    }

    /// `fmi2SetFMUstate`; the tracked time becomes the state's time when known.
    pub fn set_fmu_state(&mut self, state: &FmuState) -> Result<()> {
        const F: &str = "fmi2SetFMUstate";
        self.require_get_set(F)?;
        self.owns(F, state)?;
        let mut component = self.lock();
        component.fmi2SetFMUstate(&state.raw)?;
        if let Some(t) = state.time {
            component.time = t;
        }
        Ok(())
    }

    /// `fmi2SerializedFMUstateSize` + `fmi2SerializeFMUstate` into a new vector. Needs
    /// `canSerializeFMUstate`.
    pub fn serialize_fmu_state(&mut self, state: &FmuState) -> Result<Vec<u8>> {
        let mut bytes = Vec::new();
        self.serialize_fmu_state_into(state, &mut bytes)?;
        Ok(bytes)
    }

    /// Serializes into `out` (cleared first; its capacity is reused).
    pub fn serialize_fmu_state_into(&mut self, state: &FmuState, out: &mut Vec<u8>) -> Result<()> {
        const F: &str = "fmi2SerializeFMUstate";
        self.require_serialize(F)?;
        self.owns(F, state)?;
        let mut component = self.lock();
        let size = component.fmi2SerializedFMUstateSize(&state.raw)?;
        out.clear();
        out.resize(size, 0);
        component.fmi2SerializeFMUstate(&state.raw, out)
    }

    /// `fmi2DeSerializeFMUstate`: a new state of this instance from bytes produced by
    /// [`serialize_fmu_state`](Self::serialize_fmu_state) (possibly of another instance of
    /// the same FMU). Needs `canSerializeFMUstate`.
    pub fn deserialize_fmu_state(&mut self, bytes: &[u8]) -> Result<FmuState> {
        self.require_serialize("fmi2DeSerializeFMUstate")?;
        let raw = self.lock().fmi2DeSerializeFMUstate(bytes)?;
        Ok(FmuState {
            core: Arc::clone(&self.core),
            raw,
            time: None,
        })
    }
}
