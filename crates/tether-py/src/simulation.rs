//! A step-wise simulation: `tether.Simulation`.

use super::*;
use crate::results::{interrupt_reason, stats_dict, Rows};
use crate::system::{load_spec, start_value};

/// A coupled run advanced step by step from Python.
#[pyclass(unsendable, name = "Simulation")]
pub(crate) struct PySimulation {
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
    /// The setup's warnings.
    warnings: Vec<String>,
    /// An SSP system's extracted archive, kept while its FMUs are used.
    _ssp: Option<tether_ssp::Loaded>,
}

impl PySimulation {
    fn sim(&self) -> PyResult<&Simulation> {
        self.sim.as_ref().ok_or_else(closed)
    }
}

pub(crate) fn closed() -> PyErr {
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
            texts: Vec::new(),
        };
        rows.push(sim.time(), sim.values());
        rows.push_texts(sim.strings());
        let ssp_notes = ssp.as_ref().map(|l| l.notes.clone()).unwrap_or_default();
        let notes = [ssp_notes, sim.notes().to_vec()].concat();
        let warnings = sim.warnings().to_vec();
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
            warnings,
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
        stats_dict(py, &stats, &reason, (&self.notes, &self.warnings))
    }

    /// `(columns, data, stats)` of every point so far.
    fn result(&self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        let stats = self.stats(py)?.into_any().unbind();
        let rows = Rows {
            columns: self.rows.columns.clone(),
            bytes: self.rows.bytes.clone(),
            rounded: Vec::new(),
            texts: self.rows.texts.clone(),
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
            self.rows.push_texts(sim.strings());
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
