//! Name resolution against the FMUs: the system file's constraints, joints
//! and coupling variables become rows over the instances' coupled outputs and
//! unknowns driving their inputs, with errors that name what does not fit.

use nalgebra::Vector3;
use tether_fmi::{BaseType, Causality};

use crate::coupling::joints::{self, Condition, Frames, Joint, Side, MARKER_OUTPUTS};
use crate::coupling::rows::Level;
use crate::coupling::{Constraint, Coupling, Port, Row, Unknown, Variable};
use crate::expr::LinearExpr;
use crate::slave::{CoupledOutput, Slave};
use crate::spec::names::{describe, find_instance, Element};
use crate::spec::{ConstraintSpec, InitialMultiplier, JointInitial, JointSpec, SystemSpec};
use crate::units::{self, Dimension};
use crate::{MasterError, Method};

/// A port found while resolving joints: slave, input value reference, column
/// name and contributions, before it gets its unknown.
type PortDraft = (usize, u32, String, Vec<(usize, usize, usize)>);

impl Coupling {
    /// Resolve every constraint, joint and coupling variable of the system
    /// file against the instantiated slaves.
    pub fn build(
        spec: &SystemSpec,
        slaves: &mut [Slave],
        method: &Method,
        order: usize,
    ) -> Result<Coupling, MasterError> {
        let mut coupling = Coupling::default();
        for con in &spec.constraints {
            coupling.add_constraint(con, slaves, method)?;
        }
        let mut port_specs: Vec<PortDraft> = Vec::new();
        for joint in &spec.joints {
            coupling.add_joint(joint, slaves, &mut port_specs)?;
        }
        for var in &spec.coupling_variables {
            let m = coupling.unknowns.len();
            let owner = format!("coupling variable '{}'", var.name);
            let parse = |level: &'static str, text: &str| {
                LinearExpr::parse(text).map_err(|source| MasterError::Expression {
                    constraint: var.name.clone(),
                    level,
                    source,
                })
            };
            let value = output_level(&owner, "value", &parse("value", &var.value)?, slaves)?;
            drive_inputs(&owner, &parse("drives", &var.drives)?, m, slaves)?;
            coupling.variables.push(Variable { unknown: m, value });
            coupling.unknowns.push(Unknown {
                name: format!("{}.value", var.name),
                residual: None,
                initial: var.initial,
                row: Row::Variable(coupling.variables.len() - 1),
            });
        }
        for (slave, vr, name, contributions) in port_specs {
            let m = coupling.unknowns.len();
            slaves[slave].add_input(vr, None, m, 1.0);
            for &(j, c, component) in &contributions {
                coupling.joints[j].targets.push((c, component, m));
            }
            coupling.ports.push(Port { unknown: m });
            coupling.unknowns.push(Unknown {
                name,
                residual: None,
                initial: InitialMultiplier::Consistent,
                row: Row::Port(coupling.ports.len() - 1),
            });
        }
        for joint in &mut coupling.joints {
            // Stable: each port keeps its contributions in condition order.
            joint.targets.sort_by_key(|t| t.0);
        }
        check_driven_starts(spec, slaves)?;
        check_capabilities(slaves, method, order)?;
        for slave in slaves.iter_mut() {
            slave.finalize(order);
        }
        Ok(coupling)
    }

    fn add_constraint(
        &mut self,
        spec: &ConstraintSpec,
        slaves: &mut [Slave],
        method: &Method,
    ) -> Result<(), MasterError> {
        let m = self.unknowns.len();
        let owner = format!("constraint '{}'", spec.name);
        let parse = |level: &'static str, text: &str| {
            LinearExpr::parse(text).map_err(|source| MasterError::Expression {
                constraint: spec.name.clone(),
                level,
                source,
            })
        };
        let position = output_level(
            &owner,
            "position",
            &parse("position", &spec.position)?,
            slaves,
        )?;
        let mut optional =
            |level: &'static str, text: &Option<String>| -> Result<Option<Level>, MasterError> {
                match text {
                    Some(t) => Ok(Some(output_level(
                        &owner,
                        level,
                        &parse(level, t)?,
                        slaves,
                    )?)),
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
        let drives = parse("drives", &spec.drives)?;
        drive_inputs(&owner, &drives, m, slaves)?;
        let mut levels = vec![("position", parse("position", &spec.position)?)];
        for (level, text) in [
            ("velocity", &spec.velocity),
            ("acceleration", &spec.acceleration),
        ] {
            if let Some(text) = text {
                levels.push((level, parse(level, text)?));
            }
        }
        check_units(&spec.name, &levels, &drives, slaves)?;
        self.constraints.push(Constraint {
            position,
            velocity,
            acceleration,
        });
        self.unknowns.push(Unknown {
            name: format!("{}.lambda", spec.name),
            residual: Some(format!("{}.g", spec.name)),
            initial: spec.initial,
            row: Row::Constraint(self.constraints.len() - 1),
        });
        Ok(())
    }

    fn add_joint(
        &mut self,
        spec: &JointSpec,
        slaves: &mut [Slave],
        ports: &mut Vec<PortDraft>,
    ) -> Result<(), MasterError> {
        let invalid = |reason: String| MasterError::Joint {
            joint: spec.name.clone(),
            reason,
        };
        let v =
            |x: Option<[f64; 3]>, default: Vector3<f64>| x.map(Vector3::from).unwrap_or(default);
        let frames = Frames::new(
            v(spec.axis_i, Vector3::z()),
            v(spec.ref_i, Vector3::x()),
            v(spec.axis_j, Vector3::z()),
            v(spec.ref_j, Vector3::x()),
        )
        .map_err(|e| invalid(e.into()))?;
        let mut conditions = joints::conditions(&spec.kind, &frames).ok_or_else(|| {
            invalid(format!(
                "unknown kind '{}'; kinds are: {}",
                spec.kind,
                joints::KINDS.join(", ")
            ))
        })?;
        let planar = match spec.plane.as_deref() {
            None => false,
            Some("xy") => true,
            Some(other) => {
                return Err(invalid(format!(
                    "plane = \"{other}\" is not supported; use \"xy\" or leave it out"
                )))
            }
        };
        if planar {
            conditions.retain(Condition::acts_in_plane);
            if conditions.is_empty() {
                return Err(invalid(format!(
                    "a {} joint has no condition acting in the xy-plane",
                    spec.kind
                )));
            }
        }
        let offsets = [
            v(spec.offset_i, Vector3::zeros()),
            v(spec.offset_j, Vector3::zeros()),
        ];
        let owner = format!("joint '{}'", spec.name);
        let mut sides = Vec::with_capacity(2);
        for (text, offset) in [(&spec.i, offsets[0]), (&spec.j, offsets[1])] {
            let (instance, marker) = text.split_once('.').ok_or_else(|| {
                invalid(format!(
                    "marker '{text}' must be written <instance>.<marker>"
                ))
            })?;
            sides.push(resolve_marker(&owner, instance, marker, offset, slaves)?);
        }
        let joint_index = self.joints.len();
        let first = self.unknowns.len();
        if let JointInitial::Values(values) = &spec.initial {
            if values.len() != conditions.len() {
                return Err(invalid(format!(
                    "initial has {} values but the joint has {} conditions",
                    values.len(),
                    conditions.len()
                )));
            }
        }
        for k in 0..conditions.len() {
            let initial = match &spec.initial {
                JointInitial::Values(values) => InitialMultiplier::Value(values[k]),
                JointInitial::Consistent => InitialMultiplier::Consistent,
            };
            self.unknowns.push(Unknown {
                name: format!("{}.lambda[{}]", spec.name, k + 1),
                residual: Some(format!("{}.g[{}]", spec.name, k + 1)),
                initial,
                row: Row::Joint {
                    joint: joint_index,
                    condition: k,
                },
            });
        }
        match &spec.multipliers {
            Some(drives) => {
                // The paper's style: each multiplier drives FMU inputs.
                if drives.len() != conditions.len() {
                    return Err(invalid(format!(
                        "multipliers has {} expressions but the joint has {} conditions",
                        drives.len(),
                        conditions.len()
                    )));
                }
                for (k, text) in drives.iter().enumerate() {
                    let expr =
                        LinearExpr::parse(text).map_err(|source| MasterError::Expression {
                            constraint: spec.name.clone(),
                            level: "multipliers",
                            source,
                        })?;
                    drive_inputs(&owner, &expr, first + k, slaves)?;
                }
            }
            None => {
                // Force ports: every port component some condition can load.
                for (side_index, side) in sides.iter().enumerate() {
                    for (part, quantity) in [(0, "F"), (1, "T")] {
                        for axis in 0..3 {
                            if planar && (axis == 2) == (part == 0) {
                                continue; // in the plane: F x/y and T z only
                            }
                            let component = side_index * 6 + part * 3 + axis;
                            let loading: Vec<usize> = conditions
                                .iter()
                                .enumerate()
                                .filter(|(_, c)| {
                                    c.active_components(&offsets[0], &offsets[1])
                                        [side_index * 2 + part]
                                })
                                .map(|(k, _)| k)
                                .collect();
                            if loading.is_empty() {
                                continue;
                            }
                            let name = format!("{}.{quantity}[{}]", side.marker, axis + 1);
                            let vr = port_input(&owner, side, &name, slaves)?;
                            let key = (side.slave, vr);
                            let index = match ports.iter().position(|p| (p.0, p.1) == key) {
                                Some(i) => i,
                                None => {
                                    let column = format!("{}.{name}", slaves[side.slave].name);
                                    ports.push((side.slave, vr, column, Vec::new()));
                                    ports.len() - 1
                                }
                            };
                            for k in loading {
                                ports[index].3.push((joint_index, k, component));
                            }
                        }
                    }
                }
            }
        }
        let [side_i, side_j]: [Side; 2] = sides.try_into().expect("two sides");
        self.joints.push(Joint {
            targets: Vec::new(),
            sides: [side_i, side_j],
            conditions,
            first_unknown: first,
        });
        Ok(())
    }
}

/// Look up `<instance>.<marker>` and register its 24 outputs.
fn resolve_marker(
    owner: &str,
    instance: &str,
    marker: &str,
    offset: Vector3<f64>,
    slaves: &mut [Slave],
) -> Result<Side, MasterError> {
    let s = find_slave(owner, instance, slaves)?;
    let slave = &mut slaves[s];
    let md = slave.fmu.model_description();
    let names = joints::marker_output_names(marker);
    let mut vrs = [0u32; MARKER_OUTPUTS];
    for (k, name) in names.iter().enumerate() {
        match md.model_variables.iter().find(|v| &v.name == name) {
            Some(var)
                if var.causality == Causality::Output && var.base_type() == BaseType::Real =>
            {
                vrs[k] = var.value_reference;
            }
            Some(var) => {
                return Err(MasterError::WrongVariable {
                    instance: instance.to_string(),
                    variable: name.clone(),
                    found: describe(var),
                    role: format!("marker '{marker}' of {owner}"),
                    expected: "a Real output".into(),
                })
            }
            None if k == 0 => {
                let mut known: Vec<&str> = md
                    .model_variables
                    .iter()
                    .filter_map(|v| v.name.strip_suffix(".r[1]"))
                    .collect();
                known.dedup();
                let hint = if known.is_empty() {
                    "it has no marker ports (docs/marker-ports.md)".to_string()
                } else {
                    format!("its markers are: {}", known.join(", "))
                };
                return Err(MasterError::UnknownMarker {
                    owner: owner.to_string(),
                    instance: instance.to_string(),
                    marker: marker.to_string(),
                    hint,
                });
            }
            None => {
                return Err(MasterError::IncompleteMarker {
                    instance: instance.to_string(),
                    marker: marker.to_string(),
                    missing: name.clone(),
                })
            }
        }
    }
    let mut slots = [0usize; MARKER_OUTPUTS];
    for (k, &vr) in vrs.iter().enumerate() {
        slots[k] = slave.add_output(CoupledOutput::scalar(vr, 0));
    }
    Ok(Side {
        slave: s,
        marker: marker.to_string(),
        slots,
        offset,
    })
}

/// The value reference of a marker's force or torque input.
fn port_input(owner: &str, side: &Side, name: &str, slaves: &[Slave]) -> Result<u32, MasterError> {
    let slave = &slaves[side.slave];
    match slave
        .fmu
        .model_description()
        .model_variables
        .iter()
        .find(|v| v.name == name)
    {
        Some(var) if var.causality == Causality::Input && var.base_type() == BaseType::Real => {
            Ok(var.value_reference)
        }
        Some(var) => Err(MasterError::WrongVariable {
            instance: slave.name.clone(),
            variable: name.to_string(),
            found: describe(var),
            role: format!("the force port of {owner}"),
            expected: "a Real input".into(),
        }),
        None => Err(MasterError::MissingPort {
            owner: owner.to_string(),
            instance: slave.name.clone(),
            input: name.to_string(),
        }),
    }
}

/// Register `expr`'s inputs as driven by unknown `m`.
fn drive_inputs(
    owner: &str,
    expr: &LinearExpr,
    m: usize,
    slaves: &mut [Slave],
) -> Result<(), MasterError> {
    // Per driven input, the sum of its coefficients: all zero means the
    // terms cancel.
    let mut sums: Vec<(usize, (u32, usize), f64)> = Vec::new();
    for term in &expr.terms {
        let s = find_slave(owner, &term.instance, slaves)?;
        let slave = &slaves[s];
        let place = format!("{owner}, drives");
        let (var, element) = named(slave, &place, &term.variable)?;
        let is_real = var.base_type() == BaseType::Real;
        if var.causality != Causality::Input || !is_real || term.derivative_order != 0 {
            return Err(MasterError::WrongVariable {
                instance: term.instance.clone(),
                variable: term.variable.clone(),
                found: describe(&var),
                role: format!("'drives' of {owner}"),
                expected: "a Real input".into(),
            });
        }
        slaves[s].add_input(var.value_reference, element, m, term.coefficient);
        let key = (var.value_reference, element.map_or(0, |e| e.index));
        match sums.iter_mut().find(|(i, k, _)| *i == s && *k == key) {
            Some(sum) => sum.2 += term.coefficient,
            None => sums.push((s, key, term.coefficient)),
        }
    }
    if sums.iter().all(|&(_, _, sum)| sum == 0.0) {
        return Err(MasterError::DrivesCancel {
            owner: owner.to_string(),
            drives: expr.to_string(),
        });
    }
    Ok(())
}

/// A start value given for an input the coupling drives is refused, as
/// [`crate::Simulation::set_parameter`] refuses it: the master sets it at
/// every step.
fn check_driven_starts(spec: &SystemSpec, slaves: &[Slave]) -> Result<(), MasterError> {
    for (inst, slave) in spec.instances.iter().zip(slaves) {
        for (name, value) in &inst.parameters {
            let md = slave.fmu.model_description();
            let named = crate::spec::names::element(
                md,
                &slave.arrays,
                "parameters",
                &slave.name,
                String::new,
                name,
            );
            let Ok((var, element)) = named else { continue };
            // A whole array whose elements are partly driven gives the others
            // their values; an element or a scalar the coupling drives is refused.
            let driven = slave.coupled.inputs.iter().any(|i| {
                i.vr == var.value_reference
                    && match element {
                        Some(e) => i.element == e.index,
                        None => !var.is_array(),
                    }
            });
            if driven {
                return Err(MasterError::StartValue {
                    instance: inst.name.clone(),
                    variable: name.clone(),
                    value: value.to_string(),
                    reason: "it is an input the coupling drives; the master sets it at every step"
                        .into(),
                });
            }
        }
    }
    Ok(())
}

fn check_capabilities(slaves: &[Slave], method: &Method, order: usize) -> Result<(), MasterError> {
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
        let md = slave.fmu.model_description();
        if order > 0 {
            // One plain reason per refusal, the sentence `tether info` prints
            // (FMI 3.0 has no input derivatives: a polynomial goes through
            // intermediate update, into scalar inputs declared for it).
            let refusal = |reason: String| MasterError::NoPolynomialInput {
                instance: slave.name.clone(),
                model: slave.model_name.clone(),
                needs: crate::polynomial_inputs::NEEDS,
                reason,
            };
            if !slave.caps.polynomial_inputs {
                return Err(refusal(
                    crate::polynomial_inputs::fmu_refusal(md)
                        .unwrap_or_else(|| "the instance takes no input polynomials".into()),
                ));
            }
            // A model-exchange instance follows the polynomial on every input.
            for input in slave
                .coupled
                .inputs
                .iter()
                .filter(|_| !slave.model_exchange)
            {
                let Some(var) = md.variable_by_vr(input.vr) else {
                    continue;
                };
                if let Some(reason) = crate::polynomial_inputs::input_refusal(md, var) {
                    return Err(refusal(reason));
                }
            }
        }
        if method.needs_rollback() && !slave.caps.rollback {
            return Err(capability(
                "canGetAndSetFMUstate",
                format!(
                    "the predictor/corrector method {} (repeating macro steps)",
                    method.name()
                ),
            ));
        }
    }
    Ok(())
}

fn output_level(
    owner: &str,
    level: &'static str,
    expr: &LinearExpr,
    slaves: &mut [Slave],
) -> Result<Level, MasterError> {
    let mut out = Level::default();
    for term in &expr.terms {
        let s = find_slave(owner, &term.instance, slaves)?;
        let slave = &mut slaves[s];
        let (var, element) = named(slave, &format!("{owner}, {level}"), &term.variable)?;
        let is_real = var.base_type() == BaseType::Real;
        if var.causality != Causality::Output || !is_real {
            return Err(MasterError::WrongVariable {
                instance: term.instance.clone(),
                variable: term.variable.clone(),
                found: describe(&var),
                role: format!("the {level} level of {owner}"),
                expected: "a Real output".into(),
            });
        }
        if term.derivative_order > slave.caps.output_derivative_order {
            return Err(MasterError::MissingCapability {
                instance: slave.name.clone(),
                model: slave.model_name.clone(),
                capability: "a large enough maxOutputDerivativeOrder",
                needed_by: format!("{term} in {owner}"),
            });
        }
        if element.is_some() && term.derivative_order > 0 {
            return Err(MasterError::ArrayElement {
                place: format!("{owner}, {level}"),
                instance: slave.name.clone(),
                name: term.variable.clone(),
                reason: "output derivatives of an array element are not read (FMI 3.0 FMUs take no input derivatives either); use order = 0".into(),
            });
        }
        let (element, count) = element.map_or((0, 1), |e| (e.index, e.count));
        let slot = slave.add_output(CoupledOutput {
            vr: var.value_reference,
            order: term.derivative_order,
            element,
            count,
        });
        out.terms.push((s, slot, term.coefficient));
    }
    Ok(out)
}

/// The variable or array element `name` of `slave`, named where it appears
/// (`place`) in errors.
fn named(
    slave: &Slave,
    place: &str,
    name: &str,
) -> Result<(tether_fmi::ScalarVariable, Option<Element>), MasterError> {
    let md = slave.fmu.model_description();
    let (var, element) = crate::spec::names::element(
        md,
        &slave.arrays,
        place,
        &slave.name,
        || crate::spec::names::fmu_file(slave.fmu.path()),
        name,
    )?;
    if element.is_none() && var.is_array() {
        let sizes = slave.arrays.sizes(md, var)?;
        let shown: Vec<String> = sizes.iter().map(u64::to_string).collect();
        let first = vec!["1"; sizes.len()].join(",");
        return Err(MasterError::ArrayElement {
            place: place.to_string(),
            instance: slave.name.clone(),
            name: name.to_string(),
            reason: format!(
                "it is an array ({}); name one element, e.g. '{}[{first}]'",
                shown.join("×"),
                var.name
            ),
        });
    }
    Ok((var.clone(), element))
}

/// A term's unit for the unit check: its text (`'m'`, `'m' per s` for a
/// derivative) and dimension, or `None` where it is not compared (no or an
/// unknown unit, or a coefficient other than ±1, which may carry a unit).
fn term_unit(
    owner: &str,
    level: &str,
    term: &crate::expr::Term,
    slaves: &[Slave],
) -> Result<Option<(String, Dimension)>, MasterError> {
    if term.coefficient.abs() != 1.0 {
        return Ok(None);
    }
    let slave = &slaves[find_slave(owner, &term.instance, slaves)?];
    let (var, _) = named(slave, &format!("{owner}, {level}"), &term.variable)?;
    let Some((name, Some(dimension))) = units::unit_of(slave.fmu.model_description(), &var) else {
        return Ok(None);
    };
    Ok(Some(match term.derivative_order {
        0 => (format!("'{name}'"), dimension),
        1 => (format!("'{name}' per s"), dimension.per_second(1)),
        n => (format!("'{name}' per s{n}"), dimension.per_second(n)),
    }))
}

/// Units of a constraint, before the first step, where the FMUs declare them:
/// the terms of each level in one unit, each level the previous one's per
/// second, and drives into forces or torques, not kinematic inputs. Terms
/// with a coefficient other than ±1 are not compared (it may convert).
fn check_units(
    constraint: &str,
    levels: &[(&'static str, LinearExpr)],
    drives: &LinearExpr,
    slaves: &[Slave],
) -> Result<(), MasterError> {
    let owner = format!("constraint '{constraint}'");
    let fail = |level: &'static str, detail: String| MasterError::Units {
        constraint: constraint.to_string(),
        level,
        detail,
    };
    // The first compared term of the previous level, and its order.
    let mut previous: Option<(&'static str, String, String, Dimension, u32)> = None;
    for (level, expr) in levels {
        let order: u32 = match *level {
            "position" => 0,
            "velocity" => 1,
            _ => 2,
        };
        let mut first: Option<(String, String, Dimension)> = None;
        for term in &expr.terms {
            let Some((text, dim)) = term_unit(&owner, level, term, slaves)? else {
                continue;
            };
            match &first {
                None => first = Some((term.to_string(), text, dim)),
                Some((other, other_text, other_dim)) if !other_dim.same(&dim) => {
                    return Err(fail(
                        level,
                        format!(
                            "{other} is in {other_text} and {term} in {text}: the terms of a \
                             level need one unit (a coefficient converts)"
                        ),
                    ));
                }
                Some(_) => {}
            }
        }
        if let (Some((term, text, dim)), Some((prev_level, prev_term, prev_text, prev_dim, n))) =
            (&first, &previous)
        {
            if !prev_dim.per_second(order - n).same(dim) {
                return Err(fail(
                    level,
                    format!(
                        "{term} is in {text}; the {level} level needs the {prev_level} \
                         level's unit per {} ({prev_term} is in {prev_text})",
                        if order - n == 2 {
                            "second squared"
                        } else {
                            "second"
                        }
                    ),
                ));
            }
        }
        if let Some((term, text, dim)) = first {
            previous = Some((level, term, text, dim, order));
        }
    }
    let mut first: Option<(String, String, Dimension)> = None;
    for term in &drives.terms {
        let Some((text, dim)) = term_unit(&owner, "drives", term, slaves)? else {
            continue;
        };
        if dim.is_kinematic() {
            return Err(fail(
                "drives",
                format!(
                    "{term} is in {text}: the multiplier drives force or torque inputs, \
                     not positions, velocities or accelerations"
                ),
            ));
        }
        match &first {
            None => first = Some((term.to_string(), text, dim)),
            Some((other, other_text, other_dim)) if !other_dim.same(&dim) => {
                return Err(fail(
                    "drives",
                    format!(
                        "{other} is in {other_text} and {term} in {text}: the inputs a \
                         multiplier drives need one unit (a coefficient converts)"
                    ),
                ));
            }
            Some(_) => {}
        }
    }
    Ok(())
}

fn find_slave(owner: &str, instance: &str, slaves: &[Slave]) -> Result<usize, MasterError> {
    find_instance(owner, instance, slaves.iter().map(|s| s.name.as_str()))
}
