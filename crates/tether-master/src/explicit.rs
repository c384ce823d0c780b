//! Multipliers from direct feedthrough, without a macro-step repetition: the
//! consistent initial multipliers (acceleration-level condition at T_0, eq. 3
//! for the oscillator) and the explicit baseline method (ALGORITHM.md §5, our
//! reconstruction of the paper's ref. \[16\]).

use crate::stats::Lap;

use crate::coupling::{RowLevel, View};
use crate::polynomial::Taylor;
use crate::simulation::Simulation;
use crate::solve::Solver;
use crate::spec::InitialMultiplier;
use crate::MasterError;

impl Simulation {
    /// λ(T_0): user values stay; "consistent" ones solve g̈ = 0 at T_0 (for the
    /// explicit method: its own condition μ² g̈ + 2μ ġ + g = 0).
    pub(crate) fn initial_multipliers(&mut self) -> Result<(), MasterError> {
        let mut unknowns = std::mem::take(&mut self.work.feedthrough.unknowns);
        unknowns.clear();
        unknowns.extend(
            (0..self.coupling.len())
                .filter(|&m| self.coupling.unknowns[m].initial == InitialMultiplier::Consistent),
        );
        self.work.feedthrough.unknowns = unknowns;
        let mu = match self.method {
            crate::Method::Explicit { mu } => Some(mu),
            _ => None,
        };
        let time = self.time();
        if !self.work.feedthrough.unknowns.is_empty() {
            // Two Newton iterations: exact after one for linear feedthrough.
            for _ in 0..2 {
                self.feedthrough_newton(mu, time)?;
            }
        }
        self.set_constant_inputs()
    }

    /// One explicit macro step: hold u_N over [T_N, T_{N+1}], then compute
    /// u_{N+1} from the states at T_{N+1} so that μ² g̈ + 2μ ġ + g = 0 there.
    pub(crate) fn explicit_step(&mut self, mu: f64) -> Result<(), MasterError> {
        let mut lap = Lap::start(false, self.time_phases);
        let (t, h) = (self.time(), self.experiment.step);
        for slave in self.slaves.iter_mut() {
            slave.do_step(t, h)?;
        }
        self.n += 1;
        lap.split_into(&mut self.stats.times.predictor);
        let all = &mut self.work.feedthrough.unknowns;
        all.clear();
        all.extend(0..self.coupling.len());
        for hist in self.history.iter_mut() {
            *hist = [hist[0], hist[0], hist[1]];
        }
        self.feedthrough_newton(Some(mu), self.time())?;
        self.set_constant_inputs()?;
        self.read_accepted()?;
        lap.split_into(&mut self.stats.times.solve);
        self.step_end = lap.last();
        Ok(())
    }

    fn set_constant_inputs(&mut self) -> Result<(), MasterError> {
        for (m, hist) in self.history.iter().enumerate() {
            self.work.polys[m] = Taylor {
                value: hist[0],
                ..Taylor::default()
            };
        }
        self.apply_all()
    }

    /// One Newton step on the residual r = g̈ (+ 2ġ/μ + g/μ²) for the unknowns
    /// in `work.feedthrough.unknowns` (a subset, each with its own constraint
    /// row), with the sensitivity W = ∂g̈/∂u from perturbed inputs read back
    /// without a step. The buffers are taken out of `work` for the duration.
    fn feedthrough_newton(&mut self, mu: Option<f64>, time: f64) -> Result<(), MasterError> {
        let mut fw = std::mem::take(&mut self.work.feedthrough);
        let mut solver = std::mem::take(&mut self.work.solver);
        let outcome = self.feedthrough_newton_with(&mut fw, &mut solver, mu, time);
        self.work.feedthrough = fw;
        self.work.solver = solver;
        outcome
    }

    fn feedthrough_newton_with(
        &mut self,
        fw: &mut Feedthrough,
        solver: &mut Solver,
        mu: Option<f64>,
        time: f64,
    ) -> Result<(), MasterError> {
        self.set_constant_inputs()?;
        for (s, slave) in self.slaves.iter_mut().enumerate() {
            slave.read_coupled()?;
            self.work.base[s].copy_from_slice(&slave.coupled_values);
        }
        let unknowns = &fw.unknowns;
        let n = unknowns.len();
        let level = match mu {
            Some(mu) => RowLevel::Stabilised(mu),
            None => RowLevel::Acceleration,
        };
        for (m, hist) in self.history.iter().enumerate() {
            self.work.u[m] = hist[0];
        }
        {
            let work = &mut self.work;
            let view = View {
                slaves: &self.slaves,
                base: &work.base,
                live: None,
                latest: None,
                u: &work.u,
                bump: None,
            };
            self.coupling.eval(level, &view, &mut work.rows);
        }
        fw.r0.clear();
        fw.r0.extend(unknowns.iter().map(|&m| self.work.rows[m]));
        let (w, _) = solver.system(n);
        w.fill(0.0);
        for gi in 0..self.groups.len() {
            fw.members.clear();
            fw.members.extend(
                self.groups[gi]
                    .iter()
                    .copied()
                    .filter(|m| unknowns.contains(m)),
            );
            if fw.members.is_empty() {
                continue;
            }
            self.work.perturbed.copy_from_slice(&self.work.polys);
            for &m in &fw.members {
                let delta = self.settings.epsilon * self.history[m][0].abs().max(1.0);
                self.work.delta[m] = delta;
                self.work.perturbed[m].value += delta;
            }
            fw.touched.clear();
            fw.touched.resize(self.slaves.len(), false);
            for &m in &fw.members {
                for &s in &self.owners[m] {
                    fw.touched[s] = true;
                }
            }
            for (s, slave) in self.slaves.iter_mut().enumerate() {
                if fw.touched[s] {
                    slave.apply_inputs(&self.work.perturbed)?;
                    slave.read_coupled()?;
                }
            }
            for &m in &fw.members {
                fw.live.clear();
                fw.live.resize(self.slaves.len(), false);
                for &s in &self.owners[m] {
                    fw.live[s] = true;
                }
                let col = unknowns
                    .iter()
                    .position(|&x| x == m)
                    .expect("member of unknowns");
                let work = &mut self.work;
                let view = View {
                    slaves: &self.slaves,
                    base: &work.base,
                    live: Some(&fw.live),
                    latest: None,
                    u: &work.u,
                    bump: Some((m, work.delta[m])),
                };
                self.coupling.eval(level, &view, &mut work.rows);
                let (w, _) = solver.system(n);
                for (row, &r) in unknowns.iter().enumerate() {
                    w[row + col * n] = (work.rows[r] - fw.r0[row]) / work.delta[m];
                }
            }
            for (s, slave) in self.slaves.iter_mut().enumerate() {
                if fw.touched[s] {
                    slave.apply_inputs(&self.work.polys)?;
                }
            }
        }
        self.stats.jacobian_solves += 1;
        let (_, b) = solver.system(n);
        b.copy_from_slice(&fw.r0);
        let step = solver.solve(time, "acceleration", self.settings.max_condition)?;
        for (i, &m) in unknowns.iter().enumerate() {
            self.history[m][0] -= step[i];
        }
        Ok(())
    }
}

/// Buffers of the feedthrough Newton step, reused across macro steps.
#[derive(Debug, Default, Clone)]
pub(crate) struct Feedthrough {
    /// The unknowns being solved for.
    unknowns: Vec<usize>,
    /// Unknowns of the current perturbation group.
    members: Vec<usize>,
    /// Residuals at the unperturbed inputs.
    r0: Vec<f64>,
    /// Instances whose inputs the current group perturbs.
    touched: Vec<bool>,
    /// Instances whose latest outputs count as perturbed for one column.
    live: Vec<bool>,
}
