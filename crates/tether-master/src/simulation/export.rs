//! The interface of the system exported as one FMU (`[export]`,
//! docs/fmu-export.md), resolved against the instances: what each exported
//! variable sets or reads, with the member FMU's unit and description.

use tether_fmi::{Causality, Variability};

use super::Simulation;
use crate::signals::feeds_through;
use crate::spec::names::{describe, find_instance, fmu_file, suggest, variable};
use crate::MasterError;

/// What an exported variable is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportKind {
    /// Set before initialization: an instance parameter's start value.
    Parameter,
    /// Set between steps: an instance input the coupling does not drive.
    Input,
    /// Read at the current point: a column of the system.
    Output,
}

/// One exported Real variable; its value reference is its index in
/// [`Simulation::export_interface`].
#[derive(Debug, Clone, PartialEq)]
pub struct ExportVariable {
    pub kind: ExportKind,
    /// The exported FMU's variable name.
    pub name: String,
    /// `instance.variable` it sets, or the column it reads.
    pub target: String,
    /// Index of the column among [`Simulation::columns`] (outputs).
    pub column: Option<usize>,
    /// The start value (the instance's, or as the system file sets it).
    pub start: Option<f64>,
    pub unit: Option<String>,
    pub description: Option<String>,
}

impl Simulation {
    /// The `[export]` variables of `spec` (parameters, inputs, outputs, in
    /// value-reference order), each checked against the instances: a name
    /// that does not resolve (with suggestions), an input the coupling or a
    /// signal connection drives, a non-Real variable, a parameter that is not
    /// one or an output that is not a column: one error each.
    pub fn export_interface(
        &self,
        spec: &crate::SystemSpec,
    ) -> Result<Vec<ExportVariable>, MasterError> {
        let Some(export) = &spec.export else {
            return Err(MasterError::SystemFile {
                path: spec.source_name(),
                reason: "no [export] table: it declares the exported FMU's model_name and variables (docs/fmu-export.md)".into(),
            });
        };
        let bad = |kind: &str, name: &str, reason: String| MasterError::SystemFile {
            path: spec.source_name(),
            reason: format!("[[export.{kind}]] '{name}': {reason}"),
        };
        let mut variables = Vec::new();
        for (kind, name, target) in export.variables() {
            let place = format!("[[export.{kind}]] '{name}'");
            if kind == "output" {
                let columns = self.columns();
                let Some(column) = columns.iter().position(|c| c == target) else {
                    let hint = suggest(target, columns.iter().map(String::as_str));
                    return Err(bad(
                        kind,
                        name,
                        format!("'{target}' is not a column of the system{hint}"),
                    ));
                };
                let (unit, description) = self.column_unit(target);
                variables.push(ExportVariable {
                    kind: ExportKind::Output,
                    name: name.to_string(),
                    target: target.to_string(),
                    column: Some(column),
                    start: None,
                    unit,
                    description,
                });
                continue;
            }
            let (instance, var) = target
                .split_once('.')
                .filter(|(i, v)| !i.is_empty() && !v.is_empty())
                .ok_or_else(|| bad(kind, name, format!("'{target}' is not INSTANCE.VARIABLE")))?;
            let names = self.system.slaves.iter().map(|s| s.name.as_str());
            let s = find_instance(&place, instance, names)?;
            let slave = &self.system.slaves[s];
            let md = slave.fmu.model_description();
            let v = variable(md, &place, instance, || fmu_file(slave.fmu.path()), var)?;
            let Some(real) = v.real() else {
                return Err(bad(
                    kind,
                    name,
                    format!(
                        "'{target}' is {}: only Real variables are exported",
                        describe(v)
                    ),
                ));
            };
            let export_kind = if kind == "input" {
                if v.causality != Causality::Input {
                    return Err(bad(
                        kind,
                        name,
                        format!("'{target}' is {}, not an input", describe(v)),
                    ));
                }
                let coupled = slave
                    .coupled
                    .inputs
                    .iter()
                    .any(|i| i.vr == v.value_reference);
                let signal = spec.connections.iter().any(|c| c.to == target);
                if coupled || signal {
                    let by = if coupled {
                        "the coupling"
                    } else {
                        "a [[connection]]"
                    };
                    return Err(bad(
                        kind,
                        name,
                        format!("'{target}' is driven by {by}; export an input nothing drives"),
                    ));
                }
                ExportKind::Input
            } else {
                let settable =
                    v.causality == Causality::Parameter && v.variability != Variability::Constant;
                if !settable {
                    return Err(bad(
                        kind,
                        name,
                        format!("'{target}' is {}, not a parameter", describe(v)),
                    ));
                }
                ExportKind::Parameter
            };
            let set = spec.instances[s]
                .parameters
                .get(var)
                .and_then(|value| match value {
                    crate::StartValue::Real(x) => Some(*x),
                    crate::StartValue::Integer(i) => Some(*i as f64),
                    _ => None,
                });
            variables.push(ExportVariable {
                kind: export_kind,
                name: name.to_string(),
                target: target.to_string(),
                column: None,
                start: set.or(real.start).or(Some(0.0)),
                unit: real.attributes.unit.clone(),
                description: v.description.clone(),
            });
        }
        Ok(variables)
    }

    /// Per exported variable (value-reference order), the exported inputs an
    /// output depends on directly (indices into `variables`; empty for the
    /// parameters and inputs): an input set now changes the output at the
    /// current point, before any step. Derived from the member FMUs'
    /// ModelStructure (an output listed without dependencies, or not listed,
    /// depends on every input), the signal connections and the coupling,
    /// conservatively: once an input reaches an output the coupling reads,
    /// every coupling unknown (multiplier, coupling variable, force port)
    /// and every coupled input depend on it, and so does every column of
    /// the coupling (`.lambda`, residuals).
    pub fn export_dependencies(&self, variables: &[ExportVariable]) -> Vec<Vec<usize>> {
        let reached: Vec<Option<Reached>> = variables
            .iter()
            .map(|v| (v.kind == ExportKind::Input).then(|| self.reached_from(&v.target)))
            .collect();
        variables
            .iter()
            .map(|v| {
                if v.kind != ExportKind::Output {
                    return Vec::new();
                }
                (0..variables.len())
                    .filter(|&i| {
                        reached[i]
                            .as_ref()
                            .is_some_and(|r| self.column_reached(r, &v.target))
                    })
                    .collect()
            })
            .collect()
    }

    /// What an input `instance.variable` changes directly: per instance, the
    /// inputs and outputs reached, and whether the coupling is.
    fn reached_from(&self, target: &str) -> Reached {
        let slaves = &self.system.slaves;
        let mut r = Reached {
            inputs: vec![Vec::new(); slaves.len()],
            outputs: vec![Vec::new(); slaves.len()],
            coupling: false,
        };
        let (instance, var) = target.split_once('.').unwrap_or_default();
        let Some(s) = slaves.iter().position(|s| s.name == instance) else {
            return r;
        };
        let Ok(v) = slaves[s].fmu.model_description().variable(var) else {
            return r;
        };
        r.inputs[s].push(v.value_reference);
        let links: Vec<_> = self.signals.links().collect();
        loop {
            let mut changed = false;
            for (s, slave) in slaves.iter().enumerate() {
                let md = slave.fmu.model_description();
                let outputs = md
                    .model_variables
                    .iter()
                    .filter(|v| v.causality == tether_fmi::Causality::Output);
                for o in outputs.map(|v| v.value_reference) {
                    if r.outputs[s].contains(&o)
                        || !r.inputs[s].iter().any(|&i| feeds_through(slave, i, o))
                    {
                        continue;
                    }
                    r.outputs[s].push(o);
                    changed = true;
                    if slave.coupled.outputs.iter().any(|c| c.vr == o) {
                        r.coupling = true;
                    }
                    for &(_, _, to, to_vr) in links.iter().filter(|l| (l.0, l.1) == (s, o)) {
                        if !r.inputs[to].contains(&to_vr) {
                            r.inputs[to].push(to_vr);
                        }
                    }
                }
                if r.coupling {
                    for c in &slave.coupled.inputs {
                        if !r.inputs[s].contains(&c.vr) {
                            r.inputs[s].push(c.vr);
                            changed = true;
                        }
                    }
                }
            }
            if !changed {
                return r;
            }
        }
    }

    /// Whether column `column` is among what `r` reached.
    fn column_reached(&self, r: &Reached, column: &str) -> bool {
        let slaves = &self.system.slaves;
        let owner = slaves
            .iter()
            .position(|s| s.recorded_names().iter().any(|n| n == column));
        match owner {
            Some(s) => {
                let var = &column[slaves[s].name.len() + 1..];
                let md = slaves[s].fmu.model_description();
                md.variable(var)
                    .is_ok_and(|v| r.outputs[s].contains(&v.value_reference))
            }
            // A column of the coupling: a multiplier, a coupling variable, a
            // residual.
            None => r.coupling,
        }
    }

    /// The unit and description of an instance output column.
    fn column_unit(&self, column: &str) -> (Option<String>, Option<String>) {
        let Some((instance, var)) = column.split_once('.') else {
            return (None, None);
        };
        let slave = self.system.slaves.iter().find(|s| s.name == instance);
        let v = slave.and_then(|s| s.fmu.model_description().variable(var).ok());
        match v {
            Some(v) => (
                v.real().and_then(|r| r.attributes.unit.clone()),
                v.description.clone(),
            ),
            None => (None, None),
        }
    }

    /// Whether every instance can save and restore its FMU state
    /// (`canGetAndSetFMUstate` and `canSerializeFMUstate`), which
    /// [`Simulation::save_state`] needs.
    pub fn can_save_state(&self) -> bool {
        self.system.slaves.iter().all(|s| s.caps.serialization)
    }
}

/// What an exported input changes directly ([`Simulation::export_dependencies`]).
struct Reached {
    /// Per instance, the inputs (value references) it changes.
    inputs: Vec<Vec<u32>>,
    /// Per instance, the outputs that change with them.
    outputs: Vec<Vec<u32>>,
    /// Whether an output the coupling reads changes: then every unknown does.
    coupling: bool,
}
