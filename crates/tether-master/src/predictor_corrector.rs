//! The semi-implicit predictor/corrector macro step (paper Sect. 3.3,
//! eqs. 55–70 for Method 1 and 71–76 for Method 2).

use std::time::Instant;

use crate::coupling::{copy_small, Compiled, Coupling, RowLevel, View};
use crate::polynomial::{extrapolation, interpolation};
use crate::simulation::{Simulation, Work};
use crate::slave::Slave;
use crate::stats::Lap;
use crate::{MasterError, Method};

impl Simulation {
    /// One macro step T_N → T_{N+1}: save, predict, perturb, solve, correct.
    pub(crate) fn predictor_corrector_step(&mut self) -> Result<(), MasterError> {
        let h = self.experiment.step;
        let t = self.time();
        let k = self.settings.order;
        // Start-up: only N+1 points of history exist at T_N (docs/algorithm.md).
        let degree_pred = k.min(self.n as usize);
        let degree_corr = k.min(self.n as usize + 1);
        let nu = self.coupling.len();
        let trial = self.pool.as_ref().is_some_and(|p| p.timing(self.n));
        let mut lap = Lap::start(trial, self.time_phases);

        // Step 1, predictor (eq. 56–58): extrapolated polynomials.
        for m in 0..nu {
            self.work.polys[m] = extrapolation(&self.history[m], degree_pred, h);
            self.work.u_pred[m] = self.work.polys[m].at(h);
        }
        // Parallel perturbed runs (docs/algorithm.md): the states at T_N go to
        // the workers, which start together with the predictor.
        if self.pool.as_ref().is_some_and(|p| p.deciding(self.n)) {
            self.decide_parallel()?;
        }
        let parallel = self.pool.as_ref().is_some_and(|p| p.active);
        if parallel {
            for slave in self.slaves.iter_mut().filter(|s| s.is_coupled()) {
                slave.save_state()?;
            }
            let pool = self.pool.as_mut().expect("parallel");
            for (gi, group) in self.groups.iter().enumerate() {
                let polys = &mut pool.polys[gi];
                polys.copy_from_slice(&self.work.polys);
                for &m in group {
                    let delta = self.settings.epsilon * self.history[m][0].abs().max(1.0);
                    self.work.delta[m] = delta;
                    polys[m] = interpolation(
                        self.work.u_pred[m] + delta,
                        &self.history[m],
                        degree_corr,
                        h,
                    );
                }
            }
            pool.dispatch(&mut self.slaves, t, h, k)?;
        }
        let calibrating = self.pool.as_ref().is_some_and(|p| p.calibrating(self.n));
        for (s, slave) in self.slaves.iter_mut().enumerate() {
            if slave.is_coupled() && !parallel {
                slave.save_state()?;
            }
            slave.apply_inputs(&self.work.polys)?;
            if calibrating {
                let clock = Instant::now();
                slave.do_step(t, h)?;
                let cost = &mut self.pool.as_mut().expect("calibrating").step_cost[s];
                *cost = (*cost).min(clock.elapsed());
            } else {
                slave.do_step(t, h)?;
            }
            match &self.compiled {
                Some(c) => slave.read_coupled_into(c.part_mut(&mut self.work.flat_base, s))?,
                None => {
                    slave.read_coupled()?;
                    copy_small(&mut self.work.base[s], &slave.coupled_values);
                }
            }
        }
        if let Some(compiled) = &self.compiled {
            compiled.eval(&self.work.flat_base, &mut self.work.g);
        } else {
            let work = &mut self.work;
            let view = View {
                slaves: &self.slaves,
                base: &work.base,
                live: None,
                latest: None,
                u: &work.u_pred,
                bump: None,
            };
            for (&level, g) in self.levels.iter().zip(work.g.chunks_exact_mut(nu)) {
                self.coupling.eval(level, &view, g);
            }
        }
        lap.split_into(&mut self.stats.times.predictor);

        // Step 2a, perturbed predictors (eq. 59–64): finite-difference columns.
        if parallel {
            let pool = self.pool.as_mut().expect("parallel");
            for &(gi, s) in &pool.main_runs {
                let slave = &mut self.slaves[s];
                slave.restore_state()?;
                slave.apply_inputs(&pool.polys[gi])?;
                slave.do_step(t, h)?;
                slave.read_coupled()?;
                pool.values[gi][s].copy_from_slice(&slave.coupled_values);
            }
            pool.collect()?;
            let sim = Columns {
                coupling: &self.coupling,
                levels: &self.levels,
                compiled: self.compiled.as_ref(),
                owners: &self.owners,
                slaves: &self.slaves,
            };
            for (gi, group) in self.groups.iter().enumerate() {
                columns(sim, &mut self.work, group, Some(&pool.values[gi]));
            }
        } else {
            for gi in 0..self.groups.len() {
                copy_small(&mut self.work.perturbed, &self.work.polys);
                for &m in &self.groups[gi] {
                    let delta = self.settings.epsilon * self.history[m][0].abs().max(1.0);
                    self.work.delta[m] = delta;
                    self.work.perturbed[m] = interpolation(
                        self.work.u_pred[m] + delta,
                        &self.history[m],
                        degree_corr,
                        h,
                    );
                }
                for &s in &self.group_slaves[gi] {
                    let slave = &mut self.slaves[s];
                    slave.restore_state()?;
                    slave.apply_inputs(&self.work.perturbed)?;
                    slave.do_step(t, h)?;
                    match &self.compiled {
                        Some(c) => slave.read_coupled_into(c.part_mut(&mut self.work.flat, s))?,
                        None => slave.read_coupled()?,
                    }
                }
                let sim = Columns {
                    coupling: &self.coupling,
                    levels: &self.levels,
                    compiled: self.compiled.as_ref(),
                    owners: &self.owners,
                    slaves: &self.slaves,
                };
                columns(sim, &mut self.work, &self.groups[gi], None);
            }
        }
        lap.split_into(&mut self.stats.times.jacobian);

        // Step 2b, corrected unknowns (eq. 68 or eq. 73–76).
        self.corrected_unknowns(self.time_at(self.n + 1))?;
        lap.split_into(&mut self.stats.times.solve);

        // Step 3, corrector: repeat the step with interpolation polynomials.
        for m in 0..nu {
            let corrected = self.work.corrected[m];
            self.work.polys[m] = interpolation(corrected, &self.history[m], degree_corr, h);
        }
        for slave in self.slaves.iter_mut() {
            if slave.is_coupled() {
                slave.restore_state()?;
                slave.apply_inputs(&self.work.polys)?;
                slave.do_step(t, h)?;
            }
        }
        for (m, hist) in self.history.iter_mut().enumerate() {
            *hist = [self.work.corrected[m], hist[0], hist[1]];
        }
        self.n += 1;
        self.read_accepted()?;
        lap.split_into(&mut self.stats.times.corrector);
        self.step_end = lap.last();
        if let Some(pool) = self.pool.as_mut().filter(|p| p.timing(self.n - 1)) {
            pool.record(self.n - 1, lap.total());
            if let Some(keep) = pool.keep(self.n) {
                self.stats.parallel = pool.info;
                if !keep {
                    // Join the workers and free the copies.
                    pool.fold_counters(&mut self.slaves);
                    self.pool = None;
                }
            }
        }
        Ok(())
    }

    /// "auto": decide whether the perturbed runs go parallel (at T_N, before
    /// the states are saved: the hand-off is timed with the previous ones).
    fn decide_parallel(&mut self) -> Result<(), MasterError> {
        let pool = self.pool.as_mut().expect("deciding");
        let pays = pool.decide(&mut self.slaves)?;
        self.stats.parallel = pool.info;
        if !pays {
            // Join the workers and free the copies.
            self.pool = None;
        }
        Ok(())
    }

    /// The corrected unknowns into `work.corrected` (buffers reused, no allocation).
    fn corrected_unknowns(&mut self, time: f64) -> Result<(), MasterError> {
        let limit = self.settings.max_condition;
        let work = &mut self.work;
        match self.method {
            Method::Baumgarte { beta, gamma } => {
                // Eq. 68: u = u^p − (G^B)⁻¹ g^B with g^B = g + β ġ + γ g̈;
                // port and coupling-variable rows are not stabilised.
                let (a, b) = work.solver.system(work.u_pred.len());
                work.jac.baumgarte(
                    &work.g,
                    self.velocity_level.map(|v| (v, beta)),
                    self.acceleration_level.map(|acc| (acc, gamma)),
                    &self.algebraic_rows,
                    a,
                    b,
                );
                let level = if self.levels.len() == 1 {
                    "position"
                } else {
                    "baumgarte"
                };
                self.stats.jacobian_solves += 1;
                let step = work.solver.solve(time, level, limit)?;
                for ((c, p), s) in work.corrected.iter_mut().zip(&work.u_pred).zip(step) {
                    *c = p - s;
                }
            }
            Method::Weighted { a, b } => {
                // Eq. 73–76: solve each level, then average with weights 1, a, b.
                work.corrected.fill(0.0);
                let mut total = 0.0;
                for (l, &kind) in self.levels.iter().enumerate() {
                    let (weight, name) = match kind {
                        RowLevel::Velocity => (a, "velocity"),
                        RowLevel::Acceleration => (b, "acceleration"),
                        _ => (1.0, "position"),
                    };
                    self.stats.jacobian_solves += 1;
                    work.solver.load_level(&work.jac, &work.g, l);
                    let step = work.solver.solve(time, name, limit)?;
                    for ((c, p), s) in work.corrected.iter_mut().zip(&work.u_pred).zip(step) {
                        *c += weight * (p - s);
                    }
                    total += weight;
                }
                for c in work.corrected.iter_mut() {
                    *c /= total;
                }
            }
            Method::Explicit { .. } => unreachable!("the explicit method has its own step"),
        }
        Ok(())
    }
}

/// Finite-difference columns of the unknowns in `group` from one perturbed run:
/// its outputs are the slaves' latest values (compiled rows: `work.flat`), or
/// `latest` (parallel runs).
fn columns(sim: Columns, work: &mut Work, group: &[usize], latest: Option<&[Vec<f64>]>) {
    let nu = sim.coupling.len();
    for &m in group {
        let delta = work.delta[m];
        if let Some(compiled) = sim.compiled {
            // The instances m drives at their latest values (in `flat`, or
            // `latest` for parallel runs), the others at the predictor's.
            let owners = &sim.owners[m];
            let flat = if latest.is_none() && owners.len() == sim.slaves.len() {
                &work.flat
            } else {
                work.mixed.copy_from_slice(&work.flat_base);
                for &s in owners {
                    let values = match latest {
                        Some(latest) => &latest[s],
                        None => compiled.part(&work.flat, s),
                    };
                    copy_small(compiled.part_mut(&mut work.mixed, s), values);
                }
                &work.mixed
            };
            compiled.eval(flat, &mut work.rows);
        } else {
            // Only the instances m drives count as perturbed for column m.
            work.live.fill(false);
            for &s in &sim.owners[m] {
                work.live[s] = true;
            }
            let view = View {
                slaves: sim.slaves,
                base: &work.base,
                live: Some(&work.live),
                latest,
                u: &work.u_pred,
                bump: Some((m, delta)),
            };
            for (&level, rows) in sim.levels.iter().zip(work.rows.chunks_exact_mut(nu)) {
                sim.coupling.eval(level, &view, rows);
            }
        }
        let column = work.jac.column_mut(m);
        for ((j, row), g) in column.iter_mut().zip(&work.rows).zip(&work.g) {
            *j = (row - g) / delta;
        }
    }
}

/// What [`columns`] reads of the simulation.
#[derive(Clone, Copy)]
struct Columns<'a> {
    coupling: &'a Coupling,
    levels: &'a [RowLevel],
    compiled: Option<&'a Compiled>,
    owners: &'a [Vec<usize>],
    slaves: &'a [Slave],
}
