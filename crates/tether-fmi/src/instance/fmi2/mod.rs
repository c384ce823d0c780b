//! [`Instance`]: the safe co-simulation API of one FMU instance.

use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use crate::component::fmi2::InstantiateArgs;
use crate::component::fmi2::{RawComponent, RawState};
use crate::error::{Error, Result};
use crate::fmu::{debug_logging, Fmu, InstanceOptions};
use crate::model_description::{ModelDescription, ScalarVariable, ValueReference};
use crate::raw::{self, Status};
use crate::shared::{FmuShared, OnceGuard};

mod local;
mod state;

pub use local::LocalInstance;
pub use state::FmuState;

/// What an instance shares with its [`FmuState`](crate::FmuState)s.
///
/// The instance owns its component outright, so its calls take no lock (`&mut self`
/// serialises them). A state dropped while the instance lives cannot call the FMU
/// itself (the instance may be mid-call on another thread): it leaves its handle in
/// `orphans` and raises `pending`, and the instance frees it with `fmi2FreeFMUstate`
/// before its next call other than a Real value access (`fmi2GetReal`,
/// `fmi2SetReal`, `fmi2SetRealInputDerivatives`: the calls a macro step makes
/// most, between steps and state calls, skip the check). When the `Instance`
/// value goes while states remain, the component moves into `orphans`; the last
/// state frees itself and then the component (`fmi2FreeInstance`).
#[derive(Debug, Default)]
pub(crate) struct Shared {
    pending: AtomicBool,
    orphans: Mutex<Orphans>,
}

#[derive(Debug, Default)]
pub(crate) struct Orphans {
    /// States dropped while the instance lives, to free before its next call.
    dropped: Vec<RawState>,
    /// The component, once the `Instance` value is gone and states remain.
    component: Option<RawComponent>,
    /// Live `FmuState` values of this instance.
    states: usize,
}

impl Shared {
    /// The orphans; a poisoned lock is still usable (no FMI call panics midway).
    fn orphans(&self) -> MutexGuard<'_, Orphans> {
        self.orphans.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Counts a new `FmuState`.
    pub(crate) fn adopt_state(&self) {
        self.orphans().states += 1;
    }

    /// A state of this instance is dropped: freed now if the instance is gone,
    /// otherwise left for the instance to free before its next call.
    pub(crate) fn drop_state(&self, state: &mut RawState) {
        let mut orphans = self.orphans();
        orphans.states -= 1;
        let last = orphans.states == 0;
        match orphans.component.as_mut() {
            Some(component) => {
                free_state(component, state);
                if last {
                    // fmi2FreeInstance after the last state.
                    let component = orphans.component.take();
                    drop(orphans);
                    drop(component);
                }
            }
            None => {
                orphans.dropped.push(state.take());
                self.pending.store(true, Ordering::Release);
            }
        }
    }
}

/// `fmi2FreeFMUstate`, skipped after `fmi2Fatal` (no further call is allowed).
fn free_state(component: &mut RawComponent, state: &mut RawState) {
    if component.is_fatal() {
        return;
    }
    if let Err(e) = component.fmi2FreeFMUstate(state) {
        log::warn!(target: "tether_fmi::call", "{e}");
    }
}

/// Frees the states dropped since the last call.
#[cold]
fn free_dropped(component: &mut RawComponent, shared: &Shared) {
    let mut orphans = shared.orphans();
    for mut state in orphans.dropped.drain(..) {
        free_state(component, &mut state);
    }
    shared.pending.store(false, Ordering::Release);
}

/// Which status `fmi2Get*Status` reports (`fmi2StatusKind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum StatusKind {
    /// `fmi2DoStepStatus`.
    DoStepStatus,
    /// `fmi2PendingStatus`.
    PendingStatus,
    /// `fmi2LastSuccessfulTime`.
    LastSuccessfulTime,
    /// `fmi2Terminated`.
    Terminated,
}

impl StatusKind {
    fn raw(self) -> raw::fmi2StatusKind {
        match self {
            StatusKind::DoStepStatus => raw::fmi2DoStepStatus,
            StatusKind::PendingStatus => raw::fmi2PendingStatus,
            StatusKind::LastSuccessfulTime => raw::fmi2LastSuccessfulTime,
            StatusKind::Terminated => raw::fmi2Terminated,
        }
    }
}

/// One co-simulation instance of an FMU.
///
/// `Instance` is `Send`: it can be moved to a worker thread (calls on one instance are
/// serialised). It keeps the FMU's files and library alive, so it may outlive the
/// [`Fmu`](crate::Fmu) it came from. Errors name the function, the instance and its
/// current communication time, which the instance tracks from `setup_experiment` and
/// `do_step`.
#[derive(Debug)]
pub struct Instance {
    /// Taken out only by `Drop` (to free it now or hand it to the last state).
    raw: ManuallyDrop<RawComponent>,
    pub(crate) shared: Arc<Shared>,
    pub(crate) fmu: Arc<FmuShared>,
    name: Arc<str>,
    /// Made for model exchange: the `ModelExchange` flags say what it can do.
    pub(crate) model_exchange: bool,
}

impl Fmu {
    /// Creates a co-simulation instance (`fmi2Instantiate` with the model description's
    /// GUID). The instance is in the *instantiated* state; call
    /// [`Instance::setup_experiment`] and the initialization-mode functions next.
    ///
    /// A model that declares `canBeInstantiatedOnlyOncePerProcess="true"` gets at most one
    /// live instance per process, counted by GUID over every opened copy of it
    /// ([`Error::OnlyOncePerProcess`] otherwise).
    pub fn instantiate(&self, instance_name: &str, options: InstanceOptions) -> Result<Instance> {
        self.instantiate_as(instance_name, options, false)
    }

    /// Creates a model-exchange instance of an FMI 2.0 FMU (`fmi2Instantiate` with
    /// `fmi2ModelExchange`), for [`MeInstance`](crate::MeInstance), which drives it.
    pub(crate) fn instantiate_model_exchange(
        &self,
        instance_name: &str,
        options: InstanceOptions,
    ) -> Result<Instance> {
        self.instantiate_as(instance_name, options, true)
    }

    fn instantiate_as(
        &self,
        instance_name: &str,
        options: InstanceOptions,
        model_exchange: bool,
    ) -> Result<Instance> {
        let md = &self.shared().model_description;
        if md.standard != crate::model_description::FmiStandard::Fmi2 {
            return Err(Error::InvalidArgument {
                function: "fmi2Instantiate",
                instance: instance_name.to_owned(),
                message: format!(
                    "model '{}' is an FMI {} FMU: instantiate it with tether_fmi::instantiate",
                    md.model_name, md.fmi_version
                ),
            });
        }
        let once_per_process = if model_exchange {
            let Some(me) = &md.model_exchange else {
                return Err(Error::Unsupported {
                    model: md.model_name.clone(),
                    reason: "it has no model-exchange interface (no <ModelExchange> element)"
                        .into(),
                });
            };
            self.shared().library()?.me()?;
            me.can_be_instantiated_only_once_per_process
        } else {
            self.require_co_simulation()?;
            md.cs().can_be_instantiated_only_once_per_process
        };
        let once = if once_per_process {
            Some(OnceGuard::acquire(&md.guid, &md.model_name, instance_name)?)
        } else {
            None
        };
        let debug = debug_logging();
        let mut raw = RawComponent::fmi2Instantiate(
            self.shared().library()?,
            Arc::clone(&self.shared().dir),
            &InstantiateArgs {
                model: &md.model_name,
                instance_name,
                guid: &md.guid,
                resource_location: &self.resource_location(),
                visible: options.visible,
                logging_on: options.logging_on || debug.is_some(),
                model_exchange,
            },
        )?;
        raw.once = once;
        let mut instance = Instance::new(raw, Arc::clone(self.shared()));
        instance.model_exchange = model_exchange;
        if let Some(wanted) = debug.filter(|c| !c.is_empty()) {
            let declared = &md.log_categories;
            let mut categories = Vec::new();
            for category in &wanted {
                if declared.is_empty() || declared.iter().any(|c| c.name == *category) {
                    categories.push(category.as_str());
                } else {
                    let names: Vec<&str> = declared.iter().map(|c| c.name.as_str()).collect();
                    log::warn!(
                        "model '{}' declares no log category '{category}' (it declares: {}); \
                         not asked of instance '{instance_name}'",
                        md.model_name,
                        names.join(", ")
                    );
                }
            }
            if !categories.is_empty() {
                instance.set_debug_logging(true, &categories)?;
            }
        }
        Ok(instance)
    }
}

impl Instance {
    pub(crate) fn new(raw: RawComponent, fmu: Arc<FmuShared>) -> Instance {
        let name = Arc::from(raw.name());
        Instance {
            raw: ManuallyDrop::new(raw),
            shared: Arc::default(),
            fmu,
            name,
            model_exchange: false,
        }
    }

    /// The component, for one FMI call: the states dropped since the last call are
    /// freed first.
    #[inline]
    pub(crate) fn raw(&mut self) -> &mut RawComponent {
        if self.shared.pending.load(Ordering::Acquire) {
            free_dropped(&mut self.raw, &self.shared);
        }
        &mut self.raw
    }

    /// The component for Real value accesses and `fmi2SetFMUstate`, without
    /// freeing dropped states: `fmi2DoStep` and every other call do.
    #[inline(always)]
    pub(crate) fn live(&mut self) -> &mut RawComponent {
        &mut self.raw
    }

    fn raw_ref(&self) -> &RawComponent {
        &self.raw
    }

    /// The instance name given to `fmi2Instantiate`.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The model description of the FMU this instance belongs to.
    pub fn model_description(&self) -> &ModelDescription {
        &self.fmu.model_description
    }

    /// The variable called `name` ([`Error::UnknownVariable`] with suggestions otherwise).
    pub fn variable(&self, name: &str) -> Result<&ScalarVariable> {
        self.fmu.model_description.variable(name)
    }

    /// The value reference of the variable called `name`.
    pub fn value_reference(&self, name: &str) -> Result<ValueReference> {
        self.fmu.model_description.value_reference(name)
    }

    /// The current communication time as tracked by this instance.
    pub fn time(&self) -> f64 {
        self.raw_ref().time
    }

    /// Whether this FMU returned `fmi2Fatal` (every further call is refused).
    pub fn is_fatal(&self) -> bool {
        self.raw_ref().is_fatal()
    }

    pub(crate) fn require(
        &self,
        flag: bool,
        capability: &'static str,
        operation: &'static str,
    ) -> Result<()> {
        if flag {
            Ok(())
        } else {
            Err(Error::MissingCapability {
                model: self.fmu.model_description.model_name.clone(),
                capability,
                operation,
            })
        }
    }

    /// `fmi2SetDebugLogging`.
    pub fn set_debug_logging(&mut self, logging_on: bool, categories: &[&str]) -> Result<()> {
        self.raw().fmi2SetDebugLogging(logging_on, categories)
    }

    /// `fmi2SetupExperiment`; the tracked time becomes `start`.
    pub fn setup_experiment(
        &mut self,
        tolerance: Option<f64>,
        start: f64,
        stop: Option<f64>,
    ) -> Result<()> {
        let raw = self.raw();
        raw.fmi2SetupExperiment(tolerance, start, stop)?;
        raw.time = start;
        Ok(())
    }

    /// `fmi2EnterInitializationMode`.
    pub fn enter_initialization_mode(&mut self) -> Result<()> {
        self.raw().fmi2EnterInitializationMode()
    }

    /// `fmi2ExitInitializationMode`.
    pub fn exit_initialization_mode(&mut self) -> Result<()> {
        self.raw().fmi2ExitInitializationMode()
    }

    /// `fmi2GetReal` into `out` (same length as `vrs`; no allocation).
    #[inline]
    pub fn get_real(&mut self, vrs: &[ValueReference], out: &mut [f64]) -> Result<()> {
        self.live().fmi2GetReal(vrs, out)
    }

    /// `fmi2GetInteger` into `out`.
    pub fn get_integer(&mut self, vrs: &[ValueReference], out: &mut [i32]) -> Result<()> {
        self.raw().fmi2GetInteger(vrs, out)
    }

    /// `fmi2GetBoolean` into `out`.
    pub fn get_boolean(&mut self, vrs: &[ValueReference], out: &mut [bool]) -> Result<()> {
        self.raw().fmi2GetBoolean(vrs, out)
    }

    /// `fmi2GetString` into `out` (the strings' buffers are reused).
    pub fn get_string(&mut self, vrs: &[ValueReference], out: &mut [String]) -> Result<()> {
        self.raw().fmi2GetString(vrs, out)
    }

    /// `fmi2SetReal`.
    #[inline]
    pub fn set_real(&mut self, vrs: &[ValueReference], values: &[f64]) -> Result<()> {
        self.live().fmi2SetReal(vrs, values)
    }

    /// `fmi2SetInteger`.
    pub fn set_integer(&mut self, vrs: &[ValueReference], values: &[i32]) -> Result<()> {
        self.raw().fmi2SetInteger(vrs, values)
    }

    /// `fmi2SetBoolean`.
    pub fn set_boolean(&mut self, vrs: &[ValueReference], values: &[bool]) -> Result<()> {
        self.raw().fmi2SetBoolean(vrs, values)
    }

    /// `fmi2SetString`.
    pub fn set_string(&mut self, vrs: &[ValueReference], values: &[&str]) -> Result<()> {
        self.raw().fmi2SetString(vrs, values)
    }

    /// `fmi2SetRealInputDerivatives`: `values[i]` is the `orders[i]`-th time derivative
    /// of input `vrs[i]` at the current communication point. Needs
    /// `canInterpolateInputs`.
    #[inline(always)]
    pub fn set_real_input_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        values: &[f64],
    ) -> Result<()> {
        self.require(
            self.fmu.model_description.cs().can_interpolate_inputs,
            "canInterpolateInputs",
            "fmi2SetRealInputDerivatives",
        )?;
        self.live().fmi2SetRealInputDerivatives(vrs, orders, values)
    }

    /// `fmi2GetRealOutputDerivatives` into `out`.
    pub fn get_real_output_derivatives(
        &mut self,
        vrs: &[ValueReference],
        orders: &[i32],
        out: &mut [f64],
    ) -> Result<()> {
        self.raw().fmi2GetRealOutputDerivatives(vrs, orders, out)
    }

    /// `fmi2GetDirectionalDerivative`: `dv_unknown = J · dv_known`. Needs
    /// `providesDirectionalDerivative`.
    pub fn get_directional_derivative(
        &mut self,
        unknowns: &[ValueReference],
        knowns: &[ValueReference],
        dv_known: &[f64],
        dv_unknown: &mut [f64],
    ) -> Result<()> {
        self.require(
            self.fmu
                .model_description
                .cs()
                .provides_directional_derivative,
            "providesDirectionalDerivative",
            "fmi2GetDirectionalDerivative",
        )?;
        self.raw()
            .fmi2GetDirectionalDerivative(unknowns, knowns, dv_known, dv_unknown)
    }

    /// `fmi2DoStep` from `current_communication_point` over `step`. On success the tracked
    /// time becomes `current_communication_point + step`.
    #[inline]
    pub fn do_step(
        &mut self,
        current_communication_point: f64,
        step: f64,
        no_set_fmu_state_prior: bool,
    ) -> Result<()> {
        let raw = self.raw();
        raw.time = current_communication_point;
        raw.fmi2DoStep(current_communication_point, step, no_set_fmu_state_prior)?;
        raw.time = current_communication_point + step;
        Ok(())
    }

    /// `fmi2CancelStep`.
    pub fn cancel_step(&mut self) -> Result<()> {
        self.raw().fmi2CancelStep()
    }

    /// `fmi2Terminate`.
    pub fn terminate(&mut self) -> Result<()> {
        self.raw().fmi2Terminate()
    }

    /// `fmi2Reset`: back to the instantiated state.
    pub fn reset(&mut self) -> Result<()> {
        self.raw().fmi2Reset()
    }

    /// `fmi2GetStatus`.
    pub fn get_status(&mut self, kind: StatusKind) -> Result<Status> {
        self.raw().fmi2GetStatus(kind.raw())
    }

    /// `fmi2GetRealStatus`.
    pub fn get_real_status(&mut self, kind: StatusKind) -> Result<f64> {
        self.raw().fmi2GetRealStatus(kind.raw())
    }

    /// `fmi2GetIntegerStatus`.
    pub fn get_integer_status(&mut self, kind: StatusKind) -> Result<i32> {
        self.raw().fmi2GetIntegerStatus(kind.raw())
    }

    /// `fmi2GetBooleanStatus`.
    pub fn get_boolean_status(&mut self, kind: StatusKind) -> Result<bool> {
        self.raw().fmi2GetBooleanStatus(kind.raw())
    }

    /// `fmi2GetStringStatus`.
    pub fn get_string_status(&mut self, kind: StatusKind) -> Result<String> {
        self.raw().fmi2GetStringStatus(kind.raw())
    }

    /// `fmi2GetStatus(fmi2DoStepStatus)`.
    pub fn do_step_status(&mut self) -> Result<Status> {
        self.get_status(StatusKind::DoStepStatus)
    }

    /// `fmi2GetRealStatus(fmi2LastSuccessfulTime)`.
    pub fn last_successful_time(&mut self) -> Result<f64> {
        self.get_real_status(StatusKind::LastSuccessfulTime)
    }

    /// `fmi2GetBooleanStatus(fmi2Terminated)`.
    pub fn terminated(&mut self) -> Result<bool> {
        self.get_boolean_status(StatusKind::Terminated)
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        // SAFETY: `drop` runs once, and nothing reads `self.raw` after this line.
        let mut raw = unsafe { ManuallyDrop::take(&mut self.raw) };
        let mut orphans = self.shared.orphans();
        for mut state in orphans.dropped.drain(..) {
            free_state(&mut raw, &mut state);
        }
        if orphans.states > 0 {
            // The last state frees the component.
            orphans.component = Some(raw);
        } else {
            drop(orphans);
            drop(raw);
        }
    }
}

/// Compile-time proof that instances and states can cross threads.
const _: () = {
    const fn assert_send<T: Send>() {}
    assert_send::<Instance>();
    assert_send::<crate::FmuState>();
    assert_send::<crate::Fmu>();
};

impl crate::error::StepStatus for Instance {
    fn name(&self) -> &str {
        Instance::name(self)
    }
    fn terminated(&mut self) -> Result<bool> {
        Instance::terminated(self)
    }
    fn last_successful_time(&mut self) -> Result<f64> {
        Instance::last_successful_time(self)
    }
}
