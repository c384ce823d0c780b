//! Systems and overrides: system files and SSPs read into a `SystemSpec`, the
//! keyword arguments that override it, and TOML values to and from Python.

use super::*;

/// A start value from a Python bool, int, float or str, or a list or tuple of
/// them (an FMI 3.0 array, flat row-major or nested).
pub(crate) fn start_value(value: &Bound<'_, PyAny>) -> PyResult<StartValue> {
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
pub(crate) fn overrides(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Overrides> {
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
            "threads" => {
                if !value.is_none() {
                    o.threads = Some(value.extract()?);
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
                     mu, order, epsilon, parallel, threads, divergence_factor, iterations, iteration_tol, step_rtol, step_atol, jacobian or \
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
pub(crate) fn load_spec(
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
pub(crate) fn toml_to_py<'py>(py: Python<'py>, value: &toml::Value) -> PyResult<Bound<'py, PyAny>> {
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
pub(crate) fn py_to_toml(value: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
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
pub(crate) fn load_system<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyAny>> {
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
pub(crate) fn dump_toml(value: &Bound<'_, PyAny>) -> PyResult<String> {
    let value = py_to_toml(value)?;
    toml::to_string(&value).map_err(|e| PyValueError::new_err(e.to_string()))
}
