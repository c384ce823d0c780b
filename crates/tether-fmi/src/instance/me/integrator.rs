//! The built-in integrator of model-exchange instances: explicit Runge–Kutta
//! methods with error control — Dormand–Prince 5(4), `rk45` ([`dopri5`], in
//! buffers the instance keeps, so a step allocates nothing), and 8(5,3),
//! `dop853` (the `ode_solvers` crate) — over the states scaled by their
//! nominals, so that the absolute tolerance of state i is `atol · nominal_i`.
//!
//! One call integrates from (t0, x0) towards t1 and stops after the first
//! accepted step at which an event indicator changed sign (a state event) or
//! `CompletedIntegratorStep` asked for event mode (a step event); the event
//! time is then located by bisection, each probe integrated afresh from the
//! last point before the event, to within `100·ε·max(|t|, h)`. Every call
//! starts from its initial point with the same initial step (the integrator's
//! own choice from (t0, x0)) and no history, so a repeated step is
//! bit-identical.
//!
//! `bdf` (the default) and `esdirk`, the implicit methods of the `diffsol`
//! crate, are in [`implicit`]: the same scaled states, tolerances, callback
//! after each accepted step and restarts.

use std::cell::RefCell;

use ode_solvers::dop_shared::{IntegrationError, OutputType};
use ode_solvers::{DVector, Dop853, System};

use super::calls::MeCalls;
use super::dopri5::{self, Dopri5, Failure};
use super::inputs::InputPolynomial;
use crate::error::{Error, Result};
use crate::integrator::Method;

mod implicit;

/// How a call of [`integrate`] ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Stop {
    /// At t1.
    Reached,
    /// At a located state event.
    StateEvent,
    /// `CompletedIntegratorStep` asked for event mode.
    StepEvent,
    /// `CompletedIntegratorStep` asked to end the simulation.
    Terminate,
}

/// What the accepted steps are checked for, and what was found.
struct Watch {
    /// The event indicators at the last accepted point.
    z_prev: Vec<f64>,
    z: Vec<f64>,
    needs_completed: bool,
    /// `noSetFMUStatePriorToCurrentPoint` of `CompletedIntegratorStep`.
    no_set_prior: bool,
    tau_prev: f64,
    y_prev: Vec<f64>,
    found: Option<(Stop, f64)>,
}

/// The right-hand side over scaled states `y = x / nominal`, in time relative
/// to `t0` (the solver's own time starts at 0 at every call).
struct Rhs<'a> {
    fmu: RefCell<&'a mut dyn MeCalls>,
    /// The inputs' polynomial, set with the time.
    inputs: &'a InputPolynomial,
    t0: f64,
    nominals: &'a [f64],
    x: RefCell<Vec<f64>>,
    dx: RefCell<Vec<f64>>,
    failure: RefCell<Option<Error>>,
    /// `None` while probing for an event time (no checks, no completed steps).
    watch: Option<Watch>,
}

impl Rhs<'_> {
    /// Sets (t0 + tau, y·nominal) in the FMU, the inputs' polynomial at
    /// that time.
    fn set(&self, tau: f64, y: &[f64]) -> Result<()> {
        let mut x = self.x.borrow_mut();
        for ((x, y), n) in x.iter_mut().zip(y).zip(self.nominals) {
            *x = y * n;
        }
        let mut fmu = self.fmu.borrow_mut();
        fmu.set_time(self.t0 + tau)?;
        self.inputs.set(&mut **fmu, self.t0 + tau)?;
        fmu.set_continuous_states(&x)
    }

    fn derivatives(&self, tau: f64, y: &[f64], dy: &mut [f64]) -> Result<()> {
        self.set(tau, y)?;
        let mut dx = self.dx.borrow_mut();
        let mut fmu = self.fmu.borrow_mut();
        fmu.get_derivatives(&mut dx)?;
        if let Some(i) = dx.iter().position(|v| !v.is_finite()) {
            let (function, _, _) = fmu.names();
            return Err(Error::ModelExchange {
                instance: fmu.name().to_owned(),
                time: self.t0 + tau,
                cause: format!(
                    "{function} returned {} for the derivative of continuous state {} of {}",
                    dx[i],
                    i + 1,
                    dx.len()
                ),
            });
        }
        for ((d, x), n) in dy.iter_mut().zip(dx.iter()).zip(self.nominals) {
            *d = x / n;
        }
        Ok(())
    }

    fn fail(&self, e: Error) {
        let mut failure = self.failure.borrow_mut();
        if failure.is_none() {
            *failure = Some(e);
        }
    }

    /// After an accepted step to `tau`: a state event, a step event, a request
    /// to terminate, or nothing (true: stop).
    fn check_accepted(&mut self, tau: f64, y: &[f64]) -> Result<bool> {
        if self.watch.is_none() {
            return Ok(false);
        }
        self.set(tau, y)?;
        let fmu = self.fmu.get_mut();
        let Some(w) = self.watch.as_mut() else {
            return Ok(false);
        };
        if !w.z.is_empty() {
            fmu.get_event_indicators(&mut w.z)?;
            if crossed(&w.z_prev, &w.z) {
                w.found = Some((Stop::StateEvent, tau));
                return Ok(true);
            }
        }
        if w.needs_completed {
            let (event, terminate) = fmu.completed_integrator_step(w.no_set_prior)?;
            if terminate {
                w.found = Some((Stop::Terminate, tau));
                return Ok(true);
            }
            if event {
                w.found = Some((Stop::StepEvent, tau));
                return Ok(true);
            }
        }
        std::mem::swap(&mut w.z_prev, &mut w.z);
        w.tau_prev = tau;
        w.y_prev.clear();
        w.y_prev.extend_from_slice(y);
        Ok(false)
    }
}

/// Whether an indicator changed from > 0 to ≤ 0 or back.
pub(crate) fn crossed(before: &[f64], after: &[f64]) -> bool {
    before
        .iter()
        .zip(after)
        .any(|(b, a)| (*b > 0.0) != (*a > 0.0))
}

/// The solver borrows the right-hand side, which keeps what it found.
impl System<f64, DVector<f64>> for &mut Rhs<'_> {
    fn system(&self, tau: f64, y: &DVector<f64>, dy: &mut DVector<f64>) {
        if self.failure.borrow().is_some() {
            // The step is accepted with zero slopes and the call stops at once.
            dy.fill(0.0);
            return;
        }
        if let Err(e) = self.derivatives(tau, y.as_slice(), dy.as_mut_slice()) {
            self.fail(e);
            dy.fill(0.0);
        }
    }

    fn solout(&mut self, tau: f64, y: &DVector<f64>, _dy: &DVector<f64>) -> bool {
        if self.failure.borrow().is_some() {
            return true;
        }
        match self.check_accepted(tau, y.as_slice()) {
            Ok(stop) => stop,
            Err(e) => {
                self.fail(e);
                true
            }
        }
    }
}

impl dopri5::Problem for Rhs<'_> {
    fn rhs(&mut self, tau: f64, y: &[f64], dy: &mut [f64]) -> bool {
        match self.derivatives(tau, y, dy) {
            Ok(()) => true,
            Err(e) => {
                self.fail(e);
                false
            }
        }
    }

    fn accepted(&mut self, tau: f64, y: &[f64]) -> bool {
        match self.check_accepted(tau, y) {
            Ok(stop) => stop,
            Err(e) => {
                self.fail(e);
                true
            }
        }
    }
}

/// The buffers of the integration, kept by the instance between steps.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    dopri5: Dopri5,
    y0: Vec<f64>,
    y: Vec<f64>,
    x: Vec<f64>,
    dx: Vec<f64>,
    z: Vec<f64>,
    z_prev: Vec<f64>,
    y_prev: Vec<f64>,
    /// The bisection's two ends and probe of an event time.
    y_lo: Vec<f64>,
    y_mid: Vec<f64>,
    z_probe: Vec<f64>,
}

impl Buffers {
    /// Sizes every buffer for `nx` states and `nz` event indicators, so that
    /// no step allocates, not even the first event's.
    pub(crate) fn prepare(&mut self, nx: usize, nz: usize) {
        self.dopri5.resize(nx);
        for v in [
            &mut self.y0,
            &mut self.y,
            &mut self.x,
            &mut self.dx,
            &mut self.y_prev,
            &mut self.y_lo,
            &mut self.y_mid,
        ] {
            v.resize(nx, 0.0);
        }
        for v in [&mut self.z, &mut self.z_prev, &mut self.z_probe] {
            v.resize(nz, 0.0);
        }
    }
}

/// One integration of `rhs` from (tau0, y0) to tau1 (or to where an accepted
/// step stopped it): the time reached, the state there in `y`.
fn solve(
    settings: &Settings,
    rhs: &mut Rhs<'_>,
    dopri5: &mut Dopri5,
    (tau0, tau1): (f64, f64),
    y0: &[f64],
    y: &mut Vec<f64>,
) -> Result<f64> {
    let h_max = settings.max_step.min(tau1 - tau0);
    let failure = match settings.method {
        // diffsol's failures are left in `rhs.failure`, as the FMU's are.
        Method::Bdf | Method::Esdirk => {
            let (tau, end) = implicit::solve(settings, rhs, tau0, tau1, y0);
            y.clear();
            y.extend_from_slice(&end);
            return rhs.failure.take().map_or(Ok(tau), Err);
        }
        Method::Rk45 => {
            let options = dopri5::Options {
                rtol: settings.rtol,
                atol: settings.atol,
                h_max,
                n_max: N_MAX,
            };
            match dopri5.integrate(rhs, &options, tau0, tau1, y0, y) {
                Ok(tau) => return rhs.failure.take().map_or(Ok(tau), Err),
                Err(failure) => failure,
            }
        }
        // Hairer's defaults of DOP853.
        Method::Dop853 => {
            let mut solver = Dop853::from_param(
                &mut *rhs,
                tau0,
                tau1,
                tau1 - tau0,
                DVector::from_column_slice(y0),
                settings.rtol,
                settings.atol,
                0.9,
                0.0,
                0.333,
                6.0,
                h_max,
                0.0,
                N_MAX,
                1000,
                OutputType::Sparse,
            );
            let result = solver.integrate();
            y.clear();
            if let Some(last) = solver.y_out().last() {
                y.extend_from_slice(last.as_slice());
            }
            let tau = solver.x_out().last().copied().unwrap_or(tau0);
            match result {
                Ok(_) => return rhs.failure.take().map_or(Ok(tau), Err),
                Err(IntegrationError::MaxNumStepReached { x, n_step }) => {
                    Failure::MaxSteps { tau: x, n_step }
                }
                Err(IntegrationError::StepSizeUnderflow { x }) => Failure::Underflow { tau: x },
                Err(IntegrationError::StiffnessDetected { x }) => Failure::Stiff { tau: x },
            }
        }
    };
    Err(rhs
        .failure
        .take()
        .unwrap_or_else(|| integration_error(rhs, settings, failure)))
}

/// The most steps of one integration.
const N_MAX: u32 = 100_000;

/// The integrator settings in force for one call.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Settings {
    pub method: Method,
    pub rtol: f64,
    pub atol: f64,
    pub max_step: f64,
}

/// The state of an instance between calls: the states, their nominals, the
/// event indicators at (t0, x).
pub(crate) struct Point<'a> {
    pub t0: f64,
    pub x: &'a mut [f64],
    pub nominals: &'a [f64],
    pub z: &'a mut [f64],
    pub needs_completed: bool,
    /// No state before this point will be restored (false while a saved
    /// state may be).
    pub no_set_prior: bool,
    /// The communication step, for the event time's resolution.
    pub h: f64,
    /// The inputs' polynomial over the step.
    pub inputs: &'a InputPolynomial,
}

/// Integrates `fmu` from `p.t0` (where it is set) to `t1`; on return the FMU
/// and `p.x`, `p.z` are at the time returned, with how the call stopped.
pub(crate) fn integrate(
    fmu: &mut dyn MeCalls,
    settings: &Settings,
    p: Point<'_>,
    t1: f64,
    b: &mut Buffers,
) -> Result<(f64, Stop)> {
    let nx = p.x.len();
    b.y0.clear();
    b.y0.extend(p.x.iter().zip(p.nominals).map(|(x, n)| x / n));
    b.x.resize(nx, 0.0);
    b.dx.resize(nx, 0.0);
    b.z.resize(p.z.len(), 0.0);
    b.z_prev.clear();
    b.z_prev.extend_from_slice(p.z);
    b.y_prev.clone_from(&b.y0);
    let mut rhs = Rhs {
        fmu: RefCell::new(fmu),
        inputs: p.inputs,
        t0: p.t0,
        nominals: p.nominals,
        x: RefCell::new(std::mem::take(&mut b.x)),
        dx: RefCell::new(std::mem::take(&mut b.dx)),
        failure: RefCell::new(None),
        watch: Some(Watch {
            z_prev: std::mem::take(&mut b.z_prev),
            z: std::mem::take(&mut b.z),
            needs_completed: p.needs_completed,
            no_set_prior: p.no_set_prior,
            tau_prev: 0.0,
            y_prev: std::mem::take(&mut b.y_prev),
            found: None,
        }),
    };
    let result = finish(&mut rhs, settings, p, t1, b);
    // The buffers go back to the instance, whatever happened.
    b.x = rhs.x.into_inner();
    b.dx = rhs.dx.into_inner();
    if let Some(w) = rhs.watch {
        (b.z_prev, b.z, b.y_prev) = (w.z_prev, w.z, w.y_prev);
    }
    result
}

/// The integration of [`integrate`], its event located.
fn finish(
    rhs: &mut Rhs<'_>,
    settings: &Settings,
    p: Point<'_>,
    t1: f64,
    b: &mut Buffers,
) -> Result<(f64, Stop)> {
    let tau1 = t1 - p.t0;
    let tau_end = if p.x.is_empty() {
        // No continuous states: one step to t1 without the integrator.
        b.y.clear();
        dopri5::Problem::accepted(rhs, tau1, &[]);
        match rhs.failure.take() {
            Some(e) => return Err(e),
            None => tau1,
        }
    } else {
        solve(settings, rhs, &mut b.dopri5, (0.0, tau1), &b.y0, &mut b.y)?
    };
    let found = rhs.watch.as_ref().and_then(|w| w.found);
    let (stop, tau) = match found {
        None => (Stop::Reached, tau_end),
        Some((Stop::StateEvent, tau_hi)) => {
            let tau = locate(settings, rhs, b, tau_hi, p.h)?;
            (Stop::StateEvent, tau)
        }
        Some((stop, tau)) => (stop, tau),
    };
    set_point(rhs, tau, &b.y, p.x)?;
    if !p.z.is_empty() {
        rhs.fmu.get_mut().get_event_indicators(p.z)?;
    }
    // t0 + (t1 − t0) need not be t1 in floating point: the end is t1 exactly.
    let t = if stop == Stop::Reached && tau == tau1 {
        t1
    } else {
        p.t0 + tau
    };
    if t == t1 && t != p.t0 + tau {
        let fmu = rhs.fmu.get_mut();
        fmu.set_time(t1)?;
        rhs.inputs.set(&mut **fmu, t1)?;
    }
    Ok((t, stop))
}

/// Sets the FMU to (t0 + tau, y) and `x` to the unscaled states.
fn set_point(rhs: &Rhs<'_>, tau: f64, y: &[f64], x: &mut [f64]) -> Result<()> {
    rhs.set(tau, y)?;
    for ((x, y), n) in x.iter_mut().zip(y).zip(rhs.nominals) {
        *x = y * n;
    }
    Ok(())
}

/// The first time in (tau_prev, tau_hi] at which an indicator has changed
/// sign, to within 100·ε·max(|t|, h), by bisection: each probe integrates
/// afresh from the last point before the event. Returns the time just after
/// the crossing, the state there in `b.y` (the state at `tau_hi` on entry).
fn locate(
    settings: &Settings,
    rhs: &mut Rhs<'_>,
    b: &mut Buffers,
    tau_hi: f64,
    h: f64,
) -> Result<f64> {
    let Some(watch) = rhs.watch.take() else {
        return Ok(tau_hi);
    };
    let (mut lo, mut hi) = (watch.tau_prev, tau_hi);
    let (mut y_lo, mut y_mid, mut z) = (
        std::mem::take(&mut b.y_lo),
        std::mem::take(&mut b.y_mid),
        std::mem::take(&mut b.z_probe),
    );
    y_lo.clone_from(&watch.y_prev);
    z.resize(watch.z_prev.len(), 0.0);
    let resolution = 100.0 * f64::EPSILON * (rhs.t0 + tau_hi).abs().max(h);
    let located = (|| {
        while hi - lo > resolution {
            let mid = lo + 0.5 * (hi - lo);
            if mid <= lo || mid >= hi {
                break;
            }
            if !y_lo.is_empty() {
                solve(settings, rhs, &mut b.dopri5, (lo, mid), &y_lo, &mut y_mid)?;
            }
            rhs.set(mid, &y_mid)?;
            rhs.fmu.get_mut().get_event_indicators(&mut z)?;
            if crossed(&watch.z_prev, &z) {
                hi = mid;
                std::mem::swap(&mut b.y, &mut y_mid);
            } else {
                lo = mid;
                std::mem::swap(&mut y_lo, &mut y_mid);
            }
        }
        Ok(())
    })();
    rhs.watch = Some(watch);
    (b.y_lo, b.y_mid, b.z_probe) = (y_lo, y_mid, z);
    located.map(|()| hi)
}

/// The integrator's failure as one line naming the instance and the time.
fn integration_error(rhs: &Rhs<'_>, settings: &Settings, failure: Failure) -> Error {
    let (tau, what) = match failure {
        Failure::Rhs { tau } => (tau, "could not evaluate the derivatives".to_string()),
        Failure::MaxSteps { tau, n_step } => (tau, format!("needs more than {n_step} steps")),
        Failure::Underflow { tau } => (
            tau,
            "cannot reach the tolerance: the step size fell below the resolution of time"
                .to_string(),
        ),
        Failure::Stiff { tau } => (
            tau,
            "the model became stiff for this explicit method".to_string(),
        ),
    };
    integrator_stopped(rhs, settings, tau, &what)
}

/// One line naming the instance, the time `t0 + tau`, the integrator's
/// settings and `what` stopped it.
fn integrator_stopped(rhs: &Rhs<'_>, settings: &Settings, tau: f64, what: &str) -> Error {
    Error::ModelExchange {
        instance: rhs.fmu.borrow().name().to_owned(),
        time: rhs.t0 + tau,
        cause: format!(
            "the integrator ({}, rtol {}, atol {} × nominals) {what}",
            settings.method.name(),
            settings.rtol,
            settings.atol
        ),
    }
}
