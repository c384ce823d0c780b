//! Changes to a system file: method, polynomial degree, time grid and FMU
//! parameters, applied to a [`SystemSpec`] before a run.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use tether_master::{Method, StartValue, SystemSpec};

use crate::StudyError;

/// Settings that replace those of the system file. `None` keeps the file's value.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Overrides {
    /// The coupling method with its parameters (`{ kind = "baumgarte", beta = 2e-3 }`).
    #[serde(default)]
    pub method: Option<Method>,
    /// Degree k of the coupling polynomials.
    #[serde(default)]
    pub order: Option<usize>,
    /// Macro-step size H.
    #[serde(default)]
    pub step: Option<f64>,
    /// Stop time.
    #[serde(default)]
    pub stop: Option<f64>,
    /// Finite-difference increment ε.
    #[serde(default)]
    pub epsilon: Option<f64>,
    /// The master's divergence bound (`coupling.divergence_factor`).
    #[serde(default)]
    pub divergence_factor: Option<f64>,
    /// FMU start values by target `instance.parameter`.
    #[serde(default)]
    pub parameters: BTreeMap<String, StartValue>,
}

impl Overrides {
    /// `self` with every setting that `over` gives replaced by `over`'s.
    pub fn merged(&self, over: &Overrides) -> Overrides {
        let mut parameters = self.parameters.clone();
        parameters.extend(over.parameters.iter().map(|(k, v)| (k.clone(), v.clone())));
        Overrides {
            method: over.method.or(self.method),
            order: over.order.or(self.order),
            step: over.step.or(self.step),
            stop: over.stop.or(self.stop),
            epsilon: over.epsilon.or(self.epsilon),
            divergence_factor: over.divergence_factor.or(self.divergence_factor),
            parameters,
        }
    }

    /// Apply to a system; an unknown instance in a parameter target is an error.
    pub fn apply(&self, spec: &mut SystemSpec) -> Result<(), StudyError> {
        if let Some(method) = self.method {
            spec.method = method;
        }
        if let Some(order) = self.order {
            spec.coupling.order = order;
        }
        if let Some(step) = self.step {
            spec.experiment.step = step;
        }
        if let Some(stop) = self.stop {
            spec.experiment.stop = stop;
        }
        if let Some(eps) = self.epsilon {
            spec.coupling.epsilon = eps;
        }
        if let Some(factor) = self.divergence_factor {
            spec.coupling.divergence_factor = factor;
        }
        for (target, value) in &self.parameters {
            set_parameter(spec, target, value.clone())?;
        }
        Ok(())
    }
}

/// Set the start value of `instance.parameter` in a system. Whether the FMU
/// has such a variable is checked when the run is built.
pub fn set_parameter(
    spec: &mut SystemSpec,
    target: &str,
    value: StartValue,
) -> Result<(), StudyError> {
    let bad = |reason: String| StudyError::Target {
        target: target.to_string(),
        reason,
    };
    let (instance, parameter) = target
        .split_once('.')
        .ok_or_else(|| bad("expected instance.parameter".into()))?;
    if parameter.is_empty() {
        return Err(bad("no parameter name after the instance".into()));
    }
    let names: Vec<String> = spec.instances.iter().map(|i| i.name.clone()).collect();
    let inst = spec
        .instances
        .iter_mut()
        .find(|i| i.name == instance)
        .ok_or_else(|| {
            bad(format!(
                "no instance '{instance}' in the system; instances are {}",
                names.join(", ")
            ))
        })?;
    inst.parameters.insert(parameter.to_string(), value);
    Ok(())
}

/// Set one axis target to a number: `step` (the macro-step size H), `stop`,
/// or an FMU parameter `instance.parameter`.
pub fn set_target(spec: &mut SystemSpec, target: &str, value: f64) -> Result<(), StudyError> {
    match target {
        "step" => spec.experiment.step = value,
        "stop" => spec.experiment.stop = value,
        _ => set_parameter(spec, target, StartValue::Real(value))?,
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SYSTEM: &str = r#"
        [experiment]
        stop = 1.0
        step = 1e-3
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

    #[test]
    fn later_overrides_win_and_parameters_merge() {
        let base: Overrides =
            toml::from_str("order = 1\nstep = 1e-2\nparameters = { 'mass1.c' = 5.0 }").unwrap();
        let over: Overrides = toml::from_str(
            "step = 1e-3\nmethod = { kind = 'weighted', a = 1.0 }\nparameters = { 'mass2.d' = 2 }",
        )
        .unwrap();
        let m = base.merged(&over);
        assert_eq!((m.order, m.step), (Some(1), Some(1e-3)));
        assert_eq!(m.method, Some(Method::Weighted { a: 1.0, b: 0.0 }));
        let mut spec = SystemSpec::from_toml(SYSTEM).unwrap();
        m.apply(&mut spec).unwrap();
        assert_eq!(spec.experiment.step, 1e-3);
        assert_eq!(spec.instances[0].parameters["c"], StartValue::Real(5.0));
        assert_eq!(spec.instances[1].parameters["d"], StartValue::Integer(2));
    }

    #[test]
    fn targets_name_an_existing_instance() {
        let mut spec = SystemSpec::from_toml(SYSTEM).unwrap();
        set_target(&mut spec, "step", 5e-3).unwrap();
        assert_eq!(spec.experiment.step, 5e-3);
        let e = set_target(&mut spec, "mass3.c", 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("mass3") && e.contains("mass1, mass2"), "{e}");
        assert!(set_target(&mut spec, "mass1", 1.0).is_err());
        assert!(set_target(&mut spec, "mass1.", 1.0).is_err());
    }
}
