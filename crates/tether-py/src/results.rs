//! Results in memory for Python: the rows of a run as one `bytes` object
//! (`Rows`), the GIL taken back to look for Ctrl-C (`Signals`), and the run
//! summary as a dict.

use super::*;

/// The rows of a run as native-endian f64 bytes: `time, values…` per row.
#[derive(Default)]
pub(crate) struct Rows {
    pub(crate) columns: Vec<String>,
    pub(crate) bytes: Vec<u8>,
    /// Columns that held an integer a float rounds (beyond ±2^53).
    pub(crate) rounded: Vec<usize>,
    /// The String columns: each one's index and its text in every row.
    pub(crate) texts: Vec<(usize, Vec<String>)>,
}

impl Rows {
    pub(crate) fn push(&mut self, time: f64, values: &[f64]) {
        self.bytes.extend_from_slice(&time.to_ne_bytes());
        for v in values {
            self.bytes.extend_from_slice(&v.to_ne_bytes());
        }
    }

    /// A row's String values (by column index), after [`push`](Self::push).
    pub(crate) fn push_texts(&mut self, strings: &[(usize, String)]) {
        for (k, text) in strings {
            match self.texts.iter_mut().find(|(j, _)| j == k) {
                Some((_, column)) => column.push(text.clone()),
                None => self.texts.push((*k, vec![text.clone()])),
            }
        }
    }

    /// `(columns, data, stats)` for the Python `Result`, with a fourth
    /// item when there are String columns: `{column: [text per row]}`; a
    /// `UserWarning` names the columns whose integers the floats rounded.
    pub(crate) fn into_py(self, py: Python<'_>, stats: Py<PyAny>) -> PyResult<Py<PyAny>> {
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
        if self.texts.is_empty() {
            let tuple = (self.columns, data, stats).into_pyobject(py)?;
            return Ok(tuple.into_any().unbind());
        }
        let texts = PyDict::new(py);
        for (k, column) in &self.texts {
            texts.set_item(&self.columns[*k], column)?;
        }
        let tuple = (self.columns, data, stats, texts).into_pyobject(py)?;
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
        if !sample.strings.is_empty() {
            self.push_texts(sample.strings);
        }
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
pub(crate) struct Signals {
    last: Instant,
    /// The callback and the run's number of steps.
    progress: Option<(Py<PyAny>, u64)>,
    /// The last step handed over.
    step: u64,
}

impl Signals {
    pub(crate) fn new(progress: Option<(Py<PyAny>, u64)>) -> Signals {
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
pub(crate) fn interrupt_reason(err: PyErr, py: Python<'_>) -> Option<String> {
    if err.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py) {
        Some(INTERRUPT_REASON.to_string())
    } else {
        Some(err.to_string())
    }
}

/// The run summary of `RunStats` (its serde schema, docs/run-summary.md:
/// the same as `tether run --summary-json`), with `stop_reason` as the
/// package words it and the summary text `tether run` prints.
pub(crate) fn stats_dict<'py>(
    py: Python<'py>,
    stats: &RunStats,
    stop_reason: &str,
    (notes, warnings): (&[String], &[String]),
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
    // The setup's warnings (the CLI's `warning:` lines): parameters an FMU
    // changed in its initialization.
    d.set_item("warnings", warnings.to_vec())?;
    Ok(d)
}
