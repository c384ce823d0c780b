//! A coupled run: instantiate the FMUs, resolve the coupling, pick consistent
//! initial multipliers, then march over the macro grid `T_n = T_0 + n·H`.

use std::cmp::Ordering::{Equal, Less};
use std::time::Instant;

use crate::coupling::{self, copy_small, Compiled, Coupling, RowLevel, View};
use crate::explicit::Feedthrough;
use crate::observer::{Observer, Sample};
use crate::parallel::Pool;
use crate::polynomial::Taylor;
use crate::slave::Slave;
use crate::solve::{Jacobians, Solver};
use crate::spec::{CouplingSettings, Experiment, InitialMultiplier, SystemSpec};
use crate::stats::RunStats;
use crate::{MasterError, Method};

/// A coupled system, ready to run.
pub struct Simulation {
    pub(crate) experiment: Experiment,
    pub(crate) method: Method,
    pub(crate) settings: CouplingSettings,
    pub(crate) slaves: Vec<Slave>,
    pub(crate) coupling: Coupling,
    /// For each unknown, the slaves whose inputs it drives.
    pub(crate) owners: Vec<Vec<usize>>,
    /// Unknowns whose perturbations share one run.
    pub(crate) groups: Vec<Vec<usize>>,
    /// Per group, the slaves its perturbed run steps (those its unknowns drive).
    pub(crate) group_slaves: Vec<Vec<usize>>,
    /// Levels the method evaluates (position always first).
    pub(crate) levels: Vec<RowLevel>,
    /// Indices of the velocity and acceleration levels in `levels`, if evaluated.
    pub(crate) velocity_level: Option<usize>,
    pub(crate) acceleration_level: Option<usize>,
    /// Rows that are the same on every level (coupling variables and ports).
    pub(crate) algebraic_rows: Vec<usize>,
    /// The rows compiled for `levels`, when they are all linear constraints.
    pub(crate) compiled: Option<Compiled>,
    /// Per unknown: `[u_N, u_{N-1}, u_{N-2}]`.
    pub(crate) history: Vec<[f64; 3]>,
    /// Current macro point index N.
    pub(crate) n: u64,
    pub(crate) work: Work,
    columns: Vec<String>,
    row: Vec<f64>,
    limits: Vec<f64>,
    steps: u64,
    pub(crate) stats: RunStats,
    /// Whether the phases of each macro step are timed (off by default).
    pub(crate) time_phases: bool,
    /// The clock reading that ended the last macro step's phases, for the
    /// recording phase that follows it in [`Simulation::run`].
    pub(crate) step_end: Option<Instant>,
    /// Workers for parallel perturbed runs (docs/algorithm.md), if any.
    pub(crate) pool: Option<Pool>,
}

/// Buffers reused by every macro step.
pub(crate) struct Work {
    /// Coupled output values of each slave after the predictor (or base point).
    pub base: Vec<Vec<f64>>,
    /// The same laid end to end, for compiled rows (empty otherwise).
    pub flat_base: Vec<f64>,
    /// Latest coupled outputs laid end to end (compiled rows): of the last
    /// perturbed run, or of the accepted point.
    pub flat: Vec<f64>,
    /// `flat` for the instances an unknown drives, `flat_base` for the others.
    pub mixed: Vec<f64>,
    /// Which slaves' latest values count as perturbed.
    pub live: Vec<bool>,
    pub polys: Vec<Taylor>,
    pub perturbed: Vec<Taylor>,
    pub u_pred: Vec<f64>,
    pub delta: Vec<f64>,
    /// Condition values `g`, `ġ`, `g̈` at the predictor: every row of each
    /// level in `levels`, level after level.
    pub g: Vec<f64>,
    /// Interface Jacobians ∂g/∂u, ∂ġ/∂u, ∂g̈/∂u of the levels in `levels`.
    pub jac: Jacobians,
    /// Row values of one perturbed evaluation, laid out like `g`.
    pub rows: Vec<f64>,
    /// Current unknowns u_N.
    pub u: Vec<f64>,
    /// Corrected unknowns of the current step.
    pub corrected: Vec<f64>,
    /// LU workspace for the linear solves.
    pub solver: Solver,
    /// Buffers of the feedthrough Newton step (initial and explicit multipliers).
    pub feedthrough: Feedthrough,
}

impl Simulation {
    /// Build a run from a system description (paths already resolved).
    pub fn new(spec: &SystemSpec) -> Result<Simulation, MasterError> {
        let clock = Instant::now();
        spec.validate()?;
        let method = spec.method;
        let settings = spec.coupling;
        if matches!(method, Method::Explicit { .. }) && settings.order != 0 {
            return Err(MasterError::InvalidParameter {
                name: "order".into(),
                value: settings.order as f64,
                expected: "0: the explicit method holds the multipliers constant over a step"
                    .into(),
            });
        }
        let mut opened = Vec::new();
        let mut slaves = spec
            .instances
            .iter()
            .map(|instance| Slave::instantiate(instance, &mut opened))
            .collect::<Result<Vec<_>, _>>()?;
        let coupling = Coupling::build(spec, &mut slaves, &method, settings.order)?;
        let nu = coupling.len();
        let mut owners = vec![Vec::new(); nu];
        for (s, slave) in slaves.iter().enumerate() {
            for input in &slave.inputs {
                for &(m, _) in &input.terms {
                    if !owners[m].contains(&s) {
                        owners[m].push(s);
                    }
                }
            }
        }
        let groups = coupling::perturbation_groups(&owners);
        let group_slaves = groups
            .iter()
            .map(|group| {
                (0..slaves.len())
                    .filter(|s| group.iter().any(|&m| owners[m].contains(s)))
                    .collect()
            })
            .collect();
        let mut levels = vec![RowLevel::Position];
        if method.needs_velocity() {
            levels.push(RowLevel::Velocity);
        }
        if method.needs_acceleration() {
            levels.push(RowLevel::Acceleration);
        }
        let compiled = Compiled::new(&coupling, &levels, &slaves);
        let flat_len = compiled.as_ref().map_or(0, |c| c.len);
        let exp = spec.experiment;
        let stop = exp.start + spec.macro_steps() as f64 * exp.step;
        for slave in &mut slaves {
            slave.initialize(exp.start, stop, exp.tolerance)?;
        }
        let pool = if method.needs_rollback() {
            Pool::new(
                settings.parallel,
                &slaves,
                &spec.instances,
                &groups,
                &owners,
                (exp.start, stop, exp.tolerance),
            )?
        } else {
            None
        };
        let mut columns = Vec::new();
        for slave in &slaves {
            columns.extend(slave.recorded_names().iter().cloned());
        }
        columns.extend(coupling.unknowns.iter().map(|u| u.name.clone()));
        columns.extend(coupling.unknowns.iter().filter_map(|u| u.residual.clone()));
        let work = Work {
            base: slaves
                .iter()
                .map(|s| vec![0.0; s.coupled_values.len()])
                .collect(),
            flat_base: vec![0.0; flat_len],
            flat: vec![0.0; flat_len],
            mixed: vec![0.0; flat_len],
            live: vec![false; slaves.len()],
            polys: vec![Taylor::default(); nu],
            perturbed: vec![Taylor::default(); nu],
            u_pred: vec![0.0; nu],
            delta: vec![0.0; nu],
            g: vec![0.0; levels.len() * nu],
            jac: Jacobians::new(nu, levels.len()),
            rows: vec![0.0; levels.len() * nu],
            u: vec![0.0; nu],
            corrected: vec![0.0; nu],
            solver: Solver::default(),
            feedthrough: Feedthrough::default(),
        };
        let algebraic_rows = (0..nu)
            .filter(|&r| coupling.unknowns[r].is_algebraic())
            .collect();
        let mut sim = Simulation {
            experiment: exp,
            method,
            settings,
            history: coupling
                .unknowns
                .iter()
                .map(|c| match c.initial {
                    InitialMultiplier::Value(v) => [v; 3],
                    InitialMultiplier::Consistent => [0.0; 3],
                })
                .collect(),
            slaves,
            coupling,
            owners,
            groups,
            group_slaves,
            velocity_level: levels.iter().position(|&l| l == RowLevel::Velocity),
            acceleration_level: levels.iter().position(|&l| l == RowLevel::Acceleration),
            algebraic_rows,
            levels,
            compiled,
            n: 0,
            work,
            row: vec![0.0; columns.len()],
            limits: vec![f64::INFINITY; columns.len()],
            columns,
            steps: spec.macro_steps(),
            stats: RunStats::default(),
            time_phases: false,
            step_end: None,
            pool,
        };
        sim.initial_multipliers()?;
        sim.read_accepted()?;
        sim.fill_row();
        let factor = sim.settings.divergence_factor;
        // Finite limits (the factor is finite, > 1), so that ±∞ is always
        // beyond them in check_divergence.
        sim.limits = sim
            .row
            .iter()
            .map(|v| (factor * v.abs().max(1.0)).min(f64::MAX))
            .collect();
        sim.check_divergence()?;
        sim.stats.times.setup = clock.elapsed();
        Ok(sim)
    }

    /// Column names after `time`: every Real output as `<instance>.<variable>`,
    /// then `<constraint>.lambda`, then `<constraint>.g`.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// The current macro time T_N = T_0 + N·H.
    pub fn time(&self) -> f64 {
        self.time_at(self.n)
    }

    pub(crate) fn time_at(&self, n: u64) -> f64 {
        // Through i64: one conversion instruction instead of the unsigned
        // sequence, and the same value below 2^63 steps.
        self.experiment.start + n as i64 as f64 * self.experiment.step
    }

    /// Number of macro steps the experiment asks for.
    pub fn total_steps(&self) -> u64 {
        self.steps
    }

    /// The current coupling unknowns u_N, in column order (multipliers of
    /// constraints and joints, coupling variables, force ports).
    pub fn unknowns(&self) -> Vec<f64> {
        self.history.iter().map(|h| h[0]).collect()
    }

    /// Time the phases of every macro step from now on (predictor, Jacobian,
    /// solve, corrector, recording; see [`crate::PhaseTimes`]). Off by default:
    /// it reads the clock five times a macro step, 30–50 ns each on the
    /// machine of docs/performance.md, which is a noticeable part of a step of
    /// cheap FMUs. The setup and the whole run are always timed.
    pub fn time_phases(&mut self, on: bool) {
        self.time_phases = on;
        self.step_end = None;
    }

    /// Counters so far.
    pub fn stats(&self) -> RunStats {
        let mut stats = self.stats.clone();
        stats.times.measured = self.time_phases;
        stats.instances = self.slaves.iter().map(|s| s.counters().clone()).collect();
        if let Some(pool) = &self.pool {
            for (s, counters) in stats.instances.iter_mut().enumerate() {
                pool.add_counters(s, counters);
            }
            stats.parallel = pool.info;
        }
        stats
    }

    /// Advance one macro step with the configured method.
    pub fn step(&mut self) -> Result<(), MasterError> {
        match self.method {
            Method::Explicit { mu } => self.explicit_step(mu)?,
            _ => self.predictor_corrector_step()?,
        }
        self.stats.macro_steps += 1;
        self.fill_row();
        self.check_divergence()
    }

    /// Run to the stop time, feeding every accepted point to the observers.
    /// On failure the observers are finished with the error message (results
    /// up to the last accepted step are kept) and the error is returned.
    pub fn run(
        &mut self,
        observers: &mut [&mut dyn Observer],
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<RunStats, MasterError> {
        let clock = Instant::now();
        self.step_end = None;
        for o in observers.iter_mut() {
            o.start(&self.columns)?;
        }
        self.notify(observers)?;
        let outcome = (|| {
            while self.n < self.steps {
                if let Some(reason) = observers.iter_mut().find_map(|o| o.interrupt()) {
                    let time = self.time();
                    return Err(MasterError::Interrupted { time, reason });
                }
                self.step()?;
                self.notify(observers)?;
                progress(self.n, self.steps);
            }
            Ok(())
        })();
        let message = outcome.as_ref().err().map(|e: &MasterError| e.to_string());
        // Every observer is finished, even after another one failed; the
        // run's own error comes first, then the first observer's.
        let mut finished = Ok(());
        for o in observers.iter_mut() {
            let result = o.finish(message.as_deref());
            if finished.is_ok() {
                finished = result;
            }
        }
        self.stats.wall = clock.elapsed() + self.stats.times.setup;
        outcome?;
        finished?;
        Ok(self.stats())
    }

    fn notify(&mut self, observers: &mut [&mut dyn Observer]) -> Result<(), MasterError> {
        if observers.is_empty() {
            return Ok(());
        }
        // The recording phase starts where the step's last phase ended (it
        // includes assembling and checking the row): one clock read fewer.
        let clock = self
            .step_end
            .take()
            .or_else(|| self.time_phases.then(Instant::now));
        let sample = Sample {
            step: self.n,
            time: self.time(),
            values: &self.row,
        };
        for o in observers.iter_mut() {
            o.sample(sample)?;
        }
        if let Some(clock) = clock {
            self.stats.times.recording += clock.elapsed();
        }
        Ok(())
    }

    /// Read coupled and recorded outputs of every slave at an accepted point
    /// (the coupled ones into `work.flat` for compiled rows).
    pub(crate) fn read_accepted(&mut self) -> Result<(), MasterError> {
        for (s, slave) in self.slaves.iter_mut().enumerate() {
            match &self.compiled {
                Some(c) => slave.read_coupled_into(c.part_mut(&mut self.work.flat, s))?,
                None => slave.read_coupled()?,
            }
            slave.read_recorded()?;
        }
        Ok(())
    }

    fn fill_row(&mut self) {
        let mut i = 0;
        for slave in &self.slaves {
            let values = slave.recorded_values();
            copy_small(&mut self.row[i..i + values.len()], values);
            i += values.len();
        }
        let unknowns = &mut self.row[i..i + self.history.len()];
        for (value, h) in unknowns.iter_mut().zip(&self.history) {
            *value = h[0];
        }
        i += self.history.len();
        match &self.compiled {
            // Every row is a constraint with a residual column; the accepted
            // coupled outputs are in `flat`.
            Some(compiled) => compiled.eval(&self.work.flat, &mut self.row[i..]),
            None => self.fill_residuals(i),
        }
    }

    /// The residual columns from `i` on, from the rows' own evaluation.
    #[inline(never)]
    fn fill_residuals(&mut self, mut i: usize) {
        for (m, h) in self.history.iter().enumerate() {
            self.work.u[m] = h[0];
        }
        let view = View {
            slaves: &self.slaves,
            base: &self.work.base,
            live: None,
            latest: None,
            u: &self.work.u,
            bump: None,
        };
        for residual in self.coupling.residuals(&view) {
            self.row[i] = residual;
            i += 1;
        }
    }

    #[inline]
    fn check_divergence(&self) -> Result<(), MasterError> {
        // One branch-free pass in the common case; the culprit is searched
        // only when there is one.
        let any = self
            .row
            .iter()
            .zip(&self.limits)
            .fold(false, |any, (&v, &limit)| any | beyond(v, limit));
        if !any {
            return Ok(());
        }
        self.diverged(self.time()).map_or(Ok(()), Err)
    }

    /// The first value beyond its limit, as an error.
    #[cold]
    #[inline(never)]
    fn diverged(&self, time: f64) -> Option<MasterError> {
        let mut values = self.row.iter().zip(&self.limits).enumerate();
        let (i, (&value, &limit)) = values.find(|(_, (&v, &limit))| beyond(v, limit))?;
        Some(MasterError::Diverged {
            time,
            quantity: self.columns[i].clone(),
            value,
            limit,
        })
    }

    /// Set every coupled slave's inputs from `work.polys`.
    pub(crate) fn apply_all(&mut self) -> Result<(), MasterError> {
        for slave in &mut self.slaves {
            slave.apply_inputs(&self.work.polys)?;
        }
        Ok(())
    }
}

/// Whether `value` is NaN, infinite or larger in magnitude than the finite
/// `limit` (±∞ is larger than any finite limit).
#[inline]
fn beyond(value: f64, limit: f64) -> bool {
    // One comparison: NaN is not within the limit (it compares as None).
    !matches!(value.abs().partial_cmp(&limit), Some(Less | Equal))
}

#[cfg(test)]
mod tests {
    use super::beyond;

    #[test]
    fn divergence_catches_nan_infinities_and_large_values() {
        let limit = 1e6;
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1.1e6, -1.1e6] {
            assert!(beyond(v, limit), "{v}");
        }
        for v in [0.0, -0.0, 1e6, -1e6, 5e-324, 123.0] {
            assert!(!beyond(v, limit), "{v}");
        }
        assert!(beyond(f64::INFINITY, f64::MAX));
    }
}
