//! Studies from Python: `tether sweep` and `tether study` cut into jobs.
//!
//! A [`PyPlan`] is built on the calling machine (the checks a study makes
//! before its first run happen here). Python then either runs it here over
//! the cores ([`PyPlan::run_local`], the code of the `tether` command) or
//! sends its TOML text with job indices to an executor's workers
//! ([`run_jobs`]) and hands their results back ([`PyPlan::finish`]). Both put
//! the results together with the same Rust code (`tether_study::Plan`), so a
//! study gives the same numbers, bit for bit, wherever its jobs ran.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};
use serde::Deserialize;
use tether_master::SystemSpec;
use tether_study::{
    Axis, Cell, Class, Convergence, JobResult, Kind, Outcome, Plan, ReferenceSpec, RunResult,
    Stability, Study, StudyError, StudyResults, Table,
};

use crate::results::Rows;
use crate::system::{overrides, py_to_toml};
use crate::{failure, kind_of, message, SIGNAL_INTERVAL};

/// A study's failure as a Python error of the matching class.
fn study_failure(e: &StudyError) -> PyErr {
    let kind = match e {
        StudyError::Master(m) => kind_of(m),
        StudyError::Override(_) | StudyError::Invalid(_) | StudyError::UnknownColumn { .. } => {
            "settings"
        }
        StudyError::StudyFile { .. } => "system",
        StudyError::Interrupted { .. } => "interrupted",
        _ => "other",
    };
    failure(kind, message(e), None)
}

/// An axis from the command-line form (`"mass1.c,mass2.c=1e2..1e5:20:log"`)
/// or a dict shaped like the study file's (`{"targets": [...], "from": …}`).
fn axis(name: &str, value: &Bound<'_, PyAny>) -> PyResult<Axis> {
    let axis = if let Ok(text) = value.cast::<PyString>() {
        Axis::parse_cli(&text.to_cow()?).map_err(|e| study_failure(&e))?
    } else if value.cast::<PyDict>().is_ok() {
        Axis::deserialize(py_to_toml(value)?).map_err(|e| {
            failure(
                "settings",
                format!("axis {name}: {}", e.to_string().replace('\n', " ")),
                None,
            )
        })?
    } else {
        return Err(PyTypeError::new_err(format!(
            "{name} must be a str like \"mass1.c,mass2.c=1e2..1e5:20:log\" or a dict, not {}",
            value.get_type().name()?
        )));
    };
    axis.values().map_err(|e| study_failure(&e))?;
    Ok(axis)
}

/// A study cut into jobs, with what it needs to write its results.
#[pyclass(name = "StudyPlan", module = "tether._tether", frozen)]
pub(crate) struct PyPlan {
    study: Study,
    plan: Plan,
    payload: String,
    jobs: usize,
}

impl PyPlan {
    fn new(py: Python<'_>, study: Study, system: &SystemSpec) -> PyResult<PyPlan> {
        let variants = study.variants_of(system).map_err(|e| study_failure(&e))?;
        let plan = Plan::new(&study, variants);
        // Instantiates every variant's FMUs once: without the GIL.
        let (plan, checked) = py.detach(move || {
            let checked = plan.check().and_then(|n| Ok((n, plan.to_toml()?)));
            (plan, checked)
        });
        let (jobs, payload) = checked.map_err(|e| study_failure(&e))?;
        Ok(PyPlan {
            study,
            plan,
            payload,
            jobs,
        })
    }
}

/// The plan of `tether sweep stability|convergence` on a system file
/// (`path`) or system text (`text`), with `tether run`'s keywords.
#[pyfunction]
#[pyo3(signature = (
    kind, path=None, text=None, x=None, y=None, growth=None, monitor=None, steps=None,
    reference=None, columns=None, name=None, formats=None, **kwargs
))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn plan_sweep(
    py: Python<'_>,
    kind: &str,
    path: Option<PathBuf>,
    text: Option<&str>,
    x: Option<&Bound<'_, PyAny>>,
    y: Option<&Bound<'_, PyAny>>,
    growth: Option<f64>,
    monitor: Option<Vec<String>>,
    steps: Option<Vec<f64>>,
    reference: Option<&str>,
    columns: Option<Vec<String>>,
    name: Option<String>,
    formats: Option<Vec<String>>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyPlan> {
    let set = overrides(kwargs)?;
    let kind = match kind {
        "stability" => {
            let (Some(x), Some(y)) = (x, y) else {
                return Err(PyTypeError::new_err("sweep_stability needs x and y"));
            };
            Kind::Stability(Box::new(Stability {
                x: axis("x", x)?,
                y: axis("y", y)?,
                growth,
                monitor: monitor.unwrap_or_default(),
            }))
        }
        "convergence" => {
            let (Some(steps), Some(columns)) = (steps, columns) else {
                return Err(PyTypeError::new_err(
                    "sweep_convergence needs steps and columns",
                ));
            };
            let reference = ReferenceSpec::parse_cli(reference.unwrap_or("finest"))
                .map_err(|e| study_failure(&e))?;
            Kind::Convergence(Convergence {
                steps,
                reference,
                columns,
            })
        }
        other => {
            return Err(PyTypeError::new_err(format!(
                "unknown sweep '{other}': expected stability or convergence"
            )))
        }
    };
    let system = match (&path, text) {
        (Some(path), _) => SystemSpec::from_file(path),
        (None, Some(text)) => SystemSpec::from_toml(text),
        (None, None) => return Err(PyTypeError::new_err("no system given")),
    }
    .map_err(|e| failure(kind_of(&e), message(&e), None))?;
    // The settings act on the system like `tether run`'s keywords (errors
    // show here, before any run) and hold for every run of the study.
    let mut applied = system.clone();
    set.apply(&mut applied)
        .map_err(|e| failure("settings", e.to_string(), None))?;
    let study = Study::sweep(
        path.unwrap_or_default(),
        &applied,
        set,
        kind,
        name,
        formats.unwrap_or_else(|| vec!["svg".into()]),
    )
    .map_err(|e| study_failure(&e))?;
    PyPlan::new(py, study, &system)
}

/// The plan of a study file (`tether study FILE`).
#[pyfunction]
pub(crate) fn plan_study(py: Python<'_>, path: PathBuf) -> PyResult<PyPlan> {
    let study = Study::from_file(&path).map_err(|e| study_failure(&e))?;
    let system =
        SystemSpec::from_file(&study.system).map_err(|e| study_failure(&StudyError::Master(e)))?;
    PyPlan::new(py, study, &system)
}

/// Run the jobs `indices` of the plan written as `payload` one after the
/// other, without the GIL: what an executor's worker does. Returns one
/// plain tuple per job (see [`job_to_py`]).
#[pyfunction]
pub(crate) fn run_jobs(
    py: Python<'_>,
    payload: String,
    indices: Vec<usize>,
) -> PyResult<Vec<Py<PyAny>>> {
    let results = py
        .detach(move || Plan::from_toml(&payload)?.run_jobs(&indices))
        .map_err(|e| study_failure(&e))?;
    results.iter().map(|r| job_to_py(py, r)).collect()
}

/// A job's result as plain Python values (any executor can send them):
/// `("cell", x, y, class, reached, reason)` or `("run", source, columns,
/// times, values, incomplete, outcome, message)`.
fn job_to_py(py: Python<'_>, result: &JobResult) -> PyResult<Py<PyAny>> {
    let tuple = match result {
        JobResult::Cell(c) => ("cell", c.x, c.y, c.class.word(), c.reached, &c.reason)
            .into_pyobject(py)?
            .into_any(),
        JobResult::Run(r) => {
            let t = &r.table;
            (
                "run",
                &t.source,
                &t.columns,
                &t.times,
                &t.values,
                &t.incomplete,
                r.outcome.word(),
                r.outcome.message(),
            )
                .into_pyobject(py)?
                .into_any()
        }
    };
    Ok(tuple.unbind())
}

fn job_from_py(value: &Bound<'_, PyAny>) -> PyResult<JobResult> {
    let bad = || PyTypeError::new_err("not a job result of tether's run_jobs");
    let tag: String = value.get_item(0).map_err(|_| bad())?.extract()?;
    match tag.as_str() {
        "cell" => {
            let (_, x, y, class, reached, reason): (String, f64, f64, String, f64, String) =
                value.extract()?;
            let class = match class.as_str() {
                "stable" => Class::Stable,
                "unstable" => Class::Unstable,
                "failed" => Class::Failed,
                _ => return Err(bad()),
            };
            Ok(JobResult::Cell(Cell {
                x,
                y,
                class,
                reached,
                reason,
            }))
        }
        "run" => {
            #[allow(clippy::type_complexity)]
            let (_, source, columns, times, values, incomplete, outcome, message): (
                String,
                String,
                Vec<String>,
                Vec<f64>,
                Vec<Vec<f64>>,
                Option<String>,
                String,
                Option<String>,
            ) = value.extract()?;
            let message = message.unwrap_or_default();
            let outcome = match outcome.as_str() {
                "completed" => Outcome::Completed,
                "diverged" => Outcome::Diverged(message),
                "failed" => Outcome::Failed(message),
                _ => return Err(bad()),
            };
            Ok(JobResult::Run(RunResult {
                table: Table {
                    source,
                    columns,
                    times,
                    values,
                    incomplete,
                },
                outcome,
            }))
        }
        _ => Err(bad()),
    }
}

#[pymethods]
impl PyPlan {
    /// The plan as TOML text, for the workers.
    #[getter]
    fn payload(&self) -> &str {
        &self.payload
    }

    /// The number of jobs (runs).
    #[getter]
    fn jobs(&self) -> usize {
        self.jobs
    }

    /// `stability`, `convergence` or `series`.
    #[getter]
    fn kind(&self) -> &'static str {
        match self.study.kind {
            Kind::Series(_) => "series",
            Kind::Convergence(_) => "convergence",
            Kind::Stability(_) => "stability",
        }
    }

    /// Run every job here, in parallel over the cores (as `tether study`
    /// does), with the GIL released; Python's signal handlers run every
    /// 50 ms, Ctrl-C stops the study (no further run starts).
    /// `progress(done, total)` is called as often. Returns the results as
    /// [`finish`](Self::finish) does.
    #[pyo3(signature = (out_dir=None, progress=None))]
    fn run_local(
        &self,
        py: Python<'_>,
        out_dir: Option<PathBuf>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Py<PyAny>> {
        let done = AtomicUsize::new(0);
        let go_on = AtomicBool::new(true);
        let finished = AtomicBool::new(false);
        let mut pending: Option<PyErr> = None;
        let outcome = std::thread::scope(|scope| {
            let worker = scope.spawn(|| {
                let results = self.plan.run_all(&|| {
                    done.fetch_add(1, Ordering::Relaxed);
                    go_on.load(Ordering::Relaxed)
                });
                finished.store(true, Ordering::Release);
                results
            });
            loop {
                let over = py.detach(|| {
                    let since = Instant::now();
                    while !finished.load(Ordering::Acquire) && since.elapsed() < SIGNAL_INTERVAL {
                        std::thread::sleep(Duration::from_millis(2));
                    }
                    finished.load(Ordering::Acquire)
                });
                if pending.is_none() {
                    let call = match &progress {
                        Some(f) => f
                            .call1(py, (done.load(Ordering::Relaxed), self.jobs))
                            .map(drop),
                        None => Ok(()),
                    };
                    if let Err(e) = call.and_then(|()| py.check_signals()) {
                        go_on.store(false, Ordering::Relaxed);
                        pending = Some(e);
                    }
                }
                if over {
                    break;
                }
            }
            worker.join()
        });
        let results = match outcome {
            Ok(results) => results,
            Err(_) => {
                return Err(failure(
                    "other",
                    "a study run panicked (a bug in Tether; please report it)".into(),
                    None,
                ))
            }
        };
        match (results, pending) {
            (Err(e @ StudyError::Interrupted { .. }), Some(err))
                if err.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py) =>
            {
                Err(study_failure(&e))
            }
            (_, Some(err)) => Err(err),
            (Err(e), None) => Err(study_failure(&e)),
            (Ok(results), None) => self.report(py, &results, out_dir),
        }
    }

    /// Put the results of every job (the tuples of [`run_jobs`], in job
    /// order) together, write the files into `out_dir` if given, and return
    /// a dict: `kind`, `summary`, `files`, and `maps` (stability), `curves`
    /// and `columns` (convergence) or `runs` (series).
    #[pyo3(signature = (results, out_dir=None))]
    fn finish(
        &self,
        py: Python<'_>,
        results: Vec<Bound<'_, PyAny>>,
        out_dir: Option<PathBuf>,
    ) -> PyResult<Py<PyAny>> {
        if results.len() != self.jobs {
            return Err(failure(
                "other",
                format!(
                    "{} job results for a study of {} jobs",
                    results.len(),
                    self.jobs
                ),
                None,
            ));
        }
        let jobs = results
            .iter()
            .map(job_from_py)
            .collect::<PyResult<Vec<_>>>()?;
        let results = py
            .detach(|| self.plan.results(jobs))
            .map_err(|e| study_failure(&e))?;
        self.report(py, &results, out_dir)
    }
}

impl PyPlan {
    fn report(
        &self,
        py: Python<'_>,
        results: &StudyResults,
        out_dir: Option<PathBuf>,
    ) -> PyResult<Py<PyAny>> {
        let report = py
            .detach(|| self.study.report(results, out_dir.as_deref()))
            .map_err(|e| study_failure(&e))?;
        let d = PyDict::new(py);
        d.set_item("kind", self.kind())?;
        d.set_item("title", &self.study.title)?;
        d.set_item("summary", &report.summary)?;
        let files: Vec<String> = report
            .files
            .iter()
            .map(|f| f.display().to_string())
            .collect();
        d.set_item("files", files)?;
        match (results, &self.study.kind) {
            (StudyResults::Stability(maps), Kind::Stability(s)) => {
                let (xs, ys) = s.validate().map_err(|e| study_failure(&e))?;
                let list = PyList::empty(py);
                for m in maps {
                    let map = PyDict::new(py);
                    map.set_item("label", &m.label)?;
                    map.set_item("x", &xs)?;
                    map.set_item("y", &ys)?;
                    map.set_item("x_label", s.x.title())?;
                    map.set_item("y_label", s.y.title())?;
                    let class: Vec<&str> = m.cells.iter().map(|c| c.class.word()).collect();
                    let reached: Vec<f64> = m.cells.iter().map(|c| c.reached).collect();
                    let reason: Vec<&str> = m.cells.iter().map(|c| c.reason.as_str()).collect();
                    map.set_item("class", class)?;
                    map.set_item("reached", reached)?;
                    map.set_item("reason", reason)?;
                    list.append(map)?;
                }
                d.set_item("maps", list)?;
            }
            (StudyResults::Convergence(curves), Kind::Convergence(c)) => {
                d.set_item("columns", &c.columns)?;
                let list = PyList::empty(py);
                for curve in curves {
                    let x = PyDict::new(py);
                    x.set_item("label", &curve.label)?;
                    x.set_item("order", curve.order)?;
                    let p = &curve.points;
                    x.set_item("step", p.iter().map(|p| p.step).collect::<Vec<_>>())?;
                    x.set_item("error", p.iter().map(|p| p.error).collect::<Vec<_>>())?;
                    x.set_item("errors", p.iter().map(|p| &p.errors).collect::<Vec<_>>())?;
                    x.set_item(
                        "outcome",
                        p.iter().map(|p| p.outcome.word()).collect::<Vec<_>>(),
                    )?;
                    x.set_item(
                        "message",
                        p.iter()
                            .map(|p| p.outcome.message().unwrap_or(""))
                            .collect::<Vec<_>>(),
                    )?;
                    list.append(x)?;
                }
                d.set_item("curves", list)?;
            }
            (StudyResults::Series(runs), _) => {
                let list = PyList::empty(py);
                for run in runs {
                    list.append(series_result(py, run)?)?;
                }
                d.set_item("runs", list)?;
            }
            _ => return Err(failure("other", "results of another study".into(), None)),
        }
        Ok(d.into_any().unbind())
    }
}

/// A series run as the `(columns, data, stats)` of a `tether.Result`.
fn series_result(py: Python<'_>, run: &RunResult) -> PyResult<Py<PyAny>> {
    let t = &run.table;
    let mut rows = Rows {
        columns: t.columns.clone(),
        bytes: Vec::with_capacity(t.times.len() * (t.columns.len() + 1) * 8),
        rounded: Vec::new(),
        texts: Vec::new(),
    };
    let mut row = vec![0.0; t.columns.len()];
    for (i, &time) in t.times.iter().enumerate() {
        for (v, column) in row.iter_mut().zip(&t.values) {
            *v = column[i];
        }
        rows.push(time, &row);
    }
    let stats = PyDict::new(py);
    stats.set_item("label", &t.source)?;
    stats.set_item("macro_steps", t.times.len().saturating_sub(1))?;
    stats.set_item("stop_reason", run.outcome.message().unwrap_or("completed"))?;
    rows.into_py(py, stats.into_any().unbind())
}
