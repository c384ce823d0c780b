//! Counters of a run: what the algorithm asked of the FMUs and where the time went.

use std::fmt;

use serde::ser::{SerializeMap, Serializer};
use serde::Serialize;
use std::time::{Duration, Instant};

/// FMI calls made on one instance.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct InstanceCounters {
    /// Instance name.
    pub name: String,
    /// The model it instantiates (`modelName`), for the summary's per-model lines.
    pub model: String,
    /// `fmi2DoStep` calls.
    pub do_steps: u64,
    /// `fmi2GetFMUstate` calls.
    pub state_gets: u64,
    /// `fmi2SetFMUstate` calls.
    pub state_sets: u64,
    /// `fmi2SetReal` calls (coupled inputs).
    pub set_reals: u64,
    /// `fmi2GetReal` calls (coupled and recorded outputs).
    pub get_reals: u64,
    /// `fmi2GetInteger` calls (recorded Integer and Enumeration outputs).
    pub get_integers: u64,
    /// `fmi2GetBoolean` calls (recorded Boolean outputs).
    pub get_booleans: u64,
    /// `fmi2SetInteger` calls (Integer signal connections).
    pub set_integers: u64,
    /// `fmi2SetBoolean` calls (Boolean signal connections).
    pub set_booleans: u64,
    /// `fmi2GetString` calls (recorded String outputs, String signal
    /// connections).
    pub get_strings: u64,
    /// `fmi2SetString` calls (String signal connections).
    pub set_strings: u64,
    /// The FMI functions these counts stand for, by the FMU's standard and
    /// variable types (`fmi2SetReal`, `fmi3SetFloat64`, …).
    pub functions: CallNames,
    /// `fmi2SetRealInputDerivatives` calls.
    pub set_input_derivatives: u64,
    /// `fmi2GetRealOutputDerivatives` calls.
    pub get_output_derivatives: u64,
    /// Messages to and from the instance's host process (0 in process):
    /// [`FmuInstance::round_trips`](tether_fmi::FmuInstance::round_trips).
    pub round_trips: u64,
}

/// The names of the FMI functions an instance's counts stand for: FMI 2.0's,
/// or FMI 3.0's for the types of its inputs and outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CallNames {
    /// FMI 3.0 (`fmi3DoStep`, …), else FMI 2.0.
    pub fmi3: bool,
    /// FMI 3.0: the float type set (`Float64`, or `Float64/Float32` where
    /// the inputs have both).
    pub set_float: &'static str,
    /// FMI 3.0: the float type read.
    pub get_float: &'static str,
    /// FMI 3.0: the integer type set (`Int32`, …; `Int*` for several).
    pub set_int: &'static str,
    /// FMI 3.0: the integer type read.
    pub get_int: &'static str,
    /// A model-exchange instance: its steps are integrations, its states
    /// saved and restored by the instance (with the FMU's where it has them).
    pub model_exchange: bool,
}

impl Default for CallNames {
    fn default() -> Self {
        CallNames {
            fmi3: false,
            set_float: "Float64",
            get_float: "Float64",
            set_int: "Int32",
            get_int: "Int32",
            model_exchange: false,
        }
    }
}

impl CallNames {
    /// The names for an FMU: FMI 3.0's types of the inputs in `set` (the
    /// value references the master sets; all inputs when empty) and of its
    /// outputs (read).
    pub fn of(md: &tether_fmi::ModelDescription, set: &[u32]) -> CallNames {
        use tether_fmi::{Causality, ValueType};
        if md.standard != tether_fmi::FmiStandard::Fmi3 {
            return CallNames::default();
        }
        let kinds = |causality: Causality| {
            let mut floats: Vec<ValueType> = Vec::new();
            let mut ints: Vec<ValueType> = Vec::new();
            let chosen = |v: &&tether_fmi::ScalarVariable| {
                v.causality == causality
                    && (causality != Causality::Input
                        || set.is_empty()
                        || set.contains(&v.value_reference))
            };
            for v in md.model_variables.iter().filter(chosen) {
                let list = match v.value_type {
                    ValueType::Float32 | ValueType::Float64 => &mut floats,
                    ValueType::Boolean
                    | ValueType::String
                    | ValueType::Binary
                    | ValueType::Clock => continue,
                    _ => &mut ints,
                };
                let ty = if v.value_type == ValueType::Enumeration {
                    ValueType::Int64
                } else {
                    v.value_type
                };
                if !list.contains(&ty) {
                    list.push(ty);
                }
            }
            let float = match floats.as_slice() {
                [ValueType::Float32] => "Float32",
                [_, _] => "Float64/Float32",
                _ => "Float64",
            };
            let int = match ints.as_slice() {
                [] => "Int32",
                [one] => one.name(),
                _ => "Int*",
            };
            (float, int)
        };
        let (set_float, set_int) = kinds(Causality::Input);
        let (get_float, get_int) = kinds(Causality::Output);
        CallNames {
            fmi3: true,
            set_float,
            get_float,
            set_int,
            get_int,
            model_exchange: false,
        }
    }
}

impl InstanceCounters {
    /// Each FMI function called, by its name (`fmi2DoStep`,
    /// `fmi3SetFloat64`, …), with its count; those never called left out.
    pub fn calls(&self) -> Vec<(String, u64)> {
        self.all_calls()
            .into_iter()
            .filter(|(_, count)| *count > 0)
            .collect()
    }

    /// Every function counted, called or not, in a fixed order.
    fn all_calls(&self) -> Vec<(String, u64)> {
        let n = &self.functions;
        let v = if n.fmi3 { "fmi3" } else { "fmi2" };
        let state = if n.fmi3 { "FMUState" } else { "FMUstate" };
        let (set_real, get_real, set_int, get_int) = if n.fmi3 {
            (
                format!("fmi3Set{}", n.set_float),
                format!("fmi3Get{}", n.get_float),
                format!("fmi3Set{}", n.set_int),
                format!("fmi3Get{}", n.get_int),
            )
        } else {
            (
                "fmi2SetReal".to_string(),
                "fmi2GetReal".to_string(),
                "fmi2SetInteger".to_string(),
                "fmi2GetInteger".to_string(),
            )
        };
        let derivatives_in = if n.fmi3 {
            // FMI 3.0 has no input derivatives: the polynomials go to the
            // intermediate update callback, which sets the inputs itself.
            "polynomials for intermediate update".to_string()
        } else {
            "fmi2SetRealInputDerivatives".to_string()
        };
        let derivatives_out = if n.fmi3 {
            "fmi3GetOutputDerivatives"
        } else {
            "fmi2GetRealOutputDerivatives"
        };
        let (step, save, restore) = if n.model_exchange {
            (
                "steps integrated".to_string(),
                "states saved".to_string(),
                "states restored".to_string(),
            )
        } else {
            (
                format!("{v}DoStep"),
                format!("{v}Get{state}"),
                format!("{v}Set{state}"),
            )
        };
        let derivatives_in = if n.model_exchange {
            "input polynomials".to_string()
        } else {
            derivatives_in
        };
        [
            (step, self.do_steps),
            (save, self.state_gets),
            (restore, self.state_sets),
            (set_real, self.set_reals),
            (get_real, self.get_reals),
            (set_int, self.set_integers),
            (get_int, self.get_integers),
            (format!("{v}SetBoolean"), self.set_booleans),
            (format!("{v}GetBoolean"), self.get_booleans),
            (format!("{v}SetString"), self.set_strings),
            (format!("{v}GetString"), self.get_strings),
            (derivatives_in, self.set_input_derivatives),
            (derivatives_out.to_string(), self.get_output_derivatives),
        ]
        .into()
    }
}

/// Wall time spent in each phase of the macro steps. The setup is always
/// timed; the phases only when phase timing is on
/// ([`Simulation::time_phases`](crate::Simulation::time_phases)): it costs
/// five clock reads per macro step, a noticeable part of a step of cheap FMUs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseTimes {
    /// Whether the phases below were timed (otherwise they are zero).
    pub measured: bool,
    /// Initialisation: instantiation, start values, consistent multipliers.
    pub setup: Duration,
    /// Predictor runs (eq. 56–58).
    pub predictor: Duration,
    /// Perturbed runs for the interface Jacobian (eq. 59–64).
    pub jacobian: Duration,
    /// Building and solving the linear systems (eq. 68 / 73–76).
    pub solve: Duration,
    /// Corrector runs.
    pub corrector: Duration,
    /// Observers (recording results), including assembling and checking the
    /// row they receive.
    pub recording: Duration,
}

/// Everything counted during a run, and how it ended. Serialised (serde) as
/// the run summary of `docs/run-summary.md`: `tether run --summary-json`
/// writes it, the Python package's `stats` is the same object.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunStats {
    /// The coupling method and its parameters.
    pub method: crate::Method,
    /// Degree k of the coupling polynomials.
    pub order: usize,
    /// Start time T_0.
    pub start: f64,
    /// Macro-step size H.
    pub step: f64,
    /// The end of the macro grid (`stop` rounded to the grid).
    pub stop: f64,
    /// Time between recorded points (`[output] interval`, a multiple of H).
    pub output_interval: f64,
    /// The time of the last recorded row, if any.
    pub end_time: Option<f64>,
    /// Whether the run reached the stop time, or ended there normally at an
    /// instance's request.
    pub completed: bool,
    /// `completed`, `running`, the instance's request to end, or the error
    /// that stopped the run.
    pub stop_reason: String,
    /// Accepted macro steps.
    pub macro_steps: u64,
    /// Linear solves of the interface Jacobian (one per matrix factorised).
    pub jacobian_solves: u64,
    /// Corrections made (corrector runs), over all accepted macro steps:
    /// one per step unless the correction is iterated (`[coupling] iterations`).
    pub corrections: u64,
    /// The most corrections made in one macro step.
    pub max_corrections: u64,
    /// Macro steps (tries, with adaptive steps) that made the interface
    /// Jacobian from perturbed runs.
    pub jacobians: u64,
    /// Macro steps (tries) that reused the Jacobian with a Broyden update
    /// (`[coupling] jacobian = "reuse"`).
    pub jacobians_reused: u64,
    /// Of `jacobians`: tries whose reused Jacobian mispredicted the
    /// correction, so that it was made afresh and the correction repeated.
    pub jacobians_remade: u64,
    /// Adaptive macro steps (`[step_control]`): what the controller did.
    pub adaptive: Option<AdaptiveStats>,
    /// Iterated signal coupling (`[signals] iterations`): what the
    /// iterations did.
    pub signals: Option<SignalStats>,
    /// Per-instance FMI call counts.
    pub instances: Vec<InstanceCounters>,
    /// Where the time went.
    pub times: PhaseTimes,
    /// Total wall time of [`crate::Simulation::run`] and setup.
    pub wall: Duration,
    /// Parallel runs: workers used and the measurements behind it.
    pub parallel: crate::ParallelInfo,
    /// Set when an instance asked to end the simulation before the stop time
    /// (fmi2Discard with `fmi2Terminated`): the run ended normally there.
    pub termination: Option<Termination>,
    /// Per constraint and joint condition (its `.g` column): the largest
    /// |g| (position-level residual) over the recorded points.
    pub residuals: Vec<(String, f64)>,
    /// The threshold above which the summary warns about a residual
    /// (`[coupling] residual_warning`).
    pub residual_warning: f64,
    /// The |g| beyond which the run fails (`[coupling] residual_limit`;
    /// `None`: off).
    pub residual_limit: Option<f64>,
    /// The error that stopped the run, if any.
    pub failure: Option<Failure>,
}

/// The error that stopped a run, for the run summary's `failure` entry
/// (docs/run-summary.md).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Failure {
    /// [`MasterError::kind`](crate::MasterError::kind): `residual_limit`,
    /// `rollback_check`, `diverged`, `fmi`, …
    pub kind: &'static str,
    /// The one-line error (the run's `stop_reason`).
    pub message: String,
    /// `residual_limit` and `diverged`: the time of the accepted point.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time: Option<f64>,
    /// `residual_limit`: the condition's `.g` column; `diverged`: the
    /// quantity's column.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub column: Option<String>,
    /// `residual_limit`: |g|; `diverged`: the value.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub value: Option<f64>,
    /// `residual_limit`: `[coupling] residual_limit`; `diverged`: the bound
    /// crossed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limit: Option<f64>,
    /// `rollback_check`, `diverged_output`, `non_finite_output`: the instance.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instance: Option<String>,
    /// `rollback_check`, `diverged_output`, `non_finite_output`: its output.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub variable: Option<String>,
    /// `rollback_check` of a periodic check: the time of the last check that
    /// passed; the rows after it were written before this one failed and
    /// are not verified (they stay in the results, named by the trailer).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unverified_after: Option<f64>,
}

impl From<&crate::MasterError> for Failure {
    fn from(error: &crate::MasterError) -> Failure {
        use crate::MasterError as E;
        let mut failure = Failure {
            kind: error.kind(),
            message: error.to_string(),
            time: None,
            column: None,
            value: None,
            limit: None,
            instance: None,
            variable: None,
            unverified_after: None,
        };
        match error {
            E::ResidualLimit {
                time,
                condition: column,
                value,
                limit,
            }
            | E::Diverged {
                time,
                quantity: column,
                value,
                limit,
            } => {
                failure.time = Some(*time);
                failure.column = Some(column.clone());
                failure.value = Some(*value);
                failure.limit = Some(*limit);
            }
            E::RollbackCheck {
                instance,
                variable,
                unverified_after,
                ..
            } => {
                failure.instance = Some(instance.clone());
                failure.variable = Some(variable.clone());
                failure.unverified_after = *unverified_after;
            }
            E::DivergedOutput {
                instance, variable, ..
            }
            | E::NonFiniteOutput {
                instance, variable, ..
            } => {
                failure.instance = Some(instance.clone());
                failure.variable = Some(variable.clone());
            }
            E::SignalsNotConverged { time, .. } => failure.time = Some(*time),
            _ => {}
        }
        failure
    }
}

/// What the step-size controller of adaptive macro steps did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct AdaptiveStats {
    /// Accepted macro steps.
    pub accepted: u64,
    /// Rejected (rolled back and retried smaller) macro steps.
    pub rejected: u64,
    /// The smallest accepted step size.
    pub h_smallest: f64,
    /// The largest accepted step size.
    pub h_largest: f64,
    /// The error norm of the last accepted step (≤ 1: its estimated local
    /// error over the tolerances).
    pub last_error: f64,
}

/// What the iterations of an iterated signal coupling did (`[signals]
/// iterations`), over the accepted macro steps.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct SignalStats {
    /// `"fixed_point"` or `"newton"`.
    pub solver: crate::spec::SignalSolver,
    /// Updates of the exchanged values, over all steps: repetitions of the
    /// step (fixed point) or Newton updates.
    pub iterations: u64,
    /// The most updates in one macro step.
    pub max_iterations: u64,
    /// Runs of the macro step beyond each step's first, over all steps
    /// (Newton: the perturbed runs of its Jacobian included).
    pub repeated_runs: u64,
    /// Macro steps whose values had not converged after `iterations`.
    pub not_converged: u64,
    /// The start time T_N of the first such step.
    pub first_not_converged: Option<f64>,
}

/// An instance's request to end the simulation, and where the run ended.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Termination {
    /// The instance that asked.
    pub instance: String,
    /// The time it reported (`fmi2LastSuccessfulTime`).
    pub requested_at: f64,
    /// The last accepted macro point, the last recorded row: the coupled step
    /// to the requested time cannot be completed (the instance cannot be
    /// rolled back and re-run after it terminated).
    pub ended_at: f64,
}

impl fmt::Display for RunStats {
    /// The text summary, every line within [`SUMMARY_WIDTH`] characters
    /// (longer ones wrapped at spaces, the rest indented).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut text = String::new();
        self.write_summary(&mut text)?;
        let lines: Vec<String> = text.lines().flat_map(|l| wrap(l, SUMMARY_WIDTH)).collect();
        write!(f, "{}", lines.join("\n"))
    }
}

/// The text summary's width: lines are wrapped within it.
pub const SUMMARY_WIDTH: usize = 100;

/// `line` wrapped at spaces within `width` characters, preferring the
/// double spaces that separate a summary's fields; the continuation lines
/// indented two more than the line. A word longer than the width stays whole.
pub fn wrap(line: &str, width: usize) -> Vec<String> {
    let indent = line.len() - line.trim_start().len();
    let more = " ".repeat(indent + 2);
    let mut out: Vec<String> = Vec::new();
    let mut rest = line;
    let mut prefix = "";
    loop {
        let room = width.saturating_sub(prefix.len());
        if rest.chars().count() <= room {
            out.push(format!("{prefix}{rest}"));
            return out;
        }
        // Byte positions of the spaces within the room, after the indent.
        let from = if out.is_empty() { indent } else { 0 };
        let spaces: Vec<usize> = rest
            .char_indices()
            .take(room + 1)
            .filter(|&(i, c)| c == ' ' && i > from)
            .map(|(i, _)| i)
            .collect();
        let double = spaces
            .iter()
            .rev()
            .find(|&&i| rest[i..].starts_with("  "))
            .filter(|&&i| i * 3 >= room);
        let cut = match double.or(spaces.last()) {
            Some(&i) => i,
            None => match rest[from..].find(' ') {
                Some(i) => from + i,
                None => {
                    out.push(format!("{prefix}{rest}"));
                    return out;
                }
            },
        };
        out.push(format!("{prefix}{}", rest[..cut].trim_end()));
        rest = rest[cut..].trim_start();
        prefix = &more;
    }
}

impl RunStats {
    fn write_summary(&self, f: &mut String) -> fmt::Result {
        use std::fmt::Write as _;
        if self.jacobian_solves > 0 {
            writeln!(
                f,
                "macro steps: {}   Jacobian solves: {}   wall time: {:.3} s",
                self.macro_steps,
                self.jacobian_solves,
                self.wall.as_secs_f64()
            )?;
        } else {
            writeln!(
                f,
                "macro steps: {}   wall time: {:.3} s",
                self.macro_steps,
                self.wall.as_secs_f64()
            )?;
        }
        if let Some(a) = &self.adaptive {
            writeln!(
                f,
                "  adaptive steps: {} accepted, {} rejected   H from {:.3e} to {:.3e}",
                a.accepted, a.rejected, a.h_smallest, a.h_largest
            )?;
        }
        if self.jacobians_reused > 0 {
            writeln!(
                f,
                "  interface Jacobian: recomputed in {} steps ({} after the reused one mispredicted the correction), reused in {}",
                self.jacobians, self.jacobians_remade, self.jacobians_reused
            )?;
        }
        if let Some(i) = &self.signals {
            writeln!(
                f,
                "  signal iterations per step: {:.2} on average, {} at most ({} repeated runs of \
                 the step); not converged: {} steps",
                i.iterations as f64 / self.macro_steps.max(1) as f64,
                i.max_iterations,
                i.repeated_runs,
                i.not_converged
            )?;
            if let Some(t) = i.first_not_converged {
                writeln!(
                    f,
                    "  warning: {} macro steps did not converge within [signals] iterations \
                     (the first at t = {}): their last run stands",
                    i.not_converged,
                    crate::Time(t)
                )?;
            }
        }
        if self.max_corrections > 1 {
            writeln!(
                f,
                "  corrections per step: {:.2} on average, {} at most",
                self.corrections as f64 / self.macro_steps.max(1) as f64,
                self.max_corrections
            )?;
        }
        for line in call_table(&instance_lines(&self.instances), SUMMARY_WIDTH) {
            writeln!(f, "{line}")?;
        }
        if self.instances.len() > SUMMARY_ROWS {
            writeln!(
                f,
                "  ({} instances, counted per model; per instance in --summary-json)",
                self.instances.len()
            )?;
        }
        if !self.residuals.is_empty() {
            // The largest residuals first when there are more than a line holds.
            let mut worst: Vec<&(String, f64)> = self.residuals.iter().collect();
            if worst.len() > SUMMARY_RESIDUALS {
                worst.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            }
            write!(f, "  max |g|:")?;
            for (name, max) in worst.iter().take(SUMMARY_RESIDUALS) {
                write!(f, "  {name} {max:.2e}")?;
            }
            if worst.len() > SUMMARY_RESIDUALS {
                write!(
                    f,
                    "  … {} more, smaller (all in --summary-json)",
                    worst.len() - SUMMARY_RESIDUALS
                )?;
            }
            writeln!(f)?;
            let mut above: Vec<&(String, f64)> = self
                .residuals
                .iter()
                .filter(|(_, m)| m.is_nan() || *m > self.residual_warning)
                .collect();
            above.sort_by(|a, b| match (a.1.is_nan(), b.1.is_nan()) {
                (true, false) => std::cmp::Ordering::Less,
                (false, true) => std::cmp::Ordering::Greater,
                _ => b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)),
            });
            if above.len() == 1 {
                let (name, max) = above[0];
                writeln!(
                    f,
                    "  warning: max |{name}| = {max:.2e} exceeds residual_warning = {:e}: the \
                     constraint is not held to that accuracy (a smaller step, another index or \
                     method, or a larger residual_warning)",
                    self.residual_warning
                )?;
            } else if above.len() > 1 {
                let named: Vec<String> = above
                    .iter()
                    .take(SUMMARY_WARNED)
                    .map(|(name, max)| format!("|{name}| = {max:.2e}"))
                    .collect();
                let more = above.len().saturating_sub(SUMMARY_WARNED);
                writeln!(
                    f,
                    "  warning: {} residuals exceed residual_warning = {:e}, the largest max {}{}: \
                     these constraints are not held to that accuracy (a smaller step, another \
                     index or method, or a larger residual_warning)",
                    above.len(),
                    self.residual_warning,
                    named.join(", "),
                    if more > 0 {
                        format!(" and {more} more")
                    } else {
                        String::new()
                    }
                )?;
            }
        }
        if let Some(end) = &self.termination {
            writeln!(
                f,
                "  note: instance '{}' requested the end of the simulation at t = {} \
                 (fmi2Discard, fmi2Terminated); the run ended normally at t = {}, the last accepted point",
                end.instance,
                crate::Time(end.requested_at),
                crate::Time(end.ended_at)
            )?;
        }
        let p = &self.parallel;
        if p.workers == 0 && !p.handoff.is_zero() {
            writeln!(
                f,
                "  parallel runs not started: {:.1} µs a step in sequence, {:.1} µs in parallel \
                 (hand-off {:.1} µs)",
                p.sequential.as_secs_f64() * 1e6,
                p.parallel.as_secs_f64() * 1e6,
                p.handoff.as_secs_f64() * 1e6
            )?;
        } else if p.workers == 0 && p.handoff.is_zero() && !p.sequential.is_zero() {
            writeln!(
                f,
                "  parallel runs not started: each run is too short to gain ({:.1} µs a step \
                 in sequence)",
                p.sequential.as_secs_f64() * 1e6
            )?;
        } else if p.workers > 0 || p.handoff > Duration::ZERO {
            writeln!(
                f,
                "  parallel runs: {} worker{}, {:.1} µs a step in sequence, {:.1} µs in parallel \
                 (hand-off {:.1} µs)",
                p.workers,
                if p.workers == 1 { "" } else { "s" },
                p.sequential.as_secs_f64() * 1e6,
                p.parallel.as_secs_f64() * 1e6,
                p.handoff.as_secs_f64() * 1e6
            )?;
        }
        let t = &self.times;
        if !t.measured {
            return write!(
                f,
                "  time [s]: setup {:.3}  macro steps and recording {:.3}  (phases not timed)",
                t.setup.as_secs_f64(),
                self.wall.saturating_sub(t.setup).as_secs_f64()
            );
        }
        write!(
            f,
            "  time [s]: setup {:.3}  predictor {:.3}  jacobian {:.3}  solve {:.3}  corrector {:.3}  recording {:.3}",
            t.setup.as_secs_f64(),
            t.predictor.as_secs_f64(),
            t.jacobian.as_secs_f64(),
            t.solve.as_secs_f64(),
            t.corrector.as_secs_f64(),
            t.recording.as_secs_f64()
        )
    }
}

/// The FMI calls as a table within `width` characters: one row per function
/// called by any instance, one column per instance (or model), the columns
/// wrapped into blocks that fit.
fn call_table(columns: &[(String, InstanceCounters)], width: usize) -> Vec<String> {
    let calls: Vec<(&str, Vec<(String, u64)>)> = columns
        .iter()
        .map(|(label, c)| (label.as_str(), c.calls()))
        .collect();
    // In the order of the counters (FMI 2.0 and 3.0 names of one counter
    // together), those some instance called.
    let mut ranked: Vec<(usize, String)> = Vec::new();
    for (_, c) in columns {
        for (rank, (name, count)) in c.all_calls().into_iter().enumerate() {
            if count > 0 && !ranked.iter().any(|(_, n)| *n == name) {
                ranked.push((rank, name));
            }
        }
    }
    ranked.sort();
    let functions: Vec<String> = ranked.into_iter().map(|(_, name)| name).collect();
    if functions.is_empty() {
        return Vec::new();
    }
    let first = functions
        .iter()
        .map(String::len)
        .max()
        .unwrap_or(0)
        .max("FMI calls".len());
    let widths: Vec<usize> = calls
        .iter()
        .map(|(label, list)| {
            let digits = list
                .iter()
                .map(|(_, n)| n.to_string().len())
                .max()
                .unwrap_or(1);
            label.chars().count().max(digits)
        })
        .collect();
    let mut lines = Vec::new();
    let mut start = 0;
    while start < calls.len() {
        // As many columns as fit after the function names (at least one).
        let mut end = start + 1;
        let mut used = 2 + first + 2 + widths[start];
        while end < calls.len() && used + 2 + widths[end] <= width {
            used += 2 + widths[end];
            end += 1;
        }
        let mut header = format!("  {:<first$}", "FMI calls");
        for k in start..end {
            header.push_str(&format!("  {:>w$}", calls[k].0, w = widths[k]));
        }
        lines.push(header);
        for function in &functions {
            let mut row = format!("  {function:<first$}");
            for k in start..end {
                let count = calls[k]
                    .1
                    .iter()
                    .find(|(name, _)| name == function)
                    .map_or(0, |(_, n)| *n);
                row.push_str(&format!("  {count:>w$}", w = widths[k]));
            }
            lines.push(row);
        }
        start = end;
    }
    lines
}

/// Instances shown one per line in the text summary; beyond, one line per model.
pub const SUMMARY_ROWS: usize = 8;

/// Residuals named on the summary's `max |g|` line (the largest, beyond it).
pub const SUMMARY_RESIDUALS: usize = 8;

/// Residuals named in the warning for those above `residual_warning`.
pub const SUMMARY_WARNED: usize = 3;

/// The summary's call-count lines: one per instance up to [`SUMMARY_ROWS`],
/// otherwise one per model (`model ×n`), the counts summed, in the order of
/// first appearance.
fn instance_lines(instances: &[InstanceCounters]) -> Vec<(String, InstanceCounters)> {
    if instances.len() <= SUMMARY_ROWS {
        return instances
            .iter()
            .map(|c| (c.name.clone(), c.clone()))
            .collect();
    }
    let mut models: Vec<(String, usize, InstanceCounters)> = Vec::new();
    for c in instances {
        let i = match models.iter().position(|(m, _, _)| *m == c.model) {
            Some(i) => i,
            None => {
                models.push((c.model.clone(), 0, InstanceCounters::default()));
                models.len() - 1
            }
        };
        let (_, n, sum) = &mut models[i];
        *n += 1;
        add(sum, c);
    }
    // More models than lines: the rest together.
    if models.len() > SUMMARY_ROWS {
        let rest = models.split_off(SUMMARY_ROWS - 1);
        let mut sum = InstanceCounters::default();
        let mut n = 0;
        for (_, k, c) in &rest {
            n += k;
            add(&mut sum, c);
        }
        models.push((format!("{} other models", rest.len()), n, sum));
    }
    models
        .into_iter()
        .map(|(model, n, sum)| (format!("{model} ×{n}"), sum))
        .collect()
}

fn add(sum: &mut InstanceCounters, c: &InstanceCounters) {
    sum.do_steps += c.do_steps;
    sum.state_gets += c.state_gets;
    sum.state_sets += c.state_sets;
    sum.set_reals += c.set_reals;
    sum.get_reals += c.get_reals;
    sum.get_integers += c.get_integers;
    sum.get_booleans += c.get_booleans;
    sum.set_integers += c.set_integers;
    sum.set_booleans += c.set_booleans;
    sum.get_strings += c.get_strings;
    sum.set_strings += c.set_strings;
    sum.functions = c.functions;
    sum.set_input_derivatives += c.set_input_derivatives;
    sum.get_output_derivatives += c.get_output_derivatives;
}

/// The clock of one macro step's phases: each split adds the time since the
/// previous one to a phase. Without phase timing it never reads the clock.
pub(crate) struct Lap {
    last: Option<Instant>,
}

impl Lap {
    /// A lap that reads the clock if `on`.
    pub fn start(on: bool) -> Lap {
        Lap {
            last: on.then(Instant::now),
        }
    }

    /// Add the time since the previous split (or the start) to `phase`.
    pub fn split_into(&mut self, phase: &mut Duration) {
        if let Some(last) = self.last {
            let now = Instant::now();
            *phase += now - last;
            self.last = Some(now);
        }
    }

    /// The clock reading of the last split (the next phase's start), if timed.
    pub fn last(&self) -> Option<Instant> {
        self.last
    }
}

/// The version of the run summary's schema (`docs/run-summary.md`), its
/// `schema` field: raised when a field changes meaning or goes away.
pub const SUMMARY_SCHEMA: &str = "tether-run-summary/1";

impl RunStats {
    /// The run summary as JSON text (`docs/run-summary.md`).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a run summary always serialises")
    }
}

/// Seconds as a number.
fn secs(d: std::time::Duration) -> f64 {
    d.as_secs_f64()
}

/// Pairs as a JSON object, in their order.
struct Ordered<'a, V>(Vec<(&'a str, V)>);

impl<V: Serialize> Serialize for Ordered<'_, V> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            map.serialize_entry(k, v)?;
        }
        map.end()
    }
}

#[derive(Serialize)]
struct Calls {
    do_step: u64,
    get_fmu_state: u64,
    set_fmu_state: u64,
    set_real: u64,
    get_real: u64,
    get_integer: u64,
    get_boolean: u64,
    set_integer: u64,
    set_boolean: u64,
    get_string: u64,
    set_string: u64,
    set_real_input_derivatives: u64,
    get_real_output_derivatives: u64,
    round_trips: u64,
}

#[derive(Serialize)]
struct Times {
    measured: bool,
    setup: f64,
    predictor: f64,
    jacobian: f64,
    solve: f64,
    corrector: f64,
    recording: f64,
}

#[derive(Serialize)]
struct Parallel {
    workers: usize,
    handoff: f64,
    sequential: f64,
    parallel: f64,
    trial_sequential: f64,
    trial_parallel: f64,
}

#[derive(Serialize)]
struct Summary<'a> {
    schema: &'static str,
    method: &'a crate::Method,
    order: usize,
    start: f64,
    step: f64,
    stop: f64,
    output_interval: f64,
    completed: bool,
    stop_reason: &'a str,
    end_time: Option<f64>,
    termination: Option<&'a Termination>,
    macro_steps: u64,
    jacobian_solves: u64,
    corrections: u64,
    max_corrections: u64,
    jacobians: u64,
    jacobians_reused: u64,
    jacobians_remade: u64,
    adaptive: Option<&'a AdaptiveStats>,
    #[serde(skip_serializing_if = "Option::is_none")]
    signals: Option<&'a SignalStats>,
    wall_time: f64,
    max_abs_g: Ordered<'a, Option<f64>>,
    residual_warning: f64,
    residual_limit: Option<f64>,
    failure: Option<&'a Failure>,
    instances: Ordered<'a, Calls>,
    times: Times,
    parallel: Parallel,
}

impl Serialize for RunStats {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let t = &self.times;
        let p = &self.parallel;
        Summary {
            schema: SUMMARY_SCHEMA,
            method: &self.method,
            order: self.order,
            start: self.start,
            step: self.step,
            stop: self.stop,
            output_interval: self.output_interval,
            completed: self.completed,
            stop_reason: &self.stop_reason,
            end_time: self.end_time,
            termination: self.termination.as_ref(),
            macro_steps: self.macro_steps,
            jacobian_solves: self.jacobian_solves,
            corrections: self.corrections,
            max_corrections: self.max_corrections,
            jacobians: self.jacobians,
            jacobians_reused: self.jacobians_reused,
            jacobians_remade: self.jacobians_remade,
            adaptive: self.adaptive.as_ref(),
            signals: self.signals.as_ref(),
            wall_time: secs(self.wall),
            // NaN (a residual that was not finite) as null.
            max_abs_g: Ordered(
                self.residuals
                    .iter()
                    .map(|(name, max)| (name.as_str(), max.is_finite().then_some(*max)))
                    .collect(),
            ),
            residual_warning: self.residual_warning,
            residual_limit: self.residual_limit,
            failure: self.failure.as_ref(),
            instances: Ordered(
                self.instances
                    .iter()
                    .map(|c| {
                        let calls = Calls {
                            do_step: c.do_steps,
                            get_fmu_state: c.state_gets,
                            set_fmu_state: c.state_sets,
                            set_real: c.set_reals,
                            get_real: c.get_reals,
                            get_integer: c.get_integers,
                            get_boolean: c.get_booleans,
                            set_integer: c.set_integers,
                            set_boolean: c.set_booleans,
                            get_string: c.get_strings,
                            set_string: c.set_strings,
                            set_real_input_derivatives: c.set_input_derivatives,
                            get_real_output_derivatives: c.get_output_derivatives,
                            round_trips: c.round_trips,
                        };
                        (c.name.as_str(), calls)
                    })
                    .collect(),
            ),
            times: Times {
                measured: t.measured,
                setup: secs(t.setup),
                predictor: secs(t.predictor),
                jacobian: secs(t.jacobian),
                solve: secs(t.solve),
                corrector: secs(t.corrector),
                recording: secs(t.recording),
            },
            parallel: Parallel {
                workers: p.workers,
                handoff: secs(p.handoff),
                sequential: secs(p.sequential),
                parallel: secs(p.parallel),
                trial_sequential: secs(p.trial_sequential),
                trial_parallel: secs(p.trial_parallel),
            },
        }
        .serialize(s)
    }
}

/// What the parallel strategy did in a run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ParallelInfo {
    /// Worker threads used (0: the runs stayed on the main thread).
    pub workers: usize,
    /// Measured cost of one hand-off: waking every worker and being woken
    /// back ("auto" only; zero when the runs' costs alone ruled the workers
    /// out and none was started).
    pub handoff: Duration,
    /// Predicted time of one step's runs, sequential.
    pub sequential: Duration,
    /// Predicted time of the same runs in parallel, hand-offs included.
    pub parallel: Duration,
    /// "auto": shortest measured runs of a sequential step.
    pub trial_sequential: Duration,
    /// "auto": shortest measured runs of a parallel trial step.
    pub trial_parallel: Duration,
}

#[cfg(test)]
mod summary_tests {
    use super::*;

    /// A run of any size: the text summary stays within about 30 lines,
    /// counted per model, the largest residuals named, one warning line.
    #[test]
    fn the_text_summary_stays_short_at_any_size() {
        let instances = (0..1000)
            .map(|i| InstanceCounters {
                name: format!("body[{i}]"),
                model: format!("model{}", i % 12),
                do_steps: 3,
                ..Default::default()
            })
            .collect();
        let residuals = (0..1000)
            .map(|i| (format!("joint[{i}].g"), f64::from(i) * 1e-6))
            .collect();
        let stats = RunStats {
            instances,
            residuals,
            residual_warning: 1e-4,
            ..Default::default()
        };
        let text = stats.to_string();
        assert!(text.lines().count() <= 30, "{text}");
        assert!(
            text.lines().all(|l| l.chars().count() <= SUMMARY_WIDTH),
            "{text}"
        );
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[1..5],
            [
                "  FMI calls   model0 ×84  model1 ×84  model2 ×84  model3 ×84  model4 ×83  model5 ×83  model6 ×83",
                "  fmi2DoStep         252         252         252         252         249         249         249",
                "  FMI calls   5 other models ×415",
                "  fmi2DoStep                 1245",
            ],
            "{text}"
        );
        assert!(
            text.contains("(1000 instances, counted per model; per instance in --summary-json)")
        );
        assert!(
            text.contains("max |g|:  joint[999].g 9.99e-4  joint[998].g 9.98e-4"),
            "{text}"
        );
        assert!(
            text.contains("… 992 more, smaller (all in --summary-json)"),
            "{text}"
        );
        let flat = text.split_whitespace().collect::<Vec<_>>().join(" ");
        assert!(
            flat.contains(
                "warning: 899 residuals exceed residual_warning = 1e-4, the largest max \
                 |joint[999].g| = 9.99e-4, |joint[998].g| = 9.98e-4, |joint[997].g| = 9.97e-4 and \
                 896 more: "
            ),
            "{text}"
        );
        // Small runs: one line per instance, every residual named.
        let small = RunStats {
            instances: vec![InstanceCounters {
                name: "mass1".into(),
                model: "oscillator".into(),
                do_steps: 5,
                ..Default::default()
            }],
            residuals: vec![("link.g".into(), 2e-3)],
            residual_warning: 1e-3,
            ..Default::default()
        };
        let text = small.to_string();
        assert!(
            text.contains("\n  FMI calls   mass1\n  fmi2DoStep      5\n"),
            "{text}"
        );
        assert!(text.contains("max |g|:  link.g 2.00e-3\n"), "{text}");
        assert!(text.contains("warning: max |link.g| = 2.00e-3 exceeds residual_warning = 1e-3"));
    }
}
