//! Perturbed runs shared with worker threads (docs/algorithm.md, "Parallel
//! perturbed runs").
//!
//! The perturbed runs of an instance whose FMU can serialise its state
//! (`canSerializeFMUstate`) and may be instantiated more than once can go to a
//! copy of the instance on a worker thread: the state at T_N is serialised on
//! the main thread (`fmi2SerializeFMUstate`) and deserialised into the copy
//! (`fmi2DeSerializeFMUstate`), which is exact — the copy then computes bit
//! for bit what the original would.
//!
//! Workers are persistent threads (one per extra core), each owning one copy
//! of every capable instance; a job is handed over through a mutex and two
//! condition variables, so a macro step allocates nothing. Under "auto" the
//! strategy measures the first steps' runs sequentially, tries the workers
//! for a few steps, and keeps them only if they paid.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::algorithm::runs::{predictor_runs, Perturbed, PerturbedRuns, Sequential};
use crate::polynomial::Taylor;
use crate::slave::Slave;
use crate::spec::{InstanceSpec, Parallel};
use crate::stats::{InstanceCounters, ParallelInfo, RunStats};
use crate::MasterError;

/// Macro steps whose runs "auto" makes sequentially (and times) first.
const CALIBRATION_STEPS: u32 = 3;

/// Macro steps "auto" then runs (and times) in parallel before it decides.
const TRIAL_STEPS: u32 = 3;

/// "auto" keeps the workers only if the parallel runs took at most this
/// fraction of the sequential ones.
const PAYS: f64 = 0.9;

/// Hand-offs timed for the decision (their median counts).
const HANDOFF_SAMPLES: usize = 7;

/// Less than any hand-off can cost: it wakes a sleeping thread and is woken
/// back, two futex calls and two context switches at the least. If the runs
/// of a step could not gain even against this, "auto" decides without
/// starting a worker or timing a hand-off.
const HANDOFF_FLOOR: Duration = Duration::from_micros(2);

/// The runs strategy for `mode`: worker threads where some instance's runs
/// can go to a copy (and, for "auto", the machine has a second core);
/// otherwise every run on the main thread.
pub(crate) fn strategy(
    mode: Parallel,
    slaves: &[Slave],
    specs: &[InstanceSpec],
    group_slaves: &[Vec<usize>],
    unknowns: usize,
    experiment: (f64, f64, Option<f64>),
) -> Result<Box<dyn PerturbedRuns>, MasterError> {
    let sequential = Sequential {
        group_slaves: group_slaves.to_vec(),
    };
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let workers = match mode {
        Parallel::Off => return Ok(Box::new(sequential)),
        Parallel::Auto if cores < 2 => return Ok(Box::new(sequential)),
        _ => cores.max(2) - 1,
    };
    let mut capable = vec![false; slaves.len()];
    for &s in group_slaves.iter().flatten() {
        capable[s] = slaves[s].can_run_in_parallel();
    }
    if !capable.contains(&true) {
        return Ok(Box::new(sequential));
    }
    let outputs = group_slaves
        .iter()
        .map(|_| slaves.iter().map(|s| vec![0.0; s.coupled_len()]).collect())
        .collect();
    let mut threads = Threads {
        auto: mode == Parallel::Auto,
        workers,
        lanes: Vec::new(),
        copies: specs
            .iter()
            .zip(&capable)
            .map(|(spec, &c)| c.then(|| spec.clone()))
            .collect(),
        experiment,
        capable,
        sequential,
        main_runs: Vec::new(),
        polys: vec![vec![Taylor::default(); unknowns]; group_slaves.len()],
        outputs,
        bytes: vec![Vec::new(); slaves.len()],
        steps: 0,
        run_cost: vec![Duration::MAX; slaves.len()],
        trial: [Duration::MAX; 2],
        active: false,
        info: ParallelInfo::default(),
        retired: vec![InstanceCounters::default(); slaves.len()],
    };
    if mode == Parallel::On {
        threads.start(slaves)?;
        // Without measurements every run counts the same.
        let unit = vec![Duration::from_micros(1); slaves.len()];
        let lane_runs = threads.assign(&unit, Duration::ZERO);
        threads.hand_out(lane_runs, slaves.len());
        threads.active = true;
        threads.info.workers = threads.lanes.len();
    }
    Ok(Box::new(threads))
}

/// Perturbed runs split between the main thread and worker threads.
struct Threads {
    /// "auto" (measure, try, decide) rather than "on".
    auto: bool,
    /// Worker threads to start (one per extra core).
    workers: usize,
    /// The started workers: from the start for "on", for "auto" only once
    /// the first steps' costs say they might pay.
    lanes: Vec<Lane>,
    /// What a worker's copy of each capable instance is made from.
    copies: Vec<Option<InstanceSpec>>,
    /// (start, stop, tolerance) the copies are set up with.
    experiment: (f64, f64, Option<f64>),
    /// Per instance: whether its runs may leave the main thread.
    capable: Vec<bool>,
    /// The runs on the main thread alone (before and without workers).
    sequential: Sequential,
    /// (group, instance) runs on the main thread while the workers run theirs.
    main_runs: Vec<(usize, usize)>,
    /// Shapes of a job's perturbed polynomials and outputs (per group).
    polys: Vec<Vec<Taylor>>,
    outputs: Vec<Vec<Vec<f64>>>,
    /// Serialised states at T_N, per instance.
    bytes: Vec<Vec<u8>>,
    /// "auto": macro steps run so far.
    steps: u32,
    /// "auto": shortest measured perturbed run per instance.
    run_cost: Vec<Duration>,
    /// "auto": shortest run phase of the sequential and the parallel steps.
    trial: [Duration; 2],
    /// Whether the runs use the workers.
    active: bool,
    info: ParallelInfo,
    /// FMI calls of copies whose workers were stopped, per instance.
    retired: Vec<InstanceCounters>,
}

impl PerturbedRuns for Threads {
    fn run(
        &mut self,
        slaves: &mut [Slave],
        t: f64,
        h: f64,
        polys: &[Vec<Taylor>],
        outputs: &mut [Vec<Vec<f64>>],
    ) -> Result<(), MasterError> {
        if !self.auto {
            return self.run_parallel(slaves, t, h, polys, outputs);
        }
        let step = self.steps;
        self.steps = self.steps.saturating_add(1);
        if step < CALIBRATION_STEPS {
            return self.run_timed(slaves, t, h, polys, outputs);
        }
        if step == CALIBRATION_STEPS {
            self.active = self.decide(slaves)?;
        }
        if !self.active {
            return self.sequential.run(slaves, t, h, polys, outputs);
        }
        if step >= CALIBRATION_STEPS + TRIAL_STEPS {
            return self.run_parallel(slaves, t, h, polys, outputs);
        }
        let clock = Instant::now();
        self.run_parallel(slaves, t, h, polys, outputs)?;
        self.trial[1] = self.trial[1].min(clock.elapsed());
        if step + 1 == CALIBRATION_STEPS + TRIAL_STEPS {
            self.keep_or_stop();
        }
        Ok(())
    }

    fn predict(
        &mut self,
        slaves: &mut [Slave],
        (t, h): (f64, f64),
        polys: &[Taylor],
        predicted: &mut [Vec<f64>],
        perturbed: Option<Perturbed<'_>>,
    ) -> Result<(), MasterError> {
        // "auto" decided for the main thread: its runs go as sequentially.
        let decided = self.auto && self.steps > CALIBRATION_STEPS && !self.active;
        match perturbed {
            Some(perturbed) if decided => {
                self.sequential
                    .predict(slaves, (t, h), polys, predicted, Some(perturbed))
            }
            Some((runs, outputs)) => {
                predictor_runs(slaves, (t, h), polys, predicted)?;
                self.run(slaves, t, h, runs, outputs)
            }
            None => predictor_runs(slaves, (t, h), polys, predicted),
        }
    }

    fn terminate(&mut self) -> Result<(), MasterError> {
        for lane in &self.lanes {
            // The worker is idle between jobs: its copies are ours to call.
            let mut job = lane.wait();
            for extra in job.extras.iter_mut().flatten() {
                extra.terminate()?;
            }
        }
        Ok(())
    }

    fn report(&self, stats: &mut RunStats) {
        stats.parallel = self.info;
        for (s, counters) in stats.instances.iter_mut().enumerate() {
            add(counters, &self.retired[s]);
            for lane in &self.lanes {
                if let Some(extra) = &lock(&lane.shared).extras[s] {
                    add(counters, &extra.counters());
                }
            }
        }
    }
}

impl Threads {
    /// "auto", first steps: every run on the main thread, each run and the
    /// whole phase timed.
    fn run_timed(
        &mut self,
        slaves: &mut [Slave],
        t: f64,
        h: f64,
        polys: &[Vec<Taylor>],
        outputs: &mut [Vec<Vec<f64>>],
    ) -> Result<(), MasterError> {
        let phase = Instant::now();
        for (g, members) in self.sequential.group_slaves.iter().enumerate() {
            for &s in members {
                let clock = Instant::now();
                slaves[s].rerun(&polys[g], t, h, Some(&mut outputs[g][s]))?;
                self.run_cost[s] = self.run_cost[s].min(clock.elapsed());
            }
        }
        self.trial[0] = self.trial[0].min(phase.elapsed());
        Ok(())
    }

    /// The runs split between the main thread and the workers: the saved
    /// states and the polynomials go to the workers, the main thread makes
    /// its share, then collects theirs.
    fn run_parallel(
        &mut self,
        slaves: &mut [Slave],
        t: f64,
        h: f64,
        polys: &[Vec<Taylor>],
        outputs: &mut [Vec<Vec<f64>>],
    ) -> Result<(), MasterError> {
        self.dispatch(slaves, Some((t, h, polys)))?;
        for &(g, s) in &self.main_runs {
            slaves[s].rerun(&polys[g], t, h, Some(&mut outputs[g][s]))?;
        }
        self.collect(Some(outputs))
    }

    /// "auto", after the parallel trial: keep the workers only if the
    /// parallel runs took at most [`PAYS`] of the sequential ones.
    fn keep_or_stop(&mut self) {
        let [sequential, parallel] = self.trial;
        let pays = parallel.as_secs_f64() <= PAYS * sequential.as_secs_f64();
        log::info!(
            "parallel perturbed runs: {sequential:?} sequential, {parallel:?} parallel: {}",
            if pays { "on" } else { "off" }
        );
        self.info.trial_sequential = sequential;
        self.info.trial_parallel = parallel;
        if !pays {
            self.info.workers = 0;
            self.stop();
        }
    }

    /// Join the workers and free the copies, keeping their FMI call counts.
    fn stop(&mut self) {
        for lane in &self.lanes {
            for (s, extra) in lock(&lane.shared).extras.iter().enumerate() {
                if let Some(extra) = extra {
                    add(&mut self.retired[s], &extra.counters());
                }
            }
        }
        self.lanes.clear();
        self.active = false;
    }

    /// Start the workers, each with its own copy of every capable instance
    /// (instantiated and initialised like the original; its state is loaded
    /// from the original's before each job).
    fn start(&mut self, slaves: &[Slave]) -> Result<(), MasterError> {
        self.lanes.reserve(self.workers);
        for w in 0..self.workers {
            let mut extras = Vec::with_capacity(slaves.len());
            for (slave, copy) in slaves.iter().zip(&self.copies) {
                extras.push(match copy {
                    Some(spec) => Some(slave.duplicate(spec, w + 1, self.experiment)?),
                    None => None,
                });
            }
            let shared = Arc::new(Shared {
                job: Mutex::new(Job {
                    extras,
                    bytes: vec![Vec::new(); slaves.len()],
                    used: Vec::new(),
                    runs: Vec::new(),
                    copy_only: false,
                    polys: self.polys.clone(),
                    values: self.outputs.clone(),
                    t: 0.0,
                    h: 0.0,
                    phase: Phase::Idle,
                    error: None,
                }),
                start: Condvar::new(),
                done: Condvar::new(),
            });
            let handle = std::thread::Builder::new()
                .name(format!("tether-worker-{}", w + 1))
                .spawn({
                    let shared = Arc::clone(&shared);
                    move || worker(shared)
                })
                .map_err(|e| MasterError::Thread(e.to_string()))?;
            self.lanes.push(Lane {
                shared,
                handle: Some(handle),
            });
        }
        Ok(())
    }

    /// Split the perturbed runs between the main thread and the workers by
    /// their cost (greedy, in group order: each run to whichever of the main
    /// thread and the workers has the least load so far; a worker starts
    /// with the hand-off's cost), and predict the sequential and parallel
    /// times of a step's runs. Returns each worker's (group, instance) runs.
    fn assign(&mut self, cost: &[Duration], handoff: Duration) -> Vec<Vec<(usize, usize)>> {
        let c = |s: usize| {
            if cost[s] == Duration::MAX {
                0.0
            } else {
                cost[s].as_secs_f64()
            }
        };
        self.main_runs.clear();
        let mut lane_runs: Vec<Vec<(usize, usize)>> = vec![Vec::new(); self.workers];
        let mut main_load = 0.0;
        let mut sequential = 0.0;
        let mut loads = vec![handoff.as_secs_f64(); self.workers];
        for (g, members) in self.sequential.group_slaves.iter().enumerate() {
            for &s in members {
                let step = c(s);
                sequential += step;
                let (lane, load) = loads
                    .iter()
                    .enumerate()
                    .min_by(|a, b| a.1.total_cmp(b.1))
                    .map(|(l, &load)| (l, load))
                    .expect("at least one worker");
                if self.capable[s] && load < main_load {
                    loads[lane] += step;
                    lane_runs[lane].push((g, s));
                } else {
                    main_load += step;
                    self.main_runs.push((g, s));
                }
            }
        }
        let parallel = loads.iter().copied().fold(main_load, f64::max);
        self.info.sequential = Duration::from_secs_f64(sequential);
        self.info.parallel = Duration::from_secs_f64(parallel);
        self.info.handoff = handoff;
        lane_runs
    }

    /// Give each started worker its runs (from [`assign`](Self::assign)).
    fn hand_out(&self, lane_runs: Vec<Vec<(usize, usize)>>, instances: usize) {
        for (lane, runs) in self.lanes.iter().zip(lane_runs) {
            let mut job = lock(&lane.shared);
            job.used = (0..instances)
                .filter(|&s| runs.iter().any(|&(_, r)| r == s))
                .collect();
            job.runs = runs;
        }
    }

    /// "auto": decide from the measured run costs whether the workers might
    /// pay; if so start them, time the hand-off, split the runs and start
    /// the parallel trial unless the prediction says it cannot pay. Returns
    /// whether the trial starts.
    fn decide(&mut self, slaves: &mut [Slave]) -> Result<bool, MasterError> {
        let n = slaves.len();
        let cost = self.run_cost.clone();
        self.info.trial_sequential = self.trial[0];
        let hopeless = |info: &ParallelInfo, runs: &[Vec<(usize, usize)>]| {
            info.parallel >= info.sequential || runs.iter().all(Vec::is_empty)
        };
        // Not even a hand-off cheaper than any real one would pay: stay
        // sequential without starting a worker (small FMUs pay nothing more).
        let lane_runs = self.assign(&cost, HANDOFF_FLOOR);
        if hopeless(&self.info, &lane_runs) {
            log::info!(
                "parallel perturbed runs: predicted {:?} a step sequential, {:?} parallel with a hand-off of {HANDOFF_FLOOR:?}: off, no worker started",
                self.info.sequential,
                self.info.parallel,
            );
            self.info.handoff = Duration::ZERO;
            return Ok(false);
        }
        if let Err(e) = self.start(slaves) {
            // The workers are an optimisation: the run goes on without them.
            log::warn!("parallel perturbed runs: cannot start a worker ({e}); staying sequential");
            self.lanes.clear();
            self.info = ParallelInfo::default();
            return Ok(false);
        }
        // Every capable instance's state crosses over while timing.
        for lane in &self.lanes {
            let mut job = lock(&lane.shared);
            job.used = (0..n).filter(|&s| self.capable[s]).collect();
            job.copy_only = true;
        }
        let mut samples = [Duration::ZERO; HANDOFF_SAMPLES];
        for sample in &mut samples {
            let clock = Instant::now();
            self.dispatch(slaves, None)?;
            self.collect(None)?;
            *sample = clock.elapsed();
        }
        samples.sort_unstable();
        let handoff = samples[HANDOFF_SAMPLES / 2];
        for lane in &self.lanes {
            lock(&lane.shared).copy_only = false;
        }
        let lane_runs = self.assign(&cost, handoff);
        let pays = !hopeless(&self.info, &lane_runs);
        self.hand_out(lane_runs, n);
        log::info!(
            "parallel perturbed runs: hand-off {:?}, predicted {:?} a step sequential, {:?} parallel: {}",
            handoff,
            self.info.sequential,
            self.info.parallel,
            if pays { "trying" } else { "off" }
        );
        if pays {
            self.info.workers = self.lanes.len();
        } else {
            self.stop();
        }
        Ok(pays)
    }

    /// Hand the saved states at T_N (serialised) and, unless only the
    /// hand-off is timed, the step and its polynomials to the workers.
    fn dispatch(
        &mut self,
        slaves: &mut [Slave],
        job: Option<(f64, f64, &[Vec<Taylor>])>,
    ) -> Result<(), MasterError> {
        for (s, slave) in slaves.iter_mut().enumerate() {
            if self.capable[s] {
                slave.serialize_saved(&mut self.bytes[s])?;
            }
        }
        for lane in &self.lanes {
            let mut guard = lock(&lane.shared);
            let state = &mut *guard;
            for &s in &state.used {
                state.bytes[s].clear();
                state.bytes[s].extend_from_slice(&self.bytes[s]);
            }
            if let Some((t, h, polys)) = job {
                for &(g, _) in &state.runs {
                    state.polys[g].copy_from_slice(&polys[g]);
                }
                state.t = t;
                state.h = h;
            }
            state.phase = Phase::Pending;
            lane.shared.start.notify_one();
        }
        Ok(())
    }

    /// Wait for the workers and copy their outputs into `outputs`.
    fn collect(&mut self, mut outputs: Option<&mut [Vec<Vec<f64>>]>) -> Result<(), MasterError> {
        let mut failure = None;
        for lane in &self.lanes {
            let mut job = lane.wait();
            job.phase = Phase::Idle;
            if let Some(e) = job.error.take() {
                failure.get_or_insert(e);
                continue;
            }
            if let Some(outputs) = outputs.as_deref_mut() {
                for &(g, s) in &job.runs {
                    outputs[g][s].copy_from_slice(&job.values[g][s]);
                }
            }
        }
        failure.map_or(Ok(()), Err)
    }
}

/// Add `from`'s FMI calls to `into`'s.
fn add(into: &mut InstanceCounters, from: &InstanceCounters) {
    into.do_steps += from.do_steps;
    into.state_sets += from.state_sets;
    into.set_reals += from.set_reals;
    into.get_reals += from.get_reals;
    into.set_input_derivatives += from.set_input_derivatives;
    into.get_output_derivatives += from.get_output_derivatives;
    into.round_trips += from.round_trips;
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Idle,
    Pending,
    Done,
    Quit,
}

/// What one worker computes; owned by the mutex between hand-offs.
struct Job {
    /// This worker's copy of each capable instance.
    extras: Vec<Option<Slave>>,
    /// Serialised state at T_N, per instance.
    bytes: Vec<Vec<u8>>,
    /// Instances whose state this worker loads each step.
    used: Vec<usize>,
    /// (group, instance) runs of this worker.
    runs: Vec<(usize, usize)>,
    /// Skip the runs (timing the hand-off alone).
    copy_only: bool,
    /// Perturbed polynomials per group.
    polys: Vec<Vec<Taylor>>,
    /// Coupled outputs per group and instance after the runs.
    values: Vec<Vec<Vec<f64>>>,
    t: f64,
    h: f64,
    phase: Phase,
    error: Option<MasterError>,
}

impl Job {
    fn work(&mut self) -> Result<(), MasterError> {
        for &s in &self.used {
            let extra = self.extras[s].as_mut().expect("capable instance");
            extra.load_serialized(&self.bytes[s])?;
        }
        if self.copy_only {
            return Ok(());
        }
        for &(g, s) in &self.runs {
            let extra = self.extras[s].as_mut().expect("capable instance");
            extra.rerun(&self.polys[g], self.t, self.h, Some(&mut self.values[g][s]))?;
        }
        Ok(())
    }
}

struct Shared {
    job: Mutex<Job>,
    start: Condvar,
    done: Condvar,
}

fn lock(shared: &Shared) -> MutexGuard<'_, Job> {
    shared.job.lock().unwrap_or_else(PoisonError::into_inner)
}

fn worker(shared: Arc<Shared>) {
    let mut job = lock(&shared);
    loop {
        match job.phase {
            Phase::Pending => {
                let outcome = catch_unwind(AssertUnwindSafe(|| job.work()));
                job.error = match outcome {
                    Ok(result) => result.err(),
                    Err(_) => Some(MasterError::Worker),
                };
                job.phase = Phase::Done;
                shared.done.notify_one();
            }
            Phase::Quit => return,
            Phase::Idle | Phase::Done => {
                job = shared
                    .start
                    .wait(job)
                    .unwrap_or_else(PoisonError::into_inner);
            }
        }
    }
}

/// One worker thread and its job.
struct Lane {
    shared: Arc<Shared>,
    handle: Option<JoinHandle<()>>,
}

impl Lane {
    /// The job once the worker has finished it.
    fn wait(&self) -> MutexGuard<'_, Job> {
        let mut job = lock(&self.shared);
        while job.phase == Phase::Pending {
            job = self
                .shared
                .done
                .wait(job)
                .unwrap_or_else(PoisonError::into_inner);
        }
        job
    }
}

impl Drop for Lane {
    fn drop(&mut self) {
        {
            let mut job = self.wait();
            job.phase = Phase::Quit;
            self.shared.start.notify_one();
        }
        if let Some(handle) = self.handle.take() {
            let _ = handle.join();
        }
    }
}
