//! Multipliers from direct feedthrough, without a macro-step repetition: set
//! the unknowns as inputs, read the outputs back (no step), and make a Newton
//! step on an acceleration-level condition with the sensitivity ∂g̈/∂u from
//! perturbed inputs read back the same way. Used for the consistent initial
//! multipliers (`g̈ = 0` at T_0, eq. 3 for the oscillator) and by the explicit
//! method (`μ² g̈ + 2μ ġ + g = 0` at T_{N+1}).

use crate::coupling::rows::{Column, RowLevel, View};
use crate::linalg::solve::{Jacobians, Solver};
use crate::polynomial::Taylor;
use crate::slave::Run;
use crate::spec::InitialMultiplier;
use crate::stats::RunStats;
use crate::system::System;
use crate::MasterError;

/// Buffers of the feedthrough Newton step, sized for one system and reused.
pub(crate) struct Feedthrough {
    /// The unknowns being solved for.
    unknowns: Vec<usize>,
    /// The unknowns held constant: their values as inputs.
    polys: Vec<Taylor>,
    /// `polys` with the current group's unknowns bumped.
    bumped: Vec<Taylor>,
    /// The unknowns' current values.
    u: Vec<f64>,
    /// Coupled outputs of each instance at `polys`, and at `bumped`.
    outputs: Vec<Vec<f64>>,
    perturbed: Vec<Vec<f64>>,
    /// Instances whose inputs the current group perturbs.
    touched: Vec<bool>,
    /// Instances whose outputs count as perturbed for one column.
    live: Vec<bool>,
    /// Per unknown: its column in the solve, if it is being solved for.
    column: Vec<Option<usize>>,
    /// Row values, and the residuals of `unknowns` at `polys`.
    rows: Vec<f64>,
    r0: Vec<f64>,
    /// ∂r/∂u of every row on the pattern of the rows each unknown touches.
    jac: Jacobians,
    /// For all unknowns at once (dense or sparse by size), and for a subset.
    all: Solver,
    solver: Solver,
}

impl Feedthrough {
    pub fn new(system: &System) -> Feedthrough {
        let nu = system.coupling.len();
        let outputs: Vec<Vec<f64>> = system.outputs.clone();
        Feedthrough {
            unknowns: Vec::with_capacity(nu),
            polys: vec![Taylor::default(); nu],
            bumped: vec![Taylor::default(); nu],
            u: vec![0.0; nu],
            perturbed: outputs.clone(),
            outputs,
            touched: vec![false; system.slaves.len()],
            live: vec![false; system.slaves.len()],
            column: vec![None; nu],
            rows: vec![0.0; nu],
            r0: Vec::with_capacity(nu),
            jac: Jacobians::new(&system.touched, 1),
            all: Solver::new(&system.touched),
            solver: Solver::default(),
        }
    }

    /// λ(T_0): values given in the system file stay; "consistent" ones solve
    /// `level` = 0 (g̈, or the explicit method's stabilised condition) with
    /// two Newton steps (exact after one for linear feedthrough). The
    /// unknowns are then set as constant inputs.
    pub fn initial(
        &mut self,
        system: &mut System,
        level: RowLevel,
        time: f64,
        stats: &mut RunStats,
    ) -> Result<(), MasterError> {
        self.unknowns.clear();
        self.unknowns.extend(
            (0..system.coupling.len())
                .filter(|&m| system.coupling.unknowns[m].initial == InitialMultiplier::Consistent),
        );
        if !self.unknowns.is_empty() {
            for _ in 0..2 {
                self.newton(system, level, time, stats)?;
            }
        }
        self.hold_inputs(system)
    }

    /// Every unknown solved on `level` = 0 with two Newton steps (exact
    /// after one for linear feedthrough), then set as constant inputs: the
    /// consistent multipliers at an accepted point after an input changed
    /// ([`Simulation::consistent_values`](crate::Simulation::consistent_values)).
    pub fn solve_all(
        &mut self,
        system: &mut System,
        level: RowLevel,
        time: f64,
        stats: &mut RunStats,
    ) -> Result<(), MasterError> {
        self.newton_all(system, level, time, stats, 2)
    }

    /// One Newton step for every unknown on `level` = 0, then the unknowns
    /// set as constant inputs (the explicit method's update at T_{N+1}).
    pub fn update_all(
        &mut self,
        system: &mut System,
        level: RowLevel,
        time: f64,
        stats: &mut RunStats,
    ) -> Result<(), MasterError> {
        self.newton_all(system, level, time, stats, 1)
    }

    /// `steps` Newton steps for every unknown on `level` = 0, then the
    /// unknowns set as constant inputs.
    fn newton_all(
        &mut self,
        system: &mut System,
        level: RowLevel,
        time: f64,
        stats: &mut RunStats,
        steps: usize,
    ) -> Result<(), MasterError> {
        self.unknowns.clear();
        self.unknowns.extend(0..system.coupling.len());
        if !self.unknowns.is_empty() {
            for _ in 0..steps {
                self.newton(system, level, time, stats)?;
            }
        }
        self.hold_inputs(system)
    }

    /// Set the current unknowns u_N as constant inputs of every instance.
    fn hold_inputs(&mut self, system: &mut System) -> Result<(), MasterError> {
        for (p, h) in self.polys.iter_mut().zip(&system.history) {
            *p = Taylor {
                value: h[0],
                ..Taylor::default()
            };
        }
        system.apply_inputs(&self.polys)
    }

    /// One Newton step on the residual r = `level` of the rows of
    /// `self.unknowns` (each unknown has its own row), with W = ∂r/∂u by
    /// finite differences in the inputs (one group of unknowns at a time).
    fn newton(
        &mut self,
        system: &mut System,
        level: RowLevel,
        time: f64,
        stats: &mut RunStats,
    ) -> Result<(), MasterError> {
        self.hold_inputs(system)?;
        for (slave, out) in system.slaves.iter_mut().zip(&mut self.outputs) {
            slave.read_coupled(out, Run::Feedthrough)?;
        }
        for (u, h) in self.u.iter_mut().zip(&system.history) {
            *u = h[0];
        }
        let view = View::at(&self.outputs, &self.u);
        system.coupling.eval(level, &view, &mut self.rows);
        self.r0.clear();
        self.r0.extend(self.unknowns.iter().map(|&m| self.rows[m]));
        let n = self.unknowns.len();
        self.column.fill(None);
        for (k, &m) in self.unknowns.iter().enumerate() {
            self.column[m] = Some(k);
        }
        for (group, members) in system.groups.iter().zip(&system.group_slaves) {
            if !group.iter().any(|&m| self.column[m].is_some()) {
                continue;
            }
            let column = &self.column;
            let members_solved = || group.iter().copied().filter(|&m| column[m].is_some());
            self.bumped.copy_from_slice(&self.polys);
            for m in members_solved() {
                self.bumped[m].value += system.delta(m);
                for &s in &system.owners[m] {
                    self.touched[s] = true;
                }
            }
            for &s in members {
                if self.touched[s] {
                    let slave = &mut system.slaves[s];
                    slave.apply_inputs(&self.bumped)?;
                    slave.read_coupled(&mut self.perturbed[s], Run::Feedthrough)?;
                }
            }
            for m in members_solved() {
                for &s in &system.owners[m] {
                    self.live[s] = true;
                }
                let delta = system.delta(m);
                let view = View {
                    outputs: &self.outputs,
                    u: &self.u,
                    column: Some(Column {
                        unknown: m,
                        delta,
                        live: &self.live,
                        perturbed: &self.perturbed,
                    }),
                };
                let touched = &system.touched;
                touched.eval(&system.coupling, m, level, &view, &mut self.rows);
                for &s in &system.owners[m] {
                    self.live[s] = false;
                }
                let (rows, w) = self.jac.column_mut(m);
                for (w, &r) in w.iter_mut().zip(rows) {
                    *w = (self.rows[r] - row_at(&self.r0, column, r)) / delta;
                }
            }
            for &s in members {
                if self.touched[s] {
                    self.touched[s] = false;
                    system.slaves[s].apply_inputs(&self.polys)?;
                }
            }
        }
        stats.jacobian_solves += 1;
        let solver = if n == self.column.len() {
            // Every unknown: the rows are in unknown order.
            self.jac.load_level(&mut self.all, &self.r0, 0);
            &mut self.all
        } else {
            let (w, b) = self.solver.system(n);
            w.fill(0.0);
            for (k, &m) in self.unknowns.iter().enumerate() {
                let (rows, values) = self.jac.column_mut(m);
                for (&r, &value) in rows.iter().zip(values.iter()) {
                    if let Some(i) = self.column[r] {
                        w[i + k * n] = value;
                    }
                }
            }
            b.copy_from_slice(&self.r0);
            &mut self.solver
        };
        let step = solver.solve(time, "acceleration", system.max_condition)?;
        for (&m, s) in self.unknowns.iter().zip(step) {
            system.history[m][0] -= s;
        }
        Ok(())
    }
}

/// The residual of row `r` at the unperturbed point, for rows solved for
/// (`r0` in the order of `column`); other rows' entries are not used.
#[inline]
fn row_at(r0: &[f64], column: &[Option<usize>], r: usize) -> f64 {
    column[r].map_or(0.0, |i| r0[i])
}
