//! Constraints resolved against the FMUs: which outputs form g, ġ, g̈ and
//! which inputs each multiplier drives.

use tether_fmi::{BaseType, Causality, ScalarVariable};

use crate::expr::{LinearExpr, Term};
use crate::slave::{CoupledOutput, Slave};
use crate::spec::{ConstraintSpec, InitialMultiplier};
use crate::{MasterError, Method};

/// One level (position, velocity or acceleration) of a constraint:
/// `Σ coefficient · slave.coupled_values[slot]`.
#[derive(Debug, Clone, Default)]
pub(crate) struct Level {
    pub terms: Vec<(usize, usize, f64)>,
}

impl Level {
    /// Evaluate with the latest values of the slaves in `live` and the saved
    /// `base` values of all the others.
    pub fn eval(&self, slaves: &[Slave], base: &[Vec<f64>], live: &[bool]) -> f64 {
        self.terms
            .iter()
            .map(|&(s, slot, c)| {
                let v = if live[s] {
                    slaves[s].coupled_values[slot]
                } else {
                    base[s][slot]
                };
                c * v
            })
            .sum()
    }

    /// Evaluate with the latest values of every slave.
    pub fn eval_live(&self, slaves: &[Slave]) -> f64 {
        self.terms
            .iter()
            .map(|&(s, slot, c)| c * slaves[s].coupled_values[slot])
            .sum()
    }
}

/// A constraint with its multiplier (unknown number = constraint number).
#[derive(Debug, Clone)]
pub(crate) struct Constraint {
    pub name: String,
    pub position: Level,
    pub velocity: Option<Level>,
    pub acceleration: Option<Level>,
    pub initial: InitialMultiplier,
}

/// The three condition levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum LevelKind {
    Position,
    Velocity,
    Acceleration,
}

impl Constraint {
    pub fn level(&self, kind: LevelKind) -> &Level {
        match kind {
            LevelKind::Position => &self.position,
            LevelKind::Velocity => self.velocity.as_ref().expect("checked at build time"),
            LevelKind::Acceleration => self.acceleration.as_ref().expect("checked at build time"),
        }
    }
}

/// Resolve every constraint of the system file against the instantiated slaves.
pub(crate) fn resolve(
    specs: &[ConstraintSpec],
    slaves: &mut [Slave],
    method: &Method,
    order: usize,
) -> Result<Vec<Constraint>, MasterError> {
    let mut constraints = Vec::with_capacity(specs.len());
    for (m, spec) in specs.iter().enumerate() {
        let parse = |level: &'static str, text: &str| {
            LinearExpr::parse(text).map_err(|source| MasterError::Expression {
                constraint: spec.name.clone(),
                level,
                source,
            })
        };
        let position = output_level(
            spec,
            "position",
            &parse("position", &spec.position)?,
            slaves,
        )?;
        let mut optional =
            |level: &'static str, text: &Option<String>| -> Result<Option<Level>, MasterError> {
                match text {
                    Some(t) => Ok(Some(output_level(spec, level, &parse(level, t)?, slaves)?)),
                    None => Ok(None),
                }
            };
        let velocity = optional("velocity", &spec.velocity)?;
        let acceleration = optional("acceleration", &spec.acceleration)?;
        let needed = |level: &'static str, present: bool, needed_by: String| {
            if present {
                Ok(())
            } else {
                Err(MasterError::MissingLevel {
                    constraint: spec.name.clone(),
                    level,
                    needed_by,
                })
            }
        };
        if method.needs_velocity() {
            needed("velocity", velocity.is_some(), format!("method {method}"))?;
        }
        if method.needs_acceleration() {
            needed(
                "acceleration",
                acceleration.is_some(),
                format!("method {method}"),
            )?;
        }
        if spec.initial == InitialMultiplier::Consistent {
            needed(
                "acceleration",
                acceleration.is_some(),
                "a consistent initial multiplier (or give `initial = <value>`)".into(),
            )?;
        }
        for term in &parse("drives", &spec.drives)?.terms {
            let s = find_slave(spec, term, slaves)?;
            let var = slaves[s]
                .fmu
                .model_description()
                .variable(&term.variable)?
                .clone();
            let is_real = var.base_type() == BaseType::Real;
            if var.causality != Causality::Input || !is_real || term.derivative_order != 0 {
                return Err(MasterError::WrongVariable {
                    instance: term.instance.clone(),
                    variable: term.variable.clone(),
                    found: describe(&var),
                    role: format!("'drives' of constraint '{}'", spec.name),
                    expected: "a Real input".into(),
                });
            }
            slaves[s].add_input(var.value_reference, m, term.coefficient);
        }
        constraints.push(Constraint {
            name: spec.name.clone(),
            position,
            velocity,
            acceleration,
            initial: spec.initial,
        });
    }
    for slave in slaves.iter() {
        if !slave.is_coupled() {
            continue;
        }
        let capability =
            |capability: &'static str, needed_by: String| MasterError::MissingCapability {
                instance: slave.name.clone(),
                model: slave.model_name.clone(),
                capability,
                needed_by,
            };
        if order > 0 && !slave.can_interpolate_inputs {
            return Err(capability(
                "canInterpolateInputs",
                format!("coupling polynomials of degree k = {order} (use order = 0)"),
            ));
        }
        if method.needs_rollback() && !slave.can_get_and_set_state {
            return Err(capability(
                "canGetAndSetFMUstate",
                format!(
                    "the predictor/corrector method {} (repeating macro steps)",
                    method.name()
                ),
            ));
        }
    }
    for slave in slaves.iter_mut() {
        slave.finalize();
    }
    Ok(constraints)
}

fn output_level(
    spec: &ConstraintSpec,
    level: &'static str,
    expr: &LinearExpr,
    slaves: &mut [Slave],
) -> Result<Level, MasterError> {
    let mut out = Level::default();
    for term in &expr.terms {
        let s = find_slave(spec, term, slaves)?;
        let slave = &mut slaves[s];
        let var = slave
            .fmu
            .model_description()
            .variable(&term.variable)?
            .clone();
        let is_real = var.base_type() == BaseType::Real;
        if var.causality != Causality::Output || !is_real {
            return Err(MasterError::WrongVariable {
                instance: term.instance.clone(),
                variable: term.variable.clone(),
                found: describe(&var),
                role: format!("the {level} level of constraint '{}'", spec.name),
                expected: "a Real output".into(),
            });
        }
        if term.derivative_order > slave.max_output_derivative_order {
            return Err(MasterError::MissingCapability {
                instance: slave.name.clone(),
                model: slave.model_name.clone(),
                capability: "a large enough maxOutputDerivativeOrder",
                needed_by: format!("{term} in constraint '{}'", spec.name),
            });
        }
        let slot = slave.add_output(CoupledOutput {
            vr: var.value_reference,
            order: term.derivative_order,
        });
        out.terms.push((s, slot, term.coefficient));
    }
    Ok(out)
}

fn find_slave(spec: &ConstraintSpec, term: &Term, slaves: &[Slave]) -> Result<usize, MasterError> {
    slaves
        .iter()
        .position(|s| s.name == term.instance)
        .ok_or_else(|| {
            let close: Vec<&str> = slaves
                .iter()
                .map(|s| s.name.as_str())
                .filter(|n| similar(n, &term.instance))
                .collect();
            let hint = if close.is_empty() {
                let all: Vec<&str> = slaves.iter().map(|s| s.name.as_str()).collect();
                format!("; instances are: {}", all.join(", "))
            } else {
                format!("; did you mean '{}'?", close.join("', '"))
            };
            MasterError::UnknownInstance {
                constraint: spec.name.clone(),
                instance: term.instance.clone(),
                hint,
            }
        })
}

/// "a Real output", "an Integer parameter", … for error messages.
pub(crate) fn describe(var: &ScalarVariable) -> String {
    let ty = match var.base_type() {
        BaseType::Real => "Real",
        BaseType::Integer => "Integer",
        BaseType::Boolean => "Boolean",
        BaseType::String => "String",
        BaseType::Enumeration => "Enumeration",
    };
    let causality = match var.causality {
        Causality::Parameter => "parameter",
        Causality::CalculatedParameter => "calculated parameter",
        Causality::Input => "input",
        Causality::Output => "output",
        Causality::Local => "local variable",
        Causality::Independent => "independent variable",
    };
    let article = if matches!(var.base_type(), BaseType::Integer | BaseType::Enumeration) {
        "an"
    } else {
        "a"
    };
    format!("{article} {ty} {causality}")
}

/// Names within edit distance 2 or sharing a prefix of 3 characters.
fn similar(a: &str, b: &str) -> bool {
    let prefix = a.chars().zip(b.chars()).take_while(|(x, y)| x == y).count();
    prefix >= 3 || edit_distance(a, b) <= 2
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, &cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

/// Group unknowns so that no two in a group drive the same instance: one
/// perturbed run per group serves every unknown in it (greedy colouring).
pub(crate) fn perturbation_groups(owners: &[Vec<usize>]) -> Vec<Vec<usize>> {
    let mut groups: Vec<(Vec<usize>, Vec<usize>)> = Vec::new();
    for (m, own) in owners.iter().enumerate() {
        match groups
            .iter_mut()
            .find(|(_, used)| own.iter().all(|s| !used.contains(s)))
        {
            Some((members, used)) => {
                members.push(m);
                used.extend(own.iter().copied());
            }
            None => groups.push((vec![m], own.clone())),
        }
    }
    groups.into_iter().map(|(members, _)| members).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknowns_on_different_instances_share_a_perturbed_run() {
        // λ0 drives A and B, λ1 drives only A, λ2 only C, λ3 only B.
        let owners = vec![vec![0, 1], vec![0], vec![2], vec![1]];
        let groups = perturbation_groups(&owners);
        assert_eq!(groups, vec![vec![0, 2], vec![1, 3]]);
    }

    #[test]
    fn close_names_are_suggested() {
        assert!(similar("mass1", "mas1"));
        assert!(similar("pendulum", "pendulum_b"));
        assert!(!similar("mass1", "crank"));
        assert_eq!(edit_distance("kitten", "sitting"), 3);
    }
}
