//! [`FmuInstance`]: the one interface between a master and an FMU instance.
//!
//! For an FMI 3.0 instance ([`Fmi3Instance`](crate::Fmi3Instance)) "Real" means
//! `Float64` or `Float32`, "Integer" every integer type and enumerations (each
//! value exactly, as an [`Int`]), "String" also `Binary` as hexadecimal text; an array
//! variable takes as many values as it has elements, row-major.
//!
//! The master speaks this interface only, in its own words (save, restore,
//! step, inputs' polynomial); the implementations speak FMI. There is one
//! implementation per place and standard: [`LocalInstance`] for an FMI 2.0
//! instance loaded in this process,
//! [`RemoteInstance`](crate::remote::RemoteInstance) for one in a host process
//! of its own, and [`Fmi3Instance`](crate::Fmi3Instance) for an FMI 3.0 instance
//! in this process; [`instantiate`](crate::instantiate) picks one. The master
//! holds a `Box<dyn FmuInstance>`: a new kind of instance (an instance on
//! another machine) is one more implementation, and the macro step does not
//! change.
//!
//! # Runs
//!
//! A macro step is made of *runs*: restore the saved state, set the inputs
//! (or their polynomial over the step), step, read the coupled outputs, save
//! the state where due. [`FmuInstance::run`] takes one run as one unit, a
//! [`RunRequest`], so that an implementation that crosses a process or a
//! network can send it in one message. Its provided body makes the calls one
//! by one, in the order the request lists them. [`FmuInstance::run_batch`]
//! takes runs that do not depend on each other's outputs (a macro step's
//! predictor and perturbed runs) as one unit in the same way.
//!
//! # Deferred calls
//!
//! The methods that return nothing but a status ([`restore`](FmuInstance::restore),
//! [`set_reals`](FmuInstance::set_reals), [`set_inputs`](FmuInstance::set_inputs),
//! [`step`](FmuInstance::step), [`save`](FmuInstance::save), [`free`](FmuInstance::free),
//! a run that reads nothing, …) may be deferred by an implementation to the
//! next call that needs an answer: the isolated instance does, so that a
//! macro step costs it two messages. The error of a deferred call is then
//! returned by that later call, and still names the FMI function that failed
//! and its time ([`Error::function`]).

use std::fmt::Debug;

use crate::error::Result;

use crate::model_description::{ModelDescription, ValueReference};

/// An integer value of any FMI type (FMI 2.0 `Integer`, FMI 3.0 `Int8` …
/// `UInt64`, enumerations), exactly.
pub type Int = i128;

/// A numbered place for a saved FMU state. An instance keeps its states on
/// its own side (in its host process, for an isolated one); the master names
/// them by slot.
pub type Slot = usize;

/// The number of state slots an instance offers (0 … `SLOTS` − 1).
pub const SLOTS: usize = 4;

/// The coupled inputs of a run: their values at the start of the step and,
/// for a polynomial input of degree k > 0, their time derivatives there.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// The inputs (Real).
    pub vrs: &'a [ValueReference],
    /// Their values at the start of the step.
    pub values: &'a [f64],
    /// The inputs whose derivatives are given, once per order.
    pub derivative_vrs: &'a [ValueReference],
    /// The order of each derivative (1, 2, …).
    pub orders: &'a [i32],
    /// The derivatives themselves.
    pub derivatives: &'a [f64],
}

/// One run of a macro step, handed to an instance as one unit: each part is
/// done in the order listed here, every part optional.
#[derive(Debug, Clone, Copy, Default)]
pub struct RunRequest<'a> {
    /// Roll back to the state in this slot first.
    pub restore: Option<Slot>,
    /// Set the coupled inputs.
    pub inputs: Option<Inputs<'a>>,
    /// Step from `t` over `h`.
    pub step: Option<(f64, f64)>,
    /// Read these Real values into the run's output (`outputs[..len]`).
    pub outputs: &'a [ValueReference],
    /// The number of values `outputs` reads when some are FMI 3.0 arrays (one
    /// per element); `None`: one per variable.
    pub output_values: Option<usize>,
    /// Then read these output derivatives `(variable, order)`, one call each,
    /// into the run's output after the values.
    pub output_derivatives: &'a [(ValueReference, i32)],
    /// Then read these Real values (the recorded outputs, a second
    /// `fmi2GetReal`) into the rest of the run's output.
    pub recorded: &'a [ValueReference],
    /// The number of values `recorded` reads, as `output_values`.
    pub recorded_values: Option<usize>,
    /// Save the state into this slot last.
    pub save: Option<Slot>,
}

impl RunRequest<'_> {
    /// The number of values the run reads: its output's length.
    pub fn outputs_len(&self) -> usize {
        self.values_len() + self.output_derivatives.len() + self.recorded_len()
    }

    /// The number of values `outputs` reads.
    pub fn values_len(&self) -> usize {
        self.output_values.unwrap_or(self.outputs.len())
    }

    /// The number of values `recorded` reads.
    pub fn recorded_len(&self) -> usize {
        self.recorded_values.unwrap_or(self.recorded.len())
    }
}

/// What an instance can do, as the master asks it
/// ([`FmuInstance::capabilities`]): for a co-simulation instance what its
/// FMU's `CoSimulation` element declares, for a model-exchange instance what
/// the instance with its integrator does.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Capabilities {
    /// A state can be saved and restored ([`FmuInstance::save`],
    /// [`FmuInstance::restore`]): `canGetAndSetFMUstate`.
    pub rollback: bool,
    /// A saved state can be serialized ([`FmuInstance::serialize`]):
    /// `canSerializeFMUstate` besides rollback.
    pub serialization: bool,
    /// The inputs take polynomials over a step ([`Inputs`] with
    /// derivatives): FMI 2.0 `canInterpolateInputs`, FMI 3.0
    /// `providesIntermediateUpdate` (for the inputs declared
    /// `intermediateUpdate="true"`).
    pub polynomial_inputs: bool,
    /// Steps may change size: `canHandleVariableCommunicationStepSize`.
    pub variable_steps: bool,
    /// The highest order of output derivatives
    /// ([`FmuInstance::get_output_derivatives`]): `maxOutputDerivativeOrder`.
    pub output_derivative_order: u32,
}

impl Capabilities {
    /// What the `CoSimulation` element of `md` declares (nothing without one).
    pub fn co_simulation(md: &ModelDescription) -> Capabilities {
        let cs = md.cs();
        Capabilities {
            rollback: cs.can_get_and_set_fmu_state,
            serialization: cs.can_get_and_set_fmu_state && cs.can_serialize_fmu_state,
            polynomial_inputs: cs.can_interpolate_inputs || cs.provides_intermediate_update,
            variable_steps: cs.can_handle_variable_communication_step_size,
            output_derivative_order: cs.max_output_derivative_order,
        }
    }
    /// What a model-exchange instance of `md` can do with the built-in
    /// integrator: rollback (the instance owns the continuous states; with
    /// `canGetAndSetFMUstate` the FMU's state is saved too, without it a
    /// step is repeated only while no event and no completed integrator
    /// step fell inside it), serialized states where `ModelExchange`
    /// declares `canGetAndSetFMUstate` and `canSerializeFMUstate`, steps of
    /// any size, input polynomials of any degree on every Real input
    /// (evaluated at every time the model is); no output derivatives.
    pub fn model_exchange(md: &ModelDescription) -> Capabilities {
        let me = md.model_exchange.as_ref();
        Capabilities {
            rollback: me.is_some(),
            serialization: me
                .is_some_and(|me| me.can_get_and_set_fmu_state && me.can_serialize_fmu_state),
            polynomial_inputs: true,
            variable_steps: true,
            output_derivative_order: 0,
        }
    }
}

/// An FMU instance as a master drives it: the life cycle, values, the
/// inputs' polynomial over a step, the step, saved states, and runs.
pub trait FmuInstance: Debug + Send {
    /// The instance name.
    fn name(&self) -> &str;

    /// What the instance can do; the master asks this, not the model
    /// description.
    fn capabilities(&self) -> Capabilities;

    /// The FMU's model description.
    fn model_description(&self) -> &ModelDescription;

    /// The communication time as tracked by the instance.
    fn time(&self) -> f64;

    /// Whether the FMU reported a fatal error (no call is made after it).
    fn is_fatal(&self) -> bool;

    /// Switch the FMU's debug logging on or off for `categories` (all when empty).
    fn set_debug_logging(&mut self, on: bool, categories: &[&str]) -> Result<()>;

    /// Tell the FMU the experiment: tolerance, start and stop time.
    fn setup(&mut self, tolerance: Option<f64>, start: f64, stop: Option<f64>) -> Result<()>;

    /// Enter initialization mode, in which values can be set and read.
    fn enter_initialization(&mut self) -> Result<()>;

    /// Leave initialization mode: the instance is ready to step.
    fn exit_initialization(&mut self) -> Result<()>;

    /// Real values into `out`.
    fn get_reals(&mut self, vrs: &[ValueReference], out: &mut [f64]) -> Result<()>;
    /// Set Real values.
    fn set_reals(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()>;
    /// Integer (and Enumeration) values into `out`.
    fn get_integers(&mut self, vrs: &[ValueReference], out: &mut [Int]) -> Result<()>;
    /// Set Integer (and Enumeration) values.
    fn set_integers(&mut self, vrs: &[ValueReference], values: &[Int]) -> Result<()>;
    /// Boolean values into `out`.
    fn get_booleans(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()>;
    /// Set Boolean values.
    fn set_booleans(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()>;
    /// String values into `out`.
    fn get_strings(&mut self, vrs: &[ValueReference], out: &mut [String]) -> Result<()>;
    /// Set String values.
    fn set_strings(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()>;

    /// Set the coupled inputs for the coming step: their values and, for a
    /// polynomial of degree k > 0, its derivatives at the step's start (FMI
    /// 2.0: `fmi2SetReal`, then `fmi2SetRealInputDerivatives` when derivatives
    /// are given).
    fn set_inputs(&mut self, inputs: &Inputs<'_>) -> Result<()>;

    /// Output derivatives of the given orders into `out`.
    fn get_output_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()>;

    /// Step from `t` over `h`. A request of the FMU to end the simulation is
    /// [`Error::TerminationRequested`], with the time it reached.
    fn step(&mut self, t: f64, h: f64) -> Result<()>;

    /// Save the current state into `slot` (reusing what is there).
    fn save(&mut self, slot: Slot) -> Result<()>;
    /// Roll back to the state in `slot`, which [`save`](Self::save) filled.
    fn restore(&mut self, slot: Slot) -> Result<()>;
    /// Free the state in `slot`, if any.
    fn free(&mut self, slot: Slot) -> Result<()>;
    /// The state in `slot` as bytes into `out` (its capacity is reused).
    fn serialize(&mut self, slot: Slot, out: &mut Vec<u8>) -> Result<()>;
    /// A state from bytes of [`serialize`](Self::serialize) (of this or
    /// another instance of the same FMU) into `slot`.
    fn deserialize(&mut self, slot: Slot, bytes: &[u8]) -> Result<()>;

    /// Back to the instantiated state.
    fn reset(&mut self) -> Result<()>;

    /// The messages this instance exchanged with a process of its own so far,
    /// each a request and its reply (0 for an instance in this process).
    fn round_trips(&self) -> u64 {
        0
    }
    /// Whether the instance runs in a process of its own (isolated or on a
    /// remote host), reached by requests.
    fn is_remote(&self) -> bool {
        false
    }
    /// End the simulation (the instance is freed when dropped).
    fn terminate(&mut self) -> Result<()>;

    /// One run of a macro step (see [`RunRequest`]); the Real outputs and
    /// then the output derivatives go to `out`, which has their number.
    fn run(&mut self, run: &RunRequest<'_>, out: &mut [f64]) -> Result<()> {
        if let Some(slot) = run.restore {
            self.restore(slot)?;
        }
        if let Some(inputs) = &run.inputs {
            self.set_inputs(inputs)?;
        }
        if let Some((t, h)) = run.step {
            self.step(t, h)?;
        }
        let (values, derivatives) = out.split_at_mut(run.values_len());
        if !run.outputs.is_empty() {
            self.get_reals(run.outputs, values)?;
        }
        let (derivatives, recorded) = derivatives.split_at_mut(run.output_derivatives.len());
        for (&(vr, order), out) in run.output_derivatives.iter().zip(derivatives) {
            self.get_output_derivatives(&[vr], &[order], std::slice::from_mut(out))?;
        }
        if !run.recorded.is_empty() {
            self.get_reals(run.recorded, recorded)?;
        }
        if let Some(slot) = run.save {
            self.save(slot)?;
        }
        Ok(())
    }

    /// Runs that do not depend on each other's outputs, in order (the
    /// predictor and the perturbed runs of a macro step, each from the saved
    /// state): one unit, which an instance in another process receives as
    /// one message. Each run's output ([`RunRequest::outputs_len`] values)
    /// follows the previous one's in `out`. Stops at the first error.
    fn run_batch(&mut self, runs: &[RunRequest<'_>], out: &mut [f64]) -> Result<()> {
        let mut rest = out;
        for run in runs {
            let (head, tail) = std::mem::take(&mut rest).split_at_mut(run.outputs_len());
            self.run(run, head)?;
            rest = tail;
        }
        Ok(())
    }

    /// The first half of [`run_batch`](Self::run_batch) for an instance in
    /// a process of its own ([`is_remote`](Self::is_remote)): the batch's
    /// request sent, its reply not awaited, so that requests to several
    /// hosts run at once. Returns whether a reply is awaited: then
    /// [`receive_batch`](Self::receive_batch) with the same `runs` must
    /// follow before any other call. An instance in this process sends
    /// nothing and returns false; its batch is made by `run_batch`.
    fn send_batch(&mut self, _runs: &[RunRequest<'_>]) -> Result<bool> {
        Ok(false)
    }

    /// The second half of [`run_batch`](Self::run_batch): the reply to the
    /// request [`send_batch`](Self::send_batch) sent for `runs`, its values
    /// into `out`.
    fn receive_batch(&mut self, runs: &[RunRequest<'_>], out: &mut [f64]) -> Result<()> {
        self.run_batch(runs, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn capabilities(version: &str, cs: &str) -> Capabilities {
        let token = if version == "2.0" {
            "guid"
        } else {
            "instantiationToken"
        };
        let xml = format!(
            r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="{version}" modelName="m" {token}="{{g}}">
  <CoSimulation modelIdentifier="m" {cs}/>
  <ModelVariables/>
  <ModelStructure/>
</fmiModelDescription>"#
        );
        Capabilities::co_simulation(&ModelDescription::from_xml(&xml).unwrap())
    }

    /// FMI 2.0 takes polynomials with canInterpolateInputs, FMI 3.0 with
    /// intermediate update; serialization needs rollback too; the standard's
    /// defaults are false and 0.
    #[test]
    fn co_simulation_capabilities_are_what_the_fmu_declares() {
        assert_eq!(capabilities("2.0", ""), Capabilities::default());
        let declared = capabilities(
            "2.0",
            r#"canInterpolateInputs="true" maxOutputDerivativeOrder="2" canGetAndSetFMUstate="true"
               canSerializeFMUstate="true" canHandleVariableCommunicationStepSize="true""#,
        );
        assert_eq!(
            declared,
            Capabilities {
                rollback: true,
                serialization: true,
                polynomial_inputs: true,
                variable_steps: true,
                output_derivative_order: 2,
            }
        );
        let fmi3 = capabilities("3.0", r#"providesIntermediateUpdate="true""#);
        assert!(fmi3.polynomial_inputs && !fmi3.rollback);
        let unserializable = capabilities("2.0", r#"canSerializeFMUstate="true""#);
        assert!(!unserializable.serialization);
    }
}
