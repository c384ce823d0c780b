//! [`FmuState`]: owned FMU states (`fmi2GetFMUstate` & co), freed on drop.

use std::sync::Arc;

use super::{Instance, Shared};
use crate::component::fmi2::RawState;
use crate::error::Result;

/// A saved FMU state, tied to the instance that created it.
///
/// The state may outlive the [`Instance`] value: `fmi2FreeFMUstate` runs on drop (by
/// the instance before its next call, or at once if the instance is gone), and
/// `fmi2FreeInstance` after the last state and the instance are gone. Using it with
/// another instance is an [`Error::ForeignState`](crate::Error::ForeignState), never
/// undefined behaviour.
#[derive(Debug)]
pub struct FmuState {
    shared: Arc<Shared>,
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
        self.shared.drop_state(&mut self.raw);
    }
}

impl Instance {
    /// A new state of this instance, counted until dropped.
    fn own(&self, raw: RawState, time: Option<f64>) -> FmuState {
        self.shared.adopt_state();
        FmuState {
            shared: Arc::clone(&self.shared),
            raw,
            time,
        }
    }

    /// `canGetAndSetFMUstate` and `canSerializeFMUstate` of the interface the
    /// instance was made for.
    fn state_flags(&self) -> (bool, bool) {
        let md = &self.fmu.model_description;
        match (&md.model_exchange, self.model_exchange) {
            (Some(me), true) => (me.can_get_and_set_fmu_state, me.can_serialize_fmu_state),
            _ => (
                md.cs().can_get_and_set_fmu_state,
                md.cs().can_serialize_fmu_state,
            ),
        }
    }

    fn require_get_set(&self, operation: &'static str) -> Result<()> {
        self.require(self.state_flags().0, "canGetAndSetFMUstate", operation)
    }

    fn require_serialize(&self, operation: &'static str) -> Result<()> {
        self.require_get_set(operation)?;
        self.require(self.state_flags().1, "canSerializeFMUstate", operation)
    }

    /// `fmi2GetFMUstate` into a new state. Needs `canGetAndSetFMUstate`.
    pub fn get_fmu_state(&mut self) -> Result<FmuState> {
        self.require_get_set("fmi2GetFMUstate")?;
        let component = self.raw();
        let raw = component.fmi2GetFMUstate_new()?;
        let time = Some(component.time);
        Ok(self.own(raw, time))
    }

    /// `fmi2GetFMUstate` into an existing state of this instance, letting the FMU reuse
    /// its memory (no allocation on the master's side).
    #[inline(always)]
    pub fn update_fmu_state(&mut self, state: &mut FmuState) -> Result<()> {
        // A state of this instance exists only if the FMU can get and set
        // states (`get_fmu_state` and `deserialize_fmu_state` checked that);
        // the component refuses any other state.
        let component = self.raw();
        component.fmi2GetFMUstate_update(&mut state.raw)?;
        state.time = Some(component.time);
        Ok(())
    }

    /// `fmi2SetFMUstate`; the tracked time becomes the state's time when known.
    #[inline(always)]
    pub fn set_fmu_state(&mut self, state: &FmuState) -> Result<()> {
        // No capability check: as in `update_fmu_state`.
        let component = self.live();
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
        let component = self.raw();
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
        let raw = self.raw().fmi2DeSerializeFMUstate(bytes)?;
        Ok(self.own(raw, None))
    }
}
