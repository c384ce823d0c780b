//! Changes to a system file made outside it: `tether run` and `tether sweep`
//! flags, `--set instance.parameter=value`, and the `[set]` table and
//! `[[variant]]`s of a study file all build one [`Overrides`] and apply it to
//! a [`SystemSpec`] before the run.

use std::collections::BTreeMap;

use serde::{Deserialize, Deserializer};

use crate::{IndexConflict, IndexedKind, JacobianMode, Method, Parallel, StartValue, SystemSpec};

/// Settings that replace those of a system file. `None` (and an empty
/// [`MethodChange`]) keeps the file's value.
///
/// In a study file it is written as a TOML table whose `method` is a whole
/// method (`method = { kind = "weighted", a = 1.0 }`, parameters not given
/// are 0); the command line changes single method parameters through
/// [`MethodChange`].
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Overrides {
    /// The coupling method, or some of its parameters.
    #[serde(default, deserialize_with = "whole_method")]
    pub method: MethodChange,
    /// Degree k of the coupling polynomials (`[coupling] order`).
    #[serde(default)]
    pub order: Option<usize>,
    /// Macro-step size H (`[experiment] step`).
    #[serde(default)]
    pub step: Option<f64>,
    /// Stop time (`[experiment] stop`).
    #[serde(default)]
    pub stop: Option<f64>,
    /// Finite-difference increment ε (`[coupling] epsilon`).
    #[serde(default)]
    pub epsilon: Option<f64>,
    /// The master's divergence bound (`[coupling] divergence_factor`).
    #[serde(default)]
    pub divergence_factor: Option<f64>,
    /// The runs of a step on worker threads (`[coupling] parallel`).
    #[serde(default)]
    pub parallel: Option<Parallel>,
    /// Threads the runs may use, the main thread included (`[coupling] threads`).
    #[serde(default)]
    pub threads: Option<usize>,
    /// Corrections per macro step (`[coupling] iterations`).
    #[serde(default)]
    pub iterations: Option<usize>,
    /// Tolerance of the iterated correction (`[coupling] iteration_tol`).
    #[serde(default)]
    pub iteration_tol: Option<f64>,
    /// When the interface Jacobian is recomputed (`[coupling] jacobian`).
    #[serde(default)]
    pub jacobian: Option<JacobianMode>,
    /// Relative tolerance of adaptive macro steps (`[step_control] rtol`);
    /// turns them on.
    #[serde(default)]
    pub step_rtol: Option<f64>,
    /// Absolute tolerance of adaptive macro steps (`[step_control] atol`);
    /// turns them on.
    #[serde(default)]
    pub step_atol: Option<f64>,
    /// FMU start values by target `instance.parameter`.
    #[serde(default)]
    pub parameters: BTreeMap<String, StartValue>,
}

/// A change to the coupling method: another kind, single parameters, or both.
///
/// Applied to a method: the kind is the change's kind, else the method's own.
/// Parameters the change does not give are the method's own when the kind
/// stays, else 0 (the explicit method's μ_B has no default and must be
/// given). A parameter of another kind than the resulting one is an error.
/// A whole [`Method`] converts into a change that gives every parameter.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MethodChange {
    /// The method's kind.
    pub kind: Option<MethodKind>,
    /// The index level (methods baumgarte and weighted): the weights the
    /// change does not give are the method's own where the index uses them
    /// and they are > 0, else the index's defaults
    /// ([`IndexedKind::default_weights`]); weights the index does not use are 0.
    pub index: Option<u8>,
    /// Baumgarte velocity weight β.
    pub beta: Option<f64>,
    /// Baumgarte acceleration weight γ.
    pub gamma: Option<f64>,
    /// Velocity-level weight a (method weighted).
    pub a: Option<f64>,
    /// Acceleration-level weight b (method weighted).
    pub b: Option<f64>,
    /// Stabilisation constant μ_B (method explicit).
    pub mu: Option<f64>,
}

/// The kinds of [`Method`], without their parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MethodKind {
    /// [`Method::Baumgarte`].
    Baumgarte,
    /// [`Method::Weighted`].
    Weighted,
    /// [`Method::Explicit`].
    Explicit,
}

/// Why overrides cannot be read or applied; one line naming the culprit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OverrideError {
    /// A setting is not of the form `instance.parameter=value`.
    #[error("setting '{setting}': {reason}")]
    Setting {
        /// The setting as written.
        setting: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A target `instance.parameter` is malformed or names no instance.
    #[error("target '{target}': {reason}")]
    Target {
        /// The target as written.
        target: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A method name that is not one of the kinds.
    #[error("unknown method '{0}': expected baumgarte, weighted or explicit")]
    UnknownMethod(String),
    /// A method parameter given for another kind of method.
    #[error("{parameter} applies to method {method}, but the method is {current}")]
    Misplaced {
        /// The parameter (`beta`, `gamma`, `a`, `b`, `mu`).
        parameter: &'static str,
        /// The kind it belongs to.
        method: &'static str,
        /// The kind of the resulting method.
        current: &'static str,
    },
    /// The explicit method without its μ_B.
    #[error("method explicit needs mu (its stabilisation constant)")]
    MissingMu,
    /// An index that a weight given with it contradicts.
    #[error("{0}")]
    Index(IndexConflict),
}

impl Overrides {
    /// Read one setting `instance.parameter=value` into the parameters; the
    /// value is a boolean, an integer, a real or else a string. A later
    /// setting of the same target replaces an earlier one.
    pub fn set(&mut self, setting: &str) -> Result<(), OverrideError> {
        let bad = |reason: &str| OverrideError::Setting {
            setting: setting.to_string(),
            reason: reason.to_string(),
        };
        let (target, value) = setting
            .split_once('=')
            .ok_or_else(|| bad("expected INSTANCE.PARAMETER=VALUE"))?;
        let (target, value) = (target.trim(), value.trim());
        split_target(target)?;
        if value.is_empty() {
            return Err(bad("no value after '='"));
        }
        self.parameters
            .insert(target.to_string(), StartValue::parse_cli(value));
        Ok(())
    }

    /// `self` with every setting that `over` gives replaced by `over`'s:
    /// scalars and parameters (by target) of `over` win, and `over`'s
    /// method change goes on top of `self`'s ([`MethodChange::merged`]).
    pub fn merged(&self, over: &Overrides) -> Overrides {
        let mut parameters = self.parameters.clone();
        parameters.extend(over.parameters.iter().map(|(k, v)| (k.clone(), v.clone())));
        Overrides {
            method: self.method.merged(&over.method),
            order: over.order.or(self.order),
            step: over.step.or(self.step),
            stop: over.stop.or(self.stop),
            epsilon: over.epsilon.or(self.epsilon),
            divergence_factor: over.divergence_factor.or(self.divergence_factor),
            parallel: over.parallel.or(self.parallel),
            threads: over.threads.or(self.threads),
            iterations: over.iterations.or(self.iterations),
            iteration_tol: over.iteration_tol.or(self.iteration_tol),
            jacobian: over.jacobian.or(self.jacobian),
            step_rtol: over.step_rtol.or(self.step_rtol),
            step_atol: over.step_atol.or(self.step_atol),
            parameters,
        }
    }

    /// Apply to a system. A parameter target that is malformed or names no
    /// instance, and a method change that does not fit, are errors; whether
    /// an FMU has the parameter, and whether the values are in range, is
    /// checked when the run is built.
    pub fn apply(&self, spec: &mut SystemSpec) -> Result<(), OverrideError> {
        if let Some(stop) = self.stop {
            spec.experiment.stop = stop;
        }
        if let Some(step) = self.step {
            spec.experiment.step = step;
        }
        if let Some(order) = self.order {
            spec.coupling.order = order;
        }
        if let Some(epsilon) = self.epsilon {
            spec.coupling.epsilon = epsilon;
        }
        if let Some(factor) = self.divergence_factor {
            spec.coupling.divergence_factor = factor;
        }
        if let Some(parallel) = self.parallel {
            spec.coupling.parallel = parallel;
        }
        if let Some(threads) = self.threads {
            spec.coupling.threads = Some(threads);
        }
        if let Some(iterations) = self.iterations {
            spec.coupling.iterations = iterations;
        }
        if let Some(tol) = self.iteration_tol {
            spec.coupling.iteration_tol = tol;
        }
        if let Some(mode) = self.jacobian {
            spec.coupling.jacobian = mode;
        }
        if let Some(rtol) = self.step_rtol {
            spec.step_control.get_or_insert_with(Default::default).rtol = rtol;
        }
        if let Some(atol) = self.step_atol {
            spec.step_control.get_or_insert_with(Default::default).atol = atol;
        }
        spec.method = self.method.apply(spec.method)?;
        for (target, value) in &self.parameters {
            let (instance, parameter) = split_target(target)?;
            let names: Vec<&str> = spec.instances.iter().map(|i| i.name.as_str()).collect();
            let missing = OverrideError::Target {
                target: target.clone(),
                reason: format!(
                    "no instance '{instance}' in the system; instances are {}",
                    names.join(", ")
                ),
            };
            let inst = spec
                .instances
                .iter_mut()
                .find(|i| i.name == instance)
                .ok_or(missing)?;
            if parameter == "step" && inst.step.is_some() {
                return Err(OverrideError::Target {
                    target: target.clone(),
                    reason: format!(
                        "'step' of instance '{instance}' is its communication step in the system \
                         file, which --set does not change (it sets FMU variables)"
                    ),
                });
            }
            inst.parameters.insert(parameter.to_string(), value.clone());
        }
        Ok(())
    }
}

/// `instance.parameter` split at its first '.', both parts non-empty.
fn split_target(target: &str) -> Result<(&str, &str), OverrideError> {
    let bad = |reason: &str| OverrideError::Target {
        target: target.to_string(),
        reason: reason.to_string(),
    };
    let (instance, parameter) = target
        .split_once('.')
        .ok_or_else(|| bad("expected instance.parameter"))?;
    if instance.is_empty() {
        return Err(bad("no instance name before the '.'"));
    }
    if parameter.is_empty() {
        return Err(bad("no parameter name after the instance"));
    }
    Ok((instance, parameter))
}

/// A study file's `method` is a whole method.
fn whole_method<'de, D: Deserializer<'de>>(d: D) -> Result<MethodChange, D::Error> {
    Ok(Option::<Method>::deserialize(d)?
        .map(MethodChange::from)
        .unwrap_or_default())
}

impl MethodChange {
    /// `over` on top of `self`: if both name a kind and the kinds differ,
    /// `over` replaces `self`; otherwise each parameter `over` gives wins.
    pub fn merged(&self, over: &MethodChange) -> MethodChange {
        if matches!((self.kind, over.kind), (Some(k), Some(o)) if k != o) {
            return *over;
        }
        MethodChange {
            kind: over.kind.or(self.kind),
            index: over.index.or(self.index),
            beta: over.beta.or(self.beta),
            gamma: over.gamma.or(self.gamma),
            a: over.a.or(self.a),
            b: over.b.or(self.b),
            mu: over.mu.or(self.mu),
        }
    }

    /// The method that results from changing `current`.
    pub fn apply(&self, current: Method) -> Result<Method, OverrideError> {
        let kind = self.kind.unwrap_or(MethodKind::of(&current));
        if let Some(index) = self.index {
            let indexed = match kind {
                MethodKind::Baumgarte => IndexedKind::Baumgarte,
                MethodKind::Weighted => IndexedKind::Weighted,
                MethodKind::Explicit => {
                    return Err(OverrideError::Misplaced {
                        parameter: "index",
                        method: "baumgarte or weighted",
                        current: kind.name(),
                    })
                }
            };
            let (own, given) = match (current, indexed) {
                (Method::Baumgarte { beta, gamma }, IndexedKind::Baumgarte) => {
                    ([beta, gamma], [self.beta, self.gamma])
                }
                (Method::Weighted { a, b }, IndexedKind::Weighted) => ([a, b], [self.a, self.b]),
                (_, IndexedKind::Baumgarte) => ([0.0; 2], [self.beta, self.gamma]),
                (_, IndexedKind::Weighted) => ([0.0; 2], [self.a, self.b]),
            };
            // The method's own weights where the index uses them.
            let kept = [own[0] > 0.0 && index <= 2, own[1] > 0.0 && index <= 1];
            let weights = [0, 1].map(|l| given[l].or(kept[l].then_some(own[l])));
            let method =
                Method::at_index(indexed, Some(index), weights).map_err(OverrideError::Index)?;
            self.check_placement(kind)?;
            return Ok(method);
        }
        let method = match kind {
            MethodKind::Baumgarte => {
                let (beta, gamma) = match current {
                    Method::Baumgarte { beta, gamma } => (beta, gamma),
                    _ => (0.0, 0.0),
                };
                Method::Baumgarte {
                    beta: self.beta.unwrap_or(beta),
                    gamma: self.gamma.unwrap_or(gamma),
                }
            }
            MethodKind::Weighted => {
                let (a, b) = match current {
                    Method::Weighted { a, b } => (a, b),
                    _ => (0.0, 0.0),
                };
                Method::Weighted {
                    a: self.a.unwrap_or(a),
                    b: self.b.unwrap_or(b),
                }
            }
            MethodKind::Explicit => {
                let mu = match current {
                    Method::Explicit { mu } => Some(mu),
                    _ => None,
                };
                Method::Explicit {
                    mu: self.mu.or(mu).ok_or(OverrideError::MissingMu)?,
                }
            }
        };
        self.check_placement(kind)?;
        Ok(method)
    }

    /// A parameter of another kind than `kind` is an error.
    fn check_placement(&self, kind: MethodKind) -> Result<(), OverrideError> {
        let given = [
            ("beta", self.beta, MethodKind::Baumgarte),
            ("gamma", self.gamma, MethodKind::Baumgarte),
            ("a", self.a, MethodKind::Weighted),
            ("b", self.b, MethodKind::Weighted),
            ("mu", self.mu, MethodKind::Explicit),
        ];
        for (parameter, value, owner) in given {
            if value.is_some() && owner != kind {
                return Err(OverrideError::Misplaced {
                    parameter,
                    method: owner.name(),
                    current: kind.name(),
                });
            }
        }
        Ok(())
    }
}

impl From<Method> for MethodChange {
    fn from(method: Method) -> MethodChange {
        let kind = Some(MethodKind::of(&method));
        match method {
            Method::Baumgarte { beta, gamma } => MethodChange {
                kind,
                beta: Some(beta),
                gamma: Some(gamma),
                ..MethodChange::default()
            },
            Method::Weighted { a, b } => MethodChange {
                kind,
                a: Some(a),
                b: Some(b),
                ..MethodChange::default()
            },
            Method::Explicit { mu } => MethodChange {
                kind,
                mu: Some(mu),
                ..MethodChange::default()
            },
        }
    }
}

impl MethodKind {
    /// The kind of a method.
    pub fn of(method: &Method) -> MethodKind {
        match method {
            Method::Baumgarte { .. } => MethodKind::Baumgarte,
            Method::Weighted { .. } => MethodKind::Weighted,
            Method::Explicit { .. } => MethodKind::Explicit,
        }
    }

    /// The name in system files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MethodKind::Baumgarte => "baumgarte",
            MethodKind::Weighted => "weighted",
            MethodKind::Explicit => "explicit",
        }
    }
}

impl std::str::FromStr for MethodKind {
    type Err = OverrideError;
    fn from_str(s: &str) -> Result<MethodKind, OverrideError> {
        match s {
            "baumgarte" => Ok(MethodKind::Baumgarte),
            "weighted" => Ok(MethodKind::Weighted),
            "explicit" => Ok(MethodKind::Explicit),
            _ => Err(OverrideError::UnknownMethod(s.to_string())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SYSTEM: &str = r#"
        [experiment]
        stop = 1.0
        step = 1e-3
        [method]
        kind = "weighted"
        a = 0.5
        b = 2.0
        [[instance]]
        name = "mass1"
        fmu = "osc.fmu"
        parameters = { c = 1000.0 }
        [[instance]]
        name = "mass2"
        fmu = "osc.fmu"
        [[constraint]]
        name = "link"
        position = "mass2.x - mass1.x"
        drives = "mass1.F - mass2.F"
    "#;

    fn system() -> SystemSpec {
        SystemSpec::from_toml(SYSTEM).unwrap()
    }

    fn change(kind: Option<MethodKind>) -> MethodChange {
        MethodChange {
            kind,
            ..MethodChange::default()
        }
    }

    #[test]
    fn settings_parse_into_typed_start_values() {
        let mut o = Overrides::default();
        for s in [
            "mass1.c=5",
            "mass1.d = 2.5",
            "mass2.exact=true",
            "mass2.name=left",
            "mass1.c=7",
        ] {
            o.set(s).unwrap();
        }
        assert_eq!(o.parameters["mass1.c"], StartValue::Integer(7), "last wins");
        assert_eq!(o.parameters["mass1.d"], StartValue::Real(2.5));
        assert_eq!(o.parameters["mass2.exact"], StartValue::Boolean(true));
        assert_eq!(
            o.parameters["mass2.name"],
            StartValue::String("left".into())
        );
    }

    #[test]
    fn malformed_settings_are_refused_with_the_setting_named() {
        let mut o = Overrides::default();
        for (s, needle) in [
            (
                "mass1c",
                "setting 'mass1c': expected INSTANCE.PARAMETER=VALUE",
            ),
            ("mass1.c=", "setting 'mass1.c=': no value after '='"),
            ("mass1=5", "target 'mass1': expected instance.parameter"),
            ("mass1.=5", "target 'mass1.': no parameter name"),
            (".c=5", "target '.c': no instance name"),
        ] {
            let e = o.set(s).unwrap_err().to_string();
            assert!(e.contains(needle), "{s}: {e}");
        }
        assert!(o.parameters.is_empty());
    }

    #[test]
    fn apply_changes_only_what_is_given() {
        let mut spec = system();
        let before = format!("{spec:?}");
        Overrides::default().apply(&mut spec).unwrap();
        assert_eq!(format!("{spec:?}"), before);

        let mut o = Overrides {
            order: Some(2),
            step: Some(5e-3),
            stop: Some(0.5),
            epsilon: Some(1e-6),
            divergence_factor: Some(1e3),
            parallel: Some(Parallel::Off),
            threads: Some(3),
            iterations: Some(3),
            iteration_tol: Some(1e-8),
            step_atol: Some(1e-7),
            jacobian: Some(JacobianMode::Reuse),
            ..Overrides::default()
        };
        o.set("mass1.c=2e3").unwrap();
        o.set("mass2.m=3").unwrap();
        o.apply(&mut spec).unwrap();
        assert_eq!((spec.experiment.step, spec.experiment.stop), (5e-3, 0.5));
        assert_eq!(spec.coupling.order, 2);
        assert_eq!(spec.coupling.epsilon, 1e-6);
        assert_eq!(spec.coupling.divergence_factor, 1e3);
        assert_eq!(spec.coupling.parallel, Parallel::Off);
        assert_eq!(spec.coupling.threads, Some(3));
        assert_eq!(spec.coupling.iterations, 3);
        assert_eq!(spec.coupling.iteration_tol, 1e-8);
        assert_eq!(spec.coupling.jacobian, JacobianMode::Reuse);
        let control = spec.step_control.unwrap();
        assert_eq!((control.rtol, control.atol), (1e-4, 1e-7));
        assert_eq!(spec.method, Method::Weighted { a: 0.5, b: 2.0 });
        assert_eq!(spec.instances[0].parameters["c"], StartValue::Real(2e3));
        assert_eq!(spec.instances[1].parameters["m"], StartValue::Integer(3));
    }

    #[test]
    fn an_unknown_instance_names_the_instances_there_are() {
        let mut o = Overrides::default();
        o.set("mass3.c=1").unwrap();
        let e = o.apply(&mut system()).unwrap_err().to_string();
        assert_eq!(
            e,
            "target 'mass3.c': no instance 'mass3' in the system; instances are mass1, mass2"
        );
        // Targets written into the table directly are checked as well.
        let mut o = Overrides::default();
        o.parameters.insert("mass1".into(), StartValue::Real(1.0));
        assert!(matches!(
            o.apply(&mut system()),
            Err(OverrideError::Target { .. })
        ));
    }

    #[test]
    fn a_method_change_keeps_the_parameters_of_the_same_kind() {
        let weighted = Method::Weighted { a: 0.5, b: 2.0 };
        let only_b = MethodChange {
            b: Some(1.0),
            ..MethodChange::default()
        };
        assert_eq!(
            only_b.apply(weighted),
            Ok(Method::Weighted { a: 0.5, b: 1.0 })
        );
        let same = change(Some(MethodKind::Weighted));
        assert_eq!(same.apply(weighted), Ok(weighted));
        let other = MethodChange {
            beta: Some(0.1),
            ..change(Some(MethodKind::Baumgarte))
        };
        assert_eq!(
            other.apply(weighted),
            Ok(Method::Baumgarte {
                beta: 0.1,
                gamma: 0.0
            })
        );
        let whole = MethodChange::from(Method::Explicit { mu: 1e-2 });
        assert_eq!(whole.apply(weighted), Ok(Method::Explicit { mu: 1e-2 }));
        let explicit = Method::Explicit { mu: 3.0 };
        assert_eq!(MethodChange::default().apply(explicit), Ok(explicit));
    }

    #[test]
    fn an_index_change_keeps_the_weights_it_uses_and_defaults_the_others() {
        let index = |i, kind| MethodChange {
            index: Some(i),
            ..change(kind)
        };
        let weighted = Method::Weighted { a: 0.5, b: 2.0 };
        let w = |a, b| Ok(Method::Weighted { a, b });
        assert_eq!(index(2, None).apply(weighted), w(0.5, 0.0));
        assert_eq!(index(3, None).apply(weighted), w(0.0, 0.0));
        assert_eq!(
            index(1, None).apply(Method::Weighted { a: 0.5, b: 0.0 }),
            w(0.5, 1.0)
        );
        assert_eq!(
            index(1, Some(MethodKind::Baumgarte)).apply(weighted),
            Ok(Method::Baumgarte {
                beta: 2e-3,
                gamma: 1e-6
            })
        );
        let contradiction = MethodChange {
            a: Some(0.0),
            ..index(2, None)
        };
        assert_eq!(
            contradiction.apply(weighted).unwrap_err().to_string(),
            "index = 2 contradicts a = 0: index 2 means a > 0 and b = 0"
        );
    }

    #[test]
    fn a_method_change_that_does_not_fit_is_an_error() {
        let weighted = Method::Weighted { a: 0.5, b: 2.0 };
        let beta = MethodChange {
            beta: Some(0.1),
            ..MethodChange::default()
        };
        let e = beta.apply(weighted).unwrap_err();
        assert_eq!(
            e.to_string(),
            "beta applies to method baumgarte, but the method is weighted"
        );
        assert_eq!(
            change(Some(MethodKind::Explicit)).apply(weighted),
            Err(OverrideError::MissingMu)
        );
        let mu = MethodChange {
            mu: Some(1.0),
            ..change(Some(MethodKind::Weighted))
        };
        assert!(matches!(
            mu.apply(weighted),
            Err(OverrideError::Misplaced {
                parameter: "mu",
                ..
            })
        ));
        assert_eq!("weighted".parse::<MethodKind>(), Ok(MethodKind::Weighted));
        let e = "newton".parse::<MethodKind>().unwrap_err().to_string();
        assert!(e.contains("'newton'") && e.contains("baumgarte"), "{e}");
    }

    #[test]
    fn later_overrides_win_and_parameters_merge() {
        let base: Overrides = toml::from_str(
            "order = 1\nstep = 1e-2\nparallel = 'on'\nparameters = { 'mass1.c' = 5.0, 'mass2.d' = 1 }",
        )
        .unwrap();
        let over: Overrides = toml::from_str(
            "step = 1e-3\nmethod = { kind = 'weighted', a = 1.0 }\nparameters = { 'mass2.d' = 2 }",
        )
        .unwrap();
        let m = base.merged(&over);
        assert_eq!((m.order, m.step), (Some(1), Some(1e-3)));
        assert_eq!(m.parallel, Some(Parallel::On));
        // A study file's method is whole: b, not given, is 0.
        assert_eq!(m.method, Method::Weighted { a: 1.0, b: 0.0 }.into());
        let mut spec = system();
        m.apply(&mut spec).unwrap();
        assert_eq!(spec.method, Method::Weighted { a: 1.0, b: 0.0 });
        assert_eq!(spec.experiment.step, 1e-3);
        assert_eq!(spec.instances[0].parameters["c"], StartValue::Real(5.0));
        assert_eq!(spec.instances[1].parameters["d"], StartValue::Integer(2));
        // Merging with nothing changes nothing, either way round.
        assert_eq!(m.merged(&Overrides::default()), m);
        assert_eq!(Overrides::default().merged(&m), m);
    }

    #[test]
    fn a_later_method_of_another_kind_replaces_the_earlier_one() {
        let baumgarte: MethodChange = Method::Baumgarte {
            beta: 0.1,
            gamma: 0.2,
        }
        .into();
        let weighted: MethodChange = Method::Weighted { a: 1.0, b: 0.0 }.into();
        assert_eq!(baumgarte.merged(&weighted), weighted);
        // The same kind, or no kind: single parameters go on top.
        let gamma = MethodChange {
            gamma: Some(0.5),
            ..MethodChange::default()
        };
        let m = baumgarte.merged(&gamma);
        assert_eq!(
            m.apply(Method::default()),
            Ok(Method::Baumgarte {
                beta: 0.1,
                gamma: 0.5
            })
        );
        // Merged, then applied, is the same as applying one after the other.
        let kind = change(Some(MethodKind::Baumgarte));
        let spec = Method::Baumgarte {
            beta: 3.0,
            gamma: 4.0,
        };
        let one_by_one = kind.apply(gamma.apply(spec).unwrap()).unwrap();
        assert_eq!(gamma.merged(&kind).apply(spec), Ok(one_by_one));
    }

    #[test]
    fn a_study_table_with_an_unknown_key_is_refused() {
        let e = toml::from_str::<Overrides>("stpe = 1e-3")
            .unwrap_err()
            .to_string();
        assert!(e.contains("stpe"), "{e}");
        assert!(toml::from_str::<Overrides>("method = { kind = 'explicit' }").is_err());
    }
}
