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
    FmiType, MasterError, MethodChange, Observer, OverrideError, Overrides, RunStats, Sample,
    Simulation, SingleEnd, SingleExperiment, SingleFmu, SingleOutputs, SingleRun, StartValue,
    SystemSpec,
};

mod export;
mod fmu;
mod host;
mod results;
mod run;
mod simulation;
mod study;
mod system;

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
pub(crate) fn kind_of(e: &MasterError) -> &'static str {
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
use tether_master::error_line as message;

pub(crate) fn failure(kind: &str, message: String, partial: Option<Py<PyAny>>) -> PyErr {
    Failure::new_err((kind.to_string(), message, partial))
}

pub(crate) fn master_failure(e: &MasterError, partial: Option<Py<PyAny>>) -> PyErr {
    failure(kind_of(e), message(e), partial)
}

pub(crate) fn override_failure(e: &OverrideError) -> PyErr {
    failure("settings", e.to_string(), None)
}

/// The module `tether._tether`.
#[pymodule]
fn _tether(m: &Bound<'_, PyModule>) -> PyResult<()> {
    tether_fmi::exit_hook::install(host::on_ending);
    m.add("Failure", m.py().get_type::<Failure>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(run::run, m)?)?;
    m.add_function(wrap_pyfunction!(fmu::simulate, m)?)?;
    m.add_function(wrap_pyfunction!(fmu::info, m)?)?;
    m.add_function(wrap_pyfunction!(export::export_fmu, m)?)?;
    m.add_function(wrap_pyfunction!(system::load_system, m)?)?;
    m.add_function(wrap_pyfunction!(system::dump_toml, m)?)?;
    m.add_function(wrap_pyfunction!(host::use_fmi_host, m)?)?;
    m.add_function(wrap_pyfunction!(host::serve_fmi_host, m)?)?;
    m.add_function(wrap_pyfunction!(host::listen_host, m)?)?;
    m.add_function(wrap_pyfunction!(host::adopt_exit_hook, m)?)?;
    m.add_class::<simulation::PySimulation>()?;
    m.add_class::<study::PyPlan>()?;
    m.add_function(wrap_pyfunction!(study::plan_sweep, m)?)?;
    m.add_function(wrap_pyfunction!(study::plan_study, m)?)?;
    m.add_function(wrap_pyfunction!(study::run_jobs, m)?)?;
    Ok(())
}
