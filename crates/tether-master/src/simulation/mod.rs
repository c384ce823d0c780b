//! A coupled run: instantiate the FMUs, resolve the coupling, pick consistent
//! initial multipliers, then march over the macro grid `T_n = T_0 + n·H` with
//! the configured method's [`MacroStep`], handing every accepted point to the
//! observers and checking it for divergence.

use std::time::Instant;

mod tune;

use crate::algorithm::explicit::Explicit;
use crate::algorithm::predictor_corrector::PredictorCorrector;
use crate::algorithm::signals::Signals;
use crate::algorithm::threads;
use crate::build::feedthrough::Feedthrough;
use crate::build::system::{MacroStep, StepAt, System};
use crate::coupling::rows::RowLevel;
use crate::observer::{Observer, Sample};
use crate::slave::Run;
use crate::spec::{CheckRollback, SystemSpec};
use crate::stats::{AdaptiveStats, Lap, RunStats, Termination};
use crate::step_control::Controller;
use crate::{Experiment, MasterError, Method};

/// A coupled system, ready to run.
pub struct Simulation {
    experiment: Experiment,
    system: System,
    /// The coupling method's macro step.
    method: Box<dyn MacroStep>,
    /// Signal connections, passed around the method's step.
    signals: Signals,
    /// Current macro point index N.
    n: u64,
    steps: u64,
    /// Every column, recorded or not.
    all_columns: Vec<String>,
    /// The values of every column at the current point.
    row: Vec<f64>,
    /// The columns the observers receive (`[output] variables`) …
    columns: Vec<String>,
    /// … their indices in `row`, when not all of them …
    keep: Option<Vec<usize>>,
    /// … and their values at the current point.
    selected: Vec<f64>,
    /// Macro steps between recorded points (`[output] interval`).
    every: u64,
    /// The last accepted point when it was not recorded (off the output
    /// grid): its time and values, written at the end of the run.
    held: Option<(u64, f64)>,
    held_values: Vec<f64>,
    /// The error that stopped the run, if any.
    failure: Option<String>,
    /// Per column, the magnitude beyond which the run has diverged.
    limits: Vec<f64>,
    /// Per residual column, the largest |g| over the points so far.
    max_residuals: Vec<f64>,
    /// The first residual column's index in `row`.
    first_residual: usize,
    /// Time of the last point handed to the observers.
    last_recorded: Option<f64>,
    stats: RunStats,
    /// Whether the phases of each macro step are timed (off by default).
    time_phases: bool,
    /// The clock reading that ended the last macro step's phases, for the
    /// recording phase that follows it in [`Simulation::run`].
    step_end: Option<Instant>,
    /// `[coupling] residual_warning`, for the summary.
    residual_warning: f64,
    /// Adaptive macro steps (`[step_control]`); `None`: the uniform grid.
    adaptive: Option<Adaptive>,
}

/// The variable time grid of adaptive macro steps.
struct Adaptive {
    controller: Controller,
    /// T_N.
    t: f64,
    /// The stop time, the last point.
    stop: f64,
    /// The next step size to try.
    h: f64,
    /// T_N − T_{N−1} and T_{N−1} − T_{N−2}.
    past: [f64; 2],
    /// `[output] interval`: steps land on its grid points T_0 + j·interval.
    grid: Option<f64>,
    /// j of the next grid point.
    next_output: u64,
    /// Whether T_N is a grid point.
    on_grid: bool,
    stats: AdaptiveStats,
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
        let (step, initial_level): (Box<dyn MacroStep>, _) = match method {
            Method::Explicit { mu } => (
                Box::new(Explicit::new(&system, mu)),
                RowLevel::Stabilised(mu),
            ),
            _ => {
                let runs = threads::strategy(
                    settings.parallel,
                    &system.slaves,
                    &spec.instances,
                    &system.group_slaves,
                    system.coupling.len(),
                    (exp.start, stop, exp.tolerance),
                )?;
                let pc = PredictorCorrector::new(&system, method, &settings, runs);
                (Box::new(pc), RowLevel::Acceleration)
            }
        };
        let mut step = step;
        let adaptive = match &spec.step_control {
            None => None,
            Some(control) => {
                if matches!(method, Method::Explicit { .. }) {
                    return Err(MasterError::InvalidParameter {
                        name: "step_control".into(),
                        value: control.rtol,
                        expected: "the predictor/corrector methods (baumgarte, weighted): \
                                   the explicit method has no error estimate"
                            .into(),
                    });
                }
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
        let mut stats = RunStats::default();
        // Signals at T_0 before and after the consistent multipliers, which
        // may depend on signal inputs and change outputs that senders read.
        signals.initialize(&mut system.slaves)?;
        Feedthrough::new(&system).initial(&mut system, initial_level, exp.start, &mut stats)?;
        signals.initialize(&mut system.slaves)?;
        system.read_accepted(Run::Initial)?;
        if method.needs_rollback() && settings.check_rollback != CheckRollback::Off {
            system.check_rollback(exp.start, exp.step)?;
        }
        // Fixed steps record every `every`-th point; adaptive ones land on
        // the output grid, when there is one, and record exactly its points.
        let every = match adaptive {
            None => spec.output.every(exp.step)?,
            Some(_) => 1,
        };
        let adaptive = match adaptive {
            None => None,
            Some((control, limits)) => {
                step.control_steps(&system, control);
                signals.roll_back_with_retries();
                let grid = match spec.output.interval {
                    Some(dt) if !(dt.is_finite() && dt > 0.0) => {
                        return Err(MasterError::InvalidParameter {
                            name: "output interval".into(),
                            value: dt,
                            expected: "a positive time".into(),
                        })
                    }
                    grid => grid,
                };
                let h = limits.h_initial.min(limits.h_max).max(limits.h_min);
                Some(Adaptive {
                    controller: Controller::new(limits, settings.order),
                    t: exp.start,
                    stop: exp.stop,
                    h,
                    past: [h, h],
                    grid,
                    next_output: 1,
                    on_grid: false,
                    stats: AdaptiveStats {
                        h_smallest: f64::INFINITY,
                        ..AdaptiveStats::default()
                    },
                })
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
        let keep = (keep.len() < columns.len()).then_some(keep);
        let selected: Vec<String> = match &keep {
            Some(keep) => keep.iter().map(|&i| columns[i].clone()).collect(),
            None => columns.clone(),
        };
        stats.method = method;
        stats.order = settings.order;
        stats.start = exp.start;
        stats.step = exp.step;
        stats.stop = stop;
        stats.output_interval = match &adaptive {
            Some(a) => a.grid.unwrap_or(0.0),
            None => every as f64 * exp.step,
        };
        let mut sim = Simulation {
            experiment: exp,
            system,
            method: step,
            signals,
            n: 0,
            steps,
            row: vec![0.0; columns.len()],
            limits: vec![f64::INFINITY; columns.len()],
            max_residuals: vec![0.0; columns.len() - first_residual],
            first_residual,
            last_recorded: None,
            selected: vec![0.0; selected.len()],
            held_values: vec![0.0; selected.len()],
            columns: selected,
            all_columns: columns,
            keep,
            every,
            held: None,
            failure: None,
            stats,
            residual_warning: settings.residual_warning,
            time_phases: false,
            step_end: None,
            adaptive,
        };
        sim.fill_row();
        // Finite limits (the factor is finite, > 1), so that ±∞ is always
        // beyond them.
        let factor = settings.divergence_factor;
        sim.limits = sim
            .row
            .iter()
            .map(|v| (factor * v.abs().max(1.0)).min(f64::MAX))
            .collect();
        sim.check_divergence()?;
        sim.stats.times.setup = clock.elapsed();
        Ok(sim)
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
        &self.columns
    }

    /// The recorded values of the current point (the last accepted one), in
    /// the order of [`Simulation::columns`]: what observers receive as
    /// [`Sample::values`].
    pub fn values(&self) -> &[f64] {
        match self.keep {
            Some(_) => &self.selected,
            None => &self.row,
        }
    }

    /// The units the FMUs declare for the recorded outputs among
    /// [`columns`](Self::columns): `(column, unit)` pairs.
    pub fn units(&self) -> Vec<(String, String)> {
        let mut units = Vec::new();
        for slave in &self.system.slaves {
            let md = slave.fmu.model_description();
            for column in slave.recorded_names() {
                if !self.columns.contains(column) {
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
        match &self.adaptive {
            Some(a) => a.t,
            None => self.time_at(self.n),
        }
    }

    /// Whether the run has reached its last point.
    pub fn finished(&self) -> bool {
        match &self.adaptive {
            Some(a) => a.t >= a.stop,
            None => self.n >= self.steps,
        }
    }

    fn time_at(&self, n: u64) -> f64 {
        self.experiment.start + n as f64 * self.experiment.step
    }

    /// The time of the last point handed to the observers by
    /// [`run`](Self::run) (the last row of the results), if any. After a
    /// failure it is the time up to which results are kept; the failing
    /// step's time may be later.
    pub fn last_recorded_time(&self) -> Option<f64> {
        self.last_recorded
    }

    /// Number of macro steps the experiment asks for (with adaptive steps:
    /// how many steps of `[experiment] step` the run spans, for progress).
    pub fn total_steps(&self) -> u64 {
        self.steps
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
        self.time_phases = on;
        self.step_end = None;
    }

    /// Counters so far, and how the run ended (or that it is still running).
    pub fn stats(&self) -> RunStats {
        let mut stats = self.stats.clone();
        stats.times.measured = self.time_phases;
        stats.end_time = self.last_recorded;
        stats.completed =
            self.failure.is_none() && (self.finished() || stats.termination.is_some());
        stats.stop_reason = match (&self.failure, &stats.termination) {
            (Some(e), _) => e.clone(),
            (None, Some(end)) => format!(
                "instance '{}' requested the end of the simulation at t = {}",
                end.instance, end.requested_at
            ),
            (None, None) if stats.completed => "completed".into(),
            (None, None) => "running".into(),
        };
        stats.residuals = self.all_columns[self.first_residual..]
            .iter()
            .cloned()
            .zip(self.max_residuals.iter().copied())
            .collect();
        stats.residual_warning = self.residual_warning;
        stats.adaptive = self.adaptive.as_ref().map(|a| a.stats);
        stats.instances = self
            .system
            .slaves
            .iter()
            .map(|s| s.counters().clone())
            .collect();
        self.method.report(&mut stats);
        stats
    }

    /// Advance one macro step with the configured method (with adaptive
    /// steps: one accepted step, after as many rejected tries as it takes).
    pub fn step(&mut self) -> Result<(), MasterError> {
        let mut lap = Lap::start(self.time_phases);
        let stepped = match &self.adaptive {
            None => {
                let at = StepAt {
                    n: self.n,
                    t: self.time(),
                    h: self.experiment.step,
                    t_next: self.time_at(self.n + 1),
                    past: None,
                };
                let parts = (&mut self.signals, &mut self.method, &mut self.system);
                step_at(parts, at, &mut self.stats, &mut lap).map(|_| ())
            }
            Some(_) => self.adaptive_step(&mut lap),
        };
        if let Err(e) = stepped {
            if !matches!(e, MasterError::TerminationRequested { .. }) {
                self.failure = Some(e.to_string());
            }
            return Err(e);
        }
        self.n += 1;
        self.step_end = lap.last();
        self.stats.macro_steps += 1;
        self.fill_row();
        self.check_divergence().inspect_err(|e| {
            self.failure = Some(e.to_string());
        })
    }

    /// [`run`](Self::run) without a progress callback.
    pub fn run_to_end(
        &mut self,
        observers: &mut [&mut dyn Observer],
    ) -> Result<RunStats, MasterError> {
        self.run(observers, &mut |_, _| {})
    }

    /// One accepted step of adaptive size: try the controller's step
    /// (clipped to land on the next output grid point and on the stop time,
    /// halved when that target is within two steps),
    /// roll back and retry smaller while the error estimate exceeds the
    /// tolerances.
    fn adaptive_step(&mut self, lap: &mut Lap) -> Result<(), MasterError> {
        let a = self.adaptive.as_mut().expect("adaptive steps");
        let start = self.experiment.start;
        // The point the step must not pass: the next output grid point (a
        // point within 1e-9 intervals of the stop time is the stop time).
        let target = match a.grid {
            Some(dt) => {
                let point = start + a.next_output as f64 * dt;
                if point >= a.stop - 1e-9 * dt {
                    a.stop
                } else {
                    point
                }
            }
            None => a.stop,
        };
        loop {
            let remaining = target - a.t;
            // A clipped step ends exactly at the target; no sliver is left.
            let clipped = a.h >= remaining || remaining - a.h < 1e-3 * a.h;
            // A target within two steps is reached in two equal ones: a
            // sliver step next to full ones would put nearby points into the
            // polynomials through the past points (k ≥ 1), whose slope then
            // amplifies the multipliers' noise by the ratio of H to the sliver.
            let halved = !clipped && remaining < 2.0 * a.h;
            let h = match (clipped, halved) {
                (true, _) => remaining,
                (false, true) => 0.5 * remaining,
                (false, false) => a.h,
            };
            let at = StepAt {
                n: self.n,
                t: a.t,
                h,
                t_next: if clipped { target } else { a.t + h },
                past: Some(a.past),
            };
            let parts = (&mut self.signals, &mut self.method, &mut self.system);
            let error = step_at(parts, at, &mut self.stats, lap)?
                .expect("the predictor/corrector step estimates its error");
            let (next, accepted) = a.controller.next(h, error);
            if accepted {
                a.t = at.t_next;
                a.past = [h, a.past[0]];
                // A clipped or halved step does not shrink the next proposal.
                a.h = if clipped || halved {
                    a.h.max(next)
                } else {
                    next
                };
                a.on_grid = clipped && a.grid.is_some();
                if a.on_grid {
                    a.next_output += 1;
                }
                a.stats.accepted += 1;
                a.stats.last_error = error;
                a.stats.h_smallest = a.stats.h_smallest.min(h);
                a.stats.h_largest = a.stats.h_largest.max(h);
                return Ok(());
            }
            a.stats.rejected += 1;
            if h <= a.controller.limits.h_min {
                return Err(MasterError::StepSizeTooSmall {
                    time: a.t,
                    error,
                    h_min: a.controller.limits.h_min,
                });
            }
            a.h = next;
        }
    }

    /// Macro steps done, for progress: with adaptive steps, how many steps
    /// of `[experiment] step` the time reached spans (never beyond the total).
    fn progress(&self) -> u64 {
        match &self.adaptive {
            Some(a) => {
                let spanned = (a.t - self.experiment.start) / self.experiment.step;
                (spanned.round() as u64).min(self.steps)
            }
            None => self.n,
        }
    }

    /// Whether the current point goes to the observers: on the output grid,
    /// or the last one.
    fn recorded(&self) -> bool {
        match &self.adaptive {
            Some(a) => a.grid.is_none() || a.on_grid || self.finished(),
            None => self.n.is_multiple_of(self.every) || self.n == self.steps,
        }
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
        self.step_end = None;
        for o in observers.iter_mut() {
            o.start(&self.columns)?;
        }
        self.notify(observers)?;
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
                if self.recorded() {
                    self.notify(observers)?;
                } else {
                    self.hold();
                }
                progress(self.progress(), self.steps);
            }
            // A normal end: fmi2Terminate before the instances are freed.
            self.system.terminate()?;
            self.method.terminate()
        })();
        // The last accepted point is recorded even when it is off the output
        // grid (unless recording itself failed).
        let outcome = match outcome {
            Err(e @ MasterError::Recording(_)) => Err(e),
            outcome => self.release_held(observers).and(outcome),
        };
        let message = outcome.as_ref().err().map(|e: &MasterError| e.to_string());
        if self.failure.is_none() {
            self.failure = message.clone();
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
            values: match self.keep {
                Some(_) => &self.selected,
                None => &self.row,
            },
        };
        for o in observers.iter_mut() {
            o.sample(sample)?;
        }
        self.last_recorded = Some(sample.time);
        self.held = None;
        if let Some(clock) = clock {
            self.stats.times.recording += clock.elapsed();
        }
        Ok(())
    }

    /// Keep the current point, not on the output grid, for the end.
    fn hold(&mut self) {
        let values = match self.keep {
            Some(_) => &self.selected,
            None => &self.row,
        };
        self.held_values.copy_from_slice(values);
        self.held = Some((self.n, self.time()));
    }

    /// Record the held point, if it is the last accepted one not yet recorded.
    fn release_held(&mut self, observers: &mut [&mut dyn Observer]) -> Result<(), MasterError> {
        let Some((step, time)) = self.held.take() else {
            return Ok(());
        };
        let sample = Sample {
            step,
            time,
            values: &self.held_values,
        };
        for o in observers.iter_mut() {
            o.sample(sample)?;
        }
        self.last_recorded = Some(time);
        Ok(())
    }

    fn fill_row(&mut self) {
        let mut i = 0;
        for slave in &self.system.slaves {
            let values = slave.recorded_values();
            self.row[i..i + values.len()].copy_from_slice(values);
            i += values.len();
        }
        for h in &self.system.history {
            self.row[i] = h[0];
            i += 1;
        }
        let residuals = self.system.coupling.residuals(&self.system.outputs);
        for (residual, max) in residuals.zip(&mut self.max_residuals) {
            self.row[i] = residual;
            *max = max.max(residual.abs());
            i += 1;
        }
        if let Some(keep) = &self.keep {
            for (value, &k) in self.selected.iter_mut().zip(keep) {
                *value = self.row[k];
            }
        }
    }

    /// An error naming the first recorded value that is not finite or beyond
    /// its limit.
    fn check_divergence(&self) -> Result<(), MasterError> {
        let beyond = |(&value, &limit): (&f64, &f64)| value.is_nan() || value.abs() > limit;
        match self.row.iter().zip(&self.limits).position(beyond) {
            None => Ok(()),
            Some(i) => Err(MasterError::Diverged {
                time: self.time(),
                quantity: self.all_columns[i].clone(),
                value: self.row[i],
                limit: self.limits[i],
            }),
        }
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
    signals.send(&mut system.slaves, at)?;
    let error = method.step(system, at, stats, lap)?;
    if error.is_none_or(|e| e <= 1.0) {
        signals.receive(&mut system.slaves)?;
    }
    Ok(error)
}
