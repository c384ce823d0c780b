//! One FMU instance: the safe core behind the C functions. Every FMI call goes through
//! [`Instance::call`], which checks the state-machine table, runs the call and turns a
//! [`Failure`] into a logged status.

use crate::declaration::{Parameters, Slot};
use crate::input::{eval_all, InputJet};
use crate::integrate;
use crate::machine::{Call, MachineState};
use crate::model::{Model, ParameterReset, Restore};
use crate::snapshot::{Shape, Snapshot};
use crate::xml::LOG_CATEGORIES;

/// fmi2Status.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(i32)]
pub enum Status {
    Ok = 0,
    Warning = 1,
    Discard = 2,
    Error = 3,
    Fatal = 4,
}

/// Why a call did not succeed.
#[derive(Clone, Debug, PartialEq)]
pub struct Failure {
    pub status: Status,
    pub message: String,
    /// The model or its integration failed: the instance enters the Error state.
    /// Usage errors (wrong state, bad arguments) leave the state unchanged, since the
    /// call had no effect.
    pub enters_error_state: bool,
}

impl Failure {
    pub fn usage(message: impl Into<String>) -> Self {
        Failure {
            status: Status::Error,
            message: message.into(),
            enters_error_state: false,
        }
    }
    pub fn model(message: impl Into<String>) -> Self {
        Failure {
            status: Status::Error,
            message: message.into(),
            enters_error_state: true,
        }
    }
    pub fn discard(message: impl Into<String>) -> Self {
        Failure {
            status: Status::Discard,
            message: message.into(),
            enters_error_state: false,
        }
    }
}

pub type Outcome<T = ()> = Result<T, Failure>;

/// Receives (status, category, message) for the fmi2CallbackLogger.
pub type LogFn = Box<dyn Fn(Status, &str, &str)>;

/// Relative tolerance of the communication-point check: |t_c − t| ≤ 1e-9·max(|t|, h).
pub const TIME_TOLERANCE: f64 = 1e-9;

pub struct Instance<M: Model> {
    pub name: String,
    logger: Option<LogFn>,
    logging_on: bool,
    categories: [bool; LOG_CATEGORIES.len()],
    pub(crate) slots: Vec<Slot>,
    fingerprint: u64,
    pub data: Snapshot,
    pub(crate) model: Option<M>,
    /// Buffers for the inputs, outputs and state derivatives evaluated by
    /// `fmi2GetReal`, reused so that the steady-state calls of a co-simulation
    /// (get/set Real, input derivatives, doStep, get/set FMU state) allocate
    /// nothing.
    pub(crate) scratch: Scratch,
    /// The model asked to end the simulation ([`Model::terminate`]): answered by
    /// `fmi2GetBooleanStatus(fmi2Terminated)`. Not part of the FMU state: the
    /// request is final.
    pub terminated: bool,
    /// Made by `fmi3InstantiateCoSimulation`: log messages name the fmi3 functions,
    /// and `time` is a variable (value reference after the declared ones).
    pub fmi3: bool,
    /// Made for model exchange (`fmi2Instantiate` with fmi2ModelExchange,
    /// `fmi3InstantiateModelExchange`): the importer sets time and states
    /// ([`crate::me`]); `fmi2DoStep` is refused.
    pub me: bool,
    /// FMI 3.0 intermediate update mode (during the importer's callback): which
    /// of [`samples`](Self::samples) takes the input values set there.
    pub(crate) intermediate: Option<usize>,
    /// FMI 3.0: the inputs set at the step's two intermediate times `t_c + s`,
    /// `(s, values by input)` (`ffi::fmi3::do_step`); their buffers are reused.
    pub(crate) samples: [(f64, Vec<Option<f64>>); 2],
}

/// Per-instance work buffers (see [`Instance::scratch`]), borrowed next to the
/// model and the data (or taken out with `std::mem::take` and put back).
#[derive(Default)]
pub(crate) struct Scratch {
    pub u: Vec<f64>,
    pub y: Vec<f64>,
    pub dx: Vec<f64>,
}

impl<M: Model> Instance<M> {
    pub fn new(name: &str, logger: Option<LogFn>, logging_on: bool) -> Self {
        let d = &M::DECLARATION;
        Instance {
            name: name.to_string(),
            logger,
            logging_on,
            categories: [true; LOG_CATEGORIES.len()],
            slots: d.slots(),
            fingerprint: fingerprint::<M>(),
            data: initial_snapshot::<M>(),
            model: None,
            scratch: Scratch::default(),
            terminated: false,
            fmi3: false,
            me: false,
            intermediate: None,
            samples: Default::default(),
        }
    }

    /// The same instance as seen through the FMI 3.0 layer: log messages name the
    /// fmi3 functions and the independent variable `time` gets the value reference
    /// after the declared variables.
    pub fn fmi3(mut self) -> Self {
        self.fmi3 = true;
        self.slots.push(Slot::Time);
        self
    }

    pub fn shape() -> Shape {
        let d = &M::DECLARATION;
        Shape {
            reals: d.real_parameters.len() + 1,
            integers: d.integer_parameters.len(),
            booleans: d.boolean_parameters.len(),
            inputs: d.inputs.len(),
            states: d.states.len(),
        }
    }

    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    /// Runs one FMI call: state-table check, the call, failure logging and the
    /// resulting state transition.
    #[inline(always)]
    pub fn call(&mut self, call: Call, f: impl FnOnce(&mut Self) -> Outcome) -> Status {
        let state = self.data.machine;
        let result = if call.allowed_in(state) {
            f(self)
        } else {
            Err(not_allowed(state))
        };
        match result {
            Ok(()) => Status::Ok,
            Err(failure) => self.fail(call, failure),
        }
    }

    /// Logs a failure of `call` and applies its state transition; returns its status.
    #[cold]
    #[inline(never)]
    pub fn fail(&mut self, call: Call, failure: Failure) -> Status {
        if failure.status == Status::Fatal {
            self.data.machine = MachineState::Fatal;
        } else if failure.enters_error_state {
            self.data.machine = MachineState::Error;
        }
        self.log(
            failure.status,
            &format!("{}: {}", self.call_name(call), failure.message),
        );
        failure.status
    }

    /// The name of `call` in the FMI version of this instance.
    pub fn call_name(&self, call: Call) -> &'static str {
        if self.fmi3 {
            call.fmi3_name()
        } else {
            call.name()
        }
    }

    /// Sends a message to the environment's logger. Errors and fatal errors are always
    /// sent; other messages only with logging on and their category enabled.
    pub fn log(&self, status: Status, message: &str) {
        if let (true, Some(logger)) = (self.logs(status), &self.logger) {
            logger(status, LOG_CATEGORIES[Self::category(status)].0, message);
        }
    }

    fn category(status: Status) -> usize {
        match status {
            Status::Ok => 0,
            Status::Warning => 1,
            Status::Discard => 2,
            Status::Error => 3,
            Status::Fatal => 4,
        }
    }

    /// Whether a message of this status would reach the logger (so that routine
    /// messages are only formatted when somebody reads them).
    fn logs(&self, status: Status) -> bool {
        let all = LOG_CATEGORIES.len() - 1;
        self.logger.is_some()
            && (status as i32 >= Status::Error as i32
                || (self.logging_on
                    && (self.categories[Self::category(status)] || self.categories[all])))
    }

    /// Logs a routine event; `message` is only called when the event is logged.
    pub(crate) fn log_event(&self, message: impl FnOnce() -> String) {
        if self.logs(Status::Ok) {
            self.log(Status::Ok, &message());
        }
    }

    pub fn set_debug_logging(&mut self, on: bool, categories: &[&str]) -> Outcome {
        let mut enabled = [categories.is_empty(); LOG_CATEGORIES.len()];
        for name in categories {
            let i = LOG_CATEGORIES.iter().position(|(c, _)| c == name);
            let i = i.ok_or_else(|| Failure::usage(format!("unknown log category {name:?}")))?;
            enabled[i] = true;
        }
        self.logging_on = on;
        self.categories = enabled;
        Ok(())
    }

    pub fn setup_experiment(
        &mut self,
        tolerance: Option<f64>,
        start: f64,
        stop: Option<f64>,
    ) -> Outcome {
        if !start.is_finite() || stop.is_some_and(|s| s.is_nan() || s < start) {
            return Err(Failure::usage(format!(
                "invalid experiment: start {start}, stop {stop:?}"
            )));
        }
        if !self.fmi3 && self.parameter_reset() == ParameterReset::AtSetupExperiment {
            self.reset_parameters();
        }
        if let Some(tol) = tolerance {
            if !(tol > 0.0 && tol.is_finite()) {
                return Err(Failure::usage(format!("tolerance must be > 0, got {tol}")));
            }
            *self.tolerance_mut() = tol;
            self.model = None;
        }
        self.data.start_time = start;
        self.data.time = start;
        self.data.stop_time = stop;
        Ok(())
    }

    /// When the model resets its parameters ([`Model::parameter_reset`]),
    /// as the parameters are now.
    fn parameter_reset(&self) -> ParameterReset {
        let d = &self.data;
        M::parameter_reset(&Parameters::new(
            &M::DECLARATION,
            &d.reals,
            &d.integers,
            &d.booleans,
        ))
    }

    /// Every parameter back to its declared start value (the tolerance too).
    fn reset_parameters(&mut self) {
        let start = initial_snapshot::<M>();
        self.data.reals = start.reals;
        self.data.integers = start.integers;
        self.data.booleans = start.booleans;
        self.model = None;
    }

    fn tolerance_mut(&mut self) -> &mut f64 {
        let i = self.data.reals.len() - 1;
        &mut self.data.reals[i]
    }

    pub fn enter_initialization_mode(&mut self) -> Outcome {
        self.data.machine = MachineState::InitializationMode;
        self.model = None;
        Ok(())
    }

    pub fn exit_initialization_mode(&mut self) -> Outcome {
        if self.parameter_reset() == ParameterReset::AtExitInitialization {
            self.reset_parameters();
        }
        self.ensure_model().map_err(|f| Failure::model(f.message))?;
        self.data.machine = MachineState::StepComplete;
        self.data.step_base = self.data.time;
        self.data.step_size = 0.0;
        self.data.step_count = 0;
        self.log_event(|| {
            format!(
                "initialized at t = {}, states {:?}",
                self.data.time, self.data.states
            )
        });
        Ok(())
    }

    pub fn terminate(&mut self) -> Outcome {
        self.data.machine = MachineState::Terminated;
        Ok(())
    }

    pub fn reset(&mut self) -> Outcome {
        self.data = initial_snapshot::<M>();
        self.model = None;
        self.terminated = false;
        Ok(())
    }

    /// Builds the model from the parameters if needed; before the end of
    /// initialization this also (re)computes the initial states.
    #[inline]
    pub(crate) fn ensure_model(&mut self) -> Outcome {
        if self.model.is_some() {
            return Ok(());
        }
        self.build_model()
    }

    #[inline(never)]
    fn build_model(&mut self) -> Outcome {
        let tolerance = self.data.reals[self.data.reals.len() - 1];
        if !(tolerance > 0.0 && tolerance.is_finite()) {
            return Err(Failure::usage(format!(
                "parameter tolerance must be > 0, got {tolerance}"
            )));
        }
        let d = &self.data;
        let parameters = Parameters::new(&M::DECLARATION, &d.reals, &d.integers, &d.booleans);
        let model =
            M::new(&parameters).map_err(|e| Failure::usage(format!("invalid parameters: {e}")))?;
        if matches!(
            self.data.machine,
            MachineState::Instantiated | MachineState::InitializationMode
        ) {
            model.initial_states(&mut self.data.states);
        }
        self.model = Some(model);
        Ok(())
    }

    /// Runs `f` with the model, the data and the current input values.
    pub(crate) fn with_model<T>(
        &mut self,
        f: impl FnOnce(&M, &Snapshot, &[f64]) -> T,
    ) -> Outcome<T> {
        self.ensure_model()?;
        let mut u = std::mem::take(&mut self.scratch.u);
        u.resize(self.data.inputs.len(), 0.0);
        eval_all(&self.data.inputs, 0.0, &mut u);
        let result = match &self.model {
            Some(model) => Ok(f(model, &self.data, &u)),
            None => Err(Failure::usage("model not built")),
        };
        self.scratch.u = u;
        result
    }

    /// FMI 3.0 intermediate update: the inputs as the importer set them at the
    /// intermediate times `t_c + s` of [`samples`](Self::samples) (the kit asks at
    /// s = h/2 and s = h, see `ffi::fmi3::do_step`) become, with the value at t_c,
    /// the quadratic through these points: the same Taylor polynomial around t_c as
    /// the FMI 2.0 build takes from `fmi2SetRealInputDerivatives`, to rounding. An
    /// input set in none of the callbacks keeps its polynomial; one not set at an
    /// intermediate time keeps the last value set, as the standard says.
    pub(crate) fn take_intermediate_inputs(&mut self) {
        let [(sa, at_a), (sb, at_b)] = &self.samples;
        for (i, jet) in self.data.inputs.iter_mut().enumerate() {
            let (a, b) = (
                at_a.get(i).copied().flatten(),
                at_b.get(i).copied().flatten(),
            );
            if a.is_none() && b.is_none() {
                continue;
            }
            let u0 = jet.value;
            let a = a.unwrap_or(u0);
            let b = b.unwrap_or(a);
            let fa = (a - u0) / sa;
            let fb = (b - u0) / sb;
            let d2 = 2.0 * (fb - fa) / (sb - sa);
            *jet = InputJet {
                value: u0,
                d1: fa - 0.5 * sa * d2,
                d2,
            };
        }
    }

    /// One communication step. The communication point must equal the FMU's time
    /// within [`TIME_TOLERANCE`]; the new time is `step_base + n·h` while h is
    /// unchanged (no accumulation of `t += h`), else `t_c + h` starts a new count.
    #[inline(always)]
    pub fn do_step(&mut self, t_c: f64, h: f64) -> Outcome {
        if self.me {
            return Err(Failure::usage("a model-exchange instance does not step"));
        }
        let t = self.data.time;
        if !(h > 0.0 && h.is_finite() && t_c.is_finite()) {
            return Err(Failure::usage(format!(
                "invalid step: currentCommunicationPoint {t_c}, communicationStepSize {h}"
            )));
        }
        let tol = TIME_TOLERANCE * t.abs().max(h);
        if (t_c - t).abs() > tol {
            return Err(Failure::usage(format!(
                "currentCommunicationPoint {t_c} differs from the FMU's time {t}"
            )));
        }
        if let Some(stop) = self.data.stop_time {
            if t_c + h > stop + tol {
                return Err(Failure::usage(format!(
                    "step to {} goes beyond the stop time {stop}",
                    t_c + h
                )));
            }
        }
        self.ensure_model()?;
        let Some(model) = &self.model else {
            return Err(Failure::usage("model not built"));
        };
        let tolerance = self.data.reals[self.data.reals.len() - 1];
        let how = integrate::step(
            model,
            t,
            h,
            &mut self.data.states,
            &self.data.inputs,
            tolerance,
        )
        .map_err(Failure::model)?;
        let d = &mut self.data;
        if h == d.step_size {
            d.step_count += 1;
        } else {
            d.step_base = t_c;
            d.step_size = h;
            d.step_count = 1;
        }
        let new_time = d.step_base + d.step_count as f64 * h;
        for jet in &mut d.inputs {
            *jet = jet.shifted(new_time - t);
        }
        d.time = new_time;
        self.log_event(|| format!("step {t} -> {new_time} ({how})"));
        if model.terminate(new_time, &self.data.states) {
            self.terminated = true;
            return Err(Failure::discard(format!(
                "the model requests the end of the simulation at t = {new_time}"
            )));
        }
        Ok(())
    }

    pub fn restore(&mut self, snapshot: &Snapshot) -> Outcome {
        if snapshot.shape() != Self::shape() {
            return Err(Failure::usage("FMU state does not fit this model"));
        }
        // The model is a function of the parameters only; it is kept (with whatever it
        // precomputed) unless the state brings other parameter values, or is from
        // before the end of initialization, where building the model also sets the
        // initial states.
        let how = self
            .model
            .as_ref()
            .map_or(Restore::Exact, |m| m.restore(self.data.time));
        let d = &self.data;
        let same_model = d.reals == snapshot.reals
            && d.integers == snapshot.integers
            && d.booleans == snapshot.booleans
            && !matches!(
                snapshot.machine,
                MachineState::Instantiated | MachineState::InitializationMode
            );
        if how == Restore::KeepStates {
            let states = std::mem::take(&mut self.data.states);
            self.data.clone_from(snapshot);
            self.data.states = states;
        } else {
            self.data.clone_from(snapshot);
        }
        if !same_model {
            self.model = None;
        }
        Ok(())
    }
}

#[cold]
#[inline(never)]
fn not_allowed(state: MachineState) -> Failure {
    Failure::usage(format!("not allowed in state {state:?}"))
}

/// The start values of every variable, in the Instantiated state.
fn initial_snapshot<M: Model>() -> Snapshot {
    let d = &M::DECLARATION;
    let start = d.default_experiment.start_time;
    Snapshot {
        machine: MachineState::Instantiated,
        time: start,
        start_time: start,
        stop_time: None,
        step_base: start,
        step_size: 0.0,
        step_count: 0,
        reals: d.all_real_parameters().iter().map(|p| p.start).collect(),
        integers: d.integer_parameters.iter().map(|p| p.start).collect(),
        booleans: d.boolean_parameters.iter().map(|p| p.start).collect(),
        inputs: d
            .inputs
            .iter()
            .map(|u| InputJet::constant(u.start))
            .collect(),
        states: vec![0.0; d.states.len()],
    }
}

/// Identifies the model in serialized states: FNV-1a of the GUID.
pub fn fingerprint<M: Model>() -> u64 {
    crate::xml::model_guid::<M>()
        .bytes()
        .fold(0xcbf2_9ce4_8422_2325, |h, b| {
            (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
        })
}
