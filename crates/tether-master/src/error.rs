//! The master's error type: every message is one line naming the culprit.

use std::path::PathBuf;

use crate::expr::ExprError;

/// Everything that can stop a coupled run or keep it from starting.
#[derive(Debug, thiserror::Error)]
pub enum MasterError {
    /// The system file cannot be read or has the wrong shape.
    #[error("system file {}: {reason}", path.display())]
    SystemFile {
        /// The file.
        path: PathBuf,
        /// What is wrong, on one line.
        reason: String,
    },
    /// `[output]` (or `--output-variables`) selects something that is not there.
    #[error("{0}")]
    InvalidOutput(String),
    /// A number outside its allowed range (method parameter, step, stop time …).
    #[error("invalid {name} = {value}: expected {expected}")]
    InvalidParameter {
        /// Parameter name.
        name: String,
        /// The value given.
        value: f64,
        /// What would have been accepted.
        expected: String,
    },
    /// The time span of a simulation is not finite and increasing.
    #[error("invalid time span: start {start}, stop {stop} (stop must be after start)")]
    InvalidTimeSpan {
        /// Start time.
        start: f64,
        /// Stop time.
        stop: f64,
    },
    /// A constraint expression cannot be parsed.
    #[error("constraint '{constraint}', {level}: {source}")]
    Expression {
        /// Constraint name.
        constraint: String,
        /// `position`, `velocity`, `acceleration` or `drives`.
        level: &'static str,
        /// The parse error.
        source: ExprError,
    },
    /// An expression names an instance the system file does not declare.
    #[error("{owner} refers to unknown instance '{instance}'{hint}")]
    UnknownInstance {
        /// What refers to it: `constraint 'link'`, `joint 'hinge'` …
        owner: String,
        /// The name that was not found.
        instance: String,
        /// `; did you mean …?` or empty.
        hint: String,
    },
    /// A name refers to a variable its instance's FMU does not have.
    #[error("{0}")]
    UnknownVariable(Box<UnknownName>),
    /// An array element that does not exist: a subscript on a scalar, the
    /// wrong number of indices, an index out of range.
    #[error("{place}: instance '{instance}', '{name}': {reason}")]
    ArrayElement {
        /// Where the name appears: `constraint 'link', position`, `parameters` …
        place: String,
        /// Instance name.
        instance: String,
        /// The name as written.
        name: String,
        /// What is wrong, with the valid range.
        reason: String,
    },
    /// A joint names a marker its instance does not have.
    #[error("{owner}: instance '{instance}' has no marker '{marker}' (no output '{marker}.r[1]'); {hint}")]
    UnknownMarker {
        /// `joint 'hinge'`.
        owner: String,
        /// Instance name.
        instance: String,
        /// Marker name.
        marker: String,
        /// The markers it has, or a pointer to the convention.
        hint: String,
    },
    /// A marker lacks one of the outputs of the marker-port convention.
    #[error("instance '{instance}': marker '{marker}' has no output '{missing}' (docs/marker-ports.md lists the 24 outputs a marker needs)")]
    IncompleteMarker {
        /// Instance name.
        instance: String,
        /// Marker name.
        marker: String,
        /// The missing output.
        missing: String,
    },
    /// A joint needs a force or torque input a marker does not have.
    #[error("{owner} needs input '{input}' of instance '{instance}' (a force/torque port); declare it in the FMU, or use plane = \"xy\" for a planar joint")]
    MissingPort {
        /// `joint 'hinge'`.
        owner: String,
        /// Instance name.
        instance: String,
        /// The input name.
        input: String,
    },
    /// A joint's description is inconsistent.
    #[error("joint '{joint}': {reason}")]
    Joint {
        /// Joint name.
        joint: String,
        /// What is wrong.
        reason: String,
    },
    /// A variable is used in a role its causality or type does not allow.
    #[error("{instance}.{variable} is {found}, but {role} needs {expected}")]
    WrongVariable {
        /// Instance name.
        instance: String,
        /// Variable name.
        variable: String,
        /// What the variable is (`a parameter`, `an Integer output` …).
        found: String,
        /// The role it was used in.
        role: String,
        /// What the role requires.
        expected: String,
    },
    /// A constraint lacks a level the chosen method evaluates.
    #[error("constraint '{constraint}' has no {level} expression, which {needed_by} needs")]
    MissingLevel {
        /// Constraint name.
        constraint: String,
        /// `velocity` or `acceleration`.
        level: &'static str,
        /// What needs it.
        needed_by: String,
    },
    /// An FMU lacks a capability the chosen method needs.
    #[error(
        "instance '{instance}' ({model}) does not declare {capability}, which {needed_by} needs"
    )]
    MissingCapability {
        /// Instance name.
        instance: String,
        /// Model name.
        model: String,
        /// The capability flag.
        capability: &'static str,
        /// What needs it.
        needed_by: String,
    },
    /// A constraint's terms in units that do not fit together.
    #[error("constraint '{constraint}', {level}: {detail}")]
    Units {
        /// Constraint name.
        constraint: String,
        /// `position`, `velocity`, `acceleration` or `drives`.
        level: &'static str,
        /// The two terms and their units.
        detail: String,
    },
    /// Coupling polynomials (k > 0) into an input that takes values only.
    #[error("instance '{instance}' ({model}): {needs}; {reason}; use order = 0")]
    NoPolynomialInput {
        /// Instance name.
        instance: String,
        /// Model name.
        model: String,
        /// `k > 0 needs inputs that take polynomials`.
        needs: &'static str,
        /// Why this FMU or input takes none, in one plain clause.
        reason: String,
    },
    /// A start value cannot be applied to its variable.
    #[error(
        "instance '{instance}': cannot set {variable} = {}: {reason}",
        crate::expr::quote(value, None, "", "")
    )]
    StartValue {
        /// Instance name.
        instance: String,
        /// Variable name.
        variable: String,
        /// Value as written.
        value: String,
        /// Why not.
        reason: String,
    },
    /// The interface Jacobian cannot be solved reliably.
    #[error("singular interface Jacobian ({level} level) at t = {time}{}: condition estimate {condition:.3e} exceeds {limit:.1e}", step.map(|h| format!(" (macro step H = {h:e})")).unwrap_or_default(), time = crate::Time(*time))]
    SingularJacobian {
        /// Time of the macro point T_{N+1} being solved for.
        time: f64,
        /// Which matrix: `baumgarte`, `position`, `velocity`, `acceleration`.
        level: &'static str,
        /// Estimated 1-norm condition number after row scaling (inf if exactly singular).
        condition: f64,
        /// The accepted maximum.
        limit: f64,
        /// The macro step H being corrected, if any (not for the initial
        /// multipliers). With adaptive steps a tiny H here can be a step
        /// that shrank until the position level's sensitivities (∝ H²)
        /// vanished, as with an unstable method.
        step: Option<f64>,
    },
    /// A state, output or multiplier became non-finite or exploded.
    #[error("coupling diverged at t = {time}: {quantity} = {value:e} (limit {limit:.1e})", time = crate::Time(*time))]
    Diverged {
        /// Time of the accepted step.
        time: f64,
        /// The column name of the quantity.
        quantity: String,
        /// Its value.
        value: f64,
        /// The bound it crossed.
        limit: f64,
    },
    /// A constraint or joint condition is broken: its |g| at an accepted point
    /// exceeds `[coupling] residual_limit`.
    #[error("constraint broken at t = {time}: |{condition}| = {value:e} exceeds residual_limit = {limit:e} (in the condition's units); the coupling does not hold it: a smaller step, another index or method (docs/paper-reproduction.md), check_rollback = \"every_step\" to test the FMUs' rollback at every restore, or residual_limit = \"off\" to run anyway", time = crate::Time(*time))]
    ResidualLimit {
        /// Time of the accepted point.
        time: f64,
        /// The residual's column name, e.g. `link.g`.
        condition: String,
        /// Its magnitude |g|.
        value: f64,
        /// `[coupling] residual_limit`.
        limit: f64,
    },
    /// Adaptive steps: a step at the smallest allowed size still misses the
    /// tolerances.
    #[error("adaptive macro steps: at t = {time} the local error estimate is {error:.2} times the tolerance even at h_min = {h_min:e}; loosen [step_control] rtol/atol or lower h_min, or, if smaller steps do not lower the estimate, choose a method, index and k stable for this system (docs/paper-reproduction.md)", time = crate::Time(*time))]
    StepSizeTooSmall {
        /// Start of the step.
        time: f64,
        /// The error norm at h_min (> 1).
        error: f64,
        /// The smallest step size.
        h_min: f64,
    },
    /// An observer asked the run to stop (e.g. the user pressed Ctrl-C).
    #[error("interrupted ({reason}) at t = {time}", time = crate::Time(*time))]
    Interrupted {
        /// The last accepted macro time.
        time: f64,
        /// Why, e.g. `SIGINT`.
        reason: String,
    },
    /// An instance asked to end the simulation: `fmi2DoStep` returned
    /// fmi2Discard and `fmi2GetBooleanStatus(fmi2Terminated)` is true.
    /// [`crate::Simulation::run`] ends normally on it (docs/fmi-import.md).
    #[error("instance '{instance}' requested the end of the simulation at t = {time} (fmi2DoStep returned fmi2Discard with fmi2Terminated = true)", time = crate::Time(*time))]
    TerminationRequested {
        /// Instance name.
        instance: String,
        /// The instance's `fmi2LastSuccessfulTime` (the step's end if it
        /// does not say).
        time: f64,
    },
    /// `fmi2SetFMUstate` does not restore an instance exactly (the rollback
    /// self-check, `[coupling] check_rollback`).
    #[error("rollback self-check failed for instance '{instance}': {reason}; the predictor/corrector method repeats every macro step from a saved state and needs an exact rollback: use --method explicit (no rollback), or check_rollback = \"off\" to run anyway{}", unverified_rows(*unverified_after))]
    RollbackCheck {
        /// Instance name.
        instance: String,
        /// The first coupled output that differs.
        variable: String,
        /// What differed, naming the variable, the values and the time.
        reason: String,
        /// The time of the last rollback check that passed, when rows after
        /// it were written before this check failed (docs/reliability.md):
        /// those rows are not verified.
        unverified_after: Option<f64>,
    },
    /// An instance's coupled output went beyond its divergence limit where it
    /// was read, and the step then failed (crate::culprit): the instance
    /// that produced the value is named, then the failure.
    #[error("instance '{instance}': output '{variable}' = {value:e} {call} at t = {time} is beyond its divergence limit {limit:.1e} (divergence_factor × its initial size); then: {then}", time = crate::Time(*time))]
    DivergedOutput {
        /// Instance name.
        instance: String,
        /// The output.
        variable: String,
        /// Its value.
        value: f64,
        /// The bound it crossed.
        limit: f64,
        /// The call after which it was read.
        call: &'static str,
        /// The instance's time after the call.
        time: f64,
        /// The error that stopped the step.
        then: String,
    },
    /// An instance's output is NaN or infinite right after one of its calls.
    #[error("instance '{instance}': output '{variable}' = {value} {call} at t = {time} (the FMU computed a non-finite value)", time = crate::Time(*time))]
    NonFiniteOutput {
        /// Instance name.
        instance: String,
        /// The output (`der(x, 1)` for an output derivative).
        variable: String,
        /// NaN, inf or -inf.
        value: f64,
        /// After which call: `after the predictor's fmi2DoStep` …
        call: &'static str,
        /// The instance's time when the value was read.
        time: f64,
    },
    /// An FMI call or FMU load failed.
    #[error(transparent)]
    Fmi(tether_fmi::Error),
    /// An instance's FMU cannot be opened (its path, as resolved against the
    /// system file's folder, is in the error).
    #[error("instance '{instance}': {error}")]
    InstanceFmu {
        /// The instance.
        instance: String,
        /// Why the FMU cannot be opened.
        error: tether_fmi::Error,
    },
    /// The terms of a `drives` expression cancel: the multiplier acts on no
    /// input, and the interface Jacobian would be singular.
    #[error("{owner}: drives '{drives}' cancel out: the multiplier acts on no input (every input's coefficients sum to 0), so the interface Jacobian would be singular")]
    DrivesCancel {
        /// `constraint 'link'`.
        owner: String,
        /// The expression as written.
        drives: String,
    },
    /// Writing results failed. (The I/O error is in the message, not also a
    /// `source`, so that a printed chain names it once.)
    #[error("recording results: {0}")]
    Recording(std::io::Error),
    /// A worker thread for parallel runs could not be started.
    #[error("cannot start a worker thread for parallel runs: {0}")]
    Thread(String),
    /// A signal connection cannot be made (types, units, causality, a second
    /// sender, a direct-feedthrough loop).
    #[error("connection {connection}: {reason}")]
    Connection {
        /// `from → to`, as written.
        connection: String,
        /// What is wrong, on one line.
        reason: String,
    },
    /// The master panicked while it made an instance's runs on a worker
    /// thread (a defect of Tether: the run ends).
    #[error("instance '{instance}': Tether failed while it made its runs on a worker thread (an internal error; the run ends)")]
    Worker { instance: String },
    /// `[signals] strict = true`: an iterated macro step whose exchanged
    /// values did not converge within `[signals] iterations`.
    #[error("[signals] strict: the macro step from t = {time} did not converge in {iterations} iterations: |Δv| of connection {connection} is {residual:.1e} times the tolerance {tolerance:e} (raise iterations, loosen tolerance, or try solver = \"newton\")", time = crate::Time(*time))]
    SignalsNotConverged {
        /// T_N, the step's start.
        time: f64,
        /// `[signals] iterations`.
        iterations: usize,
        /// The connection with the largest change, `from → to`.
        connection: String,
        /// Its |Δv| / (tolerance·max(1, |v|)).
        residual: f64,
        /// `[signals] tolerance`.
        tolerance: f64,
    },
}

impl MasterError {
    /// The error's kind, as the run summary's `failure.kind` names it
    /// (docs/run-summary.md): the variant's name in snake case.
    pub fn kind(&self) -> &'static str {
        match self {
            MasterError::SystemFile { .. } => "system_file",
            MasterError::InvalidOutput(_) => "invalid_output",
            MasterError::InvalidParameter { .. } => "invalid_parameter",
            MasterError::InvalidTimeSpan { .. } => "invalid_time_span",
            MasterError::Expression { .. } => "expression",
            MasterError::Units { .. } => "units",
            MasterError::UnknownInstance { .. } => "unknown_instance",
            MasterError::UnknownVariable(_) => "unknown_variable",
            MasterError::ArrayElement { .. } => "array_element",
            MasterError::UnknownMarker { .. } => "unknown_marker",
            MasterError::IncompleteMarker { .. } => "incomplete_marker",
            MasterError::MissingPort { .. } => "missing_port",
            MasterError::Joint { .. } => "joint",
            MasterError::WrongVariable { .. } => "wrong_variable",
            MasterError::MissingLevel { .. } => "missing_level",
            MasterError::MissingCapability { .. } | MasterError::NoPolynomialInput { .. } => {
                "missing_capability"
            }
            MasterError::StartValue { .. } => "start_value",
            MasterError::SingularJacobian { .. } => "singular_jacobian",
            MasterError::Diverged { .. } => "diverged",
            MasterError::ResidualLimit { .. } => "residual_limit",
            MasterError::StepSizeTooSmall { .. } => "step_size_too_small",
            MasterError::Interrupted { .. } => "interrupted",
            MasterError::TerminationRequested { .. } => "termination_requested",
            MasterError::RollbackCheck { .. } => "rollback_check",
            MasterError::DivergedOutput { .. } => "diverged_output",
            MasterError::NonFiniteOutput { .. } => "non_finite_output",
            MasterError::Fmi(_) => "fmi",
            MasterError::InstanceFmu { .. } => "instance_fmu",
            MasterError::DrivesCancel { .. } => "drives_cancel",
            MasterError::Recording(_) => "recording",
            MasterError::Thread(_) => "thread",
            MasterError::Connection { .. } => "connection",
            MasterError::SignalsNotConverged { .. } => "signals_not_converged",
            MasterError::Worker { .. } => "worker",
        }
    }

    /// A failed rollback check after rows were written since the last one
    /// that passed, at `verified`: the message names them. Other errors pass
    /// unchanged.
    pub(crate) fn after_check_at(mut self, verified: f64) -> MasterError {
        if let MasterError::RollbackCheck {
            unverified_after, ..
        } = &mut self
        {
            *unverified_after = Some(verified);
        }
        self
    }

    /// A singular Jacobian met while correcting a macro step of size `h`
    /// names H in its message; other errors pass unchanged.
    pub(crate) fn in_step(mut self, h: f64) -> MasterError {
        if let MasterError::SingularJacobian { step, .. } = &mut self {
            *step = Some(h);
        }
        self
    }
}

impl From<std::io::Error> for MasterError {
    fn from(e: std::io::Error) -> Self {
        MasterError::Recording(e)
    }
}

impl From<tether_fmi::Error> for MasterError {
    /// An FMU's request to end the simulation is not a failure of the call:
    /// it becomes [`MasterError::TerminationRequested`].
    fn from(error: tether_fmi::Error) -> MasterError {
        match error {
            tether_fmi::Error::TerminationRequested { instance, time, .. } => {
                MasterError::TerminationRequested { instance, time }
            }
            error => MasterError::Fmi(error),
        }
    }
}

/// An error and its causes on one line, `error: cause: cause`, as the CLI
/// prints it (newlines become spaces): the one formatter of error chains for
/// the library's users (tether-py, the single-FMU runs' trailers).
pub fn error_line(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text.replace('\n', " ")
}

/// The clause of a failed periodic rollback check that names the rows
/// written since the last check that passed.
fn unverified_rows(after: Option<f64>) -> String {
    after.map_or(String::new(), |t| {
        format!(
            "; the rows after t = {} were written before this check failed and are not verified",
            crate::Time(t)
        )
    })
}

/// A variable name its instance's FMU does not have, and where it appears.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "{place}: instance '{instance}' ({fmu}) has no variable '{name}'{}",
    did_you_mean(suggestions)
)]
pub struct UnknownName {
    /// Where the name appears: `constraint 'link', position`,
    /// `parameters`, `--set mass1.xx` …
    pub place: String,
    /// Instance name.
    pub instance: String,
    /// The FMU's file name (`oscillator.fmu`), or `model 'oscillator'`
    /// where the file is not known.
    pub fmu: String,
    /// The name as written.
    pub name: String,
    /// Close names, best first.
    pub suggestions: Vec<String>,
}

impl MasterError {
    /// An unknown start-value name (or array element) made exact with the
    /// system: the FMU's file (the error names only its model), and the place `set_by(instance,
    /// variable)` says the value came from (`--set mass1.xx`; `None`: the
    /// instance's `parameters`). Other errors are returned unchanged.
    pub fn located(
        self,
        spec: &crate::SystemSpec,
        set_by: impl Fn(&str, &str) -> Option<String>,
    ) -> MasterError {
        match self {
            MasterError::UnknownVariable(mut u) if u.place == "parameters" => {
                if let Some(file) = spec.instances.iter().find(|i| i.name == u.instance) {
                    u.fmu = crate::spec::names::fmu_file(&file.fmu);
                }
                if let Some(place) = set_by(&u.instance, &u.name) {
                    u.place = place;
                }
                MasterError::UnknownVariable(u)
            }
            MasterError::ArrayElement {
                place,
                instance,
                name,
                reason,
            } if place == "parameters" => MasterError::ArrayElement {
                place: set_by(&instance, &name).unwrap_or(place),
                instance,
                name,
                reason,
            },
            other => other,
        }
    }
}

/// `; did you mean 'a', 'b'?`, or nothing without suggestions.
fn did_you_mean(suggestions: &[String]) -> String {
    if suggestions.is_empty() {
        String::new()
    } else {
        format!("; did you mean '{}'?", suggestions.join("', '"))
    }
}
