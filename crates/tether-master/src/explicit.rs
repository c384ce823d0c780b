//! Multipliers from direct feedthrough, without a macro-step repetition: the
//! consistent initial multipliers (acceleration-level condition at T_0, eq. 3
//! for the oscillator) and the explicit baseline method (ALGORITHM.md §5, our
//! reconstruction of the paper's ref. [16]).

use std::time::Instant;

use nalgebra::{DMatrix, DVector};

use crate::coupling::{RowLevel, View};
use crate::polynomial::Taylor;
use crate::simulation::Simulation;
use crate::solve::solve;
use crate::spec::InitialMultiplier;
use crate::MasterError;

impl Simulation {
    /// λ(T_0): user values stay; "consistent" ones solve g̈ = 0 at T_0 (for the
    /// explicit method: its own condition μ² g̈ + 2μ ġ + g = 0).
    pub(crate) fn initial_multipliers(&mut self) -> Result<(), MasterError> {
        let unknowns: Vec<usize> = (0..self.coupling.len())
            .filter(|&m| self.coupling.unknowns[m].initial == InitialMultiplier::Consistent)
            .collect();
        let mu = match self.method {
            crate::Method::Explicit { mu } => Some(mu),
            _ => None,
        };
        let time = self.time();
        if !unknowns.is_empty() {
            // Two Newton iterations: exact after one for linear feedthrough.
            for _ in 0..2 {
                self.feedthrough_newton(&unknowns, mu, time)?;
            }
        }
        self.set_constant_inputs()
    }

    /// One explicit macro step: hold u_N over [T_N, T_{N+1}], then compute
    /// u_{N+1} from the states at T_{N+1} so that μ² g̈ + 2μ ġ + g = 0 there.
    pub(crate) fn explicit_step(&mut self, mu: f64) -> Result<(), MasterError> {
        let clock = Instant::now();
        let (t, h) = (self.time(), self.experiment.step);
        for slave in self.slaves.iter_mut() {
            slave.do_step(t, h)?;
        }
        self.n += 1;
        self.stats.times.predictor += clock.elapsed();
        let clock = Instant::now();
        let all: Vec<usize> = (0..self.coupling.len()).collect();
        for hist in self.history.iter_mut() {
            *hist = [hist[0], hist[0], hist[1]];
        }
        self.feedthrough_newton(&all, Some(mu), self.time())?;
        self.set_constant_inputs()?;
        self.read_accepted()?;
        self.stats.times.solve += clock.elapsed();
        Ok(())
    }

    fn set_constant_inputs(&mut self) -> Result<(), MasterError> {
        for (m, hist) in self.history.iter().enumerate() {
            self.work.polys[m] = Taylor {
                value: hist[0],
                ..Taylor::default()
            };
        }
        self.apply_all(0)
    }

    /// One Newton step on the residual r = g̈ (+ 2ġ/μ + g/μ²) for the
    /// `unknowns` (a subset, each with its own constraint row), with the
    /// sensitivity W = ∂g̈/∂u from perturbed inputs read back without a step.
    fn feedthrough_newton(
        &mut self,
        unknowns: &[usize],
        mu: Option<f64>,
        time: f64,
    ) -> Result<(), MasterError> {
        self.set_constant_inputs()?;
        for (s, slave) in self.slaves.iter_mut().enumerate() {
            slave.read_coupled()?;
            self.work.base[s].copy_from_slice(&slave.coupled_values);
        }
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
                u: &work.u,
                bump: None,
            };
            self.coupling.eval(level, &view, &mut work.rows);
        }
        let r0 = DVector::from_iterator(n, unknowns.iter().map(|&m| self.work.rows[m]));
        let mut w = DMatrix::zeros(n, n);
        for gi in 0..self.groups.len() {
            let members: Vec<usize> = self.groups[gi]
                .iter()
                .copied()
                .filter(|m| unknowns.contains(m))
                .collect();
            if members.is_empty() {
                continue;
            }
            self.work.perturbed.copy_from_slice(&self.work.polys);
            for &m in &members {
                let delta = self.settings.epsilon * self.history[m][0].abs().max(1.0);
                self.work.delta[m] = delta;
                self.work.perturbed[m].value += delta;
            }
            let mut touched = vec![false; self.slaves.len()];
            for &m in &members {
                for &s in &self.owners[m] {
                    touched[s] = true;
                }
            }
            for (s, slave) in self.slaves.iter_mut().enumerate() {
                if touched[s] {
                    slave.apply_inputs(&self.work.perturbed, 0)?;
                    slave.read_coupled()?;
                }
            }
            for &m in &members {
                let mut live = vec![false; self.slaves.len()];
                for &s in &self.owners[m] {
                    live[s] = true;
                }
                let col = unknowns
                    .iter()
                    .position(|&x| x == m)
                    .expect("member of unknowns");
                let work = &mut self.work;
                let view = View {
                    slaves: &self.slaves,
                    base: &work.base,
                    live: Some(&live),
                    u: &work.u,
                    bump: Some((m, work.delta[m])),
                };
                self.coupling.eval(level, &view, &mut work.rows);
                for (row, &r) in unknowns.iter().enumerate() {
                    w[(row, col)] = (work.rows[r] - r0[row]) / work.delta[m];
                }
            }
            for (s, slave) in self.slaves.iter_mut().enumerate() {
                if touched[s] {
                    slave.apply_inputs(&self.work.polys, 0)?;
                }
            }
        }
        self.stats.jacobian_solves += 1;
        let step = solve(&w, &r0, time, "acceleration", self.settings.max_condition)?;
        for (i, &m) in unknowns.iter().enumerate() {
            self.history[m][0] -= step[i];
        }
        Ok(())
    }
}
