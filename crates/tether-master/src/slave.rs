//! One FMU instance as the coupling algorithm sees it: coupled inputs driven by
//! polynomials, coupled outputs read after each run, a saved state to roll back
//! to, and the outputs recorded at accepted steps.

use tether_fmi::{BaseType, Causality, Fmu, FmuInstance, Inputs, Int, Placement, RunRequest, Slot};

use crate::spec::Isolation;

use crate::observer::integer_value;
use crate::polynomial::Taylor;
use crate::spec::{InstanceSpec, StartValue};
use crate::stats::InstanceCounters;
use crate::MasterError;

/// The state slot of the state saved at the start of the macro step.
const SAVED: Slot = 0;
/// The state slot of the rollback self-check's own state.
const CHECK: Slot = 1;
/// The state slot of the whole system's saved state (`Simulation::save_state`).
const SNAPSHOT: Slot = 2;

/// A coupled input: `value = Σ coefficient · u[unknown]`; an element of an
/// FMI 3.0 array input is `element` of its `count` values (the others keep
/// their start values: an array is set whole).
#[derive(Debug, Clone)]
pub(crate) struct CoupledInput {
    pub vr: u32,
    pub element: usize,
    pub count: usize,
    pub terms: Vec<(usize, f64)>,
}

/// An output value read after each run: the variable itself or one of its
/// derivatives (order 1 or 2) through `fmi2GetRealOutputDerivatives`; an
/// element of an FMI 3.0 array output is `element` of its `count` values (the
/// array is read once per run).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct CoupledOutput {
    pub vr: u32,
    pub order: u32,
    pub element: usize,
    pub count: usize,
}

impl CoupledOutput {
    /// A scalar output (or its derivative).
    pub(crate) fn scalar(vr: u32, order: u32) -> CoupledOutput {
        CoupledOutput {
            vr,
            order,
            element: 0,
            count: 1,
        }
    }
}

/// The slot of a value read that no coupled output uses (an element of an
/// array nobody couples).
const UNUSED: usize = usize::MAX;

/// Which call's results an instance's outputs are read after, for the message
/// naming a non-finite output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Run {
    /// Inputs set, no step: direct feedthrough (initial multipliers, the
    /// explicit method's update).
    Feedthrough,
    /// The predictor's `fmi2DoStep`.
    Predictor,
    /// A perturbed run's `fmi2DoStep`.
    Perturbed,
    /// The corrector's `fmi2DoStep` (the accepted point).
    Corrector,
    /// The explicit method's `fmi2DoStep` (the accepted point).
    Explicit,
    /// The `fmi2DoStep` after which a signal connection's sender is read.
    Signal,
    /// `fmi2GetFMUstate` / `fmi2SetFMUstate` (the rollback checks).
    Rollback,
    /// Initialization (the point T_0).
    Initial,
}

impl Run {
    /// The call, for messages: `after the predictor's fmi2DoStep`.
    pub(crate) fn describe(self) -> &'static str {
        match self {
            Run::Feedthrough => "after fmi2SetReal of the coupled inputs (direct feedthrough)",
            Run::Predictor => "after the predictor's fmi2DoStep",
            Run::Perturbed => "after a perturbed run's fmi2DoStep",
            Run::Corrector => "after the corrector's fmi2DoStep",
            Run::Explicit => "after fmi2DoStep",
            Run::Signal => "after fmi2DoStep (the sender of a signal connection)",
            Run::Rollback => "after fmi2GetFMUstate/fmi2SetFMUstate",
            Run::Initial => "after initialization",
        }
    }
}

/// An FMU instance inside a coupled system.
pub struct Slave {
    pub(crate) name: String,
    pub(crate) model_name: String,
    /// The FMU instance, in this process or in a host process: the master
    /// reaches it only through [`FmuInstance`].
    pub(crate) backend: Box<dyn FmuInstance>,
    pub(crate) fmu: Fmu,
    /// Whether [`SAVED`] holds a state.
    saved: bool,
    pub(crate) inputs: Vec<CoupledInput>,
    /// The coupled inputs' values and derivatives as the instance takes them.
    input: InputBuffers,
    /// The same for each run of a batch ([`Slave::runs`]).
    run_inputs: Vec<InputBuffers>,
    /// The outputs of a batch of runs, run after run.
    batch_buf: Vec<f64>,
    /// The allocations of a batch's plan and requests, kept between steps
    /// (emptied; see [`recycle`]).
    planned_buf: Vec<Planned<'static>>,
    request_buf: Vec<RunRequest<'static>>,
    /// The rollback check's four readings of the coupled outputs.
    check_buf: Vec<f64>,
    /// The degree k of the unknowns' polynomials (`finalize`).
    order: usize,
    pub(crate) coupled_outputs: Vec<CoupledOutput>,
    value_vrs: Vec<u32>,
    /// The number of values `value_vrs` reads, when arrays make it differ
    /// from their number.
    value_count: Option<usize>,
    /// `value_vrs`, then `recorded_vrs`: the read at an accepted point, one
    /// call when no output derivative is read (`finalize`).
    accepted_vrs: Vec<u32>,
    /// The number of values `accepted_vrs` reads, as `value_count`.
    accepted_count: Option<usize>,
    /// The start values' effect on the FMI 3.0 arrays: sizes, values.
    pub(crate) arrays: crate::start::Arrays,
    /// The place of each coupled input's value among the values set (the
    /// elements of an array input are set together).
    input_positions: Vec<usize>,
    /// Signal connections: an array output read whole (its values).
    pub(crate) signal_buf: Vec<f64>,
    /// The output derivatives read, `(variable, order)`.
    derivative_reads: Vec<(u32, i32)>,
    /// The slot in the coupled outputs of each value of `value_buf`.
    slots: Vec<usize>,
    /// A run's outputs as the instance returns them: the values
    /// (`value_vrs`), then the derivatives (`derivative_reads`).
    value_buf: Vec<f64>,
    pub(crate) recorded_names: Vec<String>,
    recorded_vrs: Vec<u32>,
    /// The number of values `recorded_vrs` reads (arrays: one per element).
    recorded_reals: usize,
    /// Integer and Enumeration outputs, recorded after the Real ones.
    recorded_ints: Vec<u32>,
    int_buf: Vec<Int>,
    /// Boolean outputs, recorded after the Integer ones (as 0 and 1).
    recorded_bools: Vec<u32>,
    bool_buf: Vec<bool>,
    /// Recorded outputs after the latest read.
    pub(crate) recorded_values: Vec<f64>,
    /// The integers among them that a float rounds, exactly (by index).
    recorded_exact: Vec<(usize, Int)>,
    pub(crate) counters: InstanceCounters,
    pub(crate) can_interpolate_inputs: bool,
    pub(crate) max_output_derivative_order: u32,
    pub(crate) can_get_and_set_state: bool,
    /// Stepped by the signal connections' Gauss–Seidel sweep before the
    /// method's step, which then only reads its outputs.
    pub(crate) stepped_ahead: bool,
    /// `check_rollback = "every_step"`: read the coupled outputs back after
    /// each restore and compare them with those at the save.
    pub(crate) verify_restore: bool,
    /// Coupled outputs at the last save (with `verify_restore`).
    at_save: Vec<f64>,
    /// Coupled outputs read back after a restore (with `verify_restore`).
    readback: Vec<f64>,
    /// Per coupled value (as `value_buf`), the magnitude beyond which it has
    /// diverged (crate::culprit); empty until set after initialization.
    pub(crate) limits: Vec<f64>,
    /// The first coupled value read beyond its limit in the latest step.
    pub(crate) beyond: Option<crate::culprit::Beyond>,
    /// Requests to an isolated instance's host made by the rollback checks,
    /// which the counts leave out as they leave out the checks' calls.
    check_trips: u64,
}

impl Slave {
    /// Instantiate the FMU of `spec` and apply the start values. Instances of
    /// the same `.fmu` file share one opened FMU in `opened` (one extraction,
    /// one loaded library), as the C floor of docs/performance.md does.
    /// `order` is the system's degree k: at k > 0 the inputs take polynomials
    /// (an FMI 3.0 instance gets the intermediate update callback), at k = 0
    /// values only.
    pub(crate) fn instantiate(
        spec: &InstanceSpec,
        opened: &mut Vec<(std::path::PathBuf, Fmu)>,
        order: usize,
    ) -> Result<Slave, MasterError> {
        let fmu = match opened.iter().find(|(path, _)| *path == spec.fmu) {
            Some((_, fmu)) => fmu.clone(),
            None => {
                // An isolated instance's library is loaded by its host only.
                let fmu = match spec.isolation {
                    Isolation::Process => Fmu::open_unloaded(&spec.fmu, &Default::default()),
                    Isolation::None => Fmu::open(&spec.fmu),
                }
                .map_err(|error| MasterError::InstanceFmu {
                    instance: spec.name.clone(),
                    error,
                })?;
                opened.push((spec.fmu.clone(), fmu.clone()));
                fmu
            }
        };
        Slave::instantiate_as(fmu, spec, &spec.name, order)
    }

    /// Another instance of this slave's FMU with the same start values and the
    /// same coupled inputs and outputs, initialised like the original (for
    /// perturbed runs on another thread; its state is later copied over).
    pub(crate) fn duplicate(
        &self,
        spec: &InstanceSpec,
        copy: usize,
        experiment: (f64, f64, Option<f64>),
    ) -> Result<Slave, MasterError> {
        let name = format!("{}#{copy}", spec.name);
        let mut extra = Slave::instantiate_as(self.fmu.clone(), spec, &name, self.order)?;
        extra.inputs = self.inputs.clone();
        extra.coupled_outputs = self.coupled_outputs.clone();
        extra.finalize(self.order);
        let (start, stop, tolerance) = experiment;
        extra.initialize(start, stop, tolerance)?;
        Ok(extra)
    }

    /// The capability adaptive macro steps need that the FMU does not
    /// declare: rollback of a rejected step, and steps of varying size.
    pub(crate) fn cannot_vary_steps(&self) -> Option<&'static str> {
        let cs = &self.fmu.model_description().co_simulation;
        if !cs.can_get_and_set_fmu_state {
            Some("canGetAndSetFMUstate")
        } else if !cs.can_handle_variable_communication_step_size {
            Some("canHandleVariableCommunicationStepSize")
        } else {
            None
        }
    }

    /// Whether perturbed runs may go to other instances of the FMU: its state
    /// can be serialised and it may be instantiated more than once.
    pub(crate) fn can_run_in_parallel(&self) -> bool {
        let cs = &self.fmu.model_description().co_simulation;
        cs.can_get_and_set_fmu_state
            && cs.can_serialize_fmu_state
            && !cs.can_be_instantiated_only_once_per_process
    }

    /// Serialise the state saved by [`save_state`](Self::save_state) into `out`
    /// (its capacity is reused).
    pub(crate) fn serialize_saved(&mut self, out: &mut Vec<u8>) -> Result<(), MasterError> {
        assert!(
            self.saved,
            "serialize_saved is only called after save_state"
        );
        self.backend.serialize(SAVED, out)?;
        Ok(())
    }

    /// Set the state from bytes of [`serialize_saved`](Self::serialize_saved)
    /// (of another instance of the same FMU) and keep it as the saved state.
    pub(crate) fn load_serialized(&mut self, bytes: &[u8]) -> Result<(), MasterError> {
        self.backend.deserialize(SAVED, bytes)?;
        self.saved = true;
        Ok(())
    }

    /// Save the current state as bytes into `out`, for the whole system's
    /// saved state (needs `canGetAndSetFMUstate` and `canSerializeFMUstate`).
    pub(crate) fn snapshot(&mut self, out: &mut Vec<u8>) -> Result<(), MasterError> {
        let cs = &self.fmu.model_description().co_simulation;
        let lacking = if !cs.can_get_and_set_fmu_state {
            Some("canGetAndSetFMUstate")
        } else if !cs.can_serialize_fmu_state {
            Some("canSerializeFMUstate")
        } else {
            None
        };
        if let Some(capability) = lacking {
            return Err(MasterError::MissingCapability {
                instance: self.name.clone(),
                model: self.model_name.clone(),
                capability,
                needed_by: "the system's saved state".into(),
            });
        }
        self.backend.save(SNAPSHOT)?;
        self.backend.serialize(SNAPSHOT, out)?;
        self.backend.free(SNAPSHOT)?;
        Ok(())
    }

    /// Back to a state of [`snapshot`](Self::snapshot), with the recorded
    /// outputs read then.
    pub(crate) fn load_snapshot(
        &mut self,
        bytes: &[u8],
        recorded: &[f64],
    ) -> Result<(), MasterError> {
        self.backend.deserialize(SNAPSHOT, bytes)?;
        self.backend.restore(SNAPSHOT)?;
        self.backend.free(SNAPSHOT)?;
        self.recorded_values.copy_from_slice(recorded);
        self.recorded_exact.clear();
        Ok(())
    }

    fn instantiate_as(
        fmu: Fmu,
        spec: &InstanceSpec,
        name: &str,
        order: usize,
    ) -> Result<Slave, MasterError> {
        let md = fmu.model_description();
        let cs = &md.co_simulation;
        // FMI 3.0: a polynomial input goes through intermediate update (for the
        // inputs declared `intermediateUpdate="true"`, `Slave::interpolates`).
        let can_interpolate_inputs = cs.can_interpolate_inputs || cs.provides_intermediate_update;
        let max_output_derivative_order = cs.max_output_derivative_order;
        let can_get_and_set_state = cs.can_get_and_set_fmu_state;
        let model_name = md.model_name.clone();
        let counters = InstanceCounters {
            name: name.to_string(),
            model: model_name.clone(),
            functions: crate::stats::CallNames::of(md, &[]),
            ..Default::default()
        };
        let timeout = spec.call_timeout.map(std::time::Duration::from_secs_f64);
        let placement = match (&spec.host, &spec.token_file, spec.isolation) {
            (Some(host), Some(token_file), _) => Placement::Remote {
                timeout,
                host: tether_fmi::remote::tcp::RemoteHost {
                    address: tether_fmi::remote::tcp::RemoteHost::parse_address(host).map_err(
                        |reason| tether_fmi::Error::HostStart {
                            instance: name.to_string(),
                            reason,
                        },
                    )?,
                    token_file: token_file.clone(),
                    fmu_on_host: spec.fmu_on_host.clone(),
                },
            },
            (_, _, Isolation::Process) => Placement::Process { timeout },
            (_, _, Isolation::None) => Placement::InProcess,
        };
        let options = tether_fmi::InstanceOptions::default().with_polynomial_inputs(order > 0);
        let backend = tether_fmi::instantiate(&fmu, name, options, placement)?;
        let mut slave = Slave {
            name: name.to_string(),
            model_name,
            backend,
            fmu,
            saved: false,
            inputs: Vec::new(),
            input: InputBuffers::default(),
            run_inputs: Vec::new(),
            batch_buf: Vec::new(),
            planned_buf: Vec::new(),
            request_buf: Vec::new(),
            check_buf: Vec::new(),
            order: 0,
            coupled_outputs: Vec::new(),
            value_vrs: Vec::new(),
            value_count: None,
            accepted_vrs: Vec::new(),
            accepted_count: None,
            arrays: Default::default(),
            input_positions: Vec::new(),
            signal_buf: Vec::new(),
            derivative_reads: Vec::new(),
            slots: Vec::new(),
            value_buf: Vec::new(),
            recorded_values: Vec::new(),
            recorded_exact: Vec::new(),
            recorded_names: Vec::new(),
            recorded_vrs: Vec::new(),
            recorded_reals: 0,
            int_buf: Vec::new(),
            recorded_ints: Vec::new(),
            bool_buf: Vec::new(),
            recorded_bools: Vec::new(),
            counters,
            can_interpolate_inputs,
            max_output_derivative_order,
            can_get_and_set_state,
            stepped_ahead: false,
            verify_restore: false,
            at_save: Vec::new(),
            readback: Vec::new(),
            limits: Vec::new(),
            beyond: None,
            check_trips: 0,
        };
        slave.arrays = crate::start::apply_start_values(
            slave.backend.as_mut(),
            slave.fmu.model_description(),
            spec.parameters.iter().map(|(n, v)| (n.as_str(), v)),
        )?;
        slave.record_columns(&spec.name)?;
        Ok(slave)
    }

    /// The recorded outputs and their columns: the Real outputs, then the
    /// Integer (and Enumeration) ones, then the Boolean ones, each in the
    /// order of the model description, an array one column per element
    /// (`inst.y[1]`).
    fn record_columns(&mut self, instance: &str) -> Result<(), MasterError> {
        let md = self.fmu.model_description();
        let (mut reals, mut ints, mut bools) = (0, 0, 0);
        for kind in [BaseType::Real, BaseType::Integer, BaseType::Boolean] {
            for v in &md.model_variables {
                let base = match v.base_type() {
                    BaseType::Enumeration => BaseType::Integer,
                    other => other,
                };
                if v.causality != Causality::Output || base != kind {
                    continue;
                }
                let names = self.arrays.element_names(md, v)?;
                let n = names.len();
                self.recorded_names
                    .extend(names.into_iter().map(|e| format!("{instance}.{e}")));
                match kind {
                    BaseType::Real => {
                        self.recorded_vrs.push(v.value_reference);
                        reals += n;
                    }
                    BaseType::Integer => {
                        self.recorded_ints.push(v.value_reference);
                        ints += n;
                    }
                    _ => {
                        self.recorded_bools.push(v.value_reference);
                        bools += n;
                    }
                }
            }
        }
        self.recorded_reals = reals;
        self.int_buf = vec![0; ints];
        self.bool_buf = vec![false; bools];
        self.recorded_values = vec![0.0; self.recorded_names.len()];
        Ok(())
    }

    /// Set element `e` of array input `vr` to `value` (a signal connection's
    /// receiver): the array is set whole, its other elements at their values
    /// as last set.
    pub(crate) fn set_array_element(
        &mut self,
        vr: u32,
        e: crate::spec::names::Element,
        value: StartValue,
    ) -> Result<(), MasterError> {
        let md = self.fmu.model_description();
        let Some(var) = md.variable_by_vr(vr) else {
            return Err(MasterError::StartValue {
                instance: self.name.clone(),
                variable: format!("#{vr}"),
                value: value.to_string(),
                reason: "no variable has this value reference".into(),
            });
        };
        // The reason names the element (`element 5 (row-major): …`).
        let fail = |reason: String| MasterError::StartValue {
            instance: self.name.clone(),
            variable: var.name.clone(),
            value: value.to_string(),
            reason,
        };
        self.arrays
            .set_element(self.backend.as_mut(), md, var, e.index, value.clone(), fail)
    }

    /// Register a coupled Real input (an array's `element`, if any) driven by
    /// unknowns.
    pub(crate) fn add_input(
        &mut self,
        vr: u32,
        element: Option<crate::spec::names::Element>,
        unknown: usize,
        coefficient: f64,
    ) {
        let (element, count) = element.map_or((0, 1), |e| (e.index, e.count));
        if let Some(i) = self
            .inputs
            .iter_mut()
            .find(|i| i.vr == vr && i.element == element)
        {
            i.terms.push((unknown, coefficient));
        } else {
            self.inputs.push(CoupledInput {
                vr,
                element,
                count,
                terms: vec![(unknown, coefficient)],
            });
        }
    }

    /// Register a coupled output; returns its slot in `coupled_values`.
    pub(crate) fn add_output(&mut self, output: CoupledOutput) -> usize {
        if let Some(i) = self.coupled_outputs.iter().position(|o| *o == output) {
            return i;
        }
        self.coupled_outputs.push(output);
        self.coupled_outputs.len() - 1
    }

    /// Size the buffers once the coupling is known (no allocation afterwards);
    /// `order` is the degree k of the unknowns' polynomials: the inputs'
    /// derivatives up to order min(k, 2) go to the FMU.
    pub(crate) fn finalize(&mut self, order: usize) {
        self.order = order;
        // The inputs' values as set: an array whole (its elements no
        // unknown drives at their start values), each other input alone.
        self.input.vrs.clear();
        self.input.values.clear();
        self.input_positions.clear();
        for (k, i) in self.inputs.iter().enumerate() {
            let first = self.inputs[..k].iter().position(|j| j.vr == i.vr);
            let position = match first {
                Some(j) => self.input_positions[j] - self.inputs[j].element + i.element,
                None => {
                    let start = self.input.values.len();
                    self.input.vrs.push(i.vr);
                    if i.count == 1 {
                        self.input.values.push(0.0);
                    } else {
                        let md = self.fmu.model_description();
                        let starts = md
                            .variable_by_vr(i.vr)
                            .and_then(|v| self.arrays.real_values(md, v).ok())
                            .filter(|x| x.len() == i.count)
                            .unwrap_or_else(|| vec![0.0; i.count]);
                        self.input.values.extend(starts);
                    }
                    start + i.element
                }
            };
            self.input_positions.push(position);
        }
        self.input.derivative_vrs.clear();
        self.input.orders.clear();
        for d in 1..=order.min(2) as i32 {
            for i in &self.inputs {
                self.input.derivative_vrs.push(i.vr);
                self.input.orders.push(d);
            }
        }
        self.input.derivatives = vec![0.0; self.input.derivative_vrs.len()];
        self.value_vrs.clear();
        self.derivative_reads.clear();
        let mut derivative_slots = Vec::new();
        self.slots.clear();
        // Each variable read once: an array's values all, the elements
        // nobody couples unused.
        let mut firsts: Vec<usize> = Vec::new();
        for (slot, o) in self.coupled_outputs.iter().enumerate() {
            if o.order != 0 {
                self.derivative_reads.push((o.vr, o.order as i32));
                derivative_slots.push(slot);
                continue;
            }
            let first = match self.value_vrs.iter().position(|&vr| vr == o.vr) {
                Some(k) => firsts[k],
                None => {
                    self.value_vrs.push(o.vr);
                    firsts.push(self.slots.len());
                    self.slots.resize(self.slots.len() + o.count, UNUSED);
                    *firsts.last().expect("pushed")
                }
            };
            self.slots[first + o.element] = slot;
        }
        let values = self.slots.len();
        self.value_count = (values != self.value_vrs.len()).then_some(values);
        self.accepted_vrs = [&self.value_vrs[..], &self.recorded_vrs[..]].concat();
        let accepted = values + self.recorded_reals;
        self.accepted_count = (accepted != self.accepted_vrs.len()).then_some(accepted);
        self.slots.extend(derivative_slots);
        self.value_buf = vec![0.0; self.slots.len()];
        self.run_inputs.clear();
        self.at_save = vec![0.0; self.coupled_outputs.len()];
        self.readback = vec![0.0; self.coupled_outputs.len()];
    }

    /// Number of coupled outputs (the length [`read_coupled`](Self::read_coupled) fills).
    pub(crate) fn coupled_len(&self) -> usize {
        self.coupled_outputs.len()
    }

    /// Whether any unknown drives this instance.
    /// Whether the input `vr` takes a polynomial over a step: FMI 2.0
    /// `canInterpolateInputs`, FMI 3.0 `providesIntermediateUpdate` and the input's
    /// `intermediateUpdate="true"`.
    pub(crate) fn interpolates(&self, vr: u32) -> bool {
        let md = self.fmu.model_description();
        self.can_interpolate_inputs
            && (md.standard != tether_fmi::FmiStandard::Fmi3
                || md.model_variables.iter().any(|v| {
                    v.value_reference == vr
                        && v.causality == tether_fmi::Causality::Input
                        && v.intermediate_update
                }))
    }

    pub(crate) fn is_coupled(&self) -> bool {
        !self.inputs.is_empty()
    }

    /// Initialise: setup experiment, initialization mode.
    pub(crate) fn initialize(
        &mut self,
        start: f64,
        stop: f64,
        tolerance: Option<f64>,
    ) -> Result<(), MasterError> {
        self.enter_initialization(start, stop, tolerance)?;
        self.exit_initialization()
    }

    /// Setup experiment and enter initialization mode, where inputs can be
    /// set and outputs read before the first step (a loop's values at T_0).
    pub(crate) fn enter_initialization(
        &mut self,
        start: f64,
        stop: f64,
        tolerance: Option<f64>,
    ) -> Result<(), MasterError> {
        self.backend.setup(tolerance, start, Some(stop))?;
        self.backend.enter_initialization()?;
        Ok(())
    }

    /// Leave initialization mode.
    pub(crate) fn exit_initialization(&mut self) -> Result<(), MasterError> {
        self.backend.exit_initialization()?;
        Ok(())
    }

    /// Save the current state (`fmi2GetFMUstate`, reusing the previous handle).
    pub(crate) fn save_state(&mut self) -> Result<(), MasterError> {
        self.backend.save(SAVED)?;
        self.saved = true;
        self.counters.state_gets += 1;
        if self.verify_restore {
            let mut at_save = std::mem::take(&mut self.at_save);
            let read = self.read_coupled(&mut at_save, Run::Rollback);
            self.at_save = at_save;
            read?;
        }
        Ok(())
    }

    /// Roll back to the saved state (`fmi2SetFMUstate`); with
    /// `verify_restore`, read the coupled outputs back and require those of
    /// the save.
    pub(crate) fn restore_state(&mut self) -> Result<(), MasterError> {
        assert!(self.saved, "restore_state is only called after save_state");
        self.backend.restore(SAVED)?;
        self.counters.state_sets += 1;
        if self.verify_restore {
            let mut readback = std::mem::take(&mut self.readback);
            let read = self.read_coupled(&mut readback, Run::Rollback);
            let compared = read.and_then(|()| {
                let time = self.backend.time();
                self.compare_restored(&self.at_save, &readback, time)
            });
            self.readback = readback;
            compared?;
        }
        Ok(())
    }

    /// The rollback self-check (`check_rollback`, docs/reliability.md): save,
    /// step over [t, t + h] with `polys`, read the coupled outputs, restore and
    /// require the outputs of the save, repeat the step and require
    /// bit-identical outputs, restore again. The instance is left as it was
    /// (the state is the saved one); the calls are not counted.
    pub(crate) fn check_rollback(
        &mut self,
        polys: &[Taylor],
        t: f64,
        h: f64,
    ) -> Result<(), MasterError> {
        // The counts as they were (the names are not copied: the periodic
        // check allocates nothing after the first).
        let mut counters = InstanceCounters {
            name: String::new(),
            model: String::new(),
            ..self.counters
        };
        let trips = self.backend.round_trips();
        let n = self.coupled_len();
        let mut buf = std::mem::take(&mut self.check_buf);
        buf.resize(4 * n, 0.0);
        let (at_save, rest) = buf.split_at_mut(n);
        let (first, rest) = rest.split_at_mut(n);
        let (back, second) = rest.split_at_mut(n);
        self.backend.save(CHECK)?;
        self.read_coupled(at_save, Run::Rollback)?;
        self.apply_inputs(polys)?;
        self.do_step(t, h)?;
        self.read_coupled(first, Run::Rollback)?;
        self.backend.restore(CHECK)?;
        self.read_coupled(back, Run::Rollback)?;
        self.compare_restored(at_save, back, t)?;
        self.apply_inputs(polys)?;
        self.do_step(t, h)?;
        self.read_coupled(second, Run::Rollback)?;
        if let Some(i) = first_difference(first, second) {
            let variable = self.coupled_name(i);
            return Err(MasterError::RollbackCheck {
                instance: self.name.clone(),
                reason: format!(
                    "the step from t = {t} to {} repeated after fmi2SetFMUstate with the same \
                     inputs gives output '{variable}' = {}, not {} as the first time (not \
                     bit-identical)",
                    t + h,
                    second[i],
                    first[i]
                ),
                variable,
            });
        }
        self.check_buf = buf;
        self.backend.restore(CHECK)?;
        self.backend.free(CHECK)?;
        counters.name = std::mem::take(&mut self.counters.name);
        counters.model = std::mem::take(&mut self.counters.model);
        self.counters = counters;
        self.check_trips += self.backend.round_trips() - trips;
        Ok(())
    }

    /// An error naming the first coupled output whose value read back after a
    /// restore (`back`) differs from the one at the save (`saved`).
    fn compare_restored(&self, saved: &[f64], back: &[f64], time: f64) -> Result<(), MasterError> {
        match first_difference(saved, back) {
            None => Ok(()),
            Some(i) => {
                let variable = self.coupled_name(i);
                Err(MasterError::RollbackCheck {
                    instance: self.name.clone(),
                    reason: format!(
                        "after fmi2SetFMUstate back to t = {time}, output '{variable}' reads {}, \
                         not {} as at fmi2GetFMUstate (the state was not restored)",
                        back[i], saved[i]
                    ),
                    variable,
                })
            }
        }
    }

    /// The name of coupled output `slot`: the variable, or `der(x, order)`.
    pub(crate) fn coupled_name(&self, slot: usize) -> String {
        let output = self.coupled_outputs[slot];
        let md = self.fmu.model_description();
        let var = md
            .model_variables
            .iter()
            .filter(|v| v.value_reference == output.vr && v.base_type() == BaseType::Real)
            .max_by_key(|v| v.causality == Causality::Output);
        let name = match var {
            None => format!("#{}", output.vr),
            Some(v) if v.is_array() => self
                .arrays
                .element_names(md, v)
                .ok()
                .and_then(|names| names.into_iter().nth(output.element))
                .unwrap_or_else(|| v.name.clone()),
            Some(v) => v.name.clone(),
        };
        match output.order {
            0 => name,
            order => format!("der({name}, {order})"),
        }
    }

    /// Set the coupled inputs from the unknowns' polynomials, and their
    /// derivatives through `fmi2SetRealInputDerivatives` when k > 0 (`finalize`).
    pub(crate) fn apply_inputs(&mut self, polys: &[Taylor]) -> Result<(), MasterError> {
        if self.inputs.is_empty() {
            return Ok(());
        }
        combine_inputs(
            &self.inputs,
            &self.input_positions,
            polys,
            &mut self.input.values,
            &mut self.input.derivatives,
        );
        self.backend.set_inputs(&self.input.as_inputs())?;
        self.count_inputs();
        Ok(())
    }

    /// Counts the calls that set the coupled inputs.
    fn count_inputs(&mut self) {
        self.counters.set_reals += 1;
        if !self.input.derivative_vrs.is_empty() {
            self.counters.set_input_derivatives += 1;
        }
    }

    /// One `fmi2DoStep` from `t` over `h`.
    /// fmi2Discard with `fmi2Terminated` true is
    /// [`MasterError::TerminationRequested`].
    pub(crate) fn do_step(&mut self, t: f64, h: f64) -> Result<(), MasterError> {
        self.counters.do_steps += 1;
        self.backend.step(t, h)?;
        Ok(())
    }

    /// `fmi2Terminate`, at a normal end of the run (not after a fatal error:
    /// tether-fmi then calls nothing).
    pub(crate) fn terminate(&mut self) -> Result<(), MasterError> {
        if !self.backend.is_fatal() {
            self.backend.terminate()?;
        }
        Ok(())
    }

    /// Read the coupled outputs into `out` (as long as [`coupled_len`](Self::coupled_len)).
    /// Every value must be finite: otherwise the error names this instance,
    /// the output, the call `run` and the time.
    pub(crate) fn read_coupled(&mut self, out: &mut [f64], run: Run) -> Result<(), MasterError> {
        let nv = self.values_len();
        if nv > 0 {
            self.backend
                .get_reals(&self.value_vrs, &mut self.value_buf[..nv])?;
            self.counters.get_reals += 1;
        }
        for (&(vr, order), value) in self.derivative_reads.iter().zip(&mut self.value_buf[nv..]) {
            self.backend
                .get_output_derivatives(&[vr], &[order], std::slice::from_mut(value))?;
        }
        let values = std::mem::take(&mut self.value_buf);
        let taken = self.take_coupled(&values, out, run);
        self.value_buf = values;
        taken
    }

    /// The coupled outputs as read (`values`: the values of `value_vrs`,
    /// then the output derivatives) into their slots of `out`, counted, and
    /// checked to be finite and within their divergence limits.
    #[inline(always)]
    fn take_coupled(
        &mut self,
        values: &[f64],
        out: &mut [f64],
        run: Run,
    ) -> Result<(), MasterError> {
        self.counters.get_output_derivatives += self.derivative_reads.len() as u64;
        // Every slot of `out` is written: when every value is finite, `out` is.
        let mut finite = true;
        for (&value, &slot) in values.iter().zip(&self.slots) {
            if slot == UNUSED {
                continue;
            }
            out[slot] = value;
            finite &= value.is_finite();
        }
        if !finite {
            return Err(self.first_non_finite(out, run));
        }
        let beyond = |(v, limit): (&f64, &f64)| v.abs() > *limit;
        if let Some(k) = values.iter().zip(&self.limits).position(beyond) {
            self.note_beyond(k, values[k], run);
        }
        Ok(())
    }

    /// The error naming the first coupled output in `out` that is not finite.
    #[cold]
    #[inline(never)]
    fn first_non_finite(&self, out: &[f64], run: Run) -> MasterError {
        let slot = out
            .iter()
            .position(|v| !v.is_finite())
            .expect("a value read is not finite");
        self.non_finite(self.coupled_name(slot), out[slot], run)
    }

    /// Divergence limits `factor`·max(|v|, 1) around the coupled outputs
    /// `out` of the last read (the initial point's), for crate::culprit; the
    /// output derivatives are not limited.
    pub(crate) fn set_divergence_limits(&mut self, factor: f64, out: &[f64]) {
        let nv = self.values_len();
        self.limits = self.slots[..nv]
            .iter()
            .map(|&slot| match slot {
                UNUSED => f64::INFINITY,
                _ => (factor * out[slot].abs().max(1.0)).min(f64::MAX),
            })
            .collect();
    }

    /// The number of values the coupled outputs' read returns.
    fn values_len(&self) -> usize {
        self.value_count.unwrap_or(self.value_vrs.len())
    }

    /// Coupled value `k` of the last read is beyond its limit: noted, unless
    /// a value of this step (a read at the same time or later) already is.
    #[cold]
    #[inline(never)]
    fn note_beyond(&mut self, k: usize, value: f64, run: Run) {
        let time = self.backend.time();
        if self.beyond.as_ref().is_some_and(|b| b.time >= time) {
            return;
        }
        self.beyond = Some(crate::culprit::Beyond::new(
            self.coupled_name(self.slots[k]),
            value,
            self.limits[k],
            run.describe(),
            time,
        ));
    }

    /// The error for output `variable` = `value` (not finite) read after `run`.
    #[cold]
    #[inline(never)]
    pub(crate) fn non_finite(&self, variable: String, value: f64, run: Run) -> MasterError {
        MasterError::NonFiniteOutput {
            instance: self.name.clone(),
            variable,
            value,
            call: run.describe(),
            time: self.backend.time(),
        }
    }

    /// A perturbed or corrector run: roll back to the saved state, set the
    /// inputs from `polys`, step from `t` over `h`; with `out`, read the
    /// coupled outputs into it.
    pub(crate) fn rerun(
        &mut self,
        polys: &[Taylor],
        t: f64,
        h: f64,
        out: Option<&mut [f64]>,
    ) -> Result<(), MasterError> {
        if self.verify_restore {
            self.restore_state()?;
            self.apply_inputs(polys)?;
            self.do_step(t, h)?;
            return match out {
                Some(out) => self.read_coupled(out, Run::Perturbed),
                None => Ok(()),
            };
        }
        assert!(self.saved, "rerun is only called after save_state");
        self.runs(&mut [Planned {
            step: Some((polys, t, h)),
            restore: true,
            out,
            record: false,
            run: Run::Perturbed,
        }])
    }

    /// The predictor's run (only the read of the coupled outputs for an
    /// instance the signals' sweep has stepped) and, with the same step, the
    /// perturbed runs from the saved state, one per `(polys, out)` of
    /// `perturbed`: handed to the instance together, since none depends on
    /// another's outputs (docs/algorithm.md, Steps 2 and 3).
    pub(crate) fn predict_and_perturb<'p>(
        &mut self,
        polys: &[Taylor],
        (t, h): (f64, f64),
        out: &mut [f64],
        perturbed: impl Iterator<Item = (&'p [Taylor], &'p mut [f64])>,
    ) -> Result<(), MasterError> {
        let predictor = Planned {
            step: (!self.stepped_ahead).then_some((polys, t, h)),
            restore: false,
            out: Some(out),
            record: false,
            run: Run::Predictor,
        };
        if self.verify_restore {
            // Each restore is checked on its own (its outputs read back).
            self.runs(&mut [predictor])?;
            for (polys, out) in perturbed {
                self.rerun(polys, t, h, Some(out))?;
            }
            return Ok(());
        }
        let mut planned = recycle(std::mem::take(&mut self.planned_buf));
        planned.push(predictor);
        planned.extend(perturbed.map(|(polys, out)| Planned {
            step: Some((polys, t, h)),
            restore: true,
            out: Some(out),
            record: false,
            run: Run::Perturbed,
        }));
        let ran = self.runs(&mut planned);
        self.planned_buf = recycle(planned);
        ran
    }

    /// The corrector's run: from the saved state with the inputs from
    /// `polys` over the step, the coupled outputs into `out` and the recorded
    /// outputs read at T_{N+1}, the accepted point.
    pub(crate) fn correct(
        &mut self,
        polys: &[Taylor],
        t: f64,
        h: f64,
        out: &mut [f64],
    ) -> Result<(), MasterError> {
        if self.verify_restore {
            self.rerun(polys, t, h, None)?;
            return self.read_accepted(out, Run::Corrector);
        }
        assert!(self.saved, "correct is only called after save_state");
        self.runs(&mut [Planned {
            step: Some((polys, t, h)),
            restore: true,
            out: Some(out),
            record: true,
            run: Run::Corrector,
        }])
    }

    /// The coupled outputs into `out` and the recorded outputs, at an
    /// accepted point reached after `run`.
    pub(crate) fn read_accepted(&mut self, out: &mut [f64], run: Run) -> Result<(), MasterError> {
        self.runs(&mut [Planned {
            step: None,
            restore: false,
            out: Some(out),
            record: true,
            run,
        }])
    }

    /// Runs handed to the instance as one unit ([`FmuInstance::run_batch`]),
    /// in order: each from the saved state when `restore`, with the inputs
    /// from its polynomials over its step, its coupled outputs read into its
    /// `out` (checked as read after its `run`) and, with `record`, the
    /// recorded outputs.
    fn runs(&mut self, planned: &mut [Planned<'_>]) -> Result<(), MasterError> {
        let driven = !self.inputs.is_empty();
        if self.run_inputs.len() < planned.len() {
            self.run_inputs.resize(planned.len(), self.input.clone());
        }
        // The runs' inputs, the length of their outputs, and the calls
        // counted (whether or not the runs succeed).
        let mut len = 0;
        for (p, input) in planned.iter().zip(&mut self.run_inputs) {
            if p.restore {
                self.counters.state_sets += 1;
            }
            if let Some((polys, _, _)) = p.step {
                self.counters.do_steps += 1;
                if driven {
                    combine_inputs(
                        &self.inputs,
                        &self.input_positions,
                        polys,
                        &mut input.values,
                        &mut input.derivatives,
                    );
                    self.counters.set_reals += 1;
                    if !self.input.derivative_vrs.is_empty() {
                        self.counters.set_input_derivatives += 1;
                    }
                }
            }
            if p.out.is_some() {
                len += self.slots.len();
            }
            if p.record {
                len += self.recorded_reals;
            }
        }
        self.batch_buf.resize(len, 0.0);
        let mut requests = recycle(std::mem::take(&mut self.request_buf));
        // At an accepted point one call reads the coupled and the recorded
        // outputs, unless output derivatives are read between them.
        let joined = self.derivative_reads.is_empty();
        requests.extend(planned.iter().zip(&self.run_inputs).map(|(p, input)| {
            let out = p.out.is_some();
            let (outputs, output_values, recorded, recorded_values) = match p.record {
                true if out && joined => {
                    (&self.accepted_vrs[..], self.accepted_count, &[][..], None)
                }
                record => (
                    if out { &self.value_vrs[..] } else { &[] },
                    if out { self.value_count } else { None },
                    if record { &self.recorded_vrs[..] } else { &[] },
                    record.then_some(self.recorded_reals),
                ),
            };
            RunRequest {
                restore: p.restore.then_some(SAVED),
                inputs: (driven && p.step.is_some()).then(|| input.as_inputs()),
                step: p.step.map(|(_, t, h)| (t, h)),
                outputs,
                output_values,
                output_derivatives: if out { &self.derivative_reads } else { &[] },
                recorded,
                recorded_values,
                save: None,
            }
        }));
        let reads: u64 = requests
            .iter()
            .map(|r| u64::from(!r.outputs.is_empty()) + u64::from(!r.recorded.is_empty()))
            .sum();
        let ran = self.backend.run_batch(&requests, &mut self.batch_buf);
        self.request_buf = recycle(requests);
        ran?;
        self.counters.get_reals += reads;
        let batch = std::mem::take(&mut self.batch_buf);
        let mut values = batch.as_slice();
        let taken = planned.iter_mut().try_for_each(|p| {
            if let Some(out) = p.out.as_deref_mut() {
                let (coupled, rest) = values.split_at(self.slots.len());
                values = rest;
                self.take_coupled(coupled, out, p.run)?;
            }
            if p.record {
                let (recorded, rest) = values.split_at(self.recorded_reals);
                values = rest;
                self.take_recorded(recorded, p.run)?;
            }
            Ok(())
        });
        self.batch_buf = batch;
        taken
    }

    /// The recorded Real outputs `reals` as read, and the Integer and
    /// Boolean ones read now, into `recorded_values`. Every Real value must be
    /// finite, as in [`read_coupled`](Self::read_coupled).
    fn take_recorded(&mut self, reals: &[f64], run: Run) -> Result<(), MasterError> {
        self.recorded_values[..reals.len()].copy_from_slice(reals);
        let reals = reals.len();
        if !self.recorded_ints.is_empty() {
            self.backend
                .get_integers(&self.recorded_ints, &mut self.int_buf)?;
            self.counters.get_integers += 1;
            self.recorded_exact.clear();
            for (k, &x) in self.int_buf.iter().enumerate() {
                let (v, exact) = integer_value(x);
                self.recorded_values[reals + k] = v;
                if !exact {
                    self.recorded_exact.push((reals + k, x));
                }
            }
        }
        if !self.recorded_bools.is_empty() {
            self.backend
                .get_booleans(&self.recorded_bools, &mut self.bool_buf)?;
            self.counters.get_booleans += 1;
            let first = reals + self.int_buf.len();
            for (slot, &v) in self.recorded_values[first..].iter_mut().zip(&self.bool_buf) {
                *slot = if v { 1.0 } else { 0.0 };
            }
        }
        match self.recorded_values[..reals]
            .iter()
            .position(|v| !v.is_finite())
        {
            None => Ok(()),
            Some(i) => {
                let column = &self.recorded_names[i];
                // `<instance>.<variable>`: the instance's name is the prefix.
                let variable = column[column.find('.').map_or(0, |d| d + 1)..].to_string();
                Err(self.non_finite(variable, self.recorded_values[i], run))
            }
        }
    }

    /// Column names of the recorded outputs.
    pub fn recorded_names(&self) -> &[String] {
        &self.recorded_names
    }

    /// Recorded outputs after the latest read.
    pub fn recorded_values(&self) -> &[f64] {
        &self.recorded_values
    }

    /// The integers among the recorded outputs that a float rounds, exactly,
    /// by index in [`recorded_values`](Self::recorded_values).
    pub fn recorded_exact(&self) -> &[(usize, Int)] {
        &self.recorded_exact
    }

    /// Call counters, with the round trips to the instance's host process.
    pub fn counters(&self) -> InstanceCounters {
        InstanceCounters {
            round_trips: self.backend.round_trips() - self.check_trips,
            ..self.counters.clone()
        }
    }
}

/// One run of an instance as a macro step plans it ([`Slave::runs`]).
/// An empty vector with `v`'s allocation, for items of another lifetime, so
/// that a step's plan and requests allocate nothing after the first step
/// (collecting the emptied vector's own iterator reuses its allocation).
fn recycle<T, U>(mut v: Vec<T>) -> Vec<U> {
    v.clear();
    v.into_iter()
        .map(|_| -> U { unreachable!("the vector was emptied") })
        .collect()
}

struct Planned<'a> {
    /// The inputs' polynomials and the step `(t, h)`; `None`: no step, a read.
    step: Option<(&'a [Taylor], f64, f64)>,
    /// From the saved state.
    restore: bool,
    /// Where the coupled outputs go, if read.
    out: Option<&'a mut [f64]>,
    /// Read the recorded outputs too (an accepted point).
    record: bool,
    /// What the outputs are read after, for messages.
    run: Run,
}

/// The coupled inputs' values and their derivatives (the first derivatives
/// of every input, then the second, as far as min(k, 2) asks).
#[derive(Debug, Default, Clone)]
struct InputBuffers {
    vrs: Vec<u32>,
    values: Vec<f64>,
    derivative_vrs: Vec<u32>,
    orders: Vec<i32>,
    derivatives: Vec<f64>,
}

impl InputBuffers {
    /// The inputs as last combined.
    fn as_inputs(&self) -> Inputs<'_> {
        Inputs {
            vrs: &self.vrs,
            values: &self.values,
            derivative_vrs: &self.derivative_vrs,
            orders: &self.orders,
            derivatives: &self.derivatives,
        }
    }
}

/// The first index where `a` and `b` differ bit for bit.
fn first_difference(a: &[f64], b: &[f64]) -> Option<usize> {
    a.iter()
        .zip(b)
        .position(|(x, y)| x.to_bits() != y.to_bits())
}

/// The inputs' values (`values`) and derivatives (`derivatives`: the first
/// derivatives of every input, then the second, as far as min(k, 2) asks) as
/// sums over their terms.
fn combine_inputs(
    inputs: &[CoupledInput],
    positions: &[usize],
    polys: &[Taylor],
    values: &mut [f64],
    derivatives: &mut [f64],
) {
    let n = inputs.len();
    for (i, (input, &position)) in inputs.iter().zip(positions).enumerate() {
        let mut p = Taylor::default();
        for &(m, c) in &input.terms {
            p.value += c * polys[m].value;
            p.d1 += c * polys[m].d1;
            p.d2 += c * polys[m].d2;
        }
        values[position] = p.value;
        if let Some(d1) = derivatives.get_mut(i) {
            *d1 = p.d1;
        }
        if let Some(d2) = derivatives.get_mut(n + i) {
            *d2 = p.d2;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_with_several_terms_are_sums() {
        // Two inputs: u0 − 2·u1, and 0.5·u1; first and second derivatives (k = 2).
        let polys = [
            Taylor {
                value: 1.0,
                d1: 2.0,
                d2: 3.0,
            },
            Taylor {
                value: 10.0,
                d1: 20.0,
                d2: 30.0,
            },
        ];
        let inputs = [
            CoupledInput {
                vr: 0,
                element: 0,
                count: 1,
                terms: vec![(0, 1.0), (1, -2.0)],
            },
            CoupledInput {
                vr: 1,
                element: 0,
                count: 1,
                terms: vec![(1, 0.5)],
            },
        ];
        let (mut values, mut derivatives) = ([0.0; 2], [0.0; 4]);
        combine_inputs(&inputs, &[0, 1], &polys, &mut values, &mut derivatives);
        assert_eq!(values, [-19.0, 5.0]);
        assert_eq!(derivatives, [-38.0, 10.0, -57.0, 15.0]);
    }
}
