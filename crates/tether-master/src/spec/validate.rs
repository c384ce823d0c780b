//! Reading a system file and checking its own consistency, and the macro grid
//! it asks for.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::spec::{InitialMultiplier, JointInitial, SystemSpec};
use crate::{MasterError, Method};

impl SystemSpec {
    /// Read a system file; relative FMU paths are resolved against its folder.
    pub fn from_file(path: &Path) -> Result<SystemSpec, MasterError> {
        let fail = |reason: String| MasterError::SystemFile {
            path: path.to_path_buf(),
            reason,
        };
        let unreadable = |e: std::io::Error| {
            fail(if e.kind() == std::io::ErrorKind::NotFound {
                // Where it was looked for, and a name that differs in case.
                let place = tether_fmi::paths::Missing::new(path, None);
                format!("cannot access {}: {e}{}", place.located(), place.hint())
            } else {
                e.to_string()
            })
        };
        // A FIFO or a device is refused before it is opened: the open of a
        // FIFO waits for a writer that may never come.
        let metadata = std::fs::metadata(path).map_err(unreadable)?;
        if let Some(kind) = tether_fmi::special_file_kind(&metadata) {
            return Err(fail(format!("is a {kind}, not a regular file")));
        }
        let text = std::fs::read_to_string(path).map_err(unreadable)?;
        let mut spec = SystemSpec::from_toml(&text).map_err(|e| match e {
            MasterError::SystemFile { reason, .. } => MasterError::SystemFile {
                path: path.to_path_buf(),
                reason,
            },
            other => other,
        })?;
        spec.source = Some(path.to_path_buf());
        let base = path.parent().unwrap_or(Path::new("."));
        for inst in &mut spec.instances {
            if inst.fmu.is_relative() {
                inst.fmu = base.join(&inst.fmu);
            }
            if let Some(token) = inst.token_file.as_mut().filter(|t| t.is_relative()) {
                *token = base.join(&*token);
            }
        }
        Ok(spec)
    }

    /// Read a system description from TOML text (paths are left as written).
    pub fn from_toml(text: &str) -> Result<SystemSpec, MasterError> {
        let error = |reason: String| MasterError::SystemFile {
            path: PathBuf::from("<text>"),
            reason: reason.replace('\n', " ").trim().to_string(),
        };
        // Array blocks (`count = N`) are expanded first (crate::spec::arrays).
        match text.parse::<toml::Table>() {
            Ok(mut table) if crate::spec::arrays::has_arrays(&table) => {
                crate::spec::arrays::expand(&mut table).map_err(|e| {
                    match crate::spec::arrays::block_line(text, e.section, e.block) {
                        Some(line) => error(format!("line {line}: {}", e.message)),
                        None => error(e.message),
                    }
                })?;
                return SystemSpec::deserialize(table).map_err(|e| error(e.to_string()));
            }
            Err(e) => {
                if let Some(reason) = count_out_of_range(text, &e) {
                    return Err(error(reason));
                }
            }
            Ok(_) => {}
        }
        toml::from_str(text).map_err(|e| error(crate::spec::toml_error(text, &e)))
    }

    /// The file named in errors: [`source`](Self::source), else `<system>`.
    pub(crate) fn source_name(&self) -> PathBuf {
        self.source
            .clone()
            .unwrap_or_else(|| PathBuf::from("<system>"))
    }

    /// `[signals]`: the iteration keys fit together (one line naming the key).
    fn validate_signals(&self) -> Result<(), MasterError> {
        let s = &self.signals;
        let fail = |reason: &str| MasterError::SystemFile {
            path: self.source_name(),
            reason: format!("[signals] {reason}"),
        };
        if s.solver == Some(crate::spec::SignalSolver::Newton) && s.scheme.is_some() {
            return Err(fail(
                "scheme does not apply with solver = \"newton\": Newton updates every \
                 connection's value at once; remove the scheme key",
            ));
        }
        match s.iterations {
            Some(0) => Err(fail(
                "iterations = 0: give the most repetitions of a macro step (at least 1), \
                 or leave the key out to run each step once",
            )),
            Some(_) if self.connections.is_empty() => Err(fail(
                "iterations: the system has no [[connection]] whose values could be iterated",
            )),
            Some(_) if self.step_control.is_some() => Err(fail(
                "iterations: not available with [step_control] (adaptive steps); use a fixed \
                 macro step",
            )),
            None if s.solver.is_some() || s.strict => Err(fail(&format!(
                "{} needs iterations = N (the most repetitions or Newton updates per macro step)",
                if s.strict { "strict" } else { "solver" }
            ))),
            _ => Ok(()),
        }
    }

    /// Check what can be checked without the FMUs: times, settings, names.
    pub fn validate(&self) -> Result<(), MasterError> {
        // The sizes first: everything after allocates with them.
        for (section, n) in [
            ("instance", self.instances.len()),
            ("constraint", self.constraints.len()),
            ("joint", self.joints.len()),
            ("coupling_variable", self.coupling_variables.len()),
            ("connection", self.connections.len()),
        ] {
            let limit = crate::spec::arrays::limit(section);
            if n > limit {
                return Err(MasterError::SystemFile {
                    path: self.source_name(),
                    reason: format!(
                        "{n} [[{section}]] blocks, above the limit of {limit} (docs/system-file.md, \"Limits\")"
                    ),
                });
            }
        }
        let e = &self.experiment;
        let param = |name: &str, value: f64, expected: &str| MasterError::InvalidParameter {
            name: name.into(),
            value,
            expected: expected.into(),
        };
        if !e.start.is_finite() {
            return Err(param("start", e.start, "a finite start time"));
        }
        if !e.step.is_finite() || e.step <= 0.0 {
            return Err(param("step", e.step, "a finite macro-step size > 0"));
        }
        if !e.stop.is_finite() || e.stop <= e.start {
            return Err(param(
                "stop",
                e.stop,
                "a finite stop time after the start time",
            ));
        }
        if let Some(tol) = e.tolerance {
            if !tol.is_finite() || tol <= 0.0 {
                return Err(param("tolerance", tol, "a finite tolerance > 0"));
            }
        }
        if let Some(tol) = self.signals.tolerance {
            if !tol.is_finite() || tol <= 0.0 {
                return Err(param(
                    "[signals] tolerance",
                    tol,
                    "a finite relative tolerance > 0",
                ));
            }
        }
        self.validate_signals()?;
        self.method.validate()?;
        // Adaptive steps land on any output grid (docs/system-file.md).
        if self.step_control.is_none() {
            self.output.every(e.step)?;
        }
        let c = &self.coupling;
        if c.order > 2 {
            return Err(param(
                "order",
                c.order as f64,
                "a polynomial degree k of 0, 1 or 2",
            ));
        }
        if !c.epsilon.is_finite() || c.epsilon <= 0.0 || c.epsilon >= 1.0 {
            return Err(param("epsilon", c.epsilon, "a finite increment in (0, 1)"));
        }
        if let Some(threads) = c.threads.filter(|&n| n == 0 || n > 1024) {
            return Err(param(
                "threads",
                threads as f64,
                "a number of threads from 1 (the main thread alone) to 1024",
            ));
        }
        if !c.max_condition.is_finite() || c.max_condition <= 1.0 {
            return Err(param(
                "max_condition",
                c.max_condition,
                "a finite number > 1",
            ));
        }
        if !c.divergence_factor.is_finite() || c.divergence_factor <= 1.0 {
            return Err(param(
                "divergence_factor",
                c.divergence_factor,
                "a finite number > 1",
            ));
        }
        if !c.residual_warning.is_finite() || c.residual_warning <= 0.0 {
            return Err(param(
                "residual_warning",
                c.residual_warning,
                "a finite number > 0",
            ));
        }
        if let Some(l) = c.residual_limit.0.filter(|l| !l.is_finite() || *l <= 0.0) {
            return Err(param("residual_limit", l, "a finite number > 0 or \"off\""));
        }
        for i in &self.instances {
            let remote = |key: &str, reason: String| MasterError::SystemFile {
                path: self.source_name(),
                reason: format!("instance '{}': {key}: {reason}", i.name),
            };
            match (&i.host, &i.token_file) {
                (Some(host), Some(_)) => {
                    tether_fmi::remote::tcp::RemoteHost::parse_address(host)
                        .map_err(|reason| remote("host", reason))?;
                }
                (Some(_), None) => {
                    return Err(remote(
                        "host",
                        "needs token_file, the file holding the host's token".into(),
                    ))
                }
                (None, Some(_)) => return Err(remote("token_file", "given without host".into())),
                (None, None) => {}
            }
            if let Some(path) = &i.fmu_on_host {
                if i.host.is_none() {
                    return Err(remote("fmu_on_host", "given without host".into()));
                }
                if !path.is_absolute() {
                    return Err(remote(
                        "fmu_on_host",
                        format!("'{}' is not an absolute path on the host", path.display()),
                    ));
                }
            }
            for (resource, &amount) in &i.resources {
                if resource.trim().is_empty() {
                    return Err(remote("resources", "a resource needs a name".into()));
                }
                if !amount.is_finite() || amount <= 0.0 {
                    return Err(remote(
                        "resources",
                        format!("{resource} = {amount}: expected a finite number of units > 0"),
                    ));
                }
            }
            if let Some(integrator) = &i.integrator {
                integrator
                    .integrator()
                    .map_err(|reason| remote("integrator", reason))?;
                if i.fmi_type == crate::spec::InterfaceChoice::CoSimulation {
                    return Err(remote(
                        "integrator",
                        "applies to model exchange, and fmi_type is \"co_simulation\"".into(),
                    ));
                }
            }
            if let Some(t) = i.call_timeout.filter(|t| !t.is_finite() || *t <= 0.0) {
                return Err(param(
                    &format!("{}.call_timeout", i.name),
                    t,
                    "a finite time in seconds > 0",
                ));
            }
        }
        if c.iterations == 0 || c.iterations > 1000 {
            return Err(param(
                "iterations",
                c.iterations as f64,
                "a number of corrections per step from 1 to 1000",
            ));
        }
        if !c.iteration_tol.is_finite() || c.iteration_tol <= 0.0 {
            return Err(param(
                "iteration_tol",
                c.iteration_tol,
                "a finite number > 0",
            ));
        }
        if c.jacobian_max_age == 0 {
            return Err(param("jacobian_max_age", 0.0, "at least 1 step"));
        }
        if matches!(self.method, Method::Explicit { .. }) && c.order != 0 {
            return Err(param(
                "order",
                c.order as f64,
                "0: the explicit method holds the multipliers constant over a step",
            ));
        }
        if let Some(control) = &self.step_control {
            if matches!(self.method, Method::Explicit { .. }) {
                return Err(param(
                    "step_control",
                    control.rtol,
                    "the predictor/corrector methods (baumgarte, weighted): \
                     the explicit method has no error estimate",
                ));
            }
            control.limits(e.start, e.stop, e.step)?;
        }
        if self.instances.is_empty() {
            return Err(MasterError::SystemFile {
                path: self.source_name(),
                reason: "no [[instance]] given".into(),
            });
        }
        let mut seen = std::collections::HashSet::new();
        for name in self
            .instances
            .iter()
            .map(|i| &i.name)
            .chain(self.constraints.iter().map(|c| &c.name))
            .chain(self.joints.iter().map(|j| &j.name))
            .chain(self.coupling_variables.iter().map(|v| &v.name))
        {
            let valid = name
                .chars()
                .next()
                .is_some_and(|c| c.is_alphabetic() || c == '_')
                && name.chars().all(|c| c.is_alphanumeric() || c == '_');
            if !valid {
                return Err(MasterError::SystemFile {
                    path: self.source_name(),
                    reason: format!(
                        "name '{name}' must start with a letter and contain only letters, digits and '_'"
                    ),
                });
            }
            if !seen.insert(name.clone()) {
                return Err(MasterError::SystemFile {
                    path: self.source_name(),
                    reason: format!("name '{name}' is used twice"),
                });
            }
        }
        for c in &self.connections {
            for (what, v) in [("gain", c.gain), ("offset", c.offset)] {
                if let Some(v) = v.filter(|v| !v.is_finite()) {
                    return Err(param(
                        &format!("{what} of the connection to {}", c.to),
                        v,
                        "a finite number",
                    ));
                }
            }
        }
        for joint in &self.joints {
            for (side, v) in [
                ("axis_i", joint.axis_i),
                ("ref_i", joint.ref_i),
                ("axis_j", joint.axis_j),
                ("ref_j", joint.ref_j),
                ("offset_i", joint.offset_i),
                ("offset_j", joint.offset_j),
            ] {
                if let Some(v) = v {
                    if let Some(bad) = v.iter().find(|x| !x.is_finite()) {
                        return Err(param(
                            &format!("{}.{side}", joint.name),
                            *bad,
                            "finite vector components",
                        ));
                    }
                }
            }
            if let JointInitial::Values(values) = &joint.initial {
                if let Some(bad) = values.iter().find(|x| !x.is_finite()) {
                    return Err(param(
                        &format!("{}.initial", joint.name),
                        *bad,
                        "finite multipliers",
                    ));
                }
            }
        }
        let initials = self
            .constraints
            .iter()
            .map(|c| (&c.name, c.initial))
            .chain(self.coupling_variables.iter().map(|c| (&c.name, c.initial)));
        for (name, initial) in initials {
            if let InitialMultiplier::Value(v) = initial {
                if !v.is_finite() {
                    return Err(param(&format!("{name}.initial"), v, "a finite number"));
                }
            }
        }
        self.validate_export()
    }

    /// Number of macro steps: the stop time rounded to the grid `start + n·step`.
    /// The time the run ends at: `start + macro_steps()·step`, which differs
    /// from `stop` when `stop` is not on the macro grid.
    pub fn end_time(&self) -> f64 {
        let e = &self.experiment;
        if self.step_control.is_some() {
            return e.stop;
        }
        e.start + self.macro_steps() as f64 * e.step
    }

    /// Refuses a `stop` off the macro grid of a fixed-step run (beyond a
    /// relative 1e-9 of a step), naming the nearest grid point. Runs that
    /// rely on rounding (studies over several steps) call [`Self::end_time`].
    pub fn check_grid(&self) -> Result<(), MasterError> {
        let e = &self.experiment;
        // A step or span that is invalid in itself is validation's to report.
        let valid = e.step.is_finite() && e.step > 0.0 && e.stop.is_finite() && e.stop > e.start;
        if self.step_control.is_some() || !valid {
            return Ok(());
        }
        let end = self.end_time();
        if (end - e.stop).abs() <= 1e-9 * e.step {
            return Ok(());
        }
        Err(MasterError::InvalidParameter {
            name: "stop".into(),
            value: e.stop,
            expected: format!(
                "a point of the macro grid start + n·step (start = {}, step = {}); the nearest is {} \
                 (or give a step that divides stop - start, or adaptive steps)",
                e.start,
                e.step,
                tidy(end)
            ),
        })
    }

    pub fn macro_steps(&self) -> u64 {
        let e = &self.experiment;
        let n = ((e.stop - e.start) / e.step).round();
        (n.max(1.0)) as u64
    }
}

/// `x` without the last digits of rounding (`0.8999999999999999` is `0.9`),
/// for messages: twelve significant digits.
pub(crate) fn tidy(x: f64) -> f64 {
    format!("{x:.11e}").parse().unwrap_or(x)
}

/// A `count = N` beyond what TOML's integers hold (the reader refuses the
/// number, before any block is known): the line, the block and the range.
fn count_out_of_range(text: &str, e: &toml::de::Error) -> Option<String> {
    let at = e.span()?.start.min(text.len());
    let line = text[..at].matches('\n').count();
    let lines: Vec<&str> = text.lines().collect();
    let (key, value) = lines.get(line)?.split_once('=')?;
    if key.trim() != "count" {
        return None;
    }
    // The block: the last `[[section]]` header above, and how many before it.
    let bare = |l: &str| l.chars().filter(|c| !c.is_whitespace()).collect::<String>();
    let header = lines[..line]
        .iter()
        .rev()
        .map(|l| bare(l))
        .find(|l| l.starts_with('['))?;
    let section = header.strip_prefix("[[")?.split("]]").next()?.to_string();
    let block = lines[..line]
        .iter()
        .filter(|l| bare(l).starts_with(&format!("[[{section}]]")))
        .count();
    let limit = crate::spec::arrays::limit(&section);
    Some(format!(
        "line {}: [[{section}]] block {block} (count = {}): count must be an integer from 0 to {limit}",
        line + 1,
        value.split('#').next().unwrap_or("").trim()
    ))
}
