//! One FMU on its own: `tether.info` (its model description) and
//! `tether.simulate` (a run of it alone, as fmpy's `simulate_fmu`).

use super::*;
use crate::results::{Rows, Signals};
use crate::system::start_value;

/// A model description as a dict, with fmpy's attribute names.
#[pyfunction]
pub(crate) fn info<'py>(py: Python<'py>, fmu: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let opened = Fmu::open(&fmu).map_err(|e| failure("fmu", message(&e), None))?;
    let md = opened.model_description();
    let d = PyDict::new(py);
    d.set_item("fmiVersion", &md.fmi_version)?;
    d.set_item("modelName", &md.model_name)?;
    d.set_item("guid", &md.guid)?;
    d.set_item("description", &md.description)?;
    d.set_item("author", &md.author)?;
    d.set_item("version", &md.version)?;
    d.set_item("copyright", &md.copyright)?;
    d.set_item("license", &md.license)?;
    d.set_item("generationTool", &md.generation_tool)?;
    d.set_item("generationDateAndTime", &md.generation_date_and_time)?;
    let cs = md.cs();
    let c = PyDict::new(py);
    c.set_item("modelIdentifier", &cs.model_identifier)?;
    c.set_item("needsExecutionTool", cs.needs_execution_tool)?;
    c.set_item(
        "canHandleVariableCommunicationStepSize",
        cs.can_handle_variable_communication_step_size,
    )?;
    c.set_item("canInterpolateInputs", cs.can_interpolate_inputs)?;
    c.set_item("maxOutputDerivativeOrder", cs.max_output_derivative_order)?;
    c.set_item("canRunAsynchronuously", cs.can_run_asynchronuously)?;
    c.set_item(
        "canBeInstantiatedOnlyOncePerProcess",
        cs.can_be_instantiated_only_once_per_process,
    )?;
    c.set_item(
        "canNotUseMemoryManagementFunctions",
        cs.can_not_use_memory_management_functions,
    )?;
    // fmpy's names, FMI 2.0's spelling for the flags both standards have.
    c.set_item("canGetAndSetFMUstate", cs.can_get_and_set_fmu_state)?;
    c.set_item("canSerializeFMUstate", cs.can_serialize_fmu_state)?;
    c.set_item(
        "providesDirectionalDerivative",
        cs.provides_directional_derivative,
    )?;
    let fmi3 = md.standard == FmiStandard::Fmi3;
    if fmi3 {
        c.set_item(
            "providesAdjointDerivatives",
            cs.provides_adjoint_derivatives,
        )?;
        c.set_item(
            "providesPerElementDependencies",
            cs.provides_per_element_dependencies,
        )?;
        c.set_item(
            "providesIntermediateUpdate",
            cs.provides_intermediate_update,
        )?;
        c.set_item(
            "mightReturnEarlyFromDoStep",
            cs.might_return_early_from_do_step,
        )?;
        c.set_item(
            "canReturnEarlyAfterIntermediateUpdate",
            cs.can_return_early_after_intermediate_update,
        )?;
        c.set_item("hasEventMode", cs.has_event_mode)?;
        c.set_item(
            "providesEvaluateDiscreteStates",
            cs.provides_evaluate_discrete_states,
        )?;
        c.set_item("fixedInternalStepSize", cs.fixed_internal_step_size)?;
        c.set_item(
            "recommendedIntermediateInputSmoothness",
            cs.recommended_intermediate_input_smoothness,
        )?;
    }
    d.set_item("coSimulation", c)?;
    d.set_item(
        "modelExchange",
        md.model_exchange
            .as_ref()
            .map(|me| me.model_identifier.as_str()),
    )?;
    match &md.default_experiment {
        Some(de) => {
            let e = PyDict::new(py);
            e.set_item("startTime", de.start_time)?;
            e.set_item("stopTime", de.stop_time)?;
            e.set_item("stepSize", de.step_size)?;
            e.set_item("tolerance", de.tolerance)?;
            d.set_item("defaultExperiment", e)?;
        }
        None => d.set_item("defaultExperiment", py.None())?,
    }
    let variables = PyList::empty(py);
    for v in &md.model_variables {
        let x = PyDict::new(py);
        x.set_item("name", &v.name)?;
        x.set_item("valueReference", v.value_reference)?;
        x.set_item("description", &v.description)?;
        x.set_item(
            "causality",
            match v.causality {
                Causality::Parameter => "parameter",
                Causality::CalculatedParameter => "calculatedParameter",
                Causality::Input => "input",
                Causality::Output => "output",
                Causality::Local => "local",
                Causality::Independent => "independent",
            },
        )?;
        x.set_item(
            "variability",
            match v.variability {
                Variability::Constant => "constant",
                Variability::Fixed => "fixed",
                Variability::Tunable => "tunable",
                Variability::Discrete => "discrete",
                Variability::Continuous => "continuous",
            },
        )?;
        x.set_item(
            "initial",
            v.initial.map(|i| match i {
                Initial::Exact => "exact",
                Initial::Approx => "approx",
                Initial::Calculated => "calculated",
            }),
        )?;
        match &v.kind {
            VariableKind::Real(r) => {
                x.set_item("type", "Real")?;
                x.set_item("start", r.start)?;
                x.set_item("unit", &r.attributes.unit)?;
            }
            VariableKind::Integer(i) => {
                x.set_item("type", "Integer")?;
                x.set_item("start", i.start)?;
                x.set_item("unit", py.None())?;
            }
            VariableKind::Enumeration(i) => {
                x.set_item("type", "Enumeration")?;
                x.set_item("start", i.start)?;
                x.set_item("unit", py.None())?;
            }
            VariableKind::Boolean(b) => {
                x.set_item("type", "Boolean")?;
                x.set_item("start", b.start)?;
                x.set_item("unit", py.None())?;
            }
            VariableKind::String(s) => {
                x.set_item("type", "String")?;
                x.set_item("start", &s.start)?;
                x.set_item("unit", py.None())?;
            }
        }
        if fmi3 {
            // The exact type, every start value (arrays row-major), the dimensions.
            x.set_item("type", v.value_type.name())?;
            if v.structural_parameter {
                x.set_item("causality", "structuralParameter")?;
            }
            x.set_item("intermediateUpdate", v.intermediate_update)?;
            let sizes = md
                .array_sizes(v)
                .map_err(|e| failure("fmu", message(&e), None))?;
            x.set_item("shape", PyTuple::new(py, sizes)?)?;
            if let Some(values) = &v.start_values {
                let start = start_object(py, values)?;
                if v.is_array() {
                    x.set_item("start", start)?;
                } else {
                    let first = start.bind(py).get_item(0).ok();
                    x.set_item("start", first)?;
                }
            }
        }
        variables.append(x)?;
    }
    d.set_item("modelVariables", variables)?;
    Ok(d)
}

/// FMI 3.0 start values as a Python list (Binary values as bytes).
pub(crate) fn start_object(py: Python<'_>, values: &Values) -> PyResult<Py<PyList>> {
    let list = match values {
        Values::Float(v) => PyList::new(py, v)?,
        Values::Int(v) => PyList::new(py, v)?,
        Values::UInt(v) => PyList::new(py, v)?,
        Values::Boolean(v) => PyList::new(py, v)?,
        Values::String(v) => PyList::new(py, v)?,
        Values::Binary(v) => PyList::new(py, v.iter().map(|b| PyBytes::new(py, b)))?,
    };
    Ok(list.unbind())
}

/// One FMU at a fixed communication step, like `tether simulate` (the same
/// simulation, [`tether_master::SingleFmu`]): every non-String output at
/// every step, an array one column per element. Returns `(columns, data,
/// stats)`; a failure after the first row carries the rows so far.
/// `fmi_type`: fmpy's `"CoSimulation"` or `"ModelExchange"` (also
/// `tether simulate`'s `"co-simulation"`, `"model-exchange"`); None:
/// co-simulation where the FMU has it.
#[pyfunction]
#[pyo3(signature = (fmu, start=None, stop=None, step=None, tolerance=None, parameters=None, fmi_type=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate(
    py: Python<'_>,
    fmu: PathBuf,
    start: Option<f64>,
    stop: Option<f64>,
    step: Option<f64>,
    tolerance: Option<f64>,
    parameters: Option<&Bound<'_, PyDict>>,
    fmi_type: Option<String>,
) -> PyResult<Py<PyAny>> {
    let interface = match fmi_type.as_deref() {
        None => None,
        Some("CoSimulation" | "co-simulation") => Some(false),
        Some("ModelExchange" | "model-exchange") => Some(true),
        Some(other) => {
            return Err(PyValueError::new_err(format!(
                "fmi_type = {other:?}: give \"CoSimulation\" or \"ModelExchange\""
            )))
        }
    };
    let mut values = BTreeMap::new();
    if let Some(parameters) = parameters {
        for (name, value) in parameters.iter() {
            values.insert(name.extract::<String>()?, start_value(&value)?);
        }
    }
    let values: Vec<(String, StartValue)> = values.into_iter().collect();
    let outcome =
        py.detach(move || simulate_one(&fmu, (start, stop, step, tolerance), &values, interface));
    let (rows, run, warnings) = outcome.map_err(|e| master_failure(&e, None))?;
    match run.end {
        Err(e) => {
            let stats = simulate_stats(py, run.steps, &message(&e), None, &warnings)?;
            let partial = rows.into_py(py, stats)?;
            Err(master_failure(&e, Some(partial)))
        }
        Ok(end) => {
            let stats = simulate_stats(py, run.steps, "completed", Some(end), &warnings)?;
            rows.into_py(py, stats)
        }
    }
}

/// The stats of `tether.simulate`: `macro_steps`, `stop_reason` and, when
/// the FMU requested the end of the simulation, `termination` (as in the run
/// summary: `requested_at`, `ended_at`).
pub(crate) fn simulate_stats(
    py: Python<'_>,
    steps: u64,
    reason: &str,
    end: Option<SingleEnd>,
    warnings: &[String],
) -> PyResult<Py<PyAny>> {
    let d = PyDict::new(py);
    d.set_item("macro_steps", steps)?;
    d.set_item("stop_reason", reason)?;
    d.set_item("warnings", warnings.to_vec())?;
    if let Some(SingleEnd::Terminated { time }) = end {
        let t = PyDict::new(py);
        t.set_item("requested_at", time)?;
        t.set_item("ended_at", time)?;
        d.set_item("termination", t)?;
    }
    Ok(d.into_any().unbind())
}

/// [`SingleFmu`] recording into memory, with Ctrl-C looked for before every
/// step; `model_exchange`: the interface asked for (None: co-simulation where
/// the FMU has it). An error is one before the first row (no partial
/// result); a failure after it is in the run, with the rows so far.
pub(crate) fn simulate_one(
    path: &Path,
    (start, stop, step, tolerance): (Option<f64>, Option<f64>, Option<f64>, Option<f64>),
    parameters: &[(String, StartValue)],
    model_exchange: Option<bool>,
) -> Result<(Rows, SingleRun, Vec<String>), MasterError> {
    let fmu = Fmu::open(path)?;
    let md = fmu.model_description();
    let experiment = SingleExperiment::new(md, start, stop, step, tolerance)?;
    let fmi_type = match model_exchange {
        None => FmiType::default_for(md),
        Some(false) => {
            fmu.require_co_simulation()?;
            FmiType::CoSimulation
        }
        Some(true) if md.model_exchange.is_none() => {
            return Err(MasterError::MissingCapability {
                instance: path.display().to_string(),
                model: md.model_name.clone(),
                capability: "ModelExchange",
                needed_by: "fmi_type=\"ModelExchange\"".into(),
            })
        }
        Some(true) => FmiType::ModelExchange(Default::default()),
    };
    let mut single = SingleFmu::new_as(&fmu, parameters, experiment, fmi_type)?;
    let outputs = SingleOutputs::all(md, single.arrays())?;
    let mut rows = Rows {
        columns: Vec::new(),
        bytes: Vec::with_capacity(
            usize::try_from(experiment.steps + 1)
                .unwrap_or(usize::MAX)
                .saturating_mul((outputs.columns().len() + 1) * 8)
                .min(1 << 30),
        ),
        rounded: Vec::new(),
        texts: Vec::new(),
    };
    let mut signals = Signals::new(None);
    let run = single.run(&outputs, &mut rows, &mut || signals.interrupt());
    if run.end.is_ok() {
        // Like the CLI: a failing fmi2Terminate after complete results is an
        // error without them. (After a failure the instance is only freed.)
        single.terminate()?;
    }
    let warnings = single.warnings().to_vec();
    Ok((rows, run, warnings))
}
