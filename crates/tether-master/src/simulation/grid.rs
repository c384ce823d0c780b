//! The time grid of a run: the uniform grid T_N = T_0 + N·H (integer step
//! counts, no accumulated sums) or adaptive macro steps under a step-size
//! controller, behind one type. [`Grid::advance`] takes one accepted step
//! with a given try of the method and reports the step it took, as
//! libcosim's `algorithm::do_step` does.

use crate::algorithm::step::{Degree, StepAt};
use crate::state_bytes::{Pass, Passed};
use crate::stats::AdaptiveStats;
use crate::step_control::Controller;
use crate::MasterError;

/// Where the run is in time, and how it steps.
#[derive(Debug, Clone)]
pub(crate) struct Grid {
    /// T_0.
    start: f64,
    /// H: the uniform step, and the unit of progress for adaptive steps.
    step: f64,
    /// N, the index of the current point.
    n: u64,
    /// The number of steps of H the experiment spans.
    steps: u64,
    /// k, the degree of the coupling polynomials.
    order: usize,
    kind: Kind,
}

#[derive(Debug, Clone)]
enum Kind {
    /// The uniform grid; every `every`-th point is recorded.
    Uniform { every: u64 },
    /// Adaptive macro steps (`[step_control]`).
    Adaptive(Adaptive),
}

/// The variable grid of adaptive macro steps.
#[derive(Debug, Clone)]
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
    output: Option<f64>,
    /// j of the next output point.
    next_output: u64,
    /// Whether T_N is an output point.
    on_output: bool,
    stats: AdaptiveStats,
}

impl Grid {
    /// The uniform grid from `start` in `steps` steps of `step`, recording
    /// every `every`-th point, for polynomials of degree `order`.
    pub(crate) fn uniform(start: f64, step: f64, steps: u64, every: u64, order: usize) -> Grid {
        Grid {
            start,
            step,
            n: 0,
            steps,
            order,
            kind: Kind::Uniform { every },
        }
    }

    /// Adaptive steps from `start` to `stop` (exactly), the first try `h`,
    /// landing on the output points T_0 + j·`output` when given; `step` is
    /// the unit of progress.
    pub(crate) fn adaptive(
        controller: Controller,
        (start, stop, step, steps): (f64, f64, f64, u64),
        h: f64,
        output: Option<f64>,
        order: usize,
    ) -> Grid {
        Grid {
            start,
            step,
            n: 0,
            steps,
            order,
            kind: Kind::Adaptive(Adaptive {
                controller,
                t: start,
                stop,
                h,
                past: [h, h],
                output,
                next_output: 1,
                on_output: false,
                stats: AdaptiveStats {
                    h_smallest: f64::INFINITY,
                    ..AdaptiveStats::default()
                },
            }),
        }
    }

    /// N, the index of the current point.
    pub(crate) fn n(&self) -> u64 {
        self.n
    }

    /// The number of steps of H the experiment spans.
    pub(crate) fn total_steps(&self) -> u64 {
        self.steps
    }

    /// T_N.
    pub(crate) fn time(&self) -> f64 {
        match &self.kind {
            Kind::Adaptive(a) => a.t,
            Kind::Uniform { .. } => self.time_at(self.n),
        }
    }

    fn time_at(&self, n: u64) -> f64 {
        self.start + n as f64 * self.step
    }

    /// Whether the run has reached its last point.
    pub(crate) fn finished(&self) -> bool {
        match &self.kind {
            Kind::Adaptive(a) => a.t >= a.stop,
            Kind::Uniform { .. } => self.n >= self.steps,
        }
    }

    /// Whether the current point goes to the observers: on the output grid,
    /// or the last one.
    pub(crate) fn recorded(&self) -> bool {
        match &self.kind {
            Kind::Adaptive(a) => a.output.is_none() || a.on_output || self.finished(),
            Kind::Uniform { every } => self.n.is_multiple_of(*every) || self.n == self.steps,
        }
    }

    /// Steps done, for progress: with adaptive steps, how many steps of H
    /// the time reached spans (never beyond the total).
    pub(crate) fn progress(&self) -> u64 {
        match &self.kind {
            Kind::Adaptive(a) => {
                let spanned = (a.t - self.start) / self.step;
                (spanned.round() as u64).min(self.steps)
            }
            Kind::Uniform { .. } => self.n,
        }
    }

    /// The adaptive steps' counters, if the grid is adaptive.
    pub(crate) fn adaptive_stats(&self) -> Option<AdaptiveStats> {
        match &self.kind {
            Kind::Adaptive(a) => Some(a.stats),
            Kind::Uniform { .. } => None,
        }
    }

    /// One accepted step from T_N: `try_step(at)` runs the method's step
    /// and returns its error norm (adaptive steps) or `None`. On the uniform
    /// grid the one try is the step. With adaptive steps the controller's
    /// step is tried (clipped to land on the next output point and the stop
    /// time, halved when that target is within two steps), and retried
    /// smaller while the error norm exceeds 1. Returns the step taken.
    pub(crate) fn advance(
        &mut self,
        limit: Option<f64>,
        mut try_step: impl FnMut(StepAt) -> Result<Option<f64>, MasterError>,
    ) -> Result<StepAt, MasterError> {
        let at = match &mut self.kind {
            Kind::Uniform { .. } => {
                let at = StepAt {
                    n: self.n,
                    t: self.time_at(self.n),
                    h: self.step,
                    t_next: self.time_at(self.n + 1),
                    past: None,
                    degree: Degree::at(self.n, self.order),
                };
                try_step(at)?;
                at
            }
            Kind::Adaptive(a) => {
                let degree = Degree::at(self.n, self.order);
                a.advance((self.n, degree), self.start, limit, &mut try_step)?
            }
        };
        self.n += 1;
        Ok(at)
    }
}

impl Adaptive {
    fn advance(
        &mut self,
        (n, degree): (u64, Degree),
        start: f64,
        limit: Option<f64>,
        try_step: &mut impl FnMut(StepAt) -> Result<Option<f64>, MasterError>,
    ) -> Result<StepAt, MasterError> {
        // The point the step must not pass: the next output point (a point
        // within 1e-9 intervals of the stop time is the stop time).
        let point = match self.output {
            Some(dt) => {
                let point = start + self.next_output as f64 * dt;
                if point >= self.stop - 1e-9 * dt {
                    self.stop
                } else {
                    point
                }
            }
            None => self.stop,
        };
        // A limit before the next output point (or the stop) ends the step
        // there instead; one within 1e-9 of the remaining span of the point
        // is the point.
        let (target, on_point) = match limit {
            Some(l) if l < point - 1e-9 * (point - self.t) => (l, false),
            _ => (point, true),
        };
        loop {
            let remaining = target - self.t;
            // A clipped step ends exactly at the target; no sliver is left.
            let clipped = self.h >= remaining || remaining - self.h < 1e-3 * self.h;
            // A target within two steps is reached in two equal ones: a
            // sliver step next to full ones would put nearby points into the
            // polynomials through the past points (k ≥ 1), whose slope then
            // amplifies the multipliers' noise by the ratio of H to the sliver.
            let halved = !clipped && remaining < 2.0 * self.h;
            let h = match (clipped, halved) {
                (true, _) => remaining,
                (false, true) => 0.5 * remaining,
                (false, false) => self.h,
            };
            let at = StepAt {
                n,
                t: self.t,
                h,
                t_next: if clipped { target } else { self.t + h },
                past: Some(self.past),
                degree,
            };
            let error = try_step(at)?.expect("the predictor/corrector step estimates its error");
            let (next, accepted) = self.controller.next(h, error);
            if accepted {
                self.t = at.t_next;
                self.past = [h, self.past[0]];
                // A clipped or halved step does not shrink the next proposal.
                self.h = if clipped || halved {
                    self.h.max(next)
                } else {
                    next
                };
                self.on_output = clipped && on_point && self.output.is_some();
                if self.on_output {
                    self.next_output += 1;
                }
                self.stats.accepted += 1;
                self.stats.last_error = error;
                self.stats.h_smallest = self.stats.h_smallest.min(h);
                self.stats.h_largest = self.stats.h_largest.max(h);
                return Ok(at);
            }
            self.stats.rejected += 1;
            if h <= self.controller.limits.h_min {
                return Err(MasterError::StepSizeTooSmall {
                    time: self.t,
                    error,
                    h_min: self.controller.limits.h_min,
                });
            }
            self.h = next;
        }
    }
}

impl Grid {
    /// Its numbers through `p`, for the saved state's bytes.
    pub(crate) fn pass(&mut self, p: &mut Pass) -> Passed {
        p.f64(&mut self.start)?;
        p.f64(&mut self.step)?;
        p.u64(&mut self.n)?;
        p.u64(&mut self.steps)?;
        p.same(self.order, "the polynomials' degree")?;
        match &mut self.kind {
            Kind::Uniform { every } => {
                p.same(0, "[step_control]")?;
                p.u64(every)
            }
            Kind::Adaptive(a) => {
                p.same(1, "[step_control]")?;
                a.controller.pass(p)?;
                for x in [&mut a.t, &mut a.stop, &mut a.h] {
                    p.f64(x)?;
                }
                p.f64s(&mut a.past, "the past steps")?;
                p.option(&mut a.output, "[output] interval", Pass::f64)?;
                p.u64(&mut a.next_output)?;
                p.bool(&mut a.on_output)?;
                let s = &mut a.stats;
                p.u64(&mut s.accepted)?;
                p.u64(&mut s.rejected)?;
                for x in [&mut s.h_smallest, &mut s.h_largest, &mut s.last_error] {
                    p.f64(x)?;
                }
                Ok(())
            }
        }
    }
}
