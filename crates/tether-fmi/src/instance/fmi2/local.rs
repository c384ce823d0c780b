//! [`LocalInstance`]: an FMI 2.0 instance in this process as an
//! [`FmuInstance`], with its saved states in slots.

use super::Instance;
use crate::error::{Error, Result};
use crate::interface::*;
use crate::model_description::{BaseType, ModelDescription, ValueReference};
use crate::FmuState;

/// An FMI 2.0 instance in this process, with its saved states.
#[derive(Debug)]
pub struct LocalInstance {
    instance: Instance,
    states: [Option<FmuState>; SLOTS],
}

impl LocalInstance {
    /// Wraps an instance.
    pub fn new(instance: Instance) -> LocalInstance {
        LocalInstance {
            instance,
            states: Default::default(),
        }
    }

    /// The instance, for the model-exchange calls of [`crate::MeInstance`].
    pub(crate) fn instance_mut(&mut self) -> &mut Instance {
        &mut self.instance
    }
}

impl FmuInstance for LocalInstance {
    fn name(&self) -> &str {
        self.instance.name()
    }
    fn capabilities(&self) -> crate::interface::Capabilities {
        crate::interface::Capabilities::co_simulation(self.model_description())
    }
    fn model_description(&self) -> &ModelDescription {
        self.instance.model_description()
    }
    fn time(&self) -> f64 {
        self.instance.time()
    }
    fn is_fatal(&self) -> bool {
        self.instance.is_fatal()
    }
    fn set_debug_logging(&mut self, on: bool, categories: &[&str]) -> Result<()> {
        self.instance.set_debug_logging(on, categories)
    }
    fn setup(&mut self, tolerance: Option<f64>, start: f64, stop: Option<f64>) -> Result<()> {
        self.instance.setup_experiment(tolerance, start, stop)
    }
    fn enter_initialization(&mut self) -> Result<()> {
        self.instance.enter_initialization_mode()
    }
    fn exit_initialization(&mut self) -> Result<()> {
        self.instance.exit_initialization_mode()
    }
    #[inline]
    fn get_reals(&mut self, vrs: &[ValueReference], out: &mut [f64]) -> Result<()> {
        self.instance.get_real(vrs, out)
    }
    #[inline]
    fn set_reals(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        self.instance.set_real(vrs, values)
    }
    fn get_integers(&mut self, vrs: &[ValueReference], out: &mut [Int]) -> Result<()> {
        let mut narrow = vec![0; out.len()];
        self.instance.get_integer(vrs, &mut narrow)?;
        for (o, x) in out.iter_mut().zip(narrow) {
            *o = Int::from(x);
        }
        Ok(())
    }
    fn set_integers(&mut self, vrs: &[ValueReference], values: &[Int]) -> Result<()> {
        let mut narrow = Vec::with_capacity(values.len());
        for (&x, vr) in values.iter().zip(vrs) {
            let Ok(x) = i32::try_from(x) else {
                let md = self.instance.model_description();
                let name = md
                    .model_variables
                    .iter()
                    .find(|v| {
                        v.value_reference == *vr
                            && matches!(v.base_type(), BaseType::Integer | BaseType::Enumeration)
                    })
                    .map_or_else(|| vr.to_string(), |v| v.name.clone());
                return Err(Error::InvalidArgument {
                    function: "fmi2SetInteger",
                    instance: self.instance.name().to_owned(),
                    message: format!(
                        "the value {x} of '{name}' is outside the 32-bit range of an FMI 2.0 Integer"
                    ),
                });
            };
            narrow.push(x);
        }
        self.instance.set_integer(vrs, &narrow)
    }
    fn get_booleans(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()> {
        self.instance.get_boolean(vrs, out)
    }
    fn set_booleans(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()> {
        self.instance.set_boolean(vrs, values)
    }
    fn get_strings(&mut self, vrs: &[ValueReference], out: &mut [String]) -> Result<()> {
        self.instance.get_string(vrs, out)
    }
    fn set_strings(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()> {
        self.instance.set_string(vrs, values)
    }
    #[inline]
    fn set_inputs(&mut self, inputs: &Inputs<'_>) -> Result<()> {
        self.instance.set_real(inputs.vrs, inputs.values)?;
        if !inputs.derivative_vrs.is_empty() {
            self.instance.set_real_input_derivatives(
                inputs.derivative_vrs,
                inputs.orders,
                inputs.derivatives,
            )?;
        }
        Ok(())
    }
    fn get_output_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()> {
        self.instance.get_real_output_derivatives(vrs, orders, out)
    }
    #[inline]
    fn step(&mut self, t: f64, h: f64) -> Result<()> {
        match self.instance.do_step(t, h, true) {
            Ok(()) => Ok(()),
            Err(e) => Err(crate::error::step_failure(e, &mut self.instance, t + h)),
        }
    }
    #[inline]
    fn save(&mut self, slot: Slot) -> Result<()> {
        match &mut self.states[slot] {
            Some(s) => self.instance.update_fmu_state(s),
            empty => {
                *empty = Some(self.instance.get_fmu_state()?);
                Ok(())
            }
        }
    }
    #[inline]
    fn restore(&mut self, slot: Slot) -> Result<()> {
        let state = slot_state(&self.states, slot, &self.instance, "fmi2SetFMUstate")?;
        self.instance.set_fmu_state(state)
    }
    fn free(&mut self, slot: Slot) -> Result<()> {
        self.states[slot] = None;
        Ok(())
    }
    fn serialize(&mut self, slot: Slot, out: &mut Vec<u8>) -> Result<()> {
        let state = slot_state(&self.states, slot, &self.instance, "fmi2SerializeFMUstate")?;
        self.instance.serialize_fmu_state_into(state, out)
    }
    fn deserialize(&mut self, slot: Slot, bytes: &[u8]) -> Result<()> {
        // The previous state is freed (fmi2FreeFMUstate) when replaced.
        self.states[slot] = Some(self.instance.deserialize_fmu_state(bytes)?);
        Ok(())
    }
    fn reset(&mut self) -> Result<()> {
        self.instance.reset()
    }
    fn terminate(&mut self) -> Result<()> {
        self.instance.terminate()
    }
}

/// The state saved in `slot`, or an error naming `function` and the slot.
#[inline]
fn slot_state<'a>(
    states: &'a [Option<FmuState>],
    slot: Slot,
    instance: &Instance,
    function: &'static str,
) -> Result<&'a FmuState> {
    match states.get(slot) {
        Some(Some(state)) => Ok(state),
        _ => Err(no_state(slot, instance, function)),
    }
}

/// The error for a slot without a saved state.
#[cold]
#[inline(never)]
fn no_state(slot: Slot, instance: &Instance, function: &'static str) -> Error {
    Error::InvalidArgument {
        function,
        instance: instance.name().to_string(),
        message: format!("no FMU state saved in slot {slot}"),
    }
}
