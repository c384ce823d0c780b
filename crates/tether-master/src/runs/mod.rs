//! The runs of a macro step, instance by instance (docs/algorithm.md,
//! "Parallel runs"). Each phase of a step hands every instance one task —
//! its predictor run with its perturbed runs, its perturbed runs alone, its
//! corrector run, or a plain step of a signal system — and no task of a
//! phase depends on another's outputs. [`Runs`] makes a phase's tasks on the
//! main thread, or shares them with worker threads ([`pool`]) as `[coupling]
//! parallel` says; every way computes the same values bit for bit.

pub(crate) mod pool;

use std::time::{Duration, Instant};

use crate::polynomial::Taylor;
use crate::slave::{Batch, Run, Slave};
use crate::spec::{InstanceSpec, Parallel};
use crate::stats::{ParallelInfo, RunStats};
use crate::MasterError;
use pool::Pool;

/// Macro steps whose tasks are timed before the workers are (re)assigned:
/// "auto" makes them on the main thread, "on" on the workers.
const CALIBRATION_STEPS: u32 = 3;

/// Macro steps "auto" then makes in parallel (and times) before it decides.
const TRIAL_STEPS: u32 = 3;

/// "auto" keeps the workers only if a parallel step's runs took at most
/// this fraction of a sequential step's.
const PAYS: f64 = 0.9;

/// Hand-offs timed for the decision (their median counts).
const HANDOFF_SAMPLES: usize = 7;

/// Less than any hand-off can cost: it wakes a sleeping thread and is woken
/// back, two futex calls and two context switches at the least. If a step's
/// tasks could not gain even against this, "auto" decides without starting
/// a worker or timing a hand-off.
const HANDOFF_FLOOR: Duration = Duration::from_micros(2);

/// What each instance does in a phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Task {
    /// The predictor run and, with the phase's perturbed polynomials, the
    /// instance's perturbed runs from the saved state (Steps 2 and 3).
    Predict,
    /// The perturbed runs alone (Step 3, when the predictor's did not make
    /// them).
    Perturb,
    /// The corrector run from the saved state (Step 5), or only the read of
    /// the accepted outputs of an instance no unknown drives.
    Correct,
    /// One `fmi2DoStep` (Gauss–Seidel's stages, the explicit method).
    Step,
    /// One `fmi2DoStep` (unless the Gauss–Seidel sweep made it) and the
    /// read of the accepted outputs: a step of a system without unknowns.
    StepAndRead,
}

/// What the tasks of a phase share.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Phase<'a> {
    pub task: Task,
    /// T_N and H.
    pub t: f64,
    pub h: f64,
    /// Each unknown's polynomial over the step (predictor or corrector).
    pub polys: &'a [Taylor],
    /// Per perturbation group, its polynomials; empty: no perturbed runs.
    pub perturbed: &'a [Vec<Taylor>],
}

impl Phase<'_> {
    /// A phase of plain steps from `t` over `h`.
    pub fn step(t: f64, h: f64) -> Phase<'static> {
        Phase {
            task: Task::Step,
            t,
            h,
            polys: &[],
            perturbed: &[],
        }
    }
}

/// Where a phase's outputs go.
pub(crate) struct Outputs<'a> {
    /// Per instance: its coupled outputs after its run (the predicted or
    /// the accepted ones); empty for a phase of plain steps.
    pub own: &'a mut [Vec<f64>],
    /// Per group and instance: the coupled outputs after the perturbed run.
    pub perturbed: &'a mut [Vec<Vec<f64>>],
}

impl Outputs<'_> {
    /// No outputs (plain steps).
    pub fn none() -> Outputs<'static> {
        Outputs {
            own: &mut [],
            perturbed: &mut [],
        }
    }
}

/// One instance's task of `phase`: `out` its own outputs, `runs` the
/// polynomials and outputs of its perturbed runs in group order; `how`
/// splits the task of an instance in a host process ([`sent_apart`]) into
/// its request and its reply. Returns whether a reply is awaited.
#[inline]
pub(crate) fn work<'p>(
    slave: &mut Slave,
    phase: Phase<'p>,
    out: &'p mut [f64],
    runs: impl Iterator<Item = (&'p [Taylor], &'p mut [f64])>,
    how: Batch,
) -> Result<bool, MasterError> {
    let (t, h) = (phase.t, phase.h);
    match phase.task {
        Task::Predict => slave.predict_and_perturb(phase.polys, (t, h), out, runs, how),
        Task::Perturb => {
            for (polys, out) in runs {
                slave.rerun(polys, t, h, Some(out))?;
            }
            Ok(false)
        }
        Task::Correct if slave.is_coupled() => slave.correct(phase.polys, (t, h), out, how),
        Task::Correct => slave.read_accepted_as(out, Run::Corrector, how),
        Task::Step => slave.do_step(t, h).map(|()| false),
        Task::StepAndRead => {
            if how != Batch::Receive && !slave.stepped_ahead {
                slave.do_step(t, h)?;
            }
            slave.read_accepted_as(out, Run::Corrector, how)
        }
    }
}

/// Whether an instance's task of `task` is one request to a host process
/// (one batch), sent before the other instances' tasks are made and its
/// reply read after them: then every host works at once, without a thread.
pub(crate) fn sent_apart(slave: &Slave, task: Task) -> bool {
    slave.backend.is_remote()
        && !slave.check.verify_restore
        && matches!(task, Task::Predict | Task::Correct | Task::StepAndRead)
}

/// Keep the failure of the instance first in file order.
fn keep_first(failure: &mut Option<(usize, MasterError)>, s: usize, e: MasterError) {
    if failure.as_ref().is_none_or(|&(first, _)| s < first) {
        *failure = Some((s, e));
    }
}

/// Instance `s`'s task of `phase` with its outputs in `outputs`.
#[inline]
fn work_in(
    slave: &mut Slave,
    s: usize,
    (phase, how): (Phase<'_>, Batch),
    outputs: &mut Outputs<'_>,
    group_slaves: &[Vec<usize>],
) -> Result<bool, MasterError> {
    let out = match outputs.own.get_mut(s) {
        Some(out) => &mut out[..],
        None => &mut [],
    };
    if phase.perturbed.is_empty() {
        return work(slave, phase, out, std::iter::empty(), how);
    }
    let runs = group_slaves
        .iter()
        .zip(phase.perturbed)
        .zip(outputs.perturbed.iter_mut())
        .filter(|((members, _), _)| members.contains(&s))
        .map(|((_, polys), outputs)| (&polys[..], &mut outputs[s][..]));
    work(slave, phase, out, runs, how)
}

/// The runs of every phase, on the main thread or shared with workers.
pub(crate) struct Runs {
    mode: Parallel,
    /// Threads the runs may use, the main thread included.
    threads: usize,
    /// Per group, the instances its perturbed run steps.
    group_slaves: Vec<Vec<usize>>,
    /// Per instance: whether its tasks may leave the main thread.
    capable: Vec<bool>,
    /// Unknowns (the length of a phase's polynomials).
    unknowns: usize,
    /// The workers, once started.
    pool: Option<Pool>,
    /// Macro steps begun.
    steps: u32,
    /// Some instance runs in a host process ([`with_hosts`]).
    hosts: bool,
    /// Per instance: a host process's reply is due ([`with_hosts`]).
    awaiting: Vec<bool>,
    /// Per instance: its tasks' time in this step, and the shortest step's.
    step_cost: Vec<Duration>,
    cost: Vec<Duration>,
    /// Phases of this step, and of the last step.
    phases: u32,
    last_phases: u32,
    /// This step's phases' time, and the shortest sequential and parallel
    /// steps'.
    step_time: Duration,
    trial: [Duration; 2],
    info: ParallelInfo,
}

impl Runs {
    /// The runs for `mode` with `threads` threads (None: the machine's
    /// available parallelism): an instance's tasks may go to a worker unless
    /// its FMU can be instantiated only once per process, its
    /// `[[instance]]` says `parallel = false`, or it runs in a host process
    /// (its requests are sent without a thread, [`Slave::runs`]). "on"
    /// starts the workers now.
    pub fn new(
        mode: Parallel,
        threads: Option<usize>,
        slaves: &[Slave],
        specs: &[InstanceSpec],
        group_slaves: &[Vec<usize>],
        unknowns: usize,
    ) -> Result<Runs, MasterError> {
        let threads = threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
            .max(1);
        let capable: Vec<bool> = slaves
            .iter()
            .zip(specs)
            .map(|(slave, spec)| slave.can_run_in_parallel() && spec.parallel != Some(false))
            .collect();
        let n = slaves.len();
        let mut runs = Runs {
            mode,
            threads,
            group_slaves: group_slaves.to_vec(),
            capable,
            unknowns,
            pool: None,
            hosts: slaves.iter().any(|s| s.backend.is_remote()),
            awaiting: vec![false; n],
            steps: 0,
            step_cost: vec![Duration::ZERO; n],
            cost: vec![Duration::MAX; n],
            phases: 0,
            last_phases: 0,
            step_time: Duration::ZERO,
            trial: [Duration::MAX; 2],
            info: ParallelInfo::default(),
        };
        if mode == Parallel::On && runs.workers() > 0 {
            runs.start(slaves.len())?;
            // Until the first steps are measured every instance counts the same.
            let unit = vec![Duration::from_micros(1); n];
            runs.assign(&unit, Duration::ZERO, 1);
        }
        Ok(runs)
    }

    /// Worker threads worth starting: one per thread beyond the main one,
    /// no more than the instances that may leave the main thread (one fewer
    /// when every instance may: the main thread takes one of them).
    fn workers(&self) -> usize {
        let capable = self.capable.iter().filter(|&&c| c).count();
        let pinned = self.capable.len() - capable;
        let useful = if pinned > 0 {
            capable
        } else {
            capable.saturating_sub(1)
        };
        (self.threads - 1).min(useful)
    }

    fn start(&mut self, instances: usize) -> Result<(), MasterError> {
        let pool = Pool::start(
            self.workers(),
            instances,
            (&self.group_slaves, self.unknowns),
            self.hosts,
        )?;
        self.info.workers = pool.workers();
        self.pool = Some(pool);
        Ok(())
    }

    /// Whether a phase's tasks are timed (the first steps, and "auto"'s
    /// trial).
    fn timing(&self) -> bool {
        match self.mode {
            Parallel::Off => false,
            Parallel::On => self.steps <= CALIBRATION_STEPS,
            Parallel::Auto => self.steps <= CALIBRATION_STEPS + TRIAL_STEPS,
        }
    }

    /// A macro step (or a try of one) begins: the last one's times are
    /// taken, and after the first steps the workers assigned ("on") or
    /// "auto"'s decision made.
    pub fn begin_step(&mut self) -> Result<(), MasterError> {
        if !self.timing() {
            return Ok(());
        }
        let step = self.steps;
        self.steps += 1;
        if step == 0 {
            return Ok(());
        }
        // The step just made: its tasks' and its phases' times.
        for (cost, step) in self.cost.iter_mut().zip(&mut self.step_cost) {
            if !step.is_zero() {
                *cost = (*cost).min(*step);
            }
            *step = Duration::ZERO;
        }
        let parallel = usize::from(self.pool.is_some());
        self.trial[parallel] = self.trial[parallel].min(self.step_time);
        self.step_time = Duration::ZERO;
        self.last_phases = self.phases.max(1);
        self.phases = 0;
        match self.mode {
            Parallel::Off => Ok(()),
            Parallel::On => {
                if step == CALIBRATION_STEPS {
                    let cost = self.cost.clone();
                    self.assign(&cost, Duration::ZERO, self.last_phases);
                }
                Ok(())
            }
            Parallel::Auto if step == CALIBRATION_STEPS => self.decide(),
            Parallel::Auto if step == CALIBRATION_STEPS + TRIAL_STEPS => {
                self.keep_or_stop();
                Ok(())
            }
            Parallel::Auto => Ok(()),
        }
    }

    /// Make `phase`'s task on every instance `member` selects (by its index
    /// in file order and itself), its outputs
    /// into `outputs`. When several fail, the first in file order is
    /// reported.
    pub fn phase(
        &mut self,
        slaves: &mut Vec<Slave>,
        phase: Phase<'_>,
        mut outputs: Outputs<'_>,
        member: impl Fn(usize, &Slave) -> bool,
    ) -> Result<(), MasterError> {
        let timing = self.timing();
        let clock = timing.then(Instant::now);
        let cost = timing.then_some(&mut self.step_cost[..]);
        let result = match &mut self.pool {
            Some(pool) => pool.run(slaves, phase, &mut outputs, &member, cost),
            None => {
                let hosts = self.hosts.then_some(&mut self.awaiting[..]);
                let shape = (&self.group_slaves[..], hosts);
                sequential(slaves, phase, &mut outputs, shape, &member, cost)
            }
        };
        if let Some(clock) = clock {
            self.step_time += clock.elapsed();
            self.phases += 1;
        }
        result
    }

    /// Assign the instances to the main thread and the workers by their
    /// cost ([`split`]), with the predicted times in the statistics.
    fn assign(&mut self, cost: &[Duration], handoff: Duration, phases: u32) {
        let Some(pool) = &mut self.pool else {
            return;
        };
        let (lane_of, sequential, parallel) =
            split(cost, &self.capable, pool.workers(), handoff, phases);
        self.info.sequential = sequential;
        self.info.parallel = parallel;
        self.info.handoff = handoff;
        pool.assign(lane_of);
    }

    /// "auto", after the first steps: from their measured costs, whether
    /// workers might pay; if so start them, time a hand-off, split the
    /// instances and start the parallel trial unless the prediction says it
    /// cannot pay.
    fn decide(&mut self) -> Result<(), MasterError> {
        let cost = self.cost.clone();
        let phases = self.last_phases;
        self.info.trial_sequential = self.trial[0];
        if self.workers() == 0 {
            return Ok(());
        }
        // Not even a hand-off cheaper than any real one would pay: stay
        // sequential without starting a worker (small FMUs pay nothing more).
        let (_, sequential, parallel) =
            split(&cost, &self.capable, self.workers(), HANDOFF_FLOOR, phases);
        if parallel >= sequential {
            self.info.sequential = sequential;
            self.info.parallel = parallel;
            log::info!(
                "parallel runs: predicted {:?} a step sequential, {:?} parallel with a hand-off of {HANDOFF_FLOOR:?}: off, no worker started",
                sequential,
                parallel,
            );
            return Ok(());
        }
        if let Err(e) = self.start(cost.len()) {
            // The workers are an optimisation: the run goes on without them.
            log::warn!("parallel runs: cannot start a worker ({e}); staying sequential");
            self.pool = None;
            self.info = ParallelInfo::default();
            return Ok(());
        }
        let pool = self.pool.as_mut().expect("just started");
        let mut samples = [Duration::ZERO; HANDOFF_SAMPLES];
        for sample in &mut samples {
            *sample = pool.time_handoff();
        }
        samples.sort_unstable();
        let handoff = samples[HANDOFF_SAMPLES / 2];
        self.assign(&cost, handoff, phases);
        let pays = self.info.parallel < self.info.sequential
            && self.pool.as_ref().is_some_and(Pool::has_work);
        log::info!(
            "parallel runs: hand-off {:?}, predicted {:?} a step sequential, {:?} parallel: {}",
            handoff,
            self.info.sequential,
            self.info.parallel,
            if pays { "trying" } else { "off" }
        );
        if !pays {
            self.stop();
        }
        Ok(())
    }

    /// "auto", after the parallel trial: keep the workers only if a
    /// parallel step's runs took at most [`PAYS`] of a sequential step's.
    fn keep_or_stop(&mut self) {
        if self.pool.is_none() {
            return;
        }
        let [sequential, parallel] = self.trial;
        let pays = parallel.as_secs_f64() <= PAYS * sequential.as_secs_f64();
        log::info!(
            "parallel runs: {sequential:?} sequential, {parallel:?} parallel: {}",
            if pays { "on" } else { "off" }
        );
        self.info.trial_sequential = sequential;
        self.info.trial_parallel = parallel;
        if !pays {
            self.stop();
        }
    }

    /// Join the workers: every task on the main thread from now on.
    fn stop(&mut self) {
        self.pool = None;
        self.info.workers = 0;
    }

    /// What the runs decided, for the run's statistics.
    pub fn report(&self, stats: &mut RunStats) {
        stats.parallel = self.info;
    }
}

/// Split instances costing `cost` between the main thread and `workers`
/// workers: longest first, each to whichever thread has the least load so
/// far (a worker's load starts with `phases` hand-offs of `handoff`; the
/// main thread's with the instances that stay on it). Returns each
/// instance's worker (None: the main thread) and a step's predicted
/// sequential and parallel times.
fn split(
    cost: &[Duration],
    capable: &[bool],
    workers: usize,
    handoff: Duration,
    phases: u32,
) -> (Vec<Option<usize>>, Duration, Duration) {
    let c = |s: usize| match cost[s] {
        Duration::MAX => 0.0,
        d => d.as_secs_f64(),
    };
    let mut loads = vec![handoff.as_secs_f64() * f64::from(phases); workers];
    let mut main_load: f64 = (0..cost.len()).filter(|&s| !capable[s]).map(c).sum();
    let mut order: Vec<usize> = (0..cost.len()).filter(|&s| capable[s]).collect();
    order.sort_by(|&a, &b| c(b).total_cmp(&c(a)).then(a.cmp(&b)));
    let mut lane_of = vec![None; cost.len()];
    for s in order {
        let (lane, load) = loads
            .iter()
            .copied()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((0, f64::INFINITY));
        if load < main_load {
            loads[lane] += c(s);
            lane_of[s] = Some(lane);
        } else {
            main_load += c(s);
        }
    }
    let sequential: f64 = (0..cost.len()).map(c).sum();
    let parallel = loads
        .iter()
        .enumerate()
        .filter(|&(l, _)| lane_of.contains(&Some(l)))
        .map(|(_, &load)| load)
        .fold(main_load, f64::max);
    (
        lane_of,
        Duration::from_secs_f64(sequential),
        Duration::from_secs_f64(parallel),
    )
}

/// Every task of `phase` on the calling thread, in file order, each timed
/// into `cost` when given; with instances in host processes (`hosts`),
/// their requests first ([`with_hosts`]). Stops at the first failure.
pub(crate) fn sequential<M: Fn(usize, &Slave) -> bool + ?Sized>(
    slaves: &mut [Slave],
    phase: Phase<'_>,
    outputs: &mut Outputs<'_>,
    (group_slaves, hosts): (&[Vec<usize>], Option<&mut [bool]>),
    member: &M,
    mut cost: Option<&mut [Duration]>,
) -> Result<(), MasterError> {
    if let Some(awaiting) = hosts {
        return with_hosts(
            slaves,
            phase,
            outputs,
            (group_slaves, awaiting),
            member,
            cost,
        );
    }
    for (s, slave) in slaves.iter_mut().enumerate() {
        if !member(s, slave) {
            continue;
        }
        let clock = cost.is_some().then(Instant::now);
        work_in(slave, s, (phase, Batch::Whole), outputs, group_slaves)?;
        if let (Some(cost), Some(clock)) = (cost.as_deref_mut(), clock) {
            cost[s] += clock.elapsed();
        }
    }
    Ok(())
}

/// [`sequential`] for a system with instances in host processes: first the
/// requests to the hosts ([`sent_apart`]), then the instances in this
/// process, then the hosts' replies (`awaiting`: per instance, a reply is
/// due). Of several failures the first in file order is returned; every
/// reply due is read.
fn with_hosts<M: Fn(usize, &Slave) -> bool + ?Sized>(
    slaves: &mut [Slave],
    phase: Phase<'_>,
    outputs: &mut Outputs<'_>,
    (group_slaves, awaiting): (&[Vec<usize>], &mut [bool]),
    member: &M,
    mut cost: Option<&mut [Duration]>,
) -> Result<(), MasterError> {
    let mut failure = None;
    for (s, slave) in slaves.iter_mut().enumerate() {
        awaiting[s] = false;
        if member(s, slave) && sent_apart(slave, phase.task) {
            match work_in(slave, s, (phase, Batch::Send), outputs, group_slaves) {
                Ok(sent) => awaiting[s] = sent,
                Err(e) => keep_first(&mut failure, s, e),
            }
        }
    }
    for (s, slave) in slaves.iter_mut().enumerate() {
        if failure.is_some() {
            break;
        }
        if !member(s, slave) || sent_apart(slave, phase.task) {
            continue;
        }
        let clock = cost.is_some().then(Instant::now);
        if let Err(e) = work_in(slave, s, (phase, Batch::Whole), outputs, group_slaves) {
            keep_first(&mut failure, s, e);
        }
        if let (Some(cost), Some(clock)) = (cost.as_deref_mut(), clock) {
            cost[s] += clock.elapsed();
        }
    }
    for (s, slave) in slaves.iter_mut().enumerate() {
        if awaiting[s] {
            let received = work_in(slave, s, (phase, Batch::Receive), outputs, group_slaves);
            if let Err(e) = received {
                keep_first(&mut failure, s, e);
            }
        }
    }
    failure.map_or(Ok(()), |(_, e)| Err(e))
}
