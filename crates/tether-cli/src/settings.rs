//! Flags that change a system file's time grid, coupling method and FMU
//! parameters, shared by `tether run` and `tether sweep`. They build the
//! shared [`Overrides`] of tether-master.

use anyhow::{anyhow, Result};
use tether_master::{MethodChange, OverrideError, Overrides, SystemSpec};

#[derive(clap::Args, Debug, Clone)]
pub struct Settings {
    /// Stop time (overrides [experiment] stop).
    #[arg(long, allow_hyphen_values = true)]
    stop: Option<f64>,
    /// Macro-step size H (overrides [experiment] step).
    #[arg(long, allow_hyphen_values = true)]
    step: Option<f64>,
    /// Coupling method (overrides [method] kind).
    #[arg(long, value_parser = ["baumgarte", "weighted", "explicit"])]
    method: Option<String>,
    /// Index level 1, 2 or 3 of method baumgarte or weighted: the weights not
    /// given keep the system file's where the index uses them, else take the
    /// index's defaults (docs/system-file.md, [method]).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=3))]
    index: Option<u8>,
    /// Baumgarte velocity weight β (method baumgarte).
    #[arg(long, allow_hyphen_values = true)]
    beta: Option<f64>,
    /// Baumgarte acceleration weight γ (method baumgarte).
    #[arg(long, allow_hyphen_values = true)]
    gamma: Option<f64>,
    /// Velocity-level weight a (method weighted).
    #[arg(long, allow_hyphen_values = true)]
    a: Option<f64>,
    /// Acceleration-level weight b (method weighted).
    #[arg(long, allow_hyphen_values = true)]
    b: Option<f64>,
    /// Stabilisation constant μ_B (method explicit).
    #[arg(long, allow_hyphen_values = true)]
    mu: Option<f64>,
    /// Degree k of the coupling polynomials: 0, 1 or 2.
    #[arg(long, allow_hyphen_values = true)]
    order: Option<usize>,
    /// Finite-difference increment ε for the interface Jacobian.
    #[arg(long, allow_hyphen_values = true)]
    epsilon: Option<f64>,
    /// The runs of a step on worker threads: auto (only when it pays), on
    /// or off (overrides [coupling] parallel).
    #[arg(long, value_parser = ["auto", "on", "off"])]
    parallel: Option<String>,
    /// Threads the runs may use, the main thread included (overrides
    /// [coupling] threads; default: the machine's available parallelism).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=1024))]
    threads: Option<u32>,
    /// Corrections per macro step, 1 = the paper's single correction
    /// (overrides [coupling] iterations).
    #[arg(long)]
    iterations: Option<usize>,
    /// An iterated correction stops when every update is below this times
    /// max(1, |u|) (overrides [coupling] iteration_tol).
    #[arg(long)]
    iteration_tol: Option<f64>,
    /// When the interface Jacobian is made from perturbed runs: every_step
    /// (the paper) or reuse (when due, Broyden updates in between; overrides
    /// [coupling] jacobian).
    #[arg(long, value_parser = ["every_step", "reuse"])]
    jacobian: Option<String>,
    /// Adaptive macro steps with this relative tolerance of the local error
    /// estimate (sets [step_control] rtol; the step starts at --step).
    #[arg(long)]
    step_rtol: Option<f64>,
    /// Adaptive macro steps with this absolute tolerance (sets
    /// [step_control] atol).
    #[arg(long)]
    step_atol: Option<f64>,
    /// Set an FMU start value for every run: INSTANCE.PARAMETER=VALUE (repeatable).
    #[arg(long = "set", value_name = "INSTANCE.PARAMETER=VALUE")]
    set: Vec<String>,
}

impl Settings {
    /// The changes the given flags make.
    pub fn overrides(&self) -> Result<Overrides> {
        let mut overrides = Overrides {
            method: MethodChange {
                kind: self.method.as_deref().map(str::parse).transpose()?,
                index: self.index,
                beta: self.beta,
                gamma: self.gamma,
                a: self.a,
                b: self.b,
                mu: self.mu,
            },
            order: self.order,
            step: self.step,
            stop: self.stop,
            epsilon: self.epsilon,
            divergence_factor: None,
            parallel: parse(&self.parallel)?,
            threads: self.threads.map(|n| n as usize),
            iterations: self.iterations,
            iteration_tol: self.iteration_tol,
            jacobian: parse(&self.jacobian)?,
            step_rtol: self.step_rtol,
            step_atol: self.step_atol,
            parameters: Default::default(),
        };
        for setting in &self.set {
            overrides.set(setting).map_err(flag_error)?;
        }
        Ok(overrides)
    }
}

/// A flag's word parsed into its setting (the words were checked by clap).
fn parse<T: std::str::FromStr<Err = String>>(word: &Option<String>) -> Result<Option<T>> {
    word.as_deref()
        .map(str::parse)
        .transpose()
        .map_err(anyhow::Error::msg)
}

/// Apply overrides made from these flags; errors name the flags.
pub fn apply(overrides: &Overrides, spec: &mut SystemSpec) -> Result<()> {
    overrides.apply(spec).map_err(flag_error)
}

/// An override error in the words of the command line.
fn flag_error(e: OverrideError) -> anyhow::Error {
    match e {
        OverrideError::Setting { setting, reason } => anyhow!("--set {setting}: {reason}"),
        OverrideError::Misplaced {
            parameter,
            method,
            current,
        } => anyhow!("--{parameter} applies to method {method}, but the method is {current}"),
        OverrideError::MissingMu => anyhow!("method explicit needs --mu (or mu in [method])"),
        OverrideError::Index(conflict) => anyhow!("{}", conflict.describe(true)),
        e => e.into(),
    }
}
