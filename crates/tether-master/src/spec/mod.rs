//! The system file: which FMUs, how they are coupled, and how to run them.
//!
//! The format is TOML; `docs/system-file.md` documents every key. This module
//! only reads and checks the file's own consistency; names of FMU variables are
//! checked against the FMUs when the [`crate::Simulation`] is built.

mod arrays;
mod export;
pub(crate) mod names;
mod output;
pub(crate) mod overrides;
mod validate;

pub use export::{ExportLink, ExportSource, ExportSpec};
pub use output::{matches_pattern, OutputSpec};

use std::collections::BTreeMap;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::step_control::StepControl;
use crate::Method;

/// A whole system file.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SystemSpec {
    /// Free-text name shown in the run summary.
    #[serde(default)]
    pub name: Option<String>,
    /// Time grid of the run.
    pub experiment: Experiment,
    /// Coupling method and its parameters.
    #[serde(default)]
    pub method: Method,
    /// Settings shared by all methods.
    #[serde(default)]
    pub coupling: CouplingSettings,
    /// Adaptive macro steps (absent: the fixed `[experiment] step`).
    #[serde(default)]
    pub step_control: Option<StepControl>,
    /// The FMU instances, in the order their columns appear in the results.
    #[serde(rename = "instance")]
    pub instances: Vec<InstanceSpec>,
    /// Algebraic constraints between the instances.
    #[serde(rename = "constraint", default)]
    pub constraints: Vec<ConstraintSpec>,
    /// Mechanical joints between marker ports (`docs/marker-ports.md`).
    #[serde(rename = "joint", default)]
    pub joints: Vec<JointSpec>,
    /// Additional coupling variables `input = expression of outputs`
    /// (the paper's γ̃, r̃: an FMU that applies a joint's force law itself).
    #[serde(rename = "coupling_variable", default)]
    pub coupling_variables: Vec<CouplingVariableSpec>,
    /// Signal connections `from = "inst.output"` → `to = "inst.input"`,
    /// passed at macro points (docs/algorithm.md, "Signal connections").
    #[serde(rename = "connection", default, skip_serializing_if = "Vec::is_empty")]
    pub connections: Vec<ConnectionSpec>,
    /// How signal connections are evaluated.
    #[serde(default, skip_serializing_if = "SignalSettings::is_default")]
    pub signals: SignalSettings,
    /// What is recorded: the output grid and the columns (`[output]`).
    #[serde(default, skip_serializing_if = "OutputSpec::is_default")]
    pub output: OutputSpec,
    /// The interface of the system exported as one FMU (`[export]`,
    /// docs/fmu-export.md); ignored by `tether run`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub export: Option<ExportSpec>,
    /// The file this description was read from (set by
    /// [`SystemSpec::from_file`]), named in its error messages.
    #[serde(skip)]
    pub source: Option<PathBuf>,
}

/// How deep arrays and inline tables may nest in a TOML file: the TOML
/// reader's own limit (deeper is refused with this number in the message).
pub const TOML_MAX_NESTING: usize = 80;

/// A TOML error on one line: `line L, column C: message`. For an unknown
/// key the position is the key's own (toml reports the table's). Used for
/// every TOML file Tether reads (system, study and plan files, SSP's TOML
/// annotation).
pub fn toml_error(text: &str, e: &toml::de::Error) -> String {
    let mut message = e.message().replace('\n', " ").trim().to_string();
    if message.starts_with("cannot recurse further") {
        message = format!(
            "arrays and inline tables nested more than {TOML_MAX_NESTING} deep (the limit)"
        );
    }
    let Some(span) = e.span() else {
        return message;
    };
    let unknown = message
        .strip_prefix("unknown field `")
        .and_then(|rest| rest.split('`').next());
    let at = unknown
        .and_then(|key| find_key(text, span.clone(), key))
        .unwrap_or(span.start)
        .min(text.len());
    let line = text[..at].matches('\n').count() + 1;
    let column = text[..at].rfind('\n').map_or(at, |nl| at - nl - 1) + 1;
    format!("line {line}, column {column}: {message}")
}

/// Where `key = …` is written in the table at `span`: within an inline table
/// its span, else up to the next table header.
fn find_key(text: &str, span: std::ops::Range<usize>, key: &str) -> Option<usize> {
    let start = span.start.min(text.len());
    let end = if text[start..].starts_with('{') {
        span.end.min(text.len())
    } else {
        // The table's own lines: after its header, up to the next one.
        let body = text[start..].find('\n').map_or(text.len(), |n| start + n);
        text[body..]
            .match_indices('\n')
            .map(|(i, _)| body + i + 1)
            .find(|&l| text[l..].trim_start().starts_with('['))
            .unwrap_or(text.len())
    };
    let region = &text[start..end];
    let word = |c: char| c.is_alphanumeric() || c == '_' || c == '-';
    for (i, _) in region.match_indices(key) {
        let before = region[..i].chars().next_back();
        let after = region[i + key.len()..].trim_start_matches(['"', '\'']);
        let after = after.trim_start_matches([' ', '\t']);
        let bare = before.is_none_or(|c| !word(c));
        if bare && after.starts_with('=') {
            let quoted = matches!(before, Some('"' | '\''));
            return Some(start + i - usize::from(quoted));
        }
    }
    None
}

/// A signal connection: the receiving input takes `gain·value + offset` of
/// the sending output at macro points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConnectionSpec {
    /// The sending output, `<instance>.<variable>`.
    pub from: String,
    /// The receiving input, `<instance>.<variable>`.
    pub to: String,
    /// Factor of a linear transformation (Real only; default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain: Option<f64>,
    /// Offset of a linear transformation (Real only; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset: Option<f64>,
}

/// `[signals]`: the order in which signal-connected instances see each
/// other's values within a macro step, and whether the step is iterated
/// until the exchanged values agree (docs/algorithm.md, "Signal connections").
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SignalSettings {
    /// `"jacobi"` (the default) or `"gauss_seidel"`; refused with
    /// `solver = "newton"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scheme: Option<SignalScheme>,
    /// Tolerance on the exchanged values (at T_0, and per step when
    /// iterated): |Δv| ≤ tolerance·max(1, |v|); default 1e-10.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    /// Iterate every macro step: at most this many repetitions of the step
    /// (fixed point) or Newton updates (`solver = "newton"`) after its first
    /// run. None (the default): the step is run once.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub iterations: Option<usize>,
    /// How an iterated step updates the exchanged values: `"fixed_point"`
    /// (the default) or `"newton"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub solver: Option<SignalSolver>,
    /// A step that does not converge within `iterations` fails the run
    /// (otherwise it is counted and warned about once).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub strict: bool,
}

impl SignalSettings {
    fn is_default(&self) -> bool {
        *self == SignalSettings::default()
    }

    /// `tolerance`, or its default 1e-10.
    pub fn tolerance(&self) -> f64 {
        self.tolerance.unwrap_or(1e-10)
    }

    /// `scheme`, or its default Jacobi.
    pub fn scheme(&self) -> SignalScheme {
        self.scheme.unwrap_or_default()
    }
}

/// How an iterated macro step (`[signals] iterations`) updates the values
/// the signal connections exchange.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SignalSolver {
    /// Repeat the step with the values the last run produced (Jacobi or
    /// Gauss–Seidel, as `scheme` says).
    #[default]
    FixedPoint,
    /// Newton on v = G(v) with a finite-difference Jacobian from perturbed
    /// runs of the step.
    Newton,
}

/// Jacobi: every receiver takes the senders' values at T_N. Gauss–Seidel:
/// the signal-only instances step one after another in the order of the
/// system file, before the constraint-coupled ones; a receiver takes the
/// values at T_{N+1} of the senders that stepped before it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SignalScheme {
    /// All senders' values at T_N.
    #[default]
    Jacobi,
    /// Senders already stepped in this macro step give their values at T_{N+1}.
    GaussSeidel,
}

/// Time grid: `T_n = start + n·step`, up to `stop`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Experiment {
    /// Start time T_0.
    #[serde(default)]
    pub start: f64,
    /// End time.
    pub stop: f64,
    /// Macro-step size H.
    pub step: f64,
    /// Tolerance passed to every FMU's `fmi2SetupExperiment`, if given.
    #[serde(default)]
    pub tolerance: Option<f64>,
}

/// Settings that every method shares.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CouplingSettings {
    /// Degree k of the coupling polynomials (0, 1 or 2).
    pub order: usize,
    /// Relative finite-difference increment ε: Δu = ε·max(1, |u|).
    pub epsilon: f64,
    /// Largest condition number of the (row-scaled) interface Jacobian
    /// accepted before the run stops as singular.
    pub max_condition: f64,
    /// A quantity whose magnitude exceeds this factor times its scale at the
    /// start (at least 1) counts as diverged.
    pub divergence_factor: f64,
    /// The runs of a step on worker threads: auto, on or off
    /// (docs/algorithm.md, "Parallel runs").
    pub parallel: Parallel,
    /// Threads the runs may use, the main thread included (None: the
    /// machine's available parallelism).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub threads: Option<usize>,
    /// When the rollback of the instances the method rolls back is checked
    /// (docs/reliability.md): at setup, at setup and every
    /// [`crate::RECHECK_EVERY`] macro steps (the default), also after every
    /// restore, or never.
    pub check_rollback: CheckRollback,
    /// The run summary warns when the largest |g| of a constraint or joint
    /// condition over the run exceeds this (in the condition's units).
    pub residual_warning: f64,
    /// A run whose |g| of a constraint or joint condition exceeds this (in
    /// the condition's units) at an accepted point fails: the constraint is
    /// broken (docs/reliability.md). `"off"` disables it.
    pub residual_limit: ResidualLimit,
    /// Corrections per macro step (1 = the paper): after the corrector run,
    /// g is evaluated again and corrected with the same Jacobian, up to this
    /// many corrections in all (docs/algorithm.md, iterated correction).
    pub iterations: usize,
    /// An iterated correction stops when every update |Δu_m| is below
    /// `iteration_tol·max(1, |u_m|)`.
    pub iteration_tol: f64,
    /// When the interface Jacobian is made from perturbed runs: every step
    /// (the paper) or only when due, with Broyden updates in between.
    pub jacobian: JacobianMode,
    /// With `jacobian = "reuse"`: the most steps a Jacobian is kept.
    pub jacobian_max_age: u64,
}

/// When the master checks that `fmi2SetFMUstate` restores an instance
/// exactly (`[coupling] check_rollback`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CheckRollback {
    /// Once, before the first macro step: save, step, restore, compare the
    /// outputs with those at the save, repeat the step and require
    /// bit-identical outputs, restore.
    Setup,
    /// The setup check, repeated from the accepted point every
    /// [`crate::RECHECK_EVERY`] macro steps (the default): a restore that
    /// stops being exact, or was never deterministic, later in the run.
    #[default]
    Periodic,
    /// At setup, and after every restore of a macro step the coupled outputs
    /// are read back and compared with those at the save (one more
    /// `fmi2GetReal` per save and per restore).
    EveryStep,
    /// Never.
    Off,
}

/// `[coupling] residual_limit`: a number (in the constraint's units), or
/// `"off"`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResidualLimit(pub Option<f64>);

impl ResidualLimit {
    /// The default limit, 1 in the condition's units (m, rad, …): three
    /// times the largest |g| of the paper's convergence runs that complete
    /// (0.35, Method 1 index 1 with β = 0.2 at H = 1e-2), far above every
    /// example's (docs/system-file.md).
    pub const DEFAULT: ResidualLimit = ResidualLimit(Some(1.0));
}

impl Serialize for ResidualLimit {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.0 {
            Some(v) => s.serialize_f64(v),
            None => s.serialize_str("off"),
        }
    }
}

impl<'de> Deserialize<'de> for ResidualLimit {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = ResidualLimit;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a number > 0 or \"off\"")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<ResidualLimit, E> {
                Ok(ResidualLimit(Some(v)))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<ResidualLimit, E> {
                Ok(ResidualLimit(Some(v as f64)))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<ResidualLimit, E> {
                Ok(ResidualLimit(Some(v as f64)))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<ResidualLimit, E> {
                match v {
                    "off" => Ok(ResidualLimit(None)),
                    _ => Err(E::invalid_value(serde::de::Unexpected::Str(v), &self)),
                }
            }
        }
        d.deserialize_any(Visitor)
    }
}

impl Default for CouplingSettings {
    fn default() -> Self {
        CouplingSettings {
            order: 0,
            epsilon: 1e-5,
            max_condition: 1e12,
            divergence_factor: 1e6,
            parallel: Parallel::Auto,
            threads: None,
            check_rollback: CheckRollback::Periodic,
            residual_warning: 1e-3,
            residual_limit: ResidualLimit::DEFAULT,
            iterations: 1,
            iteration_tol: 1e-10,
            jacobian: JacobianMode::EveryStep,
            jacobian_max_age: 20,
        }
    }
}

/// One FMU instance.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstanceSpec {
    /// Instance name, used as the column prefix and in constraint expressions.
    pub name: String,
    /// Path of the `.fmu` file or unpacked FMU directory, relative to the system file.
    pub fmu: PathBuf,
    /// Start values of parameters (or of any settable variable) by name.
    #[serde(default)]
    pub parameters: BTreeMap<String, StartValue>,
    /// Where the FMU runs: in the master's process (default) or in a host
    /// process of its own (docs/reliability.md).
    #[serde(default)]
    pub isolation: Isolation,
    /// The longest an FMI call of this instance may take, in seconds: an
    /// isolated instance is then killed; an in-process one is reported (and
    /// the `tether` CLI ends the run).
    #[serde(default)]
    pub call_timeout: Option<f64>,
    /// A host on another machine that runs the instance, `tcp://ADDR:PORT`
    /// (`tether host`, docs/remote.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub host: Option<String>,
    /// The file holding the token of `host`, relative to the system file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub token_file: Option<PathBuf>,
    /// The FMU already on `host` (a path there): the archive is not sent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fmu_on_host: Option<PathBuf>,
    /// What a Dask worker must have to host the instance, by name, e.g.
    /// `{ licence = 1 }` (Python's `tether.run(system, client=…)`,
    /// docs/remote.md); the `tether` CLI runs the instance here and says so.
    #[serde(
        default,
        skip_serializing_if = "BTreeMap::is_empty",
        deserialize_with = "resources"
    )]
    pub resources: BTreeMap<String, f64>,
    /// The instance's own communication step, a whole multiple n·H of the
    /// system's macro step (signal-only instances: it steps every n-th
    /// macro step, docs/system-file.md "Per-instance steps"). None: H.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<f64>,
    /// `false`: the instance's runs stay on the main thread (FMUs bound to
    /// the thread that made them, such as Python-based ones); None: they
    /// may go to a worker thread (`[coupling] parallel`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parallel: Option<bool>,
    /// Which FMI interface the instance runs (docs/system-file.md, "Model
    /// exchange"): `auto` (default) keeps co-simulation and takes model
    /// exchange only where co-simulation would be refused.
    #[serde(default, skip_serializing_if = "InterfaceChoice::is_auto")]
    pub fmi_type: InterfaceChoice,
    /// The built-in integrator of a model-exchange instance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub integrator: Option<IntegratorSpec>,
}

/// `fmi_type` of an instance: the FMI interface it runs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum InterfaceChoice {
    /// Co-simulation where it runs the system's method; model exchange where
    /// co-simulation would be refused for a capability the method needs and
    /// the FMU offers model exchange.
    #[default]
    Auto,
    /// The FMU's co-simulation interface.
    CoSimulation,
    /// The FMU's model-exchange interface, integrated by the instance.
    ModelExchange,
}

impl InterfaceChoice {
    /// Every accepted spelling: Tether's and fmpy's (`fmi_type=` of
    /// `fmpy.simulate_fmu`) and SSP's `implementation`.
    pub const NAMES: [(&'static str, InterfaceChoice); 7] = [
        ("auto", InterfaceChoice::Auto),
        ("any", InterfaceChoice::Auto),
        ("co_simulation", InterfaceChoice::CoSimulation),
        ("CoSimulation", InterfaceChoice::CoSimulation),
        ("model_exchange", InterfaceChoice::ModelExchange),
        ("ModelExchange", InterfaceChoice::ModelExchange),
        ("model-exchange", InterfaceChoice::ModelExchange),
    ];

    /// The interface called `name`.
    pub fn parse(name: &str) -> Option<InterfaceChoice> {
        InterfaceChoice::NAMES
            .iter()
            .find(|(n, _)| *n == name)
            .map(|&(_, t)| t)
    }

    fn is_auto(&self) -> bool {
        *self == InterfaceChoice::Auto
    }
}

impl<'de> Deserialize<'de> for InterfaceChoice {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = String::deserialize(d)?;
        InterfaceChoice::parse(&name).ok_or_else(|| {
            serde::de::Error::custom(format!(
                "fmi_type = \"{name}\": expected \"auto\", \"co_simulation\" or \"model_exchange\" \
                 (fmpy's \"CoSimulation\" and \"ModelExchange\" too)"
            ))
        })
    }
}

/// `integrator = { method, rtol, atol, max_step }` of a model-exchange
/// instance (each optional; docs/fmi-import.md, "The integrator").
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IntegratorSpec {
    /// The method by its key name (`tether_fmi::Method::ALL`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub method: Option<String>,
    /// Relative tolerance (default: the experiment's tolerance, else 1e-6).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rtol: Option<f64>,
    /// Absolute tolerance relative to the states' nominals (default: rtol).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub atol: Option<f64>,
    /// The largest step (default: the communication step).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_step: Option<f64>,
}

impl IntegratorSpec {
    /// The integrator settings, or why they are wrong (naming the key).
    pub fn integrator(&self) -> Result<tether_fmi::Integrator, String> {
        let method = match &self.method {
            None => tether_fmi::Method::default(),
            Some(name) => tether_fmi::Method::parse(name).ok_or_else(|| {
                let known: Vec<&str> = tether_fmi::Method::ALL.iter().map(|(n, _)| *n).collect();
                format!("method = \"{name}\": unknown (known: {})", known.join(", "))
            })?,
        };
        let integrator = tether_fmi::Integrator {
            method,
            rtol: self.rtol,
            atol: self.atol,
            max_step: self.max_step,
        };
        integrator.check()?;
        Ok(integrator)
    }
}

/// `resources`: a table of numbers, the error naming what is expected.
fn resources<'de, D: serde::Deserializer<'de>>(d: D) -> Result<BTreeMap<String, f64>, D::Error> {
    struct Amount(f64);
    impl<'de> Deserialize<'de> for Amount {
        fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
            struct Visitor;
            impl serde::de::Visitor<'_> for Visitor {
                type Value = Amount;
                fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                    f.write_str("a number of units of a Dask worker resource, e.g. { licence = 1 }")
                }
                fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Amount, E> {
                    Ok(Amount(v as f64))
                }
                fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Amount, E> {
                    Ok(Amount(v as f64))
                }
                fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Amount, E> {
                    Ok(Amount(v))
                }
            }
            d.deserialize_any(Visitor)
        }
    }
    struct Table;
    impl<'de> serde::de::Visitor<'de> for Table {
        type Value = BTreeMap<String, f64>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a table of Dask worker resources, e.g. { licence = 1 }")
        }
        fn visit_map<A: serde::de::MapAccess<'de>>(
            self,
            mut map: A,
        ) -> Result<Self::Value, A::Error> {
            let mut table = BTreeMap::new();
            while let Some((name, Amount(amount))) = map.next_entry::<String, Amount>()? {
                table.insert(name, amount);
            }
            Ok(table)
        }
    }
    d.deserialize_map(Table)
}

/// Where an instance's FMU runs (`isolation` of an instance).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Isolation {
    /// In the master's process: the fastest; a crash of the FMU is the master's.
    #[default]
    None,
    /// In a host process of its own: a crash, exit or hang of the FMU becomes
    /// an error of the run.
    Process,
}

/// A start value as written in TOML.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum StartValue {
    /// `true` / `false`
    Boolean(bool),
    /// An integer literal (also accepted for Real variables).
    Integer(i64),
    /// A floating-point literal.
    Real(f64),
    /// A string (also a Binary value, in hexadecimal).
    String(String),
    /// An FMI 3.0 array: its values in row-major order, or nested by dimension.
    Array(Vec<StartValue>),
}

impl std::fmt::Display for StartValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StartValue::Boolean(b) => write!(f, "{b}"),
            StartValue::Integer(i) => write!(f, "{i}"),
            StartValue::Real(r) => write!(f, "{r}"),
            StartValue::String(s) => write!(f, "{s:?}"),
            StartValue::Array(a) => {
                write!(f, "[")?;
                for (k, x) in a.iter().enumerate() {
                    if k > 0 {
                        write!(f, ", ")?;
                    }
                    write!(f, "{x}")?;
                }
                write!(f, "]")
            }
        }
    }
}

impl StartValue {
    /// The values of an array, nested ones flattened in order (a scalar: itself).
    pub fn flatten_into(&self, out: &mut Vec<StartValue>) {
        match self {
            StartValue::Array(a) => a.iter().for_each(|x| x.flatten_into(out)),
            x => out.push(x.clone()),
        }
    }

    /// Read `NAME=VALUE` text from the command line: a boolean, a number, an
    /// array `[1, 2, 3]` (nested or flat, of those) or a string.
    pub fn parse_cli(text: &str) -> StartValue {
        if let Some(inner) = text
            .trim()
            .strip_prefix('[')
            .and_then(|t| t.strip_suffix(']'))
        {
            let parsed: Option<Vec<StartValue>> = split_top(inner)
                .into_iter()
                .map(|part| {
                    let part = part.trim();
                    (!part.is_empty()).then(|| StartValue::parse_cli(part))
                })
                .collect();
            if let Some(values) = parsed {
                return StartValue::Array(values);
            }
        }
        match text {
            "true" => StartValue::Boolean(true),
            "false" => StartValue::Boolean(false),
            _ => text
                .parse::<i64>()
                .map(StartValue::Integer)
                .or_else(|_| text.parse::<f64>().map(StartValue::Real))
                .unwrap_or_else(|_| StartValue::String(text.to_string())),
        }
    }
}

/// `text` split at the commas outside brackets (an empty text: no parts).
fn split_top(text: &str) -> Vec<&str> {
    if text.trim().is_empty() {
        return Vec::new();
    }
    let (mut parts, mut depth, mut from) = (Vec::new(), 0i32, 0);
    for (i, c) in text.char_indices() {
        match c {
            '[' => depth += 1,
            ']' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&text[from..i]);
                from = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&text[from..]);
    parts
}

/// One scalar algebraic constraint `g = 0` with its multiplier λ.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintSpec {
    /// Name, used as the column prefix (`<name>.lambda`, `<name>.g`).
    pub name: String,
    /// Position level g as a linear expression of outputs.
    pub position: String,
    /// Velocity level ġ, needed by index-2 and index-1 variants.
    #[serde(default)]
    pub velocity: Option<String>,
    /// Acceleration level g̈, needed by index-1 variants, the explicit method
    /// and consistent initial multipliers.
    #[serde(default)]
    pub acceleration: Option<String>,
    /// The inputs λ drives: each term `c·inst.input` receives `c·λ`.
    pub drives: String,
    /// λ at the start time: a number, or `"consistent"` (the default) to solve
    /// the acceleration-level condition at T_0.
    #[serde(default)]
    pub initial: InitialMultiplier,
}

/// A joint between two markers: its kind, the markers and its geometry.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// Name, used as the column prefix (`<name>.lambda[k]`, `<name>.g[k]`).
    pub name: String,
    /// atpoint, inplane, perpendicular, universal, revolute, cylindrical,
    /// translational, planar, inline or orientation.
    pub kind: String,
    /// Marker on side i: `<instance>.<marker>`.
    pub i: String,
    /// Marker on side j: `<instance>.<marker>`.
    pub j: String,
    /// `"xy"`: both sides move in the world xy-plane; only in-plane conditions
    /// and port components are used.
    #[serde(default)]
    pub plane: Option<String>,
    /// Joint-frame z axis on side i, in marker-i coordinates (default z).
    #[serde(default)]
    pub axis_i: Option<[f64; 3]>,
    /// Joint-frame x axis on side i (default x; orthonormalised against the axis).
    #[serde(default)]
    pub ref_i: Option<[f64; 3]>,
    /// Joint-frame z axis on side j, in marker-j coordinates (default z).
    #[serde(default)]
    pub axis_j: Option<[f64; 3]>,
    /// Joint-frame x axis on side j (default x).
    #[serde(default)]
    pub ref_j: Option<[f64; 3]>,
    /// Attachment point on side i, in marker-i coordinates (default origin).
    #[serde(default)]
    pub offset_i: Option<[f64; 3]>,
    /// Attachment point on side j, in marker-j coordinates (default origin).
    #[serde(default)]
    pub offset_j: Option<[f64; 3]>,
    /// The paper's style: one `drives` expression per condition; the FMUs take
    /// the multipliers as inputs and apply the force law themselves. Without
    /// it, the master drives the markers' force and torque ports.
    #[serde(default)]
    pub multipliers: Option<Vec<String>>,
    /// Multipliers at the start time: `"consistent"` (default) or one number
    /// per condition.
    #[serde(default)]
    pub initial: JointInitial,
}

/// λ(T_0) of a joint: `"consistent"` or one value per condition.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum JointInitial {
    /// Solved with the acceleration-level conditions at T_0.
    #[default]
    Consistent,
    /// Given by the user, one per condition.
    Values(Vec<f64>),
}

impl Serialize for JointInitial {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            JointInitial::Values(v) => v.serialize(s),
            JointInitial::Consistent => s.serialize_str("consistent"),
        }
    }
}

impl<'de> Deserialize<'de> for JointInitial {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            List(Vec<f64>),
            Word(String),
        }
        match Raw::deserialize(d)? {
            Raw::List(v) => Ok(JointInitial::Values(v)),
            Raw::Word(w) if w == "consistent" => Ok(JointInitial::Consistent),
            Raw::Word(w) => Err(serde::de::Error::custom(format!(
                "initial must be a list of numbers or \"consistent\", found \"{w}\""
            ))),
        }
    }
}

/// An additional coupling variable: an input that must equal an expression
/// of outputs at every macro point (row `u − value = 0`).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CouplingVariableSpec {
    /// Name, used as the column `<name>.value`.
    pub name: String,
    /// The inputs it drives, as a linear expression (`inst.input`).
    pub drives: String,
    /// The value it must take, a linear expression of outputs.
    pub value: String,
    /// Value at the start time: a number, or `"consistent"` (the default).
    #[serde(default)]
    pub initial: InitialMultiplier,
}

/// How λ(T_0) is obtained: a number, or `"consistent"`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum InitialMultiplier {
    /// Given by the user.
    Value(f64),
    /// Solved from the acceleration-level condition at T_0.
    #[default]
    Consistent,
}

impl Serialize for InitialMultiplier {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            InitialMultiplier::Value(v) => s.serialize_f64(*v),
            InitialMultiplier::Consistent => s.serialize_str("consistent"),
        }
    }
}

impl<'de> Deserialize<'de> for InitialMultiplier {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Integer(i64),
            Real(f64),
            Word(String),
        }
        match Raw::deserialize(d)? {
            Raw::Integer(i) => Ok(InitialMultiplier::Value(i as f64)),
            Raw::Real(r) => Ok(InitialMultiplier::Value(r)),
            Raw::Word(w) if w == "consistent" => Ok(InitialMultiplier::Consistent),
            Raw::Word(w) => Err(serde::de::Error::custom(format!(
                "initial must be a number or \"consistent\", found \"{w}\""
            ))),
        }
    }
}

/// `[coupling] jacobian`: when the perturbed runs are made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JacobianMode {
    /// Every macro step (the paper).
    #[default]
    EveryStep,
    /// Only when due: the Jacobian mispredicted the last correction (then it
    /// is made again at once and the correction repeated), it is older than
    /// `jacobian_max_age` steps, the step size changed by more than a factor
    /// 1.25 since it was made, or the polynomials' degree is still growing
    /// (start-up).
    Reuse,
}

impl std::str::FromStr for JacobianMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "every_step" => Ok(JacobianMode::EveryStep),
            "reuse" => Ok(JacobianMode::Reuse),
            other => Err(format!(
                "unknown jacobian mode '{other}': expected every_step or reuse"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The limit the message states is the TOML reader's: 80 levels of arrays
    /// or inline tables are read, 81 are refused with it.
    #[test]
    fn toml_nesting_is_read_up_to_the_stated_limit() {
        let nested = |n: usize| format!("a = {}1{}", "[".repeat(n), "]".repeat(n));
        let tables = |n: usize| format!("a = {}1{}", "{ b = ".repeat(n), "}".repeat(n));
        for text in [nested, tables] {
            assert!(text(TOML_MAX_NESTING).parse::<toml::Table>().is_ok());
            let deeper = text(TOML_MAX_NESTING + 1);
            let e = toml::from_str::<toml::Table>(&deeper).unwrap_err();
            assert!(
                toml_error(&deeper, &e)
                    .ends_with("arrays and inline tables nested more than 80 deep (the limit)"),
                "{}",
                toml_error(&deeper, &e)
            );
        }
    }

    #[test]
    fn cli_values_read_arrays_flat_or_nested() {
        use StartValue::{Array, Integer, Real, String as Text};
        assert_eq!(
            StartValue::parse_cli("[1, 2.5]"),
            Array(vec![Integer(1), Real(2.5)])
        );
        let nested = StartValue::parse_cli("[[1, 0], [0, 1]]");
        assert_eq!(
            nested,
            Array(vec![
                Array(vec![Integer(1), Integer(0)]),
                Array(vec![Integer(0), Integer(1)])
            ])
        );
        let mut flat = Vec::new();
        nested.flatten_into(&mut flat);
        assert_eq!(flat, [Integer(1), Integer(0), Integer(0), Integer(1)]);
        assert_eq!(nested.to_string(), "[[1, 0], [0, 1]]");
        assert_eq!(StartValue::parse_cli("[]"), Array(vec![]));
        // Not an array: an empty element, or no closing bracket.
        assert_eq!(StartValue::parse_cli("[1,,2]"), Text("[1,,2]".into()));
        assert_eq!(StartValue::parse_cli("[1"), Text("[1".into()));
    }

    #[test]
    fn an_unknown_key_is_reported_at_its_own_line_and_column() {
        let text = "[experiment]\nstop = 1.0\nstep = 1e-3\n\n[method]\nkind = \"baumgarte\"\n  \
                    betta = 1\n\n[[instance]]\nname = \"m\"\nfmu = \"o.fmu\"\n\
                    parameters = { c = 1.0 }\nisolate = true\n";
        let e = SystemSpec::from_toml(&text.replace("isolate = true\n", ""))
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "system file <text>: line 7, column 3: unknown field `betta`, expected one of \
             `index`, `beta`, `gamma`"
        );
        let text = text.replace("  betta = 1\n", "");
        let e = SystemSpec::from_toml(&text).unwrap_err().to_string();
        assert!(
            e.starts_with("system file <text>: line 12, column 1: unknown field `isolate`"),
            "{e}"
        );
        let text = text
            .replace("isolate = true\n", "")
            .replace("[experiment]\n", "[experiment]\n\"sotp\" = 2\n");
        let e = SystemSpec::from_toml(&text).unwrap_err().to_string();
        assert!(
            e.starts_with("system file <text>: line 2, column 1: unknown field `sotp`"),
            "{e}"
        );
    }

    /// `[coupling] residual_limit`: 1 by default, a number > 0, or `"off"`;
    /// anything else is one error naming the key's line.
    #[test]
    fn residual_limit_is_a_positive_number_or_off() {
        let text = "[experiment]\nstop = 1.0\nstep = 1e-3\n\n[coupling]\n\n[[instance]]\n\
                    name = \"m\"\nfmu = \"o.fmu\"\n";
        let with = |value: &str| {
            let text = text.replace(
                "[coupling]\n",
                &format!("[coupling]\nresidual_limit = {value}\n"),
            );
            SystemSpec::from_toml(&text).and_then(|s| s.validate().map(|()| s))
        };
        let limit = |value: &str| with(value).unwrap().coupling.residual_limit;
        assert_eq!(
            SystemSpec::from_toml(text).unwrap().coupling.residual_limit,
            ResidualLimit(Some(1.0))
        );
        assert_eq!(limit("0.25"), ResidualLimit(Some(0.25)));
        assert_eq!(limit("3"), ResidualLimit(Some(3.0)));
        assert_eq!(limit("\"off\""), ResidualLimit(None));
        let e = with("\"of\"").unwrap_err().to_string();
        assert!(
            e.starts_with("system file <text>: line 6, column 18: invalid value: string \"of\", expected a number > 0 or \"off\""),
            "{e}"
        );
        for bad in ["0", "-1", "nan", "inf"] {
            let e = with(bad).unwrap_err().to_string();
            assert!(e.contains("residual_limit"), "{bad}: {e}");
        }
    }

    /// `*` matches any characters (also none), everything else only itself:
    /// brackets, commas and dots are literal.
    #[test]
    fn output_patterns_take_everything_but_the_star_literally() {
        let yes = [
            ("body.A.R[1,2]", "body.A.R[1,2]"),
            ("body.*.R[1,2]", "body.A.R[1,2]"),
            ("*.lambda[*]", "hinge.lambda[3]"),
            ("*", "x"),
            ("link.*", "link."),
            ("a*b*c", "abbc"),
        ];
        for (pattern, name) in yes {
            assert!(matches_pattern(pattern, name), "{pattern} {name}");
        }
        let no = [
            ("body.A.R[1,2]", "body.A.R[1,3]"),
            ("body.A.R[1,?]", "body.A.R[1,2]"),
            ("body.A.R[12]", "body.A.R[1,2]"),
            ("link.*", "links.g"),
            ("a*b*c", "acb"),
            ("*.g", "link.gx"),
            ("ab*ba", "aba"),
        ];
        for (pattern, name) in no {
            assert!(!matches_pattern(pattern, name), "{pattern} {name}");
        }
        let columns: Vec<String> = ["b.R[1,1]", "b.R[1,2]", "h.lambda[1]", "h.g[1]"]
            .map(String::from)
            .to_vec();
        let only = |patterns: &[&str]| OutputSpec {
            interval: None,
            variables: patterns.iter().map(|p| p.to_string()).collect(),
        };
        assert_eq!(
            only(&["h.*", "b.R[1,2]"]).select(&columns).unwrap(),
            [1, 2, 3]
        );
        assert_eq!(only(&[]).select(&columns).unwrap(), [0, 1, 2, 3]);
        let interval = |dt: f64| OutputSpec {
            interval: Some(dt),
            variables: Vec::new(),
        };
        assert_eq!(interval(0.3).every(1e-3).unwrap(), 300);
        assert_eq!(interval(1e-3).every(1e-3).unwrap(), 1);
        assert!(interval(1.5e-3).every(1e-3).is_err());
        assert!(interval(0.0).every(1e-3).is_err());
        assert!(interval(f64::NAN).every(1e-3).is_err());
    }

    #[test]
    fn a_stop_time_off_the_grid_is_refused_naming_the_nearest_grid_point() {
        let spec = |stop: f64, step: f64| {
            SystemSpec::from_toml(
                &OSC.replace("stop = 1.0", &format!("stop = {stop:?}"))
                    .replace("step = 1e-3", &format!("step = {step:?}")),
            )
            .unwrap()
        };
        assert!(spec(1.0, 1e-3).check_grid().is_ok());
        assert!(
            spec(0.1, 1e-3).check_grid().is_ok(),
            "within rounding of the grid"
        );
        let off = spec(1e-4, 1e-3);
        assert_eq!(off.end_time(), 1e-3);
        assert_eq!(
            off.check_grid().unwrap_err().to_string(),
            "invalid stop = 0.0001: expected a point of the macro grid start + n·step (start = 0, step = 0.001); the nearest is 0.001 (or give a step that divides stop - start, or adaptive steps)",
        );
        assert!(spec(1.0, 0.3)
            .check_grid()
            .unwrap_err()
            .to_string()
            .contains("the nearest is 0.9 "));
    }

    const OSC: &str = r#"
        [experiment]
        stop = 1.0
        step = 1e-3

        [method]
        kind = "baumgarte"
        beta = 2e-3
        gamma = 1e-6

        [[instance]]
        name = "mass1"
        fmu = "osc.fmu"
        parameters = { m = 1, c = 1000.0, exact = true }

        [[instance]]
        name = "mass2"
        fmu = "osc.fmu"

        [[constraint]]
        name = "link"
        position = "mass2.x - mass1.x"
        drives = "mass1.F - mass2.F"
        initial = 333.0
    "#;

    #[test]
    fn a_system_file_parses_with_its_defaults() {
        let spec = SystemSpec::from_toml(OSC).unwrap();
        spec.validate().unwrap();
        assert_eq!(spec.instances.len(), 2);
        assert_eq!(spec.instances[0].parameters["m"], StartValue::Integer(1));
        assert_eq!(
            spec.instances[0].parameters["exact"],
            StartValue::Boolean(true)
        );
        assert_eq!(spec.constraints[0].initial, InitialMultiplier::Value(333.0));
        assert_eq!(spec.coupling.order, 0);
        assert_eq!(spec.macro_steps(), 1000);
        assert_eq!(
            spec.method,
            Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6
            }
        );
    }

    #[test]
    fn initial_defaults_to_consistent_and_rejects_other_words() {
        let text = OSC.replace("initial = 333.0", "");
        let spec = SystemSpec::from_toml(&text).unwrap();
        assert_eq!(spec.constraints[0].initial, InitialMultiplier::Consistent);
        let text = OSC.replace("initial = 333.0", "initial = \"consistent\"");
        assert!(SystemSpec::from_toml(&text).is_ok());
        let text = OSC.replace("initial = 333.0", "initial = \"guess\"");
        assert!(SystemSpec::from_toml(&text).is_err());
    }

    #[test]
    fn rejects_bad_experiments_and_settings() {
        for (from, to) in [
            ("step = 1e-3", "step = 0.0"),
            ("step = 1e-3", "step = -1e-3"),
            ("stop = 1.0", "stop = -1.0"),
            ("beta = 2e-3", "beta = -2e-3"),
        ] {
            let spec = SystemSpec::from_toml(&OSC.replace(from, to)).unwrap();
            let err = spec.validate().unwrap_err().to_string();
            assert!(!err.contains('\n'), "{err}");
        }
        let text = OSC.replace(
            "[[instance]]\n        name = \"mass1\"",
            "[coupling]\n        order = 3\n\n        [[instance]]\n        name = \"mass1\"",
        );
        let spec = SystemSpec::from_toml(&text).unwrap();
        assert!(spec.validate().unwrap_err().to_string().contains("order"));
        let text = OSC.replace("name = \"mass2\"", "name = \"mass1\"");
        assert!(SystemSpec::from_toml(&text).unwrap().validate().is_err());
        assert!(SystemSpec::from_toml("[experiment]\nstop = 1\nstep = 0.1\nbogus = 1\n").is_err());
    }
}

/// Whether perturbed runs go to other threads (`[coupling] parallel`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Parallel {
    /// Measure during the first macro steps, then parallel only if it pays.
    #[default]
    Auto,
    /// Always, for every instance whose FMU allows it.
    On,
    /// Never: every run on the main thread.
    Off,
}

impl std::str::FromStr for Parallel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Parallel::Auto),
            "on" => Ok(Parallel::On),
            "off" => Ok(Parallel::Off),
            _ => Err(format!("'{s}' is not one of auto, on, off")),
        }
    }
}
