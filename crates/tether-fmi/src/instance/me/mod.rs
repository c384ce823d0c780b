//! [`MeInstance`]: a model-exchange FMU (FMI 2.0 or FMI 3.0) in this process, as
//! the master drives any instance ([`FmuInstance`]): the instance owns the
//! continuous states and integrates them with the built-in integrator
//! ([`Integrator`]) over each step.
//!
//! The life cycle is the standard's: instantiate for model exchange; the
//! experiment and the start values; initialization mode; after it the event
//! iteration (`fmi2NewDiscreteStates` / `fmi3UpdateDiscreteStates` until no new
//! discrete states are needed), continuous-time mode, the states, their nominals
//! and the event indicators read. A step from t to t + h integrates towards the
//! next time event or t + h and handles, in time order:
//!
//! - **time events**: the FMU's `nextEventTime`, reached exactly;
//! - **state events**: an event indicator's sign change (from > 0 to ≤ 0 or
//!   back) after an accepted integrator step, located by bisection to within
//!   100·ε·max(|t|, h);
//! - **step events**: `CompletedIntegratorStep` (called after every accepted
//!   step unless the FMU says it is not needed) asking for event mode.
//!
//! At each event: event mode, the event iteration, continuous-time mode; the
//! states are read again when the FMU says their values changed, the nominals
//! when it says they changed. A request to terminate (in the event iteration or
//! from `CompletedIntegratorStep`) is [`Error::TerminationRequested`] at the
//! time reached, as a co-simulation FMU's. More than 100 event iterations at one
//! time end the run with one line ([`Error::ModelExchange`]: the model
//! chatters), as do NaN or infinite derivatives and an integrator that cannot
//! reach its tolerance.
//!
//! An FMU without continuous states is stepped without the integrator (one
//! step to the next event or t + h, its event indicators, if any, checked
//! there). Each step restarts the integrator from (t, x(t)) with its own
//! initial step and no history: a repeated step from the same point is
//! bit-identical.
//!
//! A saved state ([`FmuInstance::save`], where the FMU declares
//! `canGetAndSetFMUstate` for model exchange) is the FMU's state and the
//! instance's own: the continuous states, nominals, event indicators, the next
//! time event and the event counts; a restore puts both back, so a step
//! repeated after it gives the same bits.
//!
//! Values set after the initialization: continuous Real inputs at once; any
//! other value (Integer, Boolean, String and discrete Real inputs,
//! parameters) only in event mode, as the standard requires — when one
//! changes, the instance enters event mode, sets it and runs the event
//! iteration at its time (an event like any other).
//!
//! The implicit methods (`bdf`, the default, and `esdirk`) take the Jacobian
//! of the derivatives from the FMU's directional derivatives where its
//! `ModelExchange` element declares them, else from finite differences.
//!
//! Output derivatives are not offered.

mod calls;
mod dopri5;
mod inputs;
mod integrator;
mod state;

pub use crate::integrator::{Integrator, Method};

use calls::MeCalls;
use inputs::InputPolynomial;
use integrator::{Buffers, Point, Settings, Stop};

use crate::error::{Error, Result};
use crate::fmu::{Fmu, InstanceOptions};
use crate::instance::{Fmi3Instance, LocalInstance};
use crate::interface::{Capabilities, FmuInstance, Inputs, Int, Slot, SLOTS};
use crate::model_description::{
    Causality, FmiStandard, ModelDescription, ValueReference, Variability,
};

/// The most event iterations at one time before the run ends (a chattering
/// model).
pub const MAX_EVENT_ITERATIONS: u32 = 100;

/// What a saved state holds besides the FMU's own.
#[derive(Debug, Clone, Default)]
struct Saved {
    time: f64,
    x: Vec<f64>,
    nominals: Vec<f64>,
    z: Vec<f64>,
    next_event: Option<f64>,
    event_time: f64,
    event_iterations: u32,
    events: u64,
    last_event: Option<f64>,
    completed_calls: u64,
    /// Whether the FMU's own state was saved with it.
    fmu_state: bool,
}

/// A model-exchange instance in this process with its built-in integrator.
#[derive(Debug)]
pub struct MeInstance {
    inner: Box<dyn MeCalls>,
    integrator: Integrator,
    /// The experiment's tolerance (`setup`).
    tolerance: Option<f64>,
    /// Continuous states, their nominals and the event indicators at `time`.
    x: Vec<f64>,
    nominals: Vec<f64>,
    z: Vec<f64>,
    next_event: Option<f64>,
    time: f64,
    needs_completed: bool,
    /// `canGetAndSetFMUstate` of `ModelExchange`: the FMU's state is saved
    /// with the instance's.
    fmu_states: bool,
    /// `canSerializeFMUstate` besides.
    serializable: bool,
    /// The integrations made with `CompletedIntegratorStep` calls.
    completed_calls: u64,
    initialized: bool,
    /// The time of the last event and the event iterations made at it.
    event_time: f64,
    event_iterations: u32,
    /// The events handled after initialization, and the time of the last.
    events: u64,
    last_event: Option<f64>,
    /// The instance's part of the states saved in each slot.
    saved: [Option<Saved>; SLOTS],
    /// The integrator's buffers, kept between steps.
    buffers: Buffers,
    /// The inputs' polynomial over the coming step (coupling polynomials of
    /// degree k > 0), evaluated at every time the model is.
    inputs: InputPolynomial,
    /// The continuous Real inputs, sorted: the only values set outside event
    /// mode after the initialization.
    continuous_inputs: Vec<ValueReference>,
    /// The values of discrete inputs read to see whether a set changes them.
    reals: Vec<f64>,
    integers: Vec<Int>,
    booleans: Vec<bool>,
}

impl MeInstance {
    /// Instantiates `fmu` for model exchange as `name`, to be integrated with
    /// `integrator`. An FMU without a `ModelExchange` element, an FMI 3.0 FMU
    /// with clocks or a library without the model-exchange functions is
    /// refused in one line.
    pub fn new(
        fmu: &Fmu,
        name: &str,
        options: InstanceOptions,
        integrator: Integrator,
    ) -> Result<MeInstance> {
        let md = fmu.model_description();
        if let Err(reason) = integrator.check() {
            return Err(Error::InvalidArgument {
                function: "the integrator",
                instance: name.to_owned(),
                message: reason,
            });
        }
        let inner: Box<dyn MeCalls> = match md.standard {
            FmiStandard::Fmi2 => Box::new(LocalInstance::new(
                fmu.instantiate_model_exchange(name, options)?,
            )),
            FmiStandard::Fmi3 => Box::new(Fmi3Instance::new_model_exchange(fmu, name, options)?),
        };
        let me = md.model_exchange.as_ref();
        let needs_completed = me.is_some_and(|me| me.needs_completed_integrator_step);
        let fmu_states = me.is_some_and(|me| me.can_get_and_set_fmu_state);
        let serializable = fmu_states && me.is_some_and(|me| me.can_serialize_fmu_state);
        let mut continuous_inputs: Vec<ValueReference> = md
            .model_variables
            .iter()
            .filter(|v| v.causality == Causality::Input && v.variability == Variability::Continuous)
            .map(|v| v.value_reference)
            .collect();
        continuous_inputs.sort_unstable();
        let start = md
            .default_experiment
            .and_then(|d| d.start_time)
            .unwrap_or(0.0);
        Ok(MeInstance {
            inner,
            integrator,
            tolerance: None,
            x: Vec::new(),
            nominals: Vec::new(),
            z: Vec::new(),
            next_event: None,
            time: start,
            needs_completed,
            fmu_states,
            serializable,
            completed_calls: 0,
            initialized: false,
            event_time: f64::NAN,
            event_iterations: 0,
            events: 0,
            last_event: None,
            saved: Default::default(),
            buffers: Buffers::default(),
            inputs: InputPolynomial::default(),
            continuous_inputs,
            reals: Vec::new(),
            integers: Vec::new(),
            booleans: Vec::new(),
        })
    }

    /// The integrator settings as given.
    pub fn integrator(&self) -> &Integrator {
        &self.integrator
    }

    /// The continuous states now.
    pub fn continuous_states(&self) -> &[f64] {
        &self.x
    }

    /// The event indicators now.
    pub fn event_indicators(&self) -> &[f64] {
        &self.z
    }

    /// The number of events (time, state and step events) handled since the
    /// initialization, and the time of the last one.
    pub fn events(&self) -> (u64, Option<f64>) {
        (self.events, self.last_event)
    }

    /// The next time event the FMU announced, if any.
    pub fn next_event_time(&self) -> Option<f64> {
        self.next_event
    }

    /// The settings in force: rtol from the integrator, else the experiment,
    /// else the model's default experiment, else 1e-6; atol (relative to the
    /// nominals) default rtol; the largest step default the step `h`.
    fn settings(&self, h: f64) -> Settings {
        let rtol = self
            .integrator
            .rtol
            .or(self.tolerance)
            .or_else(|| {
                self.inner
                    .model_description()
                    .default_experiment
                    .and_then(|d| d.tolerance)
            })
            .unwrap_or(1e-6);
        Settings {
            method: self.integrator.method,
            rtol,
            atol: self.integrator.atol.unwrap_or(rtol),
            max_step: self.integrator.max_step.unwrap_or(h).min(h),
        }
    }

    fn error(&self, time: f64, cause: String) -> Error {
        Error::ModelExchange {
            instance: self.inner.name().to_owned(),
            time,
            cause,
        }
    }

    /// The event iteration at `t`, in event mode, then continuous-time mode:
    /// the states, nominals and indicators read as the FMU says.
    fn event_iteration(&mut self, t: f64, initial: bool) -> Result<()> {
        if t != self.event_time {
            self.event_time = t;
            self.event_iterations = 0;
        }
        if !initial {
            self.events += 1;
            self.last_event = Some(t);
        }
        let (_, update, _) = self.inner.names();
        let mut values_changed = initial;
        let mut nominals_changed = initial;
        loop {
            self.event_iterations += 1;
            if self.event_iterations > MAX_EVENT_ITERATIONS {
                return Err(self.error(
                    t,
                    format!(
                        "more than {MAX_EVENT_ITERATIONS} event iterations at this time ({update}): the model chatters"
                    ),
                ));
            }
            let info = self.inner.update_discrete_states()?;
            if info.terminate_simulation {
                return Err(Error::TerminationRequested {
                    instance: self.inner.name().to_owned(),
                    time: t,
                    how: Some(format!("{update}, terminateSimulation")),
                });
            }
            values_changed |= info.values_changed;
            nominals_changed |= info.nominals_changed;
            self.next_event = info.next_event_time;
            if !info.new_discrete_states_needed {
                break;
            }
        }
        self.inner.enter_continuous_time_mode()?;
        if values_changed && !self.x.is_empty() {
            self.inner.get_continuous_states(&mut self.x)?;
        }
        if nominals_changed && !self.nominals.is_empty() {
            self.inner.get_nominals(&mut self.nominals)?;
            for n in &mut self.nominals {
                // FMI requires nominals > 0; another value counts as 1.
                if !(n.is_finite() && *n > 0.0) {
                    *n = 1.0;
                }
            }
        }
        if !self.z.is_empty() {
            self.inner.get_event_indicators(&mut self.z)?;
        }
        Ok(())
    }

    /// Integrates from `t` to `t + h`, handling every event on the way.
    fn advance(&mut self, t: f64, h: f64) -> Result<()> {
        if !self.initialized {
            return Err(Error::InvalidArgument {
                function: "step",
                instance: self.inner.name().to_owned(),
                message: "the model-exchange instance is not initialized".into(),
            });
        }
        let end = t + h;
        let settings = self.settings(h);
        let resolution = 100.0 * f64::EPSILON * end.abs().max(h);
        // The step starts from the instance's own point: states, indicators.
        self.inner.set_time(t)?;
        self.inputs.set(&mut *self.inner, t)?;
        if !self.x.is_empty() {
            self.inner.set_continuous_states(&self.x)?;
        }
        if !self.z.is_empty() {
            self.inner.get_event_indicators(&mut self.z)?;
        }
        let mut now = t;
        loop {
            let time_event = self.next_event.filter(|&te| te <= end + resolution);
            if let Some(te) = time_event.filter(|&te| te <= now + resolution) {
                // A time event now (the FMU is at `now`).
                self.inner.set_time(te.max(now))?;
                self.inputs.set(&mut *self.inner, te.max(now))?;
                self.inner.enter_event_mode()?;
                self.event_iteration(now, false)?;
                continue;
            }
            if end - now <= resolution {
                break;
            }
            let target = time_event.map_or(end, |te| te.min(end));
            let target = if end - target <= resolution {
                end
            } else {
                target
            };
            let (reached, stop) = integrator::integrate(
                &mut *self.inner,
                &settings,
                Point {
                    t0: now,
                    x: &mut self.x,
                    nominals: &self.nominals,
                    z: &mut self.z,
                    needs_completed: self.needs_completed,
                    no_set_prior: self.saved.iter().all(Option::is_none),
                    h,
                    inputs: &self.inputs,
                },
                target,
                &mut self.buffers,
            )?;
            now = reached;
            self.time = now;
            if self.needs_completed {
                self.completed_calls += 1;
            }
            match stop {
                Stop::Reached => {}
                Stop::StateEvent | Stop::StepEvent => {
                    self.inner.enter_event_mode()?;
                    self.event_iteration(now, false)?;
                }
                Stop::Terminate => {
                    let (_, _, completed) = self.inner.names();
                    return Err(Error::TerminationRequested {
                        instance: self.inner.name().to_owned(),
                        time: now,
                        how: Some(format!("{completed}, terminateSimulation")),
                    });
                }
            }
        }
        self.time = end;
        Ok(())
    }

    /// Sets values the standard lets change only in event mode (discrete
    /// inputs, parameters) after the initialization: event mode, `set`, the
    /// event iteration at the instance's time, continuous-time mode.
    fn set_in_event_mode(
        &mut self,
        set: impl FnOnce(&mut dyn MeCalls) -> Result<()>,
    ) -> Result<()> {
        self.inner.enter_event_mode()?;
        set(&mut *self.inner)?;
        let t = self.time;
        self.event_iteration(t, false)
    }

    /// Whether every value reference in `vrs` is a continuous input.
    fn all_continuous(&self, vrs: &[ValueReference]) -> bool {
        vrs.iter()
            .all(|vr| self.continuous_inputs.binary_search(vr).is_ok())
    }

    /// Sets Real values: continuous inputs at once; after the
    /// initialization any other Real (a discrete input, a parameter) in
    /// event mode when a value changes, as the standard requires.
    fn set_values(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        if !self.initialized || self.all_continuous(vrs) {
            return self.inner.set_reals(vrs, values);
        }
        let mut now = std::mem::take(&mut self.reals);
        now.resize(vrs.len(), 0.0);
        let read = self.inner.get_reals(vrs, &mut now);
        let changed = now
            .iter()
            .zip(values)
            .any(|(a, b)| a.to_bits() != b.to_bits());
        self.reals = now;
        read?;
        if !changed {
            return Ok(());
        }
        self.set_in_event_mode(|fmu| fmu.set_reals(vrs, values))
    }

    fn unsupported_state(&self, function: &'static str) -> Error {
        Error::InvalidArgument {
            function,
            instance: self.inner.name().to_owned(),
            message: "a serialized state needs canGetAndSetFMUstate and canSerializeFMUstate in \
                      the FMU's ModelExchange element"
                .into(),
        }
    }
}

impl FmuInstance for MeInstance {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn capabilities(&self) -> Capabilities {
        Capabilities::model_exchange(self.inner.model_description())
    }
    fn model_description(&self) -> &ModelDescription {
        self.inner.model_description()
    }
    fn time(&self) -> f64 {
        self.time
    }
    fn is_fatal(&self) -> bool {
        self.inner.is_fatal()
    }
    fn set_debug_logging(&mut self, on: bool, categories: &[&str]) -> Result<()> {
        self.inner.set_debug_logging(on, categories)
    }
    fn setup(&mut self, tolerance: Option<f64>, start: f64, stop: Option<f64>) -> Result<()> {
        self.tolerance = tolerance;
        self.time = start;
        self.inner.setup(tolerance, start, stop)
    }
    fn enter_initialization(&mut self) -> Result<()> {
        self.inner.enter_initialization()
    }
    /// Leaves initialization mode (the FMU is then in event mode), runs the
    /// event iteration and enters continuous-time mode.
    fn exit_initialization(&mut self) -> Result<()> {
        self.inner.exit_initialization()?;
        let (nx, nz) = self.inner.sizes()?;
        self.x = vec![0.0; nx];
        self.nominals = vec![1.0; nx];
        self.z = vec![0.0; nz];
        self.buffers.prepare(nx, nz);
        let t = self.time;
        self.event_iteration(t, true)?;
        self.initialized = true;
        Ok(())
    }
    fn get_reals(&mut self, vrs: &[ValueReference], out: &mut [f64]) -> Result<()> {
        self.inner.get_reals(vrs, out)
    }
    /// Plain values (an input set so follows no polynomial any more):
    /// continuous inputs at once, any other Real after the initialization in
    /// event mode when a value changes.
    fn set_reals(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        self.inputs.forget(vrs);
        self.set_values(vrs, values)
    }
    fn get_integers(&mut self, vrs: &[ValueReference], out: &mut [Int]) -> Result<()> {
        self.inner.get_integers(vrs, out)
    }
    /// After the initialization in event mode, when a value changes.
    fn set_integers(&mut self, vrs: &[ValueReference], values: &[Int]) -> Result<()> {
        if !self.initialized {
            return self.inner.set_integers(vrs, values);
        }
        let mut now = std::mem::take(&mut self.integers);
        now.resize(vrs.len(), 0);
        let read = self.inner.get_integers(vrs, &mut now);
        let changed = now[..] != values[..];
        self.integers = now;
        read?;
        if !changed {
            return Ok(());
        }
        self.set_in_event_mode(|fmu| fmu.set_integers(vrs, values))
    }
    fn get_booleans(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()> {
        self.inner.get_booleans(vrs, out)
    }
    /// After the initialization in event mode, when a value changes.
    fn set_booleans(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()> {
        if !self.initialized {
            return self.inner.set_booleans(vrs, values);
        }
        let mut now = std::mem::take(&mut self.booleans);
        now.resize(vrs.len(), false);
        let read = self.inner.get_booleans(vrs, &mut now);
        let changed = now[..] != values[..];
        self.booleans = now;
        read?;
        if !changed {
            return Ok(());
        }
        self.set_in_event_mode(|fmu| fmu.set_booleans(vrs, values))
    }
    fn get_strings(&mut self, vrs: &[ValueReference], out: &mut [String]) -> Result<()> {
        self.inner.get_strings(vrs, out)
    }
    /// After the initialization in event mode, when a value changes.
    fn set_strings(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()> {
        if !self.initialized {
            return self.inner.set_strings(vrs, values);
        }
        let mut now = vec![String::new(); vrs.len()];
        self.inner.get_strings(vrs, &mut now)?;
        if now.iter().zip(values).all(|(a, b)| a == b) {
            return Ok(());
        }
        self.set_in_event_mode(|fmu| fmu.set_strings(vrs, values))
    }
    /// The values at the step's start; with derivatives, the polynomial
    /// they make, which the next step follows at every time it evaluates
    /// the model.
    fn set_inputs(&mut self, inputs: &Inputs<'_>) -> Result<()> {
        let t = self.time;
        if let Err(vr) = self.inputs.take(t, inputs) {
            return Err(Error::InvalidArgument {
                function: "set_inputs",
                instance: self.inner.name().to_owned(),
                message: format!("a derivative of value reference {vr}, which has no value"),
            });
        }
        self.set_values(inputs.vrs, inputs.values)
    }
    fn get_output_derivatives(
        &mut self,
        _vrs: &[ValueReference],
        _orders: &[i32],
        _out: &mut [f64],
    ) -> Result<()> {
        Err(Error::InvalidArgument {
            function: "get_output_derivatives",
            instance: self.inner.name().to_owned(),
            message: "a model-exchange instance has no output derivatives \
                      (its capabilities say order 0)"
                .into(),
        })
    }
    fn step(&mut self, t: f64, h: f64) -> Result<()> {
        self.advance(t, h)
    }
    /// The instance's part (time, states, nominals, indicators, next time
    /// event, event counts) and, where `ModelExchange` declares
    /// `canGetAndSetFMUstate`, the FMU's state.
    fn save(&mut self, slot: Slot) -> Result<()> {
        if !self.initialized {
            return Err(Error::InvalidArgument {
                function: "save",
                instance: self.inner.name().to_owned(),
                message: "the model-exchange instance is not initialized".into(),
            });
        }
        if self.fmu_states {
            self.inner.save(slot)?;
        }
        let saved = self.saved[slot].get_or_insert_with(Saved::default);
        saved.time = self.time;
        saved.x.clone_from(&self.x);
        saved.nominals.clone_from(&self.nominals);
        saved.z.clone_from(&self.z);
        saved.next_event = self.next_event;
        saved.event_time = self.event_time;
        saved.event_iterations = self.event_iterations;
        saved.events = self.events;
        saved.last_event = self.last_event;
        saved.completed_calls = self.completed_calls;
        saved.fmu_state = self.fmu_states;
        Ok(())
    }
    /// Back to a saved state. Without the FMU's state this is exact only
    /// while the FMU's discrete part has not moved: no event since the save
    /// and no `CompletedIntegratorStep` (the FMU declares it not needed);
    /// otherwise one error naming the time and what happened.
    fn restore(&mut self, slot: Slot) -> Result<()> {
        let Some(saved) = self.saved.get(slot).and_then(Option::as_ref) else {
            return Err(Error::InvalidArgument {
                function: "restore",
                instance: self.inner.name().to_owned(),
                message: format!("no FMU state saved in slot {slot}"),
            });
        };
        if saved.fmu_state {
            self.inner.restore(slot)?;
        } else {
            let why = if self.events != saved.events {
                Some(format!(
                    "an event at t = {} changed its discrete state",
                    self.last_event.unwrap_or(self.time)
                ))
            } else if self.completed_calls != saved.completed_calls {
                Some(
                    "it was told of completed integrator steps (it needs CompletedIntegratorStep)"
                        .into(),
                )
            } else {
                None
            };
            if let Some(why) = why {
                return Err(Error::ModelExchange {
                    instance: self.inner.name().to_owned(),
                    time: self.time,
                    cause: format!(
                        "cannot go back to t = {}: {why}, and its ModelExchange declares no \
                         canGetAndSetFMUstate to restore it",
                        saved.time
                    ),
                });
            }
            // The continuous part is the instance's: set it back.
            self.inner.set_time(saved.time)?;
            if !saved.x.is_empty() {
                self.inner.set_continuous_states(&saved.x)?;
            }
        }
        self.time = saved.time;
        self.x.clone_from(&saved.x);
        self.nominals.clone_from(&saved.nominals);
        self.z.clone_from(&saved.z);
        self.next_event = saved.next_event;
        self.event_time = saved.event_time;
        self.event_iterations = saved.event_iterations;
        self.events = saved.events;
        self.last_event = saved.last_event;
        self.completed_calls = saved.completed_calls;
        Ok(())
    }
    fn free(&mut self, slot: Slot) -> Result<()> {
        let had_fmu_state = self
            .saved
            .get_mut(slot)
            .and_then(Option::take)
            .is_some_and(|s| s.fmu_state);
        if had_fmu_state {
            self.inner.free(slot)?;
        }
        Ok(())
    }
    /// The saved state in `slot` as bytes: the instance's part, then the
    /// FMU's serialized state (needs `canSerializeFMUstate`).
    fn serialize(&mut self, slot: Slot, out: &mut Vec<u8>) -> Result<()> {
        let Some(saved) = self.saved.get(slot).and_then(Option::as_ref) else {
            return Err(Error::InvalidArgument {
                function: "serialize",
                instance: self.inner.name().to_owned(),
                message: format!("no state saved in slot {slot}"),
            });
        };
        if !(self.serializable && saved.fmu_state) {
            return Err(self.unsupported_state("serialize"));
        }
        out.clear();
        state::write(saved, out);
        let mut fmu = Vec::new();
        self.inner.serialize(slot, &mut fmu)?;
        out.extend_from_slice(&(fmu.len() as u64).to_le_bytes());
        out.extend_from_slice(&fmu);
        Ok(())
    }
    /// A state of [`serialize`](FmuInstance::serialize) into `slot`; bytes
    /// of another shape are refused in one line.
    fn deserialize(&mut self, slot: Slot, bytes: &[u8]) -> Result<()> {
        if !self.serializable {
            return Err(self.unsupported_state("deserialize"));
        }
        let nx = self.x.len();
        let nz = self.z.len();
        let Some((mut saved, rest)) = state::read(bytes, nx, nz) else {
            return Err(Error::InvalidArgument {
                function: "deserialize",
                instance: self.inner.name().to_owned(),
                message: format!(
                    "the bytes are no saved state of a model-exchange instance with {nx} \
                     continuous states and {nz} event indicators"
                ),
            });
        };
        self.inner.deserialize(slot, rest)?;
        saved.fmu_state = true;
        saved.completed_calls = self.completed_calls;
        self.saved[slot] = Some(saved);
        Ok(())
    }
    fn reset(&mut self) -> Result<()> {
        self.inner.reset()?;
        self.initialized = false;
        self.next_event = None;
        self.event_time = f64::NAN;
        self.event_iterations = 0;
        self.events = 0;
        self.last_event = None;
        Ok(())
    }
    fn terminate(&mut self) -> Result<()> {
        self.inner.terminate()
    }
}
