//! Multipliers from direct feedthrough, without a macro-step repetition: set
//! the unknowns as inputs, read the outputs back (no step), and make a Newton
//! step on an acceleration-level condition with the sensitivity ∂g̈/∂u from
//! perturbed inputs read back the same way. Used for the consistent initial
//! multipliers (`g̈ = 0` at T_0, eq. 3 for the oscillator) and by the explicit
//! method (`μ² g̈ + 2μ ġ + g = 0` at T_{N+1}).

use crate::polynomial::Taylor;
use crate::rows::{Column, RowLevel, View};
use crate::slave::Run;
use crate::solve::Solver;
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
    /// Row values, and the residuals of `unknowns` at `polys`.
    rows: Vec<f64>,
    r0: Vec<f64>,
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
            rows: vec![0.0; nu],
            r0: Vec::with_capacity(nu),
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

    /// One Newton step for every unknown on `level` = 0, then the unknowns
    /// set as constant inputs (the explicit method's update at T_{N+1}).
    pub fn update_all(
        &mut self,
        system: &mut System,
        level: RowLevel,
        time: f64,
        stats: &mut RunStats,
    ) -> Result<(), MasterError> {
        self.unknowns.clear();
        self.unknowns.extend(0..system.coupling.len());
        if !self.unknowns.is_empty() {
            self.newton(system, level, time, stats)?;
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
        self.solver.system(n).0.fill(0.0);
        for group in &system.groups {
            if !group.iter().any(|m| self.unknowns.contains(m)) {
                continue;
            }
            let members = || group.iter().copied().filter(|m| self.unknowns.contains(m));
            self.bumped.copy_from_slice(&self.polys);
            self.touched.fill(false);
            for m in members() {
                self.bumped[m].value += system.delta(m);
                for &s in &system.owners[m] {
                    self.touched[s] = true;
                }
            }
            for (s, slave) in system.slaves.iter_mut().enumerate() {
                if self.touched[s] {
                    slave.apply_inputs(&self.bumped)?;
                    slave.read_coupled(&mut self.perturbed[s], Run::Feedthrough)?;
                }
            }
            for m in members() {
                self.live.fill(false);
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
                system.coupling.eval(level, &view, &mut self.rows);
                let col = self.unknowns.iter().position(|&x| x == m);
                let col = col.expect("a member of the unknowns");
                let w = &mut self.solver.system(n).0[col * n..(col + 1) * n];
                for ((w, &r), r0) in w.iter_mut().zip(&self.unknowns).zip(&self.r0) {
                    *w = (self.rows[r] - r0) / delta;
                }
            }
            for (s, slave) in system.slaves.iter_mut().enumerate() {
                if self.touched[s] {
                    slave.apply_inputs(&self.polys)?;
                }
            }
        }
        stats.jacobian_solves += 1;
        self.solver.system(n).1.copy_from_slice(&self.r0);
        let step = self
            .solver
            .solve(time, "acceleration", system.max_condition)?;
        for (&m, s) in self.unknowns.iter().zip(step) {
            system.history[m][0] -= s;
        }
        Ok(())
    }
}
