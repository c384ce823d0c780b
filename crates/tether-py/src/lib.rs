//! `tether._tether`: the Rust half of the `tether` Python package.
//!
//! The public API is Python (`python/tether/__init__.py`); this module gives it
//! the raw pieces: a whole run with the GIL released, a step-wise simulation,
//! one FMU on its own, an FMU's model description, and system files read into
//! and written from plain dicts. Results go to Python as one `bytes` object
//! per run: the rows `time, values…` as native-endian `f64`, which NumPy views
//! without copying (`numpy.frombuffer`).
//!
//! Every failure is raised as `_tether.Failure(kind, message, partial)`, which
//! the Python half turns into the documented exception classes; `partial` is
//! the part of the results recorded before the failure, or `None`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use tether_fmi::{Causality, FmiStandard, Fmu, Initial, Values, Variability, VariableKind};
use tether_master::{
    MasterError, MethodChange, Observer, OverrideError, Overrides, RunStats, Sample, Simulation,
    SingleEnd, SingleExperiment, SingleFmu, SingleOutputs, SingleRun, StartValue, SystemSpec,
};

mod study;

create_exception!(
    _tether,
    Failure,
    PyException,
    "Internal: (kind, message, partial) of a failure, mapped to tether's exception classes."
);

/// What the CLI says when Ctrl-C stops a run; the same here.
const INTERRUPT_REASON: &str = "Ctrl-C or termination signal";

/// How often a run that has released the GIL takes it back to look for
/// Ctrl-C (Python's signal handlers run only with the GIL held).
const SIGNAL_INTERVAL: Duration = Duration::from_millis(50);

// ---------------------------------------------------------------------------
// Errors

/// The class of a failure, as the Python half names it.
fn kind_of(e: &MasterError) -> &'static str {
    match e {
        MasterError::Fmi(_)
        | MasterError::UnknownVariable(_)
        | MasterError::InstanceFmu { .. }
        | MasterError::MissingCapability { .. }
        | MasterError::NoPolynomialInput { .. } => "fmu",
        MasterError::Diverged { .. }
        | MasterError::ResidualLimit { .. }
        | MasterError::DivergedOutput { .. }
        | MasterError::SingularJacobian { .. }
        | MasterError::SignalsNotConverged { .. } => "divergence",
        MasterError::Interrupted { .. } => "interrupted",
        MasterError::InvalidParameter { .. } | MasterError::InvalidTimeSpan { .. } => "settings",
        MasterError::SystemFile { .. }
        | MasterError::Expression { .. }
        | MasterError::Units { .. }
        | MasterError::UnknownInstance { .. }
        | MasterError::UnknownMarker { .. }
        | MasterError::IncompleteMarker { .. }
        | MasterError::MissingPort { .. }
        | MasterError::Joint { .. }
        | MasterError::WrongVariable { .. }
        | MasterError::ArrayElement { .. }
        | MasterError::MissingLevel { .. }
        | MasterError::StartValue { .. }
        | MasterError::DrivesCancel { .. }
        | MasterError::InvalidOutput(_) => "system",
        _ => "other",
    }
}

/// The one-line message of an error and its causes, as the CLI prints it
/// (`outer: cause: cause`).
fn message(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text.replace('\n', " ")
}

fn failure(kind: &str, message: String, partial: Option<Py<PyAny>>) -> PyErr {
    Failure::new_err((kind.to_string(), message, partial))
}

fn master_failure(e: &MasterError, partial: Option<Py<PyAny>>) -> PyErr {
    failure(kind_of(e), message(e), partial)
}

fn override_failure(e: &OverrideError) -> PyErr {
    failure("settings", e.to_string(), None)
}

// ---------------------------------------------------------------------------
// Results

/// The rows of a run as native-endian f64 bytes: `time, values…` per row.
#[derive(Default)]
struct Rows {
    columns: Vec<String>,
    bytes: Vec<u8>,
    /// Columns that held an integer a float rounds (beyond ±2^53).
    rounded: Vec<usize>,
}

impl Rows {
    fn push(&mut self, time: f64, values: &[f64]) {
        self.bytes.extend_from_slice(&time.to_ne_bytes());
        for v in values {
            self.bytes.extend_from_slice(&v.to_ne_bytes());
        }
    }

    /// `(columns, data, stats)` for the Python `Result`; a `UserWarning`
    /// names the columns whose integers the floats rounded.
    fn into_py(self, py: Python<'_>, stats: Py<PyAny>) -> PyResult<Py<PyAny>> {
        if !self.rounded.is_empty() {
            let names: Vec<&str> = self
                .rounded
                .iter()
                .map(|&k| self.columns[k].as_str())
                .collect();
            let text = format!(
                "integers beyond ±2^53 in column(s) {} are rounded in the result's floats \
                 (tether run's CSV writes them exactly)",
                names.join(", ")
            );
            let category = py.get_type::<pyo3::exceptions::PyUserWarning>();
            PyErr::warn(py, &category, &std::ffi::CString::new(text)?, 1)?;
        }
        let data = PyBytes::new(py, &self.bytes);
        let tuple = (self.columns, data, stats).into_pyobject(py)?;
        Ok(tuple.into_any().unbind())
    }
}

impl Observer for Rows {
    fn start(&mut self, columns: &[String]) -> std::io::Result<()> {
        self.columns = columns.to_vec();
        Ok(())
    }

    fn sample(&mut self, sample: Sample<'_>) -> std::io::Result<()> {
        self.push(sample.time, sample.values);
        for &(k, _) in sample.exact {
            if !self.rounded.contains(&k) {
                self.rounded.push(k);
            }
        }
        Ok(())
    }

    fn finish(&mut self, _failure: Option<&str>) -> std::io::Result<()> {
        Ok(())
    }
}

/// Stops a run when Python has a pending signal: every [`SIGNAL_INTERVAL`]
/// it takes the GIL, calls the optional progress callback with `(step,
/// total)` and runs the signal handlers; an exception from either
/// (`KeyboardInterrupt` for Ctrl-C) stops the run.
struct Signals {
    last: Instant,
    /// The callback and the run's number of steps.
    progress: Option<(Py<PyAny>, u64)>,
    /// The last step handed over.
    step: u64,
}

impl Signals {
    fn new(progress: Option<(Py<PyAny>, u64)>) -> Signals {
        Signals {
            last: Instant::now(),
            progress,
            step: 0,
        }
    }
}

impl Observer for Signals {
    fn start(&mut self, _columns: &[String]) -> std::io::Result<()> {
        Ok(())
    }

    fn sample(&mut self, sample: Sample<'_>) -> std::io::Result<()> {
        self.step = sample.step;
        Ok(())
    }

    fn finish(&mut self, _failure: Option<&str>) -> std::io::Result<()> {
        Ok(())
    }

    fn interrupt(&mut self) -> Option<String> {
        if self.last.elapsed() < SIGNAL_INTERVAL {
            return None;
        }
        self.last = Instant::now();
        Python::attach(|py| {
            let called = match &self.progress {
                Some((f, total)) => f.call1(py, (self.step, *total)).map(drop),
                None => Ok(()),
            };
            interrupt_reason(called.and_then(|()| py.check_signals()).err()?, py)
        })
    }
}

/// The reason a pending exception from a signal handler gives: the CLI's
/// words for `KeyboardInterrupt`, else the exception itself.
fn interrupt_reason(err: PyErr, py: Python<'_>) -> Option<String> {
    if err.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py) {
        Some(INTERRUPT_REASON.to_string())
    } else {
        Some(err.to_string())
    }
}

/// The run summary of `RunStats` (its serde schema, docs/run-summary.md:
/// the same as `tether run --summary-json`), with `stop_reason` as the
/// package words it and the summary text `tether run` prints.
fn stats_dict<'py>(
    py: Python<'py>,
    stats: &RunStats,
    stop_reason: &str,
    notes: &[String],
) -> PyResult<Bound<'py, PyDict>> {
    let json = py.import("json")?;
    let d = json
        .call_method1("loads", (stats.to_json(),))?
        .cast_into::<PyDict>()?;
    d.set_item("stop_reason", stop_reason)?;
    d.set_item("summary", stats.to_string())?;
    // The setup's notes (the CLI's `note:` lines), such as the
    // direct-feedthrough loops closed only at macro points.
    d.set_item("notes", notes.to_vec())?;
    Ok(d)
}

// ---------------------------------------------------------------------------
// Systems and overrides

/// A start value from a Python bool, int, float or str, or a list or tuple of
/// them (an FMI 3.0 array, flat row-major or nested).
fn start_value(value: &Bound<'_, PyAny>) -> PyResult<StartValue> {
    if value.is_instance_of::<pyo3::types::PyList>()
        || value.is_instance_of::<pyo3::types::PyTuple>()
    {
        let items: Vec<Bound<'_, PyAny>> = value.try_iter()?.collect::<PyResult<_>>()?;
        return items
            .iter()
            .map(start_value)
            .collect::<PyResult<Vec<_>>>()
            .map(StartValue::Array);
    }
    if value.is_instance_of::<PyBool>() {
        Ok(StartValue::Boolean(value.extract()?))
    } else if value.is_instance_of::<PyInt>() {
        Ok(StartValue::Integer(value.extract()?))
    } else if value.is_instance_of::<PyFloat>() {
        Ok(StartValue::Real(value.extract()?))
    } else if value.is_instance_of::<PyString>() {
        Ok(StartValue::String(value.extract()?))
    } else if let Ok(real) = value.extract::<f64>() {
        // NumPy scalars and other numbers.
        Ok(StartValue::Real(real))
    } else {
        Err(PyTypeError::new_err(format!(
            "a parameter value must be a bool, int, float or str (or a list of them), not {}",
            value.get_type().name()?
        )))
    }
}

/// The run overrides from the keyword arguments of `tether.run`.
fn overrides(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Overrides> {
    let mut o = Overrides::default();
    let Some(kwargs) = kwargs else {
        return Ok(o);
    };
    let real = |v: &Bound<'_, PyAny>| -> PyResult<Option<f64>> {
        if v.is_none() {
            Ok(None)
        } else {
            v.extract::<f64>().map(Some)
        }
    };
    let mut method = MethodChange::default();
    for (key, value) in kwargs.iter() {
        let key: String = key.extract()?;
        match key.as_str() {
            "stop" => o.stop = real(&value)?,
            "step" => o.step = real(&value)?,
            "epsilon" => o.epsilon = real(&value)?,
            "divergence_factor" => o.divergence_factor = real(&value)?,
            "iteration_tol" => o.iteration_tol = real(&value)?,
            "step_rtol" => o.step_rtol = real(&value)?,
            "jacobian" => {
                if !value.is_none() {
                    let name: String = value.extract()?;
                    o.jacobian = Some(name.parse().map_err(|e: String| {
                        failure("settings", format!("jacobian: {e}"), None)
                    })?);
                }
            }
            "step_atol" => o.step_atol = real(&value)?,
            "iterations" => {
                if !value.is_none() {
                    o.iterations = Some(value.extract()?);
                }
            }
            "index" => {
                if !value.is_none() {
                    method.index = Some(value.extract()?);
                }
            }
            // Applied to the system by `load_spec`.
            "isolate" | "call_timeout" | "output_interval" | "output_variables" => {}
            "beta" => method.beta = real(&value)?,
            "gamma" => method.gamma = real(&value)?,
            "a" => method.a = real(&value)?,
            "b" => method.b = real(&value)?,
            "mu" => method.mu = real(&value)?,
            "order" => {
                if !value.is_none() {
                    o.order = Some(value.extract()?);
                }
            }
            "method" => {
                if !value.is_none() {
                    let name: String = value.extract()?;
                    method.kind = Some(name.parse().map_err(|e| override_failure(&e))?);
                }
            }
            "parallel" => {
                if value.is_instance_of::<PyBool>() {
                    let on: bool = value.extract()?;
                    o.parallel = Some(if on {
                        tether_master::Parallel::On
                    } else {
                        tether_master::Parallel::Off
                    });
                } else if !value.is_none() {
                    let name: String = value.extract()?;
                    o.parallel = Some(name.parse().map_err(|e: String| {
                        failure("settings", format!("parallel: {e}"), None)
                    })?);
                }
            }
            "parameters" => {
                if value.is_none() {
                    continue;
                }
                let params = value.cast::<PyDict>().map_err(|_| {
                    PyTypeError::new_err(
                        "parameters must be a dict {\"instance.parameter\": value}",
                    )
                })?;
                for (target, v) in params.iter() {
                    let target: String = target.extract()?;
                    // Checked like `--set` (instance.parameter, both non-empty).
                    o.set(&format!("{target}=x"))
                        .map_err(|e| override_failure(&e))?;
                    o.parameters.insert(target, start_value(&v)?);
                }
            }
            other => {
                return Err(PyTypeError::new_err(format!(
                "unexpected override '{other}'; expected stop, step, method, beta, gamma, a, b, \
                     mu, order, epsilon, parallel, divergence_factor, iterations, iteration_tol, step_rtol, step_atol, jacobian or \
                     parameters"
            )))
            }
        }
    }
    o.method = method;
    Ok(o)
}

/// The system from a path (a system file or SSP: `.ssp`, `.ssd` or a folder,
/// read by `tether run`'s loader, [`tether_ssp::load`]) or TOML text, with
/// the overrides applied. For SSP the [`Loaded`](tether_ssp::Loaded) owns
/// the extracted archive the system's FMUs are in: keep it while they are
/// used.
fn load_spec(
    path: Option<PathBuf>,
    text: Option<&str>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<(SystemSpec, Option<tether_ssp::Loaded>)> {
    // The overrides first: a bad keyword is reported as such.
    let overrides = overrides(kwargs)?;
    let (mut spec, ssp) = match (path, text) {
        (Some(path), _) => {
            tether_ssp::load(&path, overrides.step, overrides.stop).map_err(|e| match e {
                tether_ssp::SspError::Master(e) => master_failure(&e, None),
                e => failure("system", e.to_string(), None),
            })?
        }
        (None, Some(text)) => (
            SystemSpec::from_toml(text).map_err(|e| master_failure(&e, None))?,
            None,
        ),
        (None, None) => return Err(PyValueError::new_err("no system given")),
    };
    overrides
        .apply(&mut spec)
        .map_err(|e| override_failure(&e))?;
    if let Some(kwargs) = kwargs {
        // The options of `tether run` that are not overrides of tether-master.
        let isolate = kwargs
            .get_item("isolate")?
            .filter(|v| !v.is_none())
            .map(|v| v.extract::<bool>())
            .transpose()?
            .unwrap_or(false);
        let timeout = kwargs
            .get_item("call_timeout")?
            .filter(|v| !v.is_none())
            .map(|v| v.extract::<f64>())
            .transpose()?;
        for instance in &mut spec.instances {
            if isolate {
                instance.isolation = tether_master::spec::Isolation::Process;
            }
            if instance.call_timeout.is_none() {
                instance.call_timeout = timeout;
            }
        }
        if let Some(dt) = kwargs.get_item("output_interval")?.filter(|v| !v.is_none()) {
            spec.output.interval = Some(dt.extract()?);
        }
        if let Some(v) = kwargs
            .get_item("output_variables")?
            .filter(|v| !v.is_none())
        {
            spec.output.variables = if let Ok(one) = v.extract::<String>() {
                vec![one]
            } else {
                v.extract()?
            };
        }
    }
    Ok((spec, ssp))
}

/// A TOML value as a Python object (tables as dicts).
fn toml_to_py<'py>(py: Python<'py>, value: &toml::Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        toml::Value::String(s) => s.into_pyobject(py)?.into_any(),
        toml::Value::Integer(i) => i.into_pyobject(py)?.into_any(),
        toml::Value::Float(f) => f.into_pyobject(py)?.into_any(),
        toml::Value::Boolean(b) => b.into_pyobject(py)?.to_owned().into_any(),
        toml::Value::Datetime(d) => d.to_string().into_pyobject(py)?.into_any(),
        toml::Value::Array(a) => {
            let items = a
                .iter()
                .map(|v| toml_to_py(py, v))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any()
        }
        toml::Value::Table(t) => {
            let d = PyDict::new(py);
            for (k, v) in t {
                d.set_item(k, toml_to_py(py, v)?)?;
            }
            d.into_any()
        }
    })
}

/// A Python object (dicts, lists, tuples, str, bool, int, float; `None`
/// entries of dicts are left out) as a TOML value.
fn py_to_toml(value: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    Ok(if value.is_instance_of::<PyBool>() {
        toml::Value::Boolean(value.extract()?)
    } else if value.is_instance_of::<PyInt>() {
        toml::Value::Integer(value.extract()?)
    } else if value.is_instance_of::<PyString>() {
        toml::Value::String(value.extract()?)
    } else if let Ok(d) = value.cast::<PyDict>() {
        let mut t = toml::Table::new();
        for (k, v) in d.iter() {
            if !v.is_none() {
                t.insert(k.extract()?, py_to_toml(&v)?);
            }
        }
        toml::Value::Table(t)
    } else if value.is_instance_of::<PyList>() || value.is_instance_of::<PyTuple>() {
        toml::Value::Array(
            value
                .try_iter()?
                .map(|v| py_to_toml(&v?))
                .collect::<PyResult<_>>()?,
        )
    } else if let Ok(path) = value.extract::<PathBuf>() {
        toml::Value::String(path.to_string_lossy().into_owned())
    } else if let Ok(f) = value.extract::<f64>() {
        toml::Value::Float(f)
    } else {
        return Err(PyTypeError::new_err(format!(
            "cannot write a {} into a system file",
            value.get_type().name()?
        )));
    })
}

/// Read a system file into a dict shaped like the file (FMU paths resolved
/// against the file's folder), raising the errors of `tether run`.
#[pyfunction]
fn load_system<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let spec = SystemSpec::from_file(&path).map_err(|e| master_failure(&e, None))?;
    let value = toml::Value::try_from(&spec).map_err(|e| {
        failure(
            "system",
            format!("system file {}: {e}", path.display()),
            None,
        )
    })?;
    toml_to_py(py, &value)
}

/// A dict shaped like a system file as TOML text.
#[pyfunction]
fn dump_toml(value: &Bound<'_, PyAny>) -> PyResult<String> {
    let value = py_to_toml(value)?;
    toml::to_string(&value).map_err(|e| PyValueError::new_err(e.to_string()))
}

// ---------------------------------------------------------------------------
// Whole runs

/// Run a system to its stop time with the GIL released; returns
/// `(columns, data, stats)`.
#[pyfunction]
#[pyo3(signature = (path=None, text=None, progress=None, **kwargs))]
fn run(
    py: Python<'_>,
    path: Option<PathBuf>,
    text: Option<&str>,
    progress: Option<Py<PyAny>>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<Py<PyAny>> {
    // `_ssp` keeps an extracted archive's FMUs until the run ends.
    let (spec, _ssp) = load_spec(path, text, kwargs)?;
    // A divergence of a formulation known to be unstable says so again, as the CLI does.
    let unstable = spec.method.stability_warning(spec.coupling.order);
    let outcome = py.detach(move || -> Result<_, MasterError> {
        spec.check_grid()?;
        let mut sim = Simulation::new(&spec).map_err(|e| e.located(&spec, |_, _| None))?;
        let notes = sim.notes().to_vec();
        let mut rows = Rows::default();
        let width = sim.columns().len() + 1;
        let points = usize::try_from(sim.total_steps()).unwrap_or(usize::MAX);
        // Reserve the whole result up front (at most 1 GiB; beyond it grows).
        rows.bytes.reserve(
            (points.saturating_add(1))
                .saturating_mul(width * 8)
                .min(1 << 30),
        );
        let mut signals = Signals::new(progress.map(|f| (f, sim.total_steps())));
        let result = sim.run(&mut [&mut rows, &mut signals], &mut |_, _| {});
        Ok((rows, result.map(|_| ()), sim.stats(), notes))
    });
    match outcome {
        // The run could not start: no results.
        Err(e) => Err(master_failure(&e, None)),
        Ok((rows, Ok(()), stats, notes)) => {
            let stats = stats_dict(py, &stats, "completed", &notes)?
                .into_any()
                .unbind();
            rows.into_py(py, stats)
        }
        Ok((rows, Err(e), stats, notes)) => {
            let stats = stats_dict(py, &stats, &message(&e), &notes)?
                .into_any()
                .unbind();
            let partial = rows.into_py(py, stats)?;
            match (&e, unstable) {
                (
                    MasterError::Diverged { .. } | MasterError::ResidualLimit { .. },
                    Some(advice),
                ) => Err(failure(
                    kind_of(&e),
                    format!("{}; {advice}", message(&e)),
                    Some(partial),
                )),
                _ => Err(master_failure(&e, Some(partial))),
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Step-wise

/// A coupled run advanced step by step from Python.
#[pyclass(unsendable, name = "Simulation")]
struct PySimulation {
    /// `None` once closed.
    sim: Option<Simulation>,
    /// Accepted macro steps so far.
    n: u64,
    start: f64,
    step: f64,
    rows: Rows,
    /// The error that stopped the run, if any: no more steps after it.
    failed: Option<String>,
    /// The counters at [`close`](Self::close).
    closed_stats: Option<(RunStats, u64)>,
    /// The advice for a formulation known to be unstable, repeated on divergence.
    unstable: Option<String>,
    /// The setup's notes.
    notes: Vec<String>,
    /// An SSP system's extracted archive, kept while its FMUs are used.
    _ssp: Option<tether_ssp::Loaded>,
}

impl PySimulation {
    fn sim(&self) -> PyResult<&Simulation> {
        self.sim.as_ref().ok_or_else(closed)
    }
}

fn closed() -> PyErr {
    failure("other", "the simulation is closed".into(), None)
}

#[pymethods]
impl PySimulation {
    #[new]
    #[pyo3(signature = (path=None, text=None, **kwargs))]
    fn new(
        path: Option<PathBuf>,
        text: Option<&str>,
        kwargs: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let (spec, ssp) = load_spec(path, text, kwargs)?;
        let sim = Simulation::new(&spec)
            .map_err(|e| master_failure(&e.located(&spec, |_, _| None), None))?;
        let mut rows = Rows {
            columns: sim.columns().to_vec(),
            bytes: Vec::new(),
            rounded: Vec::new(),
        };
        rows.push(sim.time(), sim.values());
        let notes = sim.notes().to_vec();
        Ok(PySimulation {
            sim: Some(sim),
            n: 0,
            start: spec.experiment.start,
            step: spec.experiment.step,
            rows,
            failed: None,
            closed_stats: None,
            unstable: spec.method.stability_warning(spec.coupling.order),
            notes,
            _ssp: ssp,
        })
    }

    /// Free the FMU instances and remove their unpacked folders now (also
    /// done when the object is collected); the results so far stay.
    fn close(&mut self) {
        if let Some(sim) = self.sim.take() {
            self.closed_stats = Some((sim.stats(), sim.total_steps()));
        }
    }

    /// Whether [`close`](Self::close) was called.
    #[getter]
    fn closed(&self) -> bool {
        self.sim.is_none()
    }

    /// Column names after `time`.
    #[getter]
    fn columns(&self) -> PyResult<Vec<String>> {
        Ok(self.sim()?.columns().to_vec())
    }

    /// The current macro time.
    #[getter]
    fn time(&self) -> PyResult<f64> {
        Ok(self.sim()?.time())
    }

    /// Accepted macro steps so far.
    #[getter]
    fn steps(&self) -> u64 {
        self.n
    }

    /// Macro steps to the stop time.
    #[getter]
    fn total_steps(&self) -> PyResult<u64> {
        Ok(self.sim()?.total_steps())
    }

    /// The values of the current point, in column order.
    #[getter]
    fn values(&self) -> PyResult<Vec<f64>> {
        Ok(self.sim()?.values().to_vec())
    }

    /// The coupling unknowns of the current point.
    #[getter]
    fn unknowns(&self) -> PyResult<Vec<f64>> {
        Ok(self.sim()?.unknowns())
    }

    /// Counters so far, as a dict.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let (stats, total) = match (&self.sim, &self.closed_stats) {
            (Some(sim), _) => (sim.stats(), sim.total_steps()),
            (None, Some((stats, total))) => (stats.clone(), *total),
            (None, None) => return Err(closed()),
        };
        let reason = match (&self.failed, self.n >= total) {
            (Some(e), _) => e.clone(),
            (None, true) => "completed".to_string(),
            (None, false) => "running".to_string(),
        };
        stats_dict(py, &stats, &reason, &self.notes)
    }

    /// `(columns, data, stats)` of every point so far.
    fn result(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let stats = self.stats(py)?.into_any().unbind();
        let rows = Rows {
            columns: self.rows.columns.clone(),
            bytes: self.rows.bytes.clone(),
            rounded: Vec::new(),
        };
        rows.into_py(py, stats)
    }

    /// Advance up to `count` macro steps, stopping at the stop time and on
    /// Ctrl-C; returns the number of steps made.
    fn advance(&mut self, py: Python<'_>, count: u64) -> PyResult<u64> {
        if let Some(e) = &self.failed {
            return Err(failure(
                "other",
                format!("the simulation stopped earlier: {e}"),
                None,
            ));
        }
        let Some(sim) = self.sim.as_mut() else {
            return Err(closed());
        };
        let mut made = 0;
        let mut last = Instant::now();
        while made < count && self.n < sim.total_steps() {
            if last.elapsed() >= SIGNAL_INTERVAL {
                last = Instant::now();
                // The run cannot leave the GIL (a `Simulation` stays on its
                // thread), so it lets other Python threads in now and then.
                py.detach(|| ());
                if let Some(err) = py.check_signals().err() {
                    let reason = interrupt_reason(err, py).unwrap_or_default();
                    let e = MasterError::Interrupted {
                        time: sim.time(),
                        reason,
                    };
                    return Err(master_failure(&e, None));
                }
            }
            if let Err(e) = sim.step() {
                let text = message(&e);
                self.failed = Some(text.clone());
                // A formulation known to be unstable says so again, as the CLI does.
                if let (
                    MasterError::Diverged { .. } | MasterError::ResidualLimit { .. },
                    Some(advice),
                ) = (&e, &self.unstable)
                {
                    return Err(failure(kind_of(&e), format!("{text}; {advice}"), None));
                }
                return Err(master_failure(&e, None));
            }
            self.n += 1;
            made += 1;
            self.rows.push(sim.time(), sim.values());
        }
        Ok(made)
    }

    /// Set an input the coupling does not drive, or a tunable parameter, of
    /// an instance (`"instance.variable"`) before the next step.
    fn set_parameter(&mut self, target: &str, value: &Bound<'_, PyAny>) -> PyResult<()> {
        let value = start_value(value)?;
        let Some(sim) = self.sim.as_mut() else {
            return Err(closed());
        };
        sim.set_parameter(target, &value).map_err(|e| {
            let kind = match &e {
                MasterError::StartValue { .. }
                | MasterError::UnknownInstance { .. }
                | MasterError::UnknownVariable(_) => "settings",
                other => kind_of(other),
            };
            failure(kind, message(&e), None)
        })
    }

    /// The number of steps from now to the first grid point at or after `t`.
    fn steps_to(&self, t: f64) -> PyResult<u64> {
        let total = self.sim()?.total_steps();
        let target = ((t - self.start) / self.step - 1e-9).ceil();
        let target = if target.is_nan() || target < 0.0 {
            0
        } else {
            (target as u64).min(total)
        };
        Ok(target.saturating_sub(self.n))
    }
}

// ---------------------------------------------------------------------------
// One FMU

/// A model description as a dict, with fmpy's attribute names.
/// Export a system with an `[export]` table as one FMI 2.0 or 3.0 (`fmi`)
/// co-simulation FMU at `out`, its binary the runtime library `runtime`
/// (shipped in the package) and, for isolated members, the host program
/// `host` (shipped too); returns the numbers of parameters, inputs, outputs
/// and member FMU files.
#[pyfunction]
#[pyo3(signature = (out, runtime, host=None, path=None, text=None, fmi=2))]
fn export_fmu(
    py: Python<'_>,
    out: PathBuf,
    runtime: PathBuf,
    host: Option<PathBuf>,
    path: Option<PathBuf>,
    text: Option<&str>,
    fmi: u32,
) -> PyResult<(usize, usize, usize, usize)> {
    let source = match &path {
        None => "(text)".to_string(),
        Some(p) if tether_ssp::is_ssp(p) => tether_ssp::ssd_name(p),
        Some(p) => p.display().to_string(),
    };
    let fmi = tether_fmu_export::package::FmiVersion::from_number(fmi)
        .map_err(|e| failure("settings", e, None))?;
    // `_ssp` keeps an extracted archive's FMUs until they are packed.
    let (spec, _ssp) = load_spec(path, text, None)?;
    let packaged = py
        .detach(move || {
            let programs = tether_fmu_export::package::Programs {
                runtime: &runtime,
                host: host.as_deref(),
            };
            tether_fmu_export::package::package(spec, &source, &programs, &out, fmi)
        })
        .map_err(|e| failure("settings", e, None))?;
    Ok((
        packaged.parameters,
        packaged.inputs,
        packaged.outputs,
        packaged.members,
    ))
}

#[pyfunction]
fn info<'py>(py: Python<'py>, fmu: PathBuf) -> PyResult<Bound<'py, PyDict>> {
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
    let cs = &md.co_simulation;
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
    d.set_item("modelExchange", &md.model_exchange)?;
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
fn start_object(py: Python<'_>, values: &Values) -> PyResult<Py<PyList>> {
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
#[pyfunction]
#[pyo3(signature = (fmu, start=None, stop=None, step=None, tolerance=None, parameters=None))]
fn simulate(
    py: Python<'_>,
    fmu: PathBuf,
    start: Option<f64>,
    stop: Option<f64>,
    step: Option<f64>,
    tolerance: Option<f64>,
    parameters: Option<&Bound<'_, PyDict>>,
) -> PyResult<Py<PyAny>> {
    let mut values = BTreeMap::new();
    if let Some(parameters) = parameters {
        for (name, value) in parameters.iter() {
            values.insert(name.extract::<String>()?, start_value(&value)?);
        }
    }
    let values: Vec<(String, StartValue)> = values.into_iter().collect();
    let outcome = py.detach(move || simulate_one(&fmu, start, stop, step, tolerance, &values));
    let (rows, run) = outcome.map_err(|e| master_failure(&e, None))?;
    match run.end {
        Err(e) => {
            let stats = simulate_stats(py, run.steps, &message(&e), None)?;
            let partial = rows.into_py(py, stats)?;
            Err(master_failure(&e, Some(partial)))
        }
        Ok(end) => {
            let stats = simulate_stats(py, run.steps, "completed", Some(end))?;
            rows.into_py(py, stats)
        }
    }
}

/// The stats of `tether.simulate`: `macro_steps`, `stop_reason` and, when
/// the FMU requested the end of the simulation, `termination` (as in the run
/// summary: `requested_at`, `ended_at`).
fn simulate_stats(
    py: Python<'_>,
    steps: u64,
    reason: &str,
    end: Option<SingleEnd>,
) -> PyResult<Py<PyAny>> {
    let d = PyDict::new(py);
    d.set_item("macro_steps", steps)?;
    d.set_item("stop_reason", reason)?;
    if let Some(SingleEnd::Terminated { time }) = end {
        let t = PyDict::new(py);
        t.set_item("requested_at", time)?;
        t.set_item("ended_at", time)?;
        d.set_item("termination", t)?;
    }
    Ok(d.into_any().unbind())
}

/// [`SingleFmu`] recording into memory, with Ctrl-C looked for before every
/// step. An error is one before the first row (no partial result); a failure
/// after it is in the run, with the rows so far.
fn simulate_one(
    path: &Path,
    start: Option<f64>,
    stop: Option<f64>,
    step: Option<f64>,
    tolerance: Option<f64>,
    parameters: &[(String, StartValue)],
) -> Result<(Rows, SingleRun), MasterError> {
    let fmu = Fmu::open(path)?;
    let md = fmu.model_description();
    let experiment = SingleExperiment::new(md, start, stop, step, tolerance)?;
    let mut single = SingleFmu::new(&fmu, parameters, experiment)?;
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
    };
    let mut signals = Signals::new(None);
    let run = single.run(&outputs, &mut rows, &mut || signals.interrupt());
    if run.end.is_ok() {
        // Like the CLI: a failing fmi2Terminate after complete results is an
        // error without them. (After a failure the instance is only freed.)
        single.terminate()?;
    }
    Ok((rows, run))
}

// ---------------------------------------------------------------------------
// Isolated instances (`isolation = "process"`, docs/reliability.md)

/// Start the host processes of isolated instances as `program args…`
/// (the package's import sets `python -m tether._fmi_host`; the
/// `TETHER_FMI_HOST` environment variable still comes first).
#[pyfunction]
fn use_fmi_host(program: PathBuf, args: Vec<String>) {
    tether_fmi::remote::set_host(tether_fmi::remote::HostCommand {
        program,
        args: args.into_iter().map(Into::into).collect(),
    });
}

/// Serve one isolated FMU instance on standard input and output until the
/// master closes them (the body of `python -m tether._fmi_host`).
#[pyfunction]
fn serve_fmi_host(py: Python<'_>) -> PyResult<()> {
    // A host's exit, whatever its code, is reported by the master it serves.
    SERVING_HOST.store(true, std::sync::atomic::Ordering::SeqCst);
    py.detach(tether_fmi_host::serve_standard_streams)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("tether-fmi-host: {e}")))
}

/// Serve FMU instances to masters on `address` as `tether host --listen`
/// does (docs/remote.md), until the process is killed: the body of
/// `python -m tether._fmi_host --listen` that `tether.run(system,
/// client=…)` starts on a Dask worker. With `parent`, the process ends when
/// the process of that id (its parent) does.
#[pyfunction]
#[pyo3(signature = (address, token_file, max_fmu_bytes, max_frame_bytes, parent=None))]
fn listen_host(
    py: Python<'_>,
    address: String,
    token_file: PathBuf,
    max_fmu_bytes: u64,
    max_frame_bytes: u64,
    parent: Option<i32>,
) -> PyResult<()> {
    if let Some(parent) = parent {
        // SAFETY: prctl and getppid take and return plain integers; after
        // prctl the kernel kills this process when its parent ends, and a
        // parent that ended before it shows as another parent id.
        let orphaned = unsafe {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
            libc::getppid() != parent
        };
        if orphaned {
            return Err(pyo3::exceptions::PyRuntimeError::new_err(
                "tether host: the process that started it has ended",
            ));
        }
    }
    let options = tether_fmi_host::listen::ListenOptions {
        address,
        token_file,
        max_fmu_bytes,
        max_frame_bytes,
    };
    py.detach(|| tether_fmi_host::listen::listen(&options))
        .map_err(pyo3::exceptions::PyRuntimeError::new_err)
}

/// This process is the host of an isolated instance (`serve_fmi_host`): its
/// FMU's exit is left to the master, which reports it with the exit code.
static SERVING_HOST: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// An in-process FMU ends the process from inside a call (`exit()` or
/// `abort()`, tether_fmi::exit_hook): Python cannot be told, and `exit(0)`
/// would end it with status 0, silently. One line names the instance, the
/// call and the time, the extraction folders are removed, and the process
/// ends with status 1 after `exit()` (SIGABRT after `abort()`). An exit
/// outside any FMI call (the interpreter's own) is left alone.
fn on_ending(ending: tether_fmi::exit_hook::Ending) {
    use std::io::Write as _;
    if SERVING_HOST.load(std::sync::atomic::Ordering::SeqCst) {
        return;
    }
    let Some(blame) = tether_fmi::exit_hook::blame(ending) else {
        return;
    };
    let _ = writeln!(
        std::io::stderr(),
        "error: the Python process ends: {blame} (an in-process FMU shares Python's process; with isolation = \"process\" this is an exception)"
    );
    tether_fmi::remove_extractions_now();
    if let tether_fmi::exit_hook::Ending::Exit(_) = ending {
        // SAFETY: _exit ends the process at once with status 1: the code the
        // FMU chose (0 included) must not be the process's.
        unsafe { libc::_exit(1) }
    }
}

/// The exit hook acts in this process too: called in the child after
/// Python's `os.fork()` (a `multiprocessing` worker is a Python program of
/// its own), never after an FMU's own `fork()`.
#[pyfunction]
fn adopt_exit_hook() {
    tether_fmi::exit_hook::adopt();
}

/// The module `tether._tether`.
#[pymodule]
fn _tether(m: &Bound<'_, PyModule>) -> PyResult<()> {
    tether_fmi::exit_hook::install(on_ending);
    m.add("Failure", m.py().get_type::<Failure>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(info, m)?)?;
    m.add_function(wrap_pyfunction!(export_fmu, m)?)?;
    m.add_function(wrap_pyfunction!(load_system, m)?)?;
    m.add_function(wrap_pyfunction!(dump_toml, m)?)?;
    m.add_function(wrap_pyfunction!(use_fmi_host, m)?)?;
    m.add_function(wrap_pyfunction!(serve_fmi_host, m)?)?;
    m.add_function(wrap_pyfunction!(listen_host, m)?)?;
    m.add_function(wrap_pyfunction!(adopt_exit_hook, m)?)?;
    m.add_class::<PySimulation>()?;
    m.add_class::<study::PyPlan>()?;
    m.add_function(wrap_pyfunction!(study::plan_sweep, m)?)?;
    m.add_function(wrap_pyfunction!(study::plan_study, m)?)?;
    m.add_function(wrap_pyfunction!(study::run_jobs, m)?)?;
    Ok(())
}
