//! Counters of a run: what the algorithm asked of the FMUs and where the time went.

use std::fmt;
use std::time::{Duration, Instant};

/// FMI calls made on one instance.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct InstanceCounters {
    /// Instance name.
    pub name: String,
    /// `fmi2DoStep` calls.
    pub do_steps: u64,
    /// `fmi2GetFMUstate` calls.
    pub state_gets: u64,
    /// `fmi2SetFMUstate` calls.
    pub state_sets: u64,
    /// `fmi2SetReal` calls (coupled inputs).
    pub set_reals: u64,
    /// `fmi2GetReal` calls (coupled and recorded outputs).
    pub get_reals: u64,
    /// `fmi2SetRealInputDerivatives` calls.
    pub set_input_derivatives: u64,
    /// `fmi2GetRealOutputDerivatives` calls.
    pub get_output_derivatives: u64,
}

/// Wall time spent in each phase of the macro steps. The setup is always
/// timed; the phases only when phase timing is on
/// ([`Simulation::time_phases`](crate::Simulation::time_phases)): it costs
/// five clock reads per macro step, a noticeable part of a step of cheap FMUs.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhaseTimes {
    /// Whether the phases below were timed (otherwise they are zero).
    pub measured: bool,
    /// Initialisation: instantiation, start values, consistent multipliers.
    pub setup: Duration,
    /// Predictor runs (eq. 56–58).
    pub predictor: Duration,
    /// Perturbed runs for the interface Jacobian (eq. 59–64).
    pub jacobian: Duration,
    /// Building and solving the linear systems (eq. 68 / 73–76).
    pub solve: Duration,
    /// Corrector runs.
    pub corrector: Duration,
    /// Observers (recording results), including assembling and checking the
    /// row they receive.
    pub recording: Duration,
}

/// Everything counted during a run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunStats {
    /// Accepted macro steps.
    pub macro_steps: u64,
    /// Linear solves of the interface Jacobian (one per matrix factorised).
    pub jacobian_solves: u64,
    /// Corrections made (corrector runs), over all accepted macro steps:
    /// one per step unless the correction is iterated (`[coupling] iterations`).
    pub corrections: u64,
    /// The most corrections made in one macro step.
    pub max_corrections: u64,
    /// Macro steps (tries, with adaptive steps) that made the interface
    /// Jacobian from perturbed runs.
    pub jacobians: u64,
    /// Macro steps (tries) that reused the Jacobian with a Broyden update
    /// (`[coupling] jacobian = "reuse"`).
    pub jacobians_reused: u64,
    /// Adaptive macro steps (`[step_control]`): what the controller did.
    pub adaptive: Option<AdaptiveStats>,
    /// Per-instance FMI call counts.
    pub instances: Vec<InstanceCounters>,
    /// Where the time went.
    pub times: PhaseTimes,
    /// Total wall time of [`crate::Simulation::run`] and setup.
    pub wall: Duration,
    /// Parallel perturbed runs: workers used and the measurements behind it.
    pub parallel: crate::ParallelInfo,
    /// Set when an instance asked to end the simulation before the stop time
    /// (fmi2Discard with `fmi2Terminated`): the run ended normally there.
    pub termination: Option<Termination>,
    /// Per constraint and joint condition (its `.g` column): the largest
    /// |g| (position-level residual) over the recorded points.
    pub residuals: Vec<(String, f64)>,
    /// The threshold above which the summary warns about a residual
    /// (`[coupling] residual_warning`).
    pub residual_warning: f64,
}

/// What the step-size controller of adaptive macro steps did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AdaptiveStats {
    /// Accepted macro steps.
    pub accepted: u64,
    /// Rejected (rolled back and retried smaller) macro steps.
    pub rejected: u64,
    /// The smallest accepted step size.
    pub h_smallest: f64,
    /// The largest accepted step size.
    pub h_largest: f64,
    /// The error norm of the last accepted step (≤ 1: its estimated local
    /// error over the tolerances).
    pub last_error: f64,
}

/// An instance's request to end the simulation, and where the run ended.
#[derive(Debug, Clone, PartialEq)]
pub struct Termination {
    /// The instance that asked.
    pub instance: String,
    /// The time it reported (`fmi2LastSuccessfulTime`).
    pub requested_at: f64,
    /// The last accepted macro point, the last recorded row: the coupled step
    /// to the requested time cannot be completed (the instance cannot be
    /// rolled back and re-run after it terminated).
    pub ended_at: f64,
}

impl fmt::Display for RunStats {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "macro steps: {}   Jacobian solves: {}   wall time: {:.3} s",
            self.macro_steps,
            self.jacobian_solves,
            self.wall.as_secs_f64()
        )?;
        if let Some(a) = &self.adaptive {
            writeln!(
                f,
                "  adaptive steps: {} accepted, {} rejected   H from {:.3e} to {:.3e}",
                a.accepted, a.rejected, a.h_smallest, a.h_largest
            )?;
        }
        if self.jacobians_reused > 0 {
            writeln!(
                f,
                "  interface Jacobian: recomputed in {} steps, reused in {}",
                self.jacobians, self.jacobians_reused
            )?;
        }
        if self.max_corrections > 1 {
            writeln!(
                f,
                "  corrections per step: {:.2} on average, {} at most",
                self.corrections as f64 / self.macro_steps.max(1) as f64,
                self.max_corrections
            )?;
        }
        for c in &self.instances {
            writeln!(
                f,
                "  {:<16} doStep: {:>9}   getFMUstate: {:>8}   setFMUstate: {:>8}   \
                 setReal: {:>9}   getReal: {:>9}   setRealInputDerivatives: {:>8}   \
                 getRealOutputDerivatives: {:>8}",
                c.name,
                c.do_steps,
                c.state_gets,
                c.state_sets,
                c.set_reals,
                c.get_reals,
                c.set_input_derivatives,
                c.get_output_derivatives
            )?;
        }
        if !self.residuals.is_empty() {
            write!(f, "  max |g|:")?;
            for (name, max) in &self.residuals {
                write!(f, "  {name} {max:.2e}")?;
            }
            writeln!(f)?;
            for (name, max) in self
                .residuals
                .iter()
                .filter(|(_, m)| m.is_nan() || *m > self.residual_warning)
            {
                writeln!(
                    f,
                    "  warning: max |{name}| = {max:.2e} exceeds residual_warning = {:e}: the \
                     constraint is not held to that accuracy (a smaller step, another index or \
                     method, or a larger residual_warning)",
                    self.residual_warning
                )?;
            }
        }
        if let Some(end) = &self.termination {
            writeln!(
                f,
                "  note: instance '{}' requested the end of the simulation at t = {} \
                 (fmi2Discard, fmi2Terminated); the run ended normally at t = {}, the last accepted point",
                end.instance, end.requested_at, end.ended_at
            )?;
        }
        let p = &self.parallel;
        if p.workers == 0 && p.handoff.is_zero() && !p.sequential.is_zero() {
            writeln!(
                f,
                "  parallel perturbed runs: 0 worker(s)   predicted runs per step {:.1} µs sequential: \
                 less than a hand-off could save, no worker started",
                p.sequential.as_secs_f64() * 1e6
            )?;
        } else if p.workers > 0 || p.handoff > Duration::ZERO {
            writeln!(
                f,
                "  parallel perturbed runs: {} worker(s)   hand-off {:.1} µs   predicted runs per step {:.1} µs sequential, {:.1} µs parallel",
                p.workers,
                p.handoff.as_secs_f64() * 1e6,
                p.sequential.as_secs_f64() * 1e6,
                p.parallel.as_secs_f64() * 1e6
            )?;
        }
        let t = &self.times;
        if !t.measured {
            return write!(
                f,
                "  time [s]: setup {:.3}  macro steps and recording {:.3}  (phases not timed)",
                t.setup.as_secs_f64(),
                self.wall.saturating_sub(t.setup).as_secs_f64()
            );
        }
        write!(
            f,
            "  time [s]: setup {:.3}  predictor {:.3}  jacobian {:.3}  solve {:.3}  corrector {:.3}  recording {:.3}",
            t.setup.as_secs_f64(),
            t.predictor.as_secs_f64(),
            t.jacobian.as_secs_f64(),
            t.solve.as_secs_f64(),
            t.corrector.as_secs_f64(),
            t.recording.as_secs_f64()
        )
    }
}

/// The clock of one macro step's phases: each split adds the time since the
/// previous one to a phase. Without phase timing it never reads the clock.
pub(crate) struct Lap {
    last: Option<Instant>,
}

impl Lap {
    /// A lap that reads the clock if `on`.
    pub fn start(on: bool) -> Lap {
        Lap {
            last: on.then(Instant::now),
        }
    }

    /// Add the time since the previous split (or the start) to `phase`.
    pub fn split_into(&mut self, phase: &mut Duration) {
        if let Some(last) = self.last {
            let now = Instant::now();
            *phase += now - last;
            self.last = Some(now);
        }
    }

    /// The clock reading of the last split (the next phase's start), if timed.
    pub fn last(&self) -> Option<Instant> {
        self.last
    }
}
