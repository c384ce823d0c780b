//! Parallel perturbed runs (docs/algorithm.md, "Parallel perturbed runs").
//!
//! The perturbed polynomials of a macro step need only the extrapolated
//! unknowns u^p, known before the predictor runs. So the perturbed runs of an
//! instance whose FMU can serialise its state (`canSerializeFMUstate`) and may
//! be instantiated more than once go to copies of the instance on worker
//! threads, started together with the predictor: the state at T_N is
//! serialised on the main thread (`fmi2SerializeFMUstate`) and deserialised
//! into each copy (`fmi2DeSerializeFMUstate`), which is exact — the copy then
//! computes bit for bit what the original would.
//!
//! Workers are persistent threads (one per extra core), each owning one copy
//! of every capable instance; a job is handed over through a mutex and two
//! condition variables, so a macro step allocates nothing.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::polynomial::Taylor;
use crate::slave::Slave;
use crate::spec::InstanceSpec;
use crate::MasterError;

/// Whether perturbed runs go to other threads (`[coupling] parallel`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Parallel {
    /// Measure during the first macro steps, then parallel only if it pays.
    #[default]
    Auto,
    /// Always, for every instance whose FMU allows it.
    On,
    /// Never: every run on the main thread.
    Off,
}

impl std::str::FromStr for Parallel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(Parallel::Auto),
            "on" => Ok(Parallel::On),
            "off" => Ok(Parallel::Off),
            _ => Err(format!("'{s}' is not one of auto, on, off")),
        }
    }
}

/// What the parallel path did in a run.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ParallelInfo {
    /// Worker threads used (0: the run stayed sequential).
    pub workers: usize,
    /// Measured cost of one hand-off: serialising the states, waking the
    /// worker, deserialising, waking the main thread (auto only; zero when
    /// the step costs alone ruled the workers out and none was started).
    pub handoff: Duration,
    /// Predicted predictor + perturbed-run time of one step, sequential.
    pub sequential: Duration,
    /// Predicted time of the same work in parallel, hand-off included.
    pub parallel: Duration,
    /// "auto": shortest measured macro step of the sequential steps.
    pub trial_sequential: Duration,
    /// "auto": shortest measured macro step of the parallel trial steps.
    pub trial_parallel: Duration,
}

/// Macro steps run sequentially (and timed) before "auto" tries the workers.
pub(crate) const CALIBRATION_STEPS: u64 = 3;

/// Macro steps "auto" then runs (and times) in parallel before it decides.
pub(crate) const TRIAL_STEPS: u64 = 3;

/// "auto" keeps the workers only if the parallel trial steps took at most this
/// fraction of the sequential ones (docs/performance.md, "Parallel").
pub(crate) const PAYS: f64 = 0.9;

/// Hand-offs timed for the decision (their median counts).
const HANDOFF_SAMPLES: usize = 7;

/// Less than any hand-off can cost: it wakes a sleeping thread and is woken
/// back, two futex calls and two context switches at the least (measured
/// 8–41 µs on the 2-core machine of docs/performance.md). If the runs of a
/// step could not gain even against this, "auto" decides without starting a
/// worker or timing a hand-off.
pub(crate) const HANDOFF_FLOOR: Duration = Duration::from_micros(2);

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
    k: usize,
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
            extra.restore_state()?;
            extra.apply_inputs(&self.polys[g])?;
            extra.do_step(self.t, self.h)?;
            extra.read_coupled()?;
            self.values[g][s].copy_from_slice(&extra.coupled_values);
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

struct Lane {
    shared: Arc<Shared>,
    handle: Option<JoinHandle<()>>,
}

/// The worker threads and the split of the perturbed runs.
pub(crate) struct Pool {
    mode: Parallel,
    /// Worker threads to start (one per extra core).
    workers: usize,
    /// The started workers: from the start for "on", for "auto" only once
    /// the first steps' costs say they might pay.
    lanes: Vec<Lane>,
    /// What a worker's copy of each capable instance is made from.
    copies: Vec<Option<InstanceSpec>>,
    /// (start, stop, tolerance) the copies are set up with.
    experiment: (f64, f64, Option<f64>),
    /// Per instance: whether its perturbed runs may leave the main thread.
    capable: Vec<bool>,
    /// Per instance: the groups whose run it takes part in.
    runs_of: Vec<Vec<usize>>,
    /// (group, instance) runs on the main thread, after the predictor.
    pub main_runs: Vec<(usize, usize)>,
    /// Perturbed polynomials per group.
    pub polys: Vec<Vec<Taylor>>,
    /// Coupled outputs per group and instance after the perturbed runs.
    pub values: Vec<Vec<Vec<f64>>>,
    /// Serialised states at T_N, per instance.
    bytes: Vec<Vec<u8>>,
    /// Shortest measured `fmi2DoStep` per instance (calibration).
    pub step_cost: Vec<Duration>,
    /// Whether the steps use the workers (auto: after the calibration).
    pub active: bool,
    pub info: ParallelInfo,
    /// Shortest whole macro step of the sequential and the parallel trial steps.
    pub trial: [Duration; 2],
}

impl Pool {
    /// Workers for the capable instances among `slaves`, or `None` if nothing
    /// would run on them (setting off, one core under auto, no capable
    /// instance with perturbed runs).
    pub fn new(
        mode: Parallel,
        slaves: &[Slave],
        specs: &[InstanceSpec],
        groups: &[Vec<usize>],
        owners: &[Vec<usize>],
        experiment: (f64, f64, Option<f64>),
    ) -> Result<Option<Pool>, MasterError> {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let workers = match mode {
            Parallel::Off => return Ok(None),
            Parallel::Auto if cores < 2 => return Ok(None),
            _ => cores.max(2) - 1,
        };
        let mut runs_of = vec![Vec::new(); slaves.len()];
        for (g, group) in groups.iter().enumerate() {
            for &m in group {
                for &s in &owners[m] {
                    if !runs_of[s].contains(&g) {
                        runs_of[s].push(g);
                    }
                }
            }
        }
        let capable: Vec<bool> = slaves
            .iter()
            .zip(&runs_of)
            .map(|(s, runs)| s.is_coupled() && !runs.is_empty() && s.can_run_in_parallel())
            .collect();
        if !capable.contains(&true) {
            return Ok(None);
        }
        let nu = owners.len();
        let values: Vec<Vec<Vec<f64>>> = groups
            .iter()
            .map(|_| {
                slaves
                    .iter()
                    .map(|s| vec![0.0; s.coupled_values.len()])
                    .collect()
            })
            .collect();
        let polys = vec![vec![Taylor::default(); nu]; groups.len()];
        let copies = specs
            .iter()
            .zip(&capable)
            .map(|(spec, &c)| c.then(|| spec.clone()))
            .collect();
        let mut pool = Pool {
            mode,
            workers,
            lanes: Vec::new(),
            copies,
            experiment,
            capable,
            runs_of,
            main_runs: Vec::new(),
            polys,
            values,
            bytes: vec![Vec::new(); slaves.len()],
            step_cost: vec![Duration::MAX; slaves.len()],
            active: false,
            info: ParallelInfo::default(),
            trial: [Duration::MAX; 2],
        };
        if mode == Parallel::On {
            pool.start(slaves)?;
            // Without measurements every run counts the same.
            let unit = vec![Duration::from_micros(1); slaves.len()];
            let lane_runs = pool.assign(&unit, Duration::ZERO, slaves.len());
            pool.hand_out(lane_runs, slaves.len());
            pool.active = true;
            pool.info.workers = pool.lanes.len();
        }
        Ok(Some(pool))
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
                    values: self.values.clone(),
                    t: 0.0,
                    h: 0.0,
                    k: 0,
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

    /// Whether "auto" is still timing the first steps.
    pub fn calibrating(&self, n: u64) -> bool {
        self.mode == Parallel::Auto && !self.active && n < CALIBRATION_STEPS
    }

    /// Whether "auto" starts its parallel trial now.
    pub fn deciding(&self, n: u64) -> bool {
        self.mode == Parallel::Auto && !self.active && n == CALIBRATION_STEPS
    }

    /// Whether "auto" times macro step `n` (sequential or parallel trial).
    pub fn timing(&self, n: u64) -> bool {
        self.mode == Parallel::Auto && n < CALIBRATION_STEPS + TRIAL_STEPS
    }

    /// Record the wall time of macro step `n`.
    pub fn record(&mut self, n: u64, elapsed: Duration) {
        let slot = &mut self.trial[usize::from(n >= CALIBRATION_STEPS)];
        *slot = (*slot).min(elapsed);
    }

    /// "auto", after the trial: whether the parallel steps were at most
    /// [`PAYS`] of the sequential ones.
    pub fn keep(&mut self, n: u64) -> Option<bool> {
        if self.mode != Parallel::Auto || n != CALIBRATION_STEPS + TRIAL_STEPS || !self.active {
            return None;
        }
        let [sequential, parallel] = self.trial;
        let pays = parallel.as_secs_f64() <= PAYS * sequential.as_secs_f64();
        log::info!(
            "parallel perturbed runs: macro step {sequential:?} sequential, {parallel:?} parallel: {}",
            if pays { "on" } else { "off" }
        );
        self.info.trial_sequential = sequential;
        self.info.trial_parallel = parallel;
        if !pays {
            self.info.workers = 0;
        }
        Some(pays)
    }

    /// Split the perturbed runs between the main thread and the workers by
    /// their cost (longest-processing-time greedy, in group order), and
    /// predict the sequential and parallel times of a step's runs. Returns
    /// each worker's (group, instance) runs.
    fn assign(
        &mut self,
        cost: &[Duration],
        handoff: Duration,
        instances: usize,
    ) -> Vec<Vec<(usize, usize)>> {
        let c = |s: usize| cost[s].as_secs_f64();
        self.main_runs.clear();
        let mut lane_runs: Vec<Vec<(usize, usize)>> = vec![Vec::new(); self.workers];
        // Predictor runs stay on the main thread, and so do the perturbed
        // runs of instances that cannot be copied.
        let step = |s: usize| {
            if cost[s] == Duration::MAX {
                0.0
            } else {
                c(s)
            }
        };
        let mut main_load = 0.0;
        let mut sequential = 0.0;
        for s in 0..instances {
            main_load += step(s);
            sequential += step(s) * (1 + self.runs_of[s].len()) as f64;
        }
        let mut runs: Vec<(usize, usize)> = Vec::new();
        for (s, groups) in self.runs_of.iter().enumerate() {
            for &g in groups {
                runs.push((g, s));
            }
        }
        runs.sort_unstable();
        let mut loads = vec![handoff.as_secs_f64(); self.workers];
        for (g, s) in runs {
            let step = step(s);
            let (lane, load) = loads
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .map(|(l, &load)| (l, load))
                .expect("at least one worker");
            if self.capable[s] && load + step < main_load + step {
                loads[lane] += step;
                lane_runs[lane].push((g, s));
            } else {
                main_load += step;
                self.main_runs.push((g, s));
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

    /// "auto": decide from the measured step costs whether the workers might
    /// pay; if so start them, time the hand-off with the states saved at
    /// T_{N-1}, split the runs and start the parallel trial unless the
    /// prediction says it cannot pay. Returns whether the pool stays.
    pub fn decide(&mut self, slaves: &mut [Slave]) -> Result<bool, MasterError> {
        let n = slaves.len();
        let cost = self.step_cost.clone();
        // Not even a hand-off cheaper than any real one would pay: stay
        // sequential without starting a worker (small FMUs pay nothing more).
        let lane_runs = self.assign(&cost, HANDOFF_FLOOR, n);
        let hopeless = |info: &ParallelInfo, runs: &[Vec<(usize, usize)>]| {
            info.parallel >= info.sequential || runs.iter().all(Vec::is_empty)
        };
        if hopeless(&self.info, &lane_runs) {
            log::info!(
                "parallel perturbed runs: predicted runs per step {:?} sequential, {:?} parallel with a hand-off of {HANDOFF_FLOOR:?}: off, no worker started",
                self.info.sequential,
                self.info.parallel,
            );
            self.info.handoff = Duration::ZERO;
            return Ok(false);
        }
        if let Err(e) = self.start(slaves) {
            // The workers are an optimisation: the run goes on without them.
            log::warn!("parallel perturbed runs: cannot start a worker ({e}); staying sequential");
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
            self.dispatch(slaves, 0.0, 0.0, 0)?;
            self.collect()?;
            *sample = clock.elapsed();
        }
        samples.sort_unstable();
        let handoff = samples[HANDOFF_SAMPLES / 2];
        for lane in &self.lanes {
            lock(&lane.shared).copy_only = false;
        }
        let lane_runs = self.assign(&cost, handoff, n);
        // Try the workers if the prediction from the measured FMU steps and
        // hand-off is not hopeless; the trial steps decide.
        let pays = !hopeless(&self.info, &lane_runs);
        self.hand_out(lane_runs, n);
        log::info!(
            "parallel perturbed runs: hand-off {:?}, predicted runs per step {:?} sequential, {:?} parallel: {}",
            handoff,
            self.info.sequential,
            self.info.parallel,
            if pays { "trying" } else { "off" }
        );
        self.active = pays;
        if pays {
            self.info.workers = self.lanes.len();
        }
        Ok(pays)
    }

    /// Hand the states at T_N and the perturbed polynomials to the workers.
    /// Every capable instance has saved its state.
    pub fn dispatch(
        &mut self,
        slaves: &mut [Slave],
        t: f64,
        h: f64,
        k: usize,
    ) -> Result<(), MasterError> {
        for (s, slave) in slaves.iter_mut().enumerate() {
            if self.capable[s] {
                slave.serialize_saved(&mut self.bytes[s])?;
            }
        }
        for lane in &self.lanes {
            let mut job = lock(&lane.shared);
            let job = &mut *job;
            for &s in &job.used {
                job.bytes[s].clear();
                job.bytes[s].extend_from_slice(&self.bytes[s]);
            }
            for &(g, _) in &job.runs {
                job.polys[g].copy_from_slice(&self.polys[g]);
            }
            job.t = t;
            job.h = h;
            job.k = k;
            job.phase = Phase::Pending;
            lane.shared.start.notify_one();
        }
        Ok(())
    }

    /// Wait for the workers and copy their outputs into `values`.
    pub fn collect(&mut self) -> Result<(), MasterError> {
        let mut failure = None;
        for lane in &self.lanes {
            let mut job = lock(&lane.shared);
            while job.phase == Phase::Pending {
                job = lane
                    .shared
                    .done
                    .wait(job)
                    .unwrap_or_else(PoisonError::into_inner);
            }
            job.phase = Phase::Idle;
            if let Some(e) = job.error.take() {
                failure.get_or_insert(e);
                continue;
            }
            for &(g, s) in &job.runs {
                self.values[g][s].copy_from_slice(&job.values[g][s]);
            }
        }
        failure.map_or(Ok(()), Err)
    }

    /// Add the copies' FMI calls to the originals' counters (before the pool
    /// goes away), and zero them.
    pub fn fold_counters(&self, slaves: &mut [Slave]) {
        for (s, slave) in slaves.iter_mut().enumerate() {
            self.add_counters(s, &mut slave.counters);
        }
        for lane in &self.lanes {
            for extra in lock(&lane.shared).extras.iter_mut().flatten() {
                let name = std::mem::take(&mut extra.counters.name);
                extra.counters = crate::InstanceCounters {
                    name,
                    ..Default::default()
                };
            }
        }
    }

    /// FMI calls made by the copies of instance `s`.
    pub fn add_counters(&self, s: usize, into: &mut crate::InstanceCounters) {
        for lane in &self.lanes {
            if let Some(extra) = &lock(&lane.shared).extras[s] {
                let c = &extra.counters;
                into.do_steps += c.do_steps;
                into.state_sets += c.state_sets;
                into.set_reals += c.set_reals;
                into.get_reals += c.get_reals;
                into.set_input_derivatives += c.set_input_derivatives;
                into.get_output_derivatives += c.get_output_derivatives;
            }
        }
    }
}

impl Drop for Pool {
    fn drop(&mut self) {
        for lane in &mut self.lanes {
            {
                let mut job = lock(&lane.shared);
                while job.phase == Phase::Pending {
                    job = lane
                        .shared
                        .done
                        .wait(job)
                        .unwrap_or_else(PoisonError::into_inner);
                }
                job.phase = Phase::Quit;
                lane.shared.start.notify_one();
            }
            if let Some(handle) = lane.handle.take() {
                let _ = handle.join();
            }
        }
    }
}
