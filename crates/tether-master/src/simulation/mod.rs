//! A coupled run: instantiate the FMUs, resolve the coupling, pick consistent
//! initial multipliers, then march over the macro grid `T_n = T_0 + n·H` with
//! the configured method's [`MacroStep`], handing every accepted point to the
//! observers and checking it for divergence.

use std::time::Instant;

mod export;
mod grid;
mod health;
mod row;
mod state;
mod tune;

pub use export::{ExportKind, ExportVariable};
pub use state::{MasterState, SystemState};

use crate::algorithm::explicit::Explicit;
use crate::algorithm::predictor_corrector::PredictorCorrector;
use crate::algorithm::step::{MacroStep, StepAt};
use crate::coupling::rows::RowLevel;
use crate::observer::Observer;
use crate::signals::Signals;
use crate::slave::{Run, Slave};
use crate::spec::{CheckRollback, SystemSpec};
use crate::stats::{Lap, RunStats, Termination};
use crate::step_control::Controller;
use crate::system::feedthrough::Feedthrough;
use crate::system::System;
use crate::{MasterError, Method};
use grid::Grid;
use health::Health;
use row::Row;

/// A coupled system, ready to run: the instances and the coupling, the
/// method's macro step, the signal connections, the time grid, the recorded
/// row, the run's health, its counters and the phase timing.
pub struct Simulation {
    system: System,
    /// The coupling method's macro step.
    method: Box<dyn MacroStep>,
    /// Signal connections, passed around the method's step.
    signals: Signals,
    /// The time grid: uniform or adaptive.
    grid: Grid,
    /// The current point's values and what of them is recorded.
    row: Row,
    /// Divergence, residuals, the failure.
    health: Health,
    stats: RunStats,
    /// Lines for the user before the run (the direct-feedthrough loops).
    notes: Vec<String>,
    /// Warnings for the user before the run: the parameters set with
    /// `initial="exact"` that an FMU changed in its initialization.
    warnings: Vec<String>,
    /// Whether the phases of each macro step are timed (off by default),
    /// and the clock reading that ended the last macro step's phases, for
    /// the recording phase that follows it in [`Simulation::run`].
    timing: Timing,
    /// `check_rollback = "periodic"` (and `"every_step"`): the step size H of
    /// the rollback self-check repeated every [`RECHECK_EVERY`] accepted macro
    /// steps and after every rejected step.
    recheck: Option<f64>,
    /// The time of the last rollback self-check that passed: rows after it
    /// are named in the error of a check that fails (docs/reliability.md).
    verified: f64,
    /// The level the multipliers are consistent on at a point (g̈ = 0, or
    /// the explicit method's stabilised condition).
    level: RowLevel,
}

/// With `check_rollback = "periodic"` (the default), the rollback self-check
/// is repeated from the accepted point every this many macro steps (and after
/// every rejected adaptive step): per coupled instance two `fmi2DoStep` more
/// every 100 macro steps, where the predictor/corrector makes at least 3 a
/// step (docs/reliability.md).
pub const RECHECK_EVERY: u64 = 100;

/// Phase timing of the macro steps.
#[derive(Default)]
struct Timing {
    on: bool,
    step_end: Option<Instant>,
}

impl Simulation {
    /// Build a run from a system description (paths already resolved).
    pub fn new(spec: &SystemSpec) -> Result<Simulation, MasterError> {
        let clock = Instant::now();
        spec.validate()?;
        let method = spec.method;
        let settings = spec.coupling;
        let exp = spec.experiment;
        let steps = spec.macro_steps();
        // Adaptive steps end exactly at `stop`, fixed ones on the grid.
        let stop = if spec.step_control.is_some() {
            exp.stop
        } else {
            exp.start + steps as f64 * exp.step
        };
        let mut system = System::new(spec, &method, stop)?;
        let mut signals = Signals::build(spec, &mut system.slaves)?;
        // The summary names the FMI 3.0 functions for the types set.
        for (s, slave) in system.slaves.iter_mut().enumerate() {
            let mut set: Vec<u32> = slave.coupled.inputs.iter().map(|i| i.vr).collect();
            set.extend(signals.receivers(s));
            let md = slave.fmu.model_description();
            slave.counters.functions = crate::stats::CallNames {
                model_exchange: slave.model_exchange,
                ..crate::stats::CallNames::of(md, &set)
            };
        }
        let mut notes: Vec<String> = system
            .slaves
            .iter()
            .filter_map(|s| s.interface_note.clone())
            .collect();
        notes.extend(signals.loop_notes(&system.slaves));
        for (k, connections) in signals.loop_connections().iter().enumerate() {
            log::info!("direct-feedthrough loop {}: {connections}", k + 1);
        }
        // A loop's values at T_0 are solved in initialization mode, where
        // FMI 2.0 lets a master set inputs and read outputs.
        if signals.has_loops() {
            signals.initialize(&mut system.slaves)?;
        }
        system.exit_initialization()?;
        let mut warnings = Vec::new();
        for (k, slave) in system.slaves.iter_mut().enumerate() {
            warnings.extend(slave.changed_parameters(&signals.receivers(k).collect::<Vec<_>>())?);
        }
        let (step, initial_level): (Box<dyn MacroStep>, _) = match method {
            Method::Explicit { mu } => (
                Box::new(Explicit::new(&system, mu)),
                RowLevel::Stabilised(mu),
            ),
            _ => {
                let pc = PredictorCorrector::new(&system, method, &settings);
                (Box::new(pc), RowLevel::Acceleration)
            }
        };
        let mut step = step;
        let adaptive = match &spec.step_control {
            None => None,
            Some(control) => {
                if system.coupling.len() == 0 {
                    return Err(MasterError::InvalidParameter {
                        name: "step_control".into(),
                        value: control.rtol,
                        expected: "a system with constraints, joints or coupling variables: \
                                   the error estimate is on the coupled quantities"
                            .into(),
                    });
                }
                // A rejected step rolls back every instance, signal-only
                // ones too: each must restore its state and vary its step.
                let lacking: Vec<_> = system
                    .slaves
                    .iter()
                    .filter_map(|s| s.cannot_vary_steps().map(|c| (s, c)))
                    .collect();
                if let Some(&(slave, capability)) = lacking.first() {
                    let others: Vec<_> = lacking[1..]
                        .iter()
                        .map(|(s, c)| format!("'{}' ({c})", s.name))
                        .collect();
                    let role = if slave.is_coupled() {
                        ""
                    } else {
                        "; a rejected step rolls back signal-only instances too"
                    };
                    let also = if others.is_empty() {
                        String::new()
                    } else {
                        format!("; also lacking it: {}", others.join(", "))
                    };
                    return Err(MasterError::MissingCapability {
                        instance: slave.name.clone(),
                        model: slave.model_name.clone(),
                        capability,
                        needed_by: format!("adaptive macro steps ([step_control]{role}{also})"),
                    });
                }
                let limits = control.limits(exp.start, exp.stop, exp.step)?;
                Some((control, limits))
            }
        };
        signals.check_rollback(&system.slaves)?;
        let mut stats = RunStats {
            signals: signals.initial_stats(),
            ..RunStats::default()
        };
        // Signals at T_0 before and after the consistent multipliers, which
        // may depend on signal inputs and change outputs that senders read.
        signals.initialize(&mut system.slaves)?;
        Feedthrough::new(&system).initial(&mut system, initial_level, exp.start, &mut stats)?;
        signals.initialize(&mut system.slaves)?;
        system.read_accepted(Run::Initial)?;
        for (slave, out) in system.slaves.iter_mut().zip(&system.outputs) {
            slave.set_divergence_limits(settings.divergence_factor, out);
        }
        if method.needs_rollback() && settings.check_rollback != CheckRollback::Off {
            system.check_rollback(exp.start, exp.step)?;
        }
        // Fixed steps record every `every`-th point; adaptive ones land on
        // the output grid, when there is one, and record exactly its points.
        let grid = match adaptive {
            None => {
                let every = spec.output.every(exp.step)?;
                stats.output_interval = every as f64 * exp.step;
                Grid::uniform(exp.start, exp.step, steps, every, settings.order)
            }
            Some((control, limits)) => {
                step.control_steps(&system, control);
                signals.roll_back_with_retries();
                let output = match spec.output.interval {
                    Some(dt) if !(dt.is_finite() && dt > 0.0) => {
                        return Err(MasterError::InvalidParameter {
                            name: "output interval".into(),
                            value: dt,
                            expected: "a positive time".into(),
                        })
                    }
                    output => output,
                };
                stats.output_interval = output.unwrap_or(0.0);
                let h = limits.h_initial.min(limits.h_max).max(limits.h_min);
                let controller = Controller::new(limits, settings.order);
                Grid::adaptive(
                    controller,
                    (exp.start, exp.stop, exp.step, steps),
                    h,
                    output,
                    settings.order,
                )
            }
        };
        let mut columns = Vec::new();
        for slave in &system.slaves {
            columns.extend(slave.recorded_names().iter().cloned());
        }
        let unknowns = &system.coupling.unknowns;
        columns.extend(unknowns.iter().map(|u| u.name.clone()));
        let first_residual = columns.len();
        columns.extend(unknowns.iter().filter_map(|u| u.residual.clone()));
        let keep = spec.output.select(&columns)?;
        let texts = (system.slaves.iter()).any(|s| !s.recorded_strings().is_empty());
        let mut row = Row::new(columns, keep, texts);
        row.fill(&system);
        let mut health = Health::new(
            row.all_values(),
            first_residual,
            settings.divergence_factor,
            settings.residual_warning,
            settings.residual_limit.0,
        );
        health.check(row.all_values(), row.all_columns(), exp.start)?;
        stats.method = method;
        stats.order = settings.order;
        stats.start = exp.start;
        stats.step = exp.step;
        stats.stop = stop;
        stats.times.setup = clock.elapsed();
        Ok(Simulation {
            system,
            method: step,
            signals,
            grid,
            row,
            health,
            stats,
            notes,
            warnings,
            timing: Timing::default(),
            recheck: (method.needs_rollback()
                && matches!(
                    settings.check_rollback,
                    CheckRollback::Periodic | CheckRollback::EveryStep
                ))
            .then_some(exp.step),
            verified: exp.start,
            level: initial_level,
        })
    }

    /// Lines for the user before the run, each a note (not a warning): the
    /// instances `fmi_type = "auto"` ran through model exchange, and why; the
    /// direct-feedthrough loops closed only at macro points.
    pub fn notes(&self) -> &[String] {
        &self.notes
    }

    /// Warnings for the user before the run, each one line (the CLI prints
    /// them as `warning: …`): every parameter set with `initial="exact"` that
    /// an FMU changed in its initialization, with the value set and the
    /// value read.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Number of perturbed runs per macro step of the predictor/corrector
    /// methods: the groups of unknowns that drive disjoint instances.
    pub fn perturbation_groups(&self) -> usize {
        self.system.groups.len()
    }

    /// Column names after `time`, as recorded: every output (Real, then
    /// Integer, then Boolean) as `<instance>.<variable>`, then
    /// `<constraint>.lambda`, then `<constraint>.g`; only those selected by
    /// `[output] variables` when it is given.
    pub fn columns(&self) -> &[String] {
        self.row.columns()
    }

    /// The recorded values of the current point (the last accepted one), in
    /// the order of [`Simulation::columns`]: what observers receive as
    /// [`Sample::values`](crate::Sample::values).
    pub fn values(&self) -> &[f64] {
        self.row.values()
    }

    /// The String values of the current point (String outputs), by index in
    /// [`values`](Self::values), which holds 0 there: what observers
    /// receive as [`Sample::strings`](crate::Sample::strings).
    pub fn strings(&self) -> &[(usize, String)] {
        self.row.strings()
    }

    /// The units the FMUs declare for the recorded outputs among
    /// [`columns`](Self::columns): `(column, unit)` pairs.
    pub fn units(&self) -> Vec<(String, String)> {
        let mut units = Vec::new();
        let columns = self.row.columns();
        for slave in &self.system.slaves {
            let md = slave.fmu.model_description();
            for column in slave.recorded_names() {
                if !columns.contains(column) {
                    continue;
                }
                let variable = &column[slave.name.len() + 1..];
                let unit = md
                    .variable(variable)
                    .ok()
                    .and_then(|v| v.real())
                    .and_then(|r| r.attributes.unit.clone());
                if let Some(unit) = unit {
                    units.push((column.clone(), unit));
                }
            }
        }
        units
    }

    /// The current macro time T_N (T_0 + N·H on the uniform grid).
    pub fn time(&self) -> f64 {
        self.grid.time()
    }

    /// Whether the run has reached its last point.
    pub fn finished(&self) -> bool {
        self.grid.finished()
    }

    /// The time of the last point handed to the observers by
    /// [`run`](Self::run) (the last row of the results), if any. After a
    /// failure it is the time up to which results are kept; the failing
    /// step's time may be later.
    pub fn last_recorded_time(&self) -> Option<f64> {
        self.row.last_recorded()
    }

    /// Number of macro steps the experiment asks for (with adaptive steps:
    /// how many steps of `[experiment] step` the run spans, for progress).
    pub fn total_steps(&self) -> u64 {
        self.grid.total_steps()
    }

    /// The current coupling unknowns u_N, in column order (multipliers of
    /// constraints and joints, coupling variables, force ports).
    pub fn unknowns(&self) -> Vec<f64> {
        self.system.history.iter().map(|h| h[0]).collect()
    }

    /// Time the phases of every macro step from now on (predictor, Jacobian,
    /// solve, corrector, recording; see [`crate::PhaseTimes`]). Off by default:
    /// it reads the clock five times a macro step, 30–50 ns each on the
    /// machine of docs/performance.md, which is a noticeable part of a step of
    /// cheap FMUs. The setup and the whole run are always timed.
    pub fn time_phases(&mut self, on: bool) {
        self.timing = Timing { on, step_end: None };
    }

    /// Counters so far, and how the run ended (or that it is still running).
    pub fn stats(&self) -> RunStats {
        let mut stats = self.stats.clone();
        stats.times.measured = self.timing.on;
        stats.end_time = self.row.last_recorded();
        let failure = self.health.failure();
        stats.completed = failure.is_none() && (self.finished() || stats.termination.is_some());
        stats.stop_reason = match (failure, &stats.termination) {
            (Some(e), _) => e.message.clone(),
            (None, Some(end)) => format!(
                "instance '{}' requested the end of the simulation at t = {}",
                end.instance,
                crate::Time(end.requested_at)
            ),
            (None, None) if stats.completed => "completed".into(),
            (None, None) => "running".into(),
        };
        stats.residuals = self.health.residuals(self.row.all_columns()).collect();
        stats.residual_warning = self.health.residual_warning();
        stats.residual_limit = self.health.residual_limit();
        stats.failure = failure.cloned();
        stats.adaptive = self.grid.adaptive_stats();
        stats.instances = self.system.slaves.iter().map(Slave::counters).collect();
        self.system.runs.report(&mut stats);
        stats
    }

    /// Advance one macro step with the configured method (with adaptive
    /// steps: one accepted step, after as many rejected tries as it takes).
    pub fn step(&mut self) -> Result<(), MasterError> {
        self.step_limited(None)
    }

    /// [`step`](Self::step), and with adaptive steps (`[step_control]`) the
    /// step ends at `limit` when that comes before the next point of the
    /// output grid (within 1e-9 of the remaining span, it is that point):
    /// an importer's communication points are reached exactly. On the
    /// uniform grid the same as `step`.
    pub fn step_until(&mut self, limit: f64) -> Result<(), MasterError> {
        self.step_limited(Some(limit))
    }

    fn step_limited(&mut self, limit: Option<f64>) -> Result<(), MasterError> {
        let n = self.stats.macro_steps;
        if let Some(h) = self
            .recheck
            .filter(|_| n > 0 && n.is_multiple_of(RECHECK_EVERY))
        {
            // The rollback self-check again, from the accepted point: a
            // restore that stopped being exact after the first check.
            let (now, verified) = (self.grid.time(), self.verified);
            self.system
                .check_rollback(now, h)
                .map_err(|e| e.after_check_at(verified))
                .inspect_err(|e| self.health.fail(e))?;
            self.verified = now;
        }
        let mut lap = Lap::start(self.timing.on);
        let (signals, method, system) = (&mut self.signals, &mut self.method, &mut self.system);
        let stats = &mut self.stats;
        let recheck = self.recheck.is_some();
        let verified = &mut self.verified;
        let stepped = self.grid.advance(limit, |at| {
            let error = step_at(
                (&mut *signals, &mut *method, &mut *system),
                at,
                stats,
                &mut lap,
            )?;
            if recheck && error.is_some_and(|e| e.is_nan() || e > 1.0) {
                // A rejected step rolled every instance back: the rollback
                // self-check from there, before the smaller step.
                let since = *verified;
                system.check_rollback(at.t, at.h).map_err(|e| {
                    if at.t > since {
                        e.after_check_at(since)
                    } else {
                        e
                    }
                })?;
                *verified = at.t;
            }
            Ok(error)
        });
        if let Err(e) = stepped {
            // The instance whose output diverged first in the step, if any.
            let noted = (self.system.slaves.iter())
                .filter_map(|s| s.coupled.beyond.as_ref().map(|b| (s.name.as_str(), b)));
            let e = crate::culprit::blame(e, noted, self.grid.time());
            if !matches!(e, MasterError::TerminationRequested { .. }) {
                self.health.fail(&e);
            }
            return Err(e);
        }
        self.timing.step_end = lap.last();
        self.stats.macro_steps += 1;
        self.row.fill(&self.system);
        let (row, columns) = (self.row.all_values(), self.row.all_columns());
        self.health
            .check(row, columns, self.grid.time())
            .inspect_err(|e| self.health.fail(e))
    }

    /// [`run`](Self::run) without a progress callback.
    pub fn run_to_end(
        &mut self,
        observers: &mut [&mut dyn Observer],
    ) -> Result<RunStats, MasterError> {
        self.run(observers, &mut |_, _| {})
    }

    /// Run to the stop time, feeding the accepted points on the output grid
    /// (`[output] interval`, by default every one) and the last accepted
    /// point to the observers; `progress(steps done, steps in all)` is called
    /// after every accepted step.
    /// An instance's request to end the simulation (fmi2Discard with
    /// `fmi2Terminated`) ends the run normally at the last accepted point,
    /// noted in [`RunStats::termination`]. On a normal end every instance is
    /// terminated (`fmi2Terminate`). On failure the observers are finished
    /// with the error message (results up to the last accepted step are kept)
    /// and the error is returned.
    pub fn run(
        &mut self,
        observers: &mut [&mut dyn Observer],
        progress: &mut dyn FnMut(u64, u64),
    ) -> Result<RunStats, MasterError> {
        let clock = Instant::now();
        self.timing.step_end = None;
        let columns = self.row.columns();
        let started = observers
            .iter_mut()
            .try_for_each(|o| o.start(columns))
            .map_err(MasterError::from)
            .and_then(|()| self.notify(observers));
        if let Err(e) = started {
            // The results file failed at once (its header): the run failed.
            self.health.fail(&e);
            return Err(e);
        }
        let outcome = (|| {
            while !self.finished() {
                if let Some(reason) = observers.iter_mut().find_map(|o| o.interrupt()) {
                    let time = self.time();
                    return Err(MasterError::Interrupted { time, reason });
                }
                match self.step() {
                    Ok(()) => {}
                    Err(MasterError::TerminationRequested { instance, time }) => {
                        self.stats.termination = Some(Termination {
                            instance,
                            requested_at: time,
                            ended_at: self.time(),
                        });
                        break;
                    }
                    Err(e) => return Err(e),
                }
                if self.grid.recorded() {
                    self.notify(observers)?;
                } else {
                    self.row.hold(self.grid.n(), self.grid.time());
                }
                progress(self.grid.progress(), self.grid.total_steps());
            }
            // A normal end: fmi2Terminate before the instances are freed.
            self.system.terminate()
        })();
        // The last accepted point is recorded even when it is off the output
        // grid (unless recording itself failed).
        let outcome = match outcome {
            Err(e @ MasterError::Recording(_)) => Err(e),
            outcome => self.row.release_held(observers).and(outcome),
        };
        let message = outcome.as_ref().err().map(|e: &MasterError| e.to_string());
        if let (None, Err(e)) = (self.health.failure(), &outcome) {
            self.health.fail(e);
        }
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
        // The results file failed at its end (a write, or removed during the
        // run): the run is not completed.
        if let Err(e) = finished {
            let e = MasterError::from(e);
            self.health.fail(&e);
            return Err(e);
        }
        Ok(self.stats())
    }

    /// Hand the current point to the observers (timed as the recording phase).
    fn notify(&mut self, observers: &mut [&mut dyn Observer]) -> Result<(), MasterError> {
        if observers.is_empty() {
            return Ok(());
        }
        // The recording phase starts where the step's last phase ended (it
        // includes assembling and checking the row): one clock read fewer.
        let clock = self
            .timing
            .step_end
            .take()
            .or_else(|| self.timing.on.then(Instant::now));
        self.row
            .notify(observers, self.grid.n(), self.grid.time())?;
        if let Some(clock) = clock {
            self.stats.times.recording += clock.elapsed();
        }
        Ok(())
    }
}

/// One try of the step T_N → T_N + h: the signals sent, the method's step,
/// and, when the step is accepted (fixed steps, or an error norm ≤ 1), the
/// signals received. Returns the error norm of adaptive steps.
fn step_at(
    (signals, method, system): (&mut Signals, &mut Box<dyn MacroStep>, &mut System),
    at: StepAt,
    stats: &mut RunStats,
    lap: &mut Lap,
) -> Result<Option<f64>, MasterError> {
    system.runs.begin_step()?;
    if signals.iterated() {
        return signals.step_iterated((method, system), at, stats, lap);
    }
    signals.send((&mut system.slaves, &mut system.runs), at)?;
    let error = method.step(system, at, stats, lap)?;
    if error.is_none_or(|e| e <= 1.0) {
        signals.receive(&mut system.slaves)?;
    }
    Ok(error)
}
