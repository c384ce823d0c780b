//! The semi-implicit predictor/corrector macro step (paper Sect. 3.3), in the
//! five steps of docs/algorithm.md: save, predict, perturb, solve, correct.
//! Method 1 (Baumgarte, eqs. 65–68) and Method 2 (weighted multipliers,
//! eqs. 71–76) differ only in the solve.

use crate::algorithm::error_estimate::ErrorEstimate;
use crate::algorithm::jacobian_reuse::Reuse;
use crate::algorithm::step::{MacroStep, MethodState, StepAt};
use crate::coupling::rows::{Column, RowLevel, View};
use crate::linalg::solve::{Jacobians, Solver};
use crate::polynomial::{extrapolate, interpolate, Taylor};
use crate::runs::{Outputs, Phase, Task};
use crate::slave::Slave;
use crate::spec::CouplingSettings;
use crate::spec::JacobianMode;
use crate::state_bytes::{Pass, Passed};
use crate::stats::{Lap, RunStats};
use crate::step_control::StepControl;
use crate::system::System;
use crate::{MasterError, Method};

/// The method's own state ([`MacroStep::save`]): the Jacobians, their reuse,
/// the error estimate's scales.
type Saved = (Jacobians, Option<Reuse>, Option<Vec<Vec<f64>>>);

/// The numbers of a method's saved state through `p`, for the saved state's
/// bytes: this method's, or none (the explicit method keeps nothing).
pub(crate) fn pass_saved(state: &mut MethodState, p: &mut Pass) -> Passed {
    match state.downcast_mut::<Saved>() {
        Some((jac, reuse, peaks)) => {
            p.same(1, "the coupling method")?;
            jac.pass(p)?;
            p.option(reuse, "Jacobian reuse", |p, r| r.pass(p))?;
            p.option(peaks, "[step_control]", |p, peaks| {
                peaks
                    .iter_mut()
                    .try_for_each(|v| p.f64s(v, "the error scales"))
            })
        }
        None => p.same(0, "the coupling method"),
    }
}

/// The predictor/corrector method with the buffers its steps reuse (sized
/// at setup: a step allocates nothing).
pub(crate) struct PredictorCorrector {
    /// Method 1 or 2 with its weights.
    method: Method,
    /// Degree k of the coupling polynomials.
    order: usize,
    /// The levels the method evaluates, position first.
    levels: Vec<RowLevel>,
    /// Per row: the same on every level (coupling variables and ports).
    algebraic_rows: Vec<bool>,
    /// Each unknown's polynomial over the step: predictor, then corrector.
    polys: Vec<Taylor>,
    /// Extrapolated unknowns u^p at T_{N+1}.
    u_pred: Vec<f64>,
    /// Coupled outputs of each instance after the predictor.
    predicted: Vec<Vec<f64>>,
    /// g^p, ġ^p, g̈^p: every row of each level in `levels`, level after level.
    g: Vec<f64>,
    /// Per perturbation group: the polynomials with its unknowns perturbed.
    perturbed: Vec<Vec<Taylor>>,
    /// Per unknown: its increment Δu.
    delta: Vec<f64>,
    /// Per group and instance: coupled outputs after the perturbed run.
    outputs: Vec<Vec<Vec<f64>>>,
    /// Instances whose outputs count as perturbed for one column.
    live: Vec<bool>,
    /// Row values of one perturbed evaluation, laid out like `g`.
    rows: Vec<f64>,
    /// Interface Jacobians ∂g/∂u (∂ġ/∂u, ∂g̈/∂u) of the levels in `levels`.
    jac: Jacobians,
    solver: Solver,
    /// u_{N+1}.
    corrected: Vec<f64>,
    /// Corrections per macro step (`[coupling] iterations`, 1 = the paper).
    iterations: usize,
    /// Relative size of an update below which iterating stops.
    iteration_tol: f64,
    /// The point an iterated correction starts from (the last corrected u).
    iterate_from: Vec<f64>,
    /// Adaptive steps: the local error estimate (None: fixed steps).
    estimate: Option<ErrorEstimate>,
    /// Jacobian reuse (None: a Jacobian every step).
    reuse: Option<Reuse>,
    /// With reuse: g^p kept (iterating overwrites `g`), and g at the
    /// corrected point.
    g_predicted: Vec<f64>,
    g_corrected: Vec<f64>,
}

impl PredictorCorrector {
    pub fn new(system: &System, method: Method, settings: &CouplingSettings) -> Self {
        let nu = system.coupling.len();
        let mut levels = vec![RowLevel::Position];
        if method.needs_velocity() {
            levels.push(RowLevel::Velocity);
        }
        if method.needs_acceleration() {
            levels.push(RowLevel::Acceleration);
        }
        let outputs = &system.outputs;
        PredictorCorrector {
            method,
            order: settings.order,
            iterations: settings.iterations,
            iteration_tol: settings.iteration_tol,
            iterate_from: vec![0.0; nu],
            estimate: None,
            reuse: (settings.jacobian == JacobianMode::Reuse)
                .then(|| Reuse::new(settings.jacobian_max_age, nu, levels.len() * nu)),
            g_predicted: vec![0.0; levels.len() * nu],
            g_corrected: vec![0.0; levels.len() * nu],
            algebraic_rows: (0..nu)
                .map(|r| system.coupling.unknowns[r].is_algebraic())
                .collect(),
            polys: vec![Taylor::default(); nu],
            u_pred: vec![0.0; nu],
            predicted: outputs.clone(),
            g: vec![0.0; levels.len() * nu],
            perturbed: vec![vec![Taylor::default(); nu]; system.groups.len()],
            delta: vec![0.0; nu],
            outputs: vec![outputs.clone(); system.groups.len()],
            live: vec![false; system.slaves.len()],
            rows: vec![0.0; levels.len() * nu],
            jac: Jacobians::new(&system.touched, levels.len()),
            solver: Solver::new(&system.touched),
            corrected: vec![0.0; nu],
            levels,
        }
    }

    /// Step 1: save the state of every instance some unknown drives
    /// (`fmi2GetFMUstate`); with adaptive steps, of every instance (those
    /// the signals' Gauss–Seidel sweep has stepped were saved before it).
    fn save(&mut self, system: &mut System) -> Result<(), MasterError> {
        let all = self.estimate.is_some();
        let saved = |s: &&mut Slave| s.is_coupled() || (all && !s.stepped_ahead);
        for slave in system.slaves.iter_mut().filter(saved) {
            slave.save_state()?;
        }
        Ok(())
    }

    /// Step 2, predictor (eqs. 56–58): each unknown's polynomial extrapolated
    /// from its history, every instance stepped with it (but those the
    /// signals' Gauss–Seidel sweep has stepped already), g^p (ġ^p, g̈^p)
    /// evaluated from the outputs at T_{N+1}. With `perturb`, the perturbed
    /// runs of Step 3 are handed to each instance with its predictor run:
    /// they depend on u^p, not on the predictor's outputs.
    fn predict(
        &mut self,
        system: &mut System,
        at: StepAt,
        perturb: bool,
    ) -> Result<(), MasterError> {
        self.extrapolate(system, at);
        if perturb {
            self.perturbed_polynomials(system, at);
        }
        let phase = Phase {
            task: Task::Predict,
            t: at.t,
            h: at.h,
            polys: &self.polys,
            perturbed: if perturb { &self.perturbed } else { &[] },
        };
        let outputs = Outputs {
            own: &mut self.predicted,
            perturbed: &mut self.outputs,
        };
        system
            .runs
            .phase(&mut system.slaves, phase, outputs, |_, _| true)?;
        let view = View::at(&self.predicted, &self.u_pred);
        let nu = system.coupling.len();
        for (&level, g) in self.levels.iter().zip(self.g.chunks_exact_mut(nu)) {
            system.coupling.eval(level, &view, g);
        }
        Ok(())
    }

    /// The unknowns' polynomials extrapolated from their history, and u^p.
    fn extrapolate(&mut self, system: &System, at: StepAt) {
        for (m, history) in system.history.iter().enumerate() {
            self.polys[m] = extrapolate(history, at.degree.predictor, at.h, at.past);
            self.u_pred[m] = self.polys[m].at(at.h);
        }
    }

    /// Per group of unknowns, the perturbed runs' polynomials: u^p_m + Δu_m
    /// in the interpolation polynomial of each unknown m of the group.
    fn perturbed_polynomials(&mut self, system: &System, at: StepAt) {
        for (group, polys) in system.groups.iter().zip(&mut self.perturbed) {
            polys.copy_from_slice(&self.polys);
            for &m in group {
                self.delta[m] = system.delta(m);
                let u = self.u_pred[m] + self.delta[m];
                polys[m] = interpolate(u, &system.history[m], at.degree.corrector, at.h, at.past);
            }
        }
    }

    /// Step 3, perturbed predictors (eqs. 59–64): per group of unknowns, one
    /// run from the saved states with its perturbed polynomials (made with
    /// the predictor's runs, `made`, or now); column m of the interface
    /// Jacobian is (g^{pp_m} − g^p)/Δu_m, with only m's own instances read
    /// as perturbed and only the rows they touch evaluated.
    fn perturb(&mut self, system: &mut System, at: StepAt, made: bool) -> Result<(), MasterError> {
        if !made {
            self.perturbed_polynomials(system, at);
            let phase = Phase {
                task: Task::Perturb,
                t: at.t,
                h: at.h,
                polys: &self.polys,
                perturbed: &self.perturbed,
            };
            let outputs = Outputs {
                own: &mut [],
                perturbed: &mut self.outputs,
            };
            system
                .runs
                .phase(&mut system.slaves, phase, outputs, |_, s| s.is_coupled())?;
        }
        let nu = system.coupling.len();
        for (group, outputs) in system.groups.iter().zip(&self.outputs) {
            for &m in group {
                for &s in &system.owners[m] {
                    self.live[s] = true;
                }
                let view = View {
                    outputs: &self.predicted,
                    u: &self.u_pred,
                    column: Some(Column {
                        unknown: m,
                        delta: self.delta[m],
                        live: &self.live,
                        perturbed: outputs,
                    }),
                };
                let touched = &system.touched;
                for (&level, rows) in self.levels.iter().zip(self.rows.chunks_exact_mut(nu)) {
                    touched.eval(&system.coupling, m, level, &view, rows);
                }
                for &s in &system.owners[m] {
                    self.live[s] = false;
                }
                self.jac.difference(m, &self.rows, &self.g, self.delta[m]);
            }
        }
        Ok(())
    }

    /// Step 4, correction: u_{N+1} from the linearised conditions.
    fn solve(
        &mut self,
        system: &System,
        at: StepAt,
        stats: &mut RunStats,
    ) -> Result<(), MasterError> {
        let (time, limit) = (at.t_next, system.max_condition);
        let in_step = |e: MasterError| e.in_step(at.h);
        let level = |kind: RowLevel| self.levels.iter().position(|&l| l == kind);
        match self.method {
            Method::Baumgarte { beta, gamma } => {
                // Eq. 68: u = u^p − (G^B)⁻¹ g^B with g^B = g + β ġ + γ g̈;
                // port and coupling-variable rows are not stabilised.
                let velocity = level(RowLevel::Velocity).map(|v| (v, beta));
                let acceleration = level(RowLevel::Acceleration).map(|a| (a, gamma));
                let plain = &self.algebraic_rows;
                self.jac
                    .baumgarte(&mut self.solver, &self.g, velocity, acceleration, plain);
                let name = if self.levels.len() == 1 {
                    "position"
                } else {
                    "baumgarte"
                };
                stats.jacobian_solves += 1;
                let step = self.solver.solve(time, name, limit).map_err(in_step)?;
                for ((c, p), s) in self.corrected.iter_mut().zip(&self.u_pred).zip(step) {
                    *c = p - s;
                }
            }
            Method::Weighted { a, b } => {
                // Eqs. 73–76: solve each level, then average with weights 1, a, b.
                self.corrected.fill(0.0);
                let mut total = 0.0;
                for (l, &kind) in self.levels.iter().enumerate() {
                    let (weight, name) = match kind {
                        RowLevel::Velocity => (a, "velocity"),
                        RowLevel::Acceleration => (b, "acceleration"),
                        _ => (1.0, "position"),
                    };
                    stats.jacobian_solves += 1;
                    self.jac.load_level(&mut self.solver, &self.g, l);
                    let step = self.solver.solve(time, name, limit).map_err(in_step)?;
                    for ((c, p), s) in self.corrected.iter_mut().zip(&self.u_pred).zip(step) {
                        *c += weight * (p - s);
                    }
                    total += weight;
                }
                for c in &mut self.corrected {
                    *c /= total;
                }
            }
            Method::Explicit { .. } => unreachable!("the explicit method has its own step"),
        }
        Ok(())
    }

    /// Step 5, corrector: every driven instance repeats the step from its
    /// saved state with the interpolation polynomials through u_{N+1}, and
    /// the outputs at T_{N+1} are read (with the run, one unit).
    fn correct(&mut self, system: &mut System, at: StepAt) -> Result<(), MasterError> {
        for (m, history) in system.history.iter().enumerate() {
            self.polys[m] = interpolate(
                self.corrected[m],
                history,
                at.degree.corrector,
                at.h,
                at.past,
            );
        }
        let phase = Phase {
            task: Task::Correct,
            t: at.t,
            h: at.h,
            polys: &self.polys,
            perturbed: &[],
        };
        let outputs = Outputs {
            own: &mut system.outputs,
            perturbed: &mut [],
        };
        system
            .runs
            .phase(&mut system.slaves, phase, outputs, |_, _| true)
    }

    /// Iterated correction (`[coupling] iterations`, beyond the paper): g
    /// (ġ, g̈) at the corrected point, another solve with the same interface
    /// Jacobian from there, another corrector run; until every update is
    /// below `iteration_tol·max(1, |u|)` or `iterations` corrections were
    /// made. Returns the number of corrections, the first included.
    fn iterate(
        &mut self,
        system: &mut System,
        at: StepAt,
        stats: &mut RunStats,
    ) -> Result<u64, MasterError> {
        let mut corrections: usize = 1;
        while corrections < self.iterations {
            let nu = system.coupling.len();
            let view = View::at(&system.outputs, &self.corrected);
            for (&level, g) in self.levels.iter().zip(self.g.chunks_exact_mut(nu)) {
                system.coupling.eval(level, &view, g);
            }
            // The solve starts from `u_pred`: let it start from the last
            // corrected point, and keep the prediction for afterwards.
            self.iterate_from.copy_from_slice(&self.corrected);
            std::mem::swap(&mut self.u_pred, &mut self.iterate_from);
            let solved = self.solve(system, at, stats);
            std::mem::swap(&mut self.u_pred, &mut self.iterate_from);
            solved?;
            self.correct(system, at)?;
            corrections += 1;
            let tol = self.iteration_tol;
            let small = self
                .corrected
                .iter()
                .zip(&self.iterate_from)
                .all(|(u, from)| (u - from).abs() <= tol * u.abs().max(1.0));
            if small {
                break;
            }
        }
        Ok(corrections as u64)
    }

    /// Adaptive steps: the step's error norm (docs/algorithm.md, Milne's
    /// device on the coupled states of the predictor and corrector runs);
    /// a step above 1 is rolled back, every instance to its saved state.
    fn estimate_error(
        &mut self,
        system: &mut System,
        at: StepAt,
    ) -> Result<Option<f64>, MasterError> {
        let Some(estimate) = &mut self.estimate else {
            return Ok(None);
        };
        let norm = estimate.norm(&self.predicted, &system.outputs, at.degree.corrector);
        if norm.is_nan() || norm > 1.0 {
            for slave in &mut system.slaves {
                slave.restore_state()?;
            }
        }
        Ok(Some(norm))
    }

    /// Jacobian reuse: whether this step makes the perturbed runs.
    fn jacobian_due(&self, at: StepAt) -> bool {
        let growing = at.n <= self.order as u64;
        self.reuse.as_ref().is_none_or(|r| r.due(at.h, growing))
    }

    /// Jacobian reuse: g at the corrected point, and whether the Jacobian
    /// mispredicted the correction ([`Reuse::mispredicted`]).
    fn mispredicted(&mut self, system: &System) -> bool {
        let Some(reuse) = &mut self.reuse else {
            return false;
        };
        let nu = system.coupling.len();
        let view = View::at(&system.outputs, &self.corrected);
        for (&level, g) in self
            .levels
            .iter()
            .zip(self.g_corrected.chunks_exact_mut(nu))
        {
            system.coupling.eval(level, &view, g);
        }
        reuse.mispredicted(
            &mut self.jac,
            (&self.u_pred, &self.corrected),
            (&self.g_predicted, &self.g_corrected),
        )
    }

    /// Accept the step: u_{N+1} goes to the head of the history, the
    /// accepted states to the error estimate's peaks.
    fn accept(&mut self, system: &mut System) {
        for (history, &u) in system.history.iter_mut().zip(&self.corrected) {
            *history = [u, history[0], history[1]];
        }
        if let Some(estimate) = &mut self.estimate {
            estimate.accept(&system.outputs);
        }
    }
}

impl MacroStep for PredictorCorrector {
    fn step(
        &mut self,
        system: &mut System,
        at: StepAt,
        stats: &mut RunStats,
        lap: &mut Lap,
    ) -> Result<Option<f64>, MasterError> {
        if self.u_pred.is_empty() {
            // Nothing to solve for (signal connections only): every
            // instance steps once, and that is the accepted point, read.
            let phase = Phase {
                task: Task::StepAndRead,
                ..Phase::step(at.t, at.h)
            };
            let outputs = Outputs {
                own: &mut system.outputs,
                perturbed: &mut [],
            };
            let slaves = &mut system.slaves;
            system.runs.phase(slaves, phase, outputs, |_, _| true)?;
            return Ok(None);
        }
        // Beyond the paper: with Jacobian reuse, perturbed runs only when
        // due, and when the reused Jacobian mispredicted the correction: then
        // the correction is made again from g^p with a fresh one.
        let mut fresh = self.jacobian_due(at);
        self.save(system)?;
        self.predict(system, at, fresh)?;
        lap.split_into(&mut stats.times.predictor);
        if self.reuse.is_some() {
            self.g_predicted.copy_from_slice(&self.g);
        }
        let mut made = fresh;
        let corrections = loop {
            if fresh {
                self.perturb(system, at, made)?;
                made = false;
                stats.jacobians += 1;
                if let Some(reuse) = &mut self.reuse {
                    reuse.made(at.h);
                }
            }
            lap.split_into(&mut stats.times.jacobian);
            self.solve(system, at, stats)?;
            lap.split_into(&mut stats.times.solve);
            self.correct(system, at)?;
            // Beyond the paper: repeat the correction (1 = none).
            let corrections = self.iterate(system, at, stats)?;
            lap.split_into(&mut stats.times.corrector);
            let missed = self.mispredicted(system);
            if fresh || !missed {
                break corrections;
            }
            fresh = true;
            stats.jacobians_remade += 1;
            // Back to the predictor's polynomials and g^p.
            self.extrapolate(system, at);
            self.g.copy_from_slice(&self.g_predicted);
        };
        if !fresh {
            stats.jacobians_reused += 1;
        }
        // Beyond the paper: adaptive steps judge the step first.
        let error = self.estimate_error(system, at)?;
        if error.is_some_and(|e| e.is_nan() || e > 1.0) {
            return Ok(error);
        }
        stats.corrections += corrections;
        stats.max_corrections = stats.max_corrections.max(corrections);
        if let Some(reuse) = &mut self.reuse {
            reuse.accepted(&mut self.jac);
        }
        self.accept(system);
        Ok(error)
    }

    fn save(&self) -> MethodState {
        let peaks = self.estimate.as_ref().map(ErrorEstimate::peaks);
        let saved: Saved = (self.jac.clone(), self.reuse.clone(), peaks);
        Box::new(saved)
    }

    fn restore(&mut self, state: &MethodState) {
        let (jac, reuse, peaks) = state
            .downcast_ref::<Saved>()
            .expect("a state saved by this method");
        self.jac.clone_from(jac);
        self.reuse.clone_from(reuse);
        if let (Some(estimate), Some(peaks)) = (&mut self.estimate, peaks) {
            estimate.set_peaks(peaks);
        }
    }

    fn control_steps(&mut self, system: &System, control: &StepControl) -> bool {
        self.estimate = Some(ErrorEstimate::new(system, &self.levels, control));
        true
    }
}
