//! The coupling conditions as the master evaluates them: the unknowns (one per
//! row), and the rows — linear constraints between outputs, joint conditions
//! between marker ports, additional coupling variables and force-port rows.
//! [`crate::system::resolve`] builds them from the system file.

pub(crate) mod joints;
pub(crate) mod rows;
pub(crate) mod touched;

use crate::coupling::joints::Joint;
use crate::coupling::rows::{Level, RowLevel, View};
use crate::spec::InitialMultiplier;

/// A linear constraint with its multiplier.
#[derive(Debug, Clone)]
pub(crate) struct Constraint {
    pub position: Level,
    pub velocity: Option<Level>,
    pub acceleration: Option<Level>,
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
        for (r, slot) in out.iter_mut().enumerate().take(self.unknowns.len()) {
            if let Some(value) = self.eval_row(r, level, view) {
                *slot = value;
            }
        }
        // One kinematics read and one force law per joint condition; each port
        // sums its contributions in (joint, condition) order.
        for joint in &self.joints {
            self.eval_joint(joint, level, view, out);
        }
        for port in &self.ports {
            out[port.unknown] = view.unknown(port.unknown) - out[port.unknown];
        }
    }

    /// Row `r` on its own: a constraint or variable row's value, 0 for a port
    /// row (its joints add Σ λ·law, then it becomes `u − Σ`); `None` for a
    /// joint row (filled by [`Coupling::eval_joint`]).
    #[inline]
    pub fn eval_row(&self, r: usize, level: RowLevel, view: &View) -> Option<f64> {
        match self.unknowns[r].row {
            Row::Constraint(c) => Some(self.constraints[c].eval(level, view)),
            Row::Joint { .. } => None,
            Row::Variable(v) => {
                let var = &self.variables[v];
                Some(view.unknown(var.unknown) - var.value.eval(view))
            }
            Row::Port(_) => Some(0.0),
        }
    }

    /// A joint's condition rows, and its force laws added to the port rows
    /// it loads: one kinematics read and one law per loading condition.
    #[inline]
    pub fn eval_joint(&self, joint: &Joint, level: RowLevel, view: &View, out: &mut [f64]) {
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

    /// Position-level residual of every condition row, in `residual` order,
    /// from the coupled outputs of each instance (positions depend on no
    /// unknown).
    pub fn residuals<'a>(&'a self, outputs: &'a [Vec<f64>]) -> impl Iterator<Item = f64> + 'a {
        let view = View::at(outputs, &[]);
        self.unknowns
            .iter()
            .filter(|u| u.residual.is_some())
            .map(move |u| match u.row {
                Row::Constraint(c) => self.constraints[c].position.eval(&view),
                Row::Joint { joint, condition } => {
                    let j = &self.joints[joint];
                    let (ki, kj) = j.kinematics(&view);
                    j.conditions[condition].value(RowLevel::Position, &ki, &kj)
                }
                _ => unreachable!("only condition rows have residuals"),
            })
    }
}
