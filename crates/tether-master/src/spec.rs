//! The system file: which FMUs, how they are coupled, and how to run them.
//!
//! The format is TOML; `docs/system-file.md` documents every key. This module
//! only reads and checks the file's own consistency; names of FMU variables are
//! checked against the FMUs when the [`crate::Simulation`] is built.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::jacobian_reuse::JacobianMode;
use crate::step_control::StepControl;
use crate::{MasterError, Method, Parallel};

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
    /// Perturbed runs on other threads: auto, on or off (docs/algorithm.md).
    pub parallel: Parallel,
    /// When the rollback of the instances the method rolls back is checked
    /// (docs/reliability.md): at setup (the default), also after every
    /// restore, or never.
    pub check_rollback: CheckRollback,
    /// The run summary warns when the largest |g| of a constraint or joint
    /// condition over the run exceeds this (in the condition's units).
    pub residual_warning: f64,
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
    #[default]
    Setup,
    /// At setup, and after every restore of a macro step the coupled outputs
    /// are read back and compared with those at the save (one more
    /// `fmi2GetReal` per save and per restore).
    EveryStep,
    /// Never.
    Off,
}

impl Default for CouplingSettings {
    fn default() -> Self {
        CouplingSettings {
            order: 0,
            epsilon: 1e-5,
            max_condition: 1e12,
            divergence_factor: 1e6,
            parallel: Parallel::Auto,
            check_rollback: CheckRollback::Setup,
            residual_warning: 1e-3,
            iterations: 1,
            iteration_tol: 1e-10,
            jacobian: JacobianMode::EveryStep,
            jacobian_max_age: 20,
        }
    }
}

/// One FMU instance.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InstanceSpec {
    /// Instance name, used as the column prefix and in constraint expressions.
    pub name: String,
    /// Path of the `.fmu` file or unpacked FMU directory, relative to the system file.
    pub fmu: PathBuf,
    /// Start values of parameters (or of any settable variable) by name.
    #[serde(default)]
    pub parameters: BTreeMap<String, StartValue>,
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
    /// A string.
    String(String),
}

impl std::fmt::Display for StartValue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StartValue::Boolean(b) => write!(f, "{b}"),
            StartValue::Integer(i) => write!(f, "{i}"),
            StartValue::Real(r) => write!(f, "{r}"),
            StartValue::String(s) => write!(f, "{s:?}"),
        }
    }
}

impl StartValue {
    /// Read `NAME=VALUE` text from the command line: a boolean, a number or a string.
    pub fn parse_cli(text: &str) -> StartValue {
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

impl SystemSpec {
    /// Read a system file; relative FMU paths are resolved against its folder.
    pub fn from_file(path: &Path) -> Result<SystemSpec, MasterError> {
        let text = std::fs::read_to_string(path).map_err(|e| MasterError::SystemFile {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        let mut spec = SystemSpec::from_toml(&text).map_err(|e| match e {
            MasterError::SystemFile { reason, .. } => MasterError::SystemFile {
                path: path.to_path_buf(),
                reason,
            },
            other => other,
        })?;
        let base = path.parent().unwrap_or(Path::new("."));
        for inst in &mut spec.instances {
            if inst.fmu.is_relative() {
                inst.fmu = base.join(&inst.fmu);
            }
        }
        Ok(spec)
    }

    /// Read a system description from TOML text (paths are left as written).
    pub fn from_toml(text: &str) -> Result<SystemSpec, MasterError> {
        toml::from_str(text).map_err(|e| MasterError::SystemFile {
            path: PathBuf::from("<text>"),
            reason: e.to_string().replace('\n', " ").trim().to_string(),
        })
    }

    /// Check what can be checked without the FMUs: times, settings, names.
    pub fn validate(&self) -> Result<(), MasterError> {
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
        self.method.validate()?;
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
        if self.instances.is_empty() {
            return Err(MasterError::SystemFile {
                path: PathBuf::from("<system>"),
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
                    path: PathBuf::from("<system>"),
                    reason: format!(
                        "name '{name}' must start with a letter and contain only letters, digits and '_'"
                    ),
                });
            }
            if !seen.insert(name.clone()) {
                return Err(MasterError::SystemFile {
                    path: PathBuf::from("<system>"),
                    reason: format!("name '{name}' is used twice"),
                });
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
        Ok(())
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

    /// A warning when `stop` is not on the macro grid (beyond a relative 1e-9
    /// of a step): the run ends at the nearest grid point instead.
    pub fn grid_warning(&self) -> Option<String> {
        let e = &self.experiment;
        if self.step_control.is_some() {
            return None;
        }
        let end = self.end_time();
        ((end - e.stop).abs() > 1e-9 * e.step).then(|| {
            format!(
                "stop = {} is not on the macro grid start + n·step (start = {}, step = {}): the run ends at t = {end}",
                e.stop, e.start, e.step
            )
        })
    }

    pub fn macro_steps(&self) -> u64 {
        let e = &self.experiment;
        let n = ((e.stop - e.start) / e.step).round();
        (n.max(1.0)) as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stop_time_off_the_grid_is_named_with_the_actual_end() {
        let spec = |stop: f64, step: f64| {
            SystemSpec::from_toml(
                &OSC.replace("stop = 1.0", &format!("stop = {stop:?}"))
                    .replace("step = 1e-3", &format!("step = {step:?}")),
            )
            .unwrap()
        };
        assert_eq!(spec(1.0, 1e-3).grid_warning(), None);
        assert_eq!(
            spec(0.1, 1e-3).grid_warning(),
            None,
            "within rounding of the grid"
        );
        let off = spec(1e-4, 1e-3);
        assert_eq!(off.end_time(), 1e-3);
        assert_eq!(
            off.grid_warning().as_deref(),
            Some("stop = 0.0001 is not on the macro grid start + n·step (start = 0, step = 0.001): the run ends at t = 0.001")
        );
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
    fn reads_a_system_file() {
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
