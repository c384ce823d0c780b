//! Setting an instance up: instantiation where the system file places it,
//! the start values, the coupling's buffers once the coupling is known, and
//! initialization; what the FMU declares it can do.

use tether_fmi::{Fmu, Placement};

use super::interface::Needs;

use super::coupled::UNUSED;
use super::{Experiment, Slave};
use crate::spec::{InstanceSpec, Isolation, StartValue};
use crate::stats::InstanceCounters;
use crate::MasterError;

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
        experiment: Experiment,
        needs: &Needs,
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
        Slave::instantiate_as(fmu, spec, &spec.name, order, experiment, needs)
    }

    /// FMI 2.0: `fmi2SetupExperiment` right after `fmi2Instantiate` (FMI 3.0
    /// keeps the experiment for `fmi3EnterInitializationMode`), then the start
    /// values, as FMPy and libcosim set them: FMUs of some modelling tools
    /// reset their parameters in `fmi2SetupExperiment`.
    pub(super) fn instantiate_as(
        fmu: Fmu,
        spec: &InstanceSpec,
        name: &str,
        order: usize,
        experiment: Experiment,
        needs: &Needs,
    ) -> Result<Slave, MasterError> {
        let md = fmu.model_description();
        let (interface, interface_note) = super::interface::choose(spec, md, needs);
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
        let options = tether_fmi::InstanceOptions::default()
            .with_polynomial_inputs(order > 0)
            .with_interface(interface);
        let mut backend = tether_fmi::instantiate(&fmu, name, options, placement)?;
        let caps = backend.capabilities();
        let (start, stop, tolerance) = experiment;
        backend.setup(tolerance, start, Some(stop))?;
        let exact_parameters = crate::start::exact_parameters(
            fmu.model_description(),
            spec.parameters.iter().map(|(n, v)| (n.as_str(), v)),
        );
        let mut slave = Slave {
            name: name.to_string(),
            model_name,
            backend,
            fmu,
            caps,
            model_exchange: matches!(interface, tether_fmi::Interface::ModelExchange(_)),
            interface_note,
            saved: false,
            coupled: Default::default(),
            runs: Default::default(),
            recorded: Default::default(),
            check: Default::default(),
            arrays: Default::default(),
            signal_buf: Vec::new(),
            counters,
            stepped_ahead: false,
            exact_parameters,
        };
        slave.coupled.decimation = 1;
        slave.arrays = crate::start::apply_start_values(
            slave.backend.as_mut(),
            slave.fmu.model_description(),
            spec.parameters.iter().map(|(n, v)| (n.as_str(), v)),
        )?;
        slave.record_columns(&spec.name)?;
        Ok(slave)
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

    /// Size the buffers once the coupling is known (no allocation afterwards);
    /// `order` is the degree k of the unknowns' polynomials: the inputs'
    /// derivatives up to order min(k, 2) go to the FMU.
    pub(crate) fn finalize(&mut self, order: usize) {
        self.coupled.order = order;
        // The inputs' values as set: an array whole (its elements no
        // unknown drives at their start values), each other input alone.
        self.coupled.input.vrs.clear();
        self.coupled.input.values.clear();
        self.coupled.input_positions.clear();
        for (k, i) in self.coupled.inputs.iter().enumerate() {
            let first = self.coupled.inputs[..k].iter().position(|j| j.vr == i.vr);
            let position = match first {
                Some(j) => {
                    self.coupled.input_positions[j] - self.coupled.inputs[j].element + i.element
                }
                None => {
                    let start = self.coupled.input.values.len();
                    self.coupled.input.vrs.push(i.vr);
                    if i.count == 1 {
                        self.coupled.input.values.push(0.0);
                    } else {
                        let md = self.fmu.model_description();
                        let starts = md
                            .variable_by_vr(i.vr)
                            .and_then(|v| self.arrays.real_values(md, v).ok())
                            .filter(|x| x.len() == i.count)
                            .unwrap_or_else(|| vec![0.0; i.count]);
                        self.coupled.input.values.extend(starts);
                    }
                    start + i.element
                }
            };
            self.coupled.input_positions.push(position);
        }
        self.coupled.input.derivative_vrs.clear();
        self.coupled.input.orders.clear();
        for d in 1..=order.min(2) as i32 {
            for i in &self.coupled.inputs {
                self.coupled.input.derivative_vrs.push(i.vr);
                self.coupled.input.orders.push(d);
            }
        }
        self.coupled.input.derivatives = vec![0.0; self.coupled.input.derivative_vrs.len()];
        self.coupled.value_vrs.clear();
        self.coupled.derivative_reads.clear();
        let mut derivative_slots = Vec::new();
        self.coupled.slots.clear();
        // Each variable read once: an array's values all, the elements
        // nobody couples unused.
        let mut firsts: Vec<usize> = Vec::new();
        for (slot, o) in self.coupled.outputs.iter().enumerate() {
            if o.order != 0 {
                self.coupled.derivative_reads.push((o.vr, o.order as i32));
                derivative_slots.push(slot);
                continue;
            }
            let first = match self.coupled.value_vrs.iter().position(|&vr| vr == o.vr) {
                Some(k) => firsts[k],
                None => {
                    self.coupled.value_vrs.push(o.vr);
                    firsts.push(self.coupled.slots.len());
                    self.coupled
                        .slots
                        .resize(self.coupled.slots.len() + o.count, UNUSED);
                    *firsts.last().expect("pushed")
                }
            };
            self.coupled.slots[first + o.element] = slot;
        }
        let values = self.coupled.slots.len();
        self.coupled.value_count = (values != self.coupled.value_vrs.len()).then_some(values);
        self.coupled.accepted_vrs = [&self.coupled.value_vrs[..], &self.recorded.vrs[..]].concat();
        let accepted = values + self.recorded.reals;
        self.coupled.accepted_count =
            (accepted != self.coupled.accepted_vrs.len()).then_some(accepted);
        self.coupled.slots.extend(derivative_slots);
        self.coupled.value_buf = vec![0.0; self.coupled.slots.len()];
        self.runs.inputs.clear();
        self.check.at_save = vec![0.0; self.coupled.outputs.len()];
        self.check.readback = vec![0.0; self.coupled.outputs.len()];
    }

    /// Enter initialization mode, where inputs can be set and outputs read
    /// before the first step (a loop's values at T_0).
    pub(crate) fn enter_initialization(&mut self) -> Result<(), MasterError> {
        self.backend.enter_initialization()?;
        Ok(())
    }

    /// After initialization: the parameters set with `initial="exact"` that
    /// the FMU changed, one line each (the signal connections' receivers,
    /// `receivers`, left out). The reads are not counted.
    pub(crate) fn changed_parameters(
        &mut self,
        receivers: &[u32],
    ) -> Result<Vec<String>, MasterError> {
        if self.exact_parameters.is_empty() {
            return Ok(Vec::new());
        }
        let trips = self.backend.round_trips();
        let lines = crate::start::changed_parameters(
            self.backend.as_mut(),
            &self.exact_parameters,
            receivers,
        );
        self.check.trips += self.backend.round_trips() - trips;
        lines
    }

    /// Leave initialization mode.
    pub(crate) fn exit_initialization(&mut self) -> Result<(), MasterError> {
        self.backend.exit_initialization()?;
        Ok(())
    }

    /// The capability adaptive macro steps need that the FMU does not
    /// declare: rollback of a rejected step, and steps of varying size.
    pub(crate) fn cannot_vary_steps(&self) -> Option<&'static str> {
        if !self.caps.rollback {
            Some("canGetAndSetFMUstate")
        } else if !self.caps.variable_steps {
            Some("canHandleVariableCommunicationStepSize")
        } else {
            None
        }
    }

    /// Whether the instance's runs may go to a worker thread: it runs in
    /// this process (a host process's requests are sent without a thread)
    /// and its FMU does not declare `canBeInstantiatedOnlyOncePerProcess`
    /// (such an FMU may keep global state that one thread expects).
    pub(crate) fn can_run_in_parallel(&self) -> bool {
        let cs = self.fmu.model_description().cs();
        !self.backend.is_remote() && !cs.can_be_instantiated_only_once_per_process
    }

    /// Whether the input `vr` takes a polynomial over a step: FMI 2.0
    /// `canInterpolateInputs`, FMI 3.0 `providesIntermediateUpdate` and the input's
    /// `intermediateUpdate="true"`; every input of a model-exchange instance.
    pub(crate) fn interpolates(&self, vr: u32) -> bool {
        let md = self.fmu.model_description();
        self.caps.polynomial_inputs
            && (self.model_exchange
                || md.standard != tether_fmi::FmiStandard::Fmi3
                || md.model_variables.iter().any(|v| {
                    v.value_reference == vr
                        && v.causality == tether_fmi::Causality::Input
                        && v.intermediate_update
                }))
    }
}
