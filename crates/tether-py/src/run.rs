//! A whole run with the GIL released: `tether.run`.

use super::*;
use crate::results::{stats_dict, Rows, Signals};
use crate::system::load_spec;

/// Run a system to its stop time with the GIL released; returns
/// `(columns, data, stats)`.
#[pyfunction]
#[pyo3(signature = (path=None, text=None, progress=None, **kwargs))]
pub(crate) fn run(
    py: Python<'_>,
    path: Option<PathBuf>,
    text: Option<&str>,
    progress: Option<Py<PyAny>>,
    kwargs: Option<&Bound<'_, PyDict>>,
) -> PyResult<Py<PyAny>> {
    // `_ssp` keeps an extracted archive's FMUs until the run ends.
    let (spec, _ssp) = load_spec(path, text, kwargs)?;
    let ssp_notes = _ssp.as_ref().map(|l| l.notes.clone()).unwrap_or_default();
    // A divergence of a formulation known to be unstable says so again, as the CLI does.
    let unstable = spec.method.stability_warning(spec.coupling.order);
    let outcome = py.detach(move || -> Result<_, MasterError> {
        spec.check_grid()?;
        let mut sim = Simulation::new(&spec).map_err(|e| e.located(&spec, |_, _| None))?;
        let notes = (
            [ssp_notes, sim.notes().to_vec()].concat(),
            sim.warnings().to_vec(),
        );
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
            let stats = stats_dict(py, &stats, "completed", (&notes.0, &notes.1))?
                .into_any()
                .unbind();
            rows.into_py(py, stats)
        }
        Ok((rows, Err(e), stats, notes)) => {
            let stats = stats_dict(py, &stats, &message(&e), (&notes.0, &notes.1))?
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
