//! The coupling conditions resolved against the FMUs: the unknowns (one per
//! row), and the rows — linear constraints between outputs, joint conditions
//! between marker ports, additional coupling variables and force-port rows.

use nalgebra::Vector3;
use tether_fmi::{BaseType, Causality, ScalarVariable};

use crate::expr::LinearExpr;
use crate::joints::{self, Condition, Frames, Joint, Side, MARKER_OUTPUTS};
use crate::slave::{CoupledOutput, Slave};
use crate::spec::{ConstraintSpec, InitialMultiplier, JointInitial, JointSpec, SystemSpec};
use crate::{MasterError, Method};

/// Where row values come from: the slaves' latest coupled outputs, or for
/// slaves not `live`, the saved `base` values; the unknowns `u` with at most
/// one component bumped (a finite-difference column).
pub(crate) struct View<'a> {
    pub slaves: &'a [Slave],
    pub base: &'a [Vec<f64>],
    pub live: Option<&'a [bool]>,
    /// Latest values of live slaves kept outside the slaves (parallel perturbed
    /// runs), instead of `slaves[s].coupled_values`.
    pub latest: Option<&'a [Vec<f64>]>,
    pub u: &'a [f64],
    pub bump: Option<(usize, f64)>,
}

impl View<'_> {
    /// Output `slot` of slave `s`.
    #[inline]
    pub fn value(&self, s: usize, slot: usize) -> f64 {
        match self.live {
            Some(live) if !live[s] => self.base[s][slot],
            _ => match self.latest {
                Some(latest) => latest[s][slot],
                None => self.slaves[s].coupled_values[slot],
            },
        }
    }

    /// Unknown `m`, bumped if it is the perturbed one.
    #[inline]
    pub fn unknown(&self, m: usize) -> f64 {
        match self.bump {
            Some((b, delta)) if b == m => self.u[m] + delta,
            _ => self.u[m],
        }
    }
}

/// One level (position, velocity or acceleration) of a linear constraint:
/// `Σ coefficient · slave.coupled_values[slot]`.
#[derive(Debug, Clone, Default)]
pub(crate) struct Level {
    pub terms: Vec<(usize, usize, f64)>,
}

impl Level {
    pub fn eval(&self, view: &View) -> f64 {
        self.terms
            .iter()
            .map(|&(s, slot, c)| c * view.value(s, slot))
            .sum()
    }
}

/// The rows of a coupling made only of linear constraints, compiled for the
/// levels a method evaluates. The slaves' coupled outputs are laid end to end
/// in one flat array (slave `s` in `parts[s]`), and the rows of every
/// level, level after level, are runs of `(flat index, coefficient)` terms:
/// one pass over contiguous memory for all levels instead of a dispatch per
/// row and a lookup per value. The products are summed in the order of
/// [`Level::eval`], so the values are bit for bit the same.
#[derive(Debug, Clone)]
pub(crate) struct Compiled {
    /// Each slave's coupled outputs in the flat array.
    parts: Vec<std::ops::Range<usize>>,
    /// Length of the flat array.
    pub len: usize,
    /// The rows, those of the first level first.
    rows: Rows,
}

/// Compiled rows as `(flat index, coefficient)` terms.
#[derive(Debug, Clone)]
enum Rows {
    /// Every row has exactly two terms (a joint's condition on two markers'
    /// outputs, the usual case): evaluated without a loop per row.
    Pairs(Vec<[(usize, f64); 2]>),
    /// Any number of terms a row: a row's terms end at its `ends` entry and
    /// start where the row before it ends.
    Runs {
        ends: Vec<usize>,
        terms: Vec<(usize, f64)>,
    },
}

impl Compiled {
    /// `None` unless every row is a linear constraint defined on every level
    /// in `levels` (none of them the explicit method's stabilised one).
    pub fn new(coupling: &Coupling, levels: &[RowLevel], slaves: &[Slave]) -> Option<Compiled> {
        let mut rows = Vec::with_capacity(levels.len() * coupling.len());
        for &level in levels {
            for unknown in &coupling.unknowns {
                let Row::Constraint(c) = unknown.row else {
                    return None;
                };
                let constraint = &coupling.constraints[c];
                rows.push(match level {
                    RowLevel::Position => &constraint.position,
                    RowLevel::Velocity => constraint.velocity.as_ref()?,
                    RowLevel::Acceleration => constraint.acceleration.as_ref()?,
                    RowLevel::Stabilised(_) => return None,
                });
            }
        }
        let lens: Vec<usize> = slaves.iter().map(|s| s.coupled_values.len()).collect();
        Some(Compiled::from_rows(&lens, &rows))
    }

    /// The rows `rows` (levels of linear constraints) over slaves with `lens`
    /// coupled outputs each.
    fn from_rows(lens: &[usize], rows: &[&Level]) -> Compiled {
        let mut parts = Vec::with_capacity(lens.len());
        let mut len = 0;
        for &n in lens {
            parts.push(len..len + n);
            len += n;
        }
        let term = |&(s, slot, c): &(usize, usize, f64)| (parts[s].start + slot, c);
        let rows = match rows
            .iter()
            .map(|row| match &row.terms[..] {
                [a, b] => Some([term(a), term(b)]),
                _ => None,
            })
            .collect()
        {
            Some(pairs) => Rows::Pairs(pairs),
            None => {
                let mut ends = Vec::with_capacity(rows.len());
                let mut terms = Vec::new();
                for row in rows {
                    terms.extend(row.terms.iter().map(term));
                    ends.push(terms.len());
                }
                Rows::Runs { ends, terms }
            }
        };
        Compiled { parts, len, rows }
    }

    /// Slave `s`'s coupled outputs in `flat`.
    #[inline]
    pub fn part<'a>(&self, flat: &'a [f64], s: usize) -> &'a [f64] {
        &flat[self.parts[s].clone()]
    }

    /// Slave `s`'s coupled outputs in `flat`, to write.
    #[inline]
    pub fn part_mut<'a>(&self, flat: &'a mut [f64], s: usize) -> &'a mut [f64] {
        &mut flat[self.parts[s].clone()]
    }

    /// The first `out.len()` rows from `flat`: every level (`out` as long as
    /// the levels times the unknowns), or the first level only.
    #[inline]
    pub fn eval(&self, flat: &[f64], out: &mut [f64]) {
        match &self.rows {
            Rows::Pairs(pairs) => {
                // `-0.0 + p` is `p`: the same bits as the sum below.
                for (out, &[(i, a), (j, b)]) in out.iter_mut().zip(pairs) {
                    *out = a * flat[i] + b * flat[j];
                }
            }
            Rows::Runs { ends, terms } => {
                let mut start = 0;
                for (out, &end) in out.iter_mut().zip(ends) {
                    *out = terms[start..end].iter().map(|&(i, c)| c * flat[i]).sum();
                    start = end;
                }
            }
        }
    }
}

/// `to.copy_from_slice(from)`, with one to four elements as plain moves: a
/// macro step copies a few values at a time (a body's coupled outputs, an
/// unknown's polynomial), for which a call to `memcpy` costs more than the copy.
#[inline(always)]
pub(crate) fn copy_small<T: Copy>(to: &mut [T], from: &[T]) {
    match (to, from) {
        ([a], [w]) => *a = *w,
        ([a, b], [w, x]) => (*a, *b) = (*w, *x),
        ([a, b, c], [w, x, y]) => (*a, *b, *c) = (*w, *x, *y),
        ([a, b, c, d], [w, x, y, z]) => (*a, *b, *c, *d) = (*w, *x, *y, *z),
        (to, from) => to.copy_from_slice(from),
    }
}

/// A linear constraint with its multiplier.
#[derive(Debug, Clone)]
pub(crate) struct Constraint {
    pub position: Level,
    pub velocity: Option<Level>,
    pub acceleration: Option<Level>,
}

/// Which condition a row evaluates: one level, or the explicit method's
/// stabilised acceleration condition `g̈ + 2ġ/μ + g/μ²`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum RowLevel {
    Position,
    Velocity,
    Acceleration,
    Stabilised(f64),
}

impl RowLevel {
    /// Pick or combine the three levels of a condition.
    #[inline]
    pub fn combine(self, g: f64, g_dot: f64, g_ddot: f64) -> f64 {
        match self {
            RowLevel::Position => g,
            RowLevel::Velocity => g_dot,
            RowLevel::Acceleration => g_ddot,
            RowLevel::Stabilised(mu) => g_ddot + (2.0 * g_dot / mu + g / (mu * mu)),
        }
    }
}

impl Constraint {
    fn eval(&self, level: RowLevel, view: &View) -> f64 {
        let opt = |l: &Option<Level>| l.as_ref().expect("checked at build time").eval(view);
        match level {
            RowLevel::Position => self.position.eval(view),
            RowLevel::Velocity => opt(&self.velocity),
            RowLevel::Acceleration => opt(&self.acceleration),
            RowLevel::Stabilised(mu) => {
                let mut r = opt(&self.acceleration);
                r += 2.0 * opt(&self.velocity) / mu + self.position.eval(view) / (mu * mu);
                r
            }
        }
    }
}

/// An additional coupling variable: row `u − value(outputs)`.
#[derive(Debug, Clone)]
pub(crate) struct Variable {
    pub unknown: usize,
    pub value: Level,
}

/// A force or torque input of a marker, driven by its own unknown; row
/// `u − Σ λ · law component`.
#[derive(Debug, Clone)]
pub(crate) struct Port {
    pub unknown: usize,
}

/// A port found while resolving joints: slave, input value reference, column
/// name and contributions, before it gets its unknown.
type PortDraft = (usize, u32, String, Vec<(usize, usize, usize)>);

/// What row `r` (and unknown `r`) is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Row {
    Constraint(usize),
    Joint { joint: usize, condition: usize },
    Variable(usize),
    Port(usize),
}

/// A coupling unknown.
#[derive(Debug, Clone)]
pub(crate) struct Unknown {
    /// Column name of its value.
    pub name: String,
    /// Column name of its row's position-level residual, for condition rows.
    pub residual: Option<String>,
    pub initial: InitialMultiplier,
    pub row: Row,
}

impl Unknown {
    /// Rows that are the same on every level (variables and ports).
    pub fn is_algebraic(&self) -> bool {
        matches!(self.row, Row::Variable(_) | Row::Port(_))
    }
}

/// Everything the master solves for and the rows it solves.
#[derive(Debug, Clone, Default)]
pub(crate) struct Coupling {
    pub constraints: Vec<Constraint>,
    pub joints: Vec<Joint>,
    pub variables: Vec<Variable>,
    pub ports: Vec<Port>,
    pub unknowns: Vec<Unknown>,
}

impl Coupling {
    /// Number of unknowns (= rows).
    pub fn len(&self) -> usize {
        self.unknowns.len()
    }

    /// Evaluate every row at `level` into `out`.
    pub fn eval(&self, level: RowLevel, view: &View, out: &mut [f64]) {
        for (r, unknown) in self.unknowns.iter().enumerate() {
            out[r] = match unknown.row {
                Row::Constraint(c) => self.constraints[c].eval(level, view),
                // Joint rows are filled below, one kinematics read per joint.
                Row::Joint { .. } => continue,
                Row::Variable(v) => {
                    let var = &self.variables[v];
                    view.unknown(var.unknown) - var.value.eval(view)
                }
                // Port rows first accumulate Σ λ·law below.
                Row::Port(_) => 0.0,
            };
        }
        // One kinematics read and one force law per joint condition; each port
        // sums its contributions in (joint, condition) order.
        for joint in &self.joints {
            let (ki, kj) = joint.kinematics(view);
            let mut targets = joint.targets.iter().peekable();
            for (c, condition) in joint.conditions.iter().enumerate() {
                out[joint.first_unknown + c] = condition.value(level, &ki, &kj);
                if targets.peek().is_some_and(|t| t.0 == c) {
                    let law = condition.law(&ki, &kj);
                    let lambda = view.unknown(joint.first_unknown + c);
                    while let Some(&(_, component, row)) = targets.next_if(|t| t.0 == c) {
                        out[row] += lambda * law[component];
                    }
                }
            }
        }
        for port in &self.ports {
            out[port.unknown] = view.unknown(port.unknown) - out[port.unknown];
        }
    }

    /// Position-level residual of every condition row, in `residual` order.
    pub fn residuals<'a>(&'a self, view: &'a View) -> impl Iterator<Item = f64> + 'a {
        self.unknowns
            .iter()
            .filter(|u| u.residual.is_some())
            .map(move |u| match u.row {
                Row::Constraint(c) => self.constraints[c].position.eval(view),
                Row::Joint { joint, condition } => {
                    let j = &self.joints[joint];
                    let (ki, kj) = j.kinematics(view);
                    j.conditions[condition].value(RowLevel::Position, &ki, &kj)
                }
                _ => unreachable!("only condition rows have residuals"),
            })
    }

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
            slaves[slave].add_input(vr, m, 1.0);
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
        drive_inputs(&owner, &parse("drives", &spec.drives)?, m, slaves)?;
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
        slots[k] = slave.add_output(CoupledOutput { vr, order: 0 });
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
    for term in &expr.terms {
        let s = find_slave(owner, &term.instance, slaves)?;
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
                role: format!("'drives' of {owner}"),
                expected: "a Real input".into(),
            });
        }
        slaves[s].add_input(var.value_reference, m, term.coefficient);
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
                role: format!("the {level} level of {owner}"),
                expected: "a Real output".into(),
            });
        }
        if term.derivative_order > slave.max_output_derivative_order {
            return Err(MasterError::MissingCapability {
                instance: slave.name.clone(),
                model: slave.model_name.clone(),
                capability: "a large enough maxOutputDerivativeOrder",
                needed_by: format!("{term} in {owner}"),
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

fn find_slave(owner: &str, instance: &str, slaves: &[Slave]) -> Result<usize, MasterError> {
    slaves
        .iter()
        .position(|s| s.name == instance)
        .ok_or_else(|| {
            let close: Vec<&str> = slaves
                .iter()
                .map(|s| s.name.as_str())
                .filter(|n| similar(n, instance))
                .collect();
            let hint = if close.is_empty() {
                let all: Vec<&str> = slaves.iter().map(|s| s.name.as_str()).collect();
                format!("; instances are: {}", all.join(", "))
            } else {
                format!("; did you mean '{}'?", close.join("', '"))
            };
            MasterError::UnknownInstance {
                owner: owner.to_string(),
                instance: instance.to_string(),
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

    /// Compiled rows give the bits of `Level::eval`, in the two-term form
    /// and in the general one, signed zeros and non-finite values included.
    #[test]
    fn compiled_rows_match_level_eval_bit_for_bit() {
        let values = vec![
            vec![0.1, -0.0, 3.0e-9, f64::INFINITY],
            vec![-0.3, 0.0, 7.25, f64::NAN],
        ];
        let level = |terms: &[(usize, usize, f64)]| Level {
            terms: terms.to_vec(),
        };
        let pairs = [
            level(&[(0, 0, 1.0), (1, 0, -1.0)]),
            level(&[(0, 1, 1.0), (1, 1, -1.0)]),
            level(&[(0, 1, -2.0), (1, 1, 0.5)]),
            level(&[(0, 2, 1.0), (1, 2, -1.0)]),
            level(&[(0, 3, 1.0), (1, 0, -1.0)]),
            level(&[(1, 3, 1.0), (0, 0, 0.0)]),
        ];
        let mut mixed: Vec<Level> = pairs.iter().map(|l| level(&l.terms)).collect();
        mixed.push(level(&[(0, 0, 1.0), (0, 2, 2.0), (1, 0, -1.0)]));
        mixed.push(level(&[(1, 1, -1.0)]));
        let flat: Vec<f64> = values.concat();
        let view = View {
            slaves: &[],
            base: &values,
            live: None,
            latest: Some(&values),
            u: &[],
            bump: None,
        };
        for rows in [&pairs[..], &mixed[..]] {
            let refs: Vec<&Level> = rows.iter().collect();
            let compiled = Compiled::from_rows(&[4, 4], &refs);
            let two_terms = matches!(compiled.rows, Rows::Pairs(_));
            assert_eq!(two_terms, rows.len() == pairs.len());
            let mut out = vec![f64::NAN; rows.len()];
            compiled.eval(&flat, &mut out);
            for (row, got) in rows.iter().zip(&out) {
                assert_eq!(got.to_bits(), row.eval(&view).to_bits());
            }
            // The first rows only.
            let mut first = vec![f64::NAN; 2];
            compiled.eval(&flat, &mut first);
            assert_eq!(first[1].to_bits(), out[1].to_bits());
        }
    }

    #[test]
    fn close_names_are_suggested() {
        assert!(similar("mass1", "mas1"));
        assert!(similar("pendulum", "pendulum_b"));
        assert!(!similar("mass1", "crank"));
        assert_eq!(edit_distance("kitten", "sitting"), 3);
    }
}
