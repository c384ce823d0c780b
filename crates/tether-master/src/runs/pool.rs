//! Worker threads for the runs of a macro step (docs/algorithm.md,
//! "Parallel runs").
//!
//! The workers are persistent threads started once; each instance is
//! assigned to the main thread or to one worker ([`Pool::assign`]). A phase
//! hands each worker the instances it makes the phase's task on — moved to
//! it, with the buffers their outputs go to, so each is on one thread at a
//! time and nothing is shared — while the main thread makes its own; then
//! every instance moves back to its place. A hand-off goes through a mutex
//! and two condition variables and moves values whose allocations are kept,
//! so a phase allocates nothing.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::polynomial::Taylor;
use crate::runs::{sent_apart, sequential, work, Outputs, Phase, Task};
use crate::slave::{Batch, Slave};
use crate::MasterError;

/// One instance while a phase moves it: the instance, the buffers of its
/// outputs, the outcome of its task.
#[derive(Default)]
struct Seat {
    /// The instance's index in file order.
    s: usize,
    slave: Option<Slave>,
    /// Its own outputs (predicted or accepted).
    out: Vec<f64>,
    /// Per perturbation group that steps it: (group, the run's outputs).
    runs: Vec<(usize, Vec<f64>)>,
    /// Its task's time, when timed.
    cost: Duration,
    /// A host process's reply is due ([`Batch::Send`]).
    awaiting: bool,
    error: Option<MasterError>,
}

impl Seat {
    /// The seat's task of `phase` (or its request or reply, `how`), timed
    /// with `timed`; a panic becomes [`MasterError::Worker`]. After a
    /// failure the seat does nothing more in the phase.
    fn work(&mut self, phase: Phase<'_>, timed: bool, how: Batch) {
        if self.error.is_some() {
            return;
        }
        let clock = timed.then(Instant::now);
        let Seat {
            slave, out, runs, ..
        } = self;
        let slave = slave.as_mut().expect("a seated instance");
        let perturbed = !phase.perturbed.is_empty();
        let runs = runs
            .iter_mut()
            .filter(|_| perturbed)
            .map(|(g, out)| (&phase.perturbed[*g][..], &mut out[..]));
        let outcome = catch_unwind(AssertUnwindSafe(|| work(slave, phase, out, runs, how)));
        match outcome {
            Ok(Ok(awaiting)) => self.awaiting = awaiting,
            Ok(Err(e)) => self.error = Some(e),
            Err(_) => {
                let instance = self
                    .slave
                    .as_ref()
                    .map(|s| s.name.clone())
                    .unwrap_or_default();
                self.error = Some(MasterError::Worker { instance });
            }
        }
        if let Some(clock) = clock {
            self.cost = clock.elapsed();
        }
    }
}

/// The worker threads and the instances' places.
pub(crate) struct Pool {
    lanes: Vec<Lane>,
    /// Per instance: its worker (None: the main thread).
    lane_of: Vec<Option<usize>>,
    /// Per instance: its seat while a phase runs (its buffers kept between
    /// phases).
    seats: Vec<Seat>,
    /// Per instance: whether this phase's task is its.
    member: Vec<bool>,
    /// Some instance runs in a host process.
    hosts: bool,
    /// Per instance: a host process's reply is due (phases without workers).
    awaiting: Vec<bool>,
    /// Per group, the instances its perturbed run steps.
    group_slaves: Vec<Vec<usize>>,
}

impl Pool {
    /// Start `workers` threads for `instances` instances (all on the main
    /// thread until [`assign`](Self::assign)ed); `(group_slaves, unknowns)`
    /// size the buffers of a phase's polynomials; `hosts`: some instance
    /// runs in a host process.
    pub fn start(
        workers: usize,
        instances: usize,
        (group_slaves, unknowns): (&[Vec<usize>], usize),
        hosts: bool,
    ) -> Result<Pool, MasterError> {
        let seats = (0..instances)
            .map(|s| Seat {
                s,
                runs: group_slaves
                    .iter()
                    .enumerate()
                    .filter(|(_, members)| members.contains(&s))
                    .map(|(g, _)| (g, Vec::new()))
                    .collect(),
                ..Seat::default()
            })
            .collect();
        let mut lanes = Vec::with_capacity(workers);
        for w in 0..workers {
            let shared = Arc::new(Shared {
                job: Mutex::new(Job {
                    seats: Vec::with_capacity(instances),
                    task: Task::Step,
                    t: 0.0,
                    h: 0.0,
                    polys: Vec::with_capacity(unknowns),
                    perturbed: vec![vec![Taylor::default(); unknowns]; group_slaves.len()],
                    with_perturbed: false,
                    timed: false,
                    state: State::Idle,
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
            lanes.push(Lane {
                shared,
                handle: Some(handle),
            });
        }
        Ok(Pool {
            lanes,
            lane_of: vec![None; instances],
            seats,
            member: vec![false; instances],
            hosts,
            awaiting: vec![false; instances],
            group_slaves: group_slaves.to_vec(),
        })
    }

    pub fn workers(&self) -> usize {
        self.lanes.len()
    }

    /// Each instance's worker from now on (None: the main thread).
    pub fn assign(&mut self, lane_of: Vec<Option<usize>>) {
        self.lane_of = lane_of;
    }

    /// Whether some instance is assigned to a worker.
    pub fn has_work(&self) -> bool {
        self.lane_of.iter().any(Option::is_some)
    }

    /// The time of one empty hand-off to every worker and back.
    pub fn time_handoff(&mut self) -> Duration {
        let clock = Instant::now();
        for lane in &self.lanes {
            let mut job = lock(&lane.shared);
            job.state = State::Pending;
            lane.shared.start.notify_one();
        }
        for lane in &self.lanes {
            lane.wait().state = State::Idle;
        }
        clock.elapsed()
    }

    /// `phase`'s task on every instance `member` selects: those assigned
    /// to a worker there, the others here, each task's time into `cost`
    /// when given. Every instance is back in `slaves`, in its place, when
    /// this returns; of several failures, the first in file order is
    /// returned.
    pub fn run(
        &mut self,
        slaves: &mut Vec<Slave>,
        phase: Phase<'_>,
        outputs: &mut Outputs<'_>,
        member: &dyn Fn(usize, &Slave) -> bool,
        mut cost: Option<&mut [Duration]>,
    ) -> Result<(), MasterError> {
        for (s, (m, slave)) in self.member.iter_mut().zip(slaves.iter()).enumerate() {
            *m = member(s, slave);
        }
        let shared_out = (0..slaves.len()).any(|s| self.member[s] && self.lane_of[s].is_some());
        if !shared_out {
            let hosts = self.hosts.then_some(&mut self.awaiting[..]);
            let shape = (&self.group_slaves[..], hosts);
            return sequential(slaves, phase, outputs, shape, member, cost);
        }
        // Every instance to its seat, the members with their buffers.
        let mut all = std::mem::take(slaves);
        for (seat, slave) in self.seats.iter_mut().zip(all.drain(..)) {
            seat.slave = Some(slave);
        }
        let perturbed = !phase.perturbed.is_empty();
        for (s, seat) in self.seats.iter_mut().enumerate() {
            if !self.member[s] {
                continue;
            }
            if let Some(out) = outputs.own.get_mut(s) {
                std::mem::swap(&mut seat.out, out);
            }
            if perturbed {
                for (g, out) in &mut seat.runs {
                    std::mem::swap(out, &mut outputs.perturbed[*g][s]);
                }
            }
        }
        let timed = cost.is_some();
        // Requests to host processes first (they stay on this thread).
        for (s, seat) in self.seats.iter_mut().enumerate() {
            let slave = seat.slave.as_ref().expect("seated");
            if self.member[s] && sent_apart(slave, phase.task) {
                seat.work(phase, false, Batch::Send);
            }
        }
        for (l, lane) in self.lanes.iter().enumerate() {
            let mut guard = lock(&lane.shared);
            let job = &mut *guard;
            for (s, seat) in self.seats.iter_mut().enumerate() {
                if self.member[s] && self.lane_of[s] == Some(l) {
                    job.seats.push(std::mem::take(seat));
                }
            }
            if job.seats.is_empty() {
                continue;
            }
            job.task = phase.task;
            job.t = phase.t;
            job.h = phase.h;
            job.polys.clear();
            job.polys.extend_from_slice(phase.polys);
            job.with_perturbed = perturbed;
            if perturbed {
                for (to, from) in job.perturbed.iter_mut().zip(phase.perturbed) {
                    to.copy_from_slice(from);
                }
            }
            job.timed = timed;
            job.state = State::Pending;
            lane.shared.start.notify_one();
        }
        for (s, seat) in self.seats.iter_mut().enumerate() {
            if !self.member[s] || self.lane_of[s].is_some() {
                continue;
            }
            let slave = seat.slave.as_ref().expect("seated");
            if !sent_apart(slave, phase.task) {
                seat.work(phase, timed, Batch::Whole);
            }
        }
        for seat in &mut self.seats {
            if std::mem::take(&mut seat.awaiting) {
                seat.work(phase, false, Batch::Receive);
            }
        }
        for lane in &self.lanes {
            let mut job = lane.wait();
            job.state = State::Idle;
            for seat in job.seats.drain(..) {
                let s = seat.s;
                self.seats[s] = seat;
            }
        }
        // Every instance back, the members' buffers too; the first failure.
        let mut failure = None;
        for (s, seat) in self.seats.iter_mut().enumerate() {
            if self.member[s] {
                if let Some(out) = outputs.own.get_mut(s) {
                    std::mem::swap(&mut seat.out, out);
                }
                if perturbed {
                    for (g, out) in &mut seat.runs {
                        std::mem::swap(out, &mut outputs.perturbed[*g][s]);
                    }
                }
                if let Some(cost) = cost.as_deref_mut() {
                    cost[s] += seat.cost;
                }
                if let Some(e) = seat.error.take() {
                    failure.get_or_insert(e);
                }
            }
            all.push(
                seat.slave
                    .take()
                    .expect("every instance is back in its seat"),
            );
        }
        *slaves = all;
        failure.map_or(Ok(()), Err)
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    Idle,
    Pending,
    Done,
    Quit,
}

/// What one worker does; owned by the mutex between hand-offs.
struct Job {
    /// The instances whose task this worker makes, with their buffers.
    seats: Vec<Seat>,
    /// The phase, its polynomials copied.
    task: Task,
    t: f64,
    h: f64,
    polys: Vec<Taylor>,
    perturbed: Vec<Vec<Taylor>>,
    with_perturbed: bool,
    timed: bool,
    state: State,
}

impl Job {
    fn work(&mut self) {
        let phase = Phase {
            task: self.task,
            t: self.t,
            h: self.h,
            polys: &self.polys,
            perturbed: if self.with_perturbed {
                &self.perturbed
            } else {
                &[]
            },
        };
        for seat in &mut self.seats {
            seat.work(phase, self.timed, Batch::Whole);
        }
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
        match job.state {
            State::Pending => {
                job.work();
                job.state = State::Done;
                shared.done.notify_one();
            }
            State::Quit => return,
            State::Idle | State::Done => {
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
        while job.state == State::Pending {
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
            job.state = State::Quit;
            self.shared.start.notify_one();
        }
        if let Some(handle) = self.handle.take() {
            let _ = handle.join();
        }
    }
}
